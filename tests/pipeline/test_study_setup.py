"""The study as the workflow sets it up (mcbench.pipeline.study_setup), without Snakemake: the
resolved config and its plan, the weights checks, the training, render and reference inputs the
rules' input functions return, the resources, and the plan's values the rules read."""

from __future__ import annotations

import json

import pytest

from mcbench import NOISY, BenchError
from mcbench.io.weights import COMMITTED_WEIGHTS, file_sha256
from mcbench.pipeline.reference_sources import STORE_FOLDER, reference_identity
from mcbench.pipeline.registry import load_scene
from mcbench.pipeline.study_setup import METRIC_PATTERN, setup_study

CONFIG = {"scenes": ["cornell_box", "glass_caustics"], "spp": [16, 4], "resolution": [16, 16],
          "denoisers": ["jbf", "oidn", "kpcn"], "study": {"pool": False}, "metrics": ["smape", "dssim"],
          "reference": {"spp": 256, "chunks": 2},
          "combiners": [{"name": "ens", "method": "ensemble", "inputs": ["jbf", "oidn"]},
                        {"name": "avg", "method": "naive_average", "inputs": ["ens", "kpcn"]}]}


@pytest.fixture(scope="module")
def study():
    return setup_study(dict(CONFIG), source="test.yaml")


def with_weights(tmp_path, **changes):
    """A study of CONFIG (with ``changes``) whose weights folder is ``tmp_path`` holding kpcn's."""
    (tmp_path / "kpcn.pt").write_bytes(b"weights")
    return setup_study({**CONFIG, "weights_dir": str(tmp_path), **changes}, source="test.yaml")


def test_the_config_is_resolved_planned_and_summarised(study):
    assert study.config["features"] == "first_hit" and study.config["scenes"] == ["cornell_box", "glass_caustics"]
    assert list(study.plan.methods) == ["jbf", "oidn", "kpcn", "ens", "avg"]
    assert study.weights_dir == str(COMMITTED_WEIGHTS)
    first, *notes = study.summary.splitlines()
    assert first == f"mcbench: configuration test.yaml with the schema's defaults, digest {study.digest}"
    assert notes == ["mcbench: references rendered (the store "
                     f"{STORE_FOLDER} has none of this resolution): cornell_box, glass_caustics"]
    assert "relmse" in METRIC_PATTERN.split("|") and "flip" in METRIC_PATTERN.split("|")
    assert list(study.metric_labels) == ["smape", "dssim"] and all(study.metric_labels.values())


def test_a_config_mistake_names_the_source_and_the_key():
    with pytest.raises(BenchError, match=r"^test.yaml: .*spp\[0\]"):
        setup_study({**CONFIG, "spp": [4.0]}, source="test.yaml")


def test_the_render_rules_carry_features_only_when_not_the_default(study, tmp_path):
    assert study.feature_params == {}
    assert with_weights(tmp_path, features="tungsten").feature_params == {"features": "tungsten"}


def test_missing_weights_stop_the_case_plan_naming_the_folder(tmp_path):
    study = setup_study({**CONFIG, "weights_dir": str(tmp_path / "wieghts")}, source="test.yaml")
    with pytest.raises(BenchError, match=f"no weights for kpcn in {tmp_path / 'wieghts'}"):
        study.case_plan
    assert study.missing_weights("kpcn") == [f"{tmp_path / 'wieghts'}/kpcn.pt"]
    study.check_weights("jbf")                                   # not learned: nothing to check


def test_the_case_plan_carries_the_weights_digest(tmp_path):
    study = with_weights(tmp_path)
    methods = {m["name"]: m for m in study.case_plan["methods"]}
    assert methods["kpcn"]["weights_sha256"] == file_sha256(tmp_path / "kpcn.pt")
    assert "weights_sha256" not in methods["jbf"]
    assert study.weights_sha256("oidn") == "" and study.missing_weights("kpcn") == []
    job = study.case_job("cornell_box", "4", {"metrics": "m.csv", "viewer": "v", "record": "r.json"})
    assert {m["name"]: m["weights"] for m in job["methods"]}["kpcn"] == f"{tmp_path}/kpcn.pt"


def test_weights_trained_on_other_features_are_refused(tmp_path):
    (tmp_path / "kpcn.json").write_text(json.dumps({"data": {"features": "tungsten"}}))
    with pytest.raises(BenchError, match="trained on 'tungsten' features"):
        with_weights(tmp_path).check_weights("kpcn")


def test_training_inputs_while_the_weights_are_missing(tmp_path):
    crops = ["t/example_{seed}_0.exr", "t/example_{seed}_1.exr"]
    correlated = ["t/c/{base}/example_{seed}_0.exr", "t/c/{base}/example_{seed}_1.exr"]
    study = setup_study({**CONFIG, "weights_dir": str(tmp_path)}, source="test.yaml")
    seeds = study.plan.training.seeds
    inputs = study.train_inputs("kpcn", crops, correlated)
    assert inputs == {"crops": [p.format(seed=s) for p in crops for s in seeds]}
    (tmp_path / "kpcn.pt").write_bytes(b"weights")
    assert study.train_inputs("kpcn", crops, correlated) == {}


def test_a_learned_combiner_trains_on_its_bases_results(tmp_path):
    study = setup_study({**CONFIG, "weights_dir": str(tmp_path),
                         "combiners": [{"name": "dc", "method": "deep_combiner", "inputs": ["kpcn"]}]},
                        source="test.yaml")
    training = study.plan.training
    crops = [f"t/example_{{seed}}_{k}.exr" for k in range(training.settings["crops"])]
    correlated = [f"t/c/{{base}}/example_{{seed}}_{k}.exr" for k in range(training.combiner_settings["crops"])]
    inputs = study.train_inputs("deep_combiner", crops, correlated)
    bases = study.combiner_bases("deep_combiner")
    assert bases and set(inputs) == {"crops", *(f"correlated_{base}" for base in bases)}
    n = len(training.combiner_seeds) * training.combiner_settings["crops"]
    assert all(len(files) == n for files in inputs.values())
    assert inputs[f"correlated_{bases[0]}"][0] == correlated[0].format(base=bases[0], seed=training.combiner_seeds[0])
    assert study.combiner_bases("kpcn") == ()


def test_render_and_reference_inputs_of_rendered_scenes(study):
    assert study.imported_case_files("cornell_box", "4") == []
    assert study.reference_inputs("cornell_box", "r/{scene}/chunk{chunk}.exr") == ["r/cornell_box/chunk0.exr",
                                                                                   "r/cornell_box/chunk1.exr"]
    records = study.render_cost_records("b/{scene}_spp{spp}.tsv", "b/{scene}_chunk{chunk}.tsv")
    assert records["noisy"] == ["b/cornell_box_spp4.tsv", "b/cornell_box_spp16.tsv",
                                "b/glass_caustics_spp4.tsv", "b/glass_caustics_spp16.tsv"]
    assert len(records["reference"]) == 4 and records["reference"][0] == "b/cornell_box_chunk0.tsv"


def test_resources_are_functions_of_the_wildcards_and_attempt(study, tmp_path):
    class Wildcards:
        scene, spp = "cornell_box", "4"

    resources = study.resources("render_noisy")
    assert set(resources) == {"mem_mb", "runtime"}
    first, second = resources["mem_mb"](Wildcards, 1), resources["mem_mb"](Wildcards, 2)
    assert isinstance(first, int) and second == 2 * first
    assert study.case_resources()["runtime"](Wildcards, 1) >= 1
    gpu = with_weights(tmp_path, gpus=1, variant="auto")
    assert gpu.resources("render_noisy")["gpu"] == 1 and "gpu" not in gpu.resources("gather_metrics")


def test_the_plan_values_the_rules_read(study):
    ranking, cases = study.plan.ranking, study.plan.cases
    assert ranking.speed_metric == "smape" and ranking.progressive_metrics == ["smape"]
    assert ranking.ranked_entries == [NOISY, *ranking.ranked] and ranking.table_order is None
    assert study.curve_entries == [NOISY, *ranking.ranked]
    assert cases.case_list[:2] == [{"scene": "cornell_box", "spp": 4}, {"scene": "cornell_box", "spp": 16}]
    assert cases.chunk_spp("cornell_box") == 128
    assert study.plan.method_inputs["avg"] == ["ens", "kpcn"]
    assert study.plan.comparison_methods["ens"] == {"module": "ensemble", "kind": "combiner", "inputs": ["jbf", "oidn"],
                                                    "params": {}, "label": study.plan.methods["ens"].label,
                                                    "comparison_role": "ensemble"}


def _stored_study(tmp_path, **reference):
    """A study of CONFIG whose store (in ``tmp_path``) holds cornell_box's reference at 16x16."""
    import numpy as np

    from mcbench.io.reference_store import write_stored_reference

    layers = {"color": np.ones((16, 16, 3), np.float32), "variance": np.zeros((16, 16, 3), np.float32)}
    write_stored_reference(tmp_path, "cornell_box", layers, provenance={"spp": 4096},
                           identity=reference_identity("cornell_box", load_scene("cornell_box"), (16, 16)))
    return setup_study({**CONFIG, "reference": {**CONFIG["reference"], "store": str(tmp_path), **reference}},
                       source="test.yaml")


def test_a_stored_reference_replaces_the_chunks_and_is_checked(tmp_path):
    study = _stored_study(tmp_path)
    cases = study.plan.cases
    assert cases.reference_source("cornell_box") == "store" and cases.rendered_references == ["glass_caustics"]
    chunk, check = "r/{scene}/chunk{chunk}.exr", "r/{scene}.check.json"
    assert study.reference_inputs("cornell_box", chunk) == [str(tmp_path / "16x16" / "cornell_box.exr")]
    assert study.reference_inputs("glass_caustics", chunk) == ["r/glass_caustics/chunk0.exr",
                                                               "r/glass_caustics/chunk1.exr"]
    assert study.reference_checks("cornell_box", check) == ["r/cornell_box.check.json"]
    assert study.reference_checks("glass_caustics", check) == []
    assert study.checked_render("cornell_box", "r/{scene}/spp{spp}.exr") == "r/cornell_box/spp16.exr"
    assert study.render_cost_records("n/{scene}_{spp}", chunk)["reference"] == ["r/glass_caustics/chunk0.exr",
                                                                              "r/glass_caustics/chunk1.exr"]
    assert "reference of cornell_box: from the store" in study.summary


def test_the_rules_wildcards_split_stored_and_merged_scenes(tmp_path):
    import re

    study = _stored_study(tmp_path)
    stored = re.compile(rf"results/references/(?P<scene>{study.stored_scene_pattern})\.exr$")
    merged = re.compile(rf"results/references/(?P<scene>{study.merged_scene_pattern})\.exr$")
    for scene, is_stored in (("cornell_box", True), ("glass_caustics", False), ("cornell_box2", False)):
        path = f"results/references/{scene}.exr"
        assert bool(stored.match(path)) == is_stored and bool(merged.match(path)) != is_stored, scene
    rendered = _stored_study(tmp_path, source="render")
    assert rendered.plan.cases.stored_scenes == [] and not re.fullmatch(rendered.stored_scene_pattern, "cornell_box")
