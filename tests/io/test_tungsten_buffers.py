"""PFM files and Tungsten case folders (mcbench/io/tungsten_buffers.py)."""

import json

import numpy as np
import pytest

from mcbench.io.tungsten_buffers import (EXTRA_FILES, TUNGSTEN_BUFFERS, case_layers, read_case, read_pfm,
                                         write_case, write_pfm)


def test_pfm_layout_is_bottom_up_little_endian(tmp_path):
    image = np.arange(2 * 3 * 3, dtype=np.float32).reshape(2, 3, 3)
    write_pfm(tmp_path / "a.pfm", image)
    raw = (tmp_path / "a.pfm").read_bytes()
    header = b"PF\n3 2\n-1\n"
    assert raw.startswith(header)
    data = np.frombuffer(raw[len(header):], dtype="<f4").reshape(2, 3, 3)
    np.testing.assert_array_equal(data[0], image[1])       # first stored row = bottom image row
    np.testing.assert_array_equal(read_pfm(tmp_path / "a.pfm"), image)


def test_pfm_one_channel_and_big_endian(tmp_path):
    gray = np.random.default_rng(0).random((4, 5)).astype(np.float32)
    write_pfm(tmp_path / "g.pfm", gray)
    assert (tmp_path / "g.pfm").read_bytes().startswith(b"Pf\n5 4\n")
    np.testing.assert_array_equal(read_pfm(tmp_path / "g.pfm"), gray)
    (tmp_path / "be.pfm").write_bytes(b"Pf\n5 4\n1.0\n" + np.ascontiguousarray(gray[::-1], ">f4").tobytes())
    np.testing.assert_array_equal(read_pfm(tmp_path / "be.pfm"), gray)


def test_pfm_errors_name_the_file(tmp_path):
    (tmp_path / "bad.pfm").write_bytes(b"P6\n1 1\n-1\n" + b"\0" * 12)
    with pytest.raises(ValueError, match="bad.pfm"):
        read_pfm(tmp_path / "bad.pfm")
    (tmp_path / "short.pfm").write_bytes(b"PF\n2 2\n-1\n" + b"\0" * 12)
    with pytest.raises(ValueError, match="short.pfm"):
        read_pfm(tmp_path / "short.pfm")
    with pytest.raises(ValueError):
        write_pfm(tmp_path / "x.pfm", np.zeros((2, 2, 4)))


def layers(h=6, w=7, with_feature_variance=True):
    rng = np.random.default_rng(1)
    out = {}
    for q in ("color", "normal", "albedo"):
        for s in ("", "_a", "_b"):
            out[q + s] = rng.random((h, w, 3)).astype(np.float32)
    for s in ("", "_a", "_b"):
        out["depth" + s] = rng.random((h, w)).astype(np.float32)
    out["variance"] = rng.random((h, w, 3)).astype(np.float32)
    out["variance_a"], out["variance_b"] = 2 * out["variance"], 3 * out["variance"]
    if with_feature_variance:
        out["normal_variance"] = rng.random((h, w, 3)).astype(np.float32)
        out["albedo_variance"] = rng.random((h, w, 3)).astype(np.float32)
        out["depth_variance"] = rng.random((h, w)).astype(np.float32)
    return out


def test_case_round_trip_and_scene_file(tmp_path):
    src = layers()
    scene, written, derived = write_case(tmp_path / "case", src)
    assert derived == []
    doc = json.loads(scene.read_text())
    buffers = doc["renderer"]["output_buffers"]
    assert [b["type"] for b in buffers] == ["color", "normal", "albedo", "depth"]
    assert all(b["sample_variance"] and b["two_buffer_variance"] for b in buffers)
    names = {p.name for p in (tmp_path / "case").iterdir()}
    for stem in TUNGSTEN_BUFFERS:
        assert {f"{stem}.pfm", f"{stem}A.pfm", f"{stem}B.pfm", f"{stem}Variance.pfm"} <= names
    assert {f"{stem}.pfm" for stem in EXTRA_FILES} <= names
    back = read_case(tmp_path / "case")
    assert set(back) == set(written)
    for name, array in back.items():
        np.testing.assert_array_equal(array, src[name])


def test_missing_feature_variance_is_derived(tmp_path):
    src = layers(with_feature_variance=False)
    out, derived = case_layers(src)
    assert derived == ["normal_variance", "albedo_variance", "depth_variance"]
    diff = src["depth_a"].astype(np.float64) - src["depth_b"]
    np.testing.assert_allclose(out["depth_variance"], diff ** 2 / 4, rtol=1e-6)
    with pytest.raises(KeyError, match="variance"):
        case_layers({k: v for k, v in src.items() if k != "variance"})
