"""Figures as PNG (matplotlib, Agg backend), written atomically."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from grutrack.io import atomic_path  # noqa: E402


def _save(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return Path(path)


def grouped_bars(
    path: str | Path, categories: list[str], series: dict[str, list[float | None]], title: str, ylabel: str
) -> Path:
    """Bars per category, one colour per series (None bars are left out)."""
    fig, ax = plt.subplots(figsize=(max(5.0, 1.1 * len(categories) + 2), 3.6))
    width = 0.8 / max(1, len(series))
    for i, (label, values) in enumerate(series.items()):
        xs = [j + (i - (len(series) - 1) / 2) * width for j, v in enumerate(values) if v is not None]
        ax.bar(xs, [v for v in values if v is not None], width=width, label=label)
    ax.set_xticks(range(len(categories)))
    ax.set_xticklabels(categories, rotation=20, ha="right")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)  # beside, never on a bar
    return _save(fig, Path(path))


def _finish(ax, title: str, xlabel: str, ylabel: str, hlines: dict[str, float] | None, min_span: float | None) -> None:
    """Labelled horizontal reference lines, a y span of at least ``min_span`` (centred on the data), axis labels,
    title, grid and legend."""
    for label, y in (hlines or {}).items():
        ax.axhline(y, linestyle="--", linewidth=1, color="grey")
        ax.annotate(label, (ax.get_xlim()[0], y), fontsize=7, color="grey", va="bottom")
    if min_span:
        lo, hi = ax.get_ylim()
        if hi - lo < min_span:
            mid = (lo + hi) / 2
            ax.set_ylim(mid - min_span / 2, mid + min_span / 2)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def lines(
    path: str | Path,
    series: dict[str, tuple[list[float], list[float]]],
    title: str,
    xlabel: str,
    ylabel: str,
    hlines: dict[str, float] | None = None,
    min_span: float | None = None,
) -> Path:
    """Line plot of (x, y) series, with optional labelled horizontal reference lines; the y axis spans at
    least ``min_span`` (centred on the data), so that differences below it do not fill the plot."""
    fig, ax = plt.subplots(figsize=(6.0, 3.6))
    for label, (x, y) in series.items():
        ax.plot(x, y, marker="o", markersize=3, label=label)
    _finish(ax, title, xlabel, ylabel, hlines, min_span)
    return _save(fig, Path(path))


def bands(
    path: str | Path,
    groups: dict[str, tuple[list[float], list[float], list[float], list[float]]],
    title: str,
    xlabel: str,
    ylabel: str,
    min_span: float | None = None,
    hlines: dict[str, float] | None = None,
) -> Path:
    """Per group, the mean line over its runs and the band from their minimum to their maximum:
    ``groups[label] = (x, mean, low, high)``; optional labelled horizontal reference lines."""
    fig, ax = plt.subplots(figsize=(6.0, 3.6))
    for label, (x, mean, lo, hi) in groups.items():
        (line,) = ax.plot(x, mean, marker="o", markersize=3, label=label)
        ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.2, linewidth=0)
    _finish(ax, title, xlabel, ylabel, hlines, min_span)
    return _save(fig, Path(path))
