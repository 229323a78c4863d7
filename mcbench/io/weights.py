"""Where the learned methods' weights live, what their files hold, and loading them safely.

Torch-free at import (parsing the DAG imports this module): :func:`load_weights` imports torch
only when it is called.

* Folder: the config key ``weights_dir``, passed down to whatever loads weights (the case job
  hands a learned method its ``<weights_dir>/<name>.pt``); :data:`COMMITTED_WEIGHTS`, the
  committed ``methods/weights`` of this checkout, when the key is empty.
* ``<name>.pt`` -- a ``torch.save`` of ``{"arch": network, "state_dict": state_dict()}``
  (:data:`WEIGHTS_KEYS`): plain tensors and containers only, so it loads with
  ``torch.load(..., weights_only=True)``, which never runs code from the file.
* ``<name>.json`` -- the training record (data, settings, losses, machine; see
  :mod:`mcbench.nn.train`), with the SHA-256 of ``<name>.pt`` (:data:`WEIGHTS_DIGEST_KEY`):
  :func:`load_weights` refuses a weights file that does not match it, since a flipped bit in a
  tensor leaves a file torch loads without complaint.
* Training checkpoints use the same format with the keys :data:`CHECKPOINT_KEYS` (plus the
  critic's states for adversarial training).

A learned method is a method module whose declaration (:class:`mcbench.contracts.method.MethodSpec`)
sets ``learned`` (:class:`mcbench.contracts.method.LearnedSpec`: its network and training).
"""

from __future__ import annotations

import re
from pathlib import Path
from types import ModuleType

from mcbench import BenchError
from mcbench.contracts.method import method_spec

COMMITTED_WEIGHTS = Path(__file__).resolve().parents[2] / "methods" / "weights"
WEIGHTS_SUFFIX = ".pt"
RECORD_SUFFIX = ".json"
WEIGHTS_KEYS = ("arch", "state_dict")
CHECKPOINT_KEYS = ("arch", "settings", "step", "seconds", "network", "optimizer", "history")
#: Key of a training record holding the SHA-256 of its weights file (checked by :func:`load_weights`).
WEIGHTS_DIGEST_KEY = "weights_sha256"

# Sentences of torch's load errors that advise loading unsafely (or filing a torch issue); they
# are dropped from our messages, which must never suggest running code from a weights file.
_UNSAFE_ADVICE = ("weights_only", "weights only", "trusted source", "file an issue", "safe_globals",
                  "documentation of torch.load", "allowlist")


def weights_folder(configured: str | Path | None) -> Path:
    """The folder of learned weights the config key ``weights_dir`` names (empty or None: the
    committed :data:`COMMITTED_WEIGHTS`)."""
    return Path(configured) if configured else COMMITTED_WEIGHTS


def weights_path(folder: str | Path, name: str) -> Path:
    """Weights of learned method ``name`` in weights folder ``folder``: ``<folder>/<name>.pt``."""
    return Path(folder) / f"{name}{WEIGHTS_SUFFIX}"


def record_path(folder: str | Path, name: str) -> Path:
    """Training record of learned method ``name`` in weights folder ``folder``: ``<folder>/<name>.json``."""
    return Path(folder) / f"{name}{RECORD_SUFFIX}"


def method_name(module: ModuleType) -> str:
    """The registry name of a method module: the last part of its module name (``methods.kpcn`` -> ``kpcn``)."""
    return module.__name__.rsplit(".", 1)[-1]


def is_learned_method(module: ModuleType) -> bool:
    """Whether method module ``module``'s declaration makes it a learned method (imports nothing)."""
    return method_spec(module).learned is not None


def check_learned_method(module: ModuleType) -> ModuleType:
    """``module`` itself if it is a learned method, else a :class:`BenchError` naming its file and
    what its declaration lacks."""
    if not is_learned_method(module):
        raise BenchError(f"methods/{method_name(module)}.py is not a learned method: its METHOD declares no "
                         f"learned=LearnedSpec(...)")
    return module


def safe_failure_reason(error: BaseException) -> str:
    """``error``'s type and message without the sentences of torch's advice to load unsafely."""
    text = str(error).replace("WeightsUnpickler error:", "")
    sentences = (s.strip() for s in re.split(r"(?<=[.!?])\s+|\n+", text))
    kept = [s for s in sentences if s and not any(a in s.lower() for a in _UNSAFE_ADVICE)]
    return type(error).__name__ + (f": {' '.join(kept)}" if kept else "")


def trained_features(record: str | Path) -> str:
    """The feature convention (:data:`mcbench.render.renderer.FEATURE_CONVENTIONS`) a network's
    training record says its crops were rendered with (``data.features``); ``first_hit`` for a
    record without it (trained before the key existed, on first-hit features) or a missing record."""
    import json

    try:
        data = json.loads(Path(record).read_text()).get("data", {})
    except FileNotFoundError:
        return "first_hit"
    except (OSError, ValueError) as exc:
        raise BenchError(f"{record}: cannot read the training record ({exc})") from exc
    return str(data.get("features", "first_hit")) if isinstance(data, dict) else "first_hit"


def check_trained_features(record: str | Path, features: str, *, name: str) -> None:
    """Raise :class:`BenchError` when the weights of learned method ``name`` (training record
    ``record``) were trained on features of another convention than ``features`` (config key
    ``features``): a network fed features it was not trained on gives numbers no table should hold."""
    trained = trained_features(record)
    if trained != features:
        raise BenchError(f"{record}: the weights of {name} were trained on '{trained}' features, the config "
                         f"key 'features' is '{features}'; retrain them under the same features "
                         f"(`snakemake --cores 2 train_{name}` with an empty weights_dir) or set features: {trained}")


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes, as 64 hex digits (read in 1 MiB blocks)."""
    import hashlib

    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def check_weights_digest(path: str | Path) -> None:
    """Refuse weights ``path`` (``<name>.pt``) when its training record ``<name>.json`` beside it
    records a SHA-256 (:data:`WEIGHTS_DIGEST_KEY`) its bytes do not match; a file without a record
    or a record without the key (a checkpoint, weights trained elsewhere) is not checked."""
    from mcbench.io.tables import read_json

    path = Path(path)
    record_file = path.with_suffix(RECORD_SUFFIX)
    if path.suffix != WEIGHTS_SUFFIX or not record_file.exists():
        return
    expected = read_json(record_file).get(WEIGHTS_DIGEST_KEY)      # BenchError naming a damaged record
    if expected is None:
        return
    try:
        actual = file_sha256(path)
    except OSError as exc:
        raise BenchError(f"{path}: cannot read weights ({exc.strerror or exc})") from exc
    if actual != expected:
        raise BenchError(f"{path}: weights do not match the SHA-256 recorded in {record_file.name} "
                         f"(damaged, or replaced without its record): restore it (git checkout) or retrain")


def load_weights(path: str | Path, *, required: tuple[str, ...] = WEIGHTS_KEYS, what: str = "weights") -> dict:
    """The dict saved in ``path`` (weights or a checkpoint), loaded on the CPU with
    ``torch.load(..., weights_only=True)``.

    Any failure -- a missing, empty, truncated, garbage or hostile file (one that would run code
    when unpickled), or a dict without the keys ``required`` -- is a :class:`BenchError` that names
    the file (``what`` says what it should have been) and never advises loading it unsafely.
    """
    import torch

    path = Path(path)
    if not path.is_file():
        raise BenchError(f"{path}: {what} file is missing")
    check_weights_digest(path)
    try:
        blob = torch.load(path, weights_only=True, map_location="cpu")
    except Exception as error:  # torch raises UnpicklingError, RuntimeError, EOFError, OSError, ...
        raise BenchError(f"{path}: cannot load {what} ({safe_failure_reason(error)}); the file is corrupt "
                         f"or not a tensors-only {what} file: restore it or retrain") from None
    if not isinstance(blob, dict):
        raise BenchError(f"{path}: {what} file holds a {type(blob).__name__}, not a dict with keys {list(required)}")
    missing = [key for key in required if key not in blob]
    if missing:
        raise BenchError(f"{path}: {what} file lacks the key(s) {missing}")
    return blob
