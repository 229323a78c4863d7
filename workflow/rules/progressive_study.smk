# Progressive denoising (Firmino et al. 2022; methods/progressive.py, mcbench.analysis.progressive_tables,
# mcbench.pipeline.progressive_study): with at least one combiner of module `progressive` in the config,
# its consistency over the test cases (each case's relMSE against the noisy input's, per spp),
# per-spp errors and added time beside each entry's input, and one scene rendered up to
# progressive_curve.spp (8192 by default) with its base, progressive and noisy curves.

# The curve's scene: progressive_curve.scene, or the config's first scene that Mitsuba renders
# when null (cornell_box), and its downscale: in the plan (PLAN.side).


rule progressive_tables:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
        timings=rules.gather_timings.output[0],
    output:
        consistency=report(
            "results/tables/progressive/consistency.md",
            caption="../report/progressive.rst",
            category="Progressive denoising",
            subcategory="Tables",
            labels={"table": "consistency against the noisy input"},
        ),
        consistency_csv="results/tables/progressive/consistency.csv",
        per_spp=report(
            "results/tables/progressive/per_spp.md",
            caption="../report/progressive.rst",
            category="Progressive denoising",
            subcategory="Tables",
            labels={"table": "errors and added time per spp"},
        ),
        per_spp_csv="results/tables/progressive/per_spp.csv",
    params:
        pairs=dict(PLAN.side.progressive),
        labels=dict(PLAN.ranking.labels),
        metrics=[m for m in ("relmse", "smape") if m in list(PLAN.ranking.metrics)] or list(PLAN.ranking.metrics)[:1],
    threads: 1
    resources:
        **STUDY.resources("progressive_tables"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/progressive_tables.log",
    script:
        "../scripts/progressive_tables.py"


rule progressive_curve:
    input:
        reference=rules.merge_reference.output[0],
    output:
        table="results/progressive/{scene}/curve.csv",
        markdown=report(
            "results/progressive/{scene}/curve.md",
            caption="../report/progressive_curve.rst",
            category="Progressive denoising",
            subcategory="Consistency up to high spp",
            labels={"scene": "{scene}", "figure": "table"},
        ),
        figure=report(
            "results/progressive/{scene}/curve.png",
            caption="../report/progressive_curve.rst",
            category="Progressive denoising",
            subcategory="Consistency up to high spp",
            labels={"scene": "{scene}", "figure": "error against spp"},
        ),
    params:
        spp=list(config["progressive_curve"]["spp"]),
        base=config["progressive_curve"]["base"],
        divergence=config["progressive_curve"]["divergence"],
        downscale=PLAN.side.progressive_downscale,
        resolution=config["resolution"],
        variant=config["variant"],
        **STUDY.feature_params,
        seed=config["seed"],
        weights_dir=STUDY.weights_dir,
    threads: 1
    resources:
        **STUDY.resources("progressive_curve"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/progressive/{scene}.log",
    benchmark:
        "results/benchmarks/progressive/{scene}.tsv"
    script:
        "../scripts/progressive_curve.py"
