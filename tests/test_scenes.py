"""Every scene in scenes/ builds and renders finite, non-trivial buffers at tiny resolution,
at the lowest spp (2: one sample per half buffer) and a moderate one; the configs name only
existing scenes."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from mcbench.render import pick_variant, render_buffers
from scenes import available_scenes, load_scene

REPO = Path(__file__).resolve().parents[1]
SCENES = available_scenes()


@pytest.mark.parametrize("scene", SCENES)
def test_scene_declares_contract(scene):
    module = load_scene(scene)
    assert module.DESCRIPTION and len(module.DESCRIPTION.splitlines()) == 1
    assert module.CATEGORY
    width, height = module.RESOLUTION
    assert width >= 16 and height >= 16


@pytest.mark.parametrize("scene", SCENES)
def test_scene_renders_finite_at_every_spp(scene):
    """All of the paper's spp levels (and 2, one sample per half buffer) at 16x12 pixels."""
    module = load_scene(scene)
    pick_variant("auto")
    described = repr(module.build(16, 12))
    uses_medium = "'homogeneous'" in described or "'heterogeneous'" in described
    for spp in (2, 4, 8, 16, 32, 64, 128, 256, 512, 1024):
        layers, metadata = render_buffers(scene, spp, resolution=(16, 12))
        for name, layer in layers.items():
            assert np.all(np.isfinite(layer)), f"{scene} at {spp} spp: layer {name} not finite"
            assert layer.shape[:2] == (12, 16)
        assert layers["color"].min() >= 0 and layers["variance"].min() >= 0
    assert layers["color"].mean() > 0, f"{scene} renders black"
    assert ("volpath" in metadata["integrator"]) == uses_medium, f"{scene}: volpath only where there is a medium"


@pytest.mark.parametrize("config", ["config.yaml", "workflow/configs/smoke.yaml", "workflow/configs/paper.yaml"])
def test_configs_name_existing_scenes(config):
    scenes = yaml.safe_load((REPO / config).read_text())["scenes"]
    missing = sorted(set(scenes) - set(SCENES))
    assert not missing, f"{config} names scenes without a module: {missing}"
