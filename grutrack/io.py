"""Atomic file writing: a crash never leaves a half-written output that a workflow could take as done."""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it is renamed onto ``path``, on error removed."""
    path = Path(path)
    _check_output(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions of a new file
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def _check_output(path: Path) -> None:
    """Create the folder of an output file; an output that is a folder, or a folder that cannot be created
    or written, raises :class:`OutputPathError` naming the path."""
    from grutrack.errors import OutputPathError

    if path.is_dir():
        raise OutputPathError(f"{path}: output is a folder; expected a file path (e.g. {path / 'out'}.<ext>)")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError) as exc:
        blocker = next((q for q in [path.parent, *path.parent.parents] if q.exists() and not q.is_dir()), None)
        raise OutputPathError(
            f"{path}: cannot create its folder: {blocker or exc.filename} is a file, not a folder"
        ) from exc
    except PermissionError as exc:
        raise OutputPathError(f"{path}: cannot create its folder ({exc.strerror}: {exc.filename})") from exc
    if not os.access(path.parent, os.W_OK | os.X_OK):
        raise OutputPathError(f"{path}: the folder {path.parent} is not writable")


def read_json(path: str | os.PathLike, what: str = "JSON file"):
    """Parse a JSON file; a missing file or invalid JSON raises InputFormatError naming the file."""
    path, text = _read_text(path, what, "JSON")
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        from grutrack.errors import InputFormatError

        raise InputFormatError(f"{path}: not valid JSON ({exc})") from exc
    except RecursionError as exc:
        from grutrack.errors import InputFormatError

        raise InputFormatError(
            f"{path}: not a JSON document grutrack reads (lists or objects nested too deeply)"
        ) from exc


def parse_yaml(text: str):
    """``yaml.safe_load(text)`` with libyaml's C parser where PyYAML has it (ten times faster; same result)."""
    import yaml

    return yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))


def read_yaml(path: str | os.PathLike, what: str = "YAML file"):
    """Parse a YAML file; a missing file or invalid YAML raises InputFormatError naming the file."""
    import yaml

    path, text = _read_text(path, what, "YAML")
    try:
        return parse_yaml(text)
    except yaml.YAMLError as exc:
        from grutrack.errors import InputFormatError

        raise InputFormatError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from exc


def _read_text(path: str | os.PathLike, what: str, fmt: str) -> tuple[Path, str]:
    """(path, its UTF-8 text); a missing or binary file raises InputFormatError naming it."""
    from grutrack.errors import InputFormatError

    path = Path(path)
    if path.is_dir():
        raise InputFormatError(f"{path}: {what} is a folder; expected a {fmt} file")
    if not path.is_file():
        raise InputFormatError(f"{path}: {what} does not exist")
    try:
        return path, path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise InputFormatError(
            f"{path}: {what} must be {fmt} text, but this file is binary (not UTF-8 at byte "
            f"{exc.start}; a feather or pickle file?)"
        ) from exc
    except OSError as exc:
        raise InputFormatError(f"{path}: {what} cannot be read ({exc.strerror or exc})") from exc


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_json_atomic(path: str | os.PathLike, obj: Any, indent: int | None = None, compact: bool = False) -> None:
    """Write ``obj`` as JSON to ``path`` atomically (temp file in the same folder, then rename).

    The text is encoded in one call (``json.dumps``: the C encoder, one write) rather than streamed by
    ``json.dump`` in thousands of small writes; ``compact``: no spaces after separators (large submissions).
    """
    text = json.dumps(obj, indent=indent, separators=(",", ":") if compact and indent is None else None)
    with atomic_path(path) as tmp:
        with open(tmp, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text)
