"""The reference store end to end on a one-scene 32x32 study: `store_references` fills a store
from the config's reference settings; a run with `reference.source: store` takes the stored
reference (no chunk rendered), checks it against its own highest-spp render and tables it; a
stored reference from another scene file is not used (rendered, and the log says why); a stored
reference whose pixels are biased (beyond this tiny study's noise) stops the run naming the scene before any case job."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from mcbench.io.exr import read_layers, read_metadata
from mcbench.io.reference_store import read_store_record, write_stored_reference
from tests.conftest import run_snakemake as snakemake

pytestmark = [pytest.mark.slow, pytest.mark.extended]     # five runs of a one-scene study (4 min): the extended tier

SCENE, SIZE = "cornell_box", 32
CONFIG = {"variant": "auto", "seed": 0, "render_threads": 1, "resolution": [SIZE, SIZE], "scenes": [SCENE],
          "spp": [4, 64], "reference": {"spp": 1024, "chunks": 2}, "denoisers": ["jbf"], "combiners": [],
          "study": {"pool": False}, "metrics": ["relmse", "relmse_corrected"]}


def _study(folder: Path, **reference) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    config = {**CONFIG, "reference": {**CONFIG["reference"], **reference}}
    (folder / "config.yaml").write_text(yaml.safe_dump(config))
    return folder


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> Path:
    """A store made by `store_references` of the tiny study."""
    folder = _study(tmp_path_factory.mktemp("make_store"), store=str(tmp_path_factory.getbasetemp() / "store"))
    snakemake(folder, "store_references")
    return tmp_path_factory.getbasetemp() / "store"


def test_store_references_writes_a_record_with_its_provenance(store):
    stored = read_store_record(store, SCENE, (SIZE, SIZE))
    assert stored.identity["scene"] == SCENE and stored.identity["resolution"] == f"{SIZE}x{SIZE}"
    assert stored.provenance["spp"] == 1024 and stored.provenance["chunks"] == 2
    assert {"commit", "mitsuba", "drjit", "variant", "cpu", "render_seconds", "features"} <= set(stored.provenance)


def test_a_run_takes_the_stored_reference_checks_it_and_renders_no_reference(store, tmp_path):
    folder = _study(tmp_path / "run", store=str(store))
    result = snakemake(folder)
    assert "reference of cornell_box: from the store" in result.stdout + result.stderr
    results = folder / "results"
    assert not list((results / "logs").glob("render_reference/*")), "a stored reference renders no chunk"
    assert read_metadata(results / "references" / f"{SCENE}.exr")["stored_reference"] == f"{SCENE}.json"
    stored = read_store_record(store, SCENE, (SIZE, SIZE))
    np.testing.assert_array_equal(read_layers(results / "references" / f"{SCENE}.exr", ["color"])["color"],
                                  read_layers(stored.exr_path, ["color"])["color"])
    check = json.loads((results / "references" / f"{SCENE}.check.json").read_text())
    assert check["passed"] and check["render"].endswith("spp64.exr")
    assert (results / "metrics.csv").exists()
    assert "Nothing to be done" in (r := snakemake(folder, "-n")).stdout + r.stderr


def test_an_edited_scene_renders_its_reference_and_says_why(store, tmp_path):
    """A store whose record names another scene digest (an edited scene file) is not used."""
    edited = tmp_path / "edited_store"
    shutil.copytree(store, edited)
    record = edited / f"{SIZE}x{SIZE}" / f"{SCENE}.json"
    data = json.loads(record.read_text())
    data["identity"]["scene_digest"] = "0" * 64
    record.write_text(json.dumps(data))
    folder = _study(tmp_path / "run", store=str(edited))
    result = snakemake(folder, "-n")
    assert "another scene or renderer (scene_digest" in result.stdout + result.stderr
    assert "render_reference_chunk" in result.stdout and "stored_reference" not in result.stdout


def test_a_biased_stored_reference_stops_the_run_naming_the_scene(store, tmp_path):
    biased = tmp_path / "biased_store"
    stored = read_store_record(store, SCENE, (SIZE, SIZE))
    layers = read_layers(stored.exr_path, ["color", "variance"])
    layers["color"] = layers["color"].copy()
    # 15 % in one channel: this study checks against a 64-spp render of 32x32 pixels, whose block
    # means carry about 2 % noise (tests/analysis/test_reference_check.py holds 2 % at lower noise)
    layers["color"][:, :, 0] *= 1.15
    write_stored_reference(biased, SCENE, layers, identity=stored.identity, provenance=stored.provenance)
    folder = _study(tmp_path / "run", store=str(biased))
    result = snakemake(folder, check=False)
    assert result.returncode != 0
    output = result.stdout + result.stderr
    assert f"scene '{SCENE}': the stored reference" in output and "max |z|" in output
    assert not (folder / "results" / "metrics.csv").exists()
    assert (folder / "results" / "renders" / SCENE / "spp64.exr").exists(), "the renders made are kept"


def test_render_ignores_the_store(store, tmp_path):
    folder = _study(tmp_path / "run", store=str(store), source="render")
    result = snakemake(folder, "-n")
    assert "render_reference_chunk" in result.stdout and "check_reference" not in result.stdout
