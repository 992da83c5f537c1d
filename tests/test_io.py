"""Atomic writes: the target appears complete or not at all, with ordinary file permissions."""

from __future__ import annotations

import os
import stat

import pytest

from grutrack.io import atomic_path, write_json_atomic


def test_atomic_write_leaves_nothing_on_error(tmp_path):
    target = tmp_path / "out" / "x.json"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash mid-write")
    assert not target.exists() and list(target.parent.iterdir()) == []


def test_atomic_write_content_and_mode(tmp_path):
    target = tmp_path / "x.json"
    write_json_atomic(target, {"a": 1})
    assert target.read_text() == '{"a": 1}'
    mode = stat.S_IMODE(os.stat(target).st_mode)
    umask = os.umask(0)
    os.umask(umask)
    assert mode == 0o666 & ~umask
