"""Datasets behind one interface (:class:`~grutrack.datasets.base.Dataset`): the commands and the workflow
dispatch on the dataset here, once, and nowhere else.

Adding a dataset: a module in this package with a class implementing the protocol, its tests, and one line in
:data:`DATASETS` (see ARCHITECTURE.md, "Extension points").
"""

from __future__ import annotations

import importlib

from grutrack.datasets.base import Dataset, DatasetOptions
from grutrack.errors import ConfigError

#: dataset name -> "module:class"; modules are imported only when their dataset is opened
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


def open_dataset(name: str, options: DatasetOptions) -> Dataset:
    """The dataset ``name`` at ``options.dataroot`` (nothing is read until a method needs it)."""
    return dataset_class(name)(options)


__all__ = ["DATASETS", "Dataset", "DatasetOptions", "dataset_class", "open_dataset"]
