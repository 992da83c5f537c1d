"""GRU-KF checkpoints: weights, architecture, optimizer, scheduler, RNG states and position, written atomically."""

from __future__ import annotations

from pathlib import Path

import torch

from grutrack import __version__
from grutrack.errors import InputFormatError
from grutrack.io import atomic_path
from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig

FORMAT = "grutrack-grukf/1"


def save_checkpoint(path: str | Path, net: GRUKalmanNet, extra: dict | None = None) -> None:
    """Write ``{format, version, arch, model, **extra}`` to ``path`` atomically."""
    payload = {"format": FORMAT, "grutrack_version": __version__, "arch": net.config_dict(),
               "model": net.state_dict(), **(extra or {})}
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)


def read_checkpoint(path: str | Path, map_location="cpu") -> dict:
    """The checkpoint dict; clear error for a missing or foreign file."""
    path = Path(path)
    if not path.is_file():
        raise InputFormatError(f"{path}: checkpoint does not exist (train one with `grutrack train`)")
    try:
        ck = torch.load(path, map_location=map_location, weights_only=False)
    except Exception as exc:  # torch raises many types for a corrupt file
        raise InputFormatError(f"{path}: not a readable torch checkpoint ({exc})") from exc
    if not isinstance(ck, dict) or ck.get("format") != FORMAT:
        raise InputFormatError(f"{path}: not a grutrack GRU-KF checkpoint (expected format {FORMAT})")
    return ck


def load_network(path: str | Path, map_location="cpu") -> GRUKalmanNet:
    """The trained network of a checkpoint (weights loaded once, never re-initialised afterwards)."""
    ck = read_checkpoint(path, map_location)
    try:
        net = GRUKalmanNet(GRUKFConfig(**ck["arch"]), generator=torch.Generator())  # weights loaded below
    except (TypeError, ValueError, KeyError) as exc:
        raise InputFormatError(f"{path}: field 'arch' is not a GRU-KF architecture ({exc})") from exc
    load_weights(net, ck, path)
    net.eval()
    return net


def load_weights(net: GRUKalmanNet, ck: dict, path: str | Path) -> None:
    """Load ``ck['model']`` into ``net``; a missing, extra or mis-shaped tensor raises InputFormatError naming
    the file and the tensor."""
    state = ck.get("model")
    if not isinstance(state, dict):
        raise InputFormatError(f"{path}: field 'model' must hold the network's tensors")
    own = net.state_dict()
    missing, extra = sorted(set(own) - set(state)), sorted(set(state) - set(own))
    if missing or extra:
        raise InputFormatError(f"{path}: field 'model' does not fit the architecture in 'arch' (missing tensors "
                               f"{missing[:3]}, unexpected {extra[:3]})")
    for k, v in state.items():
        if not isinstance(v, torch.Tensor) or tuple(v.shape) != tuple(own[k].shape):
            got = tuple(v.shape) if isinstance(v, torch.Tensor) else type(v).__name__
            raise InputFormatError(f"{path}: tensor 'model.{k}' has shape {got}, expected {tuple(own[k].shape)} "
                                   f"(the architecture in 'arch')")
    net.load_state_dict(state)


def checkpoint_matched_box(path: str | Path) -> str:
    """The box a tracker running this checkpoint's network writes for a matched track by default: the training
    config's ``matched_box`` ("filter" or "detection"); "detection" for checkpoints written before that key."""
    cfg = read_checkpoint(path).get("train_config") or {}
    return cfg.get("matched_box", "detection")
