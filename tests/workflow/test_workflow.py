"""End-to-end runs of the Snakemake DAG on the tiny smoke config (a few 32×32 scenes, two
spp levels): tables exist, the ensemble beats the noisy input, a killed run resumes, and bad
inputs stop the run with an error naming the file or config key while keeping finished outputs."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from tests.conftest import REPO, SMOKE_CONFIG as SMOKE, run_snakemake as snakemake

pytestmark = pytest.mark.slow


def write_config(workdir: Path, **changes) -> dict:
    config = yaml.safe_load(SMOKE.read_text())
    config.update(changes)
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "config.yaml").write_text(yaml.safe_dump(config))
    return config


@pytest.fixture(scope="module")
def smoke_run(smoke_results):
    """The session's smoke run (tests/conftest.py), shared with the report tests."""
    return smoke_results


POOL_SLICE = ["kpcn", "nfor", "oidn", "rdfc", "ens10", "ens15"]   # study.ensembles [10, 15], in ID order
EXTRAS = ["jbf", "ensemble", "ensemble_exact", "onehot_sbf", "onehot_nfor", "onehot_post", "naive",
          "ensemble_unconstrained", "pd_oidn"]
METRICS = ("relmse", "relmse_corrected", "smape", "dssim", "flip")


def _scores_by_counting(values: pd.DataFrame) -> pd.DataFrame:
    """Sec. 5.3.3 by counting: score = 1 + (entries with a larger error) + (ties) / 2."""
    return values.apply(lambda row: row.map(lambda v: 1 + (row > v).sum() + ((row == v).sum() - 1) / 2), axis=1)


def test_tables_exist_and_ensemble_beats_noisy(smoke_run):
    workdir, config = smoke_run
    for metric in METRICS:
        table = pd.read_csv(workdir / f"results/tables/ranking_{metric}.csv")
        # the ranking pool: the pool's slice in ID order, then the noisy input; nothing else
        assert list(table["candidate"]) == POOL_SLICE + ["noisy"]
        assert list(table.columns) == ["candidate", "4", "64", "Avg."]
        text = (workdir / f"results/tables/ranking_{metric}.md").read_text()
        assert text.startswith("# Ranking") and "Partial pool: 6 of the 39 candidates" in text
        extras = pd.read_csv(workdir / f"results/tables/extras_{metric}.csv")
        assert list(extras["candidate"]) == EXTRAS
    metrics = pd.read_csv(workdir / "results/metrics.csv")
    assert len(metrics) == 3 * 2 * 16 * 5  # scenes × spp × (candidates + noisy) × metrics
    assert np.isfinite(metrics["value"]).all()
    relmse = metrics[metrics.metric == "relmse"].pivot_table(index=["scene", "spp"], columns="candidate", values="value")
    # At 32x32 the denoisers' blur of the Cornell box's light edge can cost more relMSE than
    # the noise they remove in a single case, so the claim is checked over all cases: the
    # ensemble's mean relMSE and its relMSE ranking score beat the noisy input's.
    assert relmse["ensemble"].mean() < relmse["noisy"].mean(), relmse
    ranking = pd.read_csv(workdir / "results/tables/ranking_relmse.csv").set_index("candidate")
    assert ranking.loc["ens15", "Avg."] > ranking.loc["noisy", "Avg."]
    # the ensembles are never worse than their worst base denoiser, case by case
    assert (relmse["ensemble"] <= relmse[["oidn", "jbf"]].max(axis=1)).all(), relmse
    assert (relmse["ens15"] <= relmse[["oidn", "rdfc"]].max(axis=1)).all(), relmse
    # every ranking value recomputed independently from metrics.csv, and every extra method's
    # score with it added alone to the pool
    for metric in METRICS:
        pool = POOL_SLICE + ["noisy"]
        values = metrics[(metrics.metric == metric)].pivot_table(index=["scene", "spp"], columns="candidate",
                                                                values="value")
        per_spp = _scores_by_counting(values[pool]).groupby(level="spp").mean().T
        table = pd.read_csv(workdir / f"results/tables/ranking_{metric}.csv").set_index("candidate")
        for spp in (4, 64):
            np.testing.assert_allclose(table[str(spp)], per_spp.loc[table.index, spp], atol=5e-5)
        np.testing.assert_allclose(table["Avg."], per_spp.loc[table.index].mean(axis=1), atol=5e-5)
        extras = pd.read_csv(workdir / f"results/tables/extras_{metric}.csv").set_index("candidate")
        for name in ("ensemble", "jbf"):
            alone = _scores_by_counting(values[pool + [name]])[name].groupby(level="spp").mean()
            np.testing.assert_allclose(extras.loc[name, ["4", "64"]].to_numpy(float), alone.to_numpy(), atol=5e-5)
    # the study's tables and figures
    study = workdir / "results/tables/study"
    for name in ("paper_table3.md", "recommendations.md", "findings.md", "summary.md"):
        assert (study / name).stat().st_size > 0, name
    recommendations = pd.read_csv(study / "recommendations.csv")
    assert set(recommendations["ours"].dropna()) <= {"ens10", "ens15"}
    for metric in METRICS:
        for key in ("error_curves", "score_curves", "score_size", "speed_score", "equal_time"):
            assert (workdir / f"results/figures/study/{key}_{metric}.png").stat().st_size > 1000
    # progressive denoising: its exceptions recounted from metrics.csv, per-spp means, the curve
    consistency = pd.read_csv(workdir / "results/tables/progressive/consistency.csv")
    assert list(consistency["spp"]) == [4, 64] and set(consistency["entry"]) == {"pd_oidn"}
    for _, row in consistency.iterrows():
        case = relmse.xs(int(row["spp"]), level="spp")
        assert row["worse"] == int((case["pd_oidn"] > case["noisy"]).sum())
        assert row["value"] == pytest.approx(case["pd_oidn"].mean(), rel=1e-5)
    per_spp = pd.read_csv(workdir / "results/tables/progressive/per_spp.csv")
    assert set(per_spp["entry"]) >= {"noisy", "oidn", "pd_oidn"} and {"relmse", "smape", "seconds"} <= set(per_spp["quantity"])
    curve = pd.read_csv(workdir / f"results/progressive/{config['scenes'][0]}/curve.csv")
    assert sorted(set(curve["spp"])) == [4, 16] and np.isfinite(curve[["relmse", "smape"]].to_numpy()).all()
    assert (workdir / f"results/progressive/{config['scenes'][0]}/curve.png").stat().st_size > 1000
    # the comparison methods: in metrics.csv and their own tables, not in the ranking pool
    relmse_all = metrics[metrics.metric == "relmse"].pivot_table(index=["scene", "spp"], columns="candidate",
                                                                 values="value")
    table1 = pd.read_csv(workdir / "results/tables/comparisons/table1_relmse.csv")
    cell = table1[(table1["size"].astype(str) == "2") & (table1["spp"].astype(str) == "4")].iloc[0]
    wins = (relmse_all.xs(4, level="spp")["ensemble"]
            < relmse_all.xs(4, level="spp")[["onehot_sbf", "onehot_nfor"]].min(axis=1))
    assert (int(cell["cases"]), int(cell["wins"])) == (3, int(wins.sum())), table1
    ranking_cmp = pd.read_csv(workdir / "results/tables/comparisons/ranking_relmse.csv")
    assert {"onehot_sbf", "onehot_nfor", "onehot_post", "naive", "ensemble_unconstrained"} <= set(ranking_cmp["candidate"])
    assert "unconstrained weights (5.2.1)" in (workdir / "results/tables/comparisons/ablations.md").read_text()
    oracle = pd.read_csv(workdir / f"results/oracle/{config['scenes'][0]}/table.csv")
    assert len(oracle) >= 9 and np.isfinite(oracle.select_dtypes("number")).all().all(), oracle
    timings = pd.read_csv(workdir / "results/timings.csv")
    assert set(timings["method"]) == set(POOL_SLICE + EXTRAS)
    assert (timings["seconds"] > 0).all()
    # one job per case runs every method (batch_methods), with its benchmark record
    assert len(list((workdir / "results/benchmarks/batches").glob("*_methods.tsv"))) == 3 * 2


def test_rerun_has_nothing_to_do(smoke_run):
    workdir, _ = smoke_run
    result = snakemake(workdir, "-n")
    assert "Nothing to be done" in result.stdout + result.stderr


def test_corrupt_render_stops_with_file_name_and_keeps_outputs(smoke_run, tmp_path):
    workdir = tmp_path / "corrupt"
    shutil.copytree(smoke_run[0], workdir, ignore=shutil.ignore_patterns(".snakemake"))
    render = workdir / "results/renders/cornell_box/spp4.exr"
    render.write_bytes(render.read_bytes()[:200])
    output = workdir / "results/outputs/cornell_box/spp4/oidn.exr"
    output.unlink()  # force the denoiser to read the corrupt render
    kept = workdir / "results/outputs/glass_caustics/spp64/ensemble.exr"
    kept_mtime = kept.stat().st_mtime_ns
    result = snakemake(workdir, "results/outputs/cornell_box/spp4/oidn.exr", check=False)
    assert result.returncode != 0
    assert "renders/cornell_box/spp4.exr" in result.stdout + result.stderr
    assert kept.stat().st_mtime_ns == kept_mtime


def test_nan_render_is_refused_naming_file_and_count(smoke_run, tmp_path):
    from mcbench.io.exr import read_layers, write_layers

    workdir = tmp_path / "nan"
    shutil.copytree(smoke_run[0], workdir, ignore=shutil.ignore_patterns(".snakemake"))
    render = workdir / "results/renders/envmap_objects/spp64.exr"
    layers = read_layers(render)
    layers["color_a"][:] = np.nan
    write_layers(render, layers, metadata={"spp": 64})
    (workdir / "results/outputs/envmap_objects/spp64/jbf.exr").unlink()
    result = snakemake(workdir, "results/outputs/envmap_objects/spp64/jbf.exr", check=False)
    text = result.stdout + result.stderr
    assert result.returncode != 0
    assert "renders/envmap_objects/spp64.exr" in text and "1024 pixel(s) with NaN/Inf" in text


def test_unknown_method_is_named_before_any_job(tmp_path):
    workdir = tmp_path / "unknown"
    write_config(workdir, denoisers=["oidn", "nfro"])
    result = snakemake(workdir, "-n", check=False)
    text = result.stdout + result.stderr
    assert result.returncode != 0
    assert "denoisers[1]" in text and "nfro" in text
    assert not (workdir / "results").exists()


def test_invalid_config_is_refused(tmp_path):
    workdir = tmp_path / "invalid"
    write_config(workdir, spp=[4, 7])
    result = snakemake(workdir, "-n", check=False)
    assert result.returncode != 0 and "7" in result.stdout + result.stderr


@pytest.mark.extended     # 100 s; the fuzz tier's random kills (test_interruptions.py) cover every stage too
def test_killed_run_resumes_without_redoing_finished_jobs(tmp_path):
    workdir = tmp_path / "resume"
    write_config(workdir, scenes=["cornell_box", "envmap_objects"])
    renders = [f"results/renders/{s}/spp{n}.exr" for s in ("cornell_box", "envmap_objects") for n in (4, 64)]
    snakemake(workdir, *renders)
    mtimes = {r: (workdir / r).stat().st_mtime_ns for r in renders}
    command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "--directory", str(workdir),
               "--configfile", str(workdir / "config.yaml"), "--cores", "2"]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 300
    while time.time() < deadline and not list((workdir / "results/outputs").glob("*/*/*.json")):
        time.sleep(0.2)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    assert list((workdir / "results/outputs").glob("*/*/*.json")), "no method finished before the kill"
    # A hard kill leaves Snakemake's lock behind; unlocking is the documented first step.
    snakemake(workdir, "--unlock")
    result = snakemake(workdir, "--rerun-incomplete")
    assert not re.search(r"^(local)?rule render_noisy:", result.stdout + result.stderr, re.MULTILINE)
    assert re.search(r"^(local)?rule run_(method|case_methods):", result.stdout + result.stderr, re.MULTILINE)
    for render, mtime in mtimes.items():
        assert (workdir / render).stat().st_mtime_ns == mtime, f"{render} was redone"
    assert (workdir / "results/tables/ranking_relmse.csv").exists()


def test_notebook_executes_headless_on_results(smoke_run, monkeypatch):
    """The whole notebook, run by a Jupyter kernel (nbclient) as a user would, on real results."""
    import nbformat
    from nbclient import NotebookClient

    workdir, _ = smoke_run
    monkeypatch.setenv("MCBENCH_RESULTS", str(workdir / "results"))
    notebook = nbformat.read(REPO / "workflow/notebooks/explore.ipynb", as_version=4)
    NotebookClient(notebook, timeout=300, kernel_name="python3",
                   resources={"metadata": {"path": str(REPO / "workflow/notebooks")}}).execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    assert sum(1 for o in outputs if "image/png" in o.get("data", {})) >= 5   # curves, scatter, images, weights
    text = "".join(o.get("text", "") for o in outputs)
    assert "# Ranking by relmse" in text and "no combiner with weight maps" not in text


def test_training_data_target_writes_reproducible_disjoint_crops(tmp_path):
    from mcbench.io.exr import read_layers, read_metadata

    # the smoke config's learned combiner (progressive) trains on a subset of these scenes
    training = {"first_seed": 3, "count": 2, "fibre_count": 0, "resolution": [32, 24], "crop": 12, "crops": 2,
                "spp": [4, 16], "target_spp": 64, "combiners": {"count": 2, "fibre_count": 0, "crops": 2}}
    workdir = tmp_path / "training"
    write_config(workdir, training=training)
    snakemake(workdir, "training_data")
    paths = sorted((workdir / "results/training").glob("example_*.exr"))
    assert [p.name for p in paths] == ["example_3_0.exr", "example_3_1.exr", "example_4_0.exr", "example_4_1.exr"]
    boxes = []
    for path in paths[:2]:
        layers = read_layers(path)
        assert {"color_spp4", "color_a_spp16", "target", "target_variance"} <= set(layers)
        assert layers["target"].shape == (12, 12, 3)
        assert all(np.isfinite(v).all() for v in layers.values())
        boxes.append([int(v) for v in read_metadata(path)["crop_box"].split(",")])
    (x0, y0, x1, y1), (u0, v0, u1, v1) = boxes
    assert x1 <= u0 or u1 <= x0 or y1 <= v0 or v1 <= y0, "crops of one image overlap"
    first = read_layers(paths[0])["color_spp4"]
    (workdir / "results/training" / paths[0].name).unlink()
    snakemake(workdir, "training_data")
    np.testing.assert_array_equal(read_layers(paths[0])["color_spp4"], first)


def test_paper_config_dry_runs_with_all_30_scenes(tmp_path):
    workdir = tmp_path / "paper"
    workdir.mkdir()
    (workdir / "config.yaml").write_text((REPO / "workflow/configs/paper.yaml").read_text())
    result = snakemake(workdir, "-n")
    text = result.stdout + result.stderr
    scenes = yaml.safe_load((REPO / "workflow/configs/paper.yaml").read_text())["scenes"]
    assert len(scenes) == 30
    for scene in scenes:
        assert f"results/references/{scene}.exr" in text
    counts = {line.split()[0]: int(line.split()[1]) for line in text.splitlines()
              if len(line.split()) == 2 and line.split()[1].isdigit()}
    assert counts["render_noisy"] == 30 * 9
    assert counts["merge_reference"] == 30


def test_train_rule_trains_missing_weights_and_the_main_job_never_retrains(tmp_path):
    import json

    import torch

    weights = tmp_path / "weights"
    training = {"first_seed": 6, "count": 2, "fibre_count": 0, "resolution": [32, 24], "crop": 12, "crops": 2,
                "spp": [4, 16],
                "target_spp": 64,
                "combiners": {"count": 2, "fibre_count": 0, "crops": 2},   # the smoke config's progressive
                "networks": {"wskpn": {"steps": 3, "batch_size": 2, "patch": 12, "validate_every": 3,
                                       "checkpoint_every": 3}}}
    workdir = tmp_path / "train"
    write_config(workdir, training=training, weights_dir=str(weights), denoisers=["oidn", "jbf", "wskpn"],
                 study={"pool": False})      # no pool: its learned bases have no weights in this folder
    weights.mkdir(exist_ok=True)                   # the smoke config's progressive: the committed weights
    for suffix in (".pt", ".json"):
        shutil.copy(REPO / "methods/weights" / f"progressive{suffix}", weights / f"progressive{suffix}")
    snakemake(workdir, "train_wskpn")
    blob = torch.load(weights / "wskpn.pt", weights_only=True)
    assert set(blob) == {"arch", "state_dict"}
    record = json.loads((weights / "wskpn.json").read_text())
    assert record["settings"]["steps"] == 3 and record["data"]["training_scenes"] == [6]
    assert record["data"]["validation_scenes"] == [7]
    assert (workdir / "results/logs/training/train_wskpn.log").exists()
    # Newer training data does not make the main job retrain: it uses the weights as they are.
    for crop in (workdir / "results/training").glob("*.exr"):
        os.utime(crop, (time.time() + 60, time.time() + 60))
    text = "".join(snakemake(workdir, "-n").stdout.splitlines(keepends=True))
    assert "train_network" not in text and "run_case_methods" in text
    snakemake(workdir, "results/outputs/cornell_box/spp4/wskpn.exr")
    timing = json.loads((workdir / "results/outputs/cornell_box/spp4/wskpn.json").read_text())
    assert timing["method"] == "wskpn" and timing["seconds"] > 0
    # Nor does a checkout without training data (a clean clone): no crops, no training planned;
    # and an explicit train_<name> with the weights present has nothing to do.
    shutil.rmtree(workdir / "results/training")
    text = snakemake(workdir, "-n").stdout
    assert "training_example" not in text and "train_network" not in text and "run_case_methods" in text
    assert "train_network" not in snakemake(workdir, "-n", "train_wskpn").stdout
    # New weights rerun the method (their digest is a parameter), still without training.
    torch.save(blob | {"state_dict": {k: v + 0.01 if v.is_floating_point() else v
                                      for k, v in blob["state_dict"].items()}}, weights / "wskpn.pt")
    text = snakemake(workdir, "-n", "results/outputs/cornell_box/spp4/wskpn.exr").stdout
    assert "run_case_methods" in text and "train_network" not in text
    # Without weights the main job stops, naming the folder (it never plans training itself);
    # train_<name> plans the training again.
    (weights / "wskpn.pt").unlink()
    result = snakemake(workdir, "-n", "results/outputs/cornell_box/spp64/wskpn.exr", check=False)
    assert result.returncode != 0 and f"no weights for wskpn in {weights}" in result.stdout + result.stderr
    assert "train_network" in snakemake(workdir, "-n", "train_wskpn").stdout


# --- the DAG is parsed the same way from anywhere, and mistakes stop before any job ----------

def _dry_run(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-n", "--nolock", *args]
    return subprocess.run(command, capture_output=True, text=True, cwd=cwd, timeout=300)


def _planned(result: subprocess.CompletedProcess) -> tuple[list[str], str]:
    """The planned (rule, output) lines and the config digest line of a dry run."""
    text = result.stdout + result.stderr
    assert result.returncode == 0, text[-3000:]
    lines = text.splitlines()
    jobs = sorted(line.strip() for line in lines if line.strip().startswith("output:"))
    digest = [line for line in lines if "mcbench: configuration" in line]
    assert len(digest) == 1, text[-2000:]
    return jobs, digest[0].split("digest ")[1]


def test_the_same_command_plans_the_same_study_from_any_folder(tmp_path):
    """From the repository root the smoke config once inherited config.yaml's per-scene reference
    spp (65536 instead of 1024), from another folder it did not: the same jobs and the same
    resolved configuration (digest) from both, including a folder with a space in its name.
    ``--forceall``: every job is planned whatever the checkout's results/ already holds (after
    the README's main job, the root's results/ is complete and the other folder's is empty)."""
    other = tmp_path / "a folder with spaces"
    other.mkdir()
    from_root = _planned(_dry_run(REPO, "--configfile", str(SMOKE), "--forceall"))
    from_other = _planned(_dry_run(other, "--configfile", str(SMOKE), "--forceall"))
    assert from_root == from_other and len(from_root[0]) > 40
    from mcbench.pipeline.config import config_digest, resolve_config

    assert from_root[1] == config_digest(resolve_config(yaml.safe_load(SMOKE.read_text())))
    # without --configfile the default study (config.yaml) is read from the checkout, not the folder
    default_root = _planned(_dry_run(REPO, "--forceall"))
    default_other = _planned(_dry_run(other, "--forceall"))
    assert default_root == default_other
    assert default_root[1] == config_digest(resolve_config(yaml.safe_load((REPO / "config.yaml").read_text())))


def _job_counts(result: subprocess.CompletedProcess) -> dict[str, int]:
    """The dry run's job-stats table as {rule: count}."""
    text = result.stdout + result.stderr
    assert result.returncode == 0, text[-3000:]
    table = text.split("Job stats:")[1].split("total")[0]
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^(\w+)\s+(\d+)$", table, re.MULTILINE)}


@pytest.mark.parametrize("batch", [True, False])
def test_methods_of_a_case_share_jobs_unless_batching_is_off(tmp_path, batch):
    """batch_methods: one job per case runs all its methods; off: one job per method. The outputs
    planned are the same."""
    config = write_config(tmp_path, batch_methods=batch, study={"pool": False})   # the config's methods only
    result = _dry_run(tmp_path, "--configfile", str(tmp_path / "config.yaml"))
    counts, cases = _job_counts(result), len(config["scenes"]) * len(config["spp"])
    if batch:
        assert counts["run_case_methods"] == cases and "run_method" not in counts
    else:
        assert counts["run_method"] == cases * (len(config["denoisers"]) + len(config["combiners"]))
        assert "run_case_methods" not in counts
    outputs = {line.strip() for line in (result.stdout + result.stderr).splitlines() if line.strip().startswith("output:")}
    planned = {p for line in outputs for p in line.removeprefix("output:").replace(",", " ").split()}
    for name in config["denoisers"] + [c["name"] for c in config["combiners"]]:
        assert f"results/outputs/cornell_box/spp4/{name}.exr" in planned


def test_a_config_naming_only_scenes_runs(tmp_path):
    workdir = tmp_path / "narrow"
    workdir.mkdir()
    (workdir / "config.yaml").write_text("scenes: [cornell_box]\nresolution: [16, 16]\n")
    text = snakemake(workdir, "-n").stdout
    assert "results/references/cornell_box.exr" in text and "fog_beams" not in text
    snakemake(workdir, "results/outputs/cornell_box/spp4/oidn.exr")
    assert (workdir / "results/outputs/cornell_box/spp4/oidn.exr").exists()


@pytest.mark.parametrize("change, message", [
    ({"combiners": [{"name": "ensemble", "method": "ensemble", "inputs": ["oidn", "jbf"], "params": {"solvr": "exact"}}]},
     "combiners[0].params.solvr"),
    ({"combiners": [{"name": "ensemble", "method": "ensemble", "inputs": ["oidn", "jbf"], "params": {"solver": "exactt"}}]},
     "combiners[0].params.solver: 'exactt' is not allowed"),
    ({"denoisers": ["oidn", "noisy"]}, "denoisers[1].name: 'noisy' is reserved"),
    ({"spp": [4.0]}, "spp[0]: 4.0 is not of type 'integer'"),
    ({"resolution": [8, 8]}, "resolution"),
])
def test_config_mistakes_stop_at_parse_naming_the_key(tmp_path, change, message):
    workdir = tmp_path / "mistake"
    write_config(workdir, **change)
    result = snakemake(workdir, "-n", check=False)
    assert result.returncode != 0 and message in result.stdout + result.stderr
    assert not (workdir / "results").exists()


def test_a_mistyped_weights_dir_stops_instead_of_planning_training(tmp_path):
    workdir = tmp_path / "weights"
    write_config(workdir, weights_dir=str(tmp_path / "wieghts"))
    result = snakemake(workdir, "-n", check=False)
    text = result.stdout + result.stderr
    assert result.returncode != 0 and f"no weights for kpcn in {tmp_path / 'wieghts'}" in text
    assert "training_example" not in text


def test_the_workflow_profile_is_loaded_from_any_folder(tmp_path):
    text = _dry_run(tmp_path, "--configfile", str(SMOKE)).stderr
    assert f"Using workflow specific profile {REPO / 'profiles/default'}" in text


def test_parsing_the_dag_imports_no_torch_and_no_unnamed_method(tmp_path):
    """A dry run imports only the method modules the config names, and never torch."""
    probe = tmp_path / "probe.py"
    probe.write_text(
        "import sys, runpy\n"
        "sys.argv = ['snakemake', '-s', sys.argv[1], '-n', '--nolock', '--configfile', sys.argv[2]]\n"
        "try:\n"
        "    runpy.run_module('snakemake', run_name='__main__')\n"
        "except SystemExit:\n"
        "    pass\n"
        "print('MODULES', sorted(m for m in sys.modules if m == 'torch' or m.startswith('methods.')))\n")
    (tmp_path / "config.yaml").write_text(yaml.safe_dump({"scenes": ["cornell_box"], "denoisers": ["oidn", "kpcn"],
                                                          "combiners": [], "study": {"pool": False}}))
    result = subprocess.run([sys.executable, str(probe), str(REPO / "Snakefile"), str(tmp_path / "config.yaml")],
                            capture_output=True, text=True, cwd=tmp_path, timeout=300)
    line = [l for l in result.stdout.splitlines() if l.startswith("MODULES")]
    assert line, result.stdout[-2000:] + result.stderr[-2000:]
    # oidn, kpcn: the config's; jbf, rdfc: the oracle study's default bases (schema oracle.denoisers)
    assert line[0] == "MODULES ['methods.jbf', 'methods.kpcn', 'methods.oidn', 'methods.rdfc']"
