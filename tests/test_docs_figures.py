"""A measured figure lives in one place, a dated file under docs/ with the command that produced it: the README,
ARCHITECTURE.md and the comments of the shipped configs link to it instead of copying it. This test looks in
those texts (outside code blocks; in YAML, the comments) for the marks of a measurement: a speed, a duration, a
memory size, a ratio, a metric value, a count of sets a candidate lost on."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: the marks of a measured figure
MEASURED = re.compile(
    r"\d\s*frames/s|\d\s*(minutes|min|hours)\b|\d\s*[GM]iB\b|\b\d+(\.\d+)?x\b"
    r"|\b(AMOTA|AMOTP|HOTA)\b[^.;|]{0,20}\b0\.\d{3,}|\blower on \d+|\bhigher on \d+"
)
#: configs whose comments quote published (not measured) figures, with their source
PUBLISHED = ("grutrack/configs/published/",)


def _texts() -> list[Path]:
    yamls = [*(REPO / "grutrack/configs").rglob("*.yaml"), *(REPO / "workflow").rglob("*.yaml")]
    return [REPO / "README.md", REPO / "ARCHITECTURE.md", *sorted(p for p in yamls if not _published(p))]


def _published(path: Path) -> bool:
    return any(str(path.relative_to(REPO)).startswith(p) for p in PUBLISHED)


def _prose(path: Path) -> list[tuple[int, str]]:
    """(line number, text) of the prose of a markdown file (code blocks left out) or the comments of a YAML file."""
    out, in_block = [], False
    for i, line in enumerate(path.read_text().splitlines(), 1):
        if path.suffix == ".md":
            if line.startswith("```"):
                in_block = not in_block
            elif not in_block:
                out.append((i, line))
        elif "#" in line:
            out.append((i, line[line.index("#") :]))
    return out


@pytest.mark.parametrize("path", _texts(), ids=lambda p: str(p.relative_to(REPO)))
def test_no_measured_figure_outside_docs(path):
    hits = [f"{i}: {m.group(0)!r} in {text.strip()[:100]}" for i, text in _prose(path) if (m := MEASURED.search(text))]
    assert not hits, (
        f"{path.relative_to(REPO)} holds measured figures (move them to docs/results/, link there):\n" + "\n".join(hits)
    )
