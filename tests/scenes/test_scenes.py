"""Every scene in scenes/ builds and renders finite, non-trivial buffers at tiny resolution,
at the lowest spp (2: one sample per half buffer) and a moderate one; the configs name only
existing scenes."""

import ast
from pathlib import Path

import numpy as np
import pytest
from mcbench.pipeline.config import read_config_file
from mcbench.render.renderer import render_buffers
from mcbench.render.variants import pick_variant
from mcbench.pipeline.config import resolve_config
from scenes import UnknownSceneError, available_scenes, load_scene, scene_spec

REPO = Path(__file__).resolve().parents[2]
SCENES = available_scenes()


@pytest.mark.parametrize("scene", SCENES)
def test_scene_declares_contract(scene):
    spec = scene_spec(load_scene(scene))
    assert spec.description and len(spec.description.splitlines()) == 1
    assert spec.category
    width, height = spec.size
    assert width >= 16 and height >= 16
    for name in ("DESCRIPTION", "CATEGORY", "RESOLUTION"):     # the declaration holds them, not the module
        assert not hasattr(load_scene(scene), name), (scene, name)


@pytest.fixture
def scratch_scene(tmp_path, monkeypatch):
    """A function writing ``scenes/<name>.py`` into a scratch folder on the registry's search path
    and loading it with :func:`scenes.load_scene`."""
    import sys

    import scenes

    monkeypatch.setattr(scenes, "__path__", [*scenes.__path__, str(tmp_path)])
    written = []

    def load(name: str, body: str):
        (tmp_path / f"{name}.py").write_text("from mcbench.contracts.scene import SceneSpec\n\n\n"
                                             "def build(width, height):\n    return {}\n\n" + body)
        written.append(f"scenes.{name}")
        return load_scene(name, config_key="scenes[0]")

    yield load
    for module in written:
        sys.modules.pop(module, None)


@pytest.mark.parametrize(("name", "body", "message"), [
    ("scratch_misspelt", "SCENE = SceneSpec(description='d', category='c', resoluton=(16, 16), build=build)\n",
     r"scenes\[0\]'?: scenes/scratch_misspelt\.py: SceneSpec has no field 'resoluton' \(did you mean 'resolution'\?\)"),
    ("scratch_type", "SCENE = SceneSpec(description='d', category='c', resolution=[16, 16], build=build)\n",
     r"scenes/scratch_type\.py: SceneSpec field 'resolution' must be"),
    ("scratch_size", "SCENE = SceneSpec(description='d', category='c', resolution=(16,), build=build)\n",
     r"scenes/scratch_size\.py: SceneSpec field 'resolution' must be \(width, height\)"),
    ("scratch_lines", "SCENE = SceneSpec(description='one\\ntwo', category='c', resolution=(16, 16), build=build)\n",
     r"scenes/scratch_lines\.py: SceneSpec field 'description' must be one non-empty line"),
    ("scratch_none", "DESCRIPTION = 'd'\nCATEGORY = 'c'\nRESOLUTION = (16, 16)\n",
     r"scenes/scratch_none\.py: SCENE must be a mcbench\.contracts\.scene\.SceneSpec .*found none"),
])
def test_the_registry_refuses_a_broken_scene_declaration_naming_the_file(scratch_scene, name, body, message):
    with pytest.raises(UnknownSceneError, match=message):
        scratch_scene(name, body)


def test_a_valid_scratch_scene_loads(scratch_scene):
    module = scratch_scene("scratch_ok", "SCENE = SceneSpec(description='d', category='c', resolution=(16, 12), "
                                         "build=build)\n")
    assert scene_spec(module).size == (16, 12) and scene_spec(module).render_folder is None


def test_scenes_import_only_core_building_blocks():
    """Scene modules build on core (mcbench.render.geometry, mcbench.render.curves), never on scenes/ helpers
    or on each other."""
    for path in sorted((REPO / "scenes").glob("[!_]*.py")):
        tree = ast.parse(path.read_text())
        imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
        imported |= {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import)
                     for alias in node.names}
        assert not {name for name in imported if name.split(".")[0] == "scenes"}, path.name
        assert "mcbench.render.geometry" in imported or path.stem == "cornell_box", path.name
    assert not list((REPO / "scenes").glob("_[!_]*.py"))     # no private helper modules left


# the default study's scenes (and the XML one) in the README's test command, the rest of the
# 30-scene suite in the extended tier (seconds to a minute each)
STUDY_SCENES = set(resolve_config({})["scenes"]) | {"xml_room"}


@pytest.mark.parametrize("scene", [scene if scene in STUDY_SCENES else pytest.param(scene, marks=pytest.mark.extended)
                                   for scene in SCENES])
def test_scene_renders_finite_at_every_spp(scene):
    """All of the paper's spp levels (and 2, one sample per half buffer) at 16x12 pixels."""
    module = load_scene(scene)
    pick_variant("auto")
    described = repr(scene_spec(module).build(16, 12))
    uses_medium = "'homogeneous'" in described or "'heterogeneous'" in described
    for spp in (2, 4, 8, 16, 32, 64, 128, 256, 512, 1024):
        layers, metadata = render_buffers(module, spp, resolution=(16, 12))
        for name, layer in layers.items():
            assert np.all(np.isfinite(layer)), f"{scene} at {spp} spp: layer {name} not finite"
            assert layer.shape[:2] == (12, 16)
        assert layers["color"].min() >= 0 and layers["variance"].min() >= 0
    assert layers["color"].mean() > 0, f"{scene} renders black"
    assert ("volpath" in metadata["integrator"]) == uses_medium, f"{scene}: volpath only where there is a medium"


@pytest.mark.parametrize("config", ["config.yaml", "workflow/configs/smoke.yaml", "workflow/configs/paper.yaml"])
def test_configs_name_existing_scenes(config):
    scenes = read_config_file(REPO / config)["scenes"]       # schema defaults filled in
    missing = sorted(set(scenes) - set(SCENES))
    assert not missing, f"{config} names scenes without a module: {missing}"
