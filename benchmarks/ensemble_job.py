"""One ensemble job as the DAG runs it, for ``bench_ensemble.py`` to time as a whole process:

    python benchmarks/ensemble_job.py RENDER.exr OUT.exr INPUT1.exr ... [--eager] [--param key=value ...]

Like :func:`mcbench.pipeline.method_runs.run_methods` for a batch of ensembles: the render's
``render_layers`` (declared in ``methods.ensemble.METHOD``) and each input's three images,
``methods.ensemble.combine``, write the output EXR (``write_layers``). Two ways to read them:

* default (as ``run_methods`` reads for a batch of such methods): a combiner that declares
  ``reads_rows`` gets the render's layers and the inputs' images as
  :class:`mcbench.io.exr.LayerRows` (:func:`mcbench.io.exr.layer_rows`: only headers are read here;
  combine reads rows as it goes, so no input is held whole);
* ``--eager``: as ``run_methods`` reads for any other batch, every layer whole
  (``RenderBuffers.load`` of the ``render_layers``, ``Denoised.load``; the ensemble reads no extras).

Prints one JSON line: seconds spent importing, reading, loading the numba cache (a combine of
an 8 x 8 crop, ``jit_s``), combining and writing (wall, ``time.perf_counter``). The parent
measures the whole process (wall time and peak RSS from ``os.wait4``).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

START = time.perf_counter()
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcbench.io.buffers import Denoised, RenderBuffers  # noqa: E402
from mcbench.io.exr import write_layers  # noqa: E402
from methods import ensemble  # noqa: E402


def parse_params(items):
    """``key=value`` strings to combine() keywords (ints, floats and booleans recognised)."""
    params = {}
    for item in items:
        key, value = item.split("=", 1)
        for cast in (int, float):
            try:
                value = cast(value)
                break
            except ValueError:
                continue
        if value in ("True", "False"):
            value = value == "True"
        params[key] = value
    return params


def main(argv):
    params = []
    if "--param" in argv:
        at = argv.index("--param")
        argv, params = argv[:at], [p for p in argv[at + 1:] if p != "--param"]
    spec = ensemble.METHOD
    eager = "--eager" in argv or not spec.reads_rows
    argv = [a for a in argv if a != "--eager"]
    render, output, *inputs = argv
    imported = time.perf_counter()
    if eager:
        buffers = RenderBuffers.load(render, layers=spec.render_layers)  # as run_methods reads it
        denoised = [Denoised.load(path) for path in inputs]                    # combine() reads no extras
    else:
        from mcbench.io.exr import layer_rows, read_metadata

        buffers = RenderBuffers(layers=layer_rows(render, ["color", *spec.render_layers]),
                                spp=int(read_metadata(render).get("spp", 0)), source=render)
        denoised = []
        for path in inputs:
            layers = layer_rows(path, ["color", "color_a", "color_b"])
            denoised.append(Denoised(full=layers["color"], a=layers["color_a"],
                                     b=layers["color_b"], source=path))
    read = time.perf_counter()
    ensemble.combine(RenderBuffers(layers={k: v[:8, :8] for k, v in buffers.layers.items()},
                                   spp=buffers.spp),
                     [Denoised(full=d.full[:8, :8], a=d.a[:8, :8], b=d.b[:8, :8]) for d in denoised],
                     **parse_params(params))         # loads the numba cache: not compute
    warm = time.perf_counter()
    result = ensemble.combine(buffers, denoised, **parse_params(params))
    combined = time.perf_counter()
    write_layers(output, result.layers())
    written = time.perf_counter()
    print(json.dumps({"import_s": imported - START, "read_s": read - imported, "jit_s": warm - read,
                      "combine_s": combined - warm, "write_s": written - combined}))


if __name__ == "__main__":
    main(sys.argv[1:])
