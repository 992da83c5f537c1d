"""GRU-KF checkpoints as networks: the network of a :class:`~grutrack.documents.Checkpoint` (the document, its one
writer and one reader, is in :mod:`grutrack.documents`), and the weights checked against the architecture."""

from __future__ import annotations

from pathlib import Path

import torch

from grutrack.documents import CHECKPOINT_FORMAT as FORMAT  # noqa: F401  (the format tag, re-exported)
from grutrack.documents import Checkpoint
from grutrack.errors import InputFormatError
from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig


def network_checkpoint(net: GRUKalmanNet, **fields) -> Checkpoint:
    """The checkpoint document of ``net`` (its architecture and a copy-free view of its weights) with ``fields``
    (:class:`~grutrack.documents.Checkpoint`'s other fields)."""
    return Checkpoint(arch=net.config_dict(), weights=net.state_dict(), **fields)


def save_checkpoint(path: str | Path, net: GRUKalmanNet, extra: dict | None = None) -> None:
    """Write ``net`` as a checkpoint to ``path`` atomically; ``extra``: more fields in the file's layout
    (``{"train_config": {...}}``), read through :meth:`Checkpoint.from_dict`."""
    doc = network_checkpoint(net)
    if extra:
        doc = Checkpoint.from_dict({**doc.to_dict(), **extra}, where=str(path))
    doc.write(path)


def read_checkpoint(path: str | Path, map_location="cpu") -> dict:
    """The checkpoint at ``path`` as the file's mapping (:meth:`Checkpoint.to_dict`; for tools that read single
    fields); a missing or foreign file is an InputFormatError naming it."""
    return Checkpoint.read(path, map_location).to_dict()


def load_network(source: str | Path | Checkpoint, map_location="cpu", where: str | Path | None = None) -> GRUKalmanNet:
    """The trained network of a checkpoint (a path, or a document already read: ``where`` names its file in
    errors), weights loaded once and never re-initialised afterwards, in eval mode."""
    ck = source if isinstance(source, Checkpoint) else Checkpoint.read(source, map_location)
    where = where or (source if not isinstance(source, Checkpoint) else "checkpoint")
    try:
        net = GRUKalmanNet(GRUKFConfig(**ck.arch), generator=torch.Generator())  # weights loaded below
    except (TypeError, ValueError, KeyError) as exc:
        raise InputFormatError(f"{where}: field 'arch' is not a GRU-KF architecture ({exc})") from exc
    load_weights(net, ck, where)
    net.eval()
    return net


def load_weights(net: GRUKalmanNet, ck: Checkpoint, path: str | Path) -> None:
    """Load the checkpoint's weights into ``net``; a missing, extra or mis-shaped tensor raises InputFormatError
    naming the file and the tensor."""
    state, own = ck.weights, net.state_dict()
    missing, extra = sorted(set(own) - set(state)), sorted(set(state) - set(own))
    if missing or extra:
        raise InputFormatError(
            f"{path}: field 'model' does not fit the architecture in 'arch' (missing tensors "
            f"{missing[:3]}, unexpected {extra[:3]})"
        )
    for k, v in state.items():
        if not isinstance(v, torch.Tensor) or tuple(v.shape) != tuple(own[k].shape):
            got = tuple(v.shape) if isinstance(v, torch.Tensor) else type(v).__name__
            raise InputFormatError(
                f"{path}: tensor 'model.{k}' has shape {got}, expected {tuple(own[k].shape)} "
                f"(the architecture in 'arch')"
            )
    net.load_state_dict(state)
