"""Cluster resources: the cost model's fit recovers known costs, requests follow the stated
margins and floors, bad cost files are named, and every job of the shipped configs declares
threads, memory and run time within the 2-GiB job limit at the default sizes."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.conftest import REPO
from mcbench import BenchError
from mcbench.pipeline.resources import (JOB_COSTS_PATH, JOB_MEMORY_LIMIT_MB, MEMORY_MARGIN, MIN_MEM_MB, MIN_RUNTIME_MIN,
                               RUNTIME_MARGIN, JobCost, estimate_job, fit_job_cost, job_request, load_job_costs,
                               write_job_costs)


def test_fit_recovers_known_costs_from_exact_records():
    truth = JobCost(base_s=2.0, s_per_mpx=30.0, s_per_mpx_entry=4.0, s_per_gsample=700.0,
                    base_mb=180.0, mb_per_mpx=900.0, mb_per_mpx_entry=15.0)
    records = []
    for pixels in (32 * 32, 128 * 128, 256 * 256):
        for entries in (1, 7, 50):
            for spp in (0, 64, 1024):
                seconds, rss = estimate_job(truth, pixels=pixels, entries=entries, spp=spp)
                records.append({"pixels": pixels, "entries": entries, "spp": spp, "seconds": seconds, "rss_mb": rss})
    fitted = fit_job_cost(records)
    for name, value in vars(truth).items():
        assert getattr(fitted, name) == pytest.approx(value, rel=1e-6, abs=1e-9), name


def test_fit_follows_the_largest_or_the_mean_job_of_each_size_and_drops_constant_columns():
    # two jobs of the same size (NFOR and OIDN share run_method): requests follow the larger
    records = [{"pixels": 16384, "entries": 1, "spp": 0, "seconds": s, "rss_mb": m} for s, m in ((2.0, 300.0), (5.0, 250.0))]
    fitted = fit_job_cost(records)
    assert fitted.base_s == pytest.approx(5.0) and fitted.base_mb == pytest.approx(300.0)
    assert fitted.s_per_mpx == fitted.mb_per_mpx == fitted.s_per_gsample == 0.0
    typical = fit_job_cost(records, statistic="mean")
    assert typical.base_s == pytest.approx(3.5) and typical.base_mb == pytest.approx(275.0)
    with pytest.raises(BenchError, match="statistic"):
        fit_job_cost(records, statistic="median")
    with pytest.raises(BenchError, match="1 records"):
        fit_job_cost(records[:1])


def test_requests_apply_the_margins_and_floors():
    assert job_request(10.0, 100.0) == {"mem_mb": MIN_MEM_MB, "runtime": MIN_RUNTIME_MIN}
    # 1000 MB x 1.5 = 1500 -> next multiple of 64: 1536; 600 s x 3 = 30 min
    assert MEMORY_MARGIN == 1.5 and RUNTIME_MARGIN == 3.0
    assert job_request(600.0, 1000.0) == {"mem_mb": 1536, "runtime": 30}
    assert job_request(601.0, 1000.0)["runtime"] == 31


def test_a_bad_cost_file_is_named_with_the_rule(tmp_path):
    path = tmp_path / "costs.yaml"
    path.write_text("rules:\n  render_noisy: {base_s: -1}\n")
    with pytest.raises(BenchError, match=r"costs.yaml: rules.render_noisy: .*base_s"):
        load_job_costs(path)
    path.write_text("rules:\n  render_noisy: {base_seconds: 1}\n")
    with pytest.raises(BenchError, match=r"rules.render_noisy: unknown cost fields \['base_seconds'\]"):
        load_job_costs(path)
    path.write_text("- not a mapping\n")
    with pytest.raises(BenchError, match="costs.yaml"):
        load_job_costs(path)


def test_written_costs_read_back_and_the_committed_file_loads(tmp_path):
    costs = {"render_noisy": JobCost(base_s=1.5, s_per_gsample=800.0, base_mb=185.0)}
    typical = {"render_noisy": JobCost(base_s=1.0, base_mb=180.0)}
    write_job_costs({"rules": costs, "typical": typical}, tmp_path / "c.yaml", header="fitted by hand\nfor a test")
    assert load_job_costs(tmp_path / "c.yaml") == costs
    assert load_job_costs(tmp_path / "c.yaml", section="typical") == typical
    assert (tmp_path / "c.yaml").read_text().startswith("# fitted by hand\n# for a test\n")
    for section in ("rules", "typical"):
        committed = load_job_costs(JOB_COSTS_PATH, section=section)
        assert {"render_noisy", "render_reference_chunk", "run_method", "run_method/nfor",
                "evaluate_entry"} <= set(committed), section


def _planned_resources(configfile: Path, *extra: str, workdir: Path) -> list[tuple[str, dict]]:
    """(rule, resources) of every job a dry run of ``configfile`` plans in an empty folder."""
    workdir.mkdir()
    result = subprocess.run([sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-n", "--nolock",
                             "--directory", str(workdir), "--configfile", str(configfile), *extra],
                            capture_output=True, text=True, timeout=900)
    text = result.stdout + result.stderr
    assert result.returncode == 0, text[-3000:]
    jobs, rule = [], None
    for line in text.splitlines():
        match = re.match(r"^(?:local)?rule (\w+):", line)
        if match:
            rule = match.group(1)
        elif line.strip().startswith("resources:") and rule:
            values = dict(item.split("=", 1) for item in line.split(":", 1)[1].replace(" ", "").split(",") if "=" in item)
            jobs.append((rule, values))
            rule = None
    return jobs


@pytest.mark.slow
@pytest.mark.parametrize("configfile", ["config.yaml", "workflow/configs/smoke.yaml"])
def test_every_job_declares_memory_and_runtime_within_the_job_limit(configfile, tmp_path):
    jobs = _planned_resources(REPO / configfile, workdir=tmp_path / "plan")
    assert len(jobs) > 50
    # the target rule `all` runs nothing (no action, no resources); every other job must declare them
    assert {rule for rule, resources in jobs if "mem_mb" not in resources} == {"all"}
    jobs = [(rule, resources) for rule, resources in jobs if rule != "all"]
    for rule, resources in jobs:
        assert int(resources["mem_mb"]) >= MIN_MEM_MB and int(resources["runtime"]) >= MIN_RUNTIME_MIN, rule
        assert int(resources["mem_mb"]) <= JOB_MEMORY_LIMIT_MB, (rule, resources)
        assert "gpu" not in resources, f"{rule} asks for a GPU though config gpus is 0"


@pytest.mark.slow
def _smoke_rendering_its_references(path: Path, **changes) -> Path:
    """The smoke config with ``changes``, its references rendered (not taken from the repository's
    store), so that every render rule is planned."""
    config = yaml.safe_load((REPO / "workflow/configs/smoke.yaml").read_text())
    config["reference"] = {**config["reference"], "source": "render"}
    path.write_text(yaml.safe_dump({**config, **changes}))
    return path


def test_gpu_jobs_are_the_renders_when_the_config_asks(tmp_path):
    config = _smoke_rendering_its_references(tmp_path / "gpu.yaml", gpus=1, gpu_model="a100")
    jobs = _planned_resources(config, workdir=tmp_path / "plan")
    with_gpu = {rule for rule, resources in jobs if resources.get("gpu") == "1" and resources.get("gpu_model") == "a100"}
    assert with_gpu == {"render_noisy", "render_reference_chunk", "oracle_study"}
    assert all("gpu" not in resources for rule, resources in jobs if rule not in with_gpu)


def test_reference_chunks_ask_for_more_time_with_more_samples():
    cost = load_job_costs(JOB_COSTS_PATH)["render_reference_chunk"]
    small = job_request(*estimate_job(cost, pixels=128 * 128, spp=4096))
    paper = job_request(*estimate_job(cost, pixels=256 * 256, spp=32768 // 4))
    assert paper["runtime"] > small["runtime"]


@pytest.mark.slow
def test_paper_config_plans_under_the_slurm_profile(tmp_path):
    jobs = _planned_resources(REPO / "workflow/configs/paper.yaml", "--profile", str(REPO / "profiles/slurm"),
                              workdir=tmp_path / "plan")
    rules = {rule for rule, _ in jobs}
    assert "render_reference_chunk" in rules and "run_case" in rules
    assert sum(rule == "render_noisy" for rule, _ in jobs) == 30 * 9
    for rule, resources in jobs:
        if rule != "all":
            assert int(resources["mem_mb"]) <= JOB_MEMORY_LIMIT_MB, (rule, resources)


@pytest.mark.slow
def test_the_gpu_profile_gives_the_renders_a_gpu(tmp_path):
    jobs = _planned_resources(_smoke_rendering_its_references(tmp_path / "smoke.yaml"), "--profile",
                              str(REPO / "profiles/slurm-gpu"), workdir=tmp_path / "plan")
    assert {rule for rule, resources in jobs if resources.get("gpu") == "1"} == \
        {"render_noisy", "render_reference_chunk", "oracle_study"}
