"""One job per case (mcbench.pipeline.cases): what it keeps and what it makes, its keys, the
case tables it writes; and the warm workers' logs and file cache."""

from __future__ import annotations

import json
import os
import shutil

import numpy as np
import OpenEXR
import pandas as pd
import pytest

from mcbench import NOISY, BenchError
from mcbench.io.exr import COMPRESSIONS, read_layers, write_layers
from mcbench.io.file_cache import cached_read, clear_cache
from mcbench.pipeline.cases import method_key, run_case, viewer_key
from mcbench.pipeline.logs import run_logged

SCENE, SPP = "box", 8
#: name, module, params, inputs: two bases, a combiner of them, a combiner of that combiner
METHODS = [("jbf", "jbf", {}, []), ("oidn", "oidn", {}, []), ("ens", "ensemble", {"solver": "exact"}, ["jbf", "oidn"]),
           ("avg", "naive_average", {}, ["ens", "oidn"])]


def test_a_methods_key_changes_with_its_own_settings_and_its_inputs_keys_only():
    """Keys of a chain base -> combiner: editing one base's params changes its key and those of
    the combiners that read it (through their inputs' keys); the other base keeps its key; a new
    render or new weights change every key that reads them."""
    def keys(params_jbf=None, render="crc32:1", weights=""):
        jbf = method_key(module="jbf", params=params_jbf or {}, input_keys=[], weights_sha256="", render=render)
        oidn = method_key(module="oidn", params={}, input_keys=[], weights_sha256=weights, render=render)
        ens = method_key(module="ensemble", params={}, input_keys=[jbf, oidn], weights_sha256="", render=render)
        return {"jbf": jbf, "oidn": oidn, "ens": ens}

    base = keys()
    edited = keys(params_jbf={"radius": 9})
    assert [name for name in base if base[name] != edited[name]] == ["jbf", "ens"]
    assert all(base[name] != value for name, value in keys(render="crc32:2").items())
    assert [name for name, value in keys(weights="abc").items() if base[name] != value] == ["oidn", "ens"]
    swapped = method_key(module="ensemble", params={}, input_keys=[base["oidn"], base["jbf"]], weights_sha256="",
                         render="crc32:1")
    assert swapped != base["ens"]                                # the inputs' order is part of it
    assert viewer_key(image="a", reference="r", weight_inputs=[], maps=[]) != viewer_key(
        image="a", reference="r", weight_inputs=["jbf"], maps=[])
    assert viewer_key(image="a", reference="r", weight_inputs=[], maps=["relmse:1"]) != viewer_key(
        image="a", reference="r", weight_inputs=[], maps=["relmse:1", "flip:2"])


@pytest.fixture
def case_dir(tmp_path, make_render_buffers):
    """A render and its reference (16 x 16) in a case folder."""
    buffers = make_render_buffers(spp=SPP, half_std=0.05, seed=7)
    truth = make_render_buffers(spp=SPP, half_std=0.0).color
    write_layers(tmp_path / "render.exr", buffers.layers, metadata={"spp": SPP, "scene": SCENE})
    write_layers(tmp_path / "reference.exr", {"color": truth}, metadata={"spp": 4096, "scene": SCENE})
    return tmp_path


def make_case(folder, *, methods=METHODS, metrics=("relmse", "smape"), keep="all") -> dict:
    """The job description common.smk builds for one case, in ``folder`` (``keep``: its keep_outputs)."""
    out = folder / "results"
    names = [name for name, *_ in methods]
    return {"scene": SCENE, "spp": SPP, "render": str(folder / "render.exr"), "reference": str(folder / "reference.exr"),
            "metrics": list(metrics),
            "methods": [{"name": name, "module": module, "params": params, "inputs": inputs, "weights": None,
                         "exr": str(out / f"outputs/{name}.exr"), "timing": str(out / f"outputs/{name}.json")}
                        for name, module, params, inputs in methods],
            "entries": [{"entry": entry, "image": str(folder / "render.exr") if entry == NOISY else str(out / f"outputs/{entry}.exr"),
                         "values": str(out / f"values/{entry}.json"), "viewer": str(out / f"viewer_entries/{entry}"),
                         "weight_inputs": next((inputs for name, _, _, inputs in methods if name == entry), [])}
                        for entry in [NOISY, *names]],
            "outputs": {"metrics": str(out / "case.csv"), "viewer": str(out / "viewer_case"),
                        "record": str(out / "case.json")}, "keep_outputs": keep}


def compression(path) -> str:
    """The name (a key of :data:`mcbench.io.exr.COMPRESSIONS`) of the compression of the EXR ``path``."""
    with OpenEXR.File(str(path)) as exr:
        code = exr.header()["compression"]
    return next(name for name, value in COMPRESSIONS.items() if value == code)


def mtimes(folder) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_mtime_ns for p in sorted(folder.rglob("*"))
            if p.is_file() and p.parent.name != "viewer_case" and not p.name.startswith((".case.", "case."))}


def test_a_case_job_makes_what_is_missing_or_stale_and_keeps_the_rest(case_dir):
    """From scratch the job makes every method and evaluation; run again it makes nothing and
    touches no kept file; an edited base remakes itself and the combiners reading it (and their
    evaluations), an added metric is the only one computed, and each case table equals a
    from-scratch job's."""
    first = run_case(make_case(case_dir))
    names = [name for name, *_ in METHODS]
    assert first["made"] == {"methods": names, "metrics": [NOISY, *names], "viewer": [NOISY, *names]}
    assert list(first["seconds"]) == ["methods", "evaluation", "assembly"]       # the job's phases, in order
    assert first["seconds"]["evaluation"]["cpu"] > 0 and all(
        lap["wall"] >= 0 and lap["cpu"] >= 0 for lap in first["seconds"].values())
    before = mtimes(case_dir / "results")
    again = run_case(make_case(case_dir))
    assert again["made"] == {"methods": [], "metrics": [], "viewer": []}
    assert mtimes(case_dir / "results") == before
    edited = [("jbf", "jbf", {"sigma_color": 0.8}, []), *METHODS[1:]]
    changed = run_case(make_case(case_dir, methods=edited))
    assert changed["made"] == {"methods": ["jbf", "ens", "avg"], "metrics": ["jbf", "ens", "avg"],
                               "viewer": ["jbf", "ens", "avg"]}
    table = pd.read_csv(case_dir / "results/case.csv")
    scratch_dir = case_dir / "scratch"
    scratch_dir.mkdir()
    for name in ("render.exr", "reference.exr"):
        shutil.copy(case_dir / name, scratch_dir / name)
    run_case(make_case(scratch_dir, methods=edited))
    pd.testing.assert_frame_equal(table, pd.read_csv(scratch_dir / "results/case.csv"))
    added = run_case(make_case(case_dir, methods=edited, metrics=("relmse", "smape", "dssim")))
    assert added["made"] == {"methods": [], "metrics": [NOISY, *names], "viewer": []}
    values = json.loads((case_dir / "results/values/jbf.json").read_text())["values"]
    assert set(values) == {"relmse", "smape", "dssim"}
    rows = pd.read_csv(case_dir / "results/case.csv")
    assert list(rows.entry.unique()) == [NOISY, *names] and list(rows.metric[:3]) == ["relmse", "smape", "dssim"]
    assert rows[rows.metric != "dssim"].reset_index(drop=True).equals(table)


def test_outputs_no_method_reads_are_evaluated_then_removed_and_made_again_only_when_needed(case_dir):
    """keep_outputs read: the output of 'avg' (no method reads it) is evaluated and removed, its
    timing record kept; the bases and 'ens' (read by 'avg') stay. Run again, nothing is made; an
    added metric makes 'avg' again for its evaluation (and removes it again), computing only that
    metric; every case table equals the one of a job that keeps every output; a new method added
    runs alone, reading the kept outputs."""
    names = [name for name, *_ in METHODS]
    out = case_dir / "results/outputs"
    first = run_case(make_case(case_dir, keep="read"))
    assert first["made"]["methods"] == names
    assert sorted(p.stem for p in out.glob("*.exr")) == ["ens", "jbf", "oidn"]
    assert sorted(p.stem for p in out.glob("*.json")) == sorted(names)
    assert {name: m["kept"] for name, m in first["methods"].items()} == {"jbf": True, "oidn": True, "ens": True,
                                                                          "avg": False}
    assert {p.stem: compression(p) for p in out.glob("*.exr")} == dict.fromkeys(["ens", "jbf", "oidn"], "zstd")
    before = mtimes(case_dir / "results")
    assert run_case(make_case(case_dir, keep="read"))["made"] == {"methods": [], "metrics": [], "viewer": []}
    assert mtimes(case_dir / "results") == before
    timing = json.loads((out / "avg.json").read_text())
    added = run_case(make_case(case_dir, keep="read", metrics=("relmse", "smape", "dssim")))
    assert added["made"] == {"methods": ["avg"], "metrics": [NOISY, *names], "viewer": []}
    assert json.loads((out / "avg.json").read_text()) == timing       # remade for its evaluation only
    assert not (out / "avg.exr").exists()
    values = json.loads((case_dir / "results/values/avg.json").read_text())
    assert values["image"].startswith("key:") and set(values["values"]) == {"relmse", "smape", "dssim"}
    every = case_dir / "every"
    every.mkdir()
    for name in ("render.exr", "reference.exr"):
        shutil.copy(case_dir / name, every / name)
    run_case(make_case(every, keep="all", metrics=("relmse", "smape", "dssim")))
    assert compression(every / "results/outputs/avg.exr") == "zstd"      # kept, though no method reads it
    pd.testing.assert_frame_equal(pd.read_csv(case_dir / "results/case.csv"), pd.read_csv(every / "results/case.csv"))
    grown = [*METHODS, ("avg2", "naive_average", {}, ["jbf", "oidn"])]
    assert run_case(make_case(case_dir, methods=grown, keep="read",
                              metrics=("relmse", "smape", "dssim")))["made"]["methods"] == ["avg2"]


def test_ensure_case_outputs_makes_removed_outputs_for_their_readers(case_dir):
    """An export of a case reads every candidate's output: the ones a case removed are made again
    (with their keys, so the case job keeps its evaluations) and kept; pixels equal a kept run's."""
    from mcbench.pipeline.cases import ensure_case_outputs

    run_case(make_case(case_dir, keep="read"))
    timing = json.loads((case_dir / "results/outputs/avg.json").read_text())
    assert ensure_case_outputs(make_case(case_dir, keep="read"), ["avg", "jbf"]) == ["avg"]
    assert json.loads((case_dir / "results/outputs/avg.json").read_text()) == timing   # its first timing kept
    assert ensure_case_outputs(make_case(case_dir, keep="read"), ["avg"]) == []
    every = case_dir / "every"
    every.mkdir()
    for name in ("render.exr", "reference.exr"):
        shutil.copy(case_dir / name, every / name)
    run_case(make_case(every, keep="all"))
    np.testing.assert_array_equal(read_layers(case_dir / "results/outputs/avg.exr")["color"],
                                  read_layers(every / "results/outputs/avg.exr")["color"])
    with pytest.raises(BenchError, match="no method"):
        ensure_case_outputs(make_case(case_dir), ["nope"])



def test_an_output_that_a_method_stops_or_starts_reading_keeps_its_evaluation(case_dir):
    """keep_outputs read: when 'avg' is removed, 'ens' is no longer read (its output goes, its
    evaluation stays); when a method reading 'ens' comes back, 'ens' is made again with its first
    timing record, and its evaluation still stays. Only the added method is evaluated."""
    out = case_dir / "results/outputs"
    run_case(make_case(case_dir, keep="read"))
    timing = json.loads((out / "ens.json").read_text())
    shrunk = run_case(make_case(case_dir, methods=METHODS[:3], keep="read"))
    assert shrunk["made"] == {"methods": [], "metrics": [], "viewer": []}
    assert not (out / "ens.exr").exists() and shrunk["methods"]["ens"]["kept"] is False
    regrown = run_case(make_case(case_dir, methods=[*METHODS[:3], ("avg3", "naive_average", {}, ["ens", "jbf"])],
                                 keep="read"))
    assert regrown["made"] == {"methods": ["ens", "avg3"], "metrics": ["avg3"], "viewer": ["avg3"]}
    assert (out / "ens.exr").exists() and json.loads((out / "ens.json").read_text()) == timing

def test_a_half_written_or_foreign_output_is_made_again(case_dir):
    """A method whose timing record is missing (killed between its two files), or whose files
    record another key (written by other settings), is made again; nothing else."""
    run_case(make_case(case_dir))
    out = case_dir / "results/outputs"
    (out / "oidn.json").unlink()
    record = json.loads((out / "jbf.json").read_text())
    (out / "jbf.json").write_text(json.dumps({**record, "key": "0" * 64}))
    (out / "jbf.json.crc32").unlink(missing_ok=True)
    remade = run_case(make_case(case_dir))
    # the bases are made again with the keys they had, so the combiners (keyed by their inputs'
    # keys) and every entry's evaluation (identified by the method keys) are kept
    assert remade["made"] == {"methods": ["jbf", "oidn"], "metrics": [], "viewer": []}


def test_a_case_whose_methods_are_out_of_dependency_order_is_refused(case_dir):
    case = make_case(case_dir, methods=[METHODS[2], *METHODS[:2]])
    with pytest.raises(BenchError, match="method 'ens'.*reads"):
        run_case(case)


def test_a_changed_render_remakes_everything(case_dir, make_render_buffers):
    run_case(make_case(case_dir))
    before = read_layers(case_dir / "results/outputs/jbf.exr")["color"]
    other = make_render_buffers(spp=SPP, half_std=0.05, seed=8)
    write_layers(case_dir / "render.exr", other.layers, metadata={"spp": SPP, "scene": SCENE})
    clear_cache()
    remade = run_case(make_case(case_dir))
    names = [name for name, *_ in METHODS]
    assert remade["made"] == {"methods": names, "metrics": [NOISY, *names], "viewer": [NOISY, *names]}
    assert not np.array_equal(read_layers(case_dir / "results/outputs/jbf.exr")["color"], before)


def test_a_log_on_a_full_disk_fails_the_step_naming_the_log_and_the_reason(capfd):
    """/dev/full takes the open and refuses every write (ENOSPC): the step fails, and the terminal
    line names the log and why, not a bare errno without a file."""
    def chatty_step():
        os.write(1, b"x" * 100_000)                  # as a C++ library writes: to fd 1

    with pytest.raises(SystemExit):
        run_logged("/dev/full", chatty_step)
    err = capfd.readouterr().err
    assert "/dev/full: cannot write the log (No space left on device)" in err


def test_a_failing_step_with_a_writable_log_puts_the_traceback_there(tmp_path, capfd):
    log = tmp_path / "step.log"

    def failing_step():
        raise ValueError("results/renders/a/spp4.exr: not an EXR")

    with pytest.raises(SystemExit):
        run_logged(str(log), failing_step)
    err = capfd.readouterr().err
    assert "ERROR: results/renders/a/spp4.exr: not an EXR" in err and f"(full traceback in {log})" in err
    assert "Traceback" in log.read_text() and "not an EXR" in log.read_text()
    assert run_logged(str(log), lambda: 7) == 7


def test_the_file_cache_rereads_a_rewritten_file_and_hands_out_read_only_arrays(tmp_path):
    clear_cache()
    path = tmp_path / "values.npy"
    np.save(path, np.arange(4.0))
    reads = []

    def reader(p):
        reads.append(p)
        return {"values": np.load(p)}

    first = cached_read(str(path), reader)
    assert cached_read(str(path), reader) is first and len(reads) == 1
    with pytest.raises(ValueError):
        first["values"][0] = 5.0                                 # an in-place write fails loudly
    stat = path.stat()
    with open(path, "r+b") as handle:                            # changed in place, mtime set back
        handle.seek(-8, 2)
        handle.write(np.float64(9.0).tobytes())
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    again = cached_read(str(path), reader)
    assert len(reads) == 2 and again["values"][-1] == 9.0         # ctime changed: read again
    with pytest.raises(FileNotFoundError):
        cached_read(str(tmp_path / "missing.npy"), reader)       # the reader's own error
