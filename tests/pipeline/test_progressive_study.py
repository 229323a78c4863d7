"""Progressive denoising's consistency curve (mcbench.pipeline.progressive_study): one tiny end-to-end curve
(cornell_box at 16x16 from a 32x32 reference averaged 2x2) with its files, the noisy error falling
roughly as 1/spp and PD's staying near it; determinism; the block-mean reference variance;
early errors naming the config key or the file; and the curve's seed slot
(mcbench.render.seeds.progressive_curve_seed), disjoint from every other kind of seed."""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest

from mcbench import BenchError
from mcbench.render.seeds import (MAX_BASE_SEED, MAX_ORACLE_REPETITIONS, MAX_PROGRESSIVE_CURVE_LEVELS,
                           MAX_PROGRESSIVE_CURVE_PASSES, TRAINING_BASE_SEED, is_oracle_seed,
                           is_progressive_curve_seed, mitsuba_seed, oracle_render_seed, progressive_curve_seed,
                           render_seed, scalar_seed_stride, training_render_seed)

LEVELS = [4, 16, 64, 256]
ENTRIES = ["noisy", "oidn", "pd_oidn", "pd_oidn_ttest_only"]


def paths(folder, stem="curve") -> dict[str, str]:
    return {"table_csv": str(folder / f"{stem}.csv"), "table_md": str(folder / f"{stem}.md"),
            "figure_png": str(folder / f"{stem}.png")}


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> str:
    """A 32x32, 4096-spp cornell_box reference (worth 16384 spp at the curve's 16x16)."""
    from mcbench.io.exr import write_layers
    from mcbench.render.renderer import merge_reference_chunks, render_reference_chunk
    from scenes import load_scene

    chunk = render_reference_chunk(load_scene("cornell_box"), 4096, 0, resolution=(32, 32), threads=1)
    layers, metadata = merge_reference_chunks([chunk])
    path = tmp_path_factory.mktemp("curve_reference") / "reference.exr"
    write_layers(str(path), layers, metadata=metadata)
    return str(path)


@pytest.fixture(scope="module")
def curve(reference, tmp_path_factory):
    from mcbench.pipeline.progressive_study import run_consistency_curve

    folder = tmp_path_factory.mktemp("curve")
    files = paths(folder)
    table = run_consistency_curve("cornell_box", reference, spp_levels=list(reversed(LEVELS)), downscale=2,
                                  resolution=(32, 32), threads=1, **files)
    return table, files


def errors(table: pd.DataFrame, metric: str = "relmse_corrected") -> pd.DataFrame:
    return table.pivot(index="spp", columns="entry", values=metric)


# --------------------------------------------------------------------------- the curve

def test_table_has_every_level_and_entry_all_finite(curve):
    table, files = curve
    assert list(table.columns) == ["spp", "entry", "label", "relmse", "relmse_corrected", "smape", "seconds"]
    assert list(table["spp"]) == [spp for spp in LEVELS for _ in ENTRIES]     # sorted
    assert list(table["entry"]) == ENTRIES * len(LEVELS)
    numbers = table[["relmse", "relmse_corrected", "smape", "seconds"]].to_numpy(np.float64)
    assert np.isfinite(numbers).all()
    assert (table[["relmse", "smape", "seconds"]].to_numpy() >= 0).all()
    assert table.loc[table["entry"] == "noisy", "label"].unique().tolist() == ["Noisy input"]
    pd.testing.assert_frame_equal(pd.read_csv(files["table_csv"]), table, check_exact=False, rtol=1e-12)
    markdown = open(files["table_md"]).read()
    assert "cornell_box at 16x16" in markdown and "Reference noise floor" in markdown
    assert "**Consistency.**" in markdown and "PD/noisy relMSE" in markdown
    assert "nan" not in markdown.lower() and "inf " not in markdown.lower()
    with open(files["figure_png"], "rb") as handle:
        assert handle.read(8) == b"\x89PNG\r\n\x1a\n"


def test_noisy_error_falls_about_as_one_over_spp(curve):
    """64x the samples: the noisy render's (reference-noise corrected) relMSE falls by a factor
    within 4x of 64 either way; the raw relMSE exceeds it by the reference's small floor."""
    noisy = errors(curve[0])["noisy"]
    fall = noisy[LEVELS[0]] / noisy[LEVELS[-1]]
    assert LEVELS[-1] / LEVELS[0] / 4 < fall < LEVELS[-1] / LEVELS[0] * 4
    assert (noisy.diff().dropna() < 0).all()          # every level better than the one below
    raw = errors(curve[0], "relmse")["noisy"]
    assert (raw > noisy).all() and (raw - noisy).max() < 0.1 * noisy[LEVELS[-1]]


def test_progressive_stays_near_the_noisy_render_at_high_spp(curve):
    """Consistency: at the top level PD is within a modest factor of the render and not worse
    than it beyond statistical slack (the two share the render's noise; PD mixes toward the
    base only where the t-test finds no significant difference). The t-test-only bound is never
    far above the render either."""
    table = errors(curve[0])
    top = LEVELS[-1]
    ratio = table.loc[top, "pd_oidn"] / table.loc[top, "noisy"]
    assert 0.3 < ratio < 1.15
    assert (table["pd_oidn"] / table["noisy"] < 1.5).all()
    assert table.loc[top, "pd_oidn_ttest_only"] / table.loc[top, "noisy"] < 3.0


def test_same_seed_same_numbers(reference, tmp_path):
    """Two runs with the same seed give identical errors (the seconds differ); another seed gives
    other renders. spp 2 (one bin per half) and 8 (two bins) both run."""
    from mcbench.pipeline.progressive_study import run_consistency_curve

    kwargs = dict(spp_levels=[2, 8], downscale=2, resolution=(32, 32), threads=1)
    first = run_consistency_curve("cornell_box", reference, **kwargs, **paths(tmp_path, "first"))
    second = run_consistency_curve("cornell_box", reference, **kwargs, **paths(tmp_path, "second"))
    other = run_consistency_curve("cornell_box", reference, seed=1, **kwargs, **paths(tmp_path, "other"))
    pd.testing.assert_frame_equal(first.drop(columns="seconds"), second.drop(columns="seconds"), check_exact=True)
    noisy = first["entry"] == "noisy"
    assert not np.array_equal(first.loc[noisy, "relmse"].to_numpy(), other.loc[noisy, "relmse"].to_numpy())


# --------------------------------------------------------------------------- the reference

def test_block_mean_variance_is_the_block_average_over_downscale_squared(tmp_path):
    """Var of a 2x2 block mean = sum of the four variances / 16; without a variance layer there
    is no corrected relMSE and no floor."""
    from mcbench.io.exr import write_layers
    from mcbench.combine.oracle_weights import block_average
    from mcbench.pipeline.progressive_study import block_reference, reference_floor

    rng = np.random.default_rng(0)
    color, variance = rng.uniform(0.1, 2.0, (24, 22, 3)), rng.uniform(0.0, 0.01, (24, 22, 3))
    write_layers(str(tmp_path / "r.exr"), {"color": color, "variance": variance})
    mu, block_variance = block_reference(str(tmp_path / "r.exr"), 11, 12, 2)
    stored = variance.astype(np.float32).astype(np.float64)
    np.testing.assert_allclose(mu, block_average(color.astype(np.float32), 2), rtol=1e-12)
    np.testing.assert_allclose(block_variance[3, 4], stored[6:8, 8:10].sum(axis=(0, 1)) / 16, rtol=1e-12)
    assert reference_floor(mu, block_variance) == pytest.approx(np.mean(block_variance / (mu ** 2 + 0.01)))
    write_layers(str(tmp_path / "c.exr"), {"color": color})
    assert block_reference(str(tmp_path / "c.exr"), 11, 12, 2)[1] is None
    assert reference_floor(mu, None) is None


def test_block_mean_variance_matches_simulated_noise():
    """The formula against simulation: 2x2 block means of independent pixels with variances v."""
    from mcbench.combine.oracle_weights import block_average

    rng = np.random.default_rng(1)
    v = rng.uniform(0.5, 2.0, (4, 4, 1))
    draws = rng.standard_normal((20000, 4, 4, 1)) * np.sqrt(v)
    means = np.stack([block_average(d, 2) for d in draws[:4000]])
    np.testing.assert_allclose(means.var(axis=0), block_average(v, 2) / 4, rtol=0.1)


# --------------------------------------------------------------------------- errors

@pytest.mark.parametrize("changes, match", [
    ({"spp_levels": [4, 7]}, r"progressive_curve\.spp.*even"),
    ({"spp_levels": [0, 4]}, r"progressive_curve\.spp"),
    ({"spp_levels": [4, 4, 8]}, r"progressive_curve\.spp.*repeat"),
    ({"spp_levels": [8]}, r"progressive_curve\.spp.*2\.\."),
    ({"spp_levels": [4, 8.5]}, r"progressive_curve\.spp"),
    ({"base": "no_such_method"}, r"progressive_curve\.base.*no_such_method"),
    ({"base": "ensemble"}, r"progressive_curve\.base.*not a denoiser"),
    ({"downscale": 3}, r"progressive_curve\.downscale"),
    ({"downscale": 4}, r"progressive_curve\.downscale.*11 pixels"),
    ({"divergence": "nfor"}, r"progressive_curve\.divergence"),
    ({"divergence": "rdfc"}, r"progressive_curve\.divergence"),
    ({"resolution": (48, 48)}, r"reference\.exr.*32x32.*48x48"),
])
def test_bad_inputs_name_the_key_or_file(reference, tmp_path, changes, match):
    from mcbench.pipeline.progressive_study import run_consistency_curve

    kwargs = dict(spp_levels=[4, 8], downscale=2, resolution=(32, 32), **paths(tmp_path)) | changes
    with pytest.raises(BenchError, match=match):
        run_consistency_curve("cornell_box", reference, **kwargs)
    assert not (tmp_path / "curve.csv").exists()


def test_missing_reference_names_the_file(tmp_path):
    from mcbench.pipeline.progressive_study import run_consistency_curve

    missing = str(tmp_path / "nowhere.exr")
    with pytest.raises(BenchError, match="nowhere.exr"):
        run_consistency_curve("cornell_box", missing, spp_levels=[4, 8], resolution=(32, 32), **paths(tmp_path))


def test_unknown_scene_names_the_key(reference, tmp_path):
    from mcbench.pipeline.progressive_study import run_consistency_curve

    with pytest.raises(BenchError, match="progressive_curve.scene|no_such_scene"):
        run_consistency_curve("no_such_scene", reference, spp_levels=[4, 8], resolution=(32, 32), **paths(tmp_path))


# --------------------------------------------------------------------------- seeds

PASSES = (0, 1, 255, 256, MAX_PROGRESSIVE_CURVE_PASSES - 1)
USED_LEVELS = range(16)       # the levels a curve uses (the default has 12)


def curve_seeds(base_seed: int, levels=USED_LEVELS, passes=PASSES) -> dict[int, tuple]:
    return {progressive_curve_seed(i, h, bin=j, pass_index=p, base_seed=base_seed): (i, h, j, p)
            for i in levels for h in (0, 1) for j in (0, 1) for p in passes}


def test_curve_seeds_are_injective_and_in_their_slot():
    seeds = curve_seeds(0) | curve_seeds(MAX_BASE_SEED) | curve_seeds(3, levels=(MAX_PROGRESSIVE_CURVE_LEVELS - 1,))
    assert len(seeds) == 2 * 16 * 2 * 2 * len(PASSES) + 2 * 2 * len(PASSES)
    assert all(0 <= s < 1 << 32 and is_progressive_curve_seed(s) for s in seeds)
    assert progressive_curve_seed(5, 1, bin=1, pass_index=0x301, base_seed=3) == (
        (7 << 29) | (3 << 26) | (1 << 25) | (1 << 24) | (5 << 15) | (3 << 13) | 0x01)


def test_curve_seeds_are_disjoint_from_every_other_kind():
    """Against every test render (every spp code), reference chunk, oracle render (every
    repetition) and a sample of training seeds (all of their low bits for four scene seeds)."""
    curve = set(curve_seeds(0)) | set(curve_seeds(MAX_BASE_SEED))
    others = set()
    for base in (0, MAX_BASE_SEED):
        spps = list(range(2, 2049, 2)) + [2048 * k for k in range(2, 1025)]
        for spp, half, j, p in itertools.product(spps, (0, 1), (0, 1), (0, 1, 0x301)):
            others.add(render_seed("noisy", spp=spp, half=half, bin=j, pass_index=p, base_seed=base))
        for chunk, p in itertools.product(range(4096), (0, 1, 0x301)):
            others.add(render_seed("reference", chunk=chunk, pass_index=p, base_seed=base))
        for r, half, j, p in itertools.product(range(MAX_ORACLE_REPETITIONS), (0, 1), (0, 1), (0, 1, 0x301)):
            others.add(oracle_render_seed(r, half, bin=j, pass_index=p, base_seed=base))
    for scene_seed in (0, 1, 40000, 65535):
        for log2, half, j, p in itertools.product(range(1, 16), (0, 1), (0, 1), range(64)):
            others.add(training_render_seed(scene_seed, "noisy", spp=1 << log2, half=half, pass_index=p, bin=j))
        for p in range(4096):
            others.add(training_render_seed(scene_seed, "target", pass_index=p))
    assert others.isdisjoint(curve)
    assert not any(is_progressive_curve_seed(s) for s in others)
    assert not any(is_oracle_seed(s) for s in curve)


def test_curve_seeds_of_scene_seeds_in_the_training_slot_differ():
    """Exhaustively for the training scene seeds whose bits 28..13 a curve seed shares: the
    curve seeds of config seed 0..6, levels 0..15, lie outside every training seed of those
    scene seeds (bits 12..8 decide)."""
    for base_seed in range(MAX_BASE_SEED + 1):
        for seed in curve_seeds(base_seed, passes=(0, MAX_PROGRESSIVE_CURVE_PASSES - 1)):
            assert seed >> 29 == TRAINING_BASE_SEED and seed & 0x1F00 == 0
    assert all(training_render_seed(s, "target") & 0x1F00 for s in range(0, 65536, 257))
    assert all(training_render_seed(9, "noisy", spp=1 << k, half=0) & 0x1F00 for k in range(1, 16))


def test_scalar_pixel_seed_ranges_are_disjoint():
    """In scalar variants (pass 0) each curve render gets its own pixel-seed range, disjoint from
    the oracle renders', reference chunks' and noisy renders'."""
    width = height = 64
    span = scalar_seed_stride(width, height) * width * height
    seeds = [progressive_curve_seed(i, h, bin=j, base_seed=b) for b in (0, MAX_BASE_SEED)
             for i in USED_LEVELS for h in (0, 1) for j in (0, 1)]
    seeds += [oracle_render_seed(r, h, bin=j) for r in range(0, MAX_ORACLE_REPETITIONS, 37)
              for h in (0, 1) for j in (0, 1)]
    seeds += [render_seed("reference", chunk=c) for c in range(0, 4096, 5)]
    seeds += [render_seed("noisy", spp=s, half=h, bin=j) for s in (4, 16, 1024, 8192) for h in (0, 1) for j in (0, 1)]
    starts = {}
    for seed in seeds:
        start = mitsuba_seed(seed, "scalar_rgb", width, height) * width * height
        assert start % span == 0 and start not in starts, (seed, starts.get(start))
        starts[start] = seed
    with pytest.raises(BenchError, match="variant"):     # the documented limit of scalar curves
        mitsuba_seed(progressive_curve_seed(0, 0), "scalar_rgb", 256, 256)


@pytest.mark.parametrize("kwargs, error, match", [
    ({"level_index": MAX_PROGRESSIVE_CURVE_LEVELS, "half": 0}, BenchError, "progressive_curve.spp"),
    ({"level_index": -1, "half": 0}, BenchError, "progressive_curve.spp"),
    ({"level_index": 0, "half": 2}, ValueError, "half"),
    ({"level_index": 0, "half": 0, "bin": 2}, ValueError, "bin"),
    ({"level_index": 0, "half": 0, "pass_index": MAX_PROGRESSIVE_CURVE_PASSES}, BenchError, "pass index"),
    ({"level_index": 0, "half": 0, "base_seed": 7}, BenchError, "'seed'"),
])
def test_curve_seed_refuses_out_of_range_fields(kwargs, error, match):
    with pytest.raises(error, match=match):
        progressive_curve_seed(**kwargs)


def test_the_divergence_bases_are_the_declared_single_image_denoisers():
    """No list of divergence bases is written anywhere: the schema takes a name, and the plan
    checks it against the denoisers whose declarations make them single-image, naming them."""
    import yaml

    from mcbench.pipeline.config import SCHEMA_PATH, resolve_config
    from mcbench.pipeline.plan import plan_study
    from mcbench.pipeline.registry import single_image_methods

    schema = yaml.safe_load(SCHEMA_PATH.read_text())
    assert "enum" not in schema["properties"]["progressive_curve"]["properties"]["divergence"]
    assert {"oidn", "jbf", "kpcn"} <= set(single_image_methods()) and "nfor" not in single_image_methods()
    config = {"scenes": ["cornell_box"], "spp": [4], "resolution": [32, 32], "study": {"pool": False},
              "denoisers": ["oidn"], "combiners": [{"name": "pd", "method": "progressive", "inputs": ["oidn"]}],
              "progressive_curve": {"divergence": "nfor", "spp": [4, 8]}}
    with pytest.raises(BenchError, match=r"progressive_curve\.divergence: 'nfor' has no single-image function; "
                                         r"name one of none, jbf, kpcn"):
        plan_study(resolve_config(config), written=config, source="test.yaml")
