"""A base denoiser that is a program outside mcbench (any language, any framework), run on each
case through files. ``config.yaml``::

    denoisers:
      - {name: box, method: external, label: "Box filter (example)",
         params: {command: ["{python}", "{workdir}/examples/box_denoiser/box_filter.py",
                            "--in", "{input_dir}", "--out", "{output_dir}", "--name", "{name}"]}}

Per case the harness writes the render into a temporary folder in the layout of
:mod:`mcbench.io.case_folders` (``colorA.exr``, ``colorB.exr``, ``albedo.exr``, ``normal.exr`` -- what
the ensemble paper's program reads -- and ``color.exr``, ``variance.exr``, ``depth.exr``; float32
RGB EXRs), runs the command (placeholders :data:`mcbench.io.external_program.PLACEHOLDERS`; no
shell; working directory the temporary folder; ``timeout`` seconds) and reads what it wrote into
``{output_dir}``: ``<name>.exr``, ``<name>A.exr``, ``<name>B.exr``, the results on the full image
and on the half buffers A and B (``<name>`` is the method's config name). With
``per_image: true`` the program denoises one image per call and is called three times (full, A,
B), each time with an input folder of that image alone (``color.exr``, ``variance.exr``,
``albedo.exr``, ``normal.exr``, ``depth.exr``: a half buffer's own features), writing
``<name>.exr``.

The time recorded for the method is the program's wall time (all its calls), not the harness's
file writing and reading (``METHOD.program_seconds``). A failure stops the job naming the command, the
case and the program's last stderr lines (:class:`mcbench.io.external_program.ExternalProgramError`).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from mcbench.io.buffers import BUFFER_SUFFIXES, Denoised, RenderBuffers
from mcbench.io.case_folders import write_case, write_image
from mcbench.io.external_program import check_command, expand_command, read_results, run_program
from mcbench.contracts.method import MethodSpec

_IMAGE_FILES = {"full": "{name}.exr", "a": "{name}A.exr", "b": "{name}B.exr"}
_seconds: list[float] = []


def program_seconds() -> float:
    """Wall seconds of the program's calls in the last :func:`denoise`."""
    return float(sum(_seconds))


def denoise(buffers: RenderBuffers, *, command: list[str], name: str = "external", timeout: float = 3600.0,
            per_image: bool = False, workdir: str = "") -> Denoised:
    """Run the program on the case (the module docstring); ``name`` is the output file stem (the
    pipeline passes the method's config name), ``workdir`` the value of ``{workdir}`` (default: the
    job's working directory). Returns its three results as float32 (H, W, 3) images."""
    command = check_command(command, config_key=f"method '{name}': params.command")
    if not timeout > 0:
        raise ValueError(f"method '{name}': params.timeout must be > 0 seconds, got {timeout!r}")
    shape = buffers.layers["color"].shape[:2]
    case = buffers.source
    _seconds.clear()
    with tempfile.TemporaryDirectory(prefix="mcbench-external-") as folder:
        folder = Path(folder)
        if not per_image:
            write_case(folder / "input", buffers.layers)
            (folder / "output").mkdir()
            expanded = expand_command(command, input_dir=folder / "input", output_dir=folder / "output",
                                      name=name, workdir=workdir or None)
            _seconds.append(run_program(expanded, cwd=folder, timeout=timeout, case=case))
            images = read_results(folder / "output", {k: f.format(name=name) for k, f in _IMAGE_FILES.items()},
                                  shape, command=expanded, case=case)
        else:
            images = {}
            for image, suffix in BUFFER_SUFFIXES.items():
                inputs, outputs = folder / f"input_{image}", folder / f"output_{image}"
                for quantity in ("color", "variance", "albedo", "normal", "depth"):
                    write_image(inputs / f"{quantity}.exr", buffers.layers[quantity + suffix])
                outputs.mkdir()
                expanded = expand_command(command, input_dir=inputs, output_dir=outputs, name=name,
                                          workdir=workdir or None)
                _seconds.append(run_program(expanded, cwd=folder, timeout=timeout, case=f"{case} (image {image})"))
                images.update(read_results(outputs, {image: f"{name}.exr"}, shape, command=expanded,
                                           case=f"{case} (image {image})"))
    return Denoised(full=images["full"], a=images["a"], b=images["b"], source=f"external program {command[0]}")


def check_config(params: dict, *, config_key: str) -> None:
    """Parse-time checks (``methods.check_params``): the command is a list of arguments with known
    placeholders, the timeout positive."""
    check_command(params.get("command"), config_key=f"{config_key}.command")
    timeout = params.get("timeout", 3600.0)
    if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not timeout > 0:
        raise ValueError(f"{config_key}.timeout: must be > 0 seconds, got {timeout!r}")


METHOD = MethodSpec(
    kind="denoiser", label="External program", run=denoise, check_config=check_config,
    render_layers=tuple(q + s for q in ("color", "variance", "albedo", "normal", "depth") for s in BUFFER_SUFFIXES.values()),
    # no untimed warm-up run on a crop: a program's start-up is part of what it costs
    warm_up=False,
    # the time recorded is the program's wall time, not the whole call's
    program_seconds=program_seconds)
