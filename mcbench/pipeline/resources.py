"""Per-job resources for a cluster: memory and run time of each rule's jobs, from measured costs.

Every rule of the workflow declares ``threads``, ``mem_mb`` and ``runtime`` (minutes), and the
rules that can use a GPU declare ``gpu`` (:class:`StudyRequests`, which
:meth:`mcbench.pipeline.study_setup.StudySetup.resources` turns into a rule's ``resources:``). A
local run ignores ``mem_mb`` and ``runtime`` unless ``--resources`` limits them; the SLURM
executor turns them into ``--mem`` and ``-t`` (``profiles/slurm``).

Cost model (one job)
--------------------
With ``P`` the job's megapixels (width x height / 1e6), ``E`` the entries the job handles (the
viewer's images; 1 for other jobs) and ``S`` the samples per pixel the job renders (0 for jobs that render
nothing)::

    seconds = base_s + s_per_mpx * P + s_per_mpx_entry * P * E + s_per_gsample * P * S / 1000
    rss_mb  = base_mb + mb_per_mpx * P + mb_per_mpx_entry * P * E

i.e. a constant part (process start, imports, the numba cache, the workflow's parse) and parts
linear in the pixels, the methods and the samples: per-method costs grow linearly with pixels
(``benchmarks/bench_nfor.py`` and the other method benchmarks measure it), a render's with pixels
x spp, and a job's memory is the interpreter's plus a few float32/float64 copies of its case's
buffers. The constants (``workflow/resources/job_costs.yaml``)
are fitted by non-negative least squares to the ``benchmark:`` records (wall seconds, peak RSS)
of finished runs at two resolutions by ``python benchmarks/job_costs.py RESULTS...``, which
writes that file; its header names the runs it was fitted to. Two fits per rule: to the largest
job of each size (section ``rules``: requests) and to the mean one (``typical``: the CPU-hour
estimates of ``benchmarks/cluster_estimate.py``); ``run_method`` also per method module
(``run_method/nfor``), since the methods' costs differ widely (NFOR, OIDN): a case's job
(``run_case``) asks for the sum of its methods' and its entries' evaluations
(:meth:`StudyRequests.case_request`).

Requests
--------
:func:`job_request` turns an estimate into what a scheduler is asked for: memory
``MEMORY_MARGIN`` x the estimate rounded up to 64 MB, at least ``MIN_MEM_MB``; run time
``RUNTIME_MARGIN`` x the estimate in whole minutes, at least ``MIN_RUNTIME_MIN`` (a cluster
node is often slower than the workstation the records come from, and SLURM kills a job at its
limit but only queues a larger request longer). A job whose request exceeds ``JOB_MEMORY_LIMIT_MB``
(2 GiB) at the default sizes is a bug in the job, not a resource to raise (``tests/pipeline/test_resources.py``
checks every rule of the default config).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Mapping

import numpy as np
import yaml

from mcbench import BenchError

__all__ = ["StudyRequests", "GPU_RULES", "JobCost", "JOB_COSTS_PATH", "MEMORY_MARGIN", "RUNTIME_MARGIN", "MIN_MEM_MB",
           "MIN_RUNTIME_MIN", "JOB_MEMORY_LIMIT_MB", "load_job_costs", "write_job_costs",
           "estimate_job", "job_request", "fit_job_cost"]

JOB_COSTS_PATH = Path(__file__).resolve().parents[2] / "workflow" / "resources" / "job_costs.yaml"

MEMORY_MARGIN = 1.5       # x the estimated peak RSS
RUNTIME_MARGIN = 3.0      # x the estimated wall time
MIN_MEM_MB = 512
MIN_RUNTIME_MIN = 5
JOB_MEMORY_LIMIT_MB = 2048


@dataclass(frozen=True)
class JobCost:
    """The fitted cost of one rule's jobs (see the module docstring for the model).

    Seconds are wall seconds of one job on one core of the measuring machine; megabytes are
    peak resident set sizes (``benchmark:`` ``max_rss``, MB)."""

    base_s: float = 0.0
    s_per_mpx: float = 0.0
    s_per_mpx_entry: float = 0.0
    s_per_gsample: float = 0.0
    base_mb: float = 0.0
    mb_per_mpx: float = 0.0
    mb_per_mpx_entry: float = 0.0

    def __post_init__(self):
        for field in fields(self):
            value = getattr(self, field.name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise BenchError(f"job cost {field.name}: {value!r} is not a finite non-negative number")


def load_job_costs(path: str | Path = JOB_COSTS_PATH, *, section: str = "rules") -> dict[str, JobCost]:
    """The per-rule costs of ``path``: a YAML mapping ``{section: {rule: {field: value}}}``.

    ``section="rules"``: fitted to the largest job of each size, what requests are made from;
    ``"typical"``: fitted to the mean job of each size, what CPU-hour estimates add up. A key
    ``rule/module`` (e.g. ``run_method/nfor``) holds one method's cost within a rule that runs
    several. BenchError naming the file and the rule for an unknown field or a bad value."""
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as error:
        raise BenchError(f"{path}: cannot read the job costs: {error}") from error
    if not isinstance(document, dict) or not isinstance(document.get(section), dict):
        raise BenchError(f"{path}: expected a mapping '{section}: {{rule: {{cost fields}}}}'")
    known = {field.name for field in fields(JobCost)}
    costs = {}
    for rule, values in document[section].items():
        if not isinstance(values, dict) or set(values) - known:
            unknown = sorted(set(values) - known) if isinstance(values, dict) else values
            raise BenchError(f"{path}: {section}.{rule}: unknown cost fields {unknown}; known: {sorted(known)}")
        try:
            costs[rule] = JobCost(**values)
        except BenchError as error:
            raise BenchError(f"{path}: {section}.{rule}: {error}") from error
    return costs


def write_job_costs(sections: dict[str, dict[str, JobCost]], path: str | Path, *, header: str) -> None:
    """Write ``{section: {rule: cost}}`` as :func:`load_job_costs` reads them, ``header`` as
    leading comment lines (the command and the runs they were fitted to); atomically."""
    path = Path(path)
    lines = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines())
    body = {section: {rule: {name: round(float(value), 6) for name, value in asdict(cost).items()}
                      for rule, cost in sorted(costs.items())}
            for section, costs in sections.items()}
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(lines + yaml.safe_dump(body, sort_keys=False))
    temporary.replace(path)


def estimate_job(cost: JobCost, *, pixels: int, entries: int = 1, spp: int = 0) -> tuple[float, float]:
    """Estimated ``(seconds, rss_mb)`` of one job: ``pixels`` per image (width x height),
    ``entries`` the job handles, ``spp`` samples per pixel rendered."""
    if pixels < 0 or entries < 0 or spp < 0:
        raise BenchError(f"job estimate: pixels {pixels}, entries {entries}, spp {spp} must be >= 0")
    mpx = pixels / 1e6
    seconds = (cost.base_s + cost.s_per_mpx * mpx + cost.s_per_mpx_entry * mpx * entries
               + cost.s_per_gsample * mpx * spp / 1000.0)
    rss_mb = cost.base_mb + cost.mb_per_mpx * mpx + cost.mb_per_mpx_entry * mpx * entries
    return seconds, rss_mb


def job_request(seconds: float, rss_mb: float) -> dict[str, int]:
    """What a scheduler is asked for an estimate: ``{"mem_mb": ..., "runtime": minutes}``
    (margins and floors in the module docstring)."""
    mem_mb = max(MIN_MEM_MB, 64 * math.ceil(MEMORY_MARGIN * max(rss_mb, 0.0) / 64))
    runtime = max(MIN_RUNTIME_MIN, math.ceil(RUNTIME_MARGIN * max(seconds, 0.0) / 60))
    return {"mem_mb": int(mem_mb), "runtime": int(runtime)}


def fit_job_cost(records, *, statistic: str = "max", min_records: int = 2) -> JobCost:
    """Fit one rule's :class:`JobCost` to measured jobs by non-negative least squares.

    ``records``: iterable of mappings with ``pixels``, ``entries``, ``spp``, ``seconds`` and
    ``rss_mb`` (one per job). Jobs of the same size (equal pixels, entries, spp) are reduced to
their maximum (``statistic="max"``: the fit follows the slowest and largest job of each size,
for requests) or their mean (``"mean"``: the typical job, for CPU-hour estimates) seconds and RSS
first. Seconds are fitted against ``[1, P, P E, P S / 1000]``, memory
    against ``[1, P, P E]`` (P megapixels; module docstring), each with ``scipy.optimize.nnls``
    so no term goes negative. A column that is constant over the records cannot be told apart
    from the constant term and is dropped (its coefficient 0): records at one resolution fit
    only the constant part. Raises BenchError with fewer than ``min_records`` records."""
    from scipy.optimize import nnls

    rows = list(records)
    if len(rows) < min_records:
        raise BenchError(f"job cost fit: {len(rows)} records, need at least {min_records}")
    if statistic not in ("max", "mean"):
        raise BenchError(f"job cost fit: statistic {statistic!r} is not 'max' or 'mean'")
    reduce = max if statistic == "max" else (lambda values: sum(values) / len(values))
    by_size: dict[tuple, list] = {}
    for row in rows:
        by_size.setdefault((row["pixels"], row["entries"], row["spp"]), []).append(row)
    rows = [{"pixels": key[0], "entries": key[1], "spp": key[2],
             "seconds": reduce([r["seconds"] for r in group]), "rss_mb": reduce([r["rss_mb"] for r in group])}
            for key, group in by_size.items()]
    mpx = np.array([row["pixels"] for row in rows], dtype=np.float64) / 1e6
    entries = np.array([row["entries"] for row in rows], dtype=np.float64)
    spp = np.array([row["spp"] for row in rows], dtype=np.float64)
    seconds = np.array([row["seconds"] for row in rows], dtype=np.float64)
    rss = np.array([row["rss_mb"] for row in rows], dtype=np.float64)

    def solve(columns, target):
        design = [np.ones_like(target)]
        kept = []
        for column in columns:
            if np.ptp(column) > 1e-12 * max(np.abs(column).max(), 1e-300):
                design.append(column)
                kept.append(True)
            else:
                kept.append(False)
        matrix = np.stack(design, axis=1)
        scale = np.maximum(np.abs(matrix).max(axis=0), 1e-300)   # columns of similar size for nnls
        solution, _ = nnls(matrix / scale, target)
        solution = solution / scale
        out, at = [float(solution[0])], 1
        for keep in kept:
            out.append(float(solution[at]) if keep else 0.0)
            at += keep
        return out

    base_s, s_px, s_px_entry, s_sample = solve([mpx, mpx * entries, mpx * spp / 1000.0], seconds)
    base_mb, mb_px, mb_px_entry = solve([mpx, mpx * entries], rss)
    return JobCost(base_s=base_s, s_per_mpx=s_px, s_per_mpx_entry=s_px_entry, s_per_gsample=s_sample,
                   base_mb=base_mb, mb_per_mpx=mb_px, mb_per_mpx_entry=mb_px_entry)


#: Rules whose jobs render with Mitsuba and can use a GPU (variant auto or cuda_ad_rgb).
GPU_RULES = frozenset({"render_noisy", "render_reference_chunk", "training_example", "oracle_study"})


@dataclass(frozen=True)
class StudyRequests:
    """The resource requests of a study's jobs: mem_mb and runtime (minutes) from the fitted
    ``costs`` (:func:`load_job_costs`) at each job's size in the ``plan``
    (:class:`mcbench.pipeline.study_plan.StudyPlan`), times the attempt (a retry asks for
    ``attempt`` times as much); ``gpus`` (and ``gpu_model``) for the rules that can use one."""

    plan: object
    costs: Mapping
    gpus: int = 0
    gpu_model: str = ""
    variant: str = "auto"

    def job_size(self, rule: str, *, scene: str | None = None, spp: int | None = None) -> tuple[int, int, int]:
        """``(pixels, entries, spp)`` of one job of ``rule`` (the cost model's size)."""
        cases = self.plan.cases
        pixels = cases.pixels(scene) if scene else 0
        if rule == "render_noisy":
            return pixels, 1, int(spp)
        if rule == "render_reference_chunk":
            return pixels, 1, int(cases.reference_spp[scene]) // cases.reference_chunks
        if rule == "viewer":
            entries = len(self.plan.ranking.entries)
            return max(cases.pixels(s) for s in cases.scenes), len(cases.pairs) * entries, 0
        return pixels, 1, 0

    def request(self, rule: str, *, scene: str | None = None, spp: int | None = None, network: str | None = None,
                attempt: int = 1) -> dict[str, int]:
        """mem_mb and runtime of one job of ``rule`` (a network's own cost, e.g.
        ``train_network/kpcn``, where measured; the floors for a rule without records)."""
        cost = (network and self.costs.get(f"{rule}/{network}")) or self.costs.get(rule, JobCost())
        pixels, entries, samples = self.job_size(rule, scene=scene, spp=spp)
        request = job_request(*estimate_job(cost, pixels=pixels, entries=entries, spp=samples))
        return {key: value * attempt for key, value in request.items()}

    def case_request(self, scene: str, *, attempt: int = 1) -> dict[str, int]:
        """mem_mb and runtime of a case's job (rule run_case): the sum of its methods' fitted
        costs (``run_method/<module>``, else ``run_method``) and of its entries' evaluations
        (``evaluate_entry``), the whole case made (an incremental run makes less)."""
        pixels = self.plan.cases.pixels(scene)
        seconds, rss_mb = 0.0, 0.0
        for method in self.plan.methods.values():
            cost = self.costs.get(f"run_method/{method.module}") or self.costs.get("run_method", JobCost())
            method_seconds, method_mb = estimate_job(cost, pixels=pixels)
            seconds, rss_mb = seconds + method_seconds, max(rss_mb, method_mb)
        evaluation_seconds, evaluation_mb = estimate_job(self.costs.get("evaluate_entry", JobCost()), pixels=pixels)
        request = job_request(seconds + evaluation_seconds * len(self.plan.ranking.entries),
                              max(rss_mb, evaluation_mb))
        return {key: value * attempt for key, value in request.items()}

    def gpu_resources(self, rule: str) -> dict:
        """``gpu`` (and ``gpu_model``) for a rule that renders with Mitsuba when the config asks
        for GPUs and its variant can use one; else nothing."""
        if rule not in GPU_RULES or not self.gpus or self.variant not in ("auto", "cuda_ad_rgb"):
            return {}
        return {"gpu": self.gpus, **({"gpu_model": self.gpu_model} if self.gpu_model else {})}
