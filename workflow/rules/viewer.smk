# The static image viewer: each entry's images (tone-mapped at each exposure, relMSE and FLIP
# error maps, ensemble weight maps) are written by its evaluation (metrics.smk); one job
# per test case links them into a case folder, so a new case or method redoes only its own
# images; `viewer` copies
# the page (workflow/report/viewer/) and every case folder into results/viewer with data.js,
# the manifest holding each case's numbers from metrics.csv.

# The page's static files (copied as they are; editing one rebuilds only the `viewer` job).
VIEWER_PAGE = [f"{workflow.basedir}/workflow/report/viewer/{name}" for name in ("index.html", "viewer.js", "viewer.css")]


rule viewer_case:
    input:
        case_entry_viewers,
    output:
        directory(f"{RESULTS}/viewer_cases/{{scene}}/spp{{spp}}"),
    params:
        entries=ENTRIES,
    # a case's assembly runs as soon as its case is done (before the next case's batch), so
    # that finished cases' assemblies do not pile up among the jobs the scheduler weighs
    priority: 10
    threads: 1
    resources:
        **job_resources("viewer_case"),
    log:
        f"{RESULTS}/logs/viewer/{{scene}}_spp{{spp}}.log",
    run:
        run_case_assembly("mcbench.pipeline.viewer:assemble_viewer_case", input, output, params, wildcards, log)


rule viewer:
    input:
        metrics=rules.gather_metrics.output[0],
        cases=expand(rules.viewer_case.output[0], scene=SCENES, spp=SPPS),
        page=VIEWER_PAGE,
    output:
        report(
            directory(f"{RESULTS}/viewer"),
            htmlindex="index.html",
            category="Images",
            subcategory="Image viewer",
            labels={"figure": "image viewer", "scene": "all"},
            caption="../report/viewer.rst",
        ),
    params:
        cases=[{"scene": scene, "spp": spp} for scene in SCENES for spp in SPPS],  # the order of input.cases
        candidates=CANDIDATES,
        labels=LABELS,
        metrics=METRIC_NAMES,
        static_dir=lambda wildcards, input: str(Path(input.page[0]).parent),
    threads: 1
    resources:
        **job_resources("viewer"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/viewer.log",
    benchmark:
        f"{RESULTS}/benchmarks/viewer.tsv"
    script:
        "../scripts/viewer.py"
