"""Running base denoisers and combiners on one test case for the case job
(:mod:`mcbench.pipeline.cases`, rule ``run_case`` of ``workflow/rules/methods.smk``): several
methods in one call, with their outputs, timing records and output checks, and what a job of
them reads of a render.
"""

from __future__ import annotations

import functools
import json
import platform
import time
from typing import Callable

import numpy as np

from mcbench import BenchError
from mcbench.io.buffers import Denoised, RenderBuffers, stored_layers
from mcbench.io.exr import check_finite, read_metadata, write_layers
from mcbench.io.file_cache import cached_read
from mcbench.contracts.method import WEIGHTS_ARGUMENT, method_spec
from mcbench.io.tables import write_json
from mcbench.io.weights import weights_folder, weights_path


def _machine() -> str:
    return f"{platform.node()} {platform.machine()} {platform.processor() or ''}".strip()


def run_method(method: str, render_path: str, output_path: str, timing_path: str, *,
               module_name: str, params: dict | None = None, input_paths: list[str] = (),
               weights: str | None = None, scene: str = "", spp: int = 0, threads: int = 1) -> None:
    """Run one base denoiser or combiner on a render and write its output EXR and timing JSON
    (``weights``: a learned method's weights file).

    The timing counts the method's compute only (EXR reading and writing excluded), measured
    with ``time.perf_counter``; base denoisers include their three runs (full, A, B).
    """
    run_methods([{"name": method, "module": module_name, "params": params or {}, "weights": weights,
                  "input_paths": list(input_paths), "exr": output_path, "timing": timing_path}],
                render_path, scene=scene, spp=spp, threads=threads)


def run_methods(entries: list[dict], render_path: str, *, scene: str = "", spp: int = 0,
                threads: int = 1) -> None:
    """Run several methods of one test case in one process, in the given order.

    ``entries``: dicts with ``name``, ``module``, ``params``, ``input_paths`` (the output EXRs
    of the method's inputs), ``exr``, ``timing`` (where its output and timing record go),
    ``weights`` (a learned method's weights file, handed to its ``run`` as ``weights_file``) and
    optionally ``key`` (:func:`mcbench.pipeline.cases.method_key`, recorded in both) and
    ``compression`` (of the output EXR, :data:`mcbench.io.exr.COMPRESSIONS`; default ``"none"``),
    in dependency order: an entry may take an earlier entry's output as an input. The render and
    every input EXR are read once; an input made earlier in the same call is read back from the
    file just written, so each method sees exactly what a job of its own would see (results
    do not depend on the batching). Every method gets its own output, timing record and output
    check. The timing is the method's compute on the case (``time.perf_counter``; EXR reading and
    writing excluded) after an untimed run on the case's top-left 32 x 32 crop (once per module and
    parameters: methods that differ only in their inputs share it), so that just-in-time
    compilation, numba's cache loading and first-call set-up are not counted (they are paid once
    per process, whatever the image size); the first failure stops the call, naming the
    method. Methods are imported once per process (a learned method's torch import is paid once
    per process, not once per method). The render and whole-file inputs are read through
    :func:`mcbench.io.file_cache.cached_read`, so a warm worker (:mod:`mcbench.pipeline.worker_pool`)
    running the next method of the same case does not decode them again.
    """
    from mcbench.pipeline.registry import load_method

    modules = {entry["module"]: load_method(entry["module"], config_key=f"method '{entry['name']}'")
               for entry in entries}
    buffers, input_of = _case_reader(render_path, modules.values())
    for entry in entries:
        module = modules[entry["module"]]
        inputs = [input_of(path) for path in entry.get("input_paths", ())]
        params = _entry_params(entry, module, scene=scene, spp=spp)
        result, seconds = _timed_run(entry["module"], module, buffers, inputs, params)
        _write_method_output(entry, result, seconds, scene=scene, spp=spp, threads=threads,
                             kind=method_spec(module).kind, shape=buffers.shape)


def _case_reader(render_path: str, modules) -> tuple[RenderBuffers, Callable[[str], Denoised]]:
    """The case's render (the layers ``modules`` read, by rows where one of them asks for it) and
    a reader of input EXRs that reads each file once and checks its shape against the render."""
    layers = render_layers(modules)
    by_rows = reads_rows(modules)
    if by_rows:
        buffers = _render_by_rows(render_path, layers)
    else:
        buffers = cached_read(render_path, lambda path: RenderBuffers.load(path, layers=layers),
                              key=("render", layers))
    loaded: dict[str, Denoised] = {}

    def input_of(path: str) -> Denoised:
        if path not in loaded:
            denoised = (_denoised_by_rows(path) if by_rows else
                        cached_read(path, lambda p: Denoised.load(p, extras=True), key=("denoised",)))
            if denoised.full.shape != buffers.color.shape:
                raise BenchError(f"{path}: shape {denoised.full.shape} does not match render "
                                 f"{render_path} of shape {buffers.color.shape}")
            loaded[path] = denoised
        return loaded[path]

    return buffers, input_of


def _entry_params(entry: dict, module, *, scene: str, spp: int) -> dict:
    """The keyword arguments of ``entry``'s ``run``: its params, plus its name and case where its
    ``run`` names them (a method that names its files), plus a learned method's weights file."""
    from mcbench.pipeline.registry import method_parameters

    params = dict(entry.get("params") or {})
    for key, value in (("name", entry["name"]), ("scene", scene), ("spp", spp)):
        if key in method_parameters(module) and key not in params:
            params[key] = value
    if method_spec(module).learned is not None:
        params[WEIGHTS_ARGUMENT] = _weights_file(entry, entry["name"])
    return params


def _timed_run(module_name: str, module, buffers: RenderBuffers, inputs: list, params: dict):
    """(result, seconds): the method's compute on the case, after an untimed run on the case's
    corner crop that compiles / loads its JIT kernels (numba's cache load alone can cost more than
    a small case's compute) and first-call set-up, once per module and parameters in the process
    (the 31 pool ensembles share one). An external program reports its own wall time."""
    spec = method_spec(module)
    key = (module_name, json.dumps(params, sort_keys=True, default=str))
    if key not in _WARMED and spec.warm_up:
        _apply(module, *_corner_crop(buffers, inputs), params)
        _WARMED.add(key)
    start = time.perf_counter()
    result = _apply(module, buffers, inputs, params)
    seconds = time.perf_counter() - start
    if spec.program_seconds is not None:
        seconds = float(spec.program_seconds())
    return result, seconds


def _write_method_output(entry: dict, result, seconds: float, *, scene: str, spp: int, threads: int,
                         kind: str, shape: tuple[int, int]) -> None:
    """Check ``result`` for NaN/Inf (naming the output file and method), then write its EXR and
    timing record."""
    method = entry["name"]
    layers = result.layers()
    bad = {name: layer for name, layer in layers.items() if not np.all(np.isfinite(layer))}
    if bad:
        check_finite(f"{entry['exr']} (output of method '{method}')", bad)
    key = {"key": entry["key"]} if entry.get("key") else {}
    write_layers(entry["exr"], stored_layers(result), metadata={"method": method, "scene": scene, "spp": spp,
                                                 "seconds": f"{seconds:.6f}", **key},
                 compression=entry.get("compression", "none"))
    height, width = shape
    write_json(entry["timing"], {"scene": scene, "spp": spp, "method": method, "module": entry["module"],
                                 "kind": kind, "seconds": seconds, "width": width, "height": height,
                                 "threads": threads, "machine": _machine(), **key})


def method_function(module, *, weights_dir) -> Callable:
    """Method module ``module``'s declared ``run``, a learned method's with its weights
    ``<weights_dir>/<name>.pt`` bound (``weights_file``), for steps that run a method outside a
    case job (the oracle study, the progressive curve, training inputs)."""
    spec = method_spec(module)
    if spec.learned is None:
        return spec.run
    name = module.__name__.rsplit(".", 1)[-1]
    return functools.partial(spec.run, **{WEIGHTS_ARGUMENT: str(weights_path(weights_folder(weights_dir), name))})


def _weights_file(entry: dict, method: str) -> str:
    """The weights file of learned method entry ``entry``; a :class:`BenchError` when it has none."""
    if not entry.get("weights"):
        raise BenchError(f"method '{method}' is a learned method, but its job names no weights file "
                         f"(the plan's 'weights' of each learned method, from the config key weights_dir)")
    return str(entry["weights"])


#: (module, parameters) already warmed up in this process (a batch, or a warm worker of mcbench.pipeline.worker_pool)
_WARMED: set[tuple[str, str]] = set()

WARM_UP_SIZE = 32  # pixels per side of the untimed warm-up crop of run_methods


def reads_rows(modules) -> bool:
    """Whether a job of these method modules reads its render and inputs by rows: every module
    declares ``reads_rows`` (:class:`mcbench.contracts.method.MethodSpec`; the ensemble), so no layer is held whole
    (``benchmarks/bench_ensemble.py`` measures the peak memory saved). Such a method reads the
    rows it needs inside its own call, so its recorded seconds include those reads (scanlines of
    uncompressed outputs; a render's ZIP blocks of 16 rows are decoded as they are reached: cheap
    next to its compute); a batch with any other
    method reads every file whole, before the timed call."""
    modules = list(modules)
    return bool(modules) and all(method_spec(module).reads_rows for module in modules)


def _render_by_rows(path: str, layers: tuple[str, ...] | None) -> RenderBuffers:
    """A render whose layers (``color`` and ``layers``) are :class:`mcbench.io.exr.LayerRows`,
    after one pass over the file by rows that checks its checksum and refuses NaN/Inf (naming the
    file and layer); the pixels are not held."""
    from mcbench.io.exr import layer_rows

    from mcbench.io.exr import check_resolution

    names = list(dict.fromkeys(["color", *(layers or ())]))
    rows = layer_rows(path, names, finite=True)
    meta = read_metadata(path)
    check_resolution(path, rows["color"].shape, meta)
    return RenderBuffers(layers=rows, spp=int(meta.get("spp", 0)), source=path)


def _denoised_by_rows(path: str) -> Denoised:
    """A method's output as :class:`mcbench.io.exr.LayerRows` of ``color``, ``color_a``, ``color_b``
    (read by rows when the method indexes them, after a pass that checks the checksum and refuses
    NaN/Inf; no extras: a method declaring ``reads_rows`` reads none)."""
    from mcbench.io.exr import layer_rows

    layers = layer_rows(path, ["color", "color_a", "color_b"], finite=True)
    return Denoised(full=layers["color"], a=layers["color_a"], b=layers["color_b"], source=path)


def render_layers(modules) -> tuple[str, ...] | None:
    """The render layers a job of these method modules reads: the union of their
    declared ``render_layers`` (:class:`mcbench.contracts.method.MethodSpec`), or None (every layer)
    when one does not declare them."""
    names: dict[str, None] = {}
    for module in modules:
        declared = method_spec(module).render_layers
        if declared is None:
            return None
        names.update(dict.fromkeys(declared))
    return tuple(names)


def needed_layers(module, *, halves: bool = True, params: dict | None = None) -> tuple[str, ...]:
    """The render layers a method cannot run without, checked against an imported render's when
    the DAG is parsed (:mod:`mcbench.pipeline.plan`): its declared ``render_layers``; or, for a
    single-image denoiser declaring ``image_quantities`` (:class:`mcbench.contracts.method.MethodSpec`),
    those quantities of the full image plus the halves' own colour (and variance, if it reads
    variance) when ``halves`` (half-buffer features fall back to the full image's,
    :meth:`mcbench.io.buffers.RenderBuffers.image`); else every layer of
    :data:`mcbench.io.buffers.REQUIRED_LAYERS`; plus, with ``params``, the layers its
    ``params_layers`` hook names for them."""
    from mcbench.io.buffers import REQUIRED_LAYERS

    spec = method_spec(module)
    extra = tuple(spec.params_layers(dict(params or {}))) if spec.params_layers is not None else ()
    if spec.render_layers is not None:
        base = spec.render_layers
    elif spec.image_quantities is None:
        base = REQUIRED_LAYERS
    else:
        quantities = spec.image_quantities
        own = [q for q in ("color", "variance") if q in quantities]
        base = (*quantities, *(q + s for s in ("_a", "_b") for q in own if halves))
    return tuple(dict.fromkeys((*base, *extra)))


def _apply(module, buffers: RenderBuffers, inputs: list[Denoised], params: dict) -> Denoised:
    spec = method_spec(module)
    if spec.kind == "denoiser":
        return spec.run(buffers, **params)
    return spec.run(buffers, inputs, **params)


def _corner_crop(buffers: RenderBuffers, inputs: list[Denoised]) -> tuple[RenderBuffers, list[Denoised]]:
    """The top-left WARM_UP_SIZE^2 pixels of a render and of its inputs (every layer)."""
    h, w = (min(WARM_UP_SIZE, n) for n in buffers.shape)

    def corner(layer: np.ndarray) -> np.ndarray:  # contiguous, like a loaded layer (same kernels)
        return np.ascontiguousarray(layer[:h, :w])

    crop = RenderBuffers(layers={k: corner(v) for k, v in buffers.layers.items()}, spp=buffers.spp,
                         source=buffers.source)
    cropped = [Denoised(full=corner(d.full), a=corner(d.a), b=corner(d.b),
                        extras={k: corner(v) for k, v in d.extras.items()} if d.extras else None)
               for d in inputs]
    return crop, cropped
