"""export_case (workflow/rules/export.smk): a case in the authors' layout, whole or not at all."""

from __future__ import annotations

import numpy as np
import pytest

from mcbench.io.buffers import Denoised
from mcbench.io.case_folders import EXTRA_RENDER_FILES, RENDER_FILES, denoiser_files, read_image
from mcbench.io.exr import ExrError, write_layers
from mcbench.pipeline.export import REFERENCE_FILE, export_case


@pytest.fixture
def case(tmp_path, make_render_buffers):
    buffers = make_render_buffers(spp=8, half_std=0.05, seed=3, height=6, width=9)
    render, reference = tmp_path / "render.exr", tmp_path / "reference.exr"
    write_layers(render, buffers.layers, metadata={"spp": 8, "scene": "box", "resolution": "9x6"})
    write_layers(reference, {"color": buffers.color * 0.9}, metadata={"resolution": "9x6"})
    rng = np.random.default_rng(4)
    outputs = {}
    for name in ("oidn", "ens10"):
        result = Denoised(*(rng.uniform(0, 1, (6, 9, 3)).astype(np.float32) for _ in range(3)))
        outputs[name] = tmp_path / f"{name}.exr"
        write_layers(outputs[name], result.layers())
    return buffers, render, reference, outputs


def test_export_case_writes_every_file_of_the_layout(case, tmp_path):
    buffers, render, reference, outputs = case
    folder = tmp_path / "export" / "box" / "spp8"
    files = export_case(str(render), {k: str(v) for k, v in outputs.items()}, str(folder),
                        reference_path=str(reference))
    assert len(files) == len(RENDER_FILES) + len(EXTRA_RENDER_FILES) + 1 + 3 * len(outputs)
    for file, layer in {**RENDER_FILES, **EXTRA_RENDER_FILES}.items():
        np.testing.assert_array_equal(read_image(folder / file), buffers.layers[layer].astype(np.float32))
    np.testing.assert_allclose(read_image(folder / REFERENCE_FILE), buffers.color * 0.9, rtol=1e-7)
    for name, path in outputs.items():
        expected = Denoised.load(path)
        for image, file in denoiser_files(folder, name).items():
            np.testing.assert_array_equal(read_image(file), expected.image(image))
    assert [p.name for p in folder.parent.iterdir()] == ["spp8"]      # no staging folder left


def test_a_damaged_input_writes_nothing(case, tmp_path):
    _, render, reference, outputs = case
    outputs["oidn"].write_bytes(outputs["oidn"].read_bytes()[:200])
    folder = tmp_path / "export" / "box" / "spp8"
    with pytest.raises(ExrError, match="oidn.exr"):
        export_case(str(render), {k: str(v) for k, v in outputs.items()}, str(folder),
                    reference_path=str(reference))
    assert not folder.exists() and (not folder.parent.exists() or list(folder.parent.iterdir()) == [])
