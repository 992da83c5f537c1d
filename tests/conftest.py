"""Shared pytest fixtures: where the real data fragments live (../shared/data by default).

Tests that need them use the ``test_data`` fixture (or the narrower ones below). Outside CI a missing
fragment skips the test; with ``CI=true`` it fails, so CI can never pass while silently skipping them.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def pytest_configure(config):
    """Every test process (each pytest-xdist worker too) runs under the toolkit's thread policy, as the commands do:
    a test that calls the tracker or the trainer directly must not start torch's one-thread-per-core pool, which
    beside the other worker oversubscribes the cores (a GRU-KF training test then takes 20 times as long)."""
    from grutrack.threads import apply_thread_policy

    apply_thread_policy()


def _data_root() -> Path:
    return Path(os.environ.get("GRUTRACK_TEST_DATA", REPO_ROOT.parent / "shared" / "data")).resolve()


def _require(path: Path) -> Path:
    if not path.exists():
        msg = (
            f"real test data missing: {path} (set GRUTRACK_TEST_DATA to the folder holding "
            f"nuscenes/ and av2/; see ../shared/data/README.md)"
        )
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(msg)
        pytest.skip(msg)
    return path


@pytest.fixture(scope="session")
def test_data() -> Path:
    """Root of the real data fragments (``nuscenes/`` and ``av2/``)."""
    return _require(_data_root())


@pytest.fixture(scope="session")
def nusc_root() -> Path:
    """The devkit-loadable v1.0-mini dataroot."""
    return _require(_data_root() / "nuscenes" / "v1.0-mini").parent


@pytest.fixture(scope="session")
def pointpillars_mini_val() -> Path:
    """Real PointPillars detections on the 81 mini_val samples (official detection JSON)."""
    return _require(_data_root() / "nuscenes" / "detections" / "pointpillars_mini_val.json")


@pytest.fixture(scope="session")
def nusc_reference() -> Path:
    """Poly-MOT's and Fast-Poly's own outputs and their detection inputs (nuscenes/reference, see its README)."""
    return _require(_data_root() / "nuscenes" / "reference" / "MD5SUMS").parent


@pytest.fixture(scope="session")
def av2_root() -> Path:
    """AV2 sensor root holding ``val/<log_id>/``."""
    return _require(_data_root() / "av2" / "sensor")


@pytest.fixture(scope="session")
def nusc_mini():
    """A loaded ``NuScenes('v1.0-mini')`` (shared across tests; loading takes a few seconds)."""
    root = _require(_data_root() / "nuscenes" / "v1.0-mini").parent
    from nuscenes import NuScenes

    return NuScenes(version="v1.0-mini", dataroot=str(root), verbose=False)


@pytest.fixture(scope="session")
def ekf_coasting_keep(tmp_path_factory) -> Path:
    """The ekf preset with every class coasting as its motion model predicts (``motion.coast_yaw_rate`` and
    ``motion.coast_acceleration`` keep, Poly-MOT's, the preset before 2026-11-28): the preset an untrained network
    (training config's coasting keep) writes the boxes of, and one whose tracks stay put as the default's coasting
    changes."""
    import yaml

    from grutrack.classes import TRACKING_CLASSES
    from grutrack.tracking.config import PRESET_DIR

    preset = yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())
    for key in ("coast_yaw_rate", "coast_acceleration"):
        preset["motion"][key] = dict.fromkeys(TRACKING_CLASSES, "keep")
    path = tmp_path_factory.mktemp("presets") / "ekf_coasting_keep.yaml"
    path.write_text(yaml.safe_dump(preset))
    return path


#: fixtures that run a workflow target for real: every test that uses one is in the slow tier
SLOW_FIXTURES = frozenset({"demo_run", "mini_run"})


def pytest_collection_modifyitems(config, items):
    """Tier the suite: a test is slow (``-m "not slow"`` leaves it out) when it is marked so or uses a fixture of
    :data:`SLOW_FIXTURES`."""
    for item in items:
        if SLOW_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)
