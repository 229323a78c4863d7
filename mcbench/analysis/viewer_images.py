"""Images and manifest of the static image viewer: pure functions over arrays plus
small writers. No Snakemake here; :mod:`mcbench.pipeline.viewer` reads the EXRs and calls these.

What the viewer shows, per test case (scene, spp):

* every entry (the reference, the noisy input, each candidate) tone-mapped with the same ACES +
  sRGB curve as DSSIM (:func:`mcbench.analysis.metrics.tonemap`) at the exposures :data:`EXPOSURES_EV`:
  exposure ``k`` EV multiplies linear radiance by ``2**k`` before tone mapping (Eq. E1 below),
  written as JPEG at full resolution;
* per-pixel error maps of the noisy input and every candidate against the reference, one per
  metric of the study that declares a map (``metrics/<name>.py``: ``error_map`` and ``map_scale``,
  e.g. relMSE and HDR-FLIP; the caller computes them), and the filtered weight maps of ensembles (``weights_filtered_{i}``, mean over RGB), each quantised to
  :data:`LEVELS` levels of a fixed :class:`ColourScale` and written as an indexed PNG whose palette is the
  scale's colour map, so a pixel's index gives its value back (:func:`index_values`); the same
  palette draws the legend (:func:`legend_indices`);
* the numbers of ``metrics.csv`` beside the images (:func:`case_numbers`).

Display value of entry radiance ``L`` (H, W, 3) at exposure ``k`` (Eq. E1)::

    D_k = srgb(aces(2**k * L)),   8-bit value round(255 * D_k)

Exposures: -2 ... +2 EV in 1-EV steps. ACES saturates at about 4x the radiance that maps to
mid-grey, so +2 EV already reveals the dark quarter of an image and -2 EV the highlights that
EV 0 clips; finer steps quadruple the viewer's size for little gain (each step is a separate
JPEG: the slider picks a pre-rendered image, no tone mapping runs in the browser).
"""

from __future__ import annotations

import json
import math
import os
import shutil
from pathlib import Path

import numpy as np

from mcbench import BenchError
from mcbench.analysis.metrics import tonemap
from mcbench.contracts.metric import ColourScale  # re-exported: the scales of the maps
from mcbench.io.tables import write_atomically

__all__ = ["EXPOSURES_EV", "JPEG_QUALITY", "LEVELS", "REFERENCE", "REFERENCE_LABEL", "CASE_RECORD",
           "ColourScale", "RELMSE_SCALE", "FLIP_SCALE", "WEIGHT_SCALE",
           "exposure_tag", "exposed_display", "display_bytes", "scale_positions", "scale_indices",
           "index_values", "palette", "legend_indices", "scale_ticks", "weight_map",
           "write_jpeg", "write_indexed_png", "write_case_images", "case_folder", "case_numbers",
           "build_manifest", "manifest_script", "manifest_files", "assemble_viewer", "directory_bytes"]

EXPOSURES_EV = (-2, -1, 0, 1, 2)
# JPEG quality 85 with 4:4:4 chroma (no subsampling: colour noise is what a reader compares)
JPEG_QUALITY = 85
# Quantisation levels of an error or weight map: 64 colours look continuous on a perceptual map
# and keep the maps' PNGs smaller than 256 levels would (noisy maps barely compress).
LEVELS = 64
REFERENCE = "reference"         # the reference's entry name in the manifest
REFERENCE_LABEL = "Reference"
CASE_RECORD = "case.json"       # a case folder's fragment of the manifest (write_case_images)


# Per-pixel relMSE spans decades (about 1e-5 at 1024 spp after denoising, above 1 on fireflies
# at 4 spp): log10 over [1e-5, 10], viridis. HDR-FLIP is in [0, 1] by definition: linear, magma
# (the FLIP paper's own map); metrics/relmse.py and metrics/flip.py declare them as their maps'
# scales. Ensemble weights are in [0, 1] (simplex): linear, cividis.
RELMSE_SCALE = ColourScale("relmse", "viridis", 1e-5, 10.0, log=True,
                           description="per-pixel relMSE, mean over RGB of (y - r)^2 / (r^2 + 0.01); log10 scale")
FLIP_SCALE = ColourScale("flip", "magma", 0.0, 1.0, log=False,
                         description="per-pixel HDR-FLIP error (Andersson et al. 2021); linear scale")
WEIGHT_SCALE = ColourScale("weights", "cividis", 0.0, 1.0, log=False,
                           description="filtered ensemble weight of one input, mean over RGB; linear scale")


def exposure_tag(ev: int) -> str:
    """File-name tag of an exposure: ``ev0``, ``evp1`` (+1 EV), ``evm2`` (-2 EV)."""
    ev = int(ev)
    return f"ev{'m' if ev < 0 else 'p' if ev > 0 else ''}{abs(ev)}"


def exposed_display(image, *, ev: float) -> np.ndarray:
    """Display values (H, W, 3) float64 in [0, 1] of linear radiance ``image`` at ``ev`` stops:
    ``tonemap(2**ev * image)`` (Eq. E1; the ACES + sRGB curve of DSSIM)."""
    return tonemap(np.asarray(image, dtype=np.float64) * 2.0 ** ev)


def display_bytes(display) -> np.ndarray:
    """8-bit values ``round(255 * d)`` (uint8, same shape) of display values ``d`` in [0, 1]."""
    return np.round(np.clip(np.asarray(display, dtype=np.float64), 0.0, 1.0) * 255.0).astype(np.uint8)


def scale_positions(values, scale: ColourScale) -> np.ndarray:
    """Positions in [0, 1] along ``scale`` (float64, same shape): (v - low) / (high - low), or
    the same in log10 for a log scale; clamped to the ends. Non-finite values raise."""
    values = np.asarray(values, dtype=np.float64)
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{scale.name} map holds NaN or Inf values")
    if scale.log:
        low, high = math.log10(scale.low), math.log10(scale.high)
        values = np.log10(np.maximum(values, scale.low))
    else:
        low, high = scale.low, scale.high
    return np.clip((values - low) / (high - low), 0.0, 1.0)


def scale_indices(values, scale: ColourScale) -> np.ndarray:
    """Palette indices (uint8, same shape) of ``values``: position p in [0, 1] falls in bin
    ``min(floor(LEVELS p), LEVELS - 1)`` of :data:`LEVELS` equal bins."""
    return np.minimum(np.floor(scale_positions(values, scale) * LEVELS), LEVELS - 1).astype(np.uint8)


def index_values(indices, scale: ColourScale) -> np.ndarray:
    """Values (float64) at the centres of the bins ``indices``: the inverse of
    :func:`scale_indices` within half a bin (1 / (2 LEVELS) of the range, in log10 for a log
    scale)."""
    positions = (np.asarray(indices, dtype=np.float64) + 0.5) / LEVELS
    if scale.log:
        low, high = math.log10(scale.low), math.log10(scale.high)
        return 10.0 ** (low + positions * (high - low))
    return scale.low + positions * (scale.high - scale.low)


def palette(scale: ColourScale) -> np.ndarray:
    """(LEVELS, 3) uint8 sRGB colours of ``scale``'s matplotlib colour map at the bin centres."""
    from matplotlib import colormaps

    try:
        colour_map = colormaps[scale.colormap]
    except KeyError as exc:
        raise BenchError(f"colour scale '{scale.name}': matplotlib has no colour map '{scale.colormap}'") from exc
    rgba = colour_map((np.arange(LEVELS) + 0.5) / LEVELS)
    return np.round(rgba[:, :3] * 255.0).astype(np.uint8)


def legend_indices(*, width: int = 256, height: int = 1) -> np.ndarray:
    """Indices (height, width) uint8 of a horizontal colour bar from low (left) to high (right);
    written with :func:`write_indexed_png` it is the scale bar, drawn by the maps' palette."""
    row = np.minimum(np.floor((np.arange(width) + 0.5) / width * LEVELS), LEVELS - 1).astype(np.uint8)
    return np.repeat(row[None, :], height, axis=0)


def scale_ticks(scale: ColourScale) -> list[dict]:
    """Tick marks of a legend: ``{"value", "position"}`` with position in [0, 1] along the bar;
    each decade of a log scale, quarters of a linear one."""
    if scale.log:
        decades = range(round(math.log10(scale.low)), round(math.log10(scale.high)) + 1)
        values = [10.0 ** d for d in decades]
    else:
        values = [scale.low + q * (scale.high - scale.low) for q in (0.0, 0.25, 0.5, 0.75, 1.0)]
    return [{"value": v, "position": float(scale_positions(v, scale))} for v in values]


def weight_map(layer) -> np.ndarray:
    """(H, W) float64 weight of one ensemble input: the mean over RGB of a ``weights_filtered_{i}``
    layer (H, W, 3), or that mean as a stored output keeps it (H, W)
    (:func:`mcbench.io.buffers.stored_layers`), clamped to [0, 1] (the simplex; float32 rounding
    may leave it by 1e-7)."""
    layer = np.asarray(layer, dtype=np.float64)
    if layer.ndim == 2:
        return np.clip(layer, 0.0, 1.0)
    if layer.ndim != 3 or layer.shape[2] != 3:
        raise ValueError(f"a weight layer must have shape (H, W, 3) or (H, W), got {layer.shape}")
    return np.clip(layer.mean(axis=2), 0.0, 1.0)


def write_jpeg(path, rgb, *, quality: int = JPEG_QUALITY) -> None:
    """Write (H, W, 3) uint8 sRGB ``rgb`` as a baseline JPEG with 4:4:4 chroma and Huffman tables
    optimised for the image (the same decoded pixels as the standard tables, 7.5 % fewer bytes on
    the default study's images), atomically."""
    from PIL import Image

    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"{path}: a JPEG needs (H, W, 3) pixels, got {rgb.shape}")
    image = Image.frombytes("RGB", (rgb.shape[1], rgb.shape[0]), rgb.tobytes())
    write_atomically(path, lambda tmp: image.save(tmp, format="JPEG", quality=quality, subsampling=0,
                                                          optimize=True))


def write_indexed_png(path, indices, scale: ColourScale) -> None:
    """Write (H, W) uint8 palette ``indices`` as an 8-bit indexed PNG with ``scale``'s palette."""
    from PIL import Image

    indices = np.ascontiguousarray(indices, dtype=np.uint8)
    if indices.ndim != 2:
        raise ValueError(f"{path}: an indexed PNG needs (H, W) indices, got {indices.shape}")
    image = Image.frombytes("P", (indices.shape[1], indices.shape[0]), indices.tobytes())
    image.putpalette(palette(scale).ravel().tolist())
    write_atomically(path, lambda tmp: image.save(tmp, format="PNG", optimize=True))


def _check_image(name: str, image, shape) -> np.ndarray:
    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 3 or image.shape[2] != 3 or (shape is not None and image.shape != shape):
        raise BenchError(f"viewer: image of '{name}' has shape {image.shape}; expected {shape or '(H, W, 3)'}")
    if not np.all(np.isfinite(image)):
        raise BenchError(f"viewer: image of '{name}' holds NaN or Inf values")
    return image


def write_case_images(case_dir, *, reference, images: dict, weights: dict | None = None,
                      exposures=EXPOSURES_EV, error_maps: dict | None = None) -> dict:
    """Write one case's viewer images into ``case_dir`` and return their manifest fragment.

    ``reference`` (H, W, 3) and ``images`` {entry name: (H, W, 3)} (the noisy input and the
    candidates): linear radiance. ``weights`` {entry name: [(input name, weights_filtered layer
    (H, W, 3)), ...]} for ensembles. ``error_maps`` {entry name: {metric: (ColourScale, (H, W)
    values)}}: each entry's per-pixel error maps (:func:`write_entry_images`).
    Returns (file names relative to ``case_dir``)::

        {"width": W, "height": H,
         "images": {entry: {"<ev>": "<entry>_<tag>.jpg"}},       # reference first
         "errors": {entry: {"<metric>": "<entry>_<metric>.png"}},  # e.g. relmse, flip
         "weights": {entry: [{"input": name, "file": "<entry>_weights<i>.png"}]}}

    The same as :func:`merge_fragments` of :func:`write_entry_images` for the reference and each entry.
    """
    if REFERENCE in images:
        raise BenchError(f"viewer: '{REFERENCE}' is the reference's entry name; no candidate may take it")
    for name in weights or {}:
        if name not in images:
            raise BenchError(f"viewer: weight maps of '{name}', which is not an entry of the case")
    fragments = [write_entry_images(case_dir, REFERENCE, reference, reference=reference, exposures=exposures)]
    for name, image in images.items():
        fragments.append(write_entry_images(case_dir, name, image, reference=reference,
                                            weights=(weights or {}).get(name), exposures=exposures,
                                            error_maps=(error_maps or {}).get(name, {})))
    return merge_fragments(fragments)


def write_entry_images(folder, name: str, image, *, reference, weights: list | None = None,
                       exposures=EXPOSURES_EV, error_maps: dict | None = None) -> dict:
    """Write one entry's viewer images into ``folder`` and return its fragment (the shape of
    :func:`write_case_images`' for this entry alone): ``image`` (H, W, 3) tone-mapped at each
    exposure; unless ``name`` is the reference's, its error maps ``error_maps`` {metric:
    (ColourScale, (H, W) values)} (in that order, each quantised on its scale into
    ``<name>_<metric>.png``) and the weight maps ``weights`` [(input name, (H, W, 3) layer), ...]."""
    folder = Path(folder)
    reference = _check_image(REFERENCE, reference, None)
    if name == REFERENCE:
        image = reference
    else:
        image = _check_image(name, image, reference.shape)
    height, width = reference.shape[:2]
    fragment = {"width": width, "height": height, "images": {}, "errors": {}, "weights": {}}
    files = {}
    for ev in exposures:
        file_name = f"{name}_{exposure_tag(ev)}.jpg"
        write_jpeg(folder / file_name, display_bytes(exposed_display(image, ev=ev)))
        files[str(int(ev))] = file_name
    fragment["images"][name] = files
    if name == REFERENCE:
        return fragment
    fragment["errors"][name] = {}
    for metric, (scale, values) in (error_maps or {}).items():
        if np.shape(values) != (height, width):
            raise BenchError(f"viewer: {metric} map of '{name}' is {np.shape(values)}, images are {(height, width)}")
        file_name = f"{name}_{metric}.png"
        write_indexed_png(folder / file_name, scale_indices(values, scale), scale)
        fragment["errors"][name][metric] = file_name
    if weights is not None:
        fragment["weights"][name] = []
        for i, (input_name, layer) in enumerate(weights):
            values = weight_map(layer)
            if values.shape != (height, width):
                raise BenchError(f"viewer: weight map {i} of '{name}' is {values.shape}, images are {(height, width)}")
            file_name = f"{name}_weights{i}.png"
            write_indexed_png(folder / file_name, scale_indices(values, WEIGHT_SCALE), WEIGHT_SCALE)
            fragment["weights"][name].append({"input": input_name, "file": file_name})
    return fragment


def merge_fragments(fragments: list[dict]) -> dict:
    """One case's fragment from its entries' (:func:`write_entry_images`), in the given order; the
    entries must have one size and distinct names."""
    merged = {"width": None, "height": None, "images": {}, "errors": {}, "weights": {}}
    for fragment in fragments:
        size = (fragment["width"], fragment["height"])
        if merged["width"] is not None and size != (merged["width"], merged["height"]):
            raise BenchError(f"viewer: entries of {size[0]}x{size[1]} and {merged['width']}x{merged['height']} "
                             f"pixels in one case")
        merged["width"], merged["height"] = size
        for key in ("images", "errors", "weights"):
            for name, value in fragment[key].items():
                if name in merged[key]:
                    raise BenchError(f"viewer: entry '{name}' twice in one case")
                merged[key][name] = value
    return merged


def case_folder(scene: str, spp: int) -> str:
    """Folder of a case's images inside the viewer folder: ``cases/<scene>/spp<N>``."""
    return f"cases/{scene}/spp{int(spp)}"


def case_numbers(metrics, *, scene: str, spp: int, entries: list[str], metric_names: list[str],
                 source: str = "metrics.csv") -> dict:
    """{entry: {metric: value}} of one case from a tidy metrics table (scene, spp, entry,
    metric, value). Every entry must have every metric once with a finite value, else the error
    names ``source`` and the missing row."""
    rows = metrics[(metrics["scene"] == scene) & (metrics["spp"] == int(spp))]
    numbers = {}
    for entry in entries:
        numbers[entry] = {}
        for metric in metric_names:
            values = rows.loc[(rows["entry"] == entry) & (rows["metric"] == metric), "value"]
            if len(values) != 1 or not np.isfinite(float(values.iloc[0])):
                raise BenchError(f"{source}: no single finite {metric} of '{entry}' for ({scene}, {spp})")
            numbers[entry][metric] = float(values.iloc[0])
    return numbers


def _scale_record(scale: ColourScale, legend_file: str) -> dict:
    return {"colormap": scale.colormap, "low": scale.low, "high": scale.high, "log": scale.log,
            "description": scale.description, "legend": legend_file, "ticks": scale_ticks(scale)}


def build_manifest(*, scenes: list[str], spps: list[int], entries: list[str], labels: dict,
                   metric_names: list[str], cases: dict, numbers: dict, exposures=EXPOSURES_EV,
                   metric_labels: dict | None = None, lower_is_better: dict | None = None,
                   error_scales: dict | None = None) -> dict:
    """The viewer's manifest (``window.MCBENCH_VIEWER``): every path relative to the viewer folder.

    ``entries``: the noisy input and the candidates in table order (the reference is added
    first); ``labels`` {entry: label}; ``cases`` {(scene, spp): fragment of
    :func:`write_case_images`}; ``numbers`` {(scene, spp): :func:`case_numbers`}. Each case's
    paths are prefixed with :func:`case_folder`; weight-map inputs get their labels.
    ``metric_labels`` and ``lower_is_better`` {metric: ...} (default: the name, True) and
    ``error_scales`` {metric: ColourScale} of the metrics with maps (in the order the page
    draws them: ``maps``) come from the metrics' declarations.
    """
    labels = {REFERENCE: REFERENCE_LABEL, **labels}
    missing = [entry for entry in entries if entry not in labels]
    if missing:
        raise BenchError(f"viewer: no label for {', '.join(missing)}")
    manifest = {"version": 1, "scenes": list(scenes), "spp": [int(s) for s in spps],
                "entries": [REFERENCE] + [e for e in entries if e != REFERENCE], "labels": labels,
                "metrics": list(metric_names), "exposures": [int(ev) for ev in exposures],
                "metric_labels": {m: (metric_labels or {}).get(m, m) for m in metric_names},
                "lower_is_better": {m: bool((lower_is_better or {}).get(m, True)) for m in metric_names},
                "maps": list(error_scales or {}),
                "scales": {name: _scale_record(scale, f"legends/{name}.png")
                           for name, scale in {**(error_scales or {}), "weights": WEIGHT_SCALE}.items()},
                "cases": {}}
    for scene in scenes:
        manifest["cases"][scene] = {}
        for spp in spps:
            if (scene, spp) not in cases:
                raise BenchError(f"viewer: no images for the case ({scene}, {spp})")
            fragment, folder = cases[(scene, spp)], case_folder(scene, spp)
            case = {"width": fragment["width"], "height": fragment["height"],
                    "images": {entry: {ev: f"{folder}/{f}" for ev, f in files.items()}
                               for entry, files in fragment["images"].items()},
                    "errors": {entry: {metric: f"{folder}/{f}" for metric, f in files.items()}
                               for entry, files in fragment["errors"].items()},
                    "weights": {entry: [{"input": w["input"], "label": labels.get(w["input"], w["input"]),
                                         "file": f"{folder}/{w['file']}"} for w in maps]
                                for entry, maps in fragment["weights"].items()},
                    "numbers": numbers[(scene, spp)]}
            absent = [e for e in manifest["entries"] if e not in case["images"]]
            if absent:
                raise BenchError(f"viewer: case ({scene}, {spp}) has no images of {', '.join(absent)}")
            manifest["cases"][scene][str(int(spp))] = case
    return manifest


def manifest_script(manifest: dict) -> str:
    """``data.js``: one statement ``window.MCBENCH_VIEWER = {...};`` (JSON; NaN/Inf refused),
    loaded by a ``<script>`` tag because ``file://`` pages may not fetch."""
    return "window.MCBENCH_VIEWER = " + json.dumps(manifest, allow_nan=False, sort_keys=True) + ";\n"


def case_files(case: dict) -> set[str]:
    """The image files one case's fragment (of :func:`write_case_images` or the manifest) names:
    tone-mapped images, error maps and weight maps."""
    files = {f for per_ev in case["images"].values() for f in per_ev.values()}
    files.update(f for per_metric in case["errors"].values() for f in per_metric.values())
    files.update(w["file"] for maps in case["weights"].values() for w in maps)
    return files


def manifest_files(manifest: dict) -> list[str]:
    """Every file the manifest names (legends, images, error and weight maps), sorted."""
    files = {scale["legend"] for scale in manifest["scales"].values()}
    for per_spp in manifest["cases"].values():
        for case in per_spp.values():
            files.update(case_files(case))
    return sorted(files)


def _link_or_copy(source, target) -> None:
    """A hard link where the file system allows one (the case images are written once and
    replaced, never edited in place, so a link is a snapshot), else a copy: the viewer then
    takes no second copy of its images on disk."""
    Path(target).unlink(missing_ok=True)     # a stale file of an earlier assembly
    try:
        os.link(source, target)
    except OSError:
        shutil.copy2(source, target)


def assemble_viewer(output_dir, *, static_dir, case_dirs: dict, manifest: dict) -> None:
    """Fill ``output_dir``: the static page (every file of ``static_dir``), ``data.js``, the
    legends, and each case folder ``case_dirs[(scene, spp)]`` copied to :func:`case_folder`
    (without its :data:`CASE_RECORD` and hidden files such as Snakemake's timestamp; files are
    hard-linked where possible). Raises naming the first file the manifest names that is not
    there afterwards."""
    output_dir, static_dir = Path(output_dir), Path(static_dir)
    if not (static_dir / "index.html").is_file():
        raise BenchError(f"{static_dir}: the viewer's static files (index.html) are missing")
    output_dir.mkdir(parents=True, exist_ok=True)
    for source in sorted(static_dir.iterdir()):
        if source.is_file() and not source.name.startswith("."):
            shutil.copyfile(source, output_dir / source.name)
    for name, record in manifest["scales"].items():
        scale = ColourScale(name, record["colormap"], record["low"], record["high"], log=record["log"],
                            description=record["description"])
        write_indexed_png(output_dir / record["legend"], legend_indices(), scale)
    for (scene, spp), source in case_dirs.items():
        shutil.copytree(source, output_dir / case_folder(scene, spp), dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns(CASE_RECORD, ".*"), copy_function=_link_or_copy)
    (output_dir / "data.js").write_text(manifest_script(manifest))
    for name in manifest_files(manifest):
        if not (output_dir / name).is_file():
            raise BenchError(f"{output_dir / name}: named by the viewer's data.js but missing")


def directory_bytes(path) -> int:
    """Total size in bytes of the files under ``path``."""
    return sum(p.stat().st_size for p in Path(path).rglob("*") if p.is_file())
