"""Figures that others published for a tracker run on a detection file known by its SHA-256
(``grutrack/configs/published/*.yaml``), compared with a metrics JSON of one's own run on that file
(``grutrack check-published``).

A figure is kept as it was printed (a quoted string in the YAML: ``"72.85"``, ``"235"``). A figure without a
decimal point is compared exactly; one with ``d`` decimals is compared with the run's value, times the metric's
``scale``, printed at ``d`` decimals (``f"{value * scale:.{d}f}"``). When the detection file is the published one
(its SHA-256 equal), a figure that differs points at the code or its configuration, not at the file.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from grutrack.documents import MetricsDocument
from grutrack.errors import ConfigError, InputFormatError

PUBLISHED_DIR = Path(__file__).resolve().parents[1] / "configs" / "published"
_INTEGER = re.compile(r"^-?[0-9]+$")


@dataclass(frozen=True)
class Figure:
    """One published figure: its metric path in a metrics JSON (``overall.amota``, ``per_class.car.ids``), the
    figure as printed and the factor from the metrics JSON's unit to the printed one."""

    path: str
    printed: str
    scale: float = 1.0

    @property
    def decimals(self) -> int | None:
        """Decimals printed; None for an integer (compared exactly)."""
        return None if _INTEGER.match(self.printed) else len(self.printed.split(".")[1])

    def ours(self, value: float | None) -> str | None:
        """``value`` (from a metrics JSON) as this figure is printed; None when there is no value. An integer
        figure shows a value that is not a whole number in full, so that it cannot read as equal."""
        if value is None:
            return None
        v = value * self.scale
        if self.decimals is None:
            return str(int(v)) if float(v).is_integer() else repr(v)
        return f"{v:.{self.decimals}f}"

    def equal(self, value: float | None) -> bool:
        """Whether ``value`` gives this figure: exactly for an integer, at the printed precision otherwise."""
        if value is None:
            return False
        if self.decimals is None:
            return value * self.scale == int(self.printed)
        return self.ours(value) == self.printed


@dataclass(frozen=True)
class PublishedResult:
    """One published result: the detection file it was run on, who published it, the code, the figures."""

    publication: str
    name: str  # the row as the publication names it
    filename: str
    sha256: str
    registry: str | None
    dataset: str
    version: str | None
    split: str
    tracker: str  # the grutrack preset that reproduces the published code
    tracker_code: str
    evaluator: str
    repository: str
    commit: str
    path: str
    license: str
    note: str | None
    figures: tuple[Figure, ...]
    file: str  # the published-results YAML it was read from

    @property
    def url(self) -> str:
        """Where the figures are, at the commit they were read at."""
        return f"https://github.com/{self.repository}/blob/{self.commit}/{self.path}"

    def figure(self, path: str) -> Figure:
        """The figure at a metric path (KeyError when there is none)."""
        for f in self.figures:
            if f.path == path:
                return f
        raise KeyError(path)


@dataclass(frozen=True)
class FigureCheck:
    """One figure: published, ours as it would be printed, equal or not."""

    path: str
    published: str
    ours: str | None
    equal: bool


def published_files(where: str | Path | None = None) -> list[Path]:
    """The published-results YAML files: the shipped ones, or those of a file or folder given."""
    p = PUBLISHED_DIR if where is None else Path(where)
    if p.is_dir():
        return sorted(q for q in p.iterdir() if q.suffix in (".yaml", ".yml"))
    if not p.is_file():
        raise ConfigError(f"published results file {p} does not exist")
    return [p]


def load_published(where: str | Path | None = None, registry: str | Path | None = None) -> list[PublishedResult]:
    """Every published result of the shipped files (or of a file / folder ``where``), each file checked against
    ``grutrack/configs/schemas/published.schema.yaml`` and then against what a schema cannot state: a result that
    names a registry source must give that source's SHA-256, split and dataset; the tracker is a shipped preset;
    nuScenes per-class figures name tracking classes. Errors are :class:`ConfigError` naming the file and key."""
    from grutrack.config_loader import load_config, shipped_names
    from grutrack.data.registry import REGISTRY_PATH, load_registry

    sources = load_registry(registry or REGISTRY_PATH)
    presets = set(shipped_names("tracker"))
    out = []
    for path in published_files(where):
        raw, file = load_config("published", path)
        for i, r in enumerate(raw["results"]):
            out.append(_result(file, f"results[{i}]", raw, r, sources, presets))
    return out


def _result(file: str, key: str, raw: dict, r: dict, sources: dict, presets: set[str]) -> PublishedResult:
    from grutrack.classes import TRACKING_CLASSES

    det = r["detections"]
    if det["registry"] is not None:
        src = sources.get(det["registry"])
        if src is None:
            raise ConfigError(f"{file}: {key}.detections.registry: no source '{det['registry']}' in the registry")
        for field in ("sha256", "split", "dataset"):
            if getattr(src, field) != det[field]:
                raise ConfigError(
                    f"{file}: {key}.detections.{field} is {det[field]}, the registry's source "
                    f"'{src.name}' has {getattr(src, field)}"
                )
    if r["tracker"] not in presets:
        raise ConfigError(
            f"{file}: {key}.tracker '{r['tracker']}' is not a tracker preset (available: {', '.join(sorted(presets))})"
        )
    if det["dataset"] == "nuscenes":
        for cls in r["per_class"]:
            if cls not in TRACKING_CLASSES:
                raise ConfigError(
                    f"{file}: {key}.per_class.{cls} is not a nuScenes tracking class ({', '.join(TRACKING_CLASSES)})"
                )
    scale = r["scale"]
    figures = [Figure(f"overall.{m}", v, float(scale.get(m, 1))) for m, v in r["overall"].items()]
    for cls, metrics in r["per_class"].items():
        figures += [Figure(f"per_class.{cls}.{m}", v, float(scale.get(m, 1))) for m, v in metrics.items()]
    src = raw["source"]
    return PublishedResult(
        publication=raw["publication"],
        name=r["name"],
        filename=det["filename"],
        sha256=det["sha256"],
        registry=det["registry"],
        dataset=det["dataset"],
        version=det["version"],
        split=det["split"],
        tracker=r["tracker"],
        tracker_code=r["tracker_code"],
        evaluator=r["evaluator"],
        repository=src["repository"],
        commit=src["commit"],
        path=r["path"],
        license=src["license"],
        note=r["note"],
        figures=tuple(figures),
        file=file,
    )


def detection_sha256(path: str | Path) -> str:
    """SHA-256 of a detection file, read in chunks; a missing or unreadable file is an :class:`InputFormatError`
    naming it."""
    from grutrack.provenance import sha256_file

    p = Path(path)
    if not p.is_file():
        raise InputFormatError(f"{p}: detection file not found" + (" (it is a folder)" if p.is_dir() else ""))
    try:
        return sha256_file(p)
    except OSError as exc:
        raise InputFormatError(f"{p}: cannot read the detection file ({exc.strerror or exc})") from exc


def results_for(results: list[PublishedResult], sha256: str, tracker: str | None = None) -> list[PublishedResult]:
    """The published results on the file of that SHA-256 (empty: not a known file), of one tracker preset when
    given. A tracker the file has no result of is a :class:`ConfigError` naming ``--tracker``; with none given, a
    file with results of several trackers is one too (which to compare is not clear)."""
    on_file = [r for r in results if r.sha256 == sha256]
    if not on_file:
        return []
    trackers = sorted({r.tracker for r in on_file})
    if tracker is None:
        if len(trackers) > 1:
            raise ConfigError(
                f"--tracker: figures of several trackers are published on this file: {', '.join(trackers)}"
            )
        return on_file
    chosen = [r for r in on_file if r.tracker == tracker]
    if not chosen:
        raise ConfigError(
            f"--tracker {tracker}: no figures of that tracker are published on this file (published: "
            f"{', '.join(trackers)})"
        )
    return chosen


def setup_differences(result: PublishedResult, doc: MetricsDocument) -> list[str]:
    """What the metrics JSON says about its data that differs from the published run's (dataset, version,
    split); a field the document leaves empty is not a difference."""
    out = []
    for field, published in (("dataset", result.dataset), ("version", result.version), ("split", result.split)):
        ours = getattr(doc, field)
        if ours and published and ours != published:
            out.append(f"{field}: published {published}, the metrics JSON's {ours}")
    return out


def compare(result: PublishedResult, doc: MetricsDocument) -> list[FigureCheck]:
    """One check per published figure, in the published order."""
    return [
        FigureCheck(f.path, f.printed, f.ours(doc.value(f.path)), f.equal(doc.value(f.path))) for f in result.figures
    ]


def format_checks(checks: list[FigureCheck]) -> str:
    """A plain-text table: figure, published, ours, equal."""
    width = max([len("figure"), *(len(c.path) for c in checks)]) + 2
    head = f"{'figure':<{width}}{'published':>12}{'ours':>14}  equal"
    lines = [head, "-" * len(head)]
    for c in checks:
        ours = "missing" if c.ours is None else c.ours
        lines.append(f"{c.path:<{width}}{c.published:>12}{ours:>14}  {'yes' if c.equal else 'NO'}")
    return "\n".join(lines)
