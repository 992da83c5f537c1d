"""Box-for-box comparison of two nuScenes tracking submissions (a reference tracker's output and ours).

Boxes of one sample are paired when they have the same class, translations within ``tol`` metres and scores
within ``score_tol``; each reference box pairs with at most one of ours (nearest first). Track ids may be
renamed and may restart per scene: the track partition agrees when, within every scene, the paired boxes
define a one-to-one map between reference and our track ids.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment


@dataclass
class ParityReport:
    """Result of :func:`compare_submissions`.

    ref_boxes / paired: reference boxes and how many of them found a partner; count_mismatch: samples whose
    box counts differ; first_divergent: (scene index, frame index, sample token) of the first sample in scene
    order where anything differs, or None; partition_breaks: paired boxes whose id map contradicts an earlier
    pair of the same scene.
    """

    ref_boxes: int = 0
    our_boxes: int = 0
    paired: int = 0
    count_mismatch: int = 0
    partition_breaks: int = 0
    max_offset: float = 0.0
    first_divergent: tuple | None = None
    divergent_samples: list = field(default_factory=list)

    @property
    def paired_fraction(self) -> float:
        return self.paired / self.ref_boxes if self.ref_boxes else 1.0

    @property
    def identical(self) -> bool:
        return (self.paired == self.ref_boxes == self.our_boxes and self.count_mismatch == 0
                and self.partition_breaks == 0)


def _pair(ref: list[dict], ours: list[dict], tol: float, score_tol: float) -> list[tuple[int, int, float]]:
    """(i_ref, j_ours, distance) pairs of one sample: same class, |dt| <= tol, |dscore| <= score_tol."""
    if not ref or not ours:
        return []
    a = np.array([r["translation"] for r in ref], dtype=np.float64)
    b = np.array([o["translation"] for o in ours], dtype=np.float64)
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    sa = np.array([r["tracking_score"] for r in ref], dtype=np.float64)
    sb = np.array([o["tracking_score"] for o in ours], dtype=np.float64)
    na = np.array([r["tracking_name"] for r in ref])
    nb = np.array([o["tracking_name"] for o in ours])
    ok = (d <= tol) & (np.abs(sa[:, None] - sb[None, :]) <= score_tol) & (na[:, None] == nb[None, :])
    if not ok.any():
        return []
    i, j = linear_sum_assignment(np.where(ok, d, 1e9))
    keep = ok[i, j]
    return list(zip(i[keep].tolist(), j[keep].tolist(), d[i[keep], j[keep]].tolist()))


def compare_submissions(ref: dict, ours: dict, scenes: list[list[str]], tol: float = 1e-6,
                        score_tol: float = 1e-6) -> ParityReport:
    """Compare submissions ``ref`` and ``ours`` (their ``results`` mappings) over ``scenes`` (per scene, its
    sample tokens in time order)."""
    rep = ParityReport()
    for si, tokens in enumerate(scenes):
        id_map, back = {}, {}
        for fi, tok in enumerate(tokens):
            r, o = ref.get(tok, []), ours.get(tok, [])
            rep.ref_boxes += len(r)
            rep.our_boxes += len(o)
            pairs = _pair(r, o, tol, score_tol)
            rep.paired += len(pairs)
            bad = len(r) != len(o) or len(pairs) != len(r)
            rep.count_mismatch += len(r) != len(o)
            for i, j, dist in pairs:
                rep.max_offset = max(rep.max_offset, dist)
                rid, oid = r[i]["tracking_id"], o[j]["tracking_id"]
                if id_map.setdefault(rid, oid) != oid or back.setdefault(oid, rid) != rid:
                    rep.partition_breaks += 1
                    bad = True
            if bad:
                rep.divergent_samples.append(tok)
                if rep.first_divergent is None:
                    rep.first_divergent = (si, fi, tok)
    return rep
