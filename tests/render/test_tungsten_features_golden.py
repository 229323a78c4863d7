"""Our Tungsten-convention feature buffers against Tungsten's own (golden buffers in
``tests/data/golden/tungsten_features/``, made by ``tools/golden/tungsten_features.py``; provenance in
that folder's README.md).

The scene (``scene.py`` there): a 45-degree perfect mirror showing a red diffuse wall, a diffuse
floor, a quad area light and open background, 48x48 pixels. Tungsten's path tracer records albedo,
normal and depth at the first non-specular vertex (``PathTracer.cpp`` L78-96, L133-140); so does our
feature pass with ``features="tungsten"`` (:mod:`mcbench.render.path_features`, the spec). Two kinds
of check:

* ``test_golden_*``: the golden buffers themselves against a ray trace of the pixel centres in
  numpy (:func:`centre_features`: camera, quads and mirror from ``scene.py``): through the mirror
  the albedo is the wall's, the normal the wall's (unflipped: the wall faces away and is seen
  from its back), the depth the summed distance camera-mirror-wall; the light's albedo is its
  BSDF albedo plus its emission; a camera ray that escapes has normal -d and depth 0; a mirror
  ray that escapes has normal -d of the reflected ray and no albedo or depth sample (0). This
  pins Tungsten's convention independently of our renderer.
* ``test_features_match_tungsten``: our render (:func:`mcbench.render.renderer.render_dict_buffers`,
  ``SPP`` spp, the test seeds of :func:`mcbench.render.seeds.render_seed`) against the golden
  (``manifest.json``'s spp: 1024), per pixel and channel:
  ``|ours - golden| <= K * s + ATOL * (1 + |golden|)`` with
  ``s^2 = max(v_o, r v_g) + max(v_g, v_o / r)``, ``v`` the stored variances of the two pixel
  means and ``r = 1024 / SPP`` (each render's variance also estimated from the other's, scaled by
  the spp ratio: a render that missed a rare value in a pixel, e.g. the floor in a wall pixel's
  corner, reports too small a variance of its own). Both renders average a pixel's samples over
  the same box footprint, so pixels on edges are compared like any other. Also the mean of z^2
  (``z = (ours - golden) / s`` where ``s > 0``) must stay <= ``MEAN_Z2_MAX`` and every 8x8 block's
  summed difference within ``K`` of its summed variance (catches a small bias spread over noisy
  pixels). Colour is compared the same way (the camera: orientation, fov axis, pixel grid).

Albedo and depth are means over the samples that *recorded* them (Tungsten's per-pixel count,
``OutputBuffer::addSample``), 0 where none did. Pixels where the three buffers (the golden, our
full buffer) disagree on whether any sample recorded albedo (:func:`partially_recorded`; e.g. a
light edge where our 32 samples of a half missed a sliver that Tungsten's 1024 hit) have no
comparable mean and are excluded from albedo and depth; at most ``MAX_PARTIAL_PIXELS`` of them
(7 measured; a render that stops recording where Tungsten records, such as first-hit features at the mirror, exceeds it).

Our full albedo/depth layer is the mean over all recorded samples of both halves (Tungsten's
``OutputBuffer::operator[]``), not ``(A + B) / 2`` of the half means: where one half recorded
nothing the full value is the other half's (:func:`test_full_weighted_feature_is_the_mean_over_recorded_samples`;
``(A + B) / 2`` gave 0.4 for the 0.8 wall there).

The comparison can fail: our ``first_hit`` features (albedo and normal at the mirror itself),
the wall's albedo 10% high, the colour image flipped either way and the normals negated each
fail it by orders of magnitude (``test_*_fails``).
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from mcbench.render.renderer import forget_scene, render_dict_buffers
from mcbench.render.seeds import render_seed
from mcbench.render.variants import pick_variant

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "golden" / "tungsten_features"
NPZ = GOLDEN / "tungsten_features.npz"
TOOL = GOLDEN.parents[3] / "tools" / "golden" / "tungsten_features.py"
SPP = 64                    # our render; the golden has manifest["spp"] = 1024
BASE_SEED = 3
K = 6.0                     # z bound per pixel and channel and per 8x8 block (max measured: 4.7)
ATOL = 1e-4                 # float32 rounding where both renders have no spread (flat quads, constant albedo)
MEAN_Z2_MAX = 2.0           # measured 0.06-1.14 over seeds and variants
BLOCK = 8
MAX_PARTIAL_PIXELS = 20     # measured 7 in llvm and scalar (first-hit features: 152-153)
QUANTITIES = ("color", "albedo", "normal", "depth")
WEIGHTED = ("albedo", "depth")

pytestmark = pytest.mark.skipif(not NPZ.exists(), reason="golden buffers missing (tools/golden/tungsten_features.py)")


def _scene_module():
    spec = importlib.util.spec_from_file_location("tungsten_features_scene", GOLDEN / "scene.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


SCENE = _scene_module()


@pytest.fixture(scope="module")
def variant():
    return pick_variant("auto")


@pytest.fixture(scope="module")
def manifest():
    return json.loads((GOLDEN / "manifest.json").read_text())


@pytest.fixture(scope="module")
def golden():
    with np.load(NPZ) as data:
        return {name: data[name].astype(np.float64) for name in data.files}


def _render(desc: dict, features: str, key: str) -> dict:
    try:
        layers, _ = render_dict_buffers(
            desc, SPP, lambda half, j, p: render_seed("noisy", spp=SPP, half=half, bin=j, pass_index=p,
                                                      base_seed=BASE_SEED),
            key=key, features=features)
    finally:
        forget_scene(key)
    return layers


@pytest.fixture(scope="module")
def ours(variant):
    return _render(SCENE.build(*SCENE.RESOLUTION), "tungsten", "test-tungsten-features-golden")


# --------------------------------------------------------------------------- comparison

def _variance_name(quantity: str) -> str:
    return "variance" if quantity == "color" else f"{quantity}_variance"


def _recorded(albedo: np.ndarray) -> np.ndarray:
    """Pixels with at least one recorded albedo sample (every recorded albedo here is > 0)."""
    return np.asarray(albedo).sum(axis=-1) > 0


def partially_recorded(golden: dict, ours: dict) -> np.ndarray:
    """(H, W) pixels where the golden and our full buffer disagree on whether albedo was recorded."""
    flags = np.stack([_recorded(golden["albedo"]), _recorded(ours["albedo"])])
    return flags.any(axis=0) & ~flags.all(axis=0)


def compare(golden: dict, ours: dict, quantity: str, spp_ratio: float) -> dict:
    """Per-pixel test of ``ours[quantity]`` against the golden (module docstring): failing
    pixels, max |z|, mean z^2, max block |z|, and the pixels left out."""
    g = golden[quantity]
    o = np.asarray(ours[quantity], dtype=np.float64)
    vg = golden[f"{quantity}_variance"]
    vo = np.asarray(ours[_variance_name(quantity)], dtype=np.float64)
    s2 = np.maximum(vo, spp_ratio * vg) + np.maximum(vg, vo / spp_ratio)
    s = np.sqrt(s2)
    d = o - g
    keep = np.ones(g.shape[:2], dtype=bool)
    if quantity in WEIGHTED:
        keep = ~partially_recorded(golden, ours)
    keep_c = keep[..., None] if g.ndim == 3 else keep
    keep_c = np.broadcast_to(keep_c, g.shape)
    bad = (np.abs(d) > K * s + ATOL * (1.0 + np.abs(g))) & keep_c
    noisy = (s > 0) & keep_c
    z = d[noisy] / s[noisy]
    h, w = g.shape[:2]
    blocks = (h // BLOCK, BLOCK, w // BLOCK, BLOCK, -1)
    block_d = np.where(keep_c, d, 0.0).reshape(blocks).sum(axis=(1, 3))
    block_v = np.where(keep_c, s2, 0.0).reshape(blocks).sum(axis=(1, 3))
    block_z = np.where(block_v > 0, np.abs(block_d) / np.sqrt(np.where(block_v > 0, block_v, 1.0)),
                       np.where(np.abs(block_d) > ATOL * BLOCK * BLOCK, np.inf, 0.0))
    bad_pixels = bad.any(axis=-1) if bad.ndim == 3 else bad
    return {"bad": bad_pixels, "n_bad": int(bad_pixels.sum()), "max_z": float(np.abs(z).max(initial=0.0)),
            "mean_z2": float(np.mean(z * z)) if z.size else 0.0, "block_z": float(block_z.max()),
            "left_out": int((~keep).sum()), "max_abs_diff": float(np.abs(np.where(keep_c, d, 0.0)).max())}


def failures(result: dict) -> list[str]:
    """What makes a :func:`compare` result fail, as messages (empty: it passes)."""
    out = []
    if result["n_bad"]:
        out.append(f"{result['n_bad']} pixel(s) beyond {K} sigma + {ATOL} (max |z| {result['max_z']:.3g}, "
                   f"max |diff| {result['max_abs_diff']:.3g})")
    if result["mean_z2"] > MEAN_Z2_MAX:
        out.append(f"mean z^2 {result['mean_z2']:.3g} > {MEAN_Z2_MAX}")
    if result["block_z"] > K:
        out.append(f"an 8x8 block's summed difference is {result['block_z']:.3g} sigma > {K}")
    if result["left_out"] > MAX_PARTIAL_PIXELS:
        out.append(f"{result['left_out']} partially recorded pixels > {MAX_PARTIAL_PIXELS}")
    return out


# --------------------------------------------------------------------------- numpy ray trace of pixel centres

def _normalize(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def camera_directions(width: int, height: int) -> np.ndarray:
    """(H, W, 3) unit directions through the pixel centres, Tungsten's pinhole camera
    (``PinholeCamera::sampleDirection`` with u = v = 0; ``Camera::fromJson``'s frame)."""
    origin, target, up = (np.array(v, dtype=np.float64) for v in
                          (SCENE.CAMERA_ORIGIN, SCENE.CAMERA_TARGET, SCENE.CAMERA_UP))
    forward = _normalize(target - origin)
    up = _normalize(up - forward * forward.dot(up))
    right = np.cross(forward, up)
    plane = 1.0 / np.tan(np.radians(SCENE.FOV_DEG) / 2)
    x = -1.0 + (np.arange(width) + 0.5) * 2.0 / width
    y = height / width - (np.arange(height) + 0.5) * 2.0 / width
    local = np.stack(np.broadcast_arrays(x[None, :], y[:, None], np.full((height, width), plane)), axis=-1)
    return _normalize(local[..., :1] * right + local[..., 1:2] * up + local[..., 2:] * forward)


def _intersect(origin, direction, skip=None):
    """Nearest quad hit along the ray: (name, t) or (None, inf)."""
    best = (None, np.inf)
    for name, (centre, e0, e1, *_rest) in SCENE.QUADS.items():
        if name == skip:
            continue
        c, e0, e1 = (np.array(v, dtype=np.float64) for v in (centre, e0, e1))
        n = np.array(SCENE.quad_normal(name))
        denom = n.dot(direction)
        if abs(denom) < 1e-9:
            continue
        base = c - 0.5 * e0 - 0.5 * e1
        t = n.dot(base - origin) / denom
        if not 1e-6 < t < best[1]:
            continue
        q = origin + t * direction - base
        if 0 <= q.dot(e0) / e0.dot(e0) <= 1 and 0 <= q.dot(e1) / e1.dot(e1) <= 1:
            best = (name, t)
    return best


def centre_features(width: int, height: int) -> dict:
    """Tungsten's features of each pixel-centre ray (one sample per pixel): ``chain`` (the quads
    hit, e.g. ``"mirror>wall"``), ``albedo``, ``normal``, ``depth``, ``recorded``."""
    dirs = camera_directions(width, height)
    origin0 = np.array(SCENE.CAMERA_ORIGIN, dtype=np.float64)
    out = {"chain": np.empty((height, width), dtype=object), "albedo": np.zeros((height, width, 3)),
           "normal": np.zeros((height, width, 3)), "depth": np.zeros((height, width)),
           "recorded": np.zeros((height, width), dtype=bool)}
    for i in range(height):
        for j in range(width):
            origin, d, skip, depth, chain = origin0, dirs[i, j], None, 0.0, []
            for bounce in range(SCENE.MAX_BOUNCES):
                name, t = _intersect(origin, d, skip)
                if name is None:
                    break
                chain.append(name)
                depth += t
                _, _, _, kind, albedo, emission = SCENE.QUADS[name]
                n = np.array(SCENE.quad_normal(name))
                if kind != "mirror":
                    front = n.dot(d) < 0
                    out["albedo"][i, j] = np.array(albedo) + (np.array(emission) if emission and front else 0.0)
                    out["normal"][i, j], out["depth"][i, j], out["recorded"][i, j] = n, depth, True
                    break
                origin, d, skip = origin + t * d, d - 2 * d.dot(n) * n, name
            if not out["recorded"][i, j]:
                out["normal"][i, j] = -d
            out["chain"][i, j] = ">".join(chain) or "escape"
    return out


@pytest.fixture(scope="module")
def centres():
    features = centre_features(*SCENE.RESOLUTION)
    chain = features["chain"]
    h, w = chain.shape
    padded = np.pad(chain, 1, mode="constant", constant_values="outside")   # border pixels: never interior
    interior = np.ones((h, w), dtype=bool)
    for di in (0, 1, 2):
        for dj in (0, 1, 2):
            interior &= padded[di:di + h, dj:dj + w] == chain
    features["interior"] = interior
    return features


# --------------------------------------------------------------------------- tests: the golden files

def test_golden_files_match_manifest(manifest):
    for name, digest in manifest["sha256"].items():
        assert hashlib.sha256((GOLDEN / name).read_bytes()).hexdigest() == digest, name
    assert manifest["tungsten"]["commit"] == "88ea02044dbaf20472a8173b6752460b50c096d8"
    assert tuple(manifest["resolution"]) == tuple(SCENE.RESOLUTION)
    assert manifest["max_bounces"] == SCENE.MAX_BOUNCES


def test_golden_scene_json_is_the_scene_module(manifest):
    """The stored scene.json is what the tool writes for scene.py now (the scene was not changed since)."""
    spec = importlib.util.spec_from_file_location("tungsten_features_tool", TOOL)
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    assert json.loads((GOLDEN / "scene.json").read_text()) == tool.tungsten_scene(SCENE, manifest["spp"])


def test_golden_has_tungsten_convention_at_pixel_centres(golden, centres):
    """Interior pixels (their 3x3 neighbourhood's centres hit the same quads) against the numpy
    trace: exact albedo and normal on flat quads, depth within K sigma of the golden plus 0.3% (the
    pixel mean of a smooth depth versus its centre value) and the escape normals within 2e-3."""
    interior = centres["interior"]
    chains = centres["chain"]
    counts = {c: int(((chains == c) & interior).sum()) for c in np.unique(chains)}
    # every case of the convention is present in the image
    for chain in ("mirror>wall", "mirror", "escape", "wall", "floor", "light"):
        assert counts.get(chain, 0) >= 4, (chain, counts)
    recorded = centres["recorded"] & interior
    np.testing.assert_allclose(golden["albedo"][recorded], centres["albedo"][recorded], atol=1e-6)
    np.testing.assert_allclose(golden["normal"][recorded], centres["normal"][recorded], atol=1e-6)
    depth_error = np.abs(golden["depth"] - centres["depth"]) - K * np.sqrt(golden["depth_variance"])
    assert np.all(depth_error[recorded] <= 3e-3 * centres["depth"][recorded]), np.abs(depth_error[recorded]).max()
    # through the mirror: the wall's albedo and normal, the summed distance (> the mirror's distance)
    through = (chains == "mirror>wall") & interior
    np.testing.assert_allclose(golden["albedo"][through], np.broadcast_to(SCENE.RED, (through.sum(), 3)), atol=1e-6)
    wall_normal = SCENE.quad_normal("wall")
    assert wall_normal == (-1.0, 0.0, 0.0)      # facing away from the scene: seen from its back side
    np.testing.assert_allclose(golden["normal"][through], np.broadcast_to(wall_normal, (through.sum(), 3)), atol=1e-6)
    wall = (chains == "wall") & interior       # the unflipped normal where the wall is seen directly too
    np.testing.assert_allclose(golden["normal"][wall], np.broadcast_to(wall_normal, (wall.sum(), 3)), atol=1e-6)
    # the light: BSDF albedo + emission
    light = (chains == "light") & interior
    expected = np.add(SCENE.LIGHT_ALBEDO, SCENE.LIGHT_EMISSION)
    np.testing.assert_allclose(golden["albedo"][light], np.broadcast_to(expected, (light.sum(), 3)), atol=1e-5)
    # paths that leave: normal -d of the last ray; depth 0 (camera ray: recorded 0; after the mirror: none); no albedo
    left = ~centres["recorded"] & interior
    np.testing.assert_allclose(golden["normal"][left], centres["normal"][left], atol=2e-3)
    assert np.all(golden["depth"][left] == 0) and np.all(golden["albedo"][left] == 0)
    assert np.all(golden["depth_variance"][left] == 0) and np.all(golden["albedo_variance"][left] == 0)


# --------------------------------------------------------------------------- tests: ours against the golden

@pytest.mark.parametrize("quantity", QUANTITIES)
def test_features_match_tungsten(golden, ours, manifest, quantity):
    result = compare(golden, ours, quantity, manifest["spp"] / SPP)
    assert not failures(result), (quantity, failures(result), result)


def test_full_weighted_feature_is_the_mean_over_recorded_samples(ours):
    """Where exactly one half buffer recorded albedo, the mean over all recorded samples (Tungsten's
    buffer, path_features' "mean = sum(w f) / sum(w)") is that half's mean."""
    one = _recorded(ours["albedo_a"]) != _recorded(ours["albedo_b"])
    assert one.any(), "no pixel with one recording half in this render (the check needs one)"
    recording_half = np.where(_recorded(ours["albedo_a"])[..., None], ours["albedo_a"], ours["albedo_b"])
    np.testing.assert_allclose(ours["albedo"][one], recording_half[one], rtol=1e-6)


# --------------------------------------------------------------------------- tests: the comparison can fail

def _mirror_pixels(golden):
    """Pixels right of the image centre whose golden normal is the wall's (-x): the mirror showing the wall."""
    normal = golden["normal"]
    columns = np.arange(normal.shape[1])[None, :]
    wall = np.linalg.norm(normal - np.array(SCENE.quad_normal("wall")), axis=-1) < 1e-3
    return wall & (columns >= normal.shape[1] // 2)


def test_first_hit_features_fail_at_the_mirror(golden, manifest, variant):
    first_hit = _render(SCENE.build(*SCENE.RESOLUTION), "first_hit", "test-tungsten-features-first-hit")
    mirror = _mirror_pixels(golden)
    assert mirror.sum() >= 50
    for quantity in ("albedo", "normal"):
        result = compare(golden, first_hit, quantity, manifest["spp"] / SPP)
        assert failures(result), quantity
    normal = compare(golden, first_hit, "normal", manifest["spp"] / SPP)
    assert normal["bad"][mirror].mean() > 0.95      # every mirror pixel fails on its normal
    assert normal["max_z"] > 100 * K
    # first-hit albedo records nothing at the mirror (a delta BSDF has no diffuse reflectance) where
    # Tungsten records the wall's: every mirror pixel counts as partially recorded, far too many
    assert partially_recorded(golden, first_hit)[mirror].mean() > 0.95


def test_wall_albedo_ten_percent_high_fails(golden, manifest, variant):
    desc = SCENE.build(*SCENE.RESOLUTION)
    reflectance = desc["wall"]["bsdf"]["bsdf"]["reflectance"]
    reflectance["value"] = [1.1 * v for v in reflectance["value"]]
    wrong = _render(desc, "tungsten", "test-tungsten-features-wall")
    result = compare(golden, wrong, "albedo", manifest["spp"] / SPP)
    assert failures(result)
    # the wall fails where seen directly and through the mirror
    assert result["bad"][_mirror_pixels(golden)].mean() > 0.9
    assert result["n_bad"] > 200


def test_flipped_colour_and_negated_normals_fail(golden, ours, manifest):
    ratio = manifest["spp"] / SPP
    for name, flip in (("vertical", np.s_[::-1]), ("horizontal", np.s_[:, ::-1])):
        flipped = dict(ours, color=ours["color"][flip], variance=ours["variance"][flip])
        assert failures(compare(golden, flipped, "color", ratio)), name
    negated = dict(ours, normal=-ours["normal"])
    result = compare(golden, negated, "normal", ratio)
    assert result["n_bad"] == golden["normal"].shape[0] * golden["normal"].shape[1]
