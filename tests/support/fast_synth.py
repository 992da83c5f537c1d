"""Tracking submissions made from nuScenes ground truth: the oracle and realistically corrupted variants.

Used by the parity tests and the benchmark of the fast evaluator (:mod:`grutrack.evaluation.fast_amota`).
Everything here is derived from the ground truth of the given split; nothing is a real tracker's output.
"""

from __future__ import annotations

import copy
from collections import defaultdict

import numpy as np

__all__ = ["gt_submission", "corrupt_submission", "SUBMISSION_META"]

SUBMISSION_META = {"use_camera": False, "use_lidar": True, "use_radar": False, "use_map": False, "use_external": False}

# Plausible class confusions for tracks that change class.
_CONFUSION = {
    "car": "truck",
    "truck": "car",
    "bus": "truck",
    "trailer": "truck",
    "pedestrian": "bicycle",
    "bicycle": "motorcycle",
    "motorcycle": "bicycle",
}


def _split_samples(nusc, split: str) -> list[list[str]]:
    """Sample tokens of the split, per scene in time order (scenes in ``nusc.scene`` order)."""
    from nuscenes.utils.splits import get_scenes_of_split

    names = set(get_scenes_of_split(split, nusc))
    scenes = []
    for scene in nusc.scene:
        if scene["name"] not in names:
            continue
        tokens = []
        token = scene["first_sample_token"]
        while token:
            tokens.append(token)
            token = nusc.get("sample", token)["next"]
        scenes.append(tokens)
    return scenes


def gt_submission(nusc, split: str, skip_empty: bool = False, score: float = 1.0) -> dict:
    """The ground truth of ``split`` as a tracking submission (the oracle).

    tracking_name from the category (``category_to_tracking_name``; other categories dropped), tracking_id the
    instance token, velocity from ``nusc.box_velocity``, score ``score``. With ``skip_empty`` the annotations
    with no lidar and no radar point are left out (the devkit drops them from the ground truth and then
    interpolates the gaps, so the oracle scores AMOTA 1.0); without it they are kept and become false positives.
    """
    from nuscenes.eval.tracking.utils import category_to_tracking_name

    results: dict[str, list[dict]] = {}
    for tokens in _split_samples(nusc, split):
        for token in tokens:
            boxes = []
            for ann_token in nusc.get("sample", token)["anns"]:
                ann = nusc.get("sample_annotation", ann_token)
                name = category_to_tracking_name(ann["category_name"])
                if name is None:
                    continue
                if skip_empty and ann["num_lidar_pts"] + ann["num_radar_pts"] == 0:
                    continue
                vel = nusc.box_velocity(ann_token)[:2]
                boxes.append(
                    {
                        "sample_token": token,
                        "translation": [float(v) for v in ann["translation"]],
                        "size": [float(v) for v in ann["size"]],
                        "rotation": [float(v) for v in ann["rotation"]],
                        "velocity": [float(vel[0]), float(vel[1])],
                        "tracking_id": ann["instance_token"],
                        "tracking_name": name,
                        "tracking_score": float(score),
                    }
                )
            results[token] = boxes
    return {"meta": dict(SUBMISSION_META), "results": results}


def corrupt_submission(
    nusc,
    split: str,
    seed: int = 0,
    *,
    base: dict | None = None,
    noise: float = 0.25,
    drop_box: float = 0.1,
    drop_track: float = 0.08,
    fragment: float = 0.15,
    swap: float = 0.1,
    class_change: float = 0.05,
    duplicate: float = 0.06,
    exact_duplicate: float = 0.03,
    fp_tracks_per_scene: int = 25,
    fp_single_per_sample: float = 2.0,
    empty_samples: float = 0.05,
    equal_scores: float | None = None,
    repeated_id: float = 0.0,
) -> dict:
    """A realistic imperfect tracker output made from the ground truth of ``split`` (deterministic per seed).

    Per ground-truth track: dropped entirely (``drop_track``), boxes dropped (``drop_box``, gaps the devkit
    interpolates), centre noise (``noise`` m, a few tracks 4x noisier), fragmented into a new id from a random
    frame (``fragment``), ids swapped with another track of the same class from a random frame (``swap``),
    class changed from a random frame (``class_change``), shadowed by a second track 0.3-1.5 m away
    (``duplicate``) or at exactly the same place (``exact_duplicate``: exact distance ties). Plus persistent
    false-positive tracks near the ground truth, single-frame false positives, samples left empty
    (``empty_samples``), optionally the same id used twice in a frame (``repeated_id``) and optionally every
    score equal (``equal_scores``). Scores: per-track level plus per-box noise (the devkit averages them).
    """
    rng = np.random.default_rng(seed)
    base = base if base is not None else gt_submission(nusc, split)
    results: dict[str, list[dict]] = {token: [] for token in base["results"]}
    counter = [0]

    def new_id(prefix: str) -> str:
        counter[0] += 1
        return "%s-%d-%d" % (prefix, seed, counter[0])

    def emit(token: str, src: dict, tid: str, name: str, xy_offset, score: float) -> None:
        box = copy.deepcopy(src)
        box["translation"][0] += float(xy_offset[0])
        box["translation"][1] += float(xy_offset[1])
        box["tracking_id"] = tid
        box["tracking_name"] = name
        box["tracking_score"] = float(score)
        results[token].append(box)

    for tokens in _split_samples(nusc, split):
        tokens = [t for t in tokens if t in base["results"]]
        # Tracks of this scene: instance -> list of (frame index, box).
        tracks: dict[str, list] = defaultdict(list)
        for k, token in enumerate(tokens):
            for box in base["results"][token]:
                tracks[box["tracking_id"]].append((k, box))
        ids = list(tracks)
        by_class: dict[str, list[str]] = defaultdict(list)
        for tid in ids:
            by_class[tracks[tid][0][1]["tracking_name"]].append(tid)

        # Id plan per (instance, frame): fragments and swaps.
        out_id: dict[str, list[str]] = {tid: [tid + "-t"] * len(tracks[tid]) for tid in ids}
        for tid in ids:
            n = len(tracks[tid])
            if n > 2 and rng.random() < fragment:
                cut = int(rng.integers(1, n))
                fresh = new_id("frag")
                out_id[tid][cut:] = [fresh] * (n - cut)
        for name, members in by_class.items():
            for tid in members:
                if len(members) > 1 and rng.random() < swap:
                    other = members[int(rng.integers(len(members)))]
                    if other == tid:
                        continue
                    frame = int(rng.integers(0, len(tokens)))
                    a = [i for i, (k, _) in enumerate(tracks[tid]) if k >= frame]
                    b = [i for i, (k, _) in enumerate(tracks[other]) if k >= frame]
                    ida = [out_id[tid][i] for i in a]
                    idb = [out_id[other][i] for i in b]
                    if a and b:
                        for i in a:
                            out_id[tid][i] = idb[0]
                        for i in b:
                            out_id[other][i] = ida[0]

        for tid in ids:
            track = tracks[tid]
            if rng.random() < drop_track:
                continue
            level = float(rng.uniform(0.15, 1.0))
            sigma = noise * (4.0 if rng.random() < 0.1 else 1.0)
            change_at = int(rng.integers(1, len(track))) if len(track) > 1 and rng.random() < class_change else None
            dup = rng.random() < duplicate
            exact_dup = rng.random() < exact_duplicate
            dup_id = new_id("dup")
            angle = rng.uniform(0, 2 * np.pi)
            dup_offset = rng.uniform(0.3, 1.5) * np.array([np.cos(angle), np.sin(angle)])
            dup_level = float(rng.uniform(0.1, 0.6))
            for i, (k, box) in enumerate(track):
                if rng.random() < drop_box:
                    continue
                name = box["tracking_name"]
                if change_at is not None and i >= change_at:
                    name = _CONFUSION[name]
                score = float(np.clip(level + rng.normal(0, 0.05), 0.01, 1.0))
                off = rng.normal(0, sigma, 2)
                emit(tokens[k], box, out_id[tid][i], name, off, score)
                if dup:
                    emit(
                        tokens[k],
                        box,
                        dup_id,
                        name,
                        off + dup_offset + rng.normal(0, 0.1, 2),
                        float(np.clip(dup_level + rng.normal(0, 0.05), 0.01, 1.0)),
                    )
                if exact_dup:
                    emit(tokens[k], box, dup_id + "x", name, off, score)
                if repeated_id and rng.random() < repeated_id:
                    emit(tokens[k], box, out_id[tid][i], name, off + rng.normal(0, 0.5, 2), score)

        # Persistent false-positive tracks: start near a GT box, drift.
        all_boxes = [(k, box) for k, token in enumerate(tokens) for box in base["results"][token]]
        for _ in range(fp_tracks_per_scene if all_boxes else 0):
            k0, src = all_boxes[int(rng.integers(len(all_boxes)))]
            length = int(rng.integers(1, 12))
            start = src["translation"][:2]
            offset = rng.uniform(-6, 6, 2)
            drift = rng.normal(0, 0.8, 2)
            name = src["tracking_name"] if rng.random() < 0.8 else str(rng.choice(list(_CONFUSION)))
            fid = new_id("fp")
            level = float(rng.uniform(0.05, 0.7))
            for step in range(length):
                k = k0 + step
                if k >= len(tokens):
                    break
                pos = offset + drift * step
                box = copy.deepcopy(src)
                box["translation"][0] = start[0]
                box["translation"][1] = start[1]
                emit(tokens[k], box, fid, name, pos, float(np.clip(level + rng.normal(0, 0.05), 0.01, 1.0)))
        # Single-frame false positives.
        for k, token in enumerate(tokens):
            gt_here = base["results"][token]
            for _ in range(int(rng.poisson(fp_single_per_sample)) if gt_here else 0):
                src = gt_here[int(rng.integers(len(gt_here)))]
                emit(
                    token,
                    src,
                    new_id("fp1"),
                    src["tracking_name"],
                    rng.uniform(-4, 4, 2),
                    float(rng.uniform(0.01, 0.6)),
                )

    for token in results:
        if rng.random() < empty_samples:
            results[token] = []
        elif len(results[token]) > 500:
            results[token] = sorted(results[token], key=lambda b: -b["tracking_score"])[:500]
        if equal_scores is not None:
            for box in results[token]:
                box["tracking_score"] = float(equal_scores)
    return {"meta": dict(SUBMISSION_META), "results": results}
