"""Renders from another renderer read as scenes (mcbench.io.render_folders): the authors' layout and
the OIDN toolkit's naming, against synthetic images whose every pixel is known."""

from __future__ import annotations

import numpy as np
import OpenEXR
import pytest

from mcbench import BenchError
from mcbench.contracts.scene import scene_spec
from mcbench.io.case_folders import write_image
from mcbench.io.exr import ExrError, NonFiniteError
from mcbench.io.render_folders import (RenderFolder, case_files, read_case, read_image_any, read_reference,
                                       reference_files, scene_module)

H, W = 12, 16


def images(seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    layers = {name: rng.uniform(0.0, 2.0, (H, W, 3)).astype(np.float32)
              for name in ("color_a", "color_b", "albedo", "variance", "variance_a", "variance_b")}
    layers["normal"] = rng.uniform(-1.0, 1.0, (H, W, 3)).astype(np.float32)
    layers["depth"] = rng.uniform(1.0, 5.0, (H, W)).astype(np.float32)
    return layers


AUTHORS_NAMES = {"color_a": "colorA.exr", "color_b": "colorB.exr", "albedo": "albedo.exr", "normal": "normal.exr",
                 "variance": "variance.exr", "variance_a": "varianceA.exr", "variance_b": "varianceB.exr",
                 "depth": "depth.exr"}


def authors_folder(root, spps=(4, 16), *, with_color=False, optional=True):
    for spp in spps:
        layers = images(spp)
        for layer, name in AUTHORS_NAMES.items():
            if optional or name in ("colorA.exr", "colorB.exr", "albedo.exr", "normal.exr"):
                write_image(root / f"spp{spp}" / name, layers[layer])
        if with_color:
            write_image(root / f"spp{spp}" / "color.exr", np.full((H, W, 3), 0.25, np.float32))
    write_image(root / "reference.exr", np.full((H, W, 3), 0.5, np.float32))
    return RenderFolder(path=root, layout="authors", stem="x", source="test")


def test_authors_layout_reads_every_layer_exactly_and_the_full_image_is_the_halves_mean(tmp_path):
    folder = authors_folder(tmp_path)
    layers = read_case(folder, 16)
    truth = images(16)
    for name, image in truth.items():
        np.testing.assert_array_equal(layers[name], image)
    np.testing.assert_array_equal(layers["color"], (truth["color_a"] + truth["color_b"]) / np.float32(2))
    assert read_reference(folder).keys() == {"color"}


def test_a_given_full_image_is_used_as_given(tmp_path):
    folder = authors_folder(tmp_path, with_color=True)
    assert np.all(read_case(folder, 4)["color"] == np.float32(0.25))


def test_only_what_the_folder_holds_is_returned(tmp_path):
    folder = authors_folder(tmp_path, optional=False)
    assert set(read_case(folder, 4)) == {"color", "color_a", "color_b", "albedo", "normal"}
    files, missing = case_files(folder, 4)
    assert set(files) == {"color_a", "color_b", "albedo", "normal"} and missing == []


def test_missing_files_are_named(tmp_path):
    folder = authors_folder(tmp_path, spps=(4,))
    (tmp_path / "spp4" / "colorB.exr").unlink()
    files, missing = case_files(folder, 4)
    assert missing == [str(tmp_path / "spp4" / "colorB.exr")]
    with pytest.raises(BenchError, match="colorB.exr"):
        read_case(folder, 4)
    with pytest.raises(BenchError, match="spp8"):
        read_case(folder, 8)


def test_size_mismatch_nan_and_negative_variance_name_the_file(tmp_path):
    folder = authors_folder(tmp_path, spps=(4,))
    write_image(tmp_path / "spp4" / "albedo.exr", np.zeros((H, W + 1, 3), np.float32))
    with pytest.raises(BenchError, match=r"albedo.exr: 17x12 pixels"):
        read_case(folder, 4)
    authors_folder(tmp_path, spps=(4,))
    bad = images(4)["variance"].copy()
    bad[3, 4, 1] = -1e-3
    write_image(tmp_path / "spp4" / "variance.exr", bad)
    with pytest.raises(BenchError, match="variance.exr: negative variance"):
        read_case(folder, 4)
    nan = np.zeros((H, W, 3), np.float32)
    nan[0, 0, 0] = np.nan
    header = {"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": nan}) as exr:
        exr.write(str(tmp_path / "spp4" / "colorA.exr"))
    with pytest.raises(NonFiniteError, match="colorA.exr"):
        read_case(folder, 4)


def test_half_float_and_xyz_channels_are_read_exactly(tmp_path):
    values = np.linspace(-1, 1, H * W * 3, dtype=np.float16).reshape(H, W, 3)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {c: np.ascontiguousarray(values[..., i]) for i, c in enumerate("XYZ")}
    with OpenEXR.File(header, channels) as exr:
        exr.write(str(tmp_path / "n.exr"))
    image = read_image_any(tmp_path / "n.exr")
    assert image.dtype == np.float32
    np.testing.assert_array_equal(image, values.astype(np.float32))
    with OpenEXR.File(header, {"RGB": np.zeros((H, W, 3), np.uint32)}) as exr:
        exr.write(str(tmp_path / "u.exr"))
    with pytest.raises(ExrError, match="u.exr: channel R holds uint32"):
        read_image_any(tmp_path / "u.exr")


def oidn_folder(root, stem="kitchen"):
    names = {"hdr": "color", "alb": "albedo", "nrm": "normal"}
    for suffix, spp in (("0004", 4), ("16spp", 16)):
        layers = images(spp)
        layers["color"] = layers["color_a"]
        for feature, layer in names.items():
            write_image(root / f"{stem}_{suffix}.{feature}.exr", layers[layer])
    write_image(root / f"{stem}_ref.hdr.exr", np.full((H, W, 3), 0.5, np.float32))
    write_image(root / "other_0004.hdr.exr", np.zeros((H, W, 3), np.float32))   # another image's files
    return RenderFolder(path=root, layout="oidn", stem=stem, source="test")


def test_oidn_naming_finds_zero_padded_and_spp_suffixed_levels_and_the_reference(tmp_path):
    folder = oidn_folder(tmp_path)
    for spp, suffix in ((4, "0004"), (16, "16spp")):
        files, missing = case_files(folder, spp)
        assert missing == [] and files == {"color": tmp_path / f"kitchen_{suffix}.hdr.exr",
                                           "albedo": tmp_path / f"kitchen_{suffix}.alb.exr",
                                           "normal": tmp_path / f"kitchen_{suffix}.nrm.exr"}
        layers = read_case(folder, spp)
        assert set(layers) == {"color", "albedo", "normal"}      # no halves, variance or depth invented
        np.testing.assert_array_equal(layers["color"], images(spp)["color_a"])
    assert case_files(folder, 8)[1] == [str(tmp_path / "kitchen_8.hdr.exr")]
    assert reference_files(folder) == {"color": tmp_path / "kitchen_ref.hdr.exr"}
    write_image(tmp_path / "kitchen_gt.hdr.exr", np.zeros((H, W, 3), np.float32))
    with pytest.raises(BenchError, match="more than one reference"):
        reference_files(folder)


def test_scene_file_gives_the_scene_contract_and_names_bad_keys(tmp_path):
    oidn_folder(tmp_path / "renders")
    (tmp_path / "kitchen.yaml").write_text("renders: renders\nlayout: oidn\ndescription: a kitchen\n")
    module = scene_module(tmp_path / "kitchen.yaml")
    spec = scene_spec(module)
    assert spec.render_folder.path == (tmp_path / "renders").resolve() and spec.render_folder.stem == "kitchen"
    assert spec.size == (W, H) and spec.description == "a kitchen" and spec.category == "renders"
    with pytest.raises(BenchError, match="not a scene to render"):
        spec.build(W, H)
    for text, message in (("renders: r\nlayout: pbrt\n", "layout"), ("layout: oidn\n", "'renders'"),
                          ("renders: r\nlayout: oidn\nstems: x\n", r"unknown key\(s\) \['stems'\]"),
                          ("- a\n", "mapping")):
        (tmp_path / "bad.yaml").write_text(text)
        with pytest.raises(BenchError, match=message):
            scene_module(tmp_path / "bad.yaml")
