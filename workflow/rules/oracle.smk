# Weights from ground-truth statistics (Zheng et al. 2021 Sec. 5.2.7, Fig. 11): one configured
# scene rendered oracle.repetitions + 1 times at oracle.spp (mcbench.steps_oracle), its base
# denoisers' true MSE matrices against the harness's reference, the weights solved from them
# next to the dual-buffer estimate's.

ORACLE = config["oracle"]
if ORACLE["scene"] not in SCENES:
    raise BenchError(f"oracle.scene: '{ORACLE['scene']}' is not one of the config's scenes "
                     f"({', '.join(SCENES)}); its reference is rendered only for those")


def oracle_reference(wildcards):
    """The harness's reference of the oracle scene (a configured scene: it has one)."""
    if wildcards.scene not in SCENES:
        raise BenchError(f"oracle.scene: '{wildcards.scene}' is not one of the config's scenes "
                         f"({', '.join(SCENES)})")
    return rules.merge_reference.output[0].format(scene=wildcards.scene)


rule oracle_study:
    input:
        reference=oracle_reference,
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
        downscale=ORACLE["downscale"],
        resolution=config["resolution"],
        variant=config["variant"],
        seed=config["seed"],
        weights_dir=WEIGHTS_DIR,
    threads: 1
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/oracle/{{scene}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/oracle/{{scene}}.tsv"
    script:
        "../scripts/oracle_study.py"
