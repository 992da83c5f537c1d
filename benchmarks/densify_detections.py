"""A denser, messier nuScenes detection file from another one, for parity checks against a tracker's own code.

Real detector output differs from ``grutrack simulate-detections``' files in ways a tracker re-implementation can
trip on: boxes of all ten detection classes (barrier, traffic_cone and construction_vehicle included, which every
tracker must drop), many low-scored boxes per sample, scores printed at a few decimals so that equal scores are
common (sort order on ties), and exact duplicate boxes (NMS on equal boxes). This script adds them to a file:

    .venv/bin/python benchmarks/densify_detections.py IN.json OUT.json [--clutter 120] [--decimals 2] \\
        [--duplicates 0.05] [--seed 1]

- every score is rounded to ``--decimals``;
- each box is repeated, exactly, with probability ``--duplicates``;
- each sample with boxes gets ``--clutter`` boxes more: a copy of one of its boxes (drawn among the first N once
  the duplicates are in, N its number of boxes), moved by N(0, 6 m) in x and y,
  its velocity by N(0, 1 m/s) per axis, given a class drawn uniformly from the ten and a score U(0.01, 0.3);
- the boxes of a sample are shuffled; ``synthetic.note`` says the file was densified (the output is SYNTHETIC
  whatever the input: it is labelled so).

Used for docs/mctrack.md's densified rows. The output is written atomically; a file that is not a detection
submission exits 2 with one line.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from grutrack.classes import DETECTION_CLASSES  # noqa: E402
from grutrack.io import write_json_atomic  # noqa: E402

CLUTTER_SIGMA_M = 6.0
CLUTTER_VEL_SIGMA = 1.0
CLUTTER_SCORES = (0.01, 0.3)
ATTRIBUTE = {
    "car": "vehicle.parked",
    "truck": "vehicle.parked",
    "bus": "vehicle.moving",
    "trailer": "vehicle.parked",
    "construction_vehicle": "vehicle.parked",
    "pedestrian": "pedestrian.standing",
    "motorcycle": "cycle.without_rider",
    "bicycle": "cycle.without_rider",
    "traffic_cone": "",
    "barrier": "",
}


def densify(
    sub: dict, clutter: int, decimals: int, duplicates: float, rng: np.random.Generator
) -> dict[str, list[dict]]:
    """The densified ``results`` of a detection submission ``sub`` (sample token -> boxes); ``sub`` is not changed.
    Translations and velocities in the file's global frame, metres and m/s."""
    out = {}
    for token, boxes in sub["results"].items():
        new = []
        for box in boxes:
            box = dict(box, detection_score=round(float(box["detection_score"]), decimals))
            new.append(box)
            if rng.random() < duplicates:
                new.append(copy.deepcopy(box))
        for _ in range(clutter if boxes else 0):
            box = copy.deepcopy(new[int(rng.integers(len(boxes)))])
            box["translation"][0] += float(rng.normal(0.0, CLUTTER_SIGMA_M))
            box["translation"][1] += float(rng.normal(0.0, CLUTTER_SIGMA_M))
            box["velocity"] = [float(v + rng.normal(0.0, CLUTTER_VEL_SIGMA)) for v in box["velocity"]]
            name = DETECTION_CLASSES[int(rng.integers(len(DETECTION_CLASSES)))]
            box["detection_name"], box["attribute_name"] = name, ATTRIBUTE[name]
            box["detection_score"] = round(float(rng.uniform(*CLUTTER_SCORES)), decimals)
            new.append(box)
        rng.shuffle(new)
        out[token] = new
    return out


def densify_file(
    src: Path, dst: Path, clutter: int = 120, decimals: int = 2, duplicates: float = 0.05, seed: int = 1
) -> tuple[int, int]:
    """Write ``src`` densified (:func:`densify`, ``np.random.default_rng(seed)``) to ``dst``, atomically, labelled
    SYNTHETIC; returns its numbers of boxes and of samples. OSError / ValueError / KeyError / TypeError /
    IndexError on a file that is not a detection submission."""
    sub = json.loads(Path(src).read_text())
    results = densify(sub, clutter, decimals, duplicates, np.random.default_rng(seed))
    note = f"SYNTHETIC: densified from {Path(src).name} by benchmarks/densify_detections.py (seed {seed})"
    write_json_atomic(dst, {**sub, "results": results, "synthetic": dict(sub.get("synthetic") or {}, note=note)})
    return sum(len(b) for b in results.values()), len(results)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("input", type=Path, help="a nuScenes detection-submission JSON")
    ap.add_argument("output", type=Path)
    ap.add_argument("--clutter", type=int, default=120, help="boxes added per sample (default 120)")
    ap.add_argument("--decimals", type=int, default=2, help="decimals every score is rounded to (default 2)")
    ap.add_argument("--duplicates", type=float, default=0.05, help="chance a box is repeated exactly (default 0.05)")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    for flag, ok, expected in (
        ("--clutter", args.clutter >= 0, "an integer >= 0"),
        ("--decimals", args.decimals >= 0, "an integer >= 0"),
        ("--duplicates", 0.0 <= args.duplicates <= 1.0, "a number in [0, 1]"),
    ):
        if not ok:
            print(f"{flag}: expected {expected}, got {getattr(args, flag[2:])}", file=sys.stderr)
            return 2
    try:
        n, samples = densify_file(args.input, args.output, args.clutter, args.decimals, args.duplicates, args.seed)
    except (OSError, ValueError, KeyError, TypeError, IndexError) as exc:
        print(f"{args.input}: expected a nuScenes detection-submission JSON ({exc!r})", file=sys.stderr)
        return 2
    print(f"{args.output}: {n} boxes, {n / max(samples, 1):.1f} per sample")
    return 0


if __name__ == "__main__":
    sys.exit(main())
