# Helpers shared by the rules: the resolved config, the method table, input functions.
# Path patterns live in the rules' own output declarations (rules.X.output); the helpers here
# expand those.

import copy
import functools
import os
import sys

from snakemake.logging import logger
from pathlib import Path

sys.path.insert(0, str(Path(workflow.basedir)))  # methods/, scenes/, mcbench/ from a checkout

from mcbench import NOISY, BenchError  # noqa: E402
from mcbench.pipeline.config import config_digest, resolve_config  # noqa: E402
from mcbench.pipeline.plan import plan_study  # noqa: E402
from mcbench.pipeline.rendering import folder_case_files, folder_reference_files  # noqa: E402
from mcbench.analysis.metrics import ALL_METRICS  # noqa: E402
from mcbench.analysis.study.study_figures import STUDY_FIGURES as STUDY_FIGURE_KEYS, curve_candidates, paper_recommended  # noqa: E402
from mcbench.pipeline.resources import StudyRequests, load_job_costs  # noqa: E402
from mcbench.io.method_spec import method_spec  # noqa: E402
from mcbench.io.weights import COMMITTED_WEIGHTS, check_trained_features, file_sha256, is_learned_method  # noqa: E402
from mcbench.pipeline.registry import load_method, load_scene  # noqa: E402


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
# The names the rules read, as plain lists and dicts (what Snakemake records in params).
METHODS = PLAN.methods   # name -> mcbench.pipeline.study_plan.MethodPlan, in dependency order
SCENES = list(PLAN.cases.scenes)
SPPS = list(PLAN.cases.spps)
CANDIDATES = list(PLAN.ranking.candidates)
# The ranking pool. With study.pool: exactly the 39 candidates of Zheng et al. Sec. 5.3.1 the
# config runs (mcbench.analysis.pool), in ID order; otherwise every candidate but the comparison methods
# of Sec. 5.2 (one-hot selection, naive averages, ablations; ranked in comparisons.smk). Every
# other method is an extra, scored in a pool that adds it alone (rule extras_table).
POOL_STUDY = PLAN.ranking.pool_study
RANKED = list(PLAN.ranking.ranked)
EXTRAS = list(PLAN.ranking.extras)
POOL_NOTE = PLAN.ranking.pool_note
# progressive denoising's entries (combiners of module progressive) -> the method each mixes with
# the noisy render (progressive.smk)
PROGRESSIVE = dict(PLAN.side.progressive)
LABELS = dict(PLAN.ranking.labels)
METRIC_NAMES = list(PLAN.ranking.metrics)
REFERENCE_CHUNKS = PLAN.cases.reference_chunks
# reference spp per configured scene: reference.scene_spp[scene] or reference.spp
REFERENCE_SPP = dict(PLAN.cases.reference_spp)


wildcard_constraints:
    scene="[A-Za-z][A-Za-z0-9_]*",
    method="[A-Za-z][A-Za-z0-9_]*",
    spp=r"\d+",
    chunk=r"\d+",
    seed=r"\d+",
    metric="|".join(ALL_METRICS),


# The case jobs (run_case) run in warm worker processes (mcbench.pipeline.worker_pool): their
# rule's `run:` block calls run_in_pool in Snakemake's own process, which needs Snakemake's
# threads for `run:` jobs (force-use-threads, set by the workflow profile profiles/default;
# without it each such job would start a whole Snakemake process: the same results, far slower).


def run_in_pool(step, *args, log, **kwargs):
    """Run ``step`` ("module:function") of a ``run:`` rule in a warm worker (mcbench.pipeline.worker_pool),
    with as many workers as the cores Snakemake was given, the job's weights folder and this
    checkout on the workers' paths."""
    from mcbench.pipeline.worker_pool import run_step

    run_step(step, *args, log_path=log, workers=max(1, int(workflow.cores or 1)),
             environment={"MCBENCH_WEIGHTS_DIR": str(Path(WEIGHTS_DIR).resolve())},
             paths=[str(Path(workflow.basedir))], **kwargs)


# A case's files (mcbench.pipeline.cases, paths: mcbench.pipeline.study_plan.StudyPaths): each
# method's output and timing record, each entry's metric values and viewer images. They are made
# by the case's one job (rule run_case), which keeps what its records say is up to date and makes
# the rest; they are not Snakemake outputs.
#: A case's entries: the noisy input and every candidate.
ENTRIES = PLAN.ranking.entries


def method_output(name, wildcards):
    """The output EXR of method ``name`` in the case of ``wildcards``."""
    return PLAN.paths.method_output(wildcards.scene, wildcards.spp, name)


def case_plan(wildcards=None):
    """Rule run_case's params (mcbench.pipeline.study_plan.StudyPlan.case_plan): the same for
    every case; new weights rerun every case, whose job reruns the methods they belong to.
    Checks that every learned method has its weights."""
    return _case_plan()


@functools.lru_cache(maxsize=None)
def _case_plan():
    for name, spec in METHODS.items():
        if spec.learned:
            check_weights(name)
    return PLAN.case_plan({module: weights_digest_of(module) for module in PLAN.learned_modules()})


def case_job(wildcards, output):
    """What run_case's job makes in one case (mcbench.pipeline.study_plan.StudyPlan.case_job)."""
    return PLAN.case_job(wildcards.scene, int(wildcards.spp), weights_dir=WEIGHTS_DIR,
                         outputs={"metrics": output.metrics, "viewer": output.viewer, "record": output.record})


def feature_params():
    """The render rules' ``features`` param: empty for the default ``first_hit`` convention (the
    params of renders made before the key existed stay the same, so a finished study is not
    rendered again), ``{"features": <convention>}`` otherwise (the params trigger then reruns every
    render, and with it everything downstream, when the convention changes)."""
    return {} if config["features"] == "first_hit" else {"features": config["features"]}


def reference_chunk_spp(wildcards):
    return REFERENCE_SPP[wildcards.scene] // REFERENCE_CHUNKS


def weights_file(network):
    return f"{WEIGHTS_DIR}/{network}.pt"


def check_weights(name):
    """A learned method's weights must exist before the main job runs it. Missing weights stop the
    DAG with the folder named (a mistyped ``weights_dir`` would otherwise plan hours of training
    renders); `snakemake train_<name>` is the one way to make them."""
    spec = METHODS[name]
    if spec.learned and not Path(weights_file(spec.module)).exists():
        raise BenchError(f"no weights for {spec.module} in {WEIGHTS_DIR} (weights_dir); train them "
                         f"with `snakemake --cores 2 train_{spec.module}` or fix weights_dir")
    if spec.learned:
        check_trained_features(Path(WEIGHTS_DIR) / f"{spec.module}.json", config["features"], name=spec.module)


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


def all_case_records(wildcards=None):
    return expand(rules.run_case.output.record, scene=SCENES, spp=SPPS)


def all_case_metrics(wildcards=None):
    return expand(rules.run_case.output.metrics, scene=SCENES, spp=SPPS)


# Scenes of renders made elsewhere (scenes/<name>.yaml): their cases and references are imported
# from the folder (rules render_noisy, merge_reference), not rendered.
RENDER_FOLDERS = dict(PLAN.cases.render_folders)


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

TRAINING = dict(PLAN.training.settings)
TRAINING_OVERRIDES = dict(PLAN.training.overrides)
TRAINING_SEEDS = list(PLAN.training.seeds)
# train_<name> rules for the learned methods the config names (no other method module is imported)
NETWORKS = list(PLAN.training.networks)
# The crops of the learned combiners: a subset of the training scenes, checked by the plan when
# the config has a learned combiner (a smaller training set for the denoisers alone stays valid).
COMBINER_TRAINING = dict(PLAN.training.combiner_settings)
COMBINER_SEEDS = list(PLAN.training.combiner_seeds)


def training_crop_files():
    return expand(rules.training_example.output, seed=TRAINING_SEEDS)


# Cluster resources (mcbench.pipeline.resources): every rule's jobs declare mem_mb and runtime (minutes)
# from the costs fitted to measured benchmark records (workflow/resources/job_costs.yaml, by
# `python benchmarks/job_costs.py`), scaled with the job's pixels, methods and samples; a local
# run ignores them unless --resources limits them. A retry (--retries) asks for `attempt` times
# as much. Rules that render with Mitsuba can use a GPU (variant auto or cuda_ad_rgb) and ask for
# config `gpus` of them (0 by default; profiles/slurm-gpu sets 1); the networks' training and
# inference run on the CPU (mcbench.nn selects no device), so their rules ask for none.

REQUESTS = StudyRequests(PLAN, load_job_costs(), gpus=config["gpus"], gpu_model=config["gpu_model"] or "",
                         variant=config["variant"])
# Rules that only read finished results and write tables, figures or pages, and the target rules,
# say `localrule: True`: on a cluster the submitting Snakemake runs them itself (never queued).


def job_resources(rule_name):
    """The ``resources:`` of a rule's jobs (mcbench.pipeline.resources.StudyRequests.request)."""

    def request(wildcards, attempt):
        return REQUESTS.request(rule_name, scene=getattr(wildcards, "scene", None), spp=getattr(wildcards, "spp", None),
                                network=getattr(wildcards, "network", None), attempt=attempt)

    return {"mem_mb": lambda wildcards, attempt: request(wildcards, attempt)["mem_mb"],
            "runtime": lambda wildcards, attempt: request(wildcards, attempt)["runtime"],
            **REQUESTS.gpu_resources(rule_name)}


def case_resources():
    """The ``resources:`` of a case's job (mcbench.pipeline.resources.StudyRequests.case_request)."""
    return {"mem_mb": lambda wildcards, attempt: REQUESTS.case_request(wildcards.scene, attempt=attempt)["mem_mb"],
            "runtime": lambda wildcards, attempt: REQUESTS.case_request(wildcards.scene, attempt=attempt)["runtime"]}


def study_targets(wildcards=None):
    """The study's tables and figures (study.smk) when the config runs the pool (study.pool),
    else nothing: without the pool there is no 39-candidate study to write."""
    if not POOL_STUDY:
        return []
    return [*rules.study_tables.output, *expand(rules.study_figures.output, metric=METRIC_NAMES)]


def oracle_targets(wildcards=None):
    """The oracle study (oracle.smk) of its scene; nothing when every scene of the config is a
    folder of renders made elsewhere (the study renders its scene again)."""
    if PLAN.side.oracle_scene is None:
        return []
    return expand(rules.oracle_study.output, scene=PLAN.side.oracle_scene)


def progressive_targets(wildcards=None):
    """Progressive denoising's tables and its consistency curve (progressive.smk) when the config
    has a combiner of module progressive, else nothing."""
    if not PROGRESSIVE:
        return []
    return [*rules.progressive_tables.output, *expand(rules.progressive_curve.output, scene=PROGRESSIVE_SCENE)]
