"""How much of a detection set's centre error persists from one keyframe to the next: the correlation between the
centre errors (x, y) of the same ground-truth object in consecutive keyframes. A filter averages away the part of
the error that is independent between frames and cannot average away the rest; a detector whose errors are
correlated over time needs less smoothing than one whose errors are not.

    PYTHONPATH=. .venv/bin/python scripts/detection_error_correlation.py --dataroot ../shared/data/nuscenes \
        --version v1.0-mini --split mini_val \
        --detections ../shared/data/nuscenes/detections/pointpillars_mini_val.json

Matching per keyframe and class: Hungarian on BEV centre distance, pairs within --max-distance (m), detections with
score >= --min-score. The correlation is taken over both axes with the errors centred (one figure), with the root
mean square error and the number of consecutive pairs beside it, per class and over all classes.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment


def matched_errors(scenes, dets: dict, min_score: float, max_distance: float) -> dict:
    """{(scene name, GT instance id, keyframe index): ((2,) centre error detection - GT, metres, class label)} of
    every GT box matched to a detection of its class (Hungarian on BEV centre distance, pairs within
    ``max_distance`` m, detections with score >= ``min_score``)."""
    out = {}
    for s in scenes:
        for k, f in enumerate(s.frames):
            d, g = dets[f.token], f.gt
            keep = d.scores >= min_score
            db, dl = d.boxes[keep], d.labels[keep]
            for lab in np.unique(g.labels):
                gi, di = np.flatnonzero(g.labels == lab), np.flatnonzero(dl == lab)
                if not len(di):
                    continue
                cost = np.hypot(g.boxes[gi, None, 0] - db[None, di, 0], g.boxes[gi, None, 1] - db[None, di, 1])
                for a, b in zip(*linear_sum_assignment(cost)):
                    if cost[a, b] <= max_distance:
                        out[(s.name, g.ids[gi[a]], k)] = (db[di[b], :2] - g.boxes[gi[a], :2], int(lab))
    return out


def lag_one_correlation(e0: np.ndarray, e1: np.ndarray) -> float:
    """Correlation of paired centre errors ``e0, e1`` (P, 2) metres (the same object in consecutive keyframes),
    both axes together, each axis centred on its mean: 0 for errors independent between frames, 1 where every
    object keeps its error from one frame to the next. NaN for fewer than 3 pairs."""
    if len(e0) < 3:
        return float("nan")
    a, b = e0 - e0.mean(axis=0), e1 - e1.mean(axis=0)
    return float(np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b)))


def summary(errors: dict, class_names) -> list[tuple[str, int, float, float]]:
    """(class or "all", consecutive pairs, lag-1 correlation, RMS of the BEV centre error's length in metres) from
    :func:`matched_errors`; ``class_names[label]`` names a label."""
    pairs = [(e, errors[(s, i, k + 1)][0], lab) for (s, i, k), (e, lab) in errors.items() if (s, i, k + 1) in errors]
    rows = []
    for name, lab in [("all", None), *[(c, j) for j, c in enumerate(class_names)]]:
        sel = [p for p in pairs if lab is None or p[2] == lab]
        if not sel:
            continue
        e0, e1 = np.array([p[0] for p in sel]), np.array([p[1] for p in sel])
        rows.append((name, len(sel), lag_one_correlation(e0, e1), float(np.sqrt(np.mean(e0**2) * 2))))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dataroot", required=True)
    ap.add_argument("--version", required=True)
    ap.add_argument("--split", required=True)
    ap.add_argument("--detections", required=True, action="append", help="nuScenes detection JSON (repeatable)")
    ap.add_argument("--min-score", type=float, default=0.3)
    ap.add_argument("--max-distance", type=float, default=2.0)
    args = ap.parse_args()

    from grutrack.data.nusc_detections import load_detections
    from grutrack.data.nuscenes import load_scenes, open_nuscenes

    nusc = open_nuscenes(args.dataroot, args.version)
    scenes = load_scenes(nusc, args.split, with_gt=True)
    tokens = [f.token for s in scenes for f in s.frames]
    print("| detections | class | consecutive pairs | lag-1 correlation | RMS centre error (m) |")
    print("|---|---|---|---|---|")
    for path in args.detections:
        errors = matched_errors(scenes, load_detections(path, tokens), args.min_score, args.max_distance)
        for name, n, rho, rms in summary(errors, scenes[0].vocabulary.names):
            print(f"| {Path(path).name} | {name} | {n} | {f'{rho:+.3f}' if np.isfinite(rho) else '-'} | {rms:.3f} |")


if __name__ == "__main__":
    main()
