"""The smoke config run end to end through a real SLURM (tests/workflow/slurm_local.py: slurmctld and
slurmd on this machine) with the project's profile, ``profiles/slurm``: every job is submitted
with sbatch, and the tables equal a local run's.

Skipped, with the reason, where this machine cannot run the daemons (not root, SLURM not
installed, a real cluster's slurm.conf present); with ``MCBENCH_REQUIRE_SLURM=1`` (set by
``.ci/run``) that is a failure instead, so CI never passes without the cluster run.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml

import tests.workflow.slurm_local as slurm_local
from tests.conftest import REPO, SMOKE_CONFIG

# extended: minutes of SLURM daemons and a second smoke run, beyond the README's test command (.ci/run
# runs the extended tier with MCBENCH_REQUIRE_SLURM=1)
pytestmark = [pytest.mark.slow, pytest.mark.extended]

# The tables that depend on the numbers only (timings differ between runs by nature).
COMPARED_TABLES = ["metrics.csv", "tables/ranking_*.csv", "tables/comparisons/table1_*.csv",
                   "tables/comparisons/table2_*.csv", "tables/comparisons/ranking_*.csv",
                   "tables/comparisons/ablations.csv"]
TIME_COLUMNS = {"time_ratio"}
COMPARED_TABLES.append("tables/progressive/consistency.csv")


def _local_rules() -> set[str]:
    """The rules that say `localrule: True` (run by the submitting Snakemake, never queued), read
    from the Snakefile and workflow/rules/*.smk."""
    names = set()
    for path in [REPO / "Snakefile", *sorted((REPO / "workflow/rules").glob("*.smk"))]:
        names |= set(re.findall(r"^\s*rule (\w+):\n\s+localrule: True", path.read_text(), re.MULTILINE))
    return names


LOCAL_RULES = _local_rules()
# the parse is checked against rules known to be local (and one known not to be)
assert {"all", "gather_metrics", "ranking_table", "study_tables", "progressive_tables"} <= LOCAL_RULES
assert "run_case" not in LOCAL_RULES and "progressive_curve" not in LOCAL_RULES


@pytest.fixture(scope="module")
def slurm_cluster(tmp_path_factory):
    reason = slurm_local.unavailable_reason()
    if reason:
        if os.environ.get("MCBENCH_REQUIRE_SLURM") == "1":
            pytest.fail(f"MCBENCH_REQUIRE_SLURM=1 but no local SLURM: {reason}")
        pytest.skip(reason)
    state = tmp_path_factory.mktemp("slurm_state")
    pids = slurm_local.start(state)
    try:
        yield state, pids
    finally:
        slurm_local.stop(state)
        for pid in pids.values():
            assert not Path(f"/proc/{pid}").exists() or "zombie" in Path(f"/proc/{pid}/status").read_text().lower(), \
                f"daemon {pid} still running after stop"


def _planned_jobs(workdir: Path) -> dict[str, int]:
    """{rule: jobs} of the smoke config's whole DAG in a fresh folder (dry run)."""
    workdir.mkdir()
    (workdir / "config.yaml").write_text(SMOKE_CONFIG.read_text())
    result = subprocess.run([sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-n", "--quiet",
                             "rules", "--directory", str(workdir), "--configfile", str(workdir / "config.yaml")],
                            capture_output=True, text=True, timeout=600)
    text = result.stdout + result.stderr
    assert result.returncode == 0, text[-3000:]
    table = text.split("Job stats:")[1].split("total")[0]
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^(\w+)\s+(\d+)$", table, re.MULTILINE)}


def _compared_files(results: Path) -> list[Path]:
    files = sorted({path for pattern in COMPARED_TABLES for path in results.glob(pattern)})
    assert files, f"no tables under {results}"
    return files


def test_smoke_config_through_slurm_equals_the_local_run(slurm_cluster, smoke_results, tmp_path):
    local_dir, _ = smoke_results
    workdir = tmp_path / "slurm_run"
    workdir.mkdir()
    (workdir / "config.yaml").write_text(yaml.safe_dump(yaml.safe_load(SMOKE_CONFIG.read_text())))
    command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "--directory", str(workdir),
               "--configfile", str(workdir / "config.yaml"), "--profile", str(REPO / "profiles" / "slurm"),
               "--jobs", "4", "--slurm-init-seconds-before-status-checks", "2", "--latency-wait", "5"]
    start = time.monotonic()
    result = subprocess.run(command, capture_output=True, text=True, timeout=2400)
    wall = time.monotonic() - start
    output = result.stdout + result.stderr
    assert result.returncode == 0, f"SLURM run failed:\n{output[-6000:]}"
    submitted = re.findall(r"has been submitted with SLURM jobid (\d+)", output)
    print(f"SLURM smoke run: {wall:.0f} s, {len(submitted)} jobs submitted")
    # every job of a non-local rule went through sbatch (the local rules ran here)
    planned = _planned_jobs(tmp_path / "plan")
    remote = sum(count for rule, count in planned.items() if rule not in LOCAL_RULES)
    assert len(set(submitted)) == len(submitted) == remote, (len(submitted), planned)

    for local_file in _compared_files(local_dir / "results"):
        relative = local_file.relative_to(local_dir / "results")
        slurm_file = workdir / "results" / relative
        assert slurm_file.exists(), f"{relative} missing from the SLURM run"
        local_table, slurm_table = pd.read_csv(local_file), pd.read_csv(slurm_file)
        drop = [c for c in local_table.columns if c in TIME_COLUMNS]
        pd.testing.assert_frame_equal(local_table.drop(columns=drop), slurm_table.drop(columns=drop),
                                      check_exact=True, obj=str(relative))
