"""The authors' case layout (mcbench.io.case_folders): files, channels, round trips and refusals."""

from __future__ import annotations

import numpy as np
import OpenEXR
import pytest

from mcbench.io.buffers import Denoised
from mcbench.io.case_folders import (EXTRA_RENDER_FILES, RENDER_FILES, check_denoiser_name, denoiser_files, read_image,
                                 write_case, write_image)
from mcbench.io.exr import ExrError, NonFiniteError


def render_layers(rng, h=5, w=7):
    layers = {name: rng.uniform(0, 1, (h, w, 3)).astype(np.float32)
              for name in ("color", "color_a", "color_b", "variance", "albedo", "normal")}
    layers["depth"] = rng.uniform(1, 2, (h, w)).astype(np.float32)
    return layers


def test_write_case_writes_the_programs_layout_and_round_trips(tmp_path):
    rng = np.random.default_rng(0)
    layers = render_layers(rng)
    out = Denoised(*(rng.uniform(0, 1, (5, 7, 3)).astype(np.float32) for _ in range(3)))
    written = write_case(tmp_path / "case", layers, {"nfor": out})
    names = sorted(str(p.relative_to(tmp_path / "case")) for p in written)
    assert names == sorted([*RENDER_FILES, *EXTRA_RENDER_FILES, "nfor/nfor.exr", "nfor/nforA.exr", "nfor/nforB.exr"])
    for file, layer in {**RENDER_FILES, **EXTRA_RENDER_FILES}.items():
        assert np.array_equal(read_image(tmp_path / "case" / file), layers[layer]), file
    files = denoiser_files(tmp_path / "case", "nfor")
    for image in ("full", "a", "b"):
        assert np.array_equal(read_image(files[image]), getattr(out, image))
    # the channels other programs expect: R, G, B (depth: Y), float32
    with OpenEXR.File(str(tmp_path / "case" / "colorA.exr"), separate_channels=True) as exr:
        assert sorted(exr.channels()) == ["B", "G", "R"]
        assert exr.channels()["R"].pixels.dtype == np.float32
    with OpenEXR.File(str(tmp_path / "case" / "depth.exr"), separate_channels=True) as exr:
        assert list(exr.channels()) == ["Y"]
    assert len(write_case(tmp_path / "small", layers, extra_files=False)) == len(RENDER_FILES)


def test_bad_input_is_refused_before_anything_is_written(tmp_path):
    rng = np.random.default_rng(1)
    layers = render_layers(rng)
    with pytest.raises(ValueError, match="albedo"):
        write_case(tmp_path / "a", {k: v for k, v in layers.items() if k != "albedo"})
    wrong = Denoised(*(np.zeros((4, 7, 3), np.float32) for _ in range(3)))
    with pytest.raises(ValueError, match="oidn.exr"):
        write_case(tmp_path / "b", layers, {"oidn": wrong})
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
    with pytest.raises(ValueError, match="denoiser name"):
        check_denoiser_name("a/b")
    bad = layers["color"].copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(NonFiniteError):
        write_image(tmp_path / "nan.exr", bad)
    with pytest.raises(ValueError, match="shape"):
        write_image(tmp_path / "x.exr", np.zeros((2, 2, 2)))


def test_read_image_names_the_file(tmp_path):
    with pytest.raises(ExrError, match="missing"):
        read_image(tmp_path / "none.exr")
    (tmp_path / "junk.exr").write_bytes(b"not an exr")
    with pytest.raises(ExrError, match="junk.exr"):
        read_image(tmp_path / "junk.exr")
    half = np.zeros((2, 3, 3), np.float16)
    with OpenEXR.File({"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}, {"RGB": half}) as exr:
        exr.write(str(tmp_path / "half.exr"))
    with pytest.raises(ExrError, match="float16"):
        read_image(tmp_path / "half.exr")
    with OpenEXR.File({"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {"Z": np.zeros((2, 3), np.float32)}) as exr:
        exr.write(str(tmp_path / "z.exr"))
    with pytest.raises(ExrError, match="no R, G, B or Y"):
        read_image(tmp_path / "z.exr")
