"""Features at the first non-specular vertex (``features: tungsten``, mcbench.render.path_features)
against closed forms.

Every scene is seen by an orthographic camera looking down -z from z = 0 (film [-0.5, 0.5]^2 in
x and y), so every camera ray has direction (0, 0, -1) and the path lengths are the same in every
pixel:

* a perfect mirror through (0, 0, -2) with normal (1, 0, 1)/sqrt(2) reflects (0, 0, -1) into
  (1, 0, 0): a camera ray at x hits it after 2 + x and reaches the wall x = 3 after 3 - x more,
  depth 5 everywhere, the wall's albedo and normal (-1, 0, 0);
* a second mirror on the plane x = 3 + y (normal (-1, 1, 0)/sqrt(2)) turns (1, 0, 0) into
  (0, 1, 0): (2 + x) + (3 + y - x) + (3 - y) = 8 to the wall y = 3, normal (0, -1, 0);
* a smooth glass slab (IOR 1.5, faces z = -1 and z = -1.5) at normal incidence reflects
  R = ((1.5 - 1)/(1.5 + 1))^2 = 0.04 of the samples at each face. A sample reaches the texture
  (z = -3) with probability P = T^2 / (1 - R^2) = 12/13 (T = 1 - R; k internal round trips with
  probability proportional to R^(2k)), the others leave the scene upwards and record the normal
  -d = (0, 0, -1): the normal's z is 2P - 1 = 11/13 on average. The depth averaged over the samples
  that recorded it is 3 + 2 * 0.5 * E[k] = 3 + R^2 / (1 - R^2); averaged over all samples it
  would be P times that (what a per-pixel mean over every sample would give).
* an emissive surface records its reflectance plus its radiance; a miss records normal -d, depth 0
  and the environment's radiance; a rough surface records at once (its first-hit features).

The first-hit convention fails each of them (shown in the tests), so none of them can pass by
accident of the scene.
"""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from mcbench import BenchError
from mcbench.contracts.scene import SceneSpec
from mcbench.render.renderer import (FEATURE_CONVENTIONS, merge_reference_chunks, render_dict_buffers,
                                     render_reference_chunk, weighted_mean_variance)
from mcbench.render.variants import pick_variant

SIZE = 16
SPP = 64
RED = (0.8, 0.05, 0.05)
GREEN = (0.05, 0.7, 0.1)
R_FRESNEL = ((1.5 - 1.0) / (1.5 + 1.0)) ** 2          # 0.04
P_REACH = (1 - R_FRESNEL) ** 2 / (1 - R_FRESNEL ** 2)   # 12/13
NEAR = 1e-3         # the orthographic camera's rays start at z = -NEAR: every depth is NEAR shorter
DEPTH_ATOL = 1e-3   # Mitsuba offsets each spawned ray by up to ~2e-4 (its ray epsilon) along the normal


@pytest.fixture(scope="module")
def variant():
    return pick_variant("auto")


def _frame(normal):
    """Orthonormal (u, v) with u x v = normal (a proper rotation taking +z to ``normal``)."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    helper = np.array([0.0, 1.0, 0.0]) if abs(n[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(helper, n)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u), n


def _quad(centre, normal, half, bsdf, emitter=None):
    """Mitsuba rectangle centred at ``centre`` with (one-sided) normal ``normal``, half-size ``half``."""
    import mitsuba as mi

    u, v, n = _frame(normal)
    matrix = [[u[i] * half, v[i] * half, n[i], centre[i]] for i in range(3)] + [[0.0, 0.0, 0.0, 1.0]]
    shape = {"type": "rectangle", "to_world": mi.ScalarTransform4f(matrix), "bsdf": bsdf}
    if emitter is not None:
        shape["emitter"] = emitter
    return shape


def _diffuse(rgb):
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb)}}


MIRROR = {"type": "conductor", "material": "none"}


def _scene(shapes: dict, *, environment=None, max_depth: int = 16) -> dict:
    import mitsuba as mi

    scene = {"type": "scene", "integrator": {"type": "path", "max_depth": max_depth},
             "sensor": {"type": "orthographic",
                        "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, -1], up=[0, 1, 0])
                        @ mi.ScalarTransform4f().scale([0.5, 0.5, 1.0]),
                        "near_clip": NEAR, "film": {"type": "hdrfilm", "width": SIZE, "height": SIZE}},
             "light": {"type": "point", "position": [1.0, 0.4, -0.5], "intensity": {"type": "rgb", "value": [5.0] * 3}}}
    if environment is not None:
        scene["environment"] = {"type": "constant", "radiance": {"type": "rgb", "value": list(environment)}}
    scene.update(shapes)
    return scene


_S = 0.5 ** 0.5
def _mirror_one():
    """The first mirror (module docstring): through (0, 0, -2), normal (1, 0, 1)/sqrt(2)."""
    return _quad((0.0, 0.0, -2.0), (_S, 0.0, _S), 2.0, MIRROR)


def _render(desc, features, variant, key, spp=SPP):
    layers, _ = render_dict_buffers(desc, spp, lambda half, j, p: 7000 + 100 * half + 10 * j + p,
                                    key=f"{key}:{features}", variant=variant, features=features)
    return layers


def _mirror_wall(**wall):
    return _scene({"mirror": _mirror_one(),
                   "wall": _quad((3.0, 0.0, -2.0), (-1.0, 0.0, 0.0), 3.0, _diffuse(RED), **wall)})


def test_conventions_are_named(variant):
    assert FEATURE_CONVENTIONS == ("tungsten", "first_hit")
    with pytest.raises(ValueError, match="features"):
        render_dict_buffers(_scene({}), 4, lambda h, j, p: 1, key="bad", features="first_non_specular")


def test_a_mirror_shows_the_wall_it_reflects(variant):
    layers = _render(_mirror_wall(), "tungsten", variant, "mirror")
    for suffix in ("", "_a", "_b"):
        np.testing.assert_allclose(layers["albedo" + suffix], np.broadcast_to(RED, (SIZE, SIZE, 3)), atol=1e-6)
        np.testing.assert_allclose(layers["normal" + suffix], np.broadcast_to((-1.0, 0.0, 0.0), (SIZE, SIZE, 3)),
                                   atol=1e-6)
        np.testing.assert_allclose(layers["depth" + suffix], 5.0 - NEAR, atol=DEPTH_ATOL)
    # the position is the wall's (x = 3) at the camera ray's height, z = -(2 + x)
    xs = (np.arange(SIZE) + 0.5) / SIZE - 0.5
    assert np.allclose(layers["position"][..., 0], 3.0, atol=1e-5)
    np.testing.assert_allclose(layers["position"][..., 2].mean(axis=0), -(2.0 + xs), atol=1e-2)
    np.testing.assert_allclose(layers["position"][..., 1].mean(axis=1), -xs, atol=1e-2)
    assert layers["albedo_variance"].max() < 1e-8 and layers["depth_variance"].max() < 1e-6   # rounding, ray offsets
    # the first hit is the mirror: its normal, no albedo, depth 2 + x
    first = _render(_mirror_wall(), "first_hit", variant, "mirror")
    np.testing.assert_allclose(first["normal"], np.broadcast_to((_S, 0.0, _S), (SIZE, SIZE, 3)), atol=1e-5)
    assert np.abs(first["albedo"]).max() < 1e-6
    np.testing.assert_allclose(first["depth"].mean(axis=0), 2.0 - NEAR + xs, atol=1e-2)


def test_a_chain_of_two_mirrors_records_the_wall_after_both(variant):
    desc = _scene({"mirror": _mirror_one(),
                   "mirror2": _quad((3.0, 0.0, -2.0), (-_S, _S, 0.0), 3.0, MIRROR),
                   "wall": _quad((3.0, 3.0, -2.0), (0.0, -1.0, 0.0), 3.0, _diffuse(GREEN))})
    layers = _render(desc, "tungsten", variant, "chain")
    np.testing.assert_allclose(layers["albedo"], np.broadcast_to(GREEN, (SIZE, SIZE, 3)), atol=1e-6)
    np.testing.assert_allclose(layers["normal"], np.broadcast_to((0.0, -1.0, 0.0), (SIZE, SIZE, 3)), atol=1e-6)
    np.testing.assert_allclose(layers["depth"], 8.0 - NEAR, atol=DEPTH_ATOL)
    assert np.allclose(layers["position"][..., 1], 3.0, atol=1e-5)


def _slab_scene(with_glass: bool = True):
    import mitsuba as mi

    checker = {"type": "diffuse", "reflectance": {"type": "checkerboard",
                                                  "color0": {"type": "rgb", "value": [0.1, 0.2, 0.3]},
                                                  "color1": {"type": "rgb", "value": [0.7, 0.6, 0.5]}}}
    shapes = {"texture": _quad((0.0, 0.0, -3.0), (0.0, 0.0, 1.0), 0.5, checker)}
    if with_glass:
        shapes["slab"] = {"type": "cube", "to_world": mi.ScalarTransform4f().translate([0.0, 0.0, -1.25])
                          @ mi.ScalarTransform4f().scale([5.0, 5.0, 0.25]),
                          "bsdf": {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0}}
    return _scene(shapes, max_depth=64)


def test_a_glass_slab_shows_the_texture_behind_it_with_tungstens_averaging(variant):
    layers = _render(_slab_scene(), "tungsten", variant, "slab")
    bare = _render(_slab_scene(with_glass=False), "first_hit", variant, "slab_bare")
    # the texture's albedo exactly (every pixel lies inside one check and some sample reaches it)
    np.testing.assert_allclose(layers["albedo"], bare["albedo"], atol=1e-6)
    assert {tuple(float(x) for x in np.round(c.astype(float), 3)) for c in bare["albedo"].reshape(-1, 3)} == {(0.1, 0.2, 0.3), (0.7, 0.6, 0.5)}
    # normal: the texture's (0, 0, 1) with probability P, the escape's -d = (0, 0, -1) otherwise
    samples = SIZE * SIZE * SPP
    nz = layers["normal"][..., 2].mean()
    sigma = math.sqrt(4 * P_REACH * (1 - P_REACH) / samples)
    assert abs(nz - (2 * P_REACH - 1)) < 5 * sigma, (nz, 2 * P_REACH - 1, sigma)
    np.testing.assert_allclose(layers["normal"][..., :2], 0.0, atol=1e-6)
    # depth over the samples that recorded it: 3 + 1.0 * E[round trips]
    q = R_FRESNEL ** 2
    expected_depth = 3.0 - NEAR + q / (1 - q)
    depth_sigma = math.sqrt(q / (1 - q) ** 2 / (samples * P_REACH))
    assert abs(layers["depth"].mean() - expected_depth) < 5 * depth_sigma + DEPTH_ATOL, layers["depth"].mean()
    # first hit: the glass (depth 1, no albedo, normal +z everywhere)
    first = _render(_slab_scene(), "first_hit", variant, "slab")
    np.testing.assert_allclose(first["depth"], 1.0 - NEAR, atol=DEPTH_ATOL)
    assert np.abs(first["albedo"]).max() < 1e-6


def test_an_emissive_surface_records_reflectance_plus_radiance_directly_and_in_a_mirror(variant):
    emitter = {"emitter": {"type": "area", "radiance": {"type": "rgb", "value": [2.0, 3.0, 4.0]}}}
    direct = _scene({"panel": _quad((0.0, 0.0, -2.0), (0.0, 0.0, 1.0), 1.0, _diffuse((0.5, 0.5, 0.5)), **emitter)})
    expected = np.broadcast_to((2.5, 3.5, 4.5), (SIZE, SIZE, 3))
    np.testing.assert_allclose(_render(direct, "tungsten", variant, "emissive")["albedo"], expected, atol=1e-5)
    mirrored = _mirror_wall(**emitter)
    np.testing.assert_allclose(_render(mirrored, "tungsten", variant, "emissive_mirror")["albedo"],
                               np.broadcast_to(np.add(RED, (2.0, 3.0, 4.0)), (SIZE, SIZE, 3)), atol=1e-5)
    # first hit: Mitsuba's albedo AOV, clipped to [0, 1], no emission
    assert _render(direct, "first_hit", variant, "emissive")["albedo"].max() <= 1.0


@pytest.mark.parametrize("environment", [None, (0.7, 0.2, 0.4)])
def test_a_miss_records_minus_d_depth_zero_and_the_environment(variant, environment):
    desc = _scene({}, environment=environment)
    layers = _render(desc, "tungsten", variant, f"miss{environment is None}")
    np.testing.assert_allclose(layers["normal"], np.broadcast_to((0.0, 0.0, 1.0), (SIZE, SIZE, 3)), atol=1e-6)
    assert np.abs(layers["depth"]).max() == 0.0 and np.abs(layers["position"]).max() == 0.0
    expected = np.zeros(3) if environment is None else np.asarray(environment)
    np.testing.assert_allclose(layers["albedo"], np.broadcast_to(expected, (SIZE, SIZE, 3)), atol=1e-6)
    # a path that leaves after a mirror: normal -d of the reflected ray, no depth (not recorded)
    reflected = _render(_scene({"mirror": _mirror_one()}, environment=environment), "tungsten", variant,
                        f"miss_mirror{environment is None}")
    np.testing.assert_allclose(reflected["normal"], np.broadcast_to((-1.0, 0.0, 0.0), (SIZE, SIZE, 3)), atol=1e-6)
    assert np.abs(reflected["depth"]).max() == 0.0
    np.testing.assert_allclose(reflected["albedo"], np.broadcast_to(expected, (SIZE, SIZE, 3)), atol=1e-6)


@pytest.mark.parametrize("bsdf", [
    {"type": "roughconductor", "alpha": 0.3},
    {"type": "roughdielectric", "alpha": 0.3, "int_ior": 1.5},
    _diffuse((0.3, 0.4, 0.5)),
], ids=["roughconductor", "roughdielectric", "diffuse"])
def test_a_rough_surface_records_at_once(variant, bsdf):
    desc = _scene({"surface": _quad((0.0, 0.0, -2.0), (0.0, 0.0, 1.0), 1.0, bsdf),
                   "wall": _quad((0.0, 0.0, -4.0), (0.0, 0.0, 1.0), 2.0, _diffuse(RED))})
    layers = _render(desc, "tungsten", variant, f"rough{bsdf['type']}")
    first = _render(desc, "first_hit", variant, f"rough{bsdf['type']}")
    np.testing.assert_allclose(layers["normal"], first["normal"], atol=1e-6)
    np.testing.assert_allclose(layers["depth"], 2.0 - NEAR, atol=DEPTH_ATOL)
    np.testing.assert_allclose(layers["position"][..., 2], -2.0, atol=1e-5)
    if bsdf["type"] == "diffuse":
        np.testing.assert_allclose(layers["albedo"], first["albedo"], atol=1e-6)
    assert not np.allclose(layers["albedo"], RED, atol=1e-3)     # never the wall behind


def test_reference_chunks_record_the_same_features(variant):
    module = types.ModuleType("tests_mirror_wall")
    module.SCENE = SceneSpec(description="a mirror before a red wall", category="test", resolution=(SIZE, SIZE),
                             build=lambda width, height: _mirror_wall())
    layers, metadata = render_reference_chunk(module, 16, 0, variant=variant, features="tungsten")
    assert metadata["features"] == "tungsten"
    np.testing.assert_allclose(layers["albedo"], np.broadcast_to(RED, (SIZE, SIZE, 3)), atol=1e-6)
    np.testing.assert_allclose(layers["depth"], 5.0 - NEAR, atol=DEPTH_ATOL)
    assert metadata["feature_spp"] == "16"
    first, first_metadata = render_reference_chunk(module, 16, 1, variant=variant, features="first_hit")
    assert first_metadata["features"] == "first_hit" and np.abs(first["albedo"]).max() < 1e-6
    # chunks of two conventions are never merged into one reference
    with pytest.raises(BenchError, match="features"):
        merge_reference_chunks([(layers, metadata), (first, first_metadata)])
    merged, merged_metadata = merge_reference_chunks([(layers, metadata)])
    assert merged_metadata["features"] == "tungsten"


def test_weighted_mean_variance_is_the_mean_and_variance_over_the_recorded_samples():
    rng = np.random.default_rng(5)
    values = rng.normal(2.0, 1.5, size=(4, 5, 3, 40))
    weights = (rng.random((4, 5, 1, 40)) < 0.6).astype(float)
    weights[0, 0] = 0.0          # no sample recorded
    weights[0, 1] = 0.0
    weights[0, 1, 0, 3] = 1.0    # one sample recorded
    s1 = (weights * values).sum(axis=-1)
    s2 = (weights * values ** 2).sum(axis=-1)
    mean, variance = weighted_mean_variance(s1, s2, weights.sum(axis=-1))
    for j in range(4):
        for i in range(5):
            kept = values[j, i][:, weights[j, i, 0] > 0]
            n = kept.shape[1]
            expected_mean = kept.mean(axis=1) if n else np.zeros(3)
            expected_var = kept.var(axis=1, ddof=1) / n if n > 1 else np.zeros(3)
            np.testing.assert_allclose(mean[j, i], expected_mean, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(variance[j, i], expected_var, rtol=1e-9, atol=1e-12)
    assert np.all(np.isfinite(mean)) and np.all(np.isfinite(variance))
