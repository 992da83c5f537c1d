"""Defaults of the SYNTHETIC demo dataset that the command line shows in its help, importable without numpy."""

VERSION = "v1.0-demo"
FRAMES_PER_SCENE = 40  # nuScenes scenes are 20 s long: 39-41 keyframes in mini
DEFAULT_SCENES = 10  # quick demo: 8 demo_train + 2 demo_val scenes (mini has 8 + 2)
