"""Random kills, two runs at once, a full disk and a read-only results folder.

* **Random kills** (fuzz tier): a run of a config smaller than the smoke one is killed (SIGKILL to
  Snakemake's whole process group, as a power loss or an out-of-memory kill would) at
  :data:`KILL_POINTS` moments: each while a job of a chosen stage is running (a random delay after
  Snakemake starts it: mid-render, mid-method, mid-metrics, mid-table, mid-report), else at a random
  moment; after each kill the README's commands resume it (``--unlock``, then the same command).
  The finished run's ``metrics.csv`` and every table are byte-identical to an uninterrupted
  run's, timing columns excepted.
* **A second Snakemake in the same folder** is refused while the first runs, and the first finishes
  with the same tables.
* **A full disk** (a small tmpfs mounted as ``results/``) and **a read-only results folder** (a
  read-only bind mount: the tests run as root, so file modes would not stop a write): the run stops
  with an error naming the file it could not write and why, and leaves no output a later run
  accepts: given room (or write access) again, the same command finishes with the uninterrupted
  run's tables. Where the machine does not allow the mount, the test skips and says why.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from mcbench.analysis import run_comparison
from tests.conftest import REPO

pytestmark = pytest.mark.fuzz     # whole tiny runs, several each: the fuzz tier (python -m pytest -q -m fuzz)

#: Smaller than the smoke config: two 16² scenes, two spp levels, two bases and two combiners.
TINY = {
    "variant": "auto", "seed": 0, "render_threads": 1, "resolution": [16, 16],
    "scenes": ["cornell_box", "envmap_objects"], "spp": [4, 16],
    "reference": {"spp": 256, "chunks": 2},
    "denoisers": ["oidn", "jbf"],
    "combiners": [{"name": "ensemble", "method": "ensemble", "inputs": ["oidn", "jbf"]},
                  {"name": "naive", "method": "naive_average", "inputs": ["oidn", "jbf"]}],
    "study": {"pool": False, "bootstrap": 100},
    "metrics": ["relmse", "smape", "dssim"],
    "oracle": {"repetitions": 2, "spp": 4, "denoisers": ["oidn", "jbf"]},
}
KILL_POINTS = 10
#: The stages to be killed in, by their rules, in the workflow's order: each kill point takes the
#: next (two per stage); one whose jobs do not start within :data:`STAGE_WAIT` s (done already) is
#: killed at a random moment instead.
STAGES = [("render", ("render_reference_chunk", "render_noisy")),
          ("method", ("run_case",)),                     # a case's methods, evaluations and tables
          ("metrics", ("gather_metrics", "gather_timings")),
          ("report", ("viewer", "gallery", "study_figures", "error_curves")),
          ("table", ("ranking_table", "extras_table", "study_tables", "scene_table"))]
STAGE_WAIT = 25.0


def _command(workdir: Path, *args: str) -> list[str]:
    return [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "--directory", str(workdir),
            "--configfile", str(workdir / "config.yaml"), "--cores", "2", *args]


def _setup(workdir: Path) -> Path:
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "config.yaml").write_text(yaml.safe_dump(TINY))
    return workdir


def _run(workdir: Path, *args: str, check: bool = True, timeout: int = 1200) -> subprocess.CompletedProcess:
    result = subprocess.run(_command(workdir, *args), capture_output=True, text=True, timeout=timeout)
    if check and result.returncode != 0:
        raise AssertionError(f"snakemake {' '.join(args)} failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}")
    return result


def table_contents(workdir: Path) -> dict[str, str]:
    """``metrics.csv`` and every table of the run in ``workdir``, timing left out."""
    return run_comparison.table_contents(workdir / "results")


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> tuple[dict[str, str], float]:
    """The tiny config's tables from a run nobody interrupted, and its wall time (s)."""
    workdir = _setup(tmp_path_factory.mktemp("uninterrupted"))
    start = time.perf_counter()
    _run(workdir)
    return table_contents(workdir), time.perf_counter() - start


class _Watched:
    """A Snakemake run in its own process group whose output is read line by line."""

    def __init__(self, workdir: Path, *args: str):
        self.process = subprocess.Popen(_command(workdir, *args), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                         text=True, start_new_session=True)
        self.lines: list[str] = []
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self):
        for line in self.process.stdout:
            self.lines.append(line.rstrip("\n"))

    def started(self, rules) -> bool:
        return any(re.match(rf"^(local)?rule ({'|'.join(rules)}):", line) for line in self.lines)

    def kill(self):
        os.killpg(self.process.pid, signal.SIGKILL)
        self.process.wait()
        self.thread.join(timeout=10)


def kill_once(workdir: Path, stage: str, rules, rng, budget: float) -> str:
    """Start (or resume) the run, kill it mid-``stage`` or at a random moment; returns what was hit."""
    run = _Watched(workdir)
    deadline = time.perf_counter() + budget
    while time.perf_counter() < deadline and run.process.poll() is None and not run.started(rules):
        time.sleep(0.05)
    if run.process.poll() is not None:
        run.thread.join(timeout=10)
        assert run.process.returncode == 0, "a resumed run failed:\n" + "\n".join(run.lines[-30:])
        return "finished before the kill"
    hit = stage if run.started(rules) else "a random moment"
    time.sleep(float(rng.uniform(0.0, 1.5)))
    if run.process.poll() is not None:
        run.thread.join(timeout=10)
        return "finished before the kill"
    run.kill()
    running = [m.group(2) for line in run.lines if (m := re.match(r"^(local)?rule (\w+):", line))]
    return f"{hit} (last job started: {running[-1] if running else 'none'})"


def test_random_kills_resume_to_byte_identical_tables(uninterrupted, tmp_path):
    expected, wall = uninterrupted
    workdir = _setup(tmp_path / "killed")
    rng = np.random.default_rng(29)
    hits = []
    for point in range(KILL_POINTS):
        stage, rules = STAGES[min(point // 2, len(STAGES) - 1)]
        hits.append(kill_once(workdir, stage, rules, rng, budget=STAGE_WAIT))
        _run(workdir, "--unlock")          # the README's first step after a hard kill
    _run(workdir)                          # ... and the same command again
    killed = [h for h in hits if h != "finished before the kill"]
    print(f"kill points: {len(killed)} of {KILL_POINTS}: " + "; ".join(hits))
    assert len(killed) >= KILL_POINTS - 2, hits
    assert {h.split(" (")[0] for h in killed} >= {"render", "method", "metrics"}, hits
    got = table_contents(workdir)
    assert sorted(got) == sorted(expected)
    for name in expected:
        assert got[name] == expected[name], f"{name} differs after {len(killed)} kills: {hits}"


def test_a_second_snakemake_in_the_same_folder_is_refused(uninterrupted, tmp_path):
    expected, _ = uninterrupted
    workdir = _setup(tmp_path / "twice")
    first = _Watched(workdir)
    deadline = time.perf_counter() + 120
    while time.perf_counter() < deadline and not first.started(("render_reference_chunk", "render_noisy")):
        time.sleep(0.05)
    assert first.process.poll() is None, "the first run ended before the second could start"
    second = _run(workdir, check=False)
    output = second.stdout + second.stderr
    assert second.returncode != 0 and "cannot be locked" in output, output[-2000:]
    assert first.process.wait(timeout=1200) == 0, "\n".join(first.lines[-40:])
    first.thread.join(timeout=10)
    assert table_contents(workdir) == expected


def _mount(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["mount", *args], capture_output=True, text=True)


def _skip_unless_mountable(tmp_path: Path):
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("needs root and mount(8) to mount a tmpfs / a read-only bind mount")
    probe = tmp_path / "probe"
    probe.mkdir()
    result = _mount("-t", "tmpfs", "-o", "size=1m", "tmpfs", str(probe))
    if result.returncode != 0:
        pytest.skip(f"this machine does not allow mounts here: {result.stderr.strip()}")
    subprocess.run(["umount", str(probe)], check=True)


def _error_names_a_file(output: str, reason: str) -> bool:
    """Whether the run's output names, on one line, a file under ``results/`` and ``reason`` (ours:
    ``<path>: cannot write (<reason>)``; Snakemake's own, for a folder or log it could not make)."""
    return any(reason in line and "results/" in line for line in output.splitlines())


def test_a_full_disk_stops_the_run_naming_the_file_and_a_later_run_finishes(uninterrupted, tmp_path):
    _skip_unless_mountable(tmp_path)
    expected, _ = uninterrupted
    workdir = _setup(tmp_path / "full")
    results = workdir / "results"
    results.mkdir()
    assert _mount("-t", "tmpfs", "-o", "size=600k", "tmpfs", str(results)).returncode == 0
    try:
        failed = _run(workdir, check=False)
        output = failed.stdout + failed.stderr
        assert failed.returncode != 0
        assert _error_names_a_file(output, "No space left on device"), output[-3000:]
        saved = tmp_path / "saved"
        shutil.copytree(results, saved, symlinks=True)
    finally:
        subprocess.run(["umount", str(results)], check=True)
    shutil.rmtree(results)
    shutil.copytree(saved, results, symlinks=True)          # what the full disk held, on a roomy disk
    _run(workdir, "--unlock")
    _run(workdir)
    assert table_contents(workdir) == expected


def test_a_read_only_results_folder_stops_the_run_naming_the_file(uninterrupted, tmp_path):
    _skip_unless_mountable(tmp_path)
    expected, _ = uninterrupted
    workdir = _setup(tmp_path / "readonly")
    _run(workdir, "results/renders/cornell_box/spp4.exr")   # something already computed
    results = workdir / "results"
    assert _mount("--bind", str(results), str(results)).returncode == 0
    try:
        remount = _mount("-o", "remount,ro,bind", str(results))
        if remount.returncode != 0:
            pytest.skip(f"this machine does not allow a read-only bind mount: {remount.stderr.strip()}")
        before = {p: p.read_bytes() for p in results.rglob("*") if p.is_file()}
        failed = _run(workdir, check=False)
        output = failed.stdout + failed.stderr
        assert failed.returncode != 0
        assert _error_names_a_file(output, "Read-only file system"), output[-3000:]
        assert {p: p.read_bytes() for p in results.rglob("*") if p.is_file()} == before, "a read-only folder changed"
    finally:
        subprocess.run(["umount", str(results)], check=True)
    _run(workdir, "--unlock")
    _run(workdir)
    assert table_contents(workdir) == expected
