"""Where a reference comes from: the store only for this scene, resolution and renderer; a stored
reference that disagrees with the local render stops the run naming the scene."""

import importlib.metadata
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from mcbench import BenchError
from mcbench.io.exr import read_layers, read_metadata, write_layers
from mcbench.io.reference_store import write_stored_reference
from mcbench.pipeline.reference_sources import (STORE_FOLDER, check_stored_reference, copy_stored_reference,
                                                reference_identity, reference_source, scene_digest, scene_files)

RESOLUTION = (32, 32)


def _python_scene(folder: Path, text="from mcbench.render.geometry import quad\nX = 1\n") -> ModuleType:
    path = folder / "box.py"
    path.write_text(text)
    module = ModuleType("scenes.box")
    module.__file__ = str(path)
    return module


def _xml_scene(folder: Path, asset_bytes=b"v 0 0 0\n") -> ModuleType:
    (folder / "meshes").mkdir(exist_ok=True)
    (folder / "meshes" / "a.obj").write_bytes(asset_bytes)
    path = folder / "room.xml"
    path.write_text('<scene version="3.0.0"><shape type="obj"><string name="filename" value="meshes/a.obj"/>'
                    '</shape></scene>')
    module = ModuleType("scenes.room")
    module.__file__ = str(path)
    return module


def test_a_python_scene_is_its_file_and_the_render_modules_it_builds_with(tmp_path):
    files = scene_files(_python_scene(tmp_path))
    assert "scene:box.py" in files and "module:mcbench.render.geometry" in files
    assert all(path.exists() for path in files.values())


def test_the_digest_follows_the_scene_file_and_its_assets(tmp_path):
    module = _python_scene(tmp_path)
    first = scene_digest(module)
    assert scene_digest(module) == first
    _python_scene(tmp_path, "from mcbench.render.geometry import quad\nX = 2\n")
    assert scene_digest(module) != first
    xml = _xml_scene(tmp_path / "x" if (tmp_path / "x").mkdir() is None else None)
    xml_digest = scene_digest(xml)
    assert "asset:meshes/a.obj" in scene_files(xml)
    _xml_scene(tmp_path / "x", asset_bytes=b"v 0 0 1\n")
    assert scene_digest(xml) != xml_digest


def test_the_digest_does_not_depend_on_where_the_checkout_is(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    assert scene_digest(_python_scene(a)) == scene_digest(_python_scene(b))


def _store(tmp_path, module, *, identity_changes=None, seed=0):
    rng = np.random.default_rng(seed)
    layers = {"color": rng.uniform(0.2, 1.0, (*RESOLUTION, 3)).astype(np.float32),
              "variance": np.full((*RESOLUTION, 3), 1e-6, np.float32)}
    identity = {**reference_identity("box", module, RESOLUTION), **(identity_changes or {})}
    store = tmp_path / "store"
    write_stored_reference(store, "box", layers, identity=identity, provenance={"spp": 4096})
    return store, layers


def test_the_store_is_used_only_for_this_identity(tmp_path):
    module = _python_scene(tmp_path)
    store, _ = _store(tmp_path, module)
    assert reference_source("box", module, RESOLUTION, requested="store", store=store).kind == "store"
    assert reference_source("box", module, RESOLUTION, requested="render", store=store).kind == "render"
    other_size = reference_source("box", module, (16, 16), requested="store", store=store)
    assert other_size.kind == "render" and "no reference" in other_size.reason
    _python_scene(tmp_path, "X = 3\n")          # the scene edited: its stored reference is not used
    edited = reference_source("box", module, RESOLUTION, requested="store", store=store)
    assert edited.kind == "render" and "scene_digest" in edited.reason


def test_a_store_of_another_mitsuba_is_not_used_and_says_so(tmp_path):
    module = _python_scene(tmp_path)
    store, _ = _store(tmp_path, module, identity_changes={"mitsuba": "0.0.1"})
    source = reference_source("box", module, RESOLUTION, requested="store", store=store)
    assert source.kind == "render"
    assert f"mitsuba: stored '0.0.1', this run '{importlib.metadata.version('mitsuba')}'" in source.reason


def test_a_misspelt_source_names_the_key(tmp_path):
    with pytest.raises(ValueError, match="reference.source"):
        reference_source("box", _python_scene(tmp_path), RESOLUTION, requested="stored")


def _render(path, color, variance, *, spp="64"):
    write_layers(path, {"color": color, "variance": variance}, metadata={"spp": spp})


def test_a_consistent_stored_reference_passes_and_a_biased_one_stops_the_run(tmp_path):
    module = _python_scene(tmp_path)
    store, layers = _store(tmp_path, module)
    stored = reference_source("box", module, RESOLUTION, requested="store", store=store).stored
    reference_path = tmp_path / "reference.exr"
    copy_stored_reference(stored, str(reference_path))
    np.testing.assert_array_equal(read_layers(reference_path, ["color"])["color"], layers["color"])
    assert read_metadata(reference_path)["stored_reference"] == "box.json"
    rng = np.random.default_rng(5)
    variance = np.full((*RESOLUTION, 3), 1e-4, np.float32)
    noisy = (layers["color"] + rng.normal(0, 1e-2, layers["color"].shape)).astype(np.float32)
    _render(tmp_path / "render.exr", noisy, variance)
    check_stored_reference("box", str(reference_path), str(tmp_path / "render.exr"), str(tmp_path / "check.json"))
    assert (tmp_path / "check.json").exists()
    biased = noisy.copy()
    biased[8:24, 8:24, 1] *= 1.02           # 2 % in one channel over a 16x16 region
    _render(tmp_path / "biased.exr", biased, variance)
    with pytest.raises(BenchError, match=r"scene 'box'.*max \|z\|"):
        check_stored_reference("box", str(reference_path), str(tmp_path / "biased.exr"), str(tmp_path / "c2.json"))
    assert not (tmp_path / "c2.json").exists()
    _render(tmp_path / "no_spp.exr", noisy, variance, spp="")
    with pytest.raises(BenchError, match=r"no_spp.exr: its header records no samples per pixel"):
        check_stored_reference("box", str(reference_path), str(tmp_path / "no_spp.exr"), str(tmp_path / "c3.json"))


def test_a_finished_runs_merged_reference_is_stored_as_its_chunks_would_be(tmp_path):
    """store_references on a finished run stores the reference it merged (its chunks, temporary,
    are gone) with the same pixels and provenance as storing the chunks themselves."""
    from mcbench.pipeline.reference_sources import store_reference_chunks
    from mcbench.pipeline.rendering import merge_reference
    from mcbench.io.reference_store import read_store_record

    rng = np.random.default_rng(5)
    chunks = []
    for k, (spp, seconds) in enumerate([(16, 2.5), (48, 7.0)]):
        color = rng.random((8, 8, 3))
        layers = {"color": color, "color_m2": color ** 2 + 0.1, "albedo": rng.random((8, 8, 3)),
                  "normal": rng.random((8, 8, 3)), "depth": rng.random((8, 8))}
        meta = {"scene": "cornell_box", "spp": spp, "chunk": k, "seeds": f"{100 + k}", "seed": 0,
                "variant": "llvm_ad_rgb", "resolution": "8x8", "mitsuba": "3.9.1", "seconds": seconds}
        chunks.append(str(tmp_path / f"chunk{k}.exr"))
        write_layers(chunks[-1], layers, metadata=meta)
    merged = str(tmp_path / "cornell_box.exr")
    merge_reference(chunks, merged)
    records = {}
    for name, inputs in (("from_chunks", chunks), ("from_merged", [merged])):
        record = tmp_path / name / "8x8" / "cornell_box.json"
        store_reference_chunks("cornell_box", inputs, str(record), features="first_hit")
        records[name] = read_store_record(tmp_path / name, "cornell_box", (8, 8))
    a, b = records["from_chunks"], records["from_merged"]
    for layer in ("color", "variance"):
        np.testing.assert_array_equal(read_layers(a.exr_path, [layer])[layer], read_layers(b.exr_path, [layer])[layer])
    for key in ("spp", "chunks", "seeds", "render_seconds", "variant"):
        assert a.provenance[key] == b.provenance[key], key
    assert b.provenance["spp"] == 64 and b.provenance["chunks"] == 2 and b.provenance["render_seconds"] == 9.5


@pytest.mark.parametrize("config_file", ["config.yaml", "workflow/configs/smoke.yaml"])
def test_the_committed_store_serves_every_scene_of_the_default_and_smoke_studies(config_file):
    """Every reference of the default and smoke studies comes from the repository's store: each
    record's identity is that of the current scene files, resolution and installed Mitsuba, and
    its EXR passes the store's checks (size, SHA-256, CRC-32, shapes, finite, variance >= 0). A
    scene or renderer module edited since the store was filled fails here, as does another Mitsuba:
    the run would still be right (it renders that reference and says why) but far slower; the
    store is refilled by `snakemake --cores 2 store_references` (docs/reference_store.md)."""
    import yaml

    from mcbench.io.reference_store import read_store_record, read_stored_layers
    from mcbench.pipeline.study_setup import setup_study

    root = Path(__file__).resolve().parents[2]
    plan = setup_study(yaml.safe_load((root / config_file).read_text()), source=config_file).plan
    sources = {scene: plan.cases.reference_source(scene) for scene in plan.cases.scenes}
    assert sources == {scene: "store" for scene in plan.cases.scenes}
    for scene in plan.cases.scenes:
        stored = read_store_record(STORE_FOLDER, scene, plan.cases.resolutions[scene])
        layers = read_stored_layers(stored)
        assert layers["color"].shape == layers["variance"].shape == (*plan.cases.resolutions[scene][::-1], 3)
