"""A study bundle end to end: the session's smoke run is exported (`snakemake export_study`),
imported into a fresh copy of the checkout elsewhere, where `snakemake -n` plans nothing; a
config that adds one method plans that method's jobs and the tables, never a render or a run
of an existing method alone; a changed parameter of an existing method reruns it. (With the
bundle's Snakemake records left out, the clone plans nothing for the added method: the test
fails then.)"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml

from tests.conftest import REPO, run_snakemake

pytestmark = pytest.mark.slow

NEW_METHOD = {"name": "jbf_narrow", "method": "jbf", "params": {"radius": 3}}


def copy_checkout(target: Path) -> Path:
    """The checkout's files as git sees them (tracked and untracked-not-ignored), copied to
    ``target``: a fresh clone, with this checkout's uncommitted changes."""
    names = subprocess.run(["git", "-C", str(REPO), "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                           capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, names):
        source = REPO / name
        if source.is_file() and not source.is_symlink():
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target / name)
    return target


def clone_snakemake(clone: Path, config: Path, *args: str) -> subprocess.CompletedProcess:
    """The clone's own Snakefile in the clone (its root is the working folder)."""
    command = [sys.executable, "-m", "snakemake", "-s", str(clone / "Snakefile"), "--directory", str(clone),
               "--configfile", str(config), "--cores", "1", *args]
    result = subprocess.run(command, capture_output=True, text=True, timeout=600, cwd=clone,
                            env={**os.environ, "PYTHONPATH": str(clone)})
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return result


def planned_jobs(output: str) -> list[tuple[str, list[str]]]:
    """(rule, output files) of each job a dry run plans."""
    jobs = []
    for block in re.split(r"\n(?=(?:local)?rule \w+:)", output):
        match = re.match(r"(?:local)?rule (\w+):", block)
        if match:
            outputs = re.search(r"^\s+output: (.*)$", block, re.M)
            jobs.append((match.group(1), outputs.group(1).split(", ") if outputs else []))
    return jobs


def made_methods(clone: Path, cases) -> dict:
    """(scene, spp) -> the methods the case's last job made (its record, mcbench.pipeline.cases)."""
    import json

    return {(scene, spp): json.loads((clone / f"results/cases/{scene}/spp{spp}.json").read_text())["made"]["methods"]
            for scene, spp in cases}


def test_an_imported_study_plans_nothing_and_an_added_method_only_its_jobs(smoke_results, tmp_path):
    """Also: a changed parameter of an existing method reruns it (the imported Snakemake records'
    params trigger; without the records it would silently not)."""
    workdir, config = smoke_results
    run_snakemake(workdir, "export_study")
    bundle = workdir / "results" / "bundle" / "study.tar.gz"
    assert bundle.is_file()

    clone = copy_checkout(tmp_path / "clone")
    smoke = clone / "smoke.yaml"
    smoke.write_text(yaml.safe_dump(config))
    imported = subprocess.run([sys.executable, "-m", "mcbench.pipeline.bundle", "import", str(bundle),
                               "--configfile", str(smoke)], capture_output=True, text=True, cwd=clone, timeout=600,
                              env={**os.environ, "PYTHONPATH": str(clone)})
    assert imported.returncode == 0, imported.stderr
    assert (clone / "results" / "metrics.csv").read_bytes() == (workdir / "results" / "metrics.csv").read_bytes()

    dry = clone_snakemake(clone, smoke, "-n")
    assert "Nothing to be done" in dry.stdout + dry.stderr, dry.stdout[-3000:]

    # one more method: its jobs and what reads them, no render, no run of existing methods alone
    added = {**config, "denoisers": [*config["denoisers"], NEW_METHOD]}
    (clone / "added.yaml").write_text(yaml.safe_dump(added))
    jobs = planned_jobs(clone_snakemake(clone, clone / "added.yaml", "-n").stdout)
    rules = {rule for rule, _ in jobs}
    assert not [rule for rule in rules if rule.startswith("render_")], rules
    cases = [(scene, spp) for scene in config["scenes"] for spp in config["spp"]]
    planned_cases = sorted(f for rule, outputs in jobs if rule == "run_case" for f in outputs if f.startswith("results/cases/"))
    assert planned_cases == sorted(f"results/cases/{scene}/spp{spp}.json" for scene, spp in cases)
    assert {"ranking_table", "gather_metrics"} <= rules

    # run it: each case's job makes the new method alone (its record), and the clone's tables are
    # the exporter's plus the new method's rows
    clone_snakemake(clone, clone / "added.yaml", "--cores", "2")
    assert made_methods(clone, cases) == {case: [NEW_METHOD["name"]] for case in cases}
    exported, ranked = workdir / "results", clone / "results"
    before, after = (pd.read_csv(root / "metrics.csv") for root in (exported, ranked))
    new_rows = after.entry == NEW_METHOD["name"]
    pd.testing.assert_frame_equal(after[~new_rows].reset_index(drop=True), before)
    assert sorted(zip(after[new_rows].scene, after[new_rows].spp, after[new_rows].metric)) == sorted(
        (scene, spp, metric) for scene, spp in cases for metric in config["metrics"])
    for metric in config["metrics"]:
        table = f"tables/ranking_{metric}.csv"                  # the pool: the new base is not in it
        assert (ranked / table).read_bytes() == (exported / table).read_bytes(), table
        extras_before, extras_after = (pd.read_csv(root / f"tables/extras_{metric}.csv") for root in (exported, ranked))
        key = extras_after.columns[0]
        assert set(extras_after[key]) - set(extras_before[key]) == {NEW_METHOD["name"]}, metric
        kept = extras_after[extras_after[key] != NEW_METHOD["name"]].reset_index(drop=True)
        pd.testing.assert_frame_equal(kept, extras_before, check_dtype=False)

    # a changed parameter of an existing method: its runs are planned in every case
    changed = {**config, "denoisers": [{"name": "jbf", "params": {"radius": 3}} if d == "jbf" else d
                                       for d in config["denoisers"]]}
    assert changed["denoisers"] != config["denoisers"]
    (clone / "changed.yaml").write_text(yaml.safe_dump(changed))
    clone_snakemake(clone, clone / "changed.yaml", "--cores", "2")
    assert all("jbf" in made for made in made_methods(clone, cases).values())
