# The run's provenance manifest (mcbench.pipeline.provenance): git commit and clean tree, the
# config digest, library versions, CPU and cores, where each reference came from (the store or
# this run), as results/manifest.json and manifest.md.
#
# When it reruns: its inputs are the tables it describes (gathered metrics and timings, the
# ranking and extras tables), so it runs again whenever they are regenerated and is always newer
# than they are; its params hold the config digest, so a changed config rewrites it too. Nothing
# depends on it but the `all` target, the report and the study's summary.md (study_tables): a
# finished study plans nothing, and a new commit alone does not rerun it (the commit it names is
# the one of the run that last wrote the tables).


rule provenance_manifest:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
        timings=rules.gather_timings.output[0],
        rankings=expand(rules.ranking_table.output.csv, metric=list(PLAN.ranking.metrics)),
        extras=expand(rules.extras_table.output.csv, metric=list(PLAN.ranking.metrics)),
        # each reference's header says where it came from (the store, this run, a folder)
        references=expand(rules.merge_reference.output[0], scene=PLAN.cases.scenes),
    output:
        json=report(
            "results/manifest.json",
            caption="../report/provenance.rst",
            category="Data",
            subcategory="Provenance",
            labels={"file": "manifest.json"},
        ),
        md=report(
            "results/manifest.md",
            caption="../report/provenance.rst",
            category="Data",
            subcategory="Provenance",
            labels={"file": "manifest.md"},
        ),
    params:
        # a params entry: a changed config reruns the rule (the script reads the config itself,
        # and the checkout from the script's own folder: a moved checkout reruns nothing)
        config_digest=STUDY.digest,
    threads: 1
    resources:
        **STUDY.resources("provenance_manifest"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/provenance_manifest.log",
    script:
        "../scripts/provenance.py"
