"""Case folders in the layout of the ensemble paper's public program, for programs outside mcbench.

The C++ program of Zheng et al. 2021 (LuisaGroup/Ensemble-Denoising, ``src/main.cpp``) reads one
folder per test case: the noisy half buffers ``colorA.exr`` and ``colorB.exr``, the features
``albedo.exr`` and ``normal.exr`` and, per base denoiser ``d``, ``d/d.exr``, ``d/dA.exr`` and
``d/dB.exr`` (its result on the full image and on the halves A and B). It writes
``blend-raw.exr`` (the raw-weight blend), ``weight-<d>-filtered.exr`` per denoiser and
``blend.exr`` (the result) into its output folder, and with ``-d`` ``guide-var.exr`` into the
case folder. :func:`write_case` writes that layout from this project's render layers and method
outputs, plus what the authors' program does not read but other programs want: the full image
``color.exr``, its per-pixel variance of the mean ``variance.exr`` and ``depth.exr``.

Every file is a single-part scanline OpenEXR of float32 pixels, uncompressed, with the channels
``R``, ``G``, ``B`` (a 1-channel layer such as depth: ``Y``), linear radiance, rows top to bottom:
what OpenCV's ``imread(..., IMREAD_UNCHANGED)`` (the program's reader), tev and the OIDN tools
read without options. The files carry no ``mcbench.*`` checksum (they are for other programs;
:func:`read_image` reads any such file, refusing missing files, wrong channel sets and non-float32
pixels by name).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

import numpy as np
import OpenEXR

from mcbench.io.exr import ExrError, check_finite, write_exr_atomically

__all__ = ["RENDER_FILES", "EXTRA_RENDER_FILES", "RESULT_PATTERN", "write_image", "read_image", "denoiser_files",
           "write_case", "check_denoiser_name", "check_result_pattern", "result_files"]

#: Files of the render that the authors' program reads (file name -> our render layer).
RENDER_FILES = {"colorA.exr": "color_a", "colorB.exr": "color_b", "albedo.exr": "albedo",
                "normal.exr": "normal"}
#: Files of the render that it does not read, written for other programs (mcbench's names).
EXTRA_RENDER_FILES = {"color.exr": "color", "variance.exr": "variance", "depth.exr": "depth"}
#: A denoiser's files in its folder ``<d>/``: file name pattern -> our output image.
DENOISER_FILES = {"{name}.exr": "full", "{name}A.exr": "a", "{name}B.exr": "b"}
#: where results made elsewhere lie, per case (the authors' naming under a scene/spp tree);
#: ``{image}`` is "" for the full image, "A" and "B" for the halves
RESULT_PATTERN = "{dir}/{scene}/spp{spp}/{name}/{name}{image}.exr"
_RESULT_FIELDS = ("dir", "scene", "spp", "name", "image")


def check_denoiser_name(name: str) -> str:
    """``name`` if it can be a folder and file stem of the layout (letters, digits, ``_``, ``-``;
    the program takes the names as a comma-separated ``-m`` list); else ``ValueError``."""
    if not name or not all(c.isalnum() or c in "_-" for c in name) or name[0] == "-":
        raise ValueError(f"denoiser name {name!r}: use letters, digits, '_' and '-' (it names a folder and files)")
    return name


def write_image(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write one image, (H, W, 3) as channels R, G, B or (H, W) as Y, float32, atomically.

    Raises ``ValueError`` for another shape and :class:`mcbench.io.exr.NonFiniteError` for NaN/Inf
    (no program should be handed them)."""
    path = Path(path)
    array = np.ascontiguousarray(image, dtype=np.float32)
    if array.ndim == 3 and array.shape[2] == 1:
        array = np.ascontiguousarray(array[..., 0])
    if not (array.ndim == 2 or (array.ndim == 3 and array.shape[2] == 3)) or 0 in array.shape:
        raise ValueError(f"{path}: image of shape {np.shape(image)}; expected (H, W, 3) or (H, W)")
    check_finite(path, {"image": array})
    channels = {"RGB": array} if array.ndim == 3 else {"Y": array}
    header = {"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}
    path.parent.mkdir(parents=True, exist_ok=True)
    write_exr_atomically(path, header, channels)


def read_image(path: str | os.PathLike, *, allow_half: bool = False, allow_xyz: bool = False) -> np.ndarray:
    """Read a single-part R, G, B (-> (H, W, 3)) or Y (-> (H, W)) float EXR as float32.

    Other channels (e.g. A) are ignored; a file without R, G, B or Y, with half/uint pixels, or
    missing/corrupt raises :class:`mcbench.io.exr.ExrError` naming it. ``allow_half``: half pixels
    are read too (converted exactly); ``allow_xyz``: channels X, Y, Z stand for R, G, B (normals
    written by other programs)."""
    path = Path(path)
    if not path.is_file():
        raise ExrError(f"{path}: EXR file is missing")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = {name: np.asarray(ch.pixels) for name, ch in exr.channels().items()}
    except Exception as exc:  # the bindings raise a bare Exception on corrupt files
        raise ExrError(f"{path}: cannot read EXR ({exc})") from exc
    sets = (["R", "G", "B"], *([["X", "Y", "Z"]] if allow_xyz else []), ["Y"])
    names = next((n for n in sets if all(c in channels for c in n)), None)
    if names is None:
        raise ExrError(f"{path}: no {' or '.join(', '.join(n) for n in sets)} channels; file has {sorted(channels)}")
    allowed = (np.float32, np.float16) if allow_half else (np.float32,)
    for name in names:
        if channels[name].dtype not in allowed:
            raise ExrError(f"{path}: channel {name} holds {channels[name].dtype} pixels, expected "
                           + ("float (32-bit or half)" if allow_half else
                              "float32 (write the file with 32-bit float channels)"))
    if len(names) == 1:
        return np.ascontiguousarray(channels[names[0]], dtype=np.float32)
    return np.ascontiguousarray(np.stack([channels[c] for c in names], axis=-1), dtype=np.float32)


def denoiser_files(folder: str | os.PathLike, name: str) -> dict[str, Path]:
    """Paths of denoiser ``name``'s files in case ``folder``: ``{"full": d/d.exr, "a": d/dA.exr,
    "b": d/dB.exr}``."""
    check_denoiser_name(name)
    return {image: Path(folder) / name / pattern.format(name=name) for pattern, image in DENOISER_FILES.items()}


def write_case(folder: str | os.PathLike, render_layers: Mapping[str, np.ndarray],
               denoised: Mapping[str, object] | None = None, *, extra_files: bool = True) -> list[Path]:
    """Write one test case in the authors' layout into ``folder``; returns the files written.

    ``render_layers``: our render's layers (:mod:`mcbench.io.buffers` names), at least those of
    :data:`RENDER_FILES` (and of :data:`EXTRA_RENDER_FILES` with ``extra_files``).
    ``denoised``: denoiser name -> its output, a :class:`mcbench.io.buffers.Denoised` or any
    object with ``full``, ``a``, ``b`` (H, W, 3) images; each goes to ``name/name{,A,B}.exr``.
    Every image must have the shape of ``colorA``; a missing layer or a mismatch raises
    ``ValueError`` naming it before anything is written."""
    folder = Path(folder)
    files = dict(RENDER_FILES, **(EXTRA_RENDER_FILES if extra_files else {}))
    missing = [layer for layer in files.values() if layer not in render_layers]
    if missing:
        raise ValueError(f"{folder}: the render has no layer(s) {missing} for the authors' layout")
    shape = np.shape(render_layers["color_a"])[:2]
    images: dict[Path, np.ndarray] = {folder / name: np.asarray(render_layers[layer])
                                      for name, layer in files.items()}
    for name, result in (denoised or {}).items():
        for image, path in denoiser_files(folder, name).items():
            images[path] = np.asarray(getattr(result, image))
    for path, image in images.items():
        if image.shape[:2] != shape:
            raise ValueError(f"{path}: image is {image.shape[:2]}, colorA is {shape}")
    for path, image in images.items():
        write_image(path, image)
    return list(images)


def check_result_pattern(pattern: str, *, config_key: str = "params.pattern") -> str:
    """``pattern`` if its placeholders are among dir, scene, spp, name, image and it holds
    ``{image}`` (the three results need three files); else ``ValueError`` naming ``config_key``."""
    import string

    if not isinstance(pattern, str):
        raise ValueError(f"{config_key}: must be a string like {RESULT_PATTERN!r}, got {pattern!r}")
    try:
        fields = [f for _, f, _, _ in string.Formatter().parse(pattern) if f is not None]
    except ValueError as exc:
        raise ValueError(f"{config_key}: {pattern!r} is not a valid template ({exc})") from None
    unknown = [f for f in fields if f not in _RESULT_FIELDS]
    if unknown or "image" not in fields:
        raise ValueError(f"{config_key}: {pattern!r} must use only {{{'}, {'.join(_RESULT_FIELDS)}}} and hold "
                         f"{{image}} (\"\", \"A\", \"B\"); unknown: {unknown}")
    return pattern


def result_files(pattern: str, *, dir: str, scene: str, spp: int, name: str) -> dict[str, Path]:
    """The files of one case's results by ``pattern`` (:data:`RESULT_PATTERN`): ``{"full", "a",
    "b"}`` -> path."""
    check_result_pattern(pattern)
    return {image: Path(pattern.format(dir=dir, scene=scene, spp=spp, name=name, image=suffix))
            for image, suffix in (("full", ""), ("a", "A"), ("b", "B"))}
