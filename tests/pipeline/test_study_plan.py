"""The typed plan (mcbench.pipeline.study_plan), built from a config without Snakemake: its
values are read-only, its case job names every file of a case in the layout the rules use, and
a case's plan follows the methods' settings and weights."""

from __future__ import annotations

import dataclasses

import pytest

from mcbench import NOISY
from mcbench.pipeline.config import resolve_config
from mcbench.pipeline.plan import plan_study

CONFIG = {"scenes": ["cornell_box", "glass_caustics"], "spp": [16, 4], "resolution": [16, 16],
          "denoisers": ["jbf", "oidn", "kpcn"], "study": {"pool": False}, "metrics": ["relmse", "smape"],
          "weights_dir": "w",
          "combiners": [{"name": "ens", "method": "ensemble", "inputs": ["jbf", "oidn"]},
                        {"name": "avg", "method": "naive_average", "inputs": ["ens", "kpcn"]}]}


@pytest.fixture(scope="module")
def plan():
    return plan_study(resolve_config(dict(CONFIG)), written=dict(CONFIG), source="test.yaml")


def test_the_plan_holds_the_configs_cases_and_methods_in_dependency_order(plan):
    assert plan.cases.pairs == [("cornell_box", 4), ("cornell_box", 16), ("glass_caustics", 4), ("glass_caustics", 16)]
    assert list(plan.methods) == ["jbf", "oidn", "kpcn", "ens", "avg"]
    assert plan.methods["avg"].inputs == ("ens", "kpcn") and plan.methods["avg"].kind == "combiner"
    assert plan.ranking.entries == [NOISY, "jbf", "oidn", "kpcn", "ens", "avg"]
    assert plan.weights_names() == ["kpcn"]


def test_the_plan_is_read_only(plan):
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.cases = None
    with pytest.raises(TypeError):
        plan.methods["new"] = plan.methods["jbf"]
    with pytest.raises(TypeError):
        plan.methods["jbf"].params["radius"] = 3


def test_a_case_job_names_every_file_of_the_case(plan):
    job = plan.case_job("glass_caustics", 4, outputs={"metrics": "m.csv", "viewer": "v", "record": "r.json"})
    assert job["render"] == "results/renders/glass_caustics/spp4.exr"
    assert job["reference"] == "results/references/glass_caustics.exr"
    by_name = {m["name"]: m for m in job["methods"]}
    assert [m["name"] for m in job["methods"]] == list(plan.methods)
    assert by_name["kpcn"]["weights"] == "w/kpcn.pt" and by_name["jbf"]["weights"] is None
    assert by_name["ens"]["exr"] == "results/outputs/glass_caustics/spp4/ens.exr"
    assert by_name["ens"]["timing"] == "results/outputs/glass_caustics/spp4/ens.json"
    entries = {e["entry"]: e for e in job["entries"]}
    assert entries[NOISY]["image"] == job["render"] and entries[NOISY]["weight_inputs"] == []
    assert entries["ens"]["image"] == by_name["ens"]["exr"] and entries["ens"]["weight_inputs"] == ["jbf", "oidn"]
    assert entries["avg"]["values"] == "results/metrics/glass_caustics/spp4/values/avg.json"
    assert entries["avg"]["viewer"] == "results/viewer_entries/glass_caustics/spp4/avg"
    assert job["outputs"] == {"metrics": "m.csv", "viewer": "v", "record": "r.json"}


def test_the_weights_folder_comes_from_the_config_and_defaults_to_the_committed_one(plan):
    from mcbench.io.weights import COMMITTED_WEIGHTS

    assert plan.paths.weights_dir == "w" and plan.paths.weights("kpcn") == "w/kpcn.pt"
    config = {key: value for key, value in CONFIG.items() if key != "weights_dir"}
    default = plan_study(resolve_config(dict(config)), written=dict(config), source="test.yaml")
    assert default.paths.weights("kpcn") == f"{COMMITTED_WEIGHTS}/kpcn.pt"


def test_the_key_of_a_method_covers_every_weights_file_it_reads():
    """Progressive denoising reads its variant's network and a learned divergence base's: the
    case job names those files and the case plan carries their digests; a learned method
    reading only its own weights keeps the one file's digest."""
    config = {**CONFIG, "denoisers": ["oidn", "kpcn"],
              "combiners": [{"name": "pd_kpcn", "method": "progressive", "inputs": ["kpcn"], "params": {"divergence": "kpcn"}},
                            {"name": "pd_no_sure", "method": "progressive", "inputs": ["oidn"], "params": {"sure_input": False}},
                            {"name": "pd_bound", "method": "progressive", "inputs": ["oidn"], "params": {"network": False}}]}
    plan = plan_study(resolve_config(dict(config)), written=dict(config), source="test.yaml")
    assert {n: m.weights for n, m in plan.methods.items()} == {
        "oidn": (), "kpcn": ("kpcn",), "pd_kpcn": ("progressive", "kpcn"), "pd_no_sure": ("progressive_no_sure",),
        "pd_bound": ()}
    assert plan.weights_names() == ["kpcn", "progressive", "progressive_no_sure"]
    job = plan.case_job("glass_caustics", 4, outputs={"metrics": "m.csv", "viewer": "v", "record": "r.json"})
    by_name = {m["name"]: m for m in job["methods"]}
    assert by_name["pd_kpcn"]["weights"] == "w/progressive.pt"
    assert by_name["pd_kpcn"]["weights_read"] == ["w/progressive.pt", "w/kpcn.pt"]
    assert by_name["kpcn"]["weights_read"] == ["w/kpcn.pt"] and by_name["oidn"]["weights_read"] == []
    digests = {"kpcn": "k", "progressive": "p", "progressive_no_sure": "s"}
    plan_of = {m["name"]: m.get("weights_sha256") for m in plan.case_plan(digests)["methods"]}
    assert plan_of == {"oidn": None, "kpcn": "k", "pd_kpcn": "p+k", "pd_no_sure": "s", "pd_bound": ""}


def test_a_case_plan_carries_the_learned_methods_weights_digest(plan):
    one = plan.case_plan({"kpcn": "a" * 64})
    other = plan.case_plan({"kpcn": "b" * 64})
    assert one != other and one["metrics"] == ["relmse", "smape"]
    assert [m.get("weights_sha256") for m in one["methods"]] == [None, None, "a" * 64, None, None]


def test_a_case_plan_names_the_columns_of_the_case_table(plan):
    """The columns of a case's metrics table are part of its job's params: a table written with
    other columns (the entries headed ``candidate``) makes Snakemake rerun the case."""
    from mcbench import METRICS_COLUMNS

    assert plan.case_plan({"kpcn": "a" * 64})["table_columns"] == list(METRICS_COLUMNS) == \
        ["scene", "spp", "entry", "metric", "value"]


def test_the_resource_requests_follow_each_jobs_size(plan):
    """A case's job asks for the sum of its methods' and evaluations' fitted costs; a bigger scene
    or more samples ask for more; GPUs only for the rules that render, when the config asks."""
    from mcbench.pipeline.resources import JobCost, StudyRequests

    costs = {"run_method": JobCost(base_s=600.0, s_per_mpx=1e5, base_mb=100.0),
             "evaluate_entry": JobCost(base_s=60.0, base_mb=50.0),
             "render_noisy": JobCost(base_s=1.0, s_per_gsample=1e6, base_mb=100.0)}
    requests = StudyRequests(plan, costs, gpus=1, variant="auto")
    one_method = StudyRequests(dataclasses.replace(plan, methods={"jbf": plan.methods["jbf"]}), costs)
    assert requests.case_request("cornell_box")["runtime"] > one_method.case_request("cornell_box")["runtime"]
    low = requests.request("render_noisy", scene="cornell_box", spp=4)
    high = requests.request("render_noisy", scene="cornell_box", spp=4096)
    assert high["runtime"] > low["runtime"]
    assert requests.request("render_noisy", scene="cornell_box", spp=4, attempt=2)["mem_mb"] == 2 * low["mem_mb"]
    assert requests.gpu_resources("render_noisy") == {"gpu": 1} and requests.gpu_resources("run_case") == {}
    assert StudyRequests(plan, costs, gpus=1, variant="llvm_ad_rgb").gpu_resources("render_noisy") == {}
