"""What a config costs on a cluster: jobs, CPU-hours and requests per rule, from the fitted job costs.

    python benchmarks/cluster_estimate.py [--configfile workflow/configs/paper.yaml]

Plans the config's jobs the way the rules do (one noisy render per scene and spp, the reference
chunks, one job per non-batched method per case, the learned and combiner batches, metrics and
viewer pages per case, the oracle study) and prices each with ``mcbench.pipeline.resources``'
``estimate_job`` and the costs of ``workflow/resources/job_costs.yaml`` (fitted by
``benchmarks/job_costs.py`` to measured runs): CPU-hours from the typical (mean) job's fit, the
requests (memory, run time) from the largest job's. CPU-seconds are a job's estimated wall seconds
times its threads; render estimates are the wall seconds measured with the default config's
``render_threads`` (1), counted as one core each whatever a config's ``render_threads`` (a
render's CPU-seconds do not shrink with more threads; its wall time would). Training is not part of
the main job (committed weights) and is not counted. GPU-hours are not estimated: no GPU
render was measured here; the renders' share of the CPU-hours is what a GPU would take over.
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcbench.pipeline.config import read_config_file  # noqa: E402
from mcbench.pipeline.resources import JobCost, estimate_job, job_request, load_job_costs  # noqa: E402
from mcbench.io.weights import is_learned_method  # noqa: E402
from methods import config_method_table  # noqa: E402
from scenes import load_scene, scene_spec  # noqa: E402

MEASURED_RENDER_THREADS = 1


def planned_jobs(config: dict) -> list[dict]:
    """One dict per job: rule, pixels, entries, spp, threads."""
    methods = config_method_table(config, is_learned=is_learned_method)
    # each case's methods and evaluations run in one job (rule run_case, methods.smk); from
    # scratch its cost is the sum of its methods' (run_method/<module>) and its entries' evaluations
    chunks = config["reference"]["chunks"]
    jobs = []
    for scene in config["scenes"]:
        width, height = config["resolution"] or scene_spec(load_scene(scene)).size
        pixels = int(width) * int(height)
        reference_spp = int(config["reference"]["scene_spp"].get(scene, config["reference"]["spp"]))
        jobs += [{"rule": "render_reference_chunk", "pixels": pixels, "entries": 1, "spp": reference_spp // chunks,
                  "threads": MEASURED_RENDER_THREADS}] * chunks
        for spp in config["spp"]:
            jobs.append({"rule": "render_noisy", "pixels": pixels, "entries": 1, "spp": spp,
                         "threads": MEASURED_RENDER_THREADS})
            jobs += [{"rule": "run_method", "module": methods[name]["module"], "pixels": pixels, "entries": 1,
                      "spp": 0, "threads": 1} for name in methods]
            jobs += [{"rule": "evaluate_entry", "pixels": pixels, "entries": 1, "spp": 0, "threads": 1}] * (len(methods) + 1)
    oracle_scene = config["oracle"]["scene"] or config["scenes"][0]
    width, height = config["resolution"] or scene_spec(load_scene(oracle_scene)).size
    jobs.append({"rule": "oracle_study", "pixels": int(width) * int(height), "entries": 1, "spp": 0, "threads": 1})
    if any(spec["module"] == "progressive" for spec in methods.values()):
        curve_scene = config["progressive_curve"]["scene"] or config["scenes"][0]
        width, height = config["resolution"] or scene_spec(load_scene(curve_scene)).size
        jobs.append({"rule": "progressive_curve", "pixels": int(width) * int(height), "entries": 1, "spp": 0,
                     "threads": 1})
    return jobs


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--configfile", default="workflow/configs/paper.yaml")
    args = parser.parse_args(argv)
    config = read_config_file(args.configfile)
    costs, typical = load_job_costs(), load_job_costs(section="typical")
    per_rule = defaultdict(lambda: {"jobs": 0, "cpu_s": 0.0, "max_s": 0.0, "mem_mb": 0, "runtime": 0})
    for job in planned_jobs(config):
        key = f"{job['rule']}/{job['module']}" if f"{job['rule']}/{job.get('module')}" in costs else job["rule"]
        size = {"pixels": job["pixels"], "entries": job["entries"], "spp": job["spp"]}
        request = job_request(*estimate_job(costs.get(key, JobCost()), **size))
        seconds, _ = estimate_job(typical.get(key, JobCost()), **size)
        row = per_rule[job["rule"]]
        row["jobs"] += 1
        row["cpu_s"] += seconds * job["threads"]
        row["max_s"] = max(row["max_s"], seconds)
        row["mem_mb"] = max(row["mem_mb"], request["mem_mb"])
        row["runtime"] = max(row["runtime"], request["runtime"])
    print(f"{args.configfile}: {len(config['scenes'])} scenes, spp {config['spp']}, "
          f"{sum(r['jobs'] for r in per_rule.values())} jobs (tables and figures: local, not counted)")
    print(f"{'rule':24s} {'jobs':>6s} {'CPU-h':>8s} {'longest typical s':>18s} {'max mem_mb':>11s} {'max runtime':>12s}")
    for rule, row in sorted(per_rule.items(), key=lambda item: -item[1]["cpu_s"]):
        print(f"{rule:24s} {row['jobs']:6d} {row['cpu_s'] / 3600:8.2f} {row['max_s']:18.1f} {row['mem_mb']:11d} "
              f"{row['runtime']:9d} min")
    total = sum(r["cpu_s"] for r in per_rule.values())
    renders = sum(per_rule[r]["cpu_s"] for r in ("render_noisy", "render_reference_chunk", "oracle_study", "progressive_curve") if r in per_rule)
    print(f"total {total / 3600:.1f} CPU-hours, of which renders {renders / 3600:.1f} "
          f"({renders / max(total, 1e-9):.0%}: what GPU renders would take over; GPU-hours not measured here)")


if __name__ == "__main__":
    main()
