# Helpers shared by the rules: the resolved config, the method table, input functions.
# Path patterns live in the rules' own output declarations (rules.X.output); the helpers here
# expand those.

import copy
import functools
import hashlib
import json
import os
import sys

from snakemake.logging import logger
from pathlib import Path

sys.path.insert(0, str(Path(workflow.basedir)))  # methods/, scenes/, mcbench/ from a checkout

from mcbench import NOISY, NOISY_LABEL, BenchError  # noqa: E402
from mcbench.pipeline.config import config_digest, resolve_config  # noqa: E402
from mcbench.pipeline.plan import plan_study  # noqa: E402
from mcbench.pipeline.render import folder_case_files, folder_reference_files  # noqa: E402
from mcbench.analysis.metrics import ALL_METRICS  # noqa: E402
from mcbench.analysis.pool import POOL  # noqa: E402
from mcbench.analysis.study.figures import STUDY_FIGURES as STUDY_FIGURE_KEYS, curve_candidates, paper_recommended  # noqa: E402
from mcbench.pipeline.resources import JobCost, estimate_job, job_request, load_job_costs  # noqa: E402
from mcbench.io.method_spec import method_spec  # noqa: E402
from mcbench.io.weights import COMMITTED_WEIGHTS, check_trained_features, file_sha256, is_learned_method  # noqa: E402
from mcbench.pipeline.registry import available_scenes, config_method_table, load_method, load_scene  # noqa: E402
from mcbench.pipeline.jobs import (  # noqa: E402
    batch_name, batch_text, missing_batches, read_batch, spec_text, target_batch_names, write_if_changed)


# The whole configuration: the config file (config.yaml or the --configfile) plus the schema's
# defaults, validated; errors name the file and the key.
_CONFIG_SOURCE = ", ".join(str(f) for f in workflow.configfiles) or "config"
_WRITTEN = copy.deepcopy(dict(config))
_RESOLVED = resolve_config(dict(config), source=_CONFIG_SOURCE)
config.clear()
config.update(_RESOLVED)
logger.info(f"mcbench: configuration {_CONFIG_SOURCE} with the schema's defaults, digest {config_digest(config)}")

RESULTS = "results"
# Learned methods' weights: the committed methods/weights of this checkout unless the config
# names another folder (relative to the working directory).
WEIGHTS_DIR = config["weights_dir"] or str(COMMITTED_WEIGHTS)

# Everything the rules plan that depends on the config alone, checked before any job
# (mcbench.pipeline.plan.plan_study; the tests call the same function). Errors name the file and
# the key, and say so when the key holds a schema default the config never wrote.
PLAN = plan_study(config, written=_WRITTEN, source=_CONFIG_SOURCE, is_learned=is_learned_method)
METHODS = PLAN["methods"]
SCENES = PLAN["scenes"]
SPPS = PLAN["spps"]
CANDIDATES = PLAN["candidates"]
# The ranking pool. With study.pool: exactly the 39 candidates of Zheng et al. Sec. 5.3.1 the
# config runs (mcbench.analysis.pool), in ID order; otherwise every candidate but the comparison methods
# of Sec. 5.2 (one-hot selection, naive averages, ablations; ranked in comparisons.smk). Every
# other method is an extra, scored in a pool that adds it alone (rule extras_table).
POOL_STUDY = PLAN["pool_study"]
RANKED = PLAN["ranked"]
EXTRAS = PLAN["extras"]
POOL_NOTE = PLAN["pool_note"]
# progressive denoising's entries (combiners of module progressive) -> the method each mixes with
# the noisy render (progressive.smk)
PROGRESSIVE = PLAN["progressive"]
LABELS = PLAN["labels"]
METRIC_NAMES = PLAN["metrics"]
REFERENCE_CHUNKS = PLAN["reference_chunks"]
# reference spp per configured scene: reference.scene_spp[scene] or reference.spp
REFERENCE_SPP = PLAN["reference_spp"]


wildcard_constraints:
    scene="[A-Za-z][A-Za-z0-9_]*",
    method="[A-Za-z][A-Za-z0-9_]*",
    spp=r"\d+",
    chunk=r"\d+",
    seed=r"\d+",
    metric="|".join(ALL_METRICS),


# The per-method and per-entry jobs run in warm worker processes (mcbench.pipeline.pool): their
# rules' `run:` blocks call run_in_pool in Snakemake's own process, which needs Snakemake's
# threads for `run:` jobs (force-use-threads, set by the workflow profile profiles/default;
# without it each such job would start a whole Snakemake process: the same results, far slower).


def run_in_pool(step, *args, log, **kwargs):
    """Run ``step`` ("module:function") of a ``run:`` rule in a warm worker (mcbench.pipeline.pool),
    with as many workers as the cores Snakemake was given, the job's weights folder and this
    checkout on the workers' paths."""
    from mcbench.pipeline.pool import run_step

    run_step(step, *args, log_path=log, workers=max(1, int(workflow.cores or 1)),
             environment={"MCBENCH_WEIGHTS_DIR": str(Path(WEIGHTS_DIR).resolve())},
             paths=[str(Path(workflow.basedir))], **kwargs)


# Per-method and per-entry files, and the jobs that make them (mcbench.pipeline.jobs): a file that
# exists belongs to its per-file rule (run_method, entry_metrics, entry_viewer), which Snakemake
# reruns when it finds the file out of date; the files that do not exist yet are made by one batch
# job per case (from scratch: every method of the case in one job). Neither kind has params: a
# method's parameters are its spec file (results/specs/methods/<name>.json, rewritten only when the
# spec changes, so its mtime says when), the metric list is in the metrics files' folder name; both
# have the same `run:` code (one rule definition in a loop), so Snakemake records the same for a
# file whichever made it. The workflow profile leaves out Snakemake's `input` rerun trigger (a
# batch's input list is not a per-file rule's): every rule whose input list can change without
# its files' mtimes carries that list in its params.
METHOD_EXR = f"{RESULTS}/outputs/{{scene}}/spp{{spp}}/{{method}}.exr"
METHOD_TIMING = f"{RESULTS}/outputs/{{scene}}/spp{{spp}}/{{method}}.json"
SPEC_FILE = f"{RESULTS}/specs/methods/{{method}}.json"
BATCH_FILE = f"{RESULTS}/specs/batches/{{name}}.json"
METRIC_SET = f"m{hashlib.sha256(json.dumps(METRIC_NAMES).encode()).hexdigest()[:10]}"
ENTRY_METRICS = f"{RESULTS}/metrics/{{scene}}/spp{{spp}}/{METRIC_SET}/{{entry}}.csv"
# The metric values of an entry kept across metric lists (an added metric is the only one computed;
# mcbench.pipeline.metrics.read_metric_values): not a rule's output, a record the evaluation reuses.
ENTRY_VALUES = f"{RESULTS}/metrics/{{scene}}/spp{{spp}}/values/{{entry}}.json"
ENTRY_VIEWER = f"{RESULTS}/viewer_entries/{{scene}}/spp{{spp}}/{{entry}}"
#: A case's entries: the noisy input and every candidate.
ENTRIES = [NOISY] + CANDIDATES
CASES = [(scene, int(spp)) for scene in SCENES for spp in SPPS]


def _path(pattern, scene, spp, **names):
    return pattern.format(scene=scene, spp=spp, **names)


def run_case_assembly(step, input, output, params, wildcards, log, **kwargs):
    """A per-case assembly (case_metrics, viewer_case) in the pool: ``step({entry: input file},
    output, scene=, spp=, **kwargs)``, the inputs in the order of ``params.entries`` (method
    names are never Snakemake input names: some, e.g. 'copy', are reserved there)."""
    run_in_pool(step, dict(zip(params.entries, input)), output[0], log=log[0], scene=wildcards.scene,
                spp=int(wildcards.spp), **kwargs)


def method_output(name, wildcards, kind="exr"):
    """Output path (``exr`` or ``timing``) of method ``name`` in the case of ``wildcards``."""
    return _path(METHOD_EXR if kind == "exr" else METHOD_TIMING, wildcards.scene, wildcards.spp, method=name)


def method_spec_file(name):
    return SPEC_FILE.format(method=name)


def _method_spec(name):
    spec = METHODS[name]
    return {"module": spec["module"], "params": spec["params"], "inputs": spec["inputs"],
            "weights_sha256": weights_digest_of(spec["module"]) if spec["learned"] else ""}


def _method_exists(scene, spp, name):
    return all(os.path.exists(_path(p, scene, spp, method=name)) for p in (METHOD_EXR, METHOD_TIMING))


def _case_item_exists(scene, spp, item):
    """Whether a case's item exists: a method's output (and timing record), or ``entry:metrics``/``entry:viewer``."""
    if ":" not in item:
        return _method_exists(scene, spp, item)
    entry, product = item.rsplit(":", 1)
    return os.path.exists(_path(ENTRY_METRICS if product == "metrics" else ENTRY_VIEWER, scene, spp, entry=entry))


def _constraints(batch):
    return {"scene": "|".join(batch["scenes"]), "spp": "|".join(str(s) for s in batch["spps"])}


def _batch_inputs(items):
    """Input function of a case batch: the method outputs its methods and evaluations read that it does not make."""
    made = {i for i in items if ":" not in i}

    def inputs(wildcards):
        wanted = [i for name in made for i in METHODS[name]["inputs"]]
        wanted += [i.rsplit(":", 1)[0] for i in items if ":" in i]
        return [method_output(name, wildcards) for name in dict.fromkeys(wanted) if name in METHODS and name not in made]

    return inputs


def _check_all_weights(names):
    def weights(wildcards):
        for name in names:
            check_weights(name)
        return []

    return weights




def entry_image(entry, wildcards):
    """The image an entry's evaluation reads: the render for the noisy input, else the method's output."""
    if entry == NOISY:
        return rules.render_noisy.output[0].format(scene=wildcards.scene, spp=wildcards.spp)
    return method_output(entry, wildcards)


def _eval_outputs(items):
    metrics = [ENTRY_METRICS.replace("{entry}", i.rsplit(":", 1)[0]) for i in items if i.endswith(":metrics")]
    viewers = [directory(ENTRY_VIEWER.replace("{entry}", i.rsplit(":", 1)[0])) for i in items if i.endswith(":viewer")]
    return {**({"metrics": metrics} if metrics else {}), **({"viewer": viewers} if viewers else {})}




def case_items(rule_name, wildcards):
    """What a case job (common.smk CASE_JOBS) makes in one case: ``(method entries, evaluation
    items)`` for ``mcbench.pipeline.methods.run_case_items``."""
    if rule_name == "run_method":
        items = [wildcards.method]
    elif rule_name in ("entry_metrics", "entry_viewer"):
        items = [f"{wildcards.entry}:{rule_name.removeprefix('entry_')}"]
    else:
        items = CASE_JOB_OF[rule_name]["items"]
    render = _path(_RENDER, wildcards.scene, wildcards.spp)
    reference = _REFERENCE.format(scene=wildcards.scene)
    entries = [{"name": name, "module": METHODS[name]["module"], "params": METHODS[name]["params"],
                "input_paths": [method_output(i, wildcards) for i in METHODS[name]["inputs"]],
                "exr": method_output(name, wildcards), "timing": method_output(name, wildcards, "timing"),
                "render": render}
               for name in items if ":" not in name]
    by_entry = {}
    for item in (i for i in items if ":" in i):
        entry, product = item.rsplit(":", 1)
        record = by_entry.setdefault(entry, {"entry": entry, "image": entry_image(entry, wildcards), "metrics": None,
                                             "reference": reference,
                                             "viewer": None, "weight_inputs": list(METHODS[entry]["inputs"])
                                             if entry in METHODS else []})
        record[product] = _path(ENTRY_METRICS if product == "metrics" else ENTRY_VIEWER, wildcards.scene,
                                wildcards.spp, entry=entry)
        if product == "metrics":
            record["values"] = _path(ENTRY_VALUES, wildcards.scene, wildcards.spp, entry=entry)
    return entries, list(by_entry.values())


def case_entry_metrics(wildcards):
    """The metrics CSVs of a case's entries, in the order of ENTRIES (the noisy input first)."""
    return [_path(ENTRY_METRICS, wildcards.scene, wildcards.spp, entry=entry) for entry in ENTRIES]


def case_entry_viewers(wildcards):
    """The viewer folders of a case's entries, in the order of ENTRIES (the noisy input's has the reference's images)."""
    return [_path(ENTRY_VIEWER, wildcards.scene, wildcards.spp, entry=entry) for entry in ENTRIES]


def feature_params():
    """The render rules' ``features`` param: empty for the default ``first_hit`` convention (the
    params of renders made before the key existed stay the same, so a finished study is not
    rendered again), ``{"features": <convention>}`` otherwise (the params trigger then reruns every
    render, and with it everything downstream, when the convention changes)."""
    return {} if config["features"] == "first_hit" else {"features": config["features"]}


def reference_chunk_spp(wildcards):
    return REFERENCE_SPP[wildcards.scene] // REFERENCE_CHUNKS


def method_inputs(wildcards):
    """Outputs of the methods a combiner takes (empty for a base denoiser)."""
    return [method_output(name, wildcards) for name in METHODS[wildcards.method]["inputs"]]


def weights_file(network):
    return f"{WEIGHTS_DIR}/{network}.pt"


def method_weights(wildcards):
    """Nothing, after checking that a learned method's weights exist (check_weights)."""
    check_weights(wildcards.method)
    return []


def check_weights(name):
    """A learned method's weights must exist before the main job runs it. Missing weights stop the
    DAG with the folder named (a mistyped ``weights_dir`` would otherwise plan hours of training
    renders); `snakemake train_<name>` is the one way to make them."""
    spec = METHODS[name]
    if spec["learned"] and not Path(weights_file(spec["module"])).exists():
        raise BenchError(f"no weights for {spec['module']} in {WEIGHTS_DIR} (weights_dir); train them "
                         f"with `snakemake --cores 2 train_{spec['module']}` or fix weights_dir")
    if spec["learned"]:
        check_trained_features(Path(WEIGHTS_DIR) / f"{spec['module']}.json", config["features"], name=spec["module"])


def weights_digest_of(module):
    """SHA-256 of the weights of method module ``module`` ("" when it has none)."""
    path = Path(weights_file(module))
    return _file_digest(str(path), path.stat().st_mtime_ns) if path.exists() else ""


@functools.lru_cache(maxsize=None)
def _file_digest(path, mtime_ns):
    """SHA-256 of a file (mcbench.io.weights.file_sha256), cached per (path, modification time)
    while the DAG is built."""
    return file_sha256(path)


def missing_weights(network):
    """The weights file of ``network`` if it is missing, else nothing: `train_<name>` trains
    only what is missing (the train rule's provenance triggers never retrain present weights)."""
    path = weights_file(network)
    return [] if Path(path).exists() else [path]


def train_network_inputs(wildcards):
    """Training crops of a network whose weights are missing (a learned combiner: the crops of
    training.combiners and its bases' results on them); none once the weights exist, so an
    explicit `train_<name>` with committed weights has nothing to do."""
    if not missing_weights(wildcards.network):
        return {}
    bases = combiner_bases(wildcards.network)
    if not bases:
        return {"crops": ancient(training_crop_files())}
    return {"crops": ancient(combiner_crop_files()),
            **{f"correlated_{base}": ancient(correlated_files(base)) for base in bases}}


def combiner_bases(network):
    """The base denoisers a learned combiner is trained on (its declared ``correlated_bases``); () for a denoiser."""
    return (method_spec(load_method(network)).correlated_bases or ()) if network in NETWORKS else ()


def combiner_crop_files():
    return [rules.training_example.output[k].format(seed=seed)
            for seed in COMBINER_SEEDS for k in range(COMBINER_TRAINING["crops"])]


def correlated_files(base):
    return [rules.training_correlated.output[k].format(seed=seed, base=base)
            for seed in COMBINER_SEEDS for k in range(COMBINER_TRAINING["crops"])]


def case_outputs(wildcards):
    """The output EXRs of a case's candidates, in the order of CANDIDATES."""
    return [method_output(name, wildcards) for name in CANDIDATES]


def all_timing_records(wildcards=None):
    return expand(METHOD_TIMING, scene=SCENES, spp=SPPS, method=CANDIDATES)


def all_case_metrics(wildcards=None):
    return expand(rules.case_metrics.output[0], scene=SCENES, spp=SPPS)


# Scenes of renders made elsewhere (scenes/<name>.yaml): their cases and references are imported
# from the folder (rules render_noisy, merge_reference), not rendered.
RENDER_FOLDERS = PLAN["render_folders"]


def imported_case_files(wildcards):
    """The folder's files of an imported case (inputs of render_noisy, so that a changed file
    reruns it); nothing for a scene that Mitsuba renders."""
    folder = RENDER_FOLDERS.get(wildcards.scene)
    if folder is None:
        return []
    return folder_case_files(folder, int(wildcards.spp))


def reference_inputs(wildcards):
    """merge_reference's inputs: the reference chunks of a rendered scene, the reference files
    of an imported one."""
    folder = RENDER_FOLDERS.get(wildcards.scene)
    if folder is None:
        return expand(rules.render_reference_chunk.output[0], scene=wildcards.scene, chunk=range(REFERENCE_CHUNKS))
    return folder_reference_files(folder)


def reference_paths():
    return {scene: rules.merge_reference.output[0].format(scene=scene) for scene in SCENES}


def render_cost_records(wildcards=None):
    """The benchmark records of the noisy renders and the reference chunks (the scene table's
    CPU-hours), declared as inputs so that the table waits for them."""
    noisy = expand(rules.render_noisy.benchmark, scene=SCENES, spp=SPPS)
    chunks = expand(rules.render_reference_chunk.benchmark, scene=[s for s in SCENES if s not in RENDER_FOLDERS],
                    chunk=range(REFERENCE_CHUNKS))
    return {"noisy": noisy, "reference": chunks}


# Training data and learned methods (rules in training.smk). Defaults: the schema's.

TRAINING = PLAN["training"]
TRAINING_OVERRIDES = PLAN["training_overrides"]
TRAINING_SEEDS = PLAN["training_seeds"]
# train_<name> rules for the learned methods the config names (no other method module is imported)
NETWORKS = PLAN["networks"]
# The crops of the learned combiners: a subset of the training scenes, checked by the plan when
# the config has a learned combiner (a smaller training set for the denoisers alone stays valid).
COMBINER_TRAINING = PLAN["combiner_training"]
COMBINER_SEEDS = PLAN["combiner_seeds"]


def training_crop_files():
    return expand(rules.training_example.output, seed=TRAINING_SEEDS)


# Cluster resources (mcbench.pipeline.resources): every rule's jobs declare mem_mb and runtime (minutes)
# from the costs fitted to measured benchmark records (workflow/resources/job_costs.yaml, by
# `python benchmarks/job_costs.py`), scaled with the job's pixels, methods and samples; a local
# run ignores them unless --resources limits them. A retry (--retries) asks for `attempt` times
# as much. Rules that render with Mitsuba can use a GPU (variant auto or cuda_ad_rgb) and ask for
# config `gpus` of them (0 by default; profiles/slurm-gpu sets 1); the networks' training and
# inference run on the CPU (mcbench.nn selects no device), so their rules ask for none.

JOB_COSTS = load_job_costs()
GPU_RULES = {"render_noisy", "render_reference_chunk", "training_example", "oracle_study"}
# Rules that only read finished results and write tables, figures or pages, and the target rules,
# say `localrule: True`: on a cluster the submitting Snakemake runs them itself (never queued).


def scene_pixels(scene):
    """Pixels of a scene's images: config resolution, else the scene's own RESOLUTION."""
    width, height = config["resolution"] or load_scene(scene).RESOLUTION
    return int(width) * int(height)


def case_entries(wildcards=None):
    """A case's images: every candidate plus the noisy input."""
    return len(CANDIDATES) + 1


def _job_size(rule_name, wildcards):
    """``(pixels, entries, spp)`` of one job of rule ``rule_name`` (mcbench.pipeline.resources' cost model)."""
    scene = getattr(wildcards, "scene", None)
    pixels = scene_pixels(scene) if scene else 0
    if rule_name == "render_noisy":
        return pixels, 1, int(wildcards.spp)
    if rule_name == "render_reference_chunk":
        return pixels, 1, reference_chunk_spp(wildcards)
    if rule_name in ("case_metrics", "viewer_case"):
        return pixels, case_entries(), 0
    if rule_name == "viewer":
        return max(scene_pixels(s) for s in SCENES), len(SCENES) * len(SPPS) * case_entries(), 0
    return pixels, 1, 0


def job_resources(rule_name, *, batch=1):
    """The ``resources:`` of the rule's jobs: mem_mb and runtime from its fitted cost (a method's
    or a network's own, e.g. run_method/nfor or train_network/kpcn, where measured; the floors
    for a rule without records), times the attempt; ``gpu`` for the rules that can use one.
    ``batch``: a batch job making that many of the rule's files asks for that many times the
    estimated time (its margin and floor applied once)."""

    def request(wildcards, attempt):
        method, network = getattr(wildcards, "method", None), getattr(wildcards, "network", None)
        own = (f"{rule_name}/{METHODS[method]['module']}" if method in METHODS else
               f"{rule_name}/{network}" if network else None)
        cost = JOB_COSTS.get(own) or JOB_COSTS.get(rule_name, JobCost())
        pixels, entries, spp = _job_size(rule_name, wildcards)
        seconds, rss_mb = estimate_job(cost, pixels=pixels, entries=entries, spp=spp)
        request = job_request(seconds * batch, rss_mb)           # the floors once, not once per item
        return {key: value * attempt for key, value in request.items()}

    resources = {"mem_mb": lambda wildcards, attempt: request(wildcards, attempt)["mem_mb"],
                 "runtime": lambda wildcards, attempt: request(wildcards, attempt)["runtime"]}
    if rule_name in GPU_RULES and config["gpus"] and config["variant"] in ("auto", "cuda_ad_rgb"):
        resources["gpu"] = config["gpus"]
        if config["gpu_model"]:
            resources["gpu_model"] = config["gpu_model"]
    return resources


def study_targets(wildcards=None):
    """The study's tables and figures (study.smk) when the config runs the pool (study.pool),
    else nothing: without the pool there is no 39-candidate study to write."""
    if not POOL_STUDY:
        return []
    return [*rules.study_tables.output, *expand(rules.study_figures.output, metric=METRIC_NAMES)]


def oracle_targets(wildcards=None):
    """The oracle study (oracle.smk) of its scene; nothing when every scene of the config is a
    folder of renders made elsewhere (the study renders its scene again)."""
    if PLAN["oracle_scene"] is None:
        return []
    return expand(rules.oracle_study.output, scene=PLAN["oracle_scene"])


def progressive_targets(wildcards=None):
    """Progressive denoising's tables and its consistency curve (progressive.smk) when the config
    has a combiner of module progressive, else nothing."""
    if not PROGRESSIVE:
        return []
    return [*rules.progressive_tables.output, *expand(rules.progressive_curve.output, scene=PROGRESSIVE_SCENE)]


# The method and evaluation jobs (methods.smk, metrics.smk): the per-file rules, then one batch rule
# per group of cases lacking the same files (mcbench.pipeline.jobs.missing_batches). The methods'
# spec files are written here, before Snakemake looks at any mtime, and only when a spec changed.
for _name in METHODS:
    write_if_changed(method_spec_file(_name), spec_text(_method_spec(_name)))

_REFERENCE = f"{RESULTS}/references/{{scene}}.exr"
_RENDER = f"{RESULTS}/renders/{{scene}}/spp{{spp}}.exr"
_ENTRY = {"entry": "|".join(ENTRIES)}
CASE_JOBS = [
    {"rule": "run_method", "outputs": {"exr": METHOD_EXR, "timing": METHOD_TIMING},
     "inputs": {"render": _RENDER, "inputs": method_inputs, "spec": lambda wildcards: [method_spec_file(wildcards.method)],
                "weights": method_weights},
     "constraints": {"method": "|".join(METHODS) or "(?!)"}, "resources": job_resources("run_method"),
     "log": f"{RESULTS}/logs/methods/{{scene}}/spp{{spp}}/{{method}}.log"},
    {"rule": "entry_metrics", "outputs": {"metrics": ENTRY_METRICS},
     "inputs": {"image": lambda wildcards: entry_image(wildcards.entry, wildcards), "reference": _REFERENCE},
     "constraints": _ENTRY, "resources": job_resources("evaluate_entry"),
     "log": f"{RESULTS}/logs/metrics/{{scene}}/spp{{spp}}/{{entry}}.log"},
    {"rule": "entry_viewer", "outputs": {"viewer": directory(ENTRY_VIEWER)},
     "inputs": {"image": lambda wildcards: entry_image(wildcards.entry, wildcards), "reference": _REFERENCE},
     "constraints": _ENTRY, "resources": job_resources("evaluate_entry"),
     "log": f"{RESULTS}/logs/viewer/{{scene}}/spp{{spp}}/{{entry}}.log"},
]
_ITEMS = list(METHODS) + [f"{entry}:{product}" for entry in ENTRIES for product in ("metrics", "viewer")]
# A process started for target jobs (a SLURM job, a spawned run: job) defines the batches it is
# asked for from the main process's records, not from the files it finds (mcbench.pipeline.jobs).
_TARGET_BATCHES = target_batch_names(sys.argv, "case_batch") if not workflow.is_main_process else []
if _TARGET_BATCHES:
    _BATCHES = [read_batch(BATCH_FILE.format(name=n), n, "case_batch") for n in _TARGET_BATCHES]
else:
    _BATCHES = missing_batches(CASES, _ITEMS, _case_item_exists)
    for _batch in _BATCHES:
        write_if_changed(BATCH_FILE.format(name=batch_name("case_batch", _batch)), batch_text(_batch))
for _batch in _BATCHES:
    _name = batch_name("case_batch", _batch)
    _methods = [i for i in _batch["items"] if ":" not in i]
    _evaluations = [i for i in _batch["items"] if ":" in i]
    CASE_JOBS.append({
        "rule": _name, "items": _batch["items"],
        "outputs": {**({"exr": [METHOD_EXR.replace("{method}", n) for n in _methods],
                        "timing": [METHOD_TIMING.replace("{method}", n) for n in _methods]} if _methods else {}),
                    **_eval_outputs(_evaluations)},
        "inputs": {"render": _RENDER, "inputs": _batch_inputs(_batch["items"]), "weights": _check_all_weights(_methods),
                   **({"reference": _REFERENCE} if _evaluations else {})},
        "constraints": _constraints(_batch),
        "resources": job_resources("run_method", batch=len(_methods) + len(_evaluations)),
        "log": f"{RESULTS}/logs/cases/{{scene}}/spp{{spp}}/{_name}.log"})
CASE_JOB_OF = {job["rule"]: job for job in CASE_JOBS}
