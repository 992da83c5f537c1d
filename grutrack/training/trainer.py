"""The training loop of the GRU-Kalman filter (ARCHITECTURE.md, "The method"): one AdamW step per scene (or per
``scenes_per_step`` scenes) on the scene loss (:mod:`grutrack.training.loss`), from the gain prior
(:mod:`grutrack.training.gain_prior`), cosine annealing over all steps; validation every ``val_every`` steps (a
:class:`~grutrack.training.validation.Validator`) with the ``select_checkpoint`` rule; resumable checkpoints
(:class:`~grutrack.documents.Checkpoint`), Ctrl-C and divergence handled after a completed step.
"""

from __future__ import annotations

import copy
import hashlib
import math
import signal
import sys
import threading
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from grutrack.data.scene import NUSCENES_VOCABULARY, BoxSet, Scene
from grutrack.documents import (
    Checkpoint,
    CheckpointSelection,
    TrainingLog,
    TrainingPosition,
    TrainingState,
    TrainingStep,
    ValidationRecord,
)
from grutrack.errors import ConfigError, GrutrackError
from grutrack.motion.checkpoint import load_weights, network_checkpoint
from grutrack.motion.grukf import GRUKalmanNet
from grutrack.tracking.config import TrackerConfig, load_tracker_config
from grutrack.tracking.factory import param_index, remap_config
from grutrack.tracking.grukf_backend import resolve_device
from grutrack.training.config import TrainConfig, config_record
from grutrack.training.gain_prior import init_gain_prior
from grutrack.training.loss import SceneLoss, run_scene, run_scenes
from grutrack.training.network import network_config
from grutrack.training.selection import next_selection
from grutrack.training.validation import Validator

#: a gain entry beyond this (a correction of 1000x the innovation) means the learned filter has diverged
MAX_ABS_GAIN = 1e3

#: between periodic checkpoints, train_log.csv is rewritten after the first step and then at most this often (s)
LOG_EVERY_S = 30.0

#: training-config keys a resumed run may change: they touch neither the weights, the scene order nor the schedule
RESUME_MAY_CHANGE = ("device", "val_every", "checkpoint_every")


class TrainingDiverged(GrutrackError):
    """The loss, a gradient or the learned gain became non-finite or exploded."""


class TrainingInterrupted(Exception):
    """Ctrl-C (SIGINT) stopped training after a completed step (step 0: after the validation before the first
    step); ``path`` is the resumable checkpoint."""

    def __init__(self, path: Path, step: int):
        after = f"step {step}" if step else "the validation before the first step"
        super().__init__(f"interrupted after {after}; resumable checkpoint {path} (continue with --resume)")
        self.path, self.step = path, step


def data_fingerprint(scenes: list[Scene], dets: dict[str, BoxSet]) -> str:
    """SHA-256 (hex) over the training scenes (names, frame tokens, timestamps, ground truth) and the
    detections of their frames: a resumed run must train on the same data."""
    h = hashlib.sha256()
    for s in scenes:
        h.update(f"{s.name}|{s.token}|{len(s.frames)}".encode())
        for f in s.frames:
            h.update(f"{f.token}|{f.timestamp}".encode())
            for bs in (f.gt, dets.get(f.token)):
                if bs is None:
                    h.update(b"-")
                    continue
                h.update(np.ascontiguousarray(bs.boxes, dtype=np.float64).tobytes())
                h.update(np.ascontiguousarray(bs.scores, dtype=np.float64).tobytes())
                h.update(np.ascontiguousarray(bs.labels, dtype=np.int64).tobytes())
                if bs.ids is not None:
                    h.update("|".join(map(str, bs.ids)).encode())
    return h.hexdigest()


def _plain(v):
    """Config values compared across a checkpoint round trip (tuples come back as lists)."""
    return list(v) if isinstance(v, tuple) else v


def _flat(cfg: dict) -> dict:
    """A training config's record with its network options as ``network.<option>`` keys (compared one by one)."""
    return {
        **{k: v for k, v in cfg.items() if k != "network"},
        **{f"network.{k}": v for k, v in cfg.get("network", {}).items()},
    }


def _rng_state(np_rng: np.random.Generator, torch_rng: torch.Generator) -> dict:
    """The states of a run's own generators (for its checkpoints)."""
    return {"numpy": np_rng.bit_generator.state, "torch": torch_rng.get_state()}


def _set_rng_state(np_rng: np.random.Generator, torch_rng: torch.Generator, st: dict) -> None:
    """Restore :func:`_rng_state` (a checkpoint's ``python`` entry, written by older versions, is not used)."""
    np_rng.bit_generator.state = st["numpy"]
    torch_rng.set_state(st["torch"])


class Trainer:
    """Runs :func:`run_scene` over the training scenes, one optimizer step per scene (per ``scenes_per_step``
    scenes: their losses averaged, the network batched over them, :func:`run_scenes`), with logging, validation
    every ``val_every`` steps and resumable checkpoints in ``out_dir``."""

    def __init__(
        self,
        cfg: TrainConfig,
        scenes: list[Scene],
        dets: dict[str, BoxSet],
        out_dir: str | Path,
        validate: Validator | None = None,
        progress: bool = True,
        source: dict | None = None,
    ):
        self.cfg, self.scenes, self.dets = cfg, scenes, dets
        self.source = dict(source or {})  # where the data came from (dataroot, split, detections), for messages
        self.fingerprint = data_fingerprint(scenes, dets)
        self._interrupted = False
        self._phase = ""  # what a first Ctrl-C lets finish (said by the SIGINT handler)
        self._log_written = time.monotonic()
        self.out = Path(out_dir)
        self.validate = validate  # a validation.Validator, or None (no validation)
        # select_checkpoint: (the validated step of highest AMOTA so far, the step best.pt holds)
        self._best: TrainingStep | None = None
        self._chosen: TrainingStep | None = None
        self._best_due = False  # the network just validated was chosen: best.pt is written after last.pt
        self.progress = progress
        self.device = resolve_device(cfg.device, "training config 'device'")
        vocab = scenes[0].vocabulary if scenes else NUSCENES_VOCABULARY
        self._preset = load_tracker_config(cfg.tracker_preset)
        self._setups: dict = {}  # vocabulary -> (label index, remapped preset)
        # the first scene's vocabulary (the command's own split): the gain prior uses it
        self.index, self.tracker_cfg = self._setup(vocab)
        # the run's own generators (no process-wide seeding): torch's for the initial weights, numpy's for the
        # scene order of every epoch
        self.torch_rng = torch.Generator().manual_seed(cfg.seed)
        self.np_rng = np.random.default_rng(cfg.seed)
        self.net = GRUKalmanNet(network_config(cfg), generator=self.torch_rng)
        first = [sc for sc in scenes if sc.vocabulary == vocab]
        init_gain_prior(self.net, cfg, first, dets, self.tracker_cfg, self.index, generator=self.torch_rng)
        self.net.to(self.device)
        # foreach: the update of all parameters in a few multi-tensor operators (same AdamW, one Python loop less)
        self.opt = torch.optim.AdamW(self.net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay, foreach=True)
        self.total_steps = cfg.epochs * -(-len(scenes) // cfg.scenes_per_step)  # ceil: a short last step
        # eta_t = eta_min + (eta_0 - eta_min) (1 + cos(pi t / T)) / 2 (Loshchilov & Hutter 2017, without restarts)
        self.sched = torch.optim.lr_scheduler.CosineAnnealingLR(
            self.opt, T_max=max(self.total_steps, 1), eta_min=min(cfg.lr_min, cfg.lr)
        )
        self.state = TrainingPosition()  # where the run stands (saved so that a resumed run continues exactly)
        self.log = TrainingLog()

    def _setup(self, vocab) -> tuple[np.ndarray, TrackerConfig]:
        """The label index (n_labels,) (dataset label -> tracking class of its parameters) and the tracker
        preset re-indexed by label, of one vocabulary (sources of several datasets mix vocabularies)."""
        if vocab not in self._setups:
            index = param_index(vocab.param_classes)
            self._setups[vocab] = (index, remap_config(self._preset, index))
        return self._setups[vocab]

    # -- checkpoints ------------------------------------------------------------------------------------
    def save(
        self, name: str = "last.pt", net: GRUKalmanNet | None = None, selected: CheckpointSelection | None = None
    ) -> Path:
        """Write a resumable checkpoint (and the CSV log) into the output folder (``net``: other weights than
        the training network's, e.g. the selected step's for model.pt; ``selected``: which step they are)."""
        path = self.out / name
        state = TrainingState(
            self.state,
            self.opt.state_dict(),
            self.sched.state_dict(),
            _rng_state(self.np_rng, self.torch_rng),
            self.log.steps,
        )
        network_checkpoint(
            self.net if net is None else net,
            train_config=asdict(self.cfg),
            training=state,
            selected=selected,
            data_fingerprint=self.fingerprint,
            data_source=self.source,
        ).write(path)
        self._write_log()
        return path

    def resume(self, path: str | Path) -> None:
        """Continue exactly from a checkpoint written by :meth:`save`; a checkpoint of other data or of other
        settings (anything but :data:`RESUME_MAY_CHANGE`) raises :class:`ConfigError`."""
        ck = Checkpoint.read(path, map_location=self.device)
        state = self._check_resumable(path, ck)
        load_weights(self.net, ck, path)
        self.opt.load_state_dict(state.optimizer)
        self.sched.load_state_dict(state.scheduler)
        _set_rng_state(self.np_rng, self.torch_rng, state.rng)
        self.state = state.position
        self.log = TrainingLog(state.log)
        self._best, self._chosen = self._resumed_selection()
        c = self._chosen
        if c is not None and c.step == self.state.step and self._best_pt_step() != c.step:
            self._write_best()  # stopped between last.pt and best.pt of a chosen step: the network is at hand

    def _resumed_selection(self) -> tuple[TrainingStep | None, TrainingStep | None]:
        """(best, chosen) of the resumed log replayed through :func:`next_selection`: the state the run had when it
        wrote the checkpoint. best.pt holds the chosen step (it is written after last.pt, never ahead of it),
        or the resumed step itself is the chosen one (stopped between the two writes; :meth:`resume` writes
        best.pt), or best.pt is from beyond the resumed step (a checkpoint of an older version, which wrote
        best.pt first), which the resumed run rewrites when it chooses that step again."""
        if self.cfg.select_checkpoint == "last":
            return None, None
        best = chosen = None
        for row in self.log.validated():
            best, chosen = next_selection(self.cfg.select_checkpoint, best, chosen, row)
        return best, chosen

    def _best_pt_step(self) -> int | None:
        """The step best.pt holds (None: no best.pt)."""
        path = self.out / "best.pt"
        held = Checkpoint.read(path).selected if path.is_file() else None
        return None if held is None else held.step

    def _check_resumable(self, path: str | Path, ck: Checkpoint) -> TrainingState:
        """``ck``'s training state; refused unless it was written by a run of the same data and settings."""
        state = ck.require_resumable(str(path))
        # a key the run's version did not have yet reads as its default (the behaviour that version had)
        old, new = _flat(config_record(ck.train_config)), _flat(asdict(self.cfg))
        changed = [k for k in new if k not in RESUME_MAY_CHANGE and _plain(old.get(k)) != _plain(new[k])]
        if changed:
            diff = ", ".join(f"{k} {old.get(k)!r} -> {new[k]!r}" for k in changed)
            raise ConfigError(
                f"{path}: cannot resume with other training settings ({diff}); use the settings "
                f"of that run or another --out"
            )
        if ck.data_fingerprint != self.fingerprint:
            was = ck.data_source or {}
            diff = ", ".join(
                f"{k} {was.get(k)!r} -> {self.source.get(k)!r}"
                for k in sorted(set(was) | set(self.source))
                if was.get(k) != self.source.get(k)
            )
            raise ConfigError(
                f"{path}: cannot resume on other training data (the scenes, ground truth or "
                f"detections differ{': ' + diff if diff else ''}); use the data of that run or "
                f"another --out"
            )
        return state

    def _write_log(self) -> None:
        self._log_written = time.monotonic()
        self.log.write(self.out / "train_log.csv")

    # -- the loop --------------------------------------------------------------------------------------
    def run(self, max_steps: int | None = None) -> Path:
        """Train until all epochs are done (or ``max_steps`` more steps); returns the final checkpoint."""
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):  # tiny batched solves: threads only add stalls
            return self._run(max_steps)

    def _run(self, max_steps: int | None) -> Path:
        """The start-up validation, the steps, the last step's validation, last.pt and the final outputs, all under
        :meth:`_sigint_deferred`: a first Ctrl-C lets the work under way finish (the start-up validation, a step
        with its validation), saves last.pt and stops with :class:`TrainingInterrupted`; once the last step is
        saved, it lets model.pt and validation.json be written and the run ends as usual."""
        self.out.mkdir(parents=True, exist_ok=True)
        with self._sigint_deferred():
            if self.state.step == 0 and not self.log.steps:
                self._clear_validated()
            if self.validate is not None and self.state.step == 0 and not self.log.steps:
                self._phase = "finishing the validation before the first step, then saving last.pt"
                self._validate_start()
                self._stop_if_interrupted(self._save_validated())
            self._phase = "finishing the current step, then saving last.pt"
            self._steps(max_steps)
            if self.state.epoch < self.cfg.epochs:
                return self.save()  # max_steps taken
            if self.validate is not None and self.log.steps and self.log.steps[-1].val_amota is None:
                self._validate_into(self.log.steps[-1])  # the last step's validation
                path = self._save_validated()
            else:
                path = self.save()
            self._stop_if_interrupted(path)
            self._phase = "the last step is saved; finishing model.pt and validation.json"
            return self._write_model()

    def _steps(self, max_steps: int | None) -> None:
        """The steps until all epochs are done (or ``max_steps`` of them): last.pt after each validated step, every
        ``checkpoint_every`` steps and at a Ctrl-C."""
        from tqdm import tqdm

        done = 0
        bar = tqdm(
            total=self.total_steps,
            initial=self.state.step,
            unit="step",
            desc="training GRU-KF",
            disable=not self.progress,
        )
        try:
            while self.state.epoch < self.cfg.epochs and (max_steps is None or done < max_steps):
                if self.state.order is None:
                    self.state.order = [int(i) for i in self.np_rng.permutation(len(self.scenes))]
                batch = self.state.order[self.state.index : self.state.index + self.cfg.scenes_per_step]
                self._step([self.scenes[i] for i in batch])
                self._advance(len(batch))
                done += 1
                bar.update(1)
                saved = self._save_validated() if self.log.steps[-1].val_amota is not None else None
                self._stop_if_interrupted(saved)
                if saved is None and self.cfg.checkpoint_every and self.state.step % self.cfg.checkpoint_every == 0:
                    self.save()
        finally:
            bar.close()

    def _stop_if_interrupted(self, saved: Path | None) -> None:
        """After a Ctrl-C: last.pt at the step just completed (``saved``: already written), then
        :class:`TrainingInterrupted`."""
        if self._interrupted:
            raise TrainingInterrupted(saved or self.save(), self.state.step)

    def _save_validated(self) -> Path:
        """After a validation: last.pt at the validated step, then best.pt when the rule chose its network. In this
        order best.pt never holds a step beyond last.pt's, so that a resumed run, which replays its log's
        validations, finds the network it selects in best.pt (or, stopped between the two writes, at hand). The
        validated network is also kept as ``validated/step_<step>.pt`` (:meth:`_write_validated`)."""
        path = self.save()
        self._write_validated()
        if self._best_due:
            self._write_best()
        return path

    def _clear_validated(self) -> None:
        """A run starting from its first step removes the ``validated/step_<step>.pt`` an earlier run left in its
        folder, so that every network there is this run's (a resumed run keeps its own)."""
        for path in (self.out / "validated").glob("step_*.pt"):
            path.unlink()

    def _write_validated(self) -> None:
        """``validated/step_<step>.pt``: the network just validated (a network checkpoint, about 1.7 MB, as
        best.pt), so that every point of the learning curve can be tracked and scored on other data after the run
        (``grutrack track --checkpoint``; docs/results/grukf_eval/README.md#validation-draws)."""
        row = self.log.steps[-1]
        folder = self.out / "validated"
        folder.mkdir(exist_ok=True)
        network_checkpoint(
            self.net, train_config=asdict(self.cfg), selected=CheckpointSelection(row.step, row.val_amota)
        ).write(folder / f"step_{row.step}.pt")

    # -- validation and the selected checkpoint --------------------------------------------------------------
    def _validate_start(self) -> None:
        """Validate the network before any step: row 0 of the log (loss NaN), a candidate for model.pt."""
        self.net.eval()
        row = TrainingStep(step=0, epoch=0, scene="(before training)", loss=math.nan, seconds=0.0)
        self._validate_into(row)
        self.log.steps.append(row)

    def _validate_into(self, row: TrainingStep) -> None:
        """Validate the current network into ``row`` (``val_amota``: the mean of the validator's score per detection
        set, ``val_amota_sets``: those scores), then consider it for model.pt."""
        per_set = np.asarray(self.validate.scores(self.net), dtype=np.float64)
        row.val_amota = round(float(per_set.mean()), 6)
        row.val_amota_sets = tuple(round(float(x), 6) for x in per_set)
        self._consider(row)

    def _consider(self, row: TrainingStep) -> None:
        """With a ``select_checkpoint`` rule other than "last": keep the network just validated as best.pt when
        the rule chooses it (:func:`next_selection`)."""
        if self.cfg.select_checkpoint == "last" or row.val_amota is None:
            return
        self._best, chosen = next_selection(self.cfg.select_checkpoint, self._best, self._chosen, row)
        if chosen is row:
            self._chosen, self._best_due = row, True  # best.pt is written after last.pt (_save_validated)

    def _write_best(self) -> None:
        """best.pt: the training network, the chosen step's (the candidate for model.pt)."""
        c = self._chosen
        network_checkpoint(
            self.net, train_config=asdict(self.cfg), selected=CheckpointSelection(c.step, c.val_amota)
        ).write(self.out / "best.pt")
        self._best_due = False

    def _write_model(self) -> Path:
        """model.pt (the selected step's network with the final run's records) and validation.json."""
        v = self.validate
        record = v.describe() if v is not None else ValidationRecord(rule="last", selected_step=0)
        record.rule, record.selected_step = "last", self.state.step
        val = self.log.validated()
        if val:
            last = val[-1] if val[-1].step == self.state.step else None
            record.selected_amota = None if last is None else last.val_amota
            record.selected_amota_sets = (
                None if last is None or last.val_amota_sets is None else list(last.val_amota_sets)
            )
            if v is not None:
                per_set = np.asarray(v.reference_scores(), dtype=np.float64)
                record.reference_amota_sets = [round(float(x), 6) for x in per_set]
                record.reference_amota = round(float(np.mean(per_set)), 6)
        net = None
        if self._chosen is not None:
            c = self._chosen
            net = copy.deepcopy(self.net)
            load_weights(net, Checkpoint.read(self.out / "best.pt", map_location=self.device), self.out / "best.pt")
            record.rule, record.selected_step, record.selected_amota = self.cfg.select_checkpoint, c.step, c.val_amota
            record.selected_amota_sets = None if c.val_amota_sets is None else list(c.val_amota_sets)
        path = self.save(
            "model.pt", net, CheckpointSelection(record.selected_step, record.selected_amota, rule=record.rule)
        )
        record.write(self.out / "validation.json")
        return path

    def _advance(self, n: int = 1) -> None:
        """Move the position past the ``n`` scenes of the step just taken (into the next epoch after its last
        scene), so that a checkpoint written now resumes with the next step."""
        self.state.index += n
        if self.state.index >= len(self.state.order):
            self.state.epoch, self.state.index, self.state.order = self.state.epoch + 1, 0, None

    def _sigint_deferred(self):
        """Context: the first Ctrl-C (SIGINT) lets the work under way finish (``_phase`` says which), then training
        saves last.pt and stops with :class:`TrainingInterrupted` (:meth:`_run`); a second one interrupts at once
        (nothing more is saved)."""
        import contextlib

        @contextlib.contextmanager
        def ctx():
            if threading.current_thread() is not threading.main_thread():
                yield
                return
            previous = signal.getsignal(signal.SIGINT)
            self._interrupted = False

            def handler(signum, frame):
                if self._interrupted:
                    raise KeyboardInterrupt
                self._interrupted = True
                print(f"\ninterrupt: {self._phase} (Ctrl-C again to abort)", file=sys.stderr, flush=True)

            signal.signal(signal.SIGINT, handler)
            try:
                yield
            finally:
                signal.signal(signal.SIGINT, previous)

        return ctx()

    def _diverged(self, scene: str, what: str) -> None:
        """Keep the last good state (the step was not applied) as last.pt and stop with a clear message
        (``scene``: the step's scene name(s))."""
        path = self.save()
        raise TrainingDiverged(
            f"training stopped at step {self.state.step + 1} (scene {scene}): {what}; "
            f"the last good checkpoint is {path} (lower lr in the training config, then "
            f"--resume)"
        )

    def _scene_losses(self, scenes: list[Scene]) -> list[SceneLoss]:
        """The collected loss of each scene of a step (graphs kept): one scene directly, several in lockstep."""
        jobs = [(sc, *self._setup(sc.vocabulary)) for sc in scenes]
        if len(jobs) == 1:
            sc, index, tracker_cfg = jobs[0]
            return [run_scene(self.net, sc, self.dets, tracker_cfg, self.cfg, self.device, index)]
        return run_scenes(self.net, jobs, self.cfg, self.dets, self.device)

    def _clip(self, params: list[torch.Tensor]) -> float:
        """The L2 norm ||g|| of the step's gradient over ``params`` (those with a gradient; float), and with
        ``grad_clip_norm`` c > 0 the gradient rescaled in place to g * min(1, c / ||g||) (norm clipping against
        exploding gradients through the GRUs' recurrence, Pascanu et al. 2013). Unclipped, one such step (||g||
        1275 against a median of 1.7 in one default training) fills AdamW's second-moment estimate v for
        thousands of steps (decay 0.999), and every later update m / sqrt(v) of those weights is a fraction of
        its size."""
        norm = torch.nn.utils.get_total_norm([p.grad for p in params])
        if self.cfg.grad_clip_norm > 0:
            torch.nn.utils.clip_grads_with_norm_(params, self.cfg.grad_clip_norm, norm)
        return float(norm)

    def _step(self, scenes: list[Scene]) -> None:
        """One optimizer step on ``scenes`` (one, the paper's setting, or ``scenes_per_step``): the mean of their
        scene losses."""
        t0 = time.perf_counter()
        self.net.train()
        name = "+".join(sc.name for sc in scenes)
        with self.net.deferring_weight_grads() as deferred:
            try:
                losses = self._scene_losses(scenes)
            except np.linalg.LinAlgError as exc:  # S = H P^- H^T + R of the parallel EKF, at a diverged state
                self._diverged(name, f"the filter's state diverged ({exc} in the EKF gain prior's update)")
            value = torch.stack([lo.value() for lo in losses]).mean()
            if not torch.isfinite(value):
                self._diverged(name, f"the loss is {value.item()}")
            gain = max(float(lo.max_abs_gain) for lo in losses)
            if gain > MAX_ABS_GAIN:
                self._diverged(name, f"the gain diverged (max |K| = {gain:.3g} > {MAX_ABS_GAIN:g})")
            self.opt.zero_grad()
            if value.requires_grad:
                deferred.backward(value, list(self.net.parameters()))
        if value.requires_grad:
            grads = [p.grad for p in self.net.parameters() if p.grad is not None]
            # the largest |entry| over all gradients (the inf-norm: no overflow of a large finite gradient)
            if grads and not bool(torch.isfinite(torch.nn.utils.get_total_norm(grads, norm_type=math.inf))):
                self.opt.zero_grad()
                self._diverged(name, "a gradient is NaN or infinite")
            grad_norm = self._clip([p for p in self.net.parameters() if p.grad is not None])
            self.opt.step()
        else:
            grad_norm = math.nan
        lr = self.opt.param_groups[0]["lr"]
        self.sched.step()
        self.state.step += 1
        row = TrainingStep(
            step=self.state.step,
            epoch=self.state.epoch,
            scene=name,
            loss=round(float(value.detach()), 8),
            gt_terms=sum(lo.gt_terms for lo in losses),
            pseudo_terms=sum(lo.pseudo_terms for lo in losses),
            prediction_terms=sum(lo.prediction_terms for lo in losses),
            lr=lr,
            seconds=round(time.perf_counter() - t0, 4),
            grad_norm=round(grad_norm, 6),
        )
        if self.validate is not None and self.cfg.val_every and self.state.step % self.cfg.val_every == 0:
            self.net.eval()
            self._validate_into(row)
        self.log.steps.append(row)
        if self.state.step == 1 or time.monotonic() - self._log_written >= LOG_EVERY_S:
            self._write_log()  # progress shows in train_log.csv from the first step on
