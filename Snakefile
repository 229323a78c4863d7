# Benchmark of Monte Carlo denoisers and their combinations, reproducing
# Zheng et al. 2021, "Ensemble Denoising for Monte Carlo Renderings".
#
#   snakemake --cores 2                       # the default study (config.yaml)
#   snakemake --cores 2 --configfile workflow/configs/smoke.yaml
#   snakemake --report results/report.zip      # the report (add the run's --configfile)
#
# A --configfile is the whole configuration: config.yaml is read only when none is given, and
# what a config leaves out comes from the schema's defaults (mcbench.pipeline.config), so the same command
# gives the same study from any folder.

from snakemake.utils import min_version

min_version("9.0")


report: "workflow/report/workflow.rst"


if not workflow.overwrite_configfiles:

    configfile: f"{workflow.basedir}/config.yaml"


include: "workflow/rules/common.smk"
include: "workflow/rules/render.smk"
include: "workflow/rules/methods.smk"
include: "workflow/rules/metrics.smk"
include: "workflow/rules/rankings.smk"
include: "workflow/rules/provenance.smk"
include: "workflow/rules/training.smk"
include: "workflow/rules/viewer.smk"
include: "workflow/rules/figures.smk"
include: "workflow/rules/comparisons.smk"
include: "workflow/rules/oracle.smk"
include: "workflow/rules/study.smk"
include: "workflow/rules/progressive_study.smk"
include: "workflow/rules/export.smk"


rule all:
    localrule: True
    input:
        rules.gather_metrics.output,
        rules.gather_timings.output,
        rules.provenance_manifest.output,
        expand(rules.ranking_table.output, metric=config["metrics"]),
        expand(rules.extras_table.output, metric=config["metrics"]),
        rules.scene_table.output,
        rules.gallery.output,
        expand(rules.error_curves.output, metric=config["metrics"]),
        rules.speed_error.output,
        rules.viewer.output,
        expand(rules.comparison_onehot.output, metric=config["metrics"]),
        rules.comparison_ablations.output,
        expand(rules.comparison_ranking.output, metric=config["metrics"]),
        get_oracle_targets(),
        get_study_targets(),
        get_progressive_targets(),
    default_target: True


# after `all`: rule export_study takes the outputs of `all` as its input
include: "workflow/rules/bundle.smk"
