"""RDFC's position and visibility features of noisy renders (mcbench.render.visibility and the
renderer's feature pass): closed forms on a hand-built scene, the Bernoulli variance identity,
definitions on misses/emitters/media/depth of field, and the colour pass left bit-identical."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mcbench.io.buffers import ALL_LAYERS, BIN_LAYERS, OPTIONAL_FEATURES, REQUIRED_LAYERS, RenderBuffers
from mcbench.render.renderer import forget_scene, render_buffers, render_dict_buffers
from mcbench.render.seeds import SCALAR_BLOCK_SIZE, mitsuba_seed, render_seed
from mcbench.render.variants import pick_variant
from scenes import load_scene

SIZE = 24
FOV = 60.0                         # degrees (square image: both axes)
PLANE_Z = -4.0                     # the plane z = -4 faces the camera at the origin (looking down -z)
LIGHT = (0.0, -1.5, -1.0)          # point light
OCCLUDER_Z = -2.0
OCCLUDER = (-1.5, -0.5, -1.2, -0.8)   # x0, x1, y0, y1 of the occluding square at z = -2
PANEL_Z = -0.5                     # a panel facing the camera with the light behind it (backlit)
PANEL = (0.05, 0.3, -0.3, -0.05)


@pytest.fixture(scope="module")
def variant():
    return pick_variant("auto")


def _rectangle(x0, x1, y0, y1, z):
    import mitsuba as mi
    return {"type": "rectangle",
            "to_world": mi.ScalarTransform4f().translate([(x0 + x1) / 2, (y0 + y1) / 2, z])
                          .scale([(x1 - x0) / 2, (y1 - y0) / 2, 1]),
            "bsdf": {"type": "diffuse"}}


def _plane_scene(size: int = SIZE) -> dict:
    """Camera at the origin looking down -z; the plane z = PLANE_Z covers x <= 0 only (the right
    half of the image misses, but for a small panel in front of the light, z = PANEL_Z > LIGHT z,
    which the camera sees lit from behind); a point light and a square occluder cast a sharp
    shadow on the plane. Diffuse BSDFs (one-sided: zero for light from behind)."""
    from mcbench.render.geometry import perspective_sensor
    sensor = perspective_sensor(size, size, origin=(0, 0, 0), target=(0, 0, -1), fov=FOV)
    return {"type": "scene", "integrator": {"type": "path", "max_depth": 2}, "sensor": sensor,
            "plane": _rectangle(-20.0, 0.0, -20.0, 20.0, PLANE_Z),
            "occluder": _rectangle(*OCCLUDER, OCCLUDER_Z),
            "panel": _rectangle(*PANEL, PANEL_Z),
            "light": {"type": "point", "position": list(LIGHT),
                      "intensity": {"type": "rgb", "value": [10.0, 10.0, 10.0]}}}


def _pixel_boxes(size: int = SIZE):
    """Per pixel (row j, column i) the world (x, y) footprint on the plane z = PLANE_Z of its square,
    from the pinhole model: x = d tan(fov/2) (2u - 1), y = d tan(fov/2) (1 - 2v), d = |PLANE_Z|,
    u, v the film coordinates in [0, 1] (image left/top at u = 0/v = 0)."""
    half = abs(PLANE_Z) * math.tan(math.radians(FOV) / 2)
    edges = np.linspace(-half, half, size + 1)
    x0, x1 = edges[:-1][None, :], edges[1:][None, :]
    y1, y0 = -edges[:-1][:, None], -edges[1:][:, None]    # rows go down
    return np.broadcast_arrays(x0, x1, y0, y1), 2 * half / size


def _shadow_box():
    """The umbra on the plane: the occluder projected from the point light, P + s (c - P)."""
    s = (PLANE_Z - LIGHT[2]) / (OCCLUDER_Z - LIGHT[2])
    x0, x1, y0, y1 = OCCLUDER
    return (LIGHT[0] + s * (x0 - LIGHT[0]), LIGHT[0] + s * (x1 - LIGHT[0]),
            LIGHT[1] + s * (y0 - LIGHT[1]), LIGHT[1] + s * (y1 - LIGHT[1]))


def _inside(box, region):
    (x0, x1, y0, y1), (a0, a1, b0, b1) = box, region
    return (x0 >= a0) & (x1 <= a1) & (y0 >= b0) & (y1 <= b1)


def _outside(box, region):
    (x0, x1, y0, y1), (a0, a1, b0, b1) = box, region
    return (x1 <= a0) | (x0 >= a1) | (y1 <= b0) | (y0 >= b1)


def _in_view(rectangle, z):
    """A rectangle at depth z seen from the camera, scaled onto the plane (pinhole: x z_plane/z)."""
    k = PLANE_Z / z
    x0, x1, y0, y1 = rectangle
    return (k * x0, k * x1, k * y0, k * y1)


def _render_plane(spp: int, key: str, seed: int = 0, size: int = SIZE):
    desc = _plane_scene(size)
    try:
        layers, _ = render_dict_buffers(
            desc, spp, lambda half, j, p: render_seed("noisy", spp=spp, half=half, bin=j, pass_index=p,
                                                      base_seed=seed), key=key)
    finally:
        forget_scene(key)
    return layers


@pytest.fixture(scope="module")
def plane(variant):
    return _render_plane(16, "test-features-plane")


def test_position_is_the_hit_on_the_plane_and_zero_on_misses(plane):
    (x0, x1, y0, y1), pixel = _pixel_boxes()
    on_plane = x1 <= 0.0
    missed = (x0 >= 0.0) & _outside((x0, x1, y0, y1), _in_view(PANEL, PANEL_Z))
    occluder = ~_outside((x0, x1, y0, y1), _in_view(OCCLUDER, OCCLUDER_Z))
    mask = on_plane & ~occluder
    n = 16
    for suffix, count in (("", n), ("_a", n // 2), ("_b", n // 2)):
        position = plane["position" + suffix].astype(np.float64)
        assert position.shape == (SIZE, SIZE, 3)
        np.testing.assert_allclose(position[mask][:, 2], PLANE_Z, atol=1e-5)      # z exact
        # x, y: the mean of `count` uniform points of the pixel's footprint (box filter): the
        # footprint's centre within 5 standard errors, pixel / sqrt(12 count)
        tol = 5 * pixel / math.sqrt(12 * count) + 1e-5
        np.testing.assert_allclose(position[mask][:, 0], ((x0 + x1) / 2)[mask], atol=tol)
        np.testing.assert_allclose(position[mask][:, 1], ((y0 + y1) / 2)[mask], atol=tol)
        assert np.all(position[missed] == 0)
        assert np.all(plane["visibility" + suffix][missed] == 0)
    # x varies linearly over the footprint: per-sample variance pixel^2 / 12, of the mean / n
    variance = plane["position_variance"][mask].astype(np.float64)
    assert variance[:, 0].mean() == pytest.approx(pixel ** 2 / 12 / n, rel=0.15)
    assert variance[:, 1].mean() == pytest.approx(pixel ** 2 / 12 / n, rel=0.15)
    assert variance[:, 2].max() < 1e-10
    assert np.all(plane["position_variance"][missed] == 0)


def test_visibility_is_one_where_lit_and_zero_in_the_umbra(plane):
    box, _ = _pixel_boxes()
    on_plane = box[1] <= 0.0
    occluder = ~_outside(box, _in_view(OCCLUDER, OCCLUDER_Z))
    umbra = on_plane & _inside(box, _shadow_box()) & ~occluder
    lit = on_plane & _outside(box, _shadow_box()) & ~occluder
    backlit = _inside(box, _in_view(PANEL, PANEL_Z))     # unoccluded, but R = f * W = 0: f is 0
    assert umbra.sum() >= 4 and lit.sum() >= 50 and backlit.sum() >= 4    # the geometry gives all
    np.testing.assert_allclose(plane["position"][backlit][:, 2], PANEL_Z, atol=1e-6)
    for suffix in ("", "_a", "_b"):
        visibility = plane["visibility" + suffix]
        assert visibility.shape == (SIZE, SIZE) and visibility.dtype == np.float32
        assert np.all(visibility[lit] == 1) and np.all(visibility[umbra] == 0)
        assert np.all(visibility[backlit] == 0)
        assert np.all(plane["visibility_variance" + suffix][lit | umbra | backlit] == 0)
        assert visibility.min() >= 0 and visibility.max() <= 1


@pytest.mark.parametrize("scene", ["cornell_box", "veach_ajar"])
def test_visibility_variance_is_the_bernoulli_variance_of_the_mean(scene, variant):
    """For 0/1 samples the sum of squares is the sum, so the stored variance of the mean is exactly
    p (1 - p) / (n - 1) with p the image's visibility and n its samples (the unbiased sample
    variance p (1 - p) n / (n - 1), divided by n)."""
    spp = 16
    layers, _ = render_buffers(load_scene(scene), spp, resolution=(16, 16), seed=2)
    fractional = 0
    for suffix, n in (("", spp), ("_a", spp // 2), ("_b", spp // 2)):
        p = layers["visibility" + suffix].astype(np.float64)
        expected = p * (1 - p) / (n - 1)
        np.testing.assert_allclose(layers["visibility_variance" + suffix], expected, rtol=1e-5, atol=1e-9)
        fractional += int(((p > 0) & (p < 1)).sum())
    assert fractional > 20                   # penumbras and edges: the identity is tested, not 0 = 0


@pytest.mark.parametrize("scene", ["envmap_objects", "fog_beams", "depth_of_field", "spot_shadows"])
def test_features_are_defined_for_every_kind_of_light_medium_and_lens(scene, variant):
    """Environment map, spot light in fog, thin lens, spot lights: finite features, visibility in
    [0, 1], and on misses (depth 0: the ray left the scene) position 0 and visibility 0."""
    layers, _ = render_buffers(load_scene(scene), 4, resolution=(16, 12), seed=1)
    for suffix in ("", "_a", "_b"):
        for name in ("position", "position_variance", "visibility", "visibility_variance"):
            assert np.all(np.isfinite(layers[name + suffix])), name + suffix
        visibility = layers["visibility" + suffix]
        assert visibility.shape == (12, 16) and layers["position" + suffix].shape == (12, 16, 3)
        assert visibility.min() >= 0 and visibility.max() <= 1 and visibility.max() > 0
        missed = layers["depth" + suffix] == 0
        assert np.all(layers["position" + suffix][missed] == 0)
        assert np.all(visibility[missed] == 0)
    if scene == "envmap_objects":
        assert (layers["depth"] == 0).any()          # the environment is seen: misses are tested


def test_the_feature_pass_traces_the_colour_pass_camera_rays(variant):
    """At 2 spp each half holds one sample: with the pinhole at the origin, the colour pass's
    depth_a is the distance along that ray from the near clip plane (Mitsuba's perspective camera
    starts its rays there: t_near = near_clip / cos(theta), near_clip 0.01 by default), so
    depth = |p| (1 - near_clip / |p_z|) for the feature pass's position p -- only if the feature
    pass traces the colour pass's camera rays."""
    near_clip = 0.01
    layers = _render_plane(2, "test-features-rays", seed=4)
    for suffix in ("_a", "_b"):
        hit = layers["depth" + suffix] > 0
        assert hit.sum() > 100
        position = layers["position" + suffix].astype(np.float64)
        distance = np.linalg.norm(position, axis=2) * (1 - near_clip / np.maximum(np.abs(position[..., 2]), 1e-9))
        np.testing.assert_allclose(distance[hit], layers["depth" + suffix][hit], rtol=2e-6)


def test_colour_and_old_features_equal_a_render_without_the_feature_pass(variant):
    """The colour pass is today's render: each bin of a noisy render equals, bit for bit, the
    film of Mitsuba rendering the scene wrapped as before the features existed (moment(aov(
    albedo, sh_normal, depth, integrator)), box filter, independent sampler), written here from
    Mitsuba's documented plugins, with that bin's seed. 6 spp per pass: several samples
    accumulate per pixel (adding channels to the colour pass changes their summation order)."""
    import mitsuba as mi

    module = load_scene("cornell_box")
    spp, width, height = 24, 12, 10
    layers, meta = render_buffers(module, spp, resolution=(width, height), seed=5)
    desc = module.build(width, height)
    nested = {"type": "aov", "aovs": "albedo:albedo,nn:sh_normal,dd:depth", "integrator": desc["integrator"]}
    desc["integrator"] = {"type": "moment", "nested": nested}
    if variant.startswith("scalar"):
        desc["integrator"]["block_size"] = SCALAR_BLOCK_SIZE
    desc["sensor"]["film"]["rfilter"] = {"type": "box"}
    desc["sensor"]["sampler"] = {"type": "independent", "sample_count": 1}
    scene = mi.load_dict(desc)
    for half in (0, 1):
        for j in (0, 1):
            seed = render_seed("noisy", spp=spp, half=half, bin=j, pass_index=0, base_seed=5)
            image = np.asarray(mi.render(scene, spp=spp // 4, seed=mitsuba_seed(seed, variant, width, height)))
            names = [f.name for f in scene.sensors()[0].film().bitmap().struct_()]
            colour = image[..., [names.index(f"nested.integrator.{c}") for c in "RGB"]]
            np.testing.assert_array_equal(layers[f"color_bin{2 * half + j}"], colour.astype(np.float32))
    assert "visibility" in layers and "position_b" in layers


def test_renders_without_the_features_still_load(tmp_path, variant):
    """The features are optional layers: a render holding only REQUIRED_LAYERS (an old or imported
    one) loads, its images have position/visibility None; a render with them gives each image its own."""
    from mcbench.io.exr import write_layers

    assert not set(OPTIONAL_FEATURES) & set(REQUIRED_LAYERS)
    assert {"position_a", "visibility_variance_b"} <= set(ALL_LAYERS) and not set(BIN_LAYERS) & set(ALL_LAYERS)
    layers, meta = render_buffers(load_scene("cornell_box"), 4, resolution=(8, 6), seed=0)
    old = tmp_path / "old.exr"
    write_layers(old, {name: layers[name] for name in REQUIRED_LAYERS}, metadata={"spp": "4"})
    image = RenderBuffers.load(old).image("a")
    assert image.position is None and image.visibility is None and image.albedo is not None
    new = tmp_path / "new.exr"
    write_layers(new, layers, metadata=meta)
    buffers = RenderBuffers.load(new)
    np.testing.assert_array_equal(buffers.image("b").position, layers["position_b"])
    np.testing.assert_array_equal(buffers.image("a").visibility, layers["visibility_a"])
    np.testing.assert_array_equal(buffers.image("full").visibility, layers["visibility"])


@pytest.mark.parametrize("features", ["first_hit", "tungsten"])
def test_visibility_tests_the_direct_lights_red_channel_as_the_authors(variant, features):
    """RDFC's authors set v = 1 where the direct light's red channel is positive (fbksd-package
    multifilm.cpp:123): the same lit pixels record 1 under a light with red and 0 under a light
    with green and blue only, in both feature conventions."""
    lit_pixels = {}
    for name, rgb in (("red", [10.0, 0.0, 0.0]), ("cyan", [0.0, 10.0, 10.0])):
        desc = _plane_scene(12)
        desc["light"]["intensity"]["value"] = rgb
        key = f"visibility-{name}-{features}"
        layers, _ = render_dict_buffers(desc, 4, lambda half, j, p: 11 + 2 * half + j + 5 * p, key=key,
                                        variant=variant, features=features)
        forget_scene(key)
        lit_pixels[name] = layers["visibility"]
    assert (lit_pixels["red"] == 1).sum() >= 20
    assert np.all(lit_pixels["cyan"] == 0)
