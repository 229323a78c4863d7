# What the rules share: the validated config, the study's plan (STUDY.plan, as PLAN) and the
# get_* input functions. The logic lives in mcbench.pipeline.study_setup; the rules read the
# typed plan (mcbench.pipeline.study_plan.StudyPlan) directly.

import os  # noqa: F401 (the train rule's params)
import sys

from snakemake.logging import logger
from pathlib import Path

sys.path.insert(0, str(Path(workflow.basedir)))  # methods/, scenes/, mcbench/ from a checkout

from mcbench.pipeline.study_setup import METRIC_PATTERN, STUDY_FIGURES, setup_study  # noqa: E402


# The whole configuration: the config file (config.yaml or the --configfile) plus the schema's
# defaults, validated, and its plan with every check that stops a config before any job. Errors
# name the file and the key.
STUDY = setup_study(config, source=", ".join(str(f) for f in workflow.configfiles) or "config")
config.clear()
config.update(STUDY.config)
logger.info(STUDY.summary)
PLAN = STUDY.plan


wildcard_constraints:
    scene="[A-Za-z][A-Za-z0-9_]*",
    method="[A-Za-z][A-Za-z0-9_]*",
    spp=r"\d+",
    chunk=r"\d+",
    seed=r"\d+",
    metric=METRIC_PATTERN,


# The case jobs (run_case) run in warm worker processes (mcbench.pipeline.worker_pool): their
# rule's `run:` block calls run_in_pool in Snakemake's own process, which needs Snakemake's
# threads for `run:` jobs (force-use-threads, set by the workflow profile profiles/default;
# without it each such job would start a whole Snakemake process: the same results, far slower).


def run_in_pool(step, *args, log, **kwargs):
    """Run ``step`` ("module:function") of a ``run:`` rule in a warm worker (mcbench.pipeline.worker_pool),
    with as many workers as the cores Snakemake was given and this checkout on the workers' paths
    (a learned method's weights file travels in the job's description, case_job)."""
    from mcbench.pipeline.worker_pool import run_step

    run_step(step, *args, log_path=log, workers=max(1, int(workflow.cores or 1)),
             paths=[str(Path(workflow.basedir))], **kwargs)


# Input functions: each unpacks the wildcards and the rules' path patterns for STUDY.


def get_case_plan(wildcards):
    """Rule run_case's params, the same for every case (learned methods' weights checked)."""
    return STUDY.case_plan


def case_job(wildcards, output):
    """What run_case's job makes in one case (its `run:` block's argument)."""
    return STUDY.case_job(wildcards.scene, wildcards.spp,
                          {"metrics": output.metrics, "viewer": output.viewer, "record": output.record})


def get_case_outputs(wildcards):
    """The output EXRs of a case's candidates, in plan order."""
    return [PLAN.paths.method_output(wildcards.scene, wildcards.spp, name) for name in PLAN.ranking.candidates]


def get_case_job(wildcards):
    """A case's job description (rule run_case's), for rules that read the outputs it may remove."""
    outputs = {key: getattr(rules.run_case.output, key).format(**wildcards) for key in ("metrics", "viewer", "record")}
    return STUDY.case_job(wildcards.scene, wildcards.spp, outputs)


def get_case_files(key):
    """Output ``key`` of rule run_case in every case."""
    return expand(getattr(rules.run_case.output, key), scene=PLAN.cases.scenes, spp=PLAN.cases.spps)


def get_imported_case_files(wildcards):
    return STUDY.imported_case_files(wildcards.scene, wildcards.spp)


def get_reference_inputs(wildcards):
    return STUDY.reference_inputs(wildcards.scene, rules.render_reference_chunk.output[0])


def get_checked_render(wildcards):
    return STUDY.checked_render(wildcards.scene, rules.render_noisy.output[0])


def get_reference_check(wildcards):
    return STUDY.reference_checks(wildcards.scene, rules.check_reference.output[0])


def get_store_inputs(wildcards):
    return STUDY.store_inputs(wildcards.scene, rules.render_reference_chunk.output[0], rules.merge_reference.output[0])


def get_store_records(wildcards):
    return STUDY.store_records(rules.store_reference.output[0])


def get_references():
    """Scene -> its merged reference."""
    return {scene: rules.merge_reference.output[0].format(scene=scene) for scene in PLAN.cases.scenes}


def get_render_cost_records(wildcards):
    return STUDY.render_cost_records(rules.render_noisy.benchmark, rules.render_reference_chunk.benchmark)


def get_training_crops():
    return STUDY.training_crops(list(rules.training_example.output))


def get_train_inputs(wildcards):
    """Training inputs of a network whose weights are missing (none once they exist). Not
    ancient(): Snakemake 9 then skips a combiner whose bases' results a retrained base remakes."""
    return STUDY.train_inputs(wildcards.network, list(rules.training_example.output),
                              list(rules.training_correlated.output))


def get_study_targets():
    """The 39-candidate study's tables and figures when the config runs the pool, else nothing."""
    if not PLAN.ranking.pool_study:
        return []
    return [*rules.study_tables.output, *expand(rules.study_figures.output, metric=PLAN.ranking.metrics)]


def get_oracle_targets():
    """The oracle study of its scene; nothing when no scene of the config is rendered here."""
    if PLAN.side.oracle_scene is None:
        return []
    return expand(rules.oracle_study.output, scene=PLAN.side.oracle_scene)


def get_progressive_targets():
    """Progressive denoising's tables and curve when the config has a progressive combiner."""
    if not PLAN.side.progressive:
        return []
    return [*rules.progressive_tables.output, *expand(rules.progressive_curve.output, scene=PLAN.side.progressive_scene)]
