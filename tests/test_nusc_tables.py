"""The devkit-free table reader against nuscenes-devkit on the real v1.0-mini: same records (reverse indexes
included), same split lists, same velocities, same tracking-class mapping."""

from __future__ import annotations

import numpy as np

from grutrack.data.nusc_tables import TABLE_NAMES, NuScenesTables, predefined_split_scenes
from grutrack.data.nuscenes import (
    DETECTION_NAME_OF_CATEGORY,
    DETECTION_VOCABULARY,
    TRACKING_NAME_OF_CATEGORY,
    category_to_tracking_name,
    load_scenes,
    open_nuscenes,
)


def test_tables_equal_the_devkits(nusc_root, nusc_mini):
    tables = NuScenesTables("v1.0-mini", nusc_root)
    for name in TABLE_NAMES:
        ref = getattr(nusc_mini, name)
        if name == "map":  # the devkit adds a MapMask image object; tables do not load map images
            ref = [{k: v for k, v in rec.items() if k != "mask"} for rec in ref]
        assert getattr(tables, name) == ref, name
    sample = nusc_mini.sample[5]
    assert tables.get("sample", sample["token"])["anns"] == sample["anns"] and len(sample["anns"]) > 0
    assert tables.getind("sample", sample["token"]) == 5
    assert tables.field2token("scene", "name", "scene-0103") == nusc_mini.field2token("scene", "name", "scene-0103")


def test_box_velocity_equals_the_devkits(nusc_root, nusc_mini):
    tables = NuScenesTables("v1.0-mini", nusc_root)
    tokens = [a["token"] for a in nusc_mini.sample_annotation[::37]]
    ours = np.array([tables.box_velocity(t) for t in tokens])
    ref = np.array([nusc_mini.box_velocity(t) for t in tokens])
    assert len(tokens) > 400 and np.isnan(ref).any()
    np.testing.assert_array_equal(ours, ref)


def test_split_lists_and_class_map_equal_the_devkits(nusc_mini):
    from nuscenes.eval.tracking.utils import category_to_tracking_name as devkit_map
    from nuscenes.utils.splits import create_splits_scenes

    ours, ref = predefined_split_scenes(), create_splits_scenes()
    assert ours == ref and len(ours["val"]) == 150 and len(ours["train"]) == 700
    names = [c["name"] for c in nusc_mini.category] + ["no.such.category"]
    assert [category_to_tracking_name(n) for n in names] == [devkit_map(n) for n in names]
    assert set(TRACKING_NAME_OF_CATEGORY.values()) == {
        "bicycle",
        "bus",
        "car",
        "motorcycle",
        "pedestrian",
        "trailer",
        "truck",
    }
    from nuscenes.eval.detection.utils import category_to_detection_name

    assert [DETECTION_NAME_OF_CATEGORY.get(n) for n in names] == [category_to_detection_name(n) for n in names]


def test_one_reader_gives_tracking_and_detection_ground_truth(nusc_root):
    """The 10-class ground truth (simulator, statistics) and the 7-class one (tracking) come from the same
    annotations: the tracking boxes are the detection boxes of the tracking classes, in the same order."""
    nusc = open_nuscenes(nusc_root, "v1.0-mini")
    det = load_scenes(nusc, "mini_val", with_gt=True, vocabulary=DETECTION_VOCABULARY)
    trk = load_scenes(nusc, "mini_val", with_gt=True)
    assert det[0].vocabulary == DETECTION_VOCABULARY and trk[0].vocabulary.names[2] == "car"
    n_det = n_trk = 0
    for sd, st in zip(det, trk):
        for fd, ft in zip(sd.frames, st.frames):
            names = np.asarray(DETECTION_VOCABULARY.names)[fd.gt.labels]
            keep = np.isin(names, st.vocabulary.names)
            np.testing.assert_array_equal(fd.gt.boxes[keep], ft.gt.boxes)
            assert list(names[keep]) == [st.vocabulary.names[i] for i in ft.gt.labels]
            np.testing.assert_array_equal(fd.gt.extra["num_pts"][keep], ft.gt.extra["num_pts"])
            n_det, n_trk = n_det + len(fd.gt), n_trk + len(ft.gt)
    assert n_det > n_trk > 3000  # barriers and cones are in the detection ground truth only


def test_scenes_from_tables_equal_scenes_from_the_devkit(nusc_root, nusc_mini):
    light = load_scenes(open_nuscenes(nusc_root, "v1.0-mini"), "mini_val", with_gt=True)
    ref = load_scenes(nusc_mini, "mini_val", with_gt=True)
    assert [s.name for s in light] == ["scene-0103", "scene-0916"]
    for a, b in zip(light, ref):
        assert [f.token for f in a.frames] == [f.token for f in b.frames]
        for fa, fb in zip(a.frames, b.frames):
            np.testing.assert_array_equal(fa.gt.boxes, fb.gt.boxes)
            np.testing.assert_array_equal(fa.gt.labels, fb.gt.labels)
            np.testing.assert_array_equal(fa.ego_translation, fb.ego_translation)


def test_table_progress_bar_counts_every_byte(nusc_root, capsys):
    NuScenesTables("v1.0-mini", nusc_root, progress=True)
    err = capsys.readouterr().err
    total = sum((nusc_root / "v1.0-mini" / f"{n}.json").stat().st_size for n in TABLE_NAMES)
    assert "reading v1.0-mini tables" in err and "100%" in err and total > 10**6
