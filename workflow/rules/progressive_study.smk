# Progressive denoising (Firmino et al. 2022; methods/progressive.py, mcbench.analysis.progressive_tables,
# mcbench.pipeline.progressive_study): with at least one combiner of module `progressive` in the config,
# its consistency over the test cases (each case's relMSE against the noisy input's, per spp),
# per-spp errors and added time beside each entry's input, and one scene rendered up to
# progressive_curve.spp (8192 by default) with its base, progressive and noisy curves.

PROGRESSIVE_DIR = f"{RESULTS}/tables/progressive"
PROGRESSIVE_CURVE = config["progressive_curve"]
# the curve's scene: progressive_curve.scene, or the config's first scene that Mitsuba renders
# when null (cornell_box), and its downscale: checked by the plan
PROGRESSIVE_SCENE = PLAN.side.progressive_scene
PROGRESSIVE_DOWNSCALE = PLAN.side.progressive_downscale


rule progressive_tables:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
        timings=rules.gather_timings.output[0],
    output:
        consistency=report(
            f"{PROGRESSIVE_DIR}/consistency.md",
            caption="../report/progressive.rst",
            category="Progressive denoising",
            subcategory="Tables",
            labels={"table": "consistency against the noisy input"},
        ),
        consistency_csv=f"{PROGRESSIVE_DIR}/consistency.csv",
        per_spp=report(
            f"{PROGRESSIVE_DIR}/per_spp.md",
            caption="../report/progressive.rst",
            category="Progressive denoising",
            subcategory="Tables",
            labels={"table": "errors and added time per spp"},
        ),
        per_spp_csv=f"{PROGRESSIVE_DIR}/per_spp.csv",
    params:
        pairs=PROGRESSIVE,
        labels=LABELS,
        metrics=[m for m in ("relmse", "smape") if m in METRIC_NAMES] or METRIC_NAMES[:1],
    threads: 1
    resources:
        **job_resources("progressive_tables"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/progressive_tables.log",
    script:
        "../scripts/progressive_study.py"


rule progressive_curve:
    input:
        reference=rules.merge_reference.output[0],
    output:
        table=f"{RESULTS}/progressive/{{scene}}/curve.csv",
        markdown=report(
            f"{RESULTS}/progressive/{{scene}}/curve.md",
            caption="../report/progressive_curve.rst",
            category="Progressive denoising",
            subcategory="Consistency up to high spp",
            labels={"scene": "{scene}", "figure": "table"},
        ),
        figure=report(
            f"{RESULTS}/progressive/{{scene}}/curve.png",
            caption="../report/progressive_curve.rst",
            category="Progressive denoising",
            subcategory="Consistency up to high spp",
            labels={"scene": "{scene}", "figure": "error against spp"},
        ),
    params:
        spp=list(PROGRESSIVE_CURVE["spp"]),
        base=PROGRESSIVE_CURVE["base"],
        divergence=PROGRESSIVE_CURVE["divergence"],
        downscale=PROGRESSIVE_DOWNSCALE,
        resolution=config["resolution"],
        variant=config["variant"],
        **feature_params(),
        seed=config["seed"],
        weights_dir=WEIGHTS_DIR,
    threads: 1
    resources:
        **job_resources("progressive_curve"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/progressive/{{scene}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/progressive/{{scene}}.tsv"
    script:
        "../scripts/progressive_study.py"
