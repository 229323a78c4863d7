"""Shared test fixtures: one builder of synthetic :class:`mcbench.io.buffers.RenderBuffers`.

Use it through the ``make_render_buffers`` fixture::

    def test_something(make_render_buffers):
        buffers = make_render_buffers(height=12, width=10, half_std=0.05, seed=3)

The synthetic case has known statistics: each half buffer is ``truth`` plus independent
Gaussian noise of standard deviation ``half_std`` (A and B independent of each other), the full
image is their mean, and the variance layers state the true variance of the mean.

The slow end-to-end tests share one finished smoke run through the session fixture
``smoke_results`` (``(workdir, config)``); ``run_snakemake`` runs this checkout's Snakefile there.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from mcbench.io.buffers import REQUIRED_LAYERS, RenderBuffers

HALF_SUFFIXES = ("_a", "_b")
ALL_SUFFIXES = ("",) + HALF_SUFFIXES


def synthetic_features(height: int, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noise-free features with edges, float64.

    Returns ``albedo`` (H, W, 3) in [0, 1] with a vertical edge at ``x = width / 2``,
    ``normal`` (H, W, 3) unit vectors, +z except a tilted disk, and ``depth`` (H, W): a ramp
    in y behind a nearer disk (depth edge at the disk's rim).
    """
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    albedo = np.where((x < width // 2)[..., None], [0.8, 0.3, 0.2], [0.2, 0.5, 0.9])
    disk = (x - 0.6 * width) ** 2 + (y - 0.4 * height) ** 2 < (0.25 * max(height, width)) ** 2
    normal = np.zeros((height, width, 3))
    normal[..., 2] = 1.0
    normal[disk] = [0.6, 0.0, 0.8]
    depth = np.where(disk, 2.0, 5.0 + y / max(height, 1))
    return albedo, normal, depth


def synthetic_truth(albedo: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Noise-free radiance (H, W, 3), float64: albedo times a smooth shading gradient, brighter
    where the normal is tilted, so colour edges coincide with feature edges."""
    height, width = albedo.shape[:2]
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    shading = 0.3 + 0.7 * (x / max(width, 1)) * (1.0 - 0.5 * y / max(height, 1))
    tilted = normal[..., 2] < 0.99
    shading = np.where(tilted, 1.5 * shading + 0.2, shading)
    return albedo * shading[..., None]


def build_render_buffers(truth=None, *, height: int = 16, width: int = 16, spp: int = 8,
                         half_std=0.1, seed=0, albedo=None, normal=None, depth=None,
                         variance=None, bins: bool = False, position=None, visibility=None) -> RenderBuffers:
    """Synthetic render buffers with independent Gaussian noise in each half buffer.

    ``truth``: noise-free radiance (H, W, 3); when given, its shape overrides ``height`` and
    ``width``; default :func:`synthetic_truth` of the default features.
    ``half_std``: standard deviation of the noise in each half buffer (scalar or array
    broadcastable to (H, W, 3)); 0 gives noise-free buffers. Noise is drawn from
    ``np.random.default_rng(seed)`` (``seed`` may be a ``Generator``, which is then advanced):
    first A, then B, each ``truth.shape`` standard normals.
    ``variance``: the *half-buffer* variance of the mean written to ``variance_a`` and
    ``variance_b`` (broadcastable to (H, W, 3)); default ``half_std**2``. The full image's
    ``variance`` is half of it, as for the mean of two independent halves.
    ``albedo``/``normal`` (H, W, 3), ``depth`` (H, W): features, identical (separate copies)
    in the full, A and B buffers; defaults from :func:`synthetic_features`. ``position``
    (H, W, 3) world position, default (x, y, depth) of the pixel grid; ``visibility`` (H, W),
    default 1 (the optional layers RDFC reads).

    ``bins``: also the four quarter-sample bins of :data:`mcbench.io.buffers.BIN_LAYERS` (noise
    ``sqrt(2) * half_std`` each, drawn bin 0..3 after A and B are *replaced* by the means of bins
    0-1 and 2-3, so the layers keep the render identities; variance_bin = 2 × the half's).

    Layers: ``color = (color_a + color_b) / 2``; every layer float32; all of
    :data:`mcbench.io.buffers.REQUIRED_LAYERS` present plus ``albedo_a/_b``, ``normal_a/_b``,
    ``depth_a/_b``, ``position{,_a,_b}``, ``visibility{,_a,_b}`` and every feature's ``_variance``.
    """
    if truth is not None:
        truth = np.asarray(truth, np.float64)
        if truth.ndim != 3 or truth.shape[2] != 3:
            raise ValueError(f"truth must have shape (H, W, 3), got {truth.shape}")
        height, width = truth.shape[:2]
    default_albedo, default_normal, default_depth = synthetic_features(height, width)
    albedo = default_albedo if albedo is None else albedo
    normal = default_normal if normal is None else normal
    depth = default_depth if depth is None else depth
    if truth is None:
        truth = synthetic_truth(np.asarray(albedo, np.float64), np.asarray(normal, np.float64))
    shape = truth.shape
    half_std = np.broadcast_to(np.asarray(half_std, np.float64), shape)
    half_variance = half_std ** 2 if variance is None else np.asarray(variance, np.float64)
    half_variance = np.broadcast_to(half_variance, shape)

    rng = np.random.default_rng(seed)
    layers = {}
    for suffix in HALF_SUFFIXES:
        layers["color" + suffix] = (truth + half_std * rng.standard_normal(shape)).astype(np.float32)
        layers["variance" + suffix] = half_variance.astype(np.float32)
    if bins:
        for j in range(4):
            layers[f"color_bin{j}"] = (truth + np.sqrt(2) * half_std * rng.standard_normal(shape)).astype(np.float32)
            layers[f"variance_bin{j}"] = (2 * half_variance).astype(np.float32)
        layers["color_a"] = (layers["color_bin0"] + layers["color_bin1"]) / np.float32(2)
        layers["color_b"] = (layers["color_bin2"] + layers["color_bin3"]) / np.float32(2)
    mean = (layers["color_a"].astype(np.float64) + layers["color_b"]) / 2
    layers["color"] = mean.astype(np.float32)
    layers["variance"] = (half_variance / 2).astype(np.float32)
    if position is None:
        yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
        position = np.stack([xx, yy, np.asarray(depth, np.float64)], axis=-1) / max(height, width, 1)
    visibility = np.ones(shape[:2]) if visibility is None else visibility
    features = {"albedo": albedo, "normal": normal, "depth": depth, "position": position,
                "visibility": visibility}
    expected = {"albedo": shape, "normal": shape, "depth": shape[:2], "position": shape,
                "visibility": shape[:2]}
    for name, value in features.items():
        value = np.asarray(value, np.float32)
        if value.shape != expected[name]:
            raise ValueError(f"{name} must have shape {expected[name]}, got {value.shape}")
        for suffix in ALL_SUFFIXES:
            layers[name + suffix] = value.copy()
            # noise-free features: zero variance (the layers every render holds)
            layers[f"{name}_variance{suffix}"] = np.zeros_like(value)
    assert all(name in layers for name in REQUIRED_LAYERS)
    return RenderBuffers(layers=layers, spp=spp)


@pytest.fixture
def make_render_buffers():
    """The builder :func:`build_render_buffers` (see its docstring for the keywords)."""
    return build_render_buffers


# --- the smoke run shared by the slow end-to-end tests ----------------------------------------

def case_job(folder, *, scene: str, spp: int, render, reference, metrics, methods=(), images=None,
             weight_inputs=None, cache=None, keep="all") -> dict:
    """The job description of one case that ``workflow/rules/common.smk`` builds for
    :func:`mcbench.pipeline.cases.run_case`, so a test runs the code the rules run.

    ``methods`` [(name, module, params, inputs)] are made by the job (outputs under
    ``folder/outputs``); ``images`` {entry: EXR} are candidates made elsewhere, evaluated as they
    are (``weight_inputs`` {entry: input names} whose weight maps the viewer draws). The noisy
    input comes first, then the methods, then ``images``. The case's products go in ``folder``
    (``case.csv``, ``viewer_case/``, ``case_record.json``); the kept per-entry values and viewer
    images under ``cache`` (default ``folder/cache``). ``keep``: the job's ``keep_outputs``
    (``all`` here, so that a test can read every output; the config's default is ``read``).
    """
    from mcbench import NOISY

    folder = Path(folder)
    cache = Path(cache) if cache is not None else folder / "cache"
    weight_inputs = dict(weight_inputs or {})
    method_rows = [{"name": name, "module": module, "params": dict(params), "inputs": list(inputs), "weights": None,
                    "exr": str(folder / "outputs" / f"{name}.exr"), "timing": str(folder / "outputs" / f"{name}.json")}
                   for name, module, params, inputs in methods]
    sources = {NOISY: str(render), **{m["name"]: m["exr"] for m in method_rows},
               **{name: str(path) for name, path in (images or {}).items()}}
    inputs_of = {m["name"]: m["inputs"] for m in method_rows}
    entries = [{"entry": entry, "image": image, "values": str(cache / "values" / f"{entry}.json"),
                "viewer": str(cache / "viewer_entries" / entry),
                "weight_inputs": list(weight_inputs.get(entry, inputs_of.get(entry, [])))}
               for entry, image in sources.items()]
    return {"scene": scene, "spp": int(spp), "render": str(render), "reference": str(reference),
            "metrics": list(metrics), "methods": method_rows, "entries": entries,
            "outputs": {"metrics": str(folder / "case.csv"), "viewer": str(folder / "viewer_case"),
                        "record": str(folder / "case_record.json")}, "keep_outputs": keep}


REPO = Path(__file__).resolve().parents[1]
SMOKE_CONFIG = REPO / "workflow" / "configs" / "smoke.yaml"


def run_snakemake(workdir: Path, *args: str, check: bool = True, timeout: int = 900) -> subprocess.CompletedProcess:
    """``snakemake`` of this checkout in ``workdir`` with its ``config.yaml`` and 2 cores; a
    failure (with ``check``) raises AssertionError with the end of Snakemake's output."""
    command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "--directory", str(workdir),
               "--configfile", str(workdir / "config.yaml"), "--cores", "2", *args]
    result = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
    if check and result.returncode != 0:
        raise AssertionError(f"snakemake {' '.join(args)} failed:\n{result.stdout[-4000:]}\n{result.stderr[-4000:]}")
    return result


@pytest.fixture(scope="session")
def smoke_results(tmp_path_factory):
    """A finished run of ``workflow/configs/smoke.yaml``: ``(workdir, config)``, results in
    ``workdir/results``. Made once per test session; ``$MCBENCH_TEST_SMOKE_DIR`` names a folder
    to run (or bring up to date) in instead, so that a developer can reuse one between sessions."""
    given = os.environ.get("MCBENCH_TEST_SMOKE_DIR")
    workdir = Path(given) if given else tmp_path_factory.mktemp("smoke_results")
    workdir.mkdir(parents=True, exist_ok=True)
    config = yaml.safe_load(SMOKE_CONFIG.read_text())
    (workdir / "config.yaml").write_text(yaml.safe_dump(config))
    run_snakemake(workdir)
    return workdir, config
