"""Defaults of the SYNTHETIC demo dataset that the command line shows in its help, and how its tables are told
from a real dataset's; importable without numpy."""

VERSION = "v1.0-demo"
FRAMES_PER_SCENE = 40  # nuScenes scenes are 20 s long: 39-41 keyframes in mini
DEFAULT_SCENES = 10  # quick demo: 8 demo_train + 2 demo_val scenes (mini has 8 + 2)

#: how every scene description (and the README) of the demo dataset starts
MARKER = "SYNTHETIC grutrack demo dataset"


def is_demo_tables(nusc) -> bool:
    """Whether nuScenes-format tables (anything with a ``scene`` list of records) are a grutrack demo dataset:
    its scene descriptions start with :data:`MARKER`."""
    return any(str(rec.get("description", "")).startswith(MARKER) for rec in nusc.scene)
