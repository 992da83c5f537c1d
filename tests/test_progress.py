"""Progress of the devkit evaluation: the bar follows the devkit's own stage messages to the end."""

from __future__ import annotations

import contextlib
import io

from grutrack.evaluation.nuscenes_eval import _DevkitProgress


def test_devkit_progress_follows_the_devkit_messages(capsys):
    classes = ["bicycle", "bus", "car", "motorcycle", "pedestrian", "trailer", "truck"]
    devkit_stdout = (
        "======\nLoading NuScenes tables for version v1.0-mini...\n23 category,\nDone loading in 0.3 s.\n"
        "Initializing nuScenes tracking evaluation\nLoaded results from x.json. Found detections for 81 "
        "samples.\nLoading annotations for mini_val split from nuScenes version: v1.0-mini\n"
        "Filtering tracks\n=> Original number of boxes: 6379\nFiltering ground truth tracks\n"
        "Accumulating metric data...\n"
        + "".join(f"Computing metrics for class {c}...\n\nComputed thresholds\n" for c in classes)
    )
    with _DevkitProgress(len(classes), enabled=True) as bar:
        with contextlib.redirect_stdout(bar.sink):
            for i in range(0, len(devkit_stdout), 7):  # arbitrary chunks: lines are reassembled
                print(devkit_stdout[i : i + 7], end="")
        assert bar.bar.n == bar.bar.total == 12
    err = capsys.readouterr().err
    assert "devkit evaluation" in err and "12/12" in err and "truck" in err


def test_disabled_progress_swallows_the_messages(capsys):
    with _DevkitProgress(7, enabled=False) as bar, contextlib.redirect_stdout(bar.sink):
        print("Computing metrics for class car...")
    assert bar.bar is None and capsys.readouterr() == ("", "")
    assert isinstance(bar.sink, io.TextIOBase)
