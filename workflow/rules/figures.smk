# Figures of the report (mcbench.analysis.error_speed_figures): error against spp per scene for each metric, and
# each method's speed against its error.

# the speed-against-error figure's metric: relMSE (the paper's), or the first metric configured
SPEED_METRIC = "relmse" if "relmse" in METRIC_NAMES else METRIC_NAMES[0]
# the error curves' lines: with the pool, its bases and the paper's recommended ensembles (40
# lines would hide each other; the study's figures draw the ensembles the data recommends),
# otherwise every ranked candidate
CURVES = ([name for name in curve_candidates(paper_recommended()) if name in RANKED] if POOL_STUDY else RANKED)


rule error_curves:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
    output:
        report(
            f"{RESULTS}/figures/error_{{metric}}.png",
            caption="../report/error_curves.rst",
            category="Figures",
            subcategory="Error against spp",
            labels={"metric": "{metric}", "figure": "error against spp, per scene"},
        ),
    params:
        labels=LABELS,
        entries=[NOISY] + CURVES,
    threads: 1
    resources:
        **job_resources("error_curves"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/figures/error_{{metric}}.log",
    script:
        "../scripts/figures.py"


rule speed_error:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
        timings=rules.gather_timings.output[0],
    output:
        report(
            f"{RESULTS}/figures/speed_error.png",
            caption="../report/speed_error.rst",
            category="Figures",
            subcategory="Speed against error",
            labels={"metric": SPEED_METRIC, "figure": "speed against error"},
        ),
    params:
        labels=LABELS,
        inputs={name: list(spec.inputs) for name, spec in METHODS.items()},
        metric=SPEED_METRIC,
    threads: 1
    resources:
        **job_resources("speed_error"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/figures/speed_error.log",
    script:
        "../scripts/figures.py"
