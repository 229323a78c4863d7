"""Which stages of a study give bit-identical results when the CPU's vector ISA changes?

Runs one small study three times, each in a fresh folder with a fresh numba cache
(``XDG_CACHE_HOME`` and ``NUMBA_CACHE_DIR`` under the folder), and compares each with the first
stage by stage (:mod:`mcbench.analysis.run_comparison`), printing a Markdown report. An
emulation on one machine of an AVX2-only CPU beside an AVX-512 one, not a second machine:

* ``native``: nothing restricted;
* ``avx2``: every library's instruction-set dispatch held to AVX2 by its documented environment
  variable (:data:`AVX2_ENV`: NumPy, OpenBLAS, PyTorch/ATen, oneDNN, MKL, numba). The renders come
  from the same Dr.Jit code as natively, so every method sees the same inputs: this run shows
  what the libraries alone change;
* ``avx2_drjit``: the same and Dr.Jit's LLVM backend (Mitsuba's renders) compiled for Haswell at
  vector width 8, as on an AVX2 CPU. Dr.Jit has no environment variable for this; the shim
  ``tools/isa_shim/sitecustomize.py`` calls its core library's ``jit_llvm_set_target``.

    python tools/isa_reproducibility.py WORKDIR                       # the three runs, then the report
    python tools/isa_reproducibility.py WORKDIR --runs native avx2     # only these (others reused if there)
    python tools/isa_reproducibility.py WORKDIR --config my.yaml       # another (small!) config
    python tools/isa_reproducibility.py WORKDIR --compare-only         # report on finished runs

``WORKDIR/<run>`` holds ``config.yaml``, ``results/``, ``cache/`` and ``snakemake.log``.
Snakemake runs with ``--cores 1``; its jobs (scripts and the warm workers of
:mod:`mcbench.pipeline.worker_pool`, started by ``forkserver`` from the Snakemake process) inherit its
environment. ``ONEDNN_VERBOSE=1`` is set in every run (it prints, does not change results) so
that the logs show which ISA oneDNN used inside the jobs; the numba cache index of each run names
the CPU numba compiled for; the shim prints its target into the render jobs' logs. OIDN and
flip-evaluator have no switch for their ISA: their code targets this CPU in every run.
"""

from __future__ import annotations

import argparse
import os
import pickle
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mcbench.analysis.run_comparison import compare_images, compare_runs  # noqa: E402
from mcbench.io.exr import read_layers  # noqa: E402

#: The default study: workflow/configs/smoke.yaml without the comparisons, progressive denoising
#: and most combiners (its scenes, 32x32, spp [4, 64], the study slice with ensembles #10, #15).
SMALL_CONFIG = {
    "variant": "auto", "seed": 0, "render_threads": 1, "resolution": [32, 32],
    "scenes": ["cornell_box", "glass_caustics", "envmap_objects"], "spp": [4, 64],
    "reference": {"spp": 1024, "chunks": 2},
    "denoisers": ["oidn", "jbf", "kpcn"],
    "combiners": [{"name": "ensemble", "method": "ensemble", "inputs": ["oidn", "jbf"],
                   "params": {"solver": "iterative"}}],
    "study": {"ensembles": [10, 15], "bootstrap": 200},
    "metrics": ["relmse", "relmse_corrected", "smape", "dssim", "flip"],
}

#: Haswell's LLVM features (AVX2 + FMA, no AVX-512): numba takes the host's features unless told.
HASWELL_FEATURES = ("+64bit,+avx,+avx2,+bmi,+bmi2,+cmov,+crc32,+cx16,+cx8,+f16c,+fma,+fsgsbase,+fxsr,"
                    "+invpcid,+lzcnt,+mmx,+movbe,+pclmul,+popcnt,+rdrnd,+sahf,+sse,+sse2,+sse3,+sse4.1,"
                    "+sse4.2,+ssse3,+xsave,+xsaveopt")

#: Each library's documented switch to AVX2 (see docs/reproducibility.md for what each changes here).
AVX2_ENV = {
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR",   # NumPy >= 2.4 dispatch groups
    "OPENBLAS_CORETYPE": "Haswell",
    "ATEN_CPU_CAPABILITY": "avx2",
    "ONEDNN_MAX_CPU_ISA": "AVX2",
    "DNNL_MAX_CPU_ISA": "AVX2",
    "MKL_ENABLE_INSTRUCTIONS": "AVX2",
    "NUMBA_CPU_NAME": "haswell",
    "NUMBA_CPU_FEATURES": HASWELL_FEATURES,
}

#: Set in every run: oneDNN prints the ISA it uses to the job's output (results unchanged).
COMMON_ENV = {"ONEDNN_VERBOSE": "1"}

#: The shim folder put first on PYTHONPATH in the ``avx2_drjit`` run, and its target.
SHIM = REPO / "tools" / "isa_shim"
DRJIT_TARGET = "haswell:8"

#: The runs, in order; the first is the one the others are compared with.
RUNS = ("native", "avx2", "avx2_drjit")

#: What each run's environment reports, printed by a fresh interpreter (:func:`probe`).
PROBE = r"""
import ctypes, glob, os, numpy as np
from numpy._core._multiarray_umath import __cpu_features__ as f
print("numpy AVX-512 dispatch (X86_V4):", f.get("X86_V4"))
lib = glob.glob(os.path.join(os.path.dirname(os.path.dirname(np.__file__)), "numpy.libs", "libscipy_openblas*.so"))
core = "?"
if lib:
    ob = ctypes.CDLL(lib[0])
    for name in ("scipy_openblas_get_corename64_", "openblas_get_corename64_", "openblas_get_corename"):
        if hasattr(ob, name):
            fn = getattr(ob, name); fn.restype = ctypes.c_char_p; core = fn().decode(); break
print("OpenBLAS core (numpy's):", core)
import torch
print("torch CPU capability:", torch.backends.cpu.get_cpu_capability())
import numba
@numba.njit(fastmath=True)
def _s(a):
    t = 0.0
    for x in a:
        t += x * x
    return t
_s(np.ones(64))
print("numba CPU name:", numba.config.CPU_NAME or "host", "| 512-bit registers in its code:",
      "zmm" in _s.inspect_asm(_s.signatures[0]))
import drjit, mitsuba
mitsuba.set_variant("llvm_ad_rgb")
jit = ctypes.CDLL(os.path.join(os.path.dirname(drjit.__file__), "libdrjit-core.so"))
jit._Z19jit_llvm_target_cpuv.restype = ctypes.c_char_p
jit._Z21jit_llvm_vector_widthv.restype = ctypes.c_uint32
print("Dr.Jit LLVM target:", jit._Z19jit_llvm_target_cpuv().decode(), "width", jit._Z21jit_llvm_vector_widthv())
"""


def run_environment(base: dict[str, str], folder: Path, run: str) -> dict[str, str]:
    """The environment of ``run`` (one of :data:`RUNS`): ``base`` with a fresh cache under
    ``folder``, :data:`AVX2_ENV` unless native, and the Dr.Jit shim for ``avx2_drjit``."""
    if run not in RUNS:
        raise ValueError(f"run must be one of {RUNS}, got {run!r}")
    env = dict(base)
    env.update(COMMON_ENV)
    env["XDG_CACHE_HOME"] = str(folder / "cache")
    env["NUMBA_CACHE_DIR"] = str(folder / "cache" / "numba")
    if run != "native":
        env.update(AVX2_ENV)
    if run == "avx2_drjit":
        env["MCBENCH_ISA_DRJIT_TARGET"] = DRJIT_TARGET
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(SHIM), base.get("PYTHONPATH", "")) if p)
    return env


def run_study(folder: Path, config: dict, env: dict[str, str]) -> None:
    """Snakemake of this checkout in ``folder`` (made fresh; must not exist) with ``config``,
    ``--cores 1``; its output in ``folder/snakemake.log``. Raises SystemExit naming the log on failure."""
    folder.mkdir(parents=True)
    (folder / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "--directory", str(folder),
               "--configfile", str(folder / "config.yaml"), "--cores", "1"]
    with open(folder / "snakemake.log", "w") as log:
        done = subprocess.run(command, stdout=log, stderr=subprocess.STDOUT, env=env)
    if done.returncode != 0:
        raise SystemExit(f"snakemake failed in {folder}; see {folder / 'snakemake.log'}")


def probe(env: dict[str, str]) -> list[str]:
    """What NumPy, OpenBLAS, PyTorch and numba report under ``env`` (a fresh interpreter)."""
    done = subprocess.run([sys.executable, "-c", PROBE], env={**env, "ONEDNN_VERBOSE": "0"},
                          capture_output=True, text=True, check=True)
    return done.stdout.strip().splitlines()


def numba_cache_targets(cache: Path) -> dict[str, int]:
    """CPU name and whether AVX-512 was enabled, per compiled overload in a numba cache folder's
    index files (numba keys its cache by CPU name and features): ``{"znver5 avx512f=on": 12, ...}``."""
    counts: dict[str, int] = {}
    for index in Path(cache).rglob("*.nbi"):
        with open(index, "rb") as f:
            pickle.load(f)                                      # numba's version
            _stamp, overloads = pickle.loads(f.read())
        for key in overloads:
            _triple, cpu, features = key[1]
            label = f"{cpu} avx512f={'on' if '+avx512f' in features else 'off'}"
            counts[label] = counts.get(label, 0) + 1
    return counts


def log_reports(folder: Path, pattern: str) -> dict[str, int]:
    """How often each text ``pattern``'s group captures in a run's Snakemake output and job logs
    (e.g. the ISA oneDNN reports, the shim's Dr.Jit target)."""
    counts: dict[str, int] = {}
    files = [folder / "snakemake.log", *(folder / "results" / "logs").rglob("*.log")]
    for path in files:
        if path.is_file():
            for found in re.findall(pattern, path.read_text(errors="replace")):
                counts[found.strip()] = counts.get(found.strip(), 0) + 1
    return counts


ONEDNN_ISA = r"onednn_verbose,[^\n]*?info,cpu,isa:([^\n]+)"
SHIM_TARGET = r"isa shim: (Dr\.Jit LLVM target [^\n]+)"


@dataclass(frozen=True)
class StageResult:
    """One stage compared: files in it, files that differ, largest absolute and relative difference."""

    stage: str
    files: int
    differing: int
    max_abs: float
    max_rel: float


def image_stage(results_a: Path, results_b: Path, folder: str) -> tuple[StageResult, list]:
    """The EXR files of ``folder`` compared bit for bit; the stage summary and the differing files."""
    found = compare_images(results_a, results_b, folder)
    count = sum(1 for _ in (Path(results_a) / folder).rglob("*.exr"))
    return (StageResult(folder, count, len(found), max((d.max_abs or 0.0 for d in found), default=0.0),
                        max((d.max_rel or 0.0 for d in found), default=0.0)), found)


def per_method(found: list, results_a: Path, results_b: Path) -> pd.DataFrame:
    """Differing method outputs (``outputs/<scene>/spp<N>/<method>.exr``) grouped by method: files,
    largest absolute and relative difference over all layers (auxiliary ones such as an
    ensemble's weights included) and over the ``color`` layer alone (the image that is scored)."""
    rows = []
    for d in found:
        row = {"method": Path(d.table).stem, "max_abs": d.max_abs or 0.0, "max_rel": d.max_rel or 0.0,
               "color_max_abs": float("nan"), "color_max_rel": float("nan")}
        a, b = Path(results_a) / d.table, Path(results_b) / d.table
        if a.is_file() and b.is_file():
            x = read_layers(a, ["color"])["color"].astype(np.float64)
            y = read_layers(b, ["color"])["color"].astype(np.float64)
            scale = np.maximum(np.abs(x), np.abs(y))
            diff = np.abs(x - y)
            row["color_max_abs"] = float(diff.max())
            row["color_max_rel"] = float(np.divide(diff, scale, out=np.zeros_like(diff), where=scale > 0).max())
        rows.append(row)
    columns = ["method", "files", "max_abs", "max_rel", "color_max_abs", "color_max_rel"]
    if not rows:
        return pd.DataFrame(columns=columns)
    frame = pd.DataFrame(rows)
    return (frame.groupby("method").agg(files=("max_abs", "size"), max_abs=("max_abs", "max"),
                                        max_rel=("max_rel", "max"), color_max_abs=("color_max_abs", "max"),
                                        color_max_rel=("color_max_rel", "max")).reset_index()[columns])


def metrics_differences(results_a: Path, results_b: Path) -> pd.DataFrame:
    """``metrics.csv`` of two runs per (entry, metric): values compared, values not identical,
    largest relative difference ``|a - b| / max(|a|, |b|)``. Rows must align on (scene, spp,
    entry, metric); ValueError where they do not."""
    keys = ["scene", "spp", "entry", "metric"]
    a = pd.read_csv(Path(results_a) / "metrics.csv").set_index(keys)["value"]
    b = pd.read_csv(Path(results_b) / "metrics.csv").set_index(keys)["value"]
    if not a.index.sort_values().equals(b.index.sort_values()):
        raise ValueError("metrics.csv: the two runs do not hold the same (scene, spp, entry, metric) rows")
    b = b.reindex(a.index)
    x, y = a.to_numpy(np.float64), b.to_numpy(np.float64)
    scale = np.maximum(np.abs(x), np.abs(y))
    rel = np.divide(np.abs(x - y), scale, out=np.zeros_like(x), where=scale > 0)
    frame = pd.DataFrame({"entry": a.index.get_level_values("entry"),
                          "metric": a.index.get_level_values("metric"),
                          "differs": ~((x == y) | (np.isnan(x) & np.isnan(y))), "max_rel": rel})
    return (frame.groupby(["entry", "metric"]).agg(values=("differs", "size"), differing=("differs", "sum"),
                                                       max_rel=("max_rel", "max")).reset_index())


def ranking_moves(results_a: Path, results_b: Path) -> pd.DataFrame:
    """Every cell of ``tables/ranking_*.csv`` that changed, and every candidate whose place in the
    ``Avg.`` order (descending score) changed: metric, candidate, column, value a, value b."""
    rows = []
    for path in sorted((Path(results_a) / "tables").glob("ranking_*.csv")):
        metric = path.stem.removeprefix("ranking_")
        a = pd.read_csv(path).set_index("candidate")
        b = pd.read_csv(Path(results_b) / "tables" / path.name).set_index("candidate").reindex(a.index)
        for column in a.columns:
            for candidate in a.index:
                va, vb = a.at[candidate, column], b.at[candidate, column]
                if not (va == vb or (pd.isna(va) and pd.isna(vb))):
                    rows.append({"metric": metric, "candidate": candidate, "column": column, "a": va, "b": vb})
        if "Avg." in a.columns:
            place_a = a["Avg."].rank(ascending=False, method="min")
            place_b = b["Avg."].rank(ascending=False, method="min")
            for candidate in a.index[place_a != place_b]:
                rows.append({"metric": metric, "candidate": candidate, "column": "place (Avg.)",
                             "a": place_a[candidate], "b": place_b[candidate]})
    return pd.DataFrame(rows, columns=["metric", "candidate", "column", "a", "b"])


def interval_moves(results_a: Path, results_b: Path) -> pd.DataFrame:
    """Scores of ``tables/study/scores_ci_*.csv`` (avg, low, medium, high) that changed, with
    whether run b's score lies inside run a's bootstrap interval for it."""
    rows = []
    for path in sorted((Path(results_a) / "tables" / "study").glob("scores_ci_*.csv")):
        metric = path.stem.removeprefix("scores_ci_")
        a = pd.read_csv(path).set_index("candidate")
        b = pd.read_csv(Path(results_b) / "tables" / "study" / path.name).set_index("candidate").reindex(a.index)
        for column in ("avg", "low", "medium", "high"):
            for candidate in a.index:
                va, vb = a.at[candidate, column], b.at[candidate, column]
                lo, hi = a.at[candidate, f"{column}_ci_low"], a.at[candidate, f"{column}_ci_high"]
                if va == vb or (pd.isna(va) and pd.isna(vb)):
                    continue
                rows.append({"metric": metric, "candidate": candidate, "score": column, "a": va, "b": vb,
                             "interval_a": f"[{lo}, {hi}]", "inside": bool(lo <= vb <= hi)})
    return pd.DataFrame(rows, columns=["metric", "candidate", "score", "a", "b", "interval_a", "inside"])


def _g(value: float) -> str:
    return f"{value:.3g}"


def _markdown(frame: pd.DataFrame) -> str:
    if frame.empty:
        return "(none)"
    header = "| " + " | ".join(frame.columns) + " |\n|" + " --- |" * len(frame.columns)
    body = ["| " + " | ".join(_g(v) if isinstance(v, float) else str(v) for v in row) + " |"
            for row in frame.itertuples(index=False)]
    return "\n".join([header, *body])


def report(workdir: Path, probes: dict[str, list[str]]) -> str:
    """The Markdown report: each run's environment, then every run of ``workdir`` after the first
    compared with the first (:func:`comparison`)."""
    runs = [name for name in RUNS if (workdir / name / "results").is_dir()]
    out = [f"# Native against AVX2-restricted dispatch ({workdir})", "", "## What each run's environment reports", ""]
    for name, lines in probes.items():
        out += [f"* **{name}** (fresh interpreter): " + "; ".join(lines)]
    for name in runs:
        out += [f"* **{name}** in the jobs: numba cache {numba_cache_targets(workdir / name / 'cache' / 'numba')}; "
                f"oneDNN {log_reports(workdir / name, ONEDNN_ISA)}; shim {log_reports(workdir / name, SHIM_TARGET)}"]
    for name in runs[1:]:
        out += ["", comparison(workdir / runs[0] / "results", workdir / name / "results", f"{runs[0]} against {name}")]
    return "\n".join(out) + "\n"


def comparison(a: Path, b: Path, title: str) -> str:
    """Two runs' results compared stage by stage (Markdown): renders, references, method outputs
    (per method), metrics.csv (per entry and metric), tables, ranking and interval moves."""
    out = [f"# {title}", "", "## Stages", "", "| stage | files | differ | max abs | max rel |",
           "| --- | ---: | ---: | ---: | ---: |"]
    found_outputs = []
    for folder in ("renders", "references", "outputs"):
        stage, found = image_stage(a, b, folder)
        found_outputs = found if folder == "outputs" else found_outputs
        out.append(f"| {folder} | {stage.files} | {stage.differing} | {_g(stage.max_abs)} | {_g(stage.max_rel)} |")
    tables = compare_runs(a, b)
    out += ["", f"Tables (metrics.csv and tables/, oracle/, progressive/, timing left out): {len(tables)} differ.", ""]
    out += [_markdown(pd.DataFrame([{"table": d.table, "status": d.status, "cells": d.cells,
                                     "max_abs": d.max_abs, "max_rel": d.max_rel} for d in tables]))]
    out += ["", "## Method outputs that differ, per method", "", _markdown(per_method(found_outputs, a, b))]
    metrics = metrics_differences(a, b)
    out += ["", "## metrics.csv per (entry, metric) that differs", "",
            f"{int((metrics['differing'] > 0).sum())} of {len(metrics)} (entry, metric) pairs differ.", "",
            _markdown(metrics[metrics["differing"] > 0])]
    out += ["", "## Ranking tables: changed cells and places", "", _markdown(ranking_moves(a, b))]
    out += ["", "## Study scores (scores_ci_*.csv) that moved, against the first run's bootstrap interval", "",
            _markdown(interval_moves(a, b))]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("workdir", type=Path, help="folder for the two runs (native/, avx2/)")
    parser.add_argument("--config", type=Path, default=None,
                        help="study config (default: the small slice of workflow/configs/smoke.yaml in SMALL_CONFIG)")
    parser.add_argument("--runs", nargs="+", choices=RUNS, default=list(RUNS),
                        help="the runs to make (each in a folder that must not exist yet); default all")
    parser.add_argument("--compare-only", action="store_true", help="do not run; report on WORKDIR's finished runs")
    args = parser.parse_args(argv)
    config = SMALL_CONFIG if args.config is None else yaml.safe_load(args.config.read_text())
    envs = {name: run_environment(dict(os.environ), args.workdir / name, name) for name in RUNS}
    if not args.compare_only:
        for name in args.runs:
            if (args.workdir / name).exists():
                raise SystemExit(f"{args.workdir / name} exists: give a new WORKDIR (each run needs a fresh folder and cache)")
            run_study(args.workdir / name, config, envs[name])
    print(report(args.workdir, {name: probe(env) for name, env in envs.items()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
