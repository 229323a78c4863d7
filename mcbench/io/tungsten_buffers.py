"""Render buffers as input folders ("cases") for Tungsten's NFOR ``denoiser``, and PFM files.

Tungsten's ``denoiser`` (tunabrain/tungsten, ``src/denoiser/denoiser.cpp``, the authors' public
re-implementation of NFOR, Bitterli et al. 2016) reads a scene file whose ``renderer`` block lists
``output_buffers``; for every entry with an ``hdr_output_file`` ``X.pfm`` and both
``sample_variance`` and ``two_buffer_variance`` set, it loads four images
(``denoiser.cpp:147-165``, names as the renderer writes them, ``OutputBuffer.hpp:150-155``):

* ``X.pfm``          the full-buffer mean (all n samples);
* ``XA.pfm``/``XB.pfm`` the means of the two half buffers (n/2 samples each);
* ``XVariance.pfm``  the sample variance *of the full-buffer mean*, M2 / (n (n - 1))
  (``OutputBuffer.hpp:179-182``).

The ``color`` entry is the image; every other entry is a feature (``normal`` and ``albedo``: three
scalar features each, ``depth``: one), in the order of the scene file. Every file is loaded as RGB;
a one-channel ``Pf`` file is replicated to three channels and a scalar feature uses channel 0.

Our layers (:mod:`mcbench.io.buffers`) map one to one: ``color``/``color_a``/``color_b``/
``variance`` -> ``color``, ``colorA``, ``colorB``, ``colorVariance`` and, for q in normal, albedo,
depth, ``q``/``q_a``/``q_b``/``q_variance`` -> ``q``, ``qA``, ``qB``, ``qVariance``. Our
``variance`` and ``q_variance`` layers are variances of the full-buffer mean, the same quantity
as Tungsten's. Where a render lacks ``q_variance``, :func:`case_layers` derives it as
(q_a - q_b)^2 / 4, an unbiased estimate of the variance of (q_a + q_b) / 2 from the two
independent halves; the derived values are what the case stores, so a comparison that reads
the case back (:func:`read_case`) uses exactly the values Tungsten saw.

Two extra files, ignored by Tungsten, keep the half buffers' own colour variances
(``variance_a``/``variance_b``) so that our NFOR's default estimator can run on a case too:
``colorVarianceOfA.pfm`` and ``colorVarianceOfB.pfm``.

PFM (``.pfm``, "portable float map"): an ASCII header ``PF`` (three channels) or ``Pf`` (one),
``width height``, and a scale whose sign gives the byte order (negative: little-endian), each on
its own line, then float32 pixels row by row from the **bottom** row up. Tungsten writes and
reads float32 PFMs (``ImageIO.cpp:298-337,528-544``; it reads native byte order and skips the
scale), whereas its ``.exr`` output is half precision: cases and outputs use PFM only.

Arrays are float32, (H, W, 3) or (H, W), row 0 at the top (the project's convention).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

__all__ = ["write_pfm", "read_pfm", "case_layers", "write_case", "read_case", "TUNGSTEN_BUFFERS",
           "SCENE_FILE", "EXTRA_FILES"]

#: Tungsten buffer stem -> (full, A, B, variance-of-the-full-mean) layer names, in scene-file order.
#: The feature order (normal, albedo, depth) is the order of ``methods/nfor.py``'s features.
TUNGSTEN_BUFFERS = {
    "color": ("color", "color_a", "color_b", "variance"),
    "normal": ("normal", "normal_a", "normal_b", "normal_variance"),
    "albedo": ("albedo", "albedo_a", "albedo_b", "albedo_variance"),
    "depth": ("depth", "depth_a", "depth_b", "depth_variance"),
}
#: Files Tungsten ignores: our half buffers' own colour variances (file stem -> layer).
EXTRA_FILES = {"colorVarianceOfA": "variance_a", "colorVarianceOfB": "variance_b"}
SCENE_FILE = "scene.json"
_SUFFIXES = ("", "A", "B", "Variance")


def write_pfm(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write ``image`` ((H, W) -> ``Pf``, (H, W, 3) -> ``PF``) as a little-endian float32 PFM
    (scale -1), rows bottom to top. Values are cast to float32."""
    image = np.asarray(image, dtype=np.float32)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3):
        raise ValueError(f"{path}: PFM holds (H, W) or (H, W, 3) images, got {image.shape}")
    h, w = image.shape[:2]
    header = f"{'PF' if image.ndim == 3 else 'Pf'}\n{w} {h}\n-1\n".encode("ascii")
    data = np.ascontiguousarray(image[::-1], dtype="<f4").tobytes()
    Path(path).write_bytes(header + data)


def read_pfm(path: str | os.PathLike) -> np.ndarray:
    """Read a float32 PFM: (H, W, 3) for ``PF``, (H, W) for ``Pf``, row 0 at the top.

    The byte order follows the sign of the scale (negative: little-endian). ValueError names
    the file when the header or the size is wrong."""
    raw = Path(path).read_bytes()
    fields, pos = [], 0
    while len(fields) < 4:                        # ident, width, height, scale
        while pos < len(raw) and raw[pos:pos + 1].isspace():
            pos += 1
        start = pos
        while pos < len(raw) and not raw[pos:pos + 1].isspace():
            pos += 1
        if start == pos:
            raise ValueError(f"{path}: truncated PFM header")
        fields.append(raw[start:pos].decode("ascii"))
    pos += 1                                      # the single whitespace byte after the scale
    ident, w, h, scale = fields[0], int(fields[1]), int(fields[2]), float(fields[3])
    channels = {"PF": 3, "Pf": 1}.get(ident)
    if channels is None:
        raise ValueError(f"{path}: not a PFM (identifier {ident!r})")
    count = w * h * channels
    if len(raw) - pos != 4 * count:
        raise ValueError(f"{path}: {len(raw) - pos} data bytes, expected {4 * count} for {w}x{h}x{channels}")
    data = np.frombuffer(raw, dtype="<f4" if scale < 0 else ">f4", count=count, offset=pos)
    shape = (h, w, 3) if channels == 3 else (h, w)
    return np.ascontiguousarray(data.reshape(shape)[::-1], dtype=np.float32)


def case_layers(layers: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], list[str]]:
    """The layers a Tungsten case holds, taken from our render's ``layers``, float32.

    Returns ``(layers, derived)``: every layer of :data:`TUNGSTEN_BUFFERS` and
    :data:`EXTRA_FILES` (the latter only when present), and the names of feature variances that
    were missing and derived as (q_a - q_b)^2 / 4 (module docstring). ``depth*`` layers are
    (H, W); a (H, W, 1) or (H, W, 3) depth keeps channel 0.
    """
    out, derived = {}, []
    for stem, names in TUNGSTEN_BUFFERS.items():
        for name in names[:3]:
            if name not in layers:
                raise KeyError(f"layer {name!r} missing (needed for Tungsten's {stem!r} buffer)")
            out[name] = np.asarray(layers[name], dtype=np.float32)
        var = names[3]
        if var in layers:
            out[var] = np.asarray(layers[var], dtype=np.float32)
        elif stem == "color":
            raise KeyError("layer 'variance' missing (Tungsten's colorVariance)")
        else:
            diff = out[names[1]].astype(np.float64) - out[names[2]].astype(np.float64)
            out[var] = (0.25 * diff * diff).astype(np.float32)
            derived.append(var)
    for name in TUNGSTEN_BUFFERS["depth"]:
        if out[name].ndim == 3:
            out[name] = np.ascontiguousarray(out[name][..., 0])
    for name in EXTRA_FILES.values():
        if name in layers:
            out[name] = np.asarray(layers[name], dtype=np.float32)
    return out, derived


def write_case(folder: str | os.PathLike, layers: dict[str, np.ndarray]) -> tuple[Path, dict[str, np.ndarray], list[str]]:
    """Write one Tungsten case into ``folder``: the PFMs of :func:`case_layers` and ``scene.json``.

    The scene file holds only a ``renderer`` block with ``output_buffers`` color, normal, albedo,
    depth (in that order), each ``{"type", "hdr_output_file": "<stem>.pfm", "sample_variance": true,
    "two_buffer_variance": true}``; paths are relative, so run the denoiser with the case folder
    as working directory. Returns ``(scene file, the layers written, derived names)``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written, derived = case_layers(layers)
    for stem, names in TUNGSTEN_BUFFERS.items():
        for suffix, name in zip(_SUFFIXES, names):
            write_pfm(folder / f"{stem}{suffix}.pfm", written[name])
    for stem, name in EXTRA_FILES.items():
        if name in written:
            write_pfm(folder / f"{stem}.pfm", written[name])
    buffers = [{"type": stem, "hdr_output_file": f"{stem}.pfm", "sample_variance": True,
                "two_buffer_variance": True} for stem in TUNGSTEN_BUFFERS]
    scene = folder / SCENE_FILE
    scene.write_text(json.dumps({"renderer": {"output_buffers": buffers}}, indent=4) + "\n")
    return scene, written, derived


def read_case(folder: str | os.PathLike) -> dict[str, np.ndarray]:
    """The layers of a case written by :func:`write_case`, under our layer names (float32;
    ``depth*`` (H, W), the rest (H, W, 3)); the extra files when present."""
    folder = Path(folder)
    layers = {}
    for stem, names in TUNGSTEN_BUFFERS.items():
        for suffix, name in zip(_SUFFIXES, names):
            layers[name] = read_pfm(folder / f"{stem}{suffix}.pfm")
    for stem, name in EXTRA_FILES.items():
        if (folder / f"{stem}.pfm").exists():
            layers[name] = read_pfm(folder / f"{stem}.pfm")
    return layers
