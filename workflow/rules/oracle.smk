# Weights from ground-truth statistics (Zheng et al. 2021 Sec. 5.2.7, Fig. 11): one configured
# scene rendered oracle.repetitions + 1 times at oracle.spp (mcbench.pipeline.oracle), its base
# denoisers' true MSE matrices against the harness's reference, the weights solved from them
# next to the dual-buffer estimate's.

ORACLE = config["oracle"]
# the scene: oracle.scene, or the config's first scene that Mitsuba renders when null (the
# default); oracle.downscale, reduced where the harness's resolution is too small for it
# (mcbench.pipeline.oracle.usable_downscale); both checked by the plan
ORACLE_SCENE = PLAN.side.oracle_scene
ORACLE_DOWNSCALE = PLAN.side.oracle_downscale


rule oracle_study:
    input:
        reference=rules.merge_reference.output[0],
    output:
        table=report(
            f"{RESULTS}/oracle/{{scene}}/table.csv",
            caption="../report/oracle_table.rst",
            category="Figures",
            subcategory="Ground-truth statistics (Fig. 11)",
            labels={"scene": "{scene}", "figure": "oracle table"},
        ),
        markdown=f"{RESULTS}/oracle/{{scene}}/table.md",
        weights=report(
            f"{RESULTS}/oracle/{{scene}}/weights.png",
            caption="../report/oracle_weights.rst",
            category="Figures",
            subcategory="Ground-truth statistics (Fig. 11)",
            labels={"scene": "{scene}", "figure": "oracle weight maps"},
        ),
    params:
        denoisers=list(ORACLE["denoisers"]),
        repetitions=ORACLE["repetitions"],
        spp=ORACLE["spp"],
        downscale=ORACLE_DOWNSCALE,
        resolution=config["resolution"],
        variant=config["variant"],
        **feature_params(),
        seed=config["seed"],
        weights_dir=WEIGHTS_DIR,
    threads: 1
    resources:
        **job_resources("oracle_study"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/oracle/{{scene}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/oracle/{{scene}}.tsv"
    script:
        "../scripts/oracle_study.py"
