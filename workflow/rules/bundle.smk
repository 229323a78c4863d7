# The finished study as one checked archive (mcbench.pipeline.bundle, docs/bundle.md):
# `snakemake --cores 1 export_study` (not part of `all`) writes results/bundle/study.tar.gz, holding
# every file of results/ but the logs, the report and earlier bundles, with the resolved config,
# the provenance and Snakemake's metadata records. Its inputs are the outputs of rule `all`, so
# that a bundle is of a finished study. In a clone elsewhere, in the checkout's root:
# `python -m mcbench.pipeline.bundle import results/bundle/study.tar.gz [--configfile CONFIG]`.


rule export_study:
    localrule: True
    input:
        rules.all.input,
    output:
        "results/bundle/study.tar.gz",
    params:
        config_digest=STUDY.digest,
    threads: 1
    resources:
        **STUDY.resources("export_study"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/export_study.log",
    script:
        "../scripts/export_study.py"
