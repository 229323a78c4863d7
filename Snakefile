# Benchmark of Monte Carlo denoisers and their combinations, reproducing
# Zheng et al. 2021, "Ensemble Denoising for Monte Carlo Renderings".
#
#   snakemake --cores 2                       # default config.yaml
#   snakemake --cores 2 --configfile workflow/configs/smoke.yaml

from snakemake.utils import min_version

min_version("9.0")


configfile: "config.yaml"


include: "workflow/rules/common.smk"
include: "workflow/rules/render.smk"
include: "workflow/rules/methods.smk"
include: "workflow/rules/metrics.smk"
include: "workflow/rules/report.smk"
include: "workflow/rules/training.smk"


rule all:
    input:
        expand(f"{RESULTS}/tables/ranking_{{metric}}.{{ext}}", metric=config["metrics"], ext=["csv", "md"]),
        f"{RESULTS}/metrics.csv",
        f"{RESULTS}/timings.csv",
        f"{RESULTS}/tables/scenes.md",
        f"{RESULTS}/figures/gallery.png",
    default_target: True
