"""Procedural training scenes (mcbench.training_data): reproducible, finite, disjoint crops, targets
much less noisy than the inputs, scenes distinct from each other and from every test scene, and
render seeds disjoint from the test renders' seeds."""

from pathlib import Path

import numpy as np
import pytest

from mcbench import BenchError
from mcbench.io.buffers import ALL_LAYERS, BIN_LAYERS
from mcbench.pipeline.config import read_config_file
from mcbench.render.seeds import (FIBRE_SEED_BASE, TRAINING_BASE_SEED, decode_seed, decode_training_seed,
                           is_fibre_seed, render_seed, training_render_seed, training_seeds)
from mcbench.training_data import (crop_boxes, random_scene, render_target, scene_fingerprint,
                                   training_example, training_scene_fingerprint)
from mcbench.render.variants import pick_variant
from scenes import available_scenes, load_scene, scene_spec

REPO = Path(__file__).resolve().parents[2]
LEVELS = (4, 16)
TARGET_SPP = 256
RESOLUTION = (32, 24)
CROP = 12


@pytest.fixture(scope="module")
def example_3():
    return training_example(3, LEVELS, TARGET_SPP, RESOLUTION, CROP, 2)


def test_same_seed_same_layers_other_seed_other_layers(example_3):
    again = training_example(3, LEVELS, TARGET_SPP, RESOLUTION, CROP, 2)
    for (layers, meta), (layers2, meta2) in zip(example_3, again):
        assert meta["crop_box"] == meta2["crop_box"] and meta["fingerprint"] == meta2["fingerprint"]
        assert layers.keys() == layers2.keys()
        for name in layers:
            np.testing.assert_array_equal(layers[name], layers2[name], err_msg=name)
    other = training_example(4, LEVELS, TARGET_SPP, RESOLUTION, CROP, 2)
    assert other[0][1]["fingerprint"] != example_3[0][1]["fingerprint"]
    assert not np.array_equal(other[0][0]["target"], example_3[0][0]["target"])


def test_layers_names_shapes_finite_and_variances(example_3):
    expected = {f"{name}_spp{spp}" for name in ALL_LAYERS + BIN_LAYERS for spp in LEVELS} | {
        "target", "target_variance"}
    for layers, meta in example_3:
        assert set(layers) == expected
        for name, layer in layers.items():
            assert layer.dtype == np.float32
            assert layer.shape[:2] == (CROP, CROP), name
            assert layer.ndim == (2 if name.startswith(("depth", "visibility")) else 3), name
            assert np.all(np.isfinite(layer)), name
        assert layers["target_variance"].min() >= 0
        assert layers["target"].min() >= 0
        # 64x the samples: the target variance is ~1/64 of the 4-spp one (allow heavy tails).
        assert layers["target_variance"].mean() < 0.1 * layers["variance_spp4"].mean() + 1e-12
        np.testing.assert_array_equal(layers["color_spp4"],
                                      (layers["color_a_spp4"] + layers["color_b_spp4"]) / np.float32(2))
        assert meta["spp_levels"] == "4,16" and meta["target_spp"] == str(TARGET_SPP)
        assert meta["variant"] and meta["mitsuba"] and meta["seed"] == "3"


def test_crops_inside_image_and_disjoint(example_3):
    width, height = RESOLUTION
    for seed in range(40):
        for size, count in ((CROP, 2), (8, 6), (12, 4), (16, 2)):
            boxes = crop_boxes(seed, width, height, size, count)
            assert len(boxes) == count
            for x0, y0, x1, y1 in boxes:
                assert 0 <= x0 and x1 <= width and 0 <= y0 and y1 <= height
                assert (x1 - x0, y1 - y0) == (size, size)
            for i, a in enumerate(boxes):
                for b in boxes[i + 1:]:
                    assert a[2] <= b[0] or b[2] <= a[0] or a[3] <= b[1] or b[3] <= a[1], (a, b)
    assert crop_boxes(5, 128, 128, 64, 2) == crop_boxes(5, 128, 128, 64, 2)
    boxes = [tuple(int(v) for v in meta["crop_box"].split(",")) for _, meta in example_3]
    assert boxes == crop_boxes(3, *RESOLUTION, CROP, 2)
    with pytest.raises(BenchError):
        crop_boxes(0, 32, 24, 16, 3)


def test_target_is_the_mean_of_its_samples_with_the_variance_of_that_mean():
    """render_target against independent truth: its mean over 4 disjoint seed sets (4 x 64 spp)
    equals the 256-spp target up to noise, and the variance of that mean predicts the spread."""
    pick_variant("auto")
    desc = random_scene(3, 12, 10)
    means, variances = [], []
    for k in range(4):
        mean, variance, seeds = render_target(desc, 64, lambda p, k=k: 1000 * k + p, key="test-target")
        means.append(mean.astype(np.float64))
        variances.append(variance.astype(np.float64))
    big, big_variance, _ = render_target(desc, 256, lambda p: 9000 + p, key="test-target")
    from mcbench.render.renderer import forget_scene
    forget_scene("test-target")
    spread = np.var(np.stack(means), axis=0, ddof=1)                  # of one 64-spp mean
    predicted = np.mean(np.stack(variances), axis=0)
    mask = predicted > 0
    assert 0.5 < spread[mask].mean() / predicted[mask].mean() < 2.0
    # 256 spp: a quarter of the 64-spp variance
    assert 0.15 < big_variance[mask].mean() / predicted[mask].mean() < 0.4


def test_same_seed_same_dict():
    assert scene_fingerprint(random_scene(11, 16, 12)) == scene_fingerprint(random_scene(11, 16, 12))
    # the film size is not part of the fingerprint
    assert scene_fingerprint(random_scene(11, 16, 12)) == scene_fingerprint(random_scene(11, 40, 30))


def test_fingerprint_same_in_another_process():
    """Seed 32784 has meshes with textured BSDFs (a traversed ``to_uv`` transform): its
    fingerprint must not depend on the process (np.array of a transform once did)."""
    import subprocess
    import sys

    code = ("from mcbench.render.variants import pick_variant; pick_variant('auto'); "
            "from mcbench.training_data import training_scene_fingerprint as f; print(f(32784))")
    runs = {subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True,
                           check=True).stdout.strip() for _ in range(2)}
    pick_variant("auto")
    runs.add(training_scene_fingerprint(32784))
    assert len(runs) == 1, runs


def test_training_fingerprints_distinct_and_not_test_scenes():
    pick_variant("auto")
    seeds = list(range(100)) + list(range(FIBRE_SEED_BASE, FIBRE_SEED_BASE + 8))
    training = [training_scene_fingerprint(seed) for seed in seeds]
    assert len(set(training)) == len(seeds)
    tests = {scene_fingerprint(scene_spec(load_scene(name)).build(16, 12)) for name in available_scenes()}
    assert len(tests) == len(available_scenes())
    assert not tests & set(training)


def test_training_seeds_object_then_fibre_family():
    settings = {"first_seed": 5, "count": 3, "fibre_count": 2}
    assert training_seeds(settings) == [5, 6, 7, FIBRE_SEED_BASE, FIBRE_SEED_BASE + 1]
    assert training_seeds({"first_seed": 0, "count": 4, "fibre_count": 0}) == [0, 1, 2, 3]
    with pytest.raises(BenchError, match="training.first_seed"):
        training_seeds({"first_seed": FIBRE_SEED_BASE - 2, "count": 3, "fibre_count": 0})
    with pytest.raises(BenchError, match="training.fibre_count"):
        training_seeds({"first_seed": 0, "count": 1, "fibre_count": FIBRE_SEED_BASE + 1})
    with pytest.raises(BenchError, match="missing training.fibre_count"):
        training_seeds({"first_seed": 0, "count": 1})          # no second default here
    config = read_config_file(REPO / "config.yaml")["training"]
    seeds = training_seeds(config)
    assert sum(map(is_fibre_seed, seeds)) == config["fibre_count"] > 0
    assert len(seeds) == config["count"] + config["fibre_count"]


def test_fibre_scenes_add_thin_curves_to_an_object_scene():
    pick_variant("auto")
    import mitsuba as mi

    seed = FIBRE_SEED_BASE + 3
    scene = random_scene(seed, 16, 12)
    fibres = [key for key in scene if key.startswith("fibres_")]
    assert fibres and all(isinstance(scene[key], mi.Shape) for key in fibres)
    assert not any(key.startswith("fibre") for key in random_scene(3, 16, 12))
    # sub-pixel strands: at 128 pixels across the frame, every radius is below 0.6 pixel
    params = mi.traverse(scene[fibres[0]])
    radius = np.array(params["control_points"]).reshape(-1, 4)[:, 3]
    sensor = scene["sensor"]
    fov = float(sensor["fov"])
    points = np.array(params["control_points"]).reshape(-1, 4)[:, :3]
    origin = np.array(sensor["to_world"].matrix)[:3, 3]
    distance = np.linalg.norm(points - origin, axis=1)
    pixel_at_distance = 2 * distance * np.tan(np.radians(fov) / 2) / 128
    assert np.percentile(radius / pixel_at_distance, 95) < 0.9
    assert scene_fingerprint(scene) == scene_fingerprint(random_scene(seed, 16, 12))


def test_training_data_imports_no_scene_module():
    """Training data is core: it builds on mcbench.render.geometry / mcbench.render.curves, never on scenes/."""
    import ast

    package = REPO / "mcbench" / "training_data"
    for path in sorted(package.glob("*.py")):
        tree = ast.parse(path.read_text())
        imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
        imported |= {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import)
                     for alias in node.names}
        assert not {m for m in imported if m.split(".")[0] in ("scenes", "methods")}, path.name
        assert "mcbench.render.renderer" not in imported or path.name == "examples.py", path.name
    assert "mcbench.render.geometry" in {node.module for node in
                                  ast.walk(ast.parse((package / "generator.py").read_text()))
                                  if isinstance(node, ast.ImportFrom)}


def test_training_seeds_disjoint_from_test_render_seeds():
    # Every config's global seed stays below the base seed reserved for training.
    for config in ("config.yaml", "workflow/configs/smoke.yaml", "workflow/configs/paper.yaml"):
        path = REPO / config
        if path.exists():
            seed = read_config_file(path)["seed"]
            assert 0 <= seed < TRAINING_BASE_SEED, f"{config}: seed {seed} collides with training"
    seeds = set()
    for scene_seed in (0, 1, 77, 65535):
        for spp in (2, 4, 16, 64, 256, 4096):
            for half in (0, 1):
                for j in (0, 1):
                    for p in (0, 1, 63):
                        seeds.add(training_render_seed(scene_seed, "noisy", spp, half, p, bin=j))
        for p in (0, 15, 4095):
            seeds.add(training_render_seed(scene_seed, "target", pass_index=p))
    assert len(seeds) == 4 * (6 * 2 * 2 * 3 + 3)                     # injective
    for s in seeds:
        assert 0 <= s < 2 ** 32
        assert decode_seed(s)["base_seed"] == TRAINING_BASE_SEED      # never a test render's
        decoded = decode_training_seed(s)
        again = (training_render_seed(decoded["scene_seed"], "noisy", decoded["spp"],
                                      decoded["half"], decoded["pass_index"], bin=decoded["bin"])
                 if decoded["kind"] == "noisy" else
                 training_render_seed(decoded["scene_seed"], "target",
                                      pass_index=decoded["pass_index"]))
        assert again == s
    # Test renders with any config seed 0..6 (noisy and reference) never decode as training.
    for base in range(TRAINING_BASE_SEED):
        for s in (render_seed("noisy", spp=4, half=1, pass_index=3, base_seed=base),
                  render_seed("noisy", spp=4, half=1, bin=1, pass_index=32767, base_seed=base),
                  render_seed("reference", chunk=4095, pass_index=32767, base_seed=base)):
            assert s not in seeds
            with pytest.raises(ValueError):
                decode_training_seed(s)
    with pytest.raises(BenchError):
        training_render_seed(65536, "target")
    with pytest.raises(BenchError):
        training_render_seed(0, "noisy", 12, 0)      # not a power of two


def test_crops_carry_their_feature_convention_and_the_same_colour(example_3):
    """Training crops record the convention their features were rendered with (the networks'
    records inherit it); the colour and its variance are the same in both conventions (the feature
    pass never touches the colour pass) and every feature is finite."""
    tungsten = training_example(3, LEVELS, TARGET_SPP, RESOLUTION, CROP, 2, features="tungsten")
    for (layers, meta), (first, first_meta) in zip(tungsten, example_3):
        assert meta["features"] == "tungsten" and first_meta["features"] == "first_hit"
        for name in ("target", "target_variance", *(f"{q}_spp{s}" for q in ("color", "variance", "color_a")
                                                   for s in LEVELS)):
            np.testing.assert_array_equal(layers[name], first[name], err_msg=name)
        assert all(np.all(np.isfinite(layer)) for layer in layers.values())
