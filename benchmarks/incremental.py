"""What adding a method to a finished study costs, and what moving the study costs.

Run in (or with ``--workdir``) the folder of a finished study: ``snakemake -n`` must plan
nothing there. Measured, in this order, each as wall time and CPU time (user + system of
Snakemake and every process it waited for, the warm workers included: ``getrusage`` of the
children), beside the machine's load:

1. adding (a) a program that copies its input (``method: external``, ``cp``) and (b) one real
   base denoiser (JBF with a wider window, ``jbf_wide``) to the study: ``add_denoisers`` in a
   copy of the study's config, the jobs the dry run plans, then the run;
2. removing them again (the study's own config: only the tables rerun);
   with ``--metric NAME`` also adding a metric to the study's list (each entry's kept values
   are reused: only NAME is computed, then the case assemblies and tables) and removing it;
3. ``--bundle``: ``snakemake --cores 1 export_study`` (time, archive size), then the import of
   that archive into a fresh ``git clone`` of this checkout (time), its ``snakemake -n``
   (must plan nothing), and the clone removed.

Each cost is also given as a fraction of ``--scratch-cpu``, the CPU seconds of the same study run
from scratch on the same machine (``/usr/bin/time -v snakemake --cores 2`` in an empty folder;
docs/measurements.md). Writes a Markdown table to stdout (or ``--out``)::

    python benchmarks/incremental.py --workdir /path/to/finished --scratch-cpu 6170 --bundle
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
COPY_PROGRAM = ["sh", "-c", "cp {input_dir}/color.exr {output_dir}/{name}.exr && "
                "cp {input_dir}/colorA.exr {output_dir}/{name}A.exr && cp {input_dir}/colorB.exr {output_dir}/{name}B.exr"]
ADDITIONS = {
    "copy program (external)": {"name": "copy_input", "method": "external", "label": "Copy of the input",
                                "params": {"command": COPY_PROGRAM}},
    "JBF, wider window (a real base)": {"name": "jbf_wide", "method": "jbf", "label": "JBF (radius 9)",
                                        "params": {"radius": 9}},
}


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed(command: list[str], *, cwd: Path) -> tuple[float, float, str]:
    """(wall s, CPU s, output) of ``command``; raises with its output's end on failure."""
    cpu, start = children_cpu(), time.perf_counter()
    result = subprocess.run(command, cwd=cwd, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - start, children_cpu() - cpu
    text = result.stdout + result.stderr
    if result.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed in {cwd}:\n{text[-3000:]}")
    return wall, cpu, text


def snakemake(workdir: Path, configfile: Path, *args: str, checkout: Path = REPO) -> list[str]:
    return [sys.executable, "-m", "snakemake", "-s", str(checkout / "Snakefile"), "--directory", str(workdir),
            "--configfile", str(configfile), *args]


def job_counts(text: str) -> dict[str, int]:
    if "Job stats:" not in text:
        return {}
    table = text.split("Job stats:")[1].split("total")[0]
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^(\w+)\s+(\d+)$", table, re.MULTILINE)}


def _arguments(argv) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workdir", type=Path, default=Path.cwd())
    parser.add_argument("--configfile", type=Path, help="the study's config (default: WORKDIR/config.yaml, "
                        "else this checkout's config.yaml)")
    parser.add_argument("--scratch-cpu", type=float, help="CPU seconds of the study run from scratch")
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--bundle", action="store_true", help="also export, import and dry-run a clone")
    parser.add_argument("--metric", help="also add this metric to the study's list, then remove it")
    parser.add_argument("--out", type=Path)
    return parser.parse_args(argv)


def _add_methods(workdir: Path, configfile: Path, base: dict, cores: int, row) -> None:
    """Each method of :data:`ADDITIONS` added to the finished study, then removed again."""
    for what, entry in ADDITIONS.items():
        config = dict(base, add_denoisers=list(base.get("add_denoisers") or []) + [entry])
        edited = workdir / f".incremental_{entry['name']}.yaml"
        edited.write_text(yaml.safe_dump(config))
        _, _, plan = timed(snakemake(workdir, edited, "-n"), cwd=workdir)
        counts = job_counts(plan)
        jobs = ", ".join(f"{rule} {n}" for rule, n in counts.items() if rule == "run_case")
        wall, cpu, _ = timed(snakemake(workdir, edited, "--cores", str(cores)), cwd=workdir)
        row(f"add {what}", wall, cpu, f"{sum(counts.values())} ({jobs})")
        wall, cpu, _ = timed(snakemake(workdir, configfile, "--cores", str(cores)), cwd=workdir)
        row(f"remove it again (tables only)", wall, cpu)
        edited.unlink()


def _add_metric(workdir: Path, configfile: Path, base: dict, metric: str, cores: int, row) -> None:
    """``metric`` added to the finished study's metrics, then removed again."""
    metrics = list(base.get("metrics") or [])
    if metric in metrics:
        raise SystemExit(f"--metric {metric}: the study already has it ({metrics})")
    edited = workdir / ".incremental_metric.yaml"
    edited.write_text(yaml.safe_dump(dict(base, metrics=metrics + [metric])))
    _, _, plan = timed(snakemake(workdir, edited, "-n"), cwd=workdir)
    wall, cpu, _ = timed(snakemake(workdir, edited, "--cores", str(cores)), cwd=workdir)
    row(f"add the metric {metric}", wall, cpu, str(sum(job_counts(plan).values())))
    wall, cpu, _ = timed(snakemake(workdir, configfile, "--cores", str(cores)), cwd=workdir)
    row("remove it again (values kept: no metric computed)", wall, cpu)
    edited.unlink()


def _bundle_round_trip(workdir: Path, configfile: Path, row) -> None:
    """The study exported, imported into a fresh clone, and dry-run there."""
    archive = workdir / "results/bundle/study.tar.gz"
    wall, cpu, _ = timed(snakemake(workdir, configfile, "--cores", "1", "export_study", "-f"), cwd=workdir)
    row("export_study", wall, cpu, extra=f"{archive.stat().st_size / 2**20:.1f} MiB")
    with tempfile.TemporaryDirectory(dir=workdir.parent) as tmp:
        clone = Path(tmp) / "clone"
        subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True)
        shutil.copyfile(configfile, clone / "study_config.yaml")
        env_command = [sys.executable, "-m", "mcbench.pipeline.bundle", "import", str(archive),
                       "--configfile", "study_config.yaml"]
        wall, cpu, _ = timed(env_command, cwd=clone)
        row("import into a fresh clone", wall, cpu)
        _, _, text = timed(snakemake(clone, clone / "study_config.yaml", "-n", checkout=clone), cwd=clone)
        row("snakemake -n in the clone", 0.0, 0.0, extra="nothing to be done" if "Nothing to be done" in text
            else "PLANS JOBS")


def main(argv=None) -> None:
    args = _arguments(argv)
    workdir = args.workdir.resolve()
    configfile = (args.configfile or (workdir / "config.yaml" if (workdir / "config.yaml").exists()
                                      else REPO / "config.yaml")).resolve()
    _, _, text = timed(snakemake(workdir, configfile, "-n"), cwd=workdir)
    if "Nothing to be done" not in text:
        raise SystemExit(f"{workdir}: the study is not finished (snakemake -n plans jobs); finish it first")
    base = yaml.safe_load(configfile.read_text()) or {}
    rows = []

    def row(what, wall, cpu, jobs="", extra=""):
        fraction = f"{100 * cpu / args.scratch_cpu:.2f} %" if args.scratch_cpu else "n/a"
        rows.append(f"| {what} | {wall:.1f} | {cpu:.1f} | {fraction} | {jobs} | {extra} | {os.getloadavg()[0]:.2f} |")

    _add_methods(workdir, configfile, base, args.cores, row)
    if args.metric:
        _add_metric(workdir, configfile, base, args.metric, args.cores, row)
    if args.bundle:
        _bundle_round_trip(workdir, configfile, row)
    header = ["| step | wall s | CPU s | CPU / from-scratch CPU | jobs planned | | load (1 min) |",
              "|---|---:|---:|---:|---|---|---:|"]
    table = "\n".join(header + rows) + "\n"
    cpu_model = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                      if line.startswith("model name")), "unknown CPU") if Path("/proc/cpuinfo").exists() else "?"
    text = f"{workdir}, {os.cpu_count()} cores, {cpu_model}\n\n{table}"
    if args.out:
        args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
