"""Class vocabularies: the 7 nuScenes tracking classes and the 10 detection classes that map onto them."""

from __future__ import annotations

TRACKING_CLASSES: tuple[str, ...] = ("bicycle", "bus", "car", "motorcycle", "pedestrian", "trailer", "truck")
CLASS_INDEX: dict[str, int] = {name: i for i, name in enumerate(TRACKING_CLASSES)}

#: nuScenes detection classes (detection_cvpr_2019); the three not tracked map to None.
DETECTION_CLASSES: tuple[str, ...] = (
    "car",
    "truck",
    "bus",
    "trailer",
    "construction_vehicle",
    "pedestrian",
    "motorcycle",
    "bicycle",
    "traffic_cone",
    "barrier",
)
DETECTION_TO_TRACKING: dict[str, str | None] = {
    "car": "car",
    "truck": "truck",
    "bus": "bus",
    "trailer": "trailer",
    "pedestrian": "pedestrian",
    "motorcycle": "motorcycle",
    "bicycle": "bicycle",
    "construction_vehicle": None,
    "traffic_cone": None,
    "barrier": None,
}
