# The static image viewer: each entry's images (tone-mapped at each exposure, relMSE and FLIP
# error maps, ensemble weight maps) are written by its evaluation, and linked into a case folder
# by the case's job (rule run_case, methods.smk), so a new case or method redoes only its own
# images; `viewer` copies
# the page (workflow/report/viewer/) and every case folder into results/viewer with data.js,
# the manifest holding each case's numbers from metrics.csv.


rule viewer:
    input:
        metrics=rules.gather_metrics.output[0],
        cases=expand(rules.run_case.output.viewer, scene=PLAN.cases.scenes, spp=PLAN.cases.spps),
        # the page's static files (copied as they are; editing one reruns only this job)
        page=multiext(f"{workflow.basedir}/workflow/report/viewer/", "index.html", "viewer.js", "viewer.css"),
    output:
        report(
            directory("results/viewer"),
            htmlindex="index.html",
            category="Images",
            subcategory="Image viewer",
            labels={"figure": "image viewer", "scene": "all"},
            caption="../report/viewer.rst",
        ),
    params:
        cases=PLAN.cases.case_list,  # the order of input.cases
        candidates=list(PLAN.ranking.candidates),
        labels=dict(PLAN.ranking.labels),
        metrics=list(PLAN.ranking.metrics),
        static_dir=lambda wildcards, input: str(Path(input.page[0]).parent),
    threads: 1
    resources:
        **STUDY.resources("viewer"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/viewer.log",
    benchmark:
        "results/benchmarks/viewer.tsv"
    script:
        "../scripts/viewer.py"
