"""The method plugin contract: one typed declaration, :class:`MethodSpec`, that every
``methods/<name>.py`` exports as its module-level ``METHOD``.

Every hook and flag a method may set is a field of :class:`MethodSpec`, with its type and default;
constructing one checks the names (a misspelt field is refused with the closest known name) and
the value of every field against its annotation (:func:`check_fields`), so a plugin that imports
has a well-formed declaration. The registry (``methods/__init__.py``) reads ``METHOD`` through
:func:`method_spec` and refuses a module whose top level still defines a hook of the contract
that the declaration does not carry (:func:`stray_hooks`).

Consumers below the plugins (``mcbench.io.weights``, ``mcbench.nn``) receive the method *module*
and read its declaration with :func:`method_spec`; they never import ``methods``. Importing this
module imports neither torch nor any plugin.
"""

from __future__ import annotations

import collections.abc
import dataclasses
import difflib
import functools
import typing
from dataclasses import dataclass
from types import ModuleType
from typing import Callable, Literal, Optional

from mcbench import BenchError

__all__ = ["KINDS", "SPEC_ATTRIBUTE", "MethodSpec", "MethodSpecError", "method_spec", "check_fields",
           "stray_hooks", "field_names"]

#: The kinds of method and the name of the function each one's ``run`` is by convention.
KINDS = {"denoiser": "denoise", "combiner": "combine"}
#: The module-level name of a plugin's declaration.
SPEC_ATTRIBUTE = "METHOD"


class MethodSpecError(BenchError):
    """A :class:`MethodSpec` with an unknown field or a value of the wrong type."""


@dataclass(frozen=True, kw_only=True, eq=False)
class MethodSpec:
    """What a method module declares (``METHOD = MethodSpec(...)``); fields, keyword-only:

    * ``kind`` -- ``"denoiser"`` or ``"combiner"``.
    * ``label`` -- the name shown in tables (a stand-in says so, e.g. ``"OptiX† (our autoencoder)"``).
    * ``run`` -- a denoiser's ``denoise(buffers: RenderBuffers, *, <params>) -> Denoised`` (the
      denoised full image and the two denoised half buffers) or a combiner's
      ``combine(buffers, inputs: list[Denoised], *, <params>) -> Denoised`` (its output may feed
      another combiner like a base denoiser's). Its keyword parameters after ``buffers`` (and
      ``inputs``), each annotated, are the method's config parameters
      (``methods.check_params``); ``name``, ``scene`` and ``spp`` receive the method's config name
      and the case unless the config sets them.
    * ``render_layers`` -- the render layers the method reads (None: all). A job whose methods all
      declare them reads only their union (``mcbench.pipeline.methods.render_layers``).
    * ``image_quantities`` -- a single-image denoiser (one that filters each of the full image and
      the halves on its own, :func:`mcbench.io.buffers.denoise_each_buffer`) names the quantities
      it reads of each image, e.g. ``("color", "albedo", "normal")``; it may then run on renders
      imported without half buffers (:mod:`mcbench.io.render_folders`). A method that declares
      neither this nor ``render_layers`` needs every layer of a render
      (``mcbench.pipeline.methods.needed_layers``).
    * ``denoise_image`` -- ``f(ImageBuffers) -> (H, W, 3)`` radiance with default params: the
      method on one image, re-run by progressive denoising's divergence (``methods.single_image_function``).
    * ``check_config`` -- ``f(params, *, config_key)``: checks of param values no annotation
      describes (raise ``ValueError`` naming ``config_key``), run when the DAG is parsed.
    * ``params_layers`` -- ``f(params) -> tuple[str, ...]``: render layers the method needs with
      these params beyond what ``render_layers`` / ``image_quantities`` say (e.g. NFOR's feature
      variances for ``feature_variance='buffer'``), checked against imported renders when the DAG
      is parsed (``mcbench.pipeline.methods.needed_layers``).
    * ``warm_up`` -- False: no untimed warm-up run on a crop before the timed run.
    * ``program_seconds`` -- ``f() -> float``: when set, the recorded time of a run is what it
      returns after the run (an external program's wall time), not the wall time of ``run``.
    * ``required_files`` -- ``f(params, *, name, scene, spp) -> list[str]``: files each case
      needs, checked when the DAG is parsed (``mcbench.pipeline.plan``).
    * ``reads_rows`` -- True: the method reads its render and inputs by rows inside ``run``, so a
      job of such methods holds no layer whole (``mcbench.pipeline.methods.reads_rows``).
    * ``inputs`` -- a combiner that combines exactly this many inputs (None: any number).
    * ``network`` -- a learned method's architecture hyperparameters, ``build_network(**network)``.
    * ``training`` -- a learned method's training settings (keys of ``mcbench.nn.train.DEFAULT_SETTINGS``).
    * ``build_network`` -- ``f(**network) -> torch.nn.Module``; importing the plugin must not
      import torch (the classes come from a cached ``network_classes()``).
    * ``critic`` -- the critic's hyperparameters of adversarial training, ``build_critic(**critic)``.
    * ``build_critic`` -- ``f(**critic) -> torch.nn.Module``, the critic of adversarial training.
    * ``augment_batch`` -- ``f(batch: dict, rng) -> dict``: a learned method's own augmentation
      of each training batch.
    * ``correlated_bases`` -- a learned combiner's base denoisers, whose results on the training
      crops it is trained on.
    * ``training_keys`` -- a learned combiner's extra network inputs ``{key: channels}``
      (``mcbench.nn.crops``).

    A learned method sets ``network``, ``training`` and ``build_network`` (all three or none; see
    :attr:`learned`), a learned combiner also ``correlated_bases`` and ``training_keys``; ``critic``
    and ``build_critic`` go together.
    """

    kind: Literal["denoiser", "combiner"]
    label: str
    run: Callable
    render_layers: Optional[tuple[str, ...]] = None
    image_quantities: Optional[tuple[str, ...]] = None
    denoise_image: Optional[Callable] = None
    check_config: Optional[Callable] = None
    params_layers: Optional[Callable] = None
    warm_up: bool = True
    program_seconds: Optional[Callable] = None
    required_files: Optional[Callable] = None
    reads_rows: bool = False
    inputs: Optional[int] = None
    network: Optional[dict] = None
    training: Optional[dict] = None
    build_network: Optional[Callable] = None
    critic: Optional[dict] = None
    build_critic: Optional[Callable] = None
    augment_batch: Optional[Callable] = None
    correlated_bases: Optional[tuple[str, ...]] = None
    training_keys: Optional[dict[str, int]] = None

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def learned(self) -> bool:
        """Whether the method has a network trained by ``mcbench.nn.train`` (``network``, ``training``
        and ``build_network`` set)."""
        return self.build_network is not None


def _refuse_unknown_fields(init: Callable) -> Callable:
    """``MethodSpec.__init__`` that first refuses a keyword that is no field, naming the closest one."""
    @functools.wraps(init)
    def checked_init(self, *args, **fields):
        unknown = [key for key in fields if key not in field_names()]
        if unknown:
            raise MethodSpecError("; ".join(f"MethodSpec has no field '{key}'{_suggestion(key)}" for key in unknown))
        init(self, *args, **fields)
    return checked_init


MethodSpec.__init__ = _refuse_unknown_fields(MethodSpec.__init__)


@functools.cache
def field_names() -> tuple[str, ...]:
    """The fields of :class:`MethodSpec`, in declaration order."""
    return tuple(f.name for f in dataclasses.fields(MethodSpec))


@functools.cache
def _hints() -> dict:
    return typing.get_type_hints(MethodSpec)


def _suggestion(key: str) -> str:
    """`` (did you mean 'x'?)`` for the field closest to ``key`` (case-insensitive), or ``""``."""
    names = {name.lower(): name for name in field_names()}
    close = difflib.get_close_matches(key.lower(), names, n=1)
    return f" (did you mean '{names[close[0]]}'?)" if close else ""


def _fits(value, hint) -> bool:
    """Whether ``value`` has the type ``hint``: ``Literal``, ``Optional``/unions, ``tuple[T, ...]``,
    ``dict`` or ``dict[K, V]``, ``Callable``, ``bool``, ``int`` (not bool), ``str``."""
    origin = typing.get_origin(hint)
    if origin is Literal:
        return value in typing.get_args(hint)
    if origin is typing.Union:
        return any(_fits(value, arg) for arg in typing.get_args(hint))
    if hint is type(None):
        return value is None
    if origin is tuple:
        item = typing.get_args(hint)[0]
        return isinstance(value, tuple) and all(_fits(v, item) for v in value)
    if origin is dict or hint is dict:
        key, item = typing.get_args(hint) or (object, object)
        return isinstance(value, dict) and all(_fits(k, key) and _fits(v, item) for k, v in value.items())
    if origin is collections.abc.Callable or hint is Callable:
        return callable(value)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return hint is object or isinstance(value, hint)


def _type_name(hint) -> str:
    """``hint`` as written in the dataclass: ``bool``, ``Optional[tuple[str, ...]]``, ..."""
    return hint.__name__ if isinstance(hint, type) else str(hint).replace("typing.", "").replace("collections.abc.", "")


def check_fields(spec: MethodSpec) -> None:
    """Refuse a declaration whose fields do not fit their annotations or each other: a
    :class:`MethodSpecError` naming the field (e.g. ``render_layers must be Optional[tuple[str, ...]],
    got a list``)."""
    for name, hint in _hints().items():
        value = getattr(spec, name)
        if not _fits(value, hint):
            raise MethodSpecError(f"MethodSpec field '{name}' must be {_type_name(hint)}, got {value!r}")
    if not spec.label:
        raise MethodSpecError("MethodSpec field 'label' must not be empty")
    if spec.inputs is not None and (spec.kind != "combiner" or spec.inputs < 1):
        raise MethodSpecError(f"MethodSpec field 'inputs' is for a combiner, at least 1, got {spec.inputs} "
                              f"for a {spec.kind}")
    groups = (("network", "training", "build_network"), ("critic", "build_critic"))
    if spec.kind == "combiner" and spec.build_network is not None:
        groups += (("build_network", "correlated_bases", "training_keys"),)
    for group in groups:
        given = [name for name in group if getattr(spec, name) is not None]
        if given and len(given) != len(group):
            missing = [name for name in group if name not in given]
            raise MethodSpecError(f"MethodSpec fields {', '.join(group)} go together: "
                                  f"{', '.join(given)} set, {', '.join(missing)} not")
    if spec.critic is not None and spec.network is None:
        raise MethodSpecError("MethodSpec fields critic, build_critic are for a learned method (network)")


#: Module-level names of the contract's hooks besides each field's own name and its upper case
#: (``render_layers``/``RENDER_LAYERS``): a module defining one of them at its top level that its
#: declaration does not carry is refused (:func:`stray_hooks`).
_OTHER_HOOK_NAMES = {"run": tuple(KINDS.values()), "program_seconds": ("TIMES_ITSELF",)}


def stray_hooks(module: ModuleType, spec: MethodSpec) -> list[str]:
    """Top-level names of ``module`` that are hooks of the contract (a field's name, in lower or
    upper case, ``denoise``/``combine`` for ``run``, ``TIMES_ITSELF`` for ``program_seconds``)
    whose value ``spec`` does not carry in that field, e.g. a ``check_config`` function the
    declaration forgot, or a leftover ``RENDER_LAYERS``. Each is named with the field to set."""
    stray = []
    for name in field_names():
        declared = getattr(spec, name)
        for attribute in dict.fromkeys((name, name.upper(), *_OTHER_HOOK_NAMES.get(name, ()))):
            if attribute in vars(module) and not _carried(vars(module)[attribute], declared):
                stray.append(f"{attribute} (set {name}= in {SPEC_ATTRIBUTE})")
    return stray


def _carried(value, declared) -> bool:
    return value is declared or (not callable(value) and type(value) is type(declared) and value == declared)


def method_spec(module: ModuleType) -> MethodSpec:
    """The declaration ``METHOD`` of method module ``module``; a :class:`BenchError` naming
    ``methods/<name>.py`` when it has none or something else under that name."""
    spec = getattr(module, SPEC_ATTRIBUTE, None)
    if not isinstance(spec, MethodSpec):
        name = module.__name__.rsplit(".", 1)[-1]
        found = "none" if spec is None else f"a {type(spec).__name__}"
        raise BenchError(f"methods/{name}.py: {SPEC_ATTRIBUTE} must be a mcbench.io.method_spec.MethodSpec "
                         f"(the method's declaration), found {found}")
    return spec
