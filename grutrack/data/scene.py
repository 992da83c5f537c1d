"""The canonical in-memory form shared by every stage: scenes of frames of boxes.

Everything after the dataset adapters (tracking, training, export) reads only these classes; nothing in
them knows whether the data came from nuScenes, Argoverse 2 or the synthetic demo.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from grutrack.boxes import BOX_DIM, empty_boxes
from grutrack.classes import TRACKING_CLASSES


@dataclass(frozen=True)
class Vocabulary:
    """What box labels mean: ``names[label]`` is the dataset's class name, ``param_classes[label]`` the
    nuScenes tracking class whose tracker parameters (thresholds, motion model, noise) it uses."""

    names: tuple[str, ...]
    param_classes: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.names)

    def labels(self, categories: np.ndarray) -> np.ndarray:
        """(N,) int64 label of each class name; -1 for a name outside the vocabulary."""
        lut = {n: i for i, n in enumerate(self.names)}
        return np.array([lut.get(c, -1) for c in categories], dtype=np.int64)


#: nuScenes (and the synthetic demo): the 7 tracking classes, each its own parameter class
NUSCENES_VOCABULARY = Vocabulary(TRACKING_CLASSES, TRACKING_CLASSES)


def _as_array(a, dtype, shape: tuple) -> np.ndarray:
    """``np.asarray(a, dtype).reshape(shape)``; an array already of that dtype and shape is taken as it is (the
    tracking loop makes a dozen box sets a frame)."""
    if type(a) is np.ndarray and a.dtype == dtype and a.ndim == len(shape) and shape[-1] in (-1, a.shape[-1]):
        return a
    return np.asarray(a, dtype=dtype).reshape(shape)


@dataclass
class BoxSet:
    """Boxes of one frame.

    boxes:  (N, 9) float64 ``[x, y, z, w, l, h, yaw, vx, vy]``, global/city frame, metres, radians, m/s.
    scores: (N,) float64 confidence in [0, 1] (1 for ground truth).
    labels: (N,) int64 index into the scene's :class:`Vocabulary` (nuScenes: the 7 tracking classes).
    ids:    (N,) object array of identity strings (GT instance tokens / track ids) or None.
    extra:  optional per-box arrays (e.g. ``num_pts`` for GT), each of length N.
    """

    boxes: np.ndarray
    scores: np.ndarray
    labels: np.ndarray
    ids: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.boxes = _as_array(self.boxes, np.float64, (-1, BOX_DIM))
        self.scores = _as_array(self.scores, np.float64, (-1,))
        self.labels = _as_array(self.labels, np.int64, (-1,))
        n = len(self.boxes)
        if len(self.scores) != n or len(self.labels) != n or (self.ids is not None and len(self.ids) != n):
            raise ValueError(
                f"BoxSet arrays disagree in length: boxes {n}, scores {len(self.scores)}, "
                f"labels {len(self.labels)}, ids {None if self.ids is None else len(self.ids)}"
            )

    def __len__(self) -> int:
        return len(self.boxes)

    @classmethod
    def empty(cls, with_ids: bool = False) -> BoxSet:
        """A set of zero boxes."""
        return cls(
            empty_boxes(), np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=object) if with_ids else None
        )

    def subset(self, index: np.ndarray) -> BoxSet:
        """The boxes selected by a boolean mask or an index array."""
        return BoxSet(
            self.boxes[index],
            self.scores[index],
            self.labels[index],
            None if self.ids is None else self.ids[index],
            {k: v[index] for k, v in self.extra.items()},
        )


@dataclass
class Frame:
    """One keyframe: its sample token, time, ego pose, and optionally detections and ground truth.

    timestamp: int, microseconds. ego_translation: (3,) float64 metres, global frame.
    ego_rotation: (4,) float64 unit quaternion ``[w, x, y, z]`` (ego -> global).
    """

    token: str
    timestamp: int
    ego_translation: np.ndarray
    ego_rotation: np.ndarray
    detections: BoxSet | None = None
    gt: BoxSet | None = None


@dataclass
class Scene:
    """A sequence of frames in time order (nuScenes scene / AV2 log); box labels index ``vocabulary``."""

    name: str
    token: str
    frames: list[Frame]
    vocabulary: Vocabulary = NUSCENES_VOCABULARY

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def sample_tokens(self) -> list[str]:
        """The frame tokens in time order."""
        return [f.token for f in self.frames]
