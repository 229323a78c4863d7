"""Run a denoiser that is a program outside mcbench on one case, through files.

The case goes to the program as a folder in the layout of :mod:`mcbench.io.case_folders` (the
ensemble paper's program's layout, extended with the full image, its variance and the depth);
the program writes its results as EXRs into an output folder, and :func:`read_results` checks
them (present, float32 R, G, B, finite, the render's size) before anyone uses them.

The command is an argument list (never a shell line) whose items may hold the placeholders of
:data:`PLACEHOLDERS`, e.g. ``["{python}", "{workdir}/examples/box_denoiser/box_filter.py",
"--in", "{input_dir}", "--out", "{output_dir}", "--name", "{name}"]``. It runs with the case's
temporary folder as working directory, a timeout, stdin closed, and its output captured; any
failure (cannot start, non-zero exit, timeout, missing/damaged/NaN/wrongly sized output) raises
:class:`ExternalProgramError` naming the command, the case and the program's last stderr lines.
"""

from __future__ import annotations

import os
import string
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from mcbench import BenchError
from mcbench.io.case_folders import check_denoiser_name, read_image
from mcbench.io.exr import ExrError

__all__ = ["PLACEHOLDERS", "STDERR_LINES", "ExternalProgramError", "check_command", "expand_command",
           "run_program", "read_results"]

#: what a command item may name: the case's input folder, the folder the program must write to,
#: the method's name (its output file stem), this Python interpreter and the workflow's folder
PLACEHOLDERS = ("input_dir", "output_dir", "name", "python", "workdir")
STDERR_LINES = 20     # the program's last stderr lines quoted in an error


class ExternalProgramError(BenchError):
    """An external program failed on a case; the message names the command, the case and the
    program's last stderr lines."""


def check_command(command, *, config_key: str = "params.command") -> list[str]:
    """``command`` as a list of strings, its placeholders among :data:`PLACEHOLDERS`; else
    ``ValueError`` naming ``config_key`` (called when the config is read and before each run)."""
    if isinstance(command, str) or not isinstance(command, (list, tuple)) or not command:
        raise ValueError(f"{config_key}: the command must be a non-empty list of arguments (no shell line), "
                         f"e.g. [./my_denoiser, --in, '{{input_dir}}', --out, '{{output_dir}}'], got {command!r}")
    for i, item in enumerate(command):
        if not isinstance(item, str):
            raise ValueError(f"{config_key}[{i}]: every argument must be a string, got {item!r}")
        try:
            names = [field for _, field, _, _ in string.Formatter().parse(item) if field is not None]
        except ValueError as exc:
            raise ValueError(f"{config_key}[{i}]: {item!r} is not a valid template ({exc}); write literal "
                             f"braces as {{{{ and }}}}") from None
        unknown = [n for n in names if n not in PLACEHOLDERS]
        if unknown:
            raise ValueError(f"{config_key}[{i}]: unknown placeholder(s) {unknown} in {item!r}; "
                             f"use {', '.join('{' + p + '}' for p in PLACEHOLDERS)}")
    return list(command)


def expand_command(command, *, input_dir, output_dir, name: str, workdir=None) -> list[str]:
    """The command with its placeholders filled in (``workdir`` default: the current folder)."""
    values = {"input_dir": str(input_dir), "output_dir": str(output_dir), "name": check_denoiser_name(name),
              "python": sys.executable, "workdir": str(workdir if workdir is not None else os.getcwd())}
    return [item.format(**values) for item in check_command(command)]


def _tail(text: str) -> str:
    lines = (text or "").strip().splitlines()[-STDERR_LINES:]
    return "\n".join(f"    {line}" for line in lines) if lines else "    (nothing on stderr)"


def run_program(command: list[str], *, cwd, timeout: float, case: str) -> float:
    """Run ``command`` (already expanded) in ``cwd``; returns its wall time in seconds.
    Raises :class:`ExternalProgramError` (command, case, last stderr lines) when it cannot start,
    exits non-zero or runs past ``timeout`` seconds (it is killed)."""
    shown = " ".join(command)
    start = time.perf_counter()
    try:
        done = subprocess.run(command, cwd=cwd, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                              timeout=timeout, errors="replace")
    except FileNotFoundError as exc:
        raise ExternalProgramError(f"external denoiser on {case}: cannot start `{shown}` ({exc})") from None
    except PermissionError as exc:
        raise ExternalProgramError(f"external denoiser on {case}: cannot run `{shown}` ({exc})") from None
    except subprocess.TimeoutExpired as exc:
        stderr = exc.stderr.decode(errors="replace") if isinstance(exc.stderr, bytes) else exc.stderr
        raise ExternalProgramError(f"external denoiser on {case}: `{shown}` ran past its timeout of "
                                   f"{timeout:g} s and was killed; its last stderr lines:\n{_tail(stderr)}") from None
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise ExternalProgramError(f"external denoiser on {case}: `{shown}` exited with status {done.returncode}; "
                                   f"its last stderr lines:\n{_tail(done.stderr)}")
    return seconds


def read_results(output_dir, files: dict[str, str], shape: tuple[int, int], *, command: list[str],
                 case: str) -> dict[str, np.ndarray]:
    """Read the program's results ``files`` (key -> file name in ``output_dir``), each an
    (H, W, 3) float32 RGB EXR of ``shape`` (H, W) without NaN/Inf. Returns key -> image; any
    failure raises :class:`ExternalProgramError` naming the file, the command and the case."""
    shown = " ".join(command)
    images = {}
    for key, file in files.items():
        path = Path(output_dir) / file
        try:
            image = read_image(path)
        except ExrError as exc:
            written = sorted(p.name for p in Path(output_dir).iterdir()) if Path(output_dir).is_dir() else []
            raise ExternalProgramError(f"external denoiser on {case}: `{shown}` did not write a usable {file} "
                                       f"({exc}); it wrote {written or 'nothing'}") from None
        if image.ndim != 3 or image.shape[:2] != tuple(shape):
            raise ExternalProgramError(f"external denoiser on {case}: {path} is {image.shape}, the render is "
                                       f"{tuple(shape)} x 3 (`{shown}`)")
        bad = int((~np.isfinite(image)).any(axis=-1).sum())
        if bad:
            raise ExternalProgramError(f"external denoiser on {case}: {path} holds NaN/Inf in {bad} pixel(s) "
                                       f"(`{shown}`)")
        images[key] = image
    return images
