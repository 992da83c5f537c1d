"""Detection resampling: fresh simulated detections of the training scenes every epoch.

A few real scenes give many distinct training sequences when every epoch draws new detections from their ground
truth with the detector simulator (:mod:`grutrack.data.detection_sim`): epoch 0 uses the detections the
training was given, epoch e >= 1 detections simulated with seed ``RESAMPLE_SEED_BASE * (seed + 1) + e``
(deterministic, so a resumed run sees the same detections) and, by ``resample_mix``:

- ``epoch``: profile ``profiles[(e - 1) % len(profiles)]`` for every scene (the profiles take turns by epoch; the
  last epochs' profile is what the network learns last);
- ``scene``: every profile in every epoch, scene i (its position in the training list) taking
  ``profiles[(e - 1 + i) % len(profiles)]``, so that every epoch mixes the detectors' error kinds and every scene
  meets every profile once in ``len(profiles)`` epochs.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from grutrack.data.scene import BoxSet, Scene
from grutrack.training.config import TrainConfig
from grutrack.training.trainer import Trainer

#: resampled detections of epoch e use seed RESAMPLE_SEED_BASE * (config seed + 1) + e (far from the small
#: seeds used for evaluation sets)
RESAMPLE_SEED_BASE = 100_000


def resample_seed(cfg_seed: int, epoch: int) -> int:
    """The simulator seed of the detections of ``epoch`` (>= 1) for a training config seed."""
    return RESAMPLE_SEED_BASE * (cfg_seed + 1) + epoch


def validation_seed(cfg_seed: int, draw: int) -> int:
    """The simulator seed of validation draw ``draw`` (>= 0) of a profile for a training config seed: draw 0
    ``resample_seed(cfg_seed, 0)`` (epoch 0 trains on the given detections, so training never draws it), the
    next ones counting down from it, below every epoch's seed of this config seed and above the last config
    seed's (``draw`` < RESAMPLE_SEED_BASE)."""
    if not 0 <= draw < RESAMPLE_SEED_BASE:
        raise ValueError(f"validation draw {draw}: expected 0 <= draw < {RESAMPLE_SEED_BASE}")
    return resample_seed(cfg_seed, 0) - draw


class DetectionResampler:
    """Simulated detections (canonical, by frame token) of the training scenes of any dataset: the dataset's
    own simulator writes them in its detection format and its own reader reads them back (one reader per
    format). ``dataset``: a :class:`grutrack.datasets.Dataset`; ``split``/``scenes``: the training split and
    its scenes; ``measured_yaw``: the tracker preset's yaw definition."""

    def __init__(self, dataset, split: str, scenes: list[Scene], measured_yaw: str = "euler_z"):
        self.dataset, self.split, self.scenes, self.measured_yaw = dataset, split, scenes, measured_yaw

    def __call__(self, profile: str, seed: int) -> dict[str, BoxSet]:
        """Detections drawn with detector ``profile`` (name or YAML path) and ``seed``."""
        from grutrack.data.detection_sim import load_profile

        prof = load_profile(profile)
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"resampled_{prof.name}_s{seed}{self.dataset.detections_suffix}"
            self.dataset.simulate_detections(self.split, prof, seed, path)
            return self.dataset.load_detections(path, self.split, self.scenes, self.measured_yaw).boxes


class ResamplingTrainer(Trainer):
    """:class:`Trainer` whose detections change every epoch (see the module docstring).

    ``resampler``: callable(profile, seed) -> detections by sample token for every training frame.
    The gain prior is computed on the given detections (epoch 0).
    """

    def __init__(
        self,
        cfg: TrainConfig,
        scenes: list[Scene],
        dets: dict[str, BoxSet],
        out_dir,
        resampler,
        validate=None,
        progress: bool = True,
        source: dict | None = None,
    ):
        super().__init__(cfg, scenes, dets, out_dir, validate=validate, progress=progress, source=source)
        self.resampler = resampler
        self.given = dets
        self._dets_epoch = 0

    def detections_for(self, epoch: int) -> dict[str, BoxSet]:
        """The detections of ``epoch`` by frame token: the given ones for epoch 0, fresh simulated ones afterwards
        (one profile for every scene, or one per scene; module docstring)."""
        profiles, seed = self.cfg.resample_profiles, resample_seed(self.cfg.seed, epoch)
        if epoch == 0 or not profiles:
            return self.given
        if self.cfg.resample_mix == "epoch" or len(profiles) == 1:
            return self.resampler(profiles[(epoch - 1) % len(profiles)], seed)
        out: dict[str, BoxSet] = {}
        n = len(profiles)
        for k, profile in enumerate(profiles):
            drawn = self.resampler(profile, seed)
            for i in range((k - epoch + 1) % n, len(self.scenes), n):  # the scenes with (e - 1 + i) % n == k
                out.update((t, drawn[t]) for t in self.scenes[i].sample_tokens if t in drawn)
        return out

    def _step(self, scenes: list[Scene]) -> None:
        if self.state.epoch != self._dets_epoch:
            self.dets = self.detections_for(self.state.epoch)
            self._dets_epoch = self.state.epoch
        super()._step(scenes)
