"""One training loop for every learned method: seeded, resumable, checkpointed.

``train_network(module, crop_files, weights_path, record_path, checkpoint_path)`` trains the
network of a learned method module (``methods/<name>.py``, resolved from its name by the caller:
core code never imports ``methods``) on training crops (:mod:`mcbench.nn.crops`) and writes

* ``weights_path`` -- ``{"arch": network, "state_dict": ...}`` (``network`` of its declaration) (format and location:
  :mod:`mcbench.io.weights`), loadable with ``torch.load(..., weights_only=True)``;
* ``record_path`` -- JSON: data, settings, loss, validation loss (overall and per validation
  scene), loss history, wall time, machine, torch version.

Settings (the ``training`` of a method's :class:`mcbench.contracts.method.LearnedSpec`,
overridable from ``config.yaml``):

``steps``, ``batch_size``, ``patch`` (square training patches, pixels), ``learning_rate``
(Adam; cosine-decayed to ``learning_rate * final_lr_fraction`` over each round of ``steps``
steps), ``rounds`` and ``plateau`` (the stopping rule below), ``loss`` (a name
in :data:`mcbench.nn.losses.LOSSES`), ``grad_clip`` (global gradient-norm clip; HDR fireflies
make rare huge gradients), ``seed``, ``validate_every``, ``checkpoint_every``, ``threads``, and
a method may declare ``augment_batch(buffers, rng)`` (extra training inputs drawn from
``default_rng([seed, step, 1])``, e.g. the swap flags of progressive denoising); for adversarial
training (a method that also declares ``critic`` and ``build_critic``): ``adversarial_weight``,
``gradient_penalty``, ``critic_learning_rate``.

Stopping rule: training runs in rounds of ``steps`` steps, each one cosine cycle of the learning
rate (a warm restart, Loshchilov & Hutter 2017) ending with a validation. From the second round on,
training stops after a round whose final validation loss is lower than the best earlier round's
by less than ``plateau`` of it (default 2 %: the validation loss stopped improving,
:func:`plateau_reached`), or after ``rounds`` rounds; the weights of the round with the lowest
validation loss are kept (in the checkpoint too, so a resumed run keeps them). ``rounds: 1`` (the
default) is a fixed count of ``steps`` steps. The record gives ``steps_run``, ``rounds_run`` and
``stopped_by`` (``plateau`` or ``rounds``).

Determinism and resuming: weights are initialised from ``torch.manual_seed(seed)``; batch
``s`` is drawn from ``default_rng([seed, s])`` and the gradient-penalty mixing from a torch
generator seeded ``(seed, s)``; the learning rate is a function of the step. A checkpoint holds
the network, critic and optimiser states and the history, written atomically every
``checkpoint_every`` steps, so a killed run resumes from its last checkpoint and continues with
the batches an uninterrupted run would have drawn. Checkpoints load through
:func:`mcbench.io.weights.load_weights` (tensors only; a corrupt or hostile file is an error naming it).

Adversarial training (MCGAN, Xu et al. 2019) uses a WGAN-GP critic (Gulrajani et al. 2017):
critic loss ``D(fake) - D(real) + λ_GP (‖∇D(mix)‖ - 1)²``, generator loss
``loss + adversarial_weight · (-D(fake))``; one critic step per generator step (the usual five
is more than our CPU budget allows).
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Callable

import numpy as np
import torch

from mcbench import BenchError
from mcbench.contracts.method import LearnedSpec, method_spec
from mcbench.io.tables import read_json, write_json
from mcbench.nn.crops import CropSet, crop_paths, load_crops, sample_batch, validation_batches
from mcbench.nn.losses import LOSSES
from mcbench.progress import eta_seconds, progress_line
from mcbench.io.weights import (CHECKPOINT_KEYS, WEIGHTS_DIGEST_KEY, check_learned_method, file_sha256, load_weights,
                                method_name, record_path, weights_folder, weights_path)

DEFAULT_SETTINGS = {
    "steps": 4000,
    "batch_size": 8,
    "patch": 64,
    "learning_rate": 5e-4,
    "final_lr_fraction": 0.05,
    "loss": "l1_log",
    "grad_clip": 1.0,
    "seed": 0,
    "validate_every": 1000,
    "checkpoint_every": 250,
    "threads": 2,
    "adversarial_weight": 0.0,
    "gradient_penalty": 10.0,
    "critic_learning_rate": 1e-4,
    "rounds": 1,
    "plateau": 0.02,
}
# Settings that may change between a run and its resumption without changing the result's meaning
# (more rounds continue a run that stopped at its last round).
RESUMABLE_CHANGES = ("threads", "validate_every", "checkpoint_every", "rounds")
# Steps between two progress lines (mean training loss over the interval, its seconds, ETA).
LOG_EVERY = 50
# Validation items (full crops) per forward pass: small, because a network's activations over a
# whole crop are large and peak memory grows with the batch (``benchmarks/training_memory.py``);
# each item's result does not depend on the batch it is in (to the last bit for most networks,
# within float32 rounding for the others), and validation never changes the weights.
VALIDATION_BATCH = 2


def training_settings(module, overrides: dict | None = None) -> dict:
    """DEFAULT_SETTINGS < the ``training`` of the method's declaration < ``overrides`` (unknown keys
    are refused)."""
    settings = dict(DEFAULT_SETTINGS)
    declared = method_spec(module).learned.training
    for source, values in (("METHOD.learned.training", declared), ("config", overrides or {})):
        unknown = sorted(set(values) - set(DEFAULT_SETTINGS))
        if unknown:
            raise BenchError(f"{source} of '{module.__name__}': unknown training setting(s) {unknown}; "
                             f"known: {sorted(DEFAULT_SETTINGS)}")
        settings.update(values)
    if not isinstance(settings["rounds"], int) or settings["rounds"] < 1 or not settings["plateau"] >= 0:
        raise BenchError(f"'{module.__name__}': training rounds must be an integer >= 1 and plateau >= 0, got "
                         f"rounds {settings['rounds']!r}, plateau {settings['plateau']!r}")
    if settings["loss"] not in LOSSES:
        raise BenchError(f"'{module.__name__}': unknown loss '{settings['loss']}'; known: {sorted(LOSSES)}")
    return settings


def learning_rate(settings: dict, step: int, key: str = "learning_rate") -> float:
    """Cosine decay from the initial rate to ``final_lr_fraction`` of it at the last step of each
    round of ``steps`` steps (a warm restart at the start of each round)."""
    base = settings[key]
    progress = min(max((step % settings["steps"]) / max(settings["steps"] - 1, 1), 0.0), 1.0)
    floor = settings["final_lr_fraction"]
    return base * (floor + (1.0 - floor) * 0.5 * (1.0 + math.cos(math.pi * progress)))


def round_ends(history: list[dict], steps: int) -> list[dict]:
    """The validations of ``history`` at the end of a round (step a multiple of ``steps``)."""
    return [entry for entry in history if entry["step"] % steps == 0]


def plateau_reached(history: list[dict], steps: int, plateau: float) -> bool:
    """The stopping rule (module docstring): True when the last round's final validation loss is
    lower than the best of the earlier rounds' by less than ``plateau`` of it (a relative
    improvement below ``plateau``, or none); False before the second round ends."""
    ends = round_ends(history, steps)
    if len(ends) < 2:
        return False
    best_before = min(entry["validation_loss"] for entry in ends[:-1])
    return best_before - ends[-1]["validation_loss"] < plateau * abs(best_before)


def _save_atomic(obj, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        torch.save(obj, tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def count_parameters(network: torch.nn.Module) -> int:
    return int(sum(p.numel() for p in network.parameters()))


@torch.no_grad()
def evaluate(network: torch.nn.Module, crops: CropSet, loss: str, batch_size: int = VALIDATION_BATCH) -> dict:
    """Mean ``loss`` and relMSE of ``network`` over every (crop, level) full buffer of ``crops``.

    Returns ``{"loss", "relmse", "items", "per_scene": {seed: loss}, "per_spp": {spp: {"loss",
    "relmse", "noisy_loss", "noisy_relmse"[, "correlated_loss", "correlated_relmse"]}}}``; every
    item (one crop at one level) weighs the same; ``noisy_*`` are the errors of the noisy input
    itself and ``correlated_*`` (a combiner's data) those of the base result it combines, for
    comparison.
    """
    loss_fn, relmse_fn = LOSSES[loss], LOSSES["relmse"]
    was_training = network.training
    network.eval()
    rows = []
    for buffers, targets, batch_seeds, batch_spp in validation_batches(crops, batch_size):
        prediction = network(buffers)
        for i in range(len(targets)):
            y, t = prediction[i:i + 1], targets[i:i + 1]
            row = [int(batch_seeds[i]), int(batch_spp[i]), float(loss_fn(y, t)), float(relmse_fn(y, t))]
            for key in ("color", "correlated"):
                if key in buffers:
                    x = buffers[key][i:i + 1]
                    row += [float(loss_fn(x, t)), float(relmse_fn(x, t))]
            rows.append(row)
    network.train(was_training)
    table = np.array(rows, dtype=np.float64)
    seeds, spp = table[:, 0].astype(int), table[:, 1].astype(int)
    names = ("loss", "relmse", "noisy_loss", "noisy_relmse", "correlated_loss", "correlated_relmse")
    per_scene = {str(s): float(table[seeds == s, 2].mean()) for s in np.unique(seeds)}
    per_spp = {str(n): dict(zip(names, (float(v) for v in table[spp == n, 2:].mean(axis=0)))) for n in np.unique(spp)}
    return {"loss": float(table[:, 2].mean()), "relmse": float(table[:, 3].mean()), "items": int(len(table)),
            "per_scene": per_scene, "per_spp": per_spp}


def _gradient_penalty(critic, real, fake, buffers, generator: torch.Generator) -> torch.Tensor:
    mix = torch.rand(real.shape[0], 1, 1, 1, generator=generator)
    mixed = (mix * real + (1 - mix) * fake).requires_grad_(True)
    scores = critic(mixed, buffers)
    (gradient,) = torch.autograd.grad(scores.sum(), mixed, create_graph=True)
    return ((gradient.flatten(1).norm(dim=1) - 1.0) ** 2).mean()


@dataclass
class _Run:
    """One training run's state: the network and its optimiser, the critic and its optimiser
    (adversarial training only, else None), the validation history, the step and seconds the run
    starts from (a resumed run's), and the weights of the best round so far (``rounds`` > 1)."""

    name: str
    label: str
    spec: LearnedSpec
    settings: dict
    network: torch.nn.Module
    optimizer: torch.optim.Optimizer
    critic: torch.nn.Module | None = None
    critic_optimizer: torch.optim.Optimizer | None = None
    history: list = field(default_factory=list)
    start_step: int = 0
    elapsed: float = 0.0
    best_state: dict | None = None

    @property
    def adversarial(self) -> bool:
        return self.critic is not None

    @property
    def steps(self) -> int:
        """The steps of one round."""
        return int(self.settings["steps"])

    @property
    def total_steps(self) -> int:
        """The steps of every round."""
        return self.steps * int(self.settings["rounds"])


def _split_crops(name: str, data, settings: dict, log) -> tuple[CropSet, str, CropSet, CropSet]:
    """``(crops, folder, training set, validation set)`` of ``data`` (crop files or a
    :class:`CropSet`), refused unless both sets hold crops."""
    crops = data if isinstance(data, CropSet) else load_crops(list(data))
    folder = crops.info.get("folder") or (str(Path(list(data)[0]).parent) if not isinstance(data, CropSet) else "")
    train_set, validation_set = crops.split()
    if not len(train_set) or not len(validation_set):
        raise BenchError(f"training data has {len(train_set)} training and {len(validation_set)} validation "
                         f"crops; need both (validation scenes: seed % 8 == 7)")
    log(f"{name}: {len(train_set)} training crops, {len(validation_set)} validation crops, "
        f"levels {crops.spp[:, 0].astype(int).tolist()}, settings {settings}")
    return crops, folder, train_set, validation_set


def _new_run(name: str, label: str, spec: LearnedSpec, settings: dict) -> _Run:
    """The network initialised from ``torch.manual_seed(seed)``, its Adam optimiser and, for
    adversarial training, the critic and its optimiser (drawn after the network, in this order)."""
    torch.manual_seed(int(settings["seed"]))
    network = spec.build_network(**spec.network)
    run = _Run(name, label, spec, settings, network, torch.optim.Adam(network.parameters(), lr=settings["learning_rate"]))
    if settings["adversarial_weight"] > 0:
        if spec.build_critic is None:
            raise BenchError(f"methods/{name}.py sets adversarial_weight but its LearnedSpec declares no build_critic")
        run.critic = spec.build_critic(**spec.critic)
        run.critic_optimizer = torch.optim.Adam(run.critic.parameters(), lr=settings["critic_learning_rate"],
                                                betas=(0.5, 0.9))
    return run


def _resume(run: _Run, checkpoint: Path, log) -> None:
    """Load ``checkpoint`` into ``run`` (states, history, step, seconds, best round); refused,
    naming the file, when it is of another architecture or of settings outside
    :data:`RESUMABLE_CHANGES`."""
    required = CHECKPOINT_KEYS + (("critic", "critic_optimizer") if run.adversarial else ())
    state = load_weights(checkpoint, required=required, what="checkpoint")
    fixed = {k: v for k, v in run.settings.items() if k not in RESUMABLE_CHANGES}
    if state["arch"] != run.spec.network or {k: v for k, v in state["settings"].items()
                                             if k not in RESUMABLE_CHANGES} != fixed:
        raise BenchError(f"{checkpoint}: checkpoint of other architecture or settings; delete it to "
                         f"train from scratch")
    run.network.load_state_dict(state["network"])
    run.optimizer.load_state_dict(state["optimizer"])
    if run.adversarial:
        run.critic.load_state_dict(state["critic"])
        run.critic_optimizer.load_state_dict(state["critic_optimizer"])
    run.history, run.start_step, run.elapsed = list(state["history"]), int(state["step"]), float(state["seconds"])
    run.best_state = state.get("best_network")
    log(f"{run.name}: resuming from {checkpoint} at step {run.start_step}")


def _save_checkpoint(run: _Run, checkpoint: Path, step: int, seconds: float) -> None:
    """The run's states and history at ``step`` into ``checkpoint``, atomically."""
    state = {"arch": run.spec.network, "settings": run.settings, "step": step, "seconds": seconds,
             "network": run.network.state_dict(), "optimizer": run.optimizer.state_dict(), "history": run.history}
    if run.best_state is not None:
        state["best_network"] = run.best_state
    if run.adversarial:
        state.update(critic=run.critic.state_dict(), critic_optimizer=run.critic_optimizer.state_dict())
    _save_atomic(state, checkpoint)


def _critic_step(run: _Run, buffers: dict, targets: torch.Tensor, step: int) -> None:
    """One WGAN-GP step of the critic on the network's output for ``buffers`` (its mixing drawn
    from a torch generator seeded by the seed and ``step``)."""
    settings = run.settings
    for group in run.critic_optimizer.param_groups:
        group["lr"] = learning_rate(settings, step, "critic_learning_rate")
    with torch.no_grad():
        fake = run.network(buffers)
    generator = torch.Generator().manual_seed(int(settings["seed"]) * 1_000_003 + step)
    critic_loss = (run.critic(fake, buffers).mean() - run.critic(targets, buffers).mean()
                   + settings["gradient_penalty"] * _gradient_penalty(run.critic, targets, fake, buffers, generator))
    run.critic_optimizer.zero_grad()
    critic_loss.backward()
    run.critic_optimizer.step()


def _training_step(run: _Run, train_set: CropSet, step: int) -> float:
    """One optimiser step on batch ``step`` (after the critic's, in adversarial training); its
    training loss, refused when not finite."""
    settings = run.settings
    for group in run.optimizer.param_groups:
        group["lr"] = learning_rate(settings, step)
    buffers, targets = sample_batch(train_set, settings["seed"], step, settings["batch_size"], settings["patch"])
    if run.spec.augment_batch is not None:   # a method's own augmentation (progressive: the swap), seeded per step
        buffers = run.spec.augment_batch(buffers, np.random.default_rng([int(settings["seed"]), step, 1]))
    if run.adversarial:
        _critic_step(run, buffers, targets, step)
    prediction = run.network(buffers)
    loss = LOSSES[settings["loss"]](prediction, targets)
    total = loss
    if run.adversarial:
        for p in run.critic.parameters():
            p.requires_grad_(False)
        total = loss - settings["adversarial_weight"] * run.critic(prediction, buffers).mean()
        for p in run.critic.parameters():
            p.requires_grad_(True)
    run.optimizer.zero_grad()
    total.backward()
    if settings["grad_clip"]:
        torch.nn.utils.clip_grad_norm_(run.network.parameters(), settings["grad_clip"])
    run.optimizer.step()
    loss_value = loss.item()
    if not math.isfinite(loss_value):
        raise BenchError(f"{run.name}: training loss became {loss_value} at step {step}; lower learning_rate")
    return loss_value


def _validate(run: _Run, validation_set: CropSet, running: list[float], done: int, started: float, log) -> bool:
    """Validate after ``done`` steps: one entry of the history, the best round's weights kept at
    a round's end; whether the stopping rule ends training here."""
    settings, steps = run.settings, run.steps
    validation_started = time.perf_counter()
    result = evaluate(run.network, validation_set, settings["loss"])
    run.history.append({"step": done, "round": (done - 1) // steps + 1,
                        "train_loss": float(np.mean(running[-settings["validate_every"]:])),
                        "validation_loss": result["loss"], "validation_relmse": result["relmse"],
                        "seconds": time.perf_counter() - started})
    if settings["rounds"] > 1 and done % steps == 0 and result["loss"] <= min(
            entry["validation_loss"] for entry in round_ends(run.history, steps)):
        run.best_state = {key: value.detach().clone() for key, value in run.network.state_dict().items()}
    stopped = done % steps == 0 and plateau_reached(run.history, steps, settings["plateau"])
    log(f"{run.name}: step {done} validation {settings['loss']} {result['loss']:.5f} "
        f"relMSE {result['relmse']:.5f} ({time.perf_counter() - validation_started:.1f} s, "
        f"elapsed {time.perf_counter() - started:.1f} s)")
    return stopped


def _progress(run: _Run, step: int, running: list[float], clock: dict) -> tuple[str, float]:
    """The progress line after ``step`` (the mean training loss over the last interval, its
    seconds and the run's ETA; ``clock``: ``started``, ``session``, ``interval`` start times) and
    the time it was taken at."""
    done, now = step + 1, time.perf_counter()
    steps_in_interval = min(len(running), done % LOG_EVERY or LOG_EVERY)
    eta = eta_seconds(now - clock["session"], done - run.start_step, run.total_steps - run.start_step)
    line = progress_line(run.name, f"step {done}/{run.total_steps} loss {np.mean(running[-steps_in_interval:]):.5f} "
                                   f"lr {learning_rate(run.settings, step):.2e}, {now - clock['interval']:.1f} s for "
                                   f"{steps_in_interval} steps "
                                   f"({(now - clock['interval']) / steps_in_interval:.3f} s/step)",
                         now - clock["started"], eta)
    return line, now


def _train_rounds(run: _Run, train_set: CropSet, validation_set: CropSet, checkpoint: Path, log) -> float:
    """Train from the run's step until its last round ends or the stopping rule stops it,
    validating and checkpointing on the way; the run's seconds (a resumed run's included)."""
    settings, steps = run.settings, run.steps
    run.network.train()
    now = time.perf_counter()
    clock = {"started": now - run.elapsed, "session": now, "interval": now}
    running = []
    stopped = run.start_step % steps == 0 and plateau_reached(run.history, steps, settings["plateau"])
    for step in range(run.start_step, run.start_step if stopped else run.total_steps):
        running.append(_training_step(run, train_set, step))
        done = step + 1
        if done % LOG_EVERY == 0 or done % steps == 0:
            line, clock["interval"] = _progress(run, step, running, clock)
            log(line)
        if done % settings["validate_every"] == 0 or done % steps == 0:
            validation_started = time.perf_counter()
            stopped = _validate(run, validation_set, running, done, clock["started"], log)
            clock["interval"] += time.perf_counter() - validation_started
        if done % settings["checkpoint_every"] == 0 or done % steps == 0:
            _save_checkpoint(run, checkpoint, done, time.perf_counter() - clock["started"])
        if stopped:
            log(f"{run.name}: round {done // steps} improved the validation loss by less than "
                f"{settings['plateau']:.0%}: stopped at step {done}")
            break
    return time.perf_counter() - clock["started"]


def _training_record(run: _Run, crops: CropSet, folder: str, train_set: CropSet, validation_set: CropSet,
                     final: dict, seconds: float) -> dict:
    """The training record (module docstring) of a finished run whose final validation is ``final``."""
    settings, steps = run.settings, run.steps
    steps_run = run.history[-1]["step"] if run.history else run.start_step
    return {
        "network": run.name,
        "label": run.label,
        "arch": run.spec.network,
        "parameters": count_parameters(run.network),
        "settings": settings,
        "data": {
            **crops.info,
            "crops": len(crops), "training_crops": len(train_set), "validation_crops": len(validation_set),
            "training_scenes": sorted(int(s) for s in set(train_set.seeds.tolist())),
            "validation_scenes": sorted(int(s) for s in set(validation_set.seeds.tolist())),
            "folder": folder,
            "source": "procedural training scenes of mcbench.training_data (no test scene)",
        },
        "loss": settings["loss"],
        # one epoch = every (training crop, level, buffer) once, as a full crop
        "epochs": steps_run * settings["batch_size"] * settings["patch"] ** 2
                  / math.prod(train_set.shape[:3] + train_set.shape[4:]),
        "steps_run": steps_run,
        "rounds_run": math.ceil(steps_run / steps),
        "stopped_by": "plateau" if plateau_reached(run.history, steps, settings["plateau"]) else "rounds",
        "validation": final,
        "history": run.history,
        "seconds": seconds,
        "machine": f"{platform.node()} {platform.machine()} {platform.processor() or ''}".strip(),
        "cpu_count": os.cpu_count(),
        "threads": int(settings["threads"]),
        "torch": torch.__version__,
        "finished": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


def train_network(module: ModuleType, data: list[str | Path] | CropSet, weights_out: str | Path,
                  record_out: str | Path, checkpoint: str | Path, overrides: dict | None = None,
                  log=print, *, provenance: dict | None = None) -> dict:
    """Train the network of learned method ``module`` (resuming from ``checkpoint`` if present)
    on ``data``: training crop files, or a :class:`CropSet` already loaded (a combiner's, from
    :func:`mcbench.nn.crops.load_combiner_crops`); returns the record (``provenance``, e.g. the
    CPU, is added to it as given)."""
    name = method_name(check_learned_method(module))
    spec = method_spec(module).learned
    settings = training_settings(module, overrides)
    torch.set_num_threads(int(settings["threads"]))
    checkpoint = Path(checkpoint)
    crops, folder, train_set, validation_set = _split_crops(name, data, settings, log)
    run = _new_run(name, method_spec(module).label, spec, settings)
    if checkpoint.exists():
        _resume(run, checkpoint, log)
    seconds = _train_rounds(run, train_set, validation_set, checkpoint, log)
    if run.best_state is not None:          # the round with the lowest validation loss
        run.network.load_state_dict(run.best_state)
    run.network.eval()
    final = evaluate(run.network, validation_set, settings["loss"])
    record = {**_training_record(run, crops, folder, train_set, validation_set, final, seconds), **(provenance or {})}
    _save_atomic({"arch": spec.network, "state_dict": run.network.state_dict()}, Path(weights_out))
    record[WEIGHTS_DIGEST_KEY] = file_sha256(weights_out)
    write_json(record_out, record, checksum=False)   # committed beside the weights: a checkout may change it
    log(f"{name}: done in {seconds:.0f} s, validation {settings['loss']} {final['loss']:.5f}")
    return record


def evaluate_committed(module: ModuleType, crops: CropSet, weights_dir: str | Path) -> dict:
    """Validation loss of the weights in ``weights_dir`` of learned method ``module`` on ``crops``
    (its validation scenes, or all of them when none is a validation scene)."""
    from mcbench.nn.inference import load_network

    name = method_name(module)
    record = read_json(record_path(weights_dir, name))
    network = load_network(method_spec(module), weights_path(weights_dir, name))
    _, validation_set = crops.split()
    return evaluate(network, validation_set if len(validation_set) else crops, record["loss"])


def correlated_paths(folder: str | Path, bases, crop_files: list[Path]) -> tuple[list[Path], dict[str, list[Path]]]:
    """The crops of ``crop_files`` that have results of every base in ``folder/correlated/<base>/``
    (same file name), and those results: ``(crops, {base: files})``."""
    folder = Path(folder)
    kept = [c for c in crop_files if all((folder / "correlated" / b / c.name).exists() for b in bases)]
    return kept, {b: [folder / "correlated" / b / c.name for c in kept] for b in bases}


def main(argv: list[str] | None = None, *, load_method: Callable[[str], ModuleType],
         load_data: Callable | None = None, provenance: dict | None = None) -> int:
    """Command line: ``train <name>`` or ``evaluate <name>``; ``load_method`` resolves a method
    name to its module (the caller's, e.g. ``methods.load_method``: core never imports ``methods``);
    ``load_data(name, crop_files, correlated_files)`` builds a learned combiner's training data
    (the crops with results of its declared ``correlated_bases`` under ``<data>/correlated/<base>/``);
    ``provenance``: added to a training's record (:func:`train_network`)."""
    parser = argparse.ArgumentParser(prog="python -m mcbench.pipeline.training",
                                     description="Train a learned denoiser, or evaluate its committed weights.")
    parser.add_argument("command", choices=["train", "evaluate"])
    parser.add_argument("name", help="method module in methods/ (kpcn, mcgan, optix_ae, wskpn, ...)")
    parser.add_argument("--data", default="results/training", help="folder of training crops")
    parser.add_argument("--steps", type=int, default=None, help="override the steps of its training settings")
    parser.add_argument("--checkpoint", default=None)
    parser.add_argument("--weights-dir", default=None,
                        help="folder of the weights (default: the committed methods/weights)")
    args = parser.parse_args(argv)
    folder = weights_folder(args.weights_dir)
    try:
        module = check_learned_method(load_method(args.name))
        files = crop_paths(args.data)
        data = files
        if method_spec(module).kind == "combiner":
            if load_data is None:
                raise BenchError(f"{args.name} is a combiner: no loader for its base results")
            files, correlated = correlated_paths(args.data, method_spec(module).learned.correlated_bases, files)
            data = load_data(args.name, files, correlated)
        if args.command == "train":
            overrides = {"steps": args.steps} if args.steps else {}
            checkpoint = args.checkpoint or f"results/training/checkpoints/{args.name}.ckpt"
            train_network(module, data, weights_path(folder, args.name), record_path(folder, args.name), checkpoint,
                          overrides, log=lambda m: print(m, file=sys.stderr, flush=True), provenance=provenance)
        else:
            result = evaluate_committed(module, data if isinstance(data, CropSet) else load_crops(data), folder)
            recorded = read_json(record_path(folder, args.name))["validation"]["loss"]
            print(f"{args.name}: validation loss {result['loss']:.6f} (recorded {recorded:.6f}, "
                  f"ratio {result['loss'] / recorded:.4f}), relMSE {result['relmse']:.6f}")
    except BenchError as exc:
        print(f"mcbench.pipeline.training: {exc}", file=sys.stderr)
        return 1
    return 0
