"""Renders made by another renderer (pbrt, Tungsten, Falcor, ...) as the scenes of a study.

A scene file ``scenes/<name>.yaml`` names a folder of OpenEXR renders instead of a scene to
render::

    description: pbrt-v4 kitchen, glossy inter-reflections    # one line (optional)
    category: renders                                        # optional
    renders: ../data/kitchen     # the folder, relative to this file (or absolute, ~ allowed)
    layout: authors              # authors | oidn
    stem: kitchen                # oidn only: the files' name stem (default: the scene's name)

Two layouts are read, both single-part float EXRs with channels R, G, B (a one-channel image:
Y; normals may be X, Y, Z), float32 or half pixels (converted exactly to float32):

``authors`` -- the case folders of the ensemble paper's public program (LuisaGroup/Ensemble-
  Denoising, ``src/main.cpp``), one per spp, as :mod:`mcbench.io.case_folders` writes them
  (``snakemake export_cases``)::

      <renders>/spp<N>/colorA.exr colorB.exr albedo.exr normal.exr      the program's inputs
                       color.exr variance.exr depth.exr                 optional (mcbench's)
                       varianceA.exr varianceB.exr                      optional (mcbench's)
      <renders>/reference.exr [reference_variance.exr]

  The half buffers hold N/2 disjoint samples each; without ``color.exr`` the full image is their
  mean ``(colorA + colorB) / 2`` (what the program's full image is when both halves have N/2
  samples). ``variance*`` is the per-pixel variance *of the mean*, as in
  :mod:`mcbench.io.buffers`.

``oidn`` -- the naming of Open Image Denoise's training toolkit (``training/dataset.py``: an
  image ``<stem>_<suffix>.<feature>.exr`` with the suffix the spp, plain or zero-padded digits or
  ``<N>spp``, and ``ref``/``reference``/``gt``/``target`` for the reference)::

      <renders>/<stem>_<N>.hdr.exr  <stem>_<N>.alb.exr  <stem>_<N>.nrm.exr
      <renders>/<stem>_ref.hdr.exr

  No half buffers, no variance, no depth: such a scene can be ranked with single-image denoisers
  that read only colour, albedo and normal (``oidn``), never with a method that needs what is not
  there (the pipeline refuses that combination when the DAG is parsed, naming the missing files).

Nothing is fed in place of a missing layer: :func:`case_files` says which layers a case has, and
:func:`read_case` returns only those. Every file of every case is checked when read (missing,
corrupt, wrong channels, NaN/Inf, sizes that disagree) with the file named.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import numpy as np

from mcbench import BenchError
from mcbench.contracts.scene import SceneSpec
from mcbench.io.exr import ExrError, check_finite

__all__ = ["LAYOUTS", "AUTHORS_FILES", "OIDN_FEATURES", "REFERENCE_SUFFIXES", "RenderFolder",
           "scene_module", "case_files", "reference_files", "read_image_any", "read_case",
           "read_reference", "reference_names", "image_size", "reference_resolution"]

LAYOUTS = ("authors", "oidn")
#: A case folder's files in the authors' layout -> our render layer (:mod:`mcbench.io.buffers`).
AUTHORS_FILES = {"colorA.exr": "color_a", "colorB.exr": "color_b", "albedo.exr": "albedo",
                 "normal.exr": "normal", "color.exr": "color", "variance.exr": "variance",
                 "varianceA.exr": "variance_a", "varianceB.exr": "variance_b", "depth.exr": "depth"}
#: The files the authors' program itself reads: a case folder must hold them.
AUTHORS_REQUIRED = ("colorA.exr", "colorB.exr", "albedo.exr", "normal.exr")
#: The OIDN toolkit's features -> our render layer.
OIDN_FEATURES = {"hdr": "color", "alb": "albedo", "nrm": "normal"}
#: Suffixes the OIDN toolkit reads as the reference (``training/dataset.py``).
REFERENCE_SUFFIXES = ("ref", "reference", "gt", "target")
_SCENE_KEYS = {"description", "category", "renders", "layout", "stem"}


@dataclass(frozen=True)
class RenderFolder:
    """A folder of renders: ``path`` (absolute), ``layout`` (one of :data:`LAYOUTS`), ``stem``
    (the OIDN naming's file stem) and ``source`` (the scene file that names it, for messages)."""
    path: Path
    layout: str
    stem: str
    source: str

    def __str__(self) -> str:
        return f"{self.path} ({self.layout} layout, named by {self.source})"


def _scene_file_values(path: Path) -> dict:
    import yaml

    try:
        values = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise BenchError(f"{path}: cannot read the scene file ({exc})") from None
    if not isinstance(values, dict):
        raise BenchError(f"{path}: a scene file of renders is a mapping with keys renders, layout "
                         f"(and optionally description, category, stem)")
    unknown = sorted(set(values) - _SCENE_KEYS)
    if unknown:
        raise BenchError(f"{path}: unknown key(s) {unknown}; known: {sorted(_SCENE_KEYS)}")
    for key in ("renders", "layout"):
        if not isinstance(values.get(key), str) or not values[key]:
            raise BenchError(f"{path}: key '{key}' must be given as a string")
    if values["layout"] not in LAYOUTS:
        raise BenchError(f"{path}: key 'layout' is {values['layout']!r}; one of {', '.join(LAYOUTS)}")
    for key in ("description", "category", "stem"):
        if key in values and not isinstance(values[key], str):
            raise BenchError(f"{path}: key '{key}' must be a string")
    return values


def scene_module(path: str | os.PathLike) -> ModuleType:
    """A scene module for the scene file ``path`` (YAML, keys in the module docstring): its
    ``SCENE`` (:class:`mcbench.contracts.scene.SceneSpec`) has a ``description``, ``category``,
    ``render_folder`` (a :class:`RenderFolder`), ``resolution`` (the size of its reference image,
    read from the header when asked) and a ``build`` that refuses (these scenes are not rendered).
    The folder itself is checked case by case (:func:`case_files`), when the DAG is parsed."""
    path = Path(path)
    values = _scene_file_values(path)
    folder = Path(os.path.expanduser(values["renders"]))
    if not folder.is_absolute():
        folder = (path.parent / folder).resolve()
    render_folder = RenderFolder(path=folder, layout=values["layout"], stem=values.get("stem", path.stem),
                                 source=str(path))
    module = ModuleType(path.stem, f"renders of {folder} ({path})")
    module.__file__ = str(path)

    def build(width=None, height=None):
        raise BenchError(f"scene '{path.stem}' ({path}) is a folder of renders, not a scene to render "
                         f"(the oracle study and progressive denoising's curve render their scene again: "
                         f"give them a Mitsuba scene)")

    module.SCENE = SceneSpec(description=values.get("description", f"renders from {folder}"),
                             category=values.get("category", "renders"),
                             resolution=lambda: reference_resolution(render_folder), build=build,
                             render_folder=render_folder)
    return module


def reference_resolution(folder: RenderFolder) -> tuple[int, int]:
    """``(width, height)`` of the folder's reference image, read from its header."""
    files = reference_files(folder)
    if "color" not in files:
        raise BenchError(f"{folder}: no reference image ({reference_names(folder)})")
    height, width = image_size(files["color"])
    return width, height


def _case_dir(folder: RenderFolder, spp: int) -> Path:
    return folder.path / f"spp{spp}"


def _oidn_spp(token: str) -> int | None:
    token = token.lower()
    if token.endswith("spp"):
        token = token[:-3]
    return int(token) if token.isdecimal() else None


def _oidn_files(folder: RenderFolder) -> dict[tuple[str, str], Path]:
    """``(suffix, feature) -> path`` of the OIDN-named files of ``folder.stem`` in the folder."""
    pattern = re.compile(rf"{re.escape(folder.stem)}_([A-Za-z0-9]+)\.([a-z0-9]+)\.exr")
    found = {}
    if folder.path.is_dir():
        for entry in sorted(folder.path.iterdir()):
            match = pattern.fullmatch(entry.name)
            if match and match.group(2) in OIDN_FEATURES:
                found[(match.group(1).lower(), match.group(2))] = entry
    return found


def case_files(folder: RenderFolder, spp: int) -> tuple[dict[str, Path], list[str]]:
    """The files of the case at ``spp``: ``({layer: path}, [missing required files])``.

    ``layer`` names are :mod:`mcbench.io.buffers`'s (``color_a``, ``albedo``, ...). Required: the
    authors' program's four inputs (authors' layout), the colour image (OIDN naming); the rest
    is what the folder happens to hold. Reads no pixels."""
    if folder.layout == "authors":
        case = _case_dir(folder, spp)
        files = {layer: case / name for name, layer in AUTHORS_FILES.items() if (case / name).is_file()}
        missing = [str(case / name) for name in AUTHORS_REQUIRED if not (case / name).is_file()]
        return files, missing
    matches = {}
    for (suffix, feature), path in _oidn_files(folder).items():
        if _oidn_spp(suffix) == spp:
            if OIDN_FEATURES[feature] in matches:
                raise BenchError(f"{folder}: two files for {feature} at {spp} spp: "
                                 f"{matches[OIDN_FEATURES[feature]].name} and {path.name}")
            matches[OIDN_FEATURES[feature]] = path
    missing = [] if "color" in matches else [str(folder.path / f"{folder.stem}_{spp}.hdr.exr")]
    return matches, missing


def reference_names(folder: RenderFolder) -> str:
    """Where the reference of ``folder`` is looked for, as a message names it."""
    if folder.layout == "authors":
        return str(folder.path / "reference.exr")
    return " or ".join(f"{folder.path / folder.stem}_{s}.hdr.exr" for s in REFERENCE_SUFFIXES)


def reference_files(folder: RenderFolder) -> dict[str, Path]:
    """The reference's files: ``{"color": path[, "variance": path]}`` (empty when it has none;
    the variance of the reference's mean is optional: the corrected relMSE needs it)."""
    if folder.layout == "authors":
        files = {"color": folder.path / "reference.exr", "variance": folder.path / "reference_variance.exr"}
        return {k: p for k, p in files.items() if p.is_file()}
    found = [path for (suffix, feature), path in _oidn_files(folder).items()
             if feature == "hdr" and suffix in REFERENCE_SUFFIXES]
    if len(found) > 1:
        raise BenchError(f"{folder}: more than one reference: {', '.join(p.name for p in found)}")
    return {"color": found[0]} if found else {}


def image_size(path: str | os.PathLike) -> tuple[int, int]:
    """``(height, width)`` of an EXR from its header (no pixels read); ExrError naming it."""
    import OpenEXR

    path = Path(path)
    try:
        with OpenEXR.File(str(path), header_only=True) as exr:
            (x0, y0), (x1, y1) = exr.header()["dataWindow"]
    except Exception as exc:  # the bindings raise a bare Exception on corrupt files
        raise ExrError(f"{path}: cannot read EXR header ({exc})") from exc
    return int(y1) - int(y0) + 1, int(x1) - int(x0) + 1


def read_image_any(path: str | os.PathLike) -> np.ndarray:
    """One image of another renderer: R, G, B (or X, Y, Z) -> (H, W, 3), Y -> (H, W); float32 or
    half pixels, returned as float32 (half converts exactly). Missing/corrupt files, other channel
    sets and integer pixels raise :class:`mcbench.io.exr.ExrError` naming the file."""
    from mcbench.io.case_folders import read_image

    image = read_image(path, allow_half=True, allow_xyz=True)
    check_finite(path, {"image": image})
    return image


def _as_layer(path: Path, image: np.ndarray, layer: str) -> np.ndarray:
    """``image`` in the shape of ``layer``: depth (H, W) from a Y image (or a grey R=G=B one),
    every other layer (H, W, 3)."""
    if layer == "depth":
        if image.ndim == 3:
            if not (np.array_equal(image[..., 0], image[..., 1]) and np.array_equal(image[..., 0], image[..., 2])):
                raise ExrError(f"{path}: depth must be one channel (Y) or three equal ones")
            image = image[..., 0]
        return np.ascontiguousarray(image)
    if image.ndim != 3:
        raise ExrError(f"{path}: {layer} needs three channels (R, G, B), the file has one")
    return image


def read_case(folder: RenderFolder, spp: int) -> dict[str, np.ndarray]:
    """Every layer the case at ``spp`` holds, float32, named as :mod:`mcbench.io.buffers` names
    them; ``color`` is ``(color_a + color_b) / 2`` where the folder gives the halves but not the
    full image. Raises :class:`mcbench.BenchError` naming the file for a missing required file,
    unreadable or non-finite pixels, or images whose sizes disagree."""
    files, missing = case_files(folder, spp)
    if missing:
        raise BenchError(f"{folder}: the case at {spp} spp lacks {', '.join(missing)}")
    layers = {layer: _as_layer(path, read_image_any(path), layer) for layer, path in files.items()}
    sizes = {layer: image.shape[:2] for layer, image in layers.items()}
    first = next(iter(files))
    for layer, size in sizes.items():
        if size != sizes[first]:
            raise BenchError(f"{files[layer]}: {size[1]}x{size[0]} pixels, but {files[first]} is "
                             f"{sizes[first][1]}x{sizes[first][0]}")
    if "color" not in layers:
        layers["color"] = (layers["color_a"] + layers["color_b"]) / np.float32(2)
    for name in [n for n in layers if n.startswith("variance")]:
        if (layers[name] < 0).any():
            raise BenchError(f"{files[name]}: negative variance")
    return layers


def read_reference(folder: RenderFolder) -> dict[str, np.ndarray]:
    """The reference: ``{"color": (H, W, 3)[, "variance": (H, W, 3)]}`` float32, checked like a
    case (missing, unreadable, non-finite, sizes, negative variance), the file named."""
    files = reference_files(folder)
    if "color" not in files:
        raise BenchError(f"{folder}: no reference image ({reference_names(folder)})")
    layers = {layer: _as_layer(path, read_image_any(path), layer) for layer, path in files.items()}
    if "variance" in layers:
        if layers["variance"].shape != layers["color"].shape:
            raise BenchError(f"{files['variance']}: {layers['variance'].shape[:2]} pixels, the reference "
                             f"{files['color']} is {layers['color'].shape[:2]}")
        if (layers["variance"] < 0).any():
            raise BenchError(f"{files['variance']}: negative variance")
    return layers
