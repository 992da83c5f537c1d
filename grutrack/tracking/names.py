"""Tracker names, importable without numpy (the command line builds its parser from them)."""

#: trackers selectable with ``--tracker``; greedy and ab3dmot are the Table I baselines
#: (grutrack/tracking/baselines.py)
TRACKERS: tuple[str, ...] = ("ekf", "grukf", "greedy", "ab3dmot")
