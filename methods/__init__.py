"""Method registry: one module per base denoiser or combiner.

A method module declares itself in one module-level object, ``METHOD``, a
:class:`mcbench.contracts.method.MethodSpec` (the contract: every hook and flag with its type,
default and meaning is a field there; a learned method adds ``learned=LearnedSpec(...)``), e.g.::

    METHOD = MethodSpec(kind="denoiser", label="#6 OIDN", run=denoise, denoise_image=denoise_image,
                        image_quantities=("color", "albedo", "normal"))

* a denoiser's ``run`` is ``denoise(buffers: RenderBuffers, *, <params>) -> Denoised`` returning
  the denoised full image and the two denoised half buffers. Methods that denoise each image on
  their own use :func:`denoise_each_buffer`; methods that compute half-buffer results internally
  (NFOR, RDFC) return them directly.
* a combiner's ``run`` is ``combine(buffers: RenderBuffers, inputs: list[Denoised], *, <params>)
  -> Denoised``; its output may feed another combiner like any base denoiser output.

:func:`load_method` refuses a module without a declaration, with a field of the wrong type or an
unknown (misspelt) field -- naming the closest field -- or with a top-level hook of the contract
(``check_config``, ``RENDER_LAYERS``, ``TIMES_ITSELF``, ...) that its declaration does not carry;
each error names ``methods/<name>.py``.

Config parameters are the keyword-only parameters of ``run``, each annotated (``int``, ``float``,
``bool``, ``str`` or ``typing.Literal[...]`` for a choice): when the DAG is parsed,
:func:`method_table` checks every config entry's ``params`` against them (:func:`check_params`,
then the declaration's ``check_config``), so a misspelt key or a value outside the choices stops
the run before any job, naming e.g. ``combiners[3].params.solvr``.

A learned method (``learned=LearnedSpec(network=..., build_network=..., training=...)``) imports
torch only inside ``build_network``/``denoise``: its ``nn.Module`` classes are defined by a cached
``network_classes()`` function on first use, so importing the module (as parsing the DAG does)
never imports torch. Its ``run`` takes the keyword ``weights_file`` (the runner passes it) and
hands it with ``METHOD`` to the shared inference of :mod:`mcbench.nn.inference`
(``denoise_with_network(METHOD, buffers, weights_file)``).

Adding a method is one new file here plus one line in ``config.yaml``.
"""

from __future__ import annotations

import functools
import importlib
import inspect
import math
import pkgutil
import re
import types
import typing
from types import ModuleType
from typing import Callable

from mcbench import NOISY, NOISY_LABEL, BenchError  # NOISY*: re-exported
from mcbench.io.buffers import denoise_each_buffer  # re-exported: single-image methods call it
from mcbench.contracts.fields import SpecError
from mcbench.contracts.method import KINDS, WEIGHTS_ARGUMENT, MethodSpec, SingleImageDenoiser, method_spec, stray_hooks
from mcbench.analysis.pool import candidate, expand_methods

__all__ = ["KINDS", "MethodSpec", "method_spec", "NOISY", "NOISY_LABEL", "UnknownMethodError", "available_methods", "load_method",
           "denoise_each_buffer", "single_image_methods", "single_image_function", "method_parameters", "check_params",
           "method_table", "config_method_table"]

class UnknownMethodError(BenchError):
    """A config key names a method that has no module in ``methods/``."""


def available_methods() -> list[str]:
    """Names of the method modules in this package."""
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))


def load_method(name: str, kind: str | None = None, config_key: str = "config") -> ModuleType:
    """Import ``methods.<name>`` and check its declaration ``METHOD`` (module docstring) and, when
    given, that it is a ``kind``.

    ``config_key`` is named in the error (e.g. ``"denoisers[2]"``) so a typo in
    ``config.yaml`` is reported where it is.
    """
    if name not in available_methods():
        raise UnknownMethodError(
            f"{config_key}: unknown method '{name}'; available: {', '.join(available_methods())}")
    try:
        module = importlib.import_module(f"{__name__}.{name}")
    except SpecError as exc:       # raised by the declaration while the module imports
        raise UnknownMethodError(f"{config_key}: methods/{name}.py: {exc}") from None
    try:
        spec = method_spec(module)
    except BenchError as exc:
        raise UnknownMethodError(f"{config_key}: {exc}") from None
    stray = stray_hooks(module, spec)
    if stray:
        raise UnknownMethodError(f"{config_key}: methods/{name}.py defines hook(s) of the method contract that "
                                 f"its METHOD does not carry: {', '.join(stray)}")
    if kind is not None and spec.kind != kind:
        raise UnknownMethodError(f"{config_key}: '{name}' is a {spec.kind}, not a {kind}")
    return module


@functools.cache
def single_image_methods() -> tuple[str, ...]:
    """The denoisers that run on one image alone (:attr:`MethodSpec.single_image`: a declared
    ``denoise_image`` or a learned denoiser's network), from every module's declaration."""
    return tuple(name for name in available_methods()
                 if method_spec(load_method(name, config_key=f"methods/{name}.py")).single_image)


def single_image_function(name: str, *, weights_dir) -> Callable:
    """Base denoiser ``name`` as a function of one :class:`mcbench.io.buffers.ImageBuffers` ->
    (H, W, 3) radiance: its declared ``denoise_image`` (default params), or a learned denoiser's
    network with the weights ``<weights_dir>/<name>.pt`` (:func:`mcbench.nn.inference.image_function`).
    A :class:`BenchError` naming the single-image denoisers for any other method."""
    module = load_method(name, kind="denoiser", config_key=f"single-image base '{name}'")
    spec = method_spec(module)
    if spec.denoise_image is not None:
        return spec.denoise_image
    if spec.learned is not None:
        from pathlib import Path

        from mcbench.nn.inference import image_function

        return image_function(spec, Path(weights_dir) / f"{name}.pt")
    raise BenchError(f"{name} has no single-image function (it filters the half buffers jointly); "
                     f"one of {', '.join(single_image_methods())}")


# ---------------------------------------------------------------------------------------------
# The candidate table of a config: checked when the DAG is parsed, before any job runs.

_POSITIONAL = {"denoiser": 1, "combiner": 2}   # denoise(buffers, ...), combine(buffers, inputs, ...)


def method_parameters(module: ModuleType) -> dict[str, inspect.Parameter]:
    """The config parameters of a method: the keyword parameters of its declared ``run``
    (``denoise``/``combine``) after the positional ``buffers`` (and ``inputs``), but for the
    weights a learned method receives from the runner (``weights_file``)."""
    spec = method_spec(module)
    parameters = list(inspect.signature(spec.run).parameters.values())[_POSITIONAL[spec.kind]:]
    return {p.name: p for p in parameters
            if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and p.name != WEIGHTS_ARGUMENT}


def _allowed(value, hint) -> bool:
    """Whether ``value`` (from YAML) fits the annotation ``hint``: ``Literal[...]`` values,
    ``bool``, ``int`` (not bool), ``float`` (int or float, not bool), ``str``,
    :data:`SingleImageDenoiser` (a name of :func:`single_image_methods`), unions of these;
    any other annotation is not checked here."""
    if hint is SingleImageDenoiser:
        return isinstance(value, str) and value in single_image_methods()
    origin = typing.get_origin(hint)
    if origin is typing.Literal:
        return any(value == choice and type(value) is type(choice) for choice in typing.get_args(hint))
    if origin in (typing.Union, types.UnionType):
        return any(_allowed(value, arg) for arg in typing.get_args(hint))
    if origin is list:          # list[T]: a YAML list of T's
        (item,) = typing.get_args(hint) or (object,)
        return isinstance(value, list) and all(_allowed(v, item) for v in value)
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if hint is str:
        return isinstance(value, str)
    return True


def _describe(hint) -> str:
    if hint is SingleImageDenoiser:
        return "a single-image denoiser (" + ", ".join(single_image_methods()) + ")"
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return " or ".join(_describe(arg) for arg in typing.get_args(hint))
    if typing.get_origin(hint) is typing.Literal:
        return "one of " + ", ".join(repr(v) for v in typing.get_args(hint))
    if typing.get_origin(hint) is list:
        return f"a list of {_describe(typing.get_args(hint)[0])} (an argument list, not one string)"
    return getattr(hint, "__name__", str(hint))


@functools.lru_cache(maxsize=None)
def _type_hints(function: Callable) -> dict:
    """``typing.get_type_hints(function)``, once per function (a config checks one method's
    params dozens of times: the pool's 31 ensembles)."""
    return typing.get_type_hints(function)


def _key_text(key) -> str:
    """``.name`` for a plain key, ``['spp ']`` as Python writes it for any other (a space, a dot),
    so that a key in an error reads as the config wrote it."""
    return f".{key}" if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_-]*", str(key)) else f"[{str(key)!r}]"


def check_params(module: ModuleType, params: dict, *, config_key: str) -> None:
    """Refuse params that ``module``'s ``denoise``/``combine`` does not take, values outside the
    annotated type or ``Literal`` choices, and missing required parameters. Errors name the key,
    e.g. ``combiners[3].params.solvr: ensemble has no parameter 'solvr'; it takes solver, ...``."""
    name = module.__name__.split(".")[-1]
    if not isinstance(params, dict):
        raise BenchError(f"{config_key}: params must be a mapping, got {type(params).__name__}")
    known = method_parameters(module)
    spec = method_spec(module)
    function = spec.run
    try:
        hints = _type_hints(function)
    except Exception as exc:   # an annotation that does not evaluate is the module's bug
        raise BenchError(f"methods/{name}.py: cannot read the annotations of {function.__name__}() ({exc})") from exc
    for key, value in params.items():
        if key not in known:
            raise BenchError(f"{config_key}{_key_text(key)}: {name} has no parameter '{key}'; it takes "
                             f"{', '.join(known) or 'no parameters'}")
        hint = hints.get(key)
        if hint is not None and not _allowed(value, hint):
            raise BenchError(f"{config_key}{_key_text(key)}: {value!r} is not allowed for {name}; expected {_describe(hint)}")
    missing = [key for key, p in known.items() if p.default is p.empty and key not in params]
    if missing:
        raise BenchError(f"{config_key}: {name} needs parameter(s) {', '.join(missing)}")
    if spec.check_config is not None:     # a method's own checks of values no annotation describes
        try:
            spec.check_config(params, config_key=config_key)
        except ValueError as exc:
            raise BenchError(str(exc)) from None


def _default_label(module: ModuleType, inputs: list[str], params: dict) -> str:
    """The declared ``label`` plus what tells this entry apart: its inputs (combiners) and its params."""
    details = []
    if inputs:
        details.append("+".join(inputs))
    if params:
        details.append(", ".join(f"{key}={value}" for key, value in params.items()))
    label = method_spec(module).label
    return f"{label} ({'; '.join(details)})" if details else label


def method_table(denoisers: list, combiners: list, *, is_learned: Callable[[ModuleType], bool],
                 keys: tuple[list[str], list[str]] | None = None) -> dict:
    """Ordered ``{candidate name: {kind, module, params, inputs, label, learned}}`` of a config.

    Everything that would otherwise fail hours later or silently change a table stops here, with
    the config key: unknown modules, a wrong kind, params the method does not take or values it
    does not allow, the reserved name ``noisy``, duplicate names, combiner inputs that are not an
    earlier entry, and duplicate table labels (default labels include inputs and params, so two
    variants of one method differ). Imports only the method modules the config names.

    ``keys`` (one list for the denoisers, one for the combiners) names where each entry comes
    from in error messages; default ``denoisers[i]``/``combiners[i]`` (entries merged from the
    candidate pool have keys of their own, ``mcbench.analysis.pool.expand_methods``).
    """
    table = {}
    if keys is None:
        keys = ([f"denoisers[{i}]" for i in range(len(denoisers))], [f"combiners[{i}]" for i in range(len(combiners))])
    if len(keys[0]) != len(denoisers) or len(keys[1]) != len(combiners):
        raise ValueError("method_table: keys must name every denoiser and combiner entry")
    entries = [("denoiser", key, {"name": e} if isinstance(e, str) else dict(e)) for key, e in zip(keys[0], denoisers)]
    entries += [("combiner", key, dict(e)) for key, e in zip(keys[1], combiners)]
    explicit_label, loaded = {}, {}
    for kind, key, entry in entries:
        name = entry["name"]
        if name == NOISY:
            raise BenchError(f"{key}.name: '{NOISY}' is reserved for the noisy input's row; choose another name")
        if name in table:
            raise BenchError(f"{key}.name: duplicate method name '{name}'")
        module_name = entry.get("method", name)
        module = loaded.get((module_name, kind))
        if module is None:
            module = loaded[module_name, kind] = load_method(
                module_name, kind=kind, config_key=f"{key}.method" if "method" in entry else key)
        params = dict(entry.get("params") or {})
        check_params(module, params, config_key=f"{key}.params")
        inputs = list(entry.get("inputs", []))
        for position, input_name in enumerate(inputs):
            if input_name not in table:
                raise BenchError(f"{key}.inputs[{position}]: '{input_name}' is not a denoiser or an "
                                 f"earlier combiner of the config")
            if input_name in inputs[:position]:
                raise BenchError(f"{key}.inputs[{position}]: '{input_name}' is already "
                                 f"inputs[{inputs.index(input_name)}]; each input once")
        expected = method_spec(module).inputs
        if kind == "combiner" and expected is not None and len(inputs) != expected:
            raise BenchError(f"{key}.inputs: {module.__name__.split('.')[-1]} combines exactly {expected} "
                             f"input(s), got {len(inputs)}")
        table[name] = {"kind": kind, "module": module.__name__.split(".")[-1], "params": params,
                       "inputs": inputs, "label": entry.get("label") or _default_label(module, inputs, params),
                       "learned": bool(is_learned(module)), "config_key": key,
                       "comparison_role": method_spec(module).comparison_role}
        explicit_label[name] = bool(entry.get("label"))
    labels = {NOISY_LABEL: NOISY}
    for name, spec in table.items():
        if spec["label"] in labels:
            other = labels[spec["label"]]
            if _from_pool(spec["config_key"]) and other in table and not _from_pool(table[other]["config_key"]):
                name, other = other, name        # blame the config's own line, not the pool's
            key, label = table[name]["config_key"], table[name]["label"]
            if explicit_label[name]:
                raise BenchError(f"{key}.label: '{label}' is also the label of '{other}'; table rows must "
                                 f"have distinct labels")
            raise BenchError(f"{key}: its default label '{label}' is also the label of '{other}'; table rows "
                             f"must have distinct labels: give it a label")
        labels[spec["label"]] = name
    return table


def _from_pool(config_key: str) -> bool:
    """Whether a method-table entry comes from the candidate pool (``study.pool (#k name)``)."""
    return config_key.startswith("study.pool")


def config_method_table(config: dict, *, is_learned: Callable[[ModuleType], bool]) -> dict:
    """:func:`method_table` of a resolved config: its ``denoisers`` and ``combiners`` with the
    candidate pool merged in when ``study.pool`` is set (:func:`mcbench.analysis.pool.expand_methods`),
    errors naming the config key (or ``study.pool (#k name)``) of the entry at fault."""
    denoisers, combiners = expand_methods(config)
    pool_names = {(e if isinstance(e, str) else e["name"]): key for key, e in denoisers + combiners if _from_pool(key)}
    for key, entry in denoisers + combiners:
        name = entry if isinstance(entry, str) else entry.get("name")
        if not _from_pool(key) and name in pool_names:
            raise BenchError(f"{key}.name: '{name}' is the name of candidate #{candidate(name).id} of the pool "
                             f"(study.pool); choose another name")
    return method_table([e for _, e in denoisers], [e for _, e in combiners], is_learned=is_learned,
                        keys=([k for k, _ in denoisers], [k for k, _ in combiners]))
