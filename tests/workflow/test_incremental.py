"""Each edit of the config costs what it changes, and incremental equals from scratch.

A tiny study (one 16x16 scene, 4 spp, JBF, OIDN and their ensemble) is run once; each edit kind
of the config (a new plugin method, an external program, precomputed results, a combiner over
existing outputs, one method's params, a removed method, a new scene, a new spp level, a new
metric, the feature convention) is then applied to a copy of that finished study. For each: the
work must be exactly what the edit needs: the render jobs the dry run plans, and the method
outputs and entry evaluations the case jobs make (their records, mcbench.pipeline.cases: never
another method's output), then the tables; and after the incremental run every table
(mcbench.analysis.run_comparison: metrics.csv and every table, timing left out) must equal that
of a from-scratch run of the edited config.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from mcbench.analysis.run_comparison import compare_runs
from tests.conftest import REPO, run_snakemake

pytestmark = pytest.mark.slow

SCENE, SPP = "cornell_box", 4
BASE = {
    "variant": "auto", "seed": 0, "render_threads": 1, "resolution": [16, 16],
    "scenes": [SCENE], "spp": [SPP], "reference": {"spp": 64, "chunks": 1},
    "denoisers": ["jbf", "oidn"],
    "combiners": [{"name": "ens", "method": "ensemble", "inputs": ["jbf", "oidn"]}],
    "study": {"pool": False}, "metrics": ["relmse", "smape"],
    "oracle": {"repetitions": 2, "spp": 4, "denoisers": ["oidn", "jbf"]},
}
#: Rules that only assemble or tabulate finished results (each reruns when a result it reads changed).
TABLE_RULES = {"gather_metrics", "gather_timings", "ranking_table", "extras_table",
               "scene_table", "gallery", "error_curves", "speed_error", "viewer", "provenance_manifest", "all",
               "comparison_onehot", "comparison_ablations", "comparison_ranking", "study_tables", "study_figures",
               "progressive_tables"}
#: A program that "denoises" by copying its input (the README's external-program contract).
COPY_PROGRAM = ["sh", "-c", "cp {input_dir}/color.exr {output_dir}/{name}.exr && "
                "cp {input_dir}/colorA.exr {output_dir}/{name}A.exr && cp {input_dir}/colorB.exr {output_dir}/{name}B.exr"]


def planned_jobs(workdir: Path) -> list[tuple[str, dict, list[str]]]:
    """(rule, wildcards, outputs) of every job a dry run in ``workdir`` plans."""
    command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-n", "--nolock",
               "--directory", str(workdir), "--configfile", str(workdir / "config.yaml")]
    result = subprocess.run(command, capture_output=True, text=True, timeout=600)
    text = result.stdout + result.stderr
    assert result.returncode == 0, text[-3000:]
    jobs = []
    for block in re.split(r"\n(?=(?:local)?rule \w+:)", text):
        match = re.match(r"(?:local)?rule (\w+):", block)
        if not match:
            continue
        wildcards, outputs = {}, []
        for line in block.splitlines():
            line = line.strip()
            if line.startswith("wildcards:"):
                wildcards = dict(pair.strip().split("=", 1) for pair in line.split(":", 1)[1].split(","))
            elif line.startswith("output:"):
                outputs = [p.strip() for p in line.split(":", 1)[1].split(",")]
        jobs.append((match.group(1), wildcards, outputs))
    return jobs


def work_jobs(jobs) -> set[tuple[str, str]]:
    """What the planned jobs other than the cases' compute (not assemble or tabulate): (rule,
    "key=value/...") for each."""
    return {(rule, "/".join(f"{key}={value}" for key, value in sorted(wildcards.items())))
            for rule, wildcards, _ in jobs if rule not in TABLE_RULES and rule != "run_case"}


def made_by_cases(workdir: Path, jobs) -> set[tuple[str, str]]:
    """What the case jobs planned in ``jobs`` made, from their records after the run: ("method" |
    "metrics" | "viewer", "scene/spp/name") for each method output and entry evaluation."""
    made = set()
    for rule, wildcards, _ in jobs:
        if rule != "run_case":
            continue
        scene, spp = wildcards["scene"], wildcards["spp"]
        record = json.loads((workdir / f"results/cases/{scene}/spp{spp}.json").read_text())
        made |= {(kind, f"{scene}/{spp}/{name}") for kind, names in (("method", record["made"]["methods"]),
                 ("metrics", record["made"]["metrics"]), ("viewer", record["made"]["viewer"])) for name in names}
    return made


def write_config(workdir: Path, config: dict) -> None:
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "config.yaml").write_text(yaml.safe_dump(config))


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> Path:
    """The tiny study, finished."""
    workdir = tmp_path_factory.mktemp("incremental_base")
    write_config(workdir, BASE)
    run_snakemake(workdir)
    return workdir


def precomputed_dir(finished: Path, target: Path) -> str:
    """Files of a 'precomputed' method: JBF's results of the finished study, in the authors' naming."""
    from mcbench.io.buffers import Denoised
    from mcbench.io.case_folders import write_image

    output = Denoised.load(str(finished / f"results/outputs/{SCENE}/spp{SPP}/jbf.exr"))
    folder = target / SCENE / f"spp{SPP}" / "pre"
    folder.mkdir(parents=True)
    for suffix, image in (("", output.full), ("A", output.a), ("B", output.b)):
        write_image(folder / f"pre{suffix}.exr", image)
    return str(target)


def cases(scenes, spps, names):
    """A method's output and evaluation (metrics, viewer images) in each case; only the evaluation for 'noisy'."""
    return {(kind, f"{scene}/{spp}/{name}") for scene in scenes for spp in spps for name in names
            for kind in (["method"] if name != "noisy" else []) + ["metrics", "viewer"]}


def edit_plugin(config, finished, tmp):
    config["add_denoisers"] = [{"name": "jbf_wide", "method": "jbf", "label": "JBF wide", "params": {"radius": 9}}]
    return cases([SCENE], [SPP], ["jbf_wide"])


def edit_external(config, finished, tmp):
    # "copy" is also a reserved name of Snakemake's input lists: method names must never be used as such
    config["add_denoisers"] = [{"name": "copy", "method": "external", "label": "Copy",
                                "params": {"command": COPY_PROGRAM}}]
    return cases([SCENE], [SPP], ["copy"])


def edit_precomputed(config, finished, tmp):
    config["add_denoisers"] = [{"name": "pre", "method": "precomputed", "label": "Precomputed",
                                "params": {"dir": precomputed_dir(finished, tmp / "precomputed")}}]
    return cases([SCENE], [SPP], ["pre"])


def edit_combiner(config, finished, tmp):
    config["add_combiners"] = [{"name": "ens_exact", "method": "ensemble", "inputs": ["jbf", "oidn"],
                                "label": "Ensemble exact", "params": {"solver": "exact"}}]
    return cases([SCENE], [SPP], ["ens_exact"])


def edit_params(config, finished, tmp):
    config["denoisers"] = [{"name": "jbf", "method": "jbf", "params": {"sigma_color": 0.8}}, "oidn"]
    return cases([SCENE], [SPP], ["jbf", "ens"])          # JBF and the ensemble that reads it


def edit_remove(config, finished, tmp):
    config["combiners"] = []
    return set()                                          # tables only


def edit_scene(config, finished, tmp):
    config["scenes"] = [SCENE, "glass_caustics"]
    new = {("render_noisy", f"scene=glass_caustics/spp={SPP}"), ("merge_reference", "scene=glass_caustics"),
           ("render_reference_chunk", "chunk=0/scene=glass_caustics")}
    return new | cases(["glass_caustics"], [SPP], ["jbf", "oidn", "ens", "noisy"])


def edit_spp(config, finished, tmp):
    config["spp"] = [SPP, 8]
    return {("render_noisy", f"scene={SCENE}/spp=8")} | cases([SCENE], [8], ["jbf", "oidn", "ens", "noisy"])


def edit_metric(config, finished, tmp):
    config["metrics"] = ["relmse", "smape", "dssim"]
    # the ensemble's output, which no method reads, was removed after its evaluation
    # (keep_outputs: read): made again for the added metric, then removed again
    return {("metrics", f"{SCENE}/{SPP}/{name}") for name in ("jbf", "oidn", "ens", "noisy")} | \
        {("method", f"{SCENE}/{SPP}/ens")}


def edit_features(config, finished, tmp):
    config["features"] = "tungsten"
    # every render (noisy, reference, the oracle's) and everything that reads one
    renders = {("render_noisy", f"scene={SCENE}/spp={SPP}"), ("render_reference_chunk", f"chunk=0/scene={SCENE}"),
               ("merge_reference", f"scene={SCENE}"), ("oracle_study", f"scene={SCENE}")}
    return renders | cases([SCENE], [SPP], ["jbf", "oidn", "ens", "noisy"])


EDITS = {"plugin": edit_plugin, "external": edit_external, "precomputed": edit_precomputed,
         "combiner": edit_combiner, "params": edit_params, "remove": edit_remove, "scene": edit_scene,
         "spp": edit_spp, "metric": edit_metric, "features": edit_features}


#: The edit kinds of the README's test command (about 70 s each); the others are in the extended
#: tier (.ci/run runs it after the suite), so that command stays within its time.
DEFAULT_TIER = ("plugin", "params", "metric")


@pytest.mark.parametrize("kind", [kind if kind in DEFAULT_TIER else pytest.param(kind, marks=pytest.mark.extended)
                                  for kind in EDITS])
def test_an_edit_runs_only_what_it_changes_and_equals_a_run_from_scratch(finished, tmp_path, kind):
    incremental = tmp_path / "incremental"
    shutil.copytree(finished, incremental, symlinks=True)     # mtimes and Snakemake's records kept
    config = yaml.safe_load((finished / "config.yaml").read_text())
    expected = EDITS[kind](config, finished, tmp_path)
    write_config(incremental, config)
    jobs = planned_jobs(incremental)
    planned = work_jobs(jobs)
    assert planned == {item for item in expected if item[0] not in ("method", "metrics", "viewer")}, planned
    cases = [(wildcards["scene"], int(wildcards["spp"])) for rule, wildcards, _ in jobs if rule == "run_case"]
    assert len(cases) == len(set(cases))                 # one job a case, whatever it makes
    run_snakemake(incremental)
    made = made_by_cases(incremental, jobs)
    assert made == {item for item in expected if item[0] in ("method", "metrics", "viewer")}, sorted(made)
    if kind == "metric":                      # the entries' kept values: the two known, the added one
        records = sorted((incremental / "results" / "metrics").glob("*/spp*/values/*.json"))
        assert len(records) == len([item for item in expected if item[0] == "metrics"]), records
        for record in records:
            before = json.loads((finished / record.relative_to(incremental)).read_text())["values"]
            after = json.loads(record.read_text())["values"]
            assert set(before) == {"relmse", "smape"} and set(after) == {"relmse", "smape", "dssim"}, record
            assert {name: after[name] for name in before} == before, record
    assert "Nothing to be done" in run_snakemake(incremental, "-n").stdout + run_snakemake(incremental, "-n").stderr
    scratch = tmp_path / "scratch"
    write_config(scratch, config)
    run_snakemake(scratch)
    differences = compare_runs(incremental / "results", scratch / "results")
    assert not differences, differences
