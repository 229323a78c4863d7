"""Results made elsewhere (on a GPU machine, by another program, from a paper's supplement),
read from files and ranked like any base denoiser. ``config.yaml``::

    denoisers:
      - {name: optix_gpu, method: precomputed, label: "OptiX (GPU box)", params: {dir: /data/optix}}

Per case the three results are read by ``pattern`` (default
:data:`mcbench.io.case_folders.RESULT_PATTERN`: ``{dir}/{scene}/spp{spp}/{name}/{name}{image}.exr``,
``{image}`` = "", "A", "B": the full image and the half buffers A and B, the authors' naming),
float32 RGB EXRs of the render's size without NaN/Inf (:func:`mcbench.io.case_folders.read_image`).
Every file of every case is checked when the DAG is parsed (:func:`required_files`), so a missing
case stops the run before any job, naming the file. The recorded time is ``seconds`` (measured
where the results were made; 0 when unknown), not a time measured here.
"""

from __future__ import annotations

import numpy as np

from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.io.case_folders import RESULT_PATTERN, check_result_pattern, read_image, result_files
from mcbench.contracts.method import MethodSpec

_seconds: list[float] = [0.0]


def program_seconds() -> float:
    """The time recorded for the last case: the ``seconds`` it was given."""
    return _seconds[0]


def denoise(buffers: RenderBuffers, *, dir: str, pattern: str = RESULT_PATTERN, seconds: float = 0.0,
            name: str = "precomputed", scene: str = "", spp: int = 0) -> Denoised:
    """The case's three results from their files (the module docstring); ``name``, ``scene`` and
    ``spp`` are filled in by the pipeline (the method's config name and the case)."""
    shape = buffers.layers["color"].shape
    files = result_files(pattern, dir=dir, scene=scene, spp=spp, name=name)
    images = {}
    for image, path in files.items():
        values = read_image(path)
        if values.shape != shape:
            raise ValueError(f"{path}: precomputed result is {values.shape}, the render {buffers.source} is {shape}")
        bad = int((~np.isfinite(values)).any(axis=-1).sum())
        if bad:
            raise ValueError(f"{path}: precomputed result holds NaN/Inf in {bad} pixel(s)")
        images[image] = values
    _seconds[0] = float(seconds)
    return Denoised(full=images["full"], a=images["a"], b=images["b"], source=str(files["full"]))


def check_config(params: dict, *, config_key: str) -> None:
    """Parse-time checks: the pattern's placeholders, a non-negative time."""
    check_result_pattern(params.get("pattern", RESULT_PATTERN), config_key=f"{config_key}.pattern")
    seconds = params.get("seconds", 0.0)
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not (0 <= seconds < float("inf")):
        raise ValueError(f"{config_key}.seconds: must be a finite time >= 0, got {seconds!r}")


def required_files(params: dict, *, name: str, scene: str, spp: int) -> list[str]:
    """The files the case (scene, spp) needs, checked when the DAG is parsed."""
    return [str(p) for p in result_files(params.get("pattern", RESULT_PATTERN), dir=params["dir"], scene=scene,
                                         spp=spp, name=name).values()]


METHOD = MethodSpec(kind="denoiser", label="Precomputed results", run=denoise, render_layers=("color",),
                    warm_up=False, program_seconds=program_seconds, check_config=check_config,
                    required_files=required_files)
