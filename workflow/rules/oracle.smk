# Weights from ground-truth statistics (Zheng et al. 2021 Sec. 5.2.7, Fig. 11): one configured
# scene rendered oracle.repetitions + 1 times at oracle.spp (mcbench.pipeline.oracle), its base
# denoisers' true MSE matrices against the harness's reference, the weights solved from them
# next to the dual-buffer estimate's.

# The scene: oracle.scene, or the config's first scene that Mitsuba renders when null (the
# default); oracle.downscale, reduced where the harness's resolution is too small for it
# (mcbench.pipeline.oracle.usable_downscale); both in the plan (PLAN.side).


rule oracle_study:
    input:
        reference=rules.merge_reference.output[0],
    output:
        table=report(
            "results/oracle/{scene}/table.csv",
            caption="../report/oracle_table.rst",
            category="Figures",
            subcategory="Ground-truth statistics (Fig. 11)",
            labels={"scene": "{scene}", "figure": "oracle table"},
        ),
        markdown="results/oracle/{scene}/table.md",
        weights=report(
            "results/oracle/{scene}/weights.png",
            caption="../report/oracle_weights.rst",
            category="Figures",
            subcategory="Ground-truth statistics (Fig. 11)",
            labels={"scene": "{scene}", "figure": "oracle weight maps"},
        ),
    params:
        denoisers=list(config["oracle"]["denoisers"]),
        repetitions=config["oracle"]["repetitions"],
        spp=config["oracle"]["spp"],
        downscale=PLAN.side.oracle_downscale,
        resolution=config["resolution"],
        variant=config["variant"],
        **STUDY.feature_params,
        seed=config["seed"],
        weights_dir=STUDY.weights_dir,
    threads: 1
    resources:
        **STUDY.resources("oracle_study"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/oracle/{scene}.log",
    benchmark:
        "results/benchmarks/oracle/{scene}.tsv"
    script:
        "../scripts/oracle_study.py"
