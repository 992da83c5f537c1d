"""Datasets behind one interface (:class:`~grutrack.datasets.base.Dataset`): the commands and the workflow
dispatch on the dataset here, once, and nowhere else.

Adding a dataset: a module in this package with a class implementing the protocol, its tests, and one line in
:data:`DATASETS` (see ARCHITECTURE.md, "Extension points").
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from grutrack.errors import ConfigError

if TYPE_CHECKING:
    from grutrack.datasets.base import Dataset, DatasetOptions

#: dataset name -> "module:class"; modules are imported only when their dataset is opened (so the command line
#: lists the names without importing numpy)
DATASETS: dict[str, str] = {
    "nuscenes": "grutrack.datasets.nuscenes:NuScenesDataset",
    "av2": "grutrack.datasets.av2:AV2Dataset",
}


def dataset_class(name: str) -> type:
    """The class of dataset ``name`` (its module imported now)."""
    if name not in DATASETS:
        raise ConfigError(f"--dataset: unknown dataset '{name}' (available: {', '.join(DATASETS)})")
    module, cls = DATASETS[name].split(":")
    return getattr(importlib.import_module(module), cls)


def config_kinds() -> dict[str, tuple[str, dict]]:
    """Every workflow config dataset kind -> (the dataset that reads it, the JSON schema of a ``datasets:`` entry
    of that kind), from the ``config_kinds`` of every class in :data:`DATASETS`."""
    kinds: dict[str, tuple[str, dict]] = {}
    for name in DATASETS:
        for kind, schema in dataset_class(name).config_kinds.items():
            if kind in kinds:
                raise RuntimeError(f"config kind '{kind}' is declared by datasets {kinds[kind][0]} and {name}")
            kinds[kind] = (name, schema)
    return kinds


def open_dataset(name: str, options: DatasetOptions) -> Dataset:
    """The dataset ``name`` at ``options.dataroot`` (nothing is read until a method needs it)."""
    return dataset_class(name)(options)


def __getattr__(name: str):
    """``Dataset`` and ``DatasetOptions`` from :mod:`grutrack.datasets.base`, imported on first use."""
    if name in ("Dataset", "DatasetOptions", "Detections"):
        from grutrack.datasets import base

        return getattr(base, name)
    raise AttributeError(f"module 'grutrack.datasets' has no attribute {name!r}")


__all__ = ["DATASETS", "Dataset", "DatasetOptions", "config_kinds", "dataset_class", "open_dataset"]
