"""The oracle seed slot of mcbench.render.seeds: injective, decoded, and disjoint from every test,
reference and training render seed (also as scalar-variant pixel-seed ranges)."""

from __future__ import annotations

import itertools

import pytest

from mcbench import BenchError
from mcbench.render.seeds import (MAX_BASE_SEED, MAX_ORACLE_REPETITIONS, decode_oracle_seed, decode_seed,
                           is_oracle_seed, mitsuba_seed, oracle_render_seed, render_seed,
                           scalar_seed_stride, training_render_seed)

PASSES = (0, 1, 2, 0x7FFF)


def all_oracle_seeds(base_seed: int, passes=PASSES) -> dict[int, tuple]:
    return {oracle_render_seed(r, h, bin=j, pass_index=p, base_seed=base_seed): (r, h, j, p)
            for r in range(MAX_ORACLE_REPETITIONS) for h in (0, 1) for j in (0, 1) for p in passes}


def test_oracle_seeds_are_injective_and_decode():
    for base in (0, MAX_BASE_SEED):
        seeds = all_oracle_seeds(base)
        assert len(seeds) == MAX_ORACLE_REPETITIONS * 2 * 2 * len(PASSES)
        for seed, (r, h, j, p) in itertools.islice(seeds.items(), 0, None, 97):
            assert 0 <= seed < 1 << 32
            assert decode_oracle_seed(seed) == {"base_seed": base, "repetition": r, "half": h, "bin": j,
                                                "pass_index": p}


def test_oracle_seed_bit_layout():
    """The documented layout, bit by bit."""
    seed = oracle_render_seed(5, 1, bin=1, pass_index=9, base_seed=3)
    assert seed == (3 << 29) | (1 << 28) | (((5 << 2) | (1 << 1) | 1) << 16) | (1 << 15) | 9


def test_no_test_reference_or_training_seed_is_an_oracle_seed():
    """Every reference chunk (all 4096, every pass bit pattern sampled) and noisy render (every spp
    code) seed is outside the oracle slot, and so are training seeds (base 7)."""
    oracle = all_oracle_seeds(0) | all_oracle_seeds(MAX_BASE_SEED)
    others = set()
    for base in (0, MAX_BASE_SEED):
        for chunk in range(4096):
            for p in PASSES:
                others.add(render_seed("reference", chunk=chunk, pass_index=p, base_seed=base))
        spps = list(range(2, 2049, 2)) + [2048 * k for k in range(2, 1025)]
        for spp, half, j, p in itertools.product(spps, (0, 1), (0, 1), (0, 0x7FFF)):
            others.add(render_seed("noisy", spp=spp, half=half, bin=j, pass_index=p, base_seed=base))
    for scene_seed in (0, 1, 40000, 65535):
        for spp, half, j, p in itertools.product((2, 64, 32768), (0, 1), (0, 1), (0, 63)):
            others.add(training_render_seed(scene_seed, "noisy", spp=spp, half=half, pass_index=p, bin=j))
        others.add(training_render_seed(scene_seed, "target", pass_index=4095))
    assert others.isdisjoint(oracle)
    assert not any(is_oracle_seed(s) for s in others)
    assert all(is_oracle_seed(s) for s in oracle)


def test_existing_layouts_unchanged():
    """Pinned values of the older layouts (the oracle slot is an addition only)."""
    assert render_seed("noisy", spp=16, half=1, bin=1, pass_index=3, base_seed=2) == \
        (2 << 29) | (((7 << 1) | 1) << 16) | (1 << 15) | 3
    assert render_seed("reference", chunk=4095, pass_index=5, base_seed=6) == \
        (6 << 29) | (1 << 28) | (4095 << 16) | 5
    # decode_seed is unchanged, so it reads an oracle seed as a reference chunk
    assert decode_seed(oracle_render_seed(0, 0))["kind"] == "reference"


def test_scalar_pixel_seed_ranges_are_disjoint():
    """In scalar variants every render uses pixel seeds [index * m * W * H, (index + 1) * m * W * H);
    oracle renders (pass 0) get ranges disjoint from the reference chunks' and noisy renders'."""
    width = height = 64
    span = scalar_seed_stride(width, height) * width * height
    starts = {}
    seeds = [oracle_render_seed(r, h, bin=j) for r in range(0, MAX_ORACLE_REPETITIONS, 37)
             for h in (0, 1) for j in (0, 1)]
    seeds += [render_seed("reference", chunk=c) for c in range(0, 4096, 5)]
    seeds += [render_seed("noisy", spp=s, half=h, bin=j) for s in (4, 16, 1024) for h in (0, 1) for j in (0, 1)]
    for seed in seeds:
        start = mitsuba_seed(seed, "scalar_rgb", width, height) * width * height
        assert start % span == 0 and start not in starts, (seed, starts.get(start))
        starts[start] = seed


@pytest.mark.parametrize("kwargs, error", [
    ({"repetition": MAX_ORACLE_REPETITIONS, "half": 0}, BenchError),
    ({"repetition": -1, "half": 0}, BenchError),
    ({"repetition": 0, "half": 2}, ValueError),
    ({"repetition": 0, "half": 0, "bin": 2}, ValueError),
    ({"repetition": 0, "half": 0, "pass_index": 1 << 15}, BenchError),
    ({"repetition": 0, "half": 0, "base_seed": 7}, BenchError),
])
def test_oracle_seed_refuses_out_of_range_fields(kwargs, error):
    with pytest.raises(error):
        oracle_render_seed(**kwargs)


def test_decode_refuses_non_oracle_seed():
    with pytest.raises(ValueError, match="not an oracle"):
        decode_oracle_seed(render_seed("reference", chunk=3))
