"""The work behind ``workflow/rules/export.smk``: every test case in the layout of the ensemble
paper's public program (:mod:`mcbench.io.case_folders`), so that their C++ tool, tev or any other
program can read this project's renders and results.

One folder per case, ``results/export/<scene>/spp<N>/``: ``colorA.exr``, ``colorB.exr``,
``albedo.exr``, ``normal.exr`` (what the authors' program reads), ``color.exr``, ``variance.exr``,
``depth.exr`` (the full image, its per-pixel variance of the mean, the depth), ``reference.exr``
(the case's reference), and per candidate ``d``: ``d/d.exr``, ``d/dA.exr``, ``d/dB.exr`` (its
result on the full image and on the halves A and B). E.g. the authors' program on an exported
case: ``OPENCV_IO_ENABLE_OPENEXR=1 EnsembleDenoising -i results/export/cornell_box/spp64 -o out
-m nfor,oidn,rdfc -s fbstab``.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.io.case_folders import EXTRA_RENDER_FILES, RENDER_FILES, write_case, write_image
from mcbench.io.exr import check_finite, check_resolution, read_layers

__all__ = ["REFERENCE_FILE", "export_case"]

REFERENCE_FILE = "reference.exr"


def export_case(render_path: str, candidates: dict[str, str], output_dir: str, *,
                reference_path: str | None = None) -> list[Path]:
    """Write one case (the render at ``render_path``, the method outputs ``candidates``: name ->
    EXR, and the reference) in the authors' layout into ``output_dir``; returns the files, relative
    to it. Every input is read and checked (missing or damaged files, NaN/Inf, shapes) before
    anything is written; the folder appears whole or not at all (written beside it, then renamed)."""
    layers = tuple(dict.fromkeys([*RENDER_FILES.values(), *EXTRA_RENDER_FILES.values()]))
    buffers = RenderBuffers.load(render_path, layers=layers)
    outputs = {name: Denoised.load(path) for name, path in candidates.items()}
    reference = None
    if reference_path is not None:
        reference = read_layers(reference_path, ["color"])
        check_finite(reference_path, reference)
        check_resolution(reference_path, reference["color"].shape)
    output = Path(output_dir)
    output.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{output.name}.", dir=output.parent))
    try:
        files = write_case(staging, buffers.layers, outputs)
        if reference is not None:
            if reference["color"].shape != buffers.layers["color_a"].shape:
                raise ValueError(f"{reference_path}: reference is {reference['color'].shape[:2]}, "
                                 f"the render {render_path} is {buffers.layers['color_a'].shape[:2]}")
            write_image(staging / REFERENCE_FILE, reference["color"])
            files.append(staging / REFERENCE_FILE)
        if output.exists():
            shutil.rmtree(output)
        os.replace(staging, output)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return [f.relative_to(staging) for f in files]
