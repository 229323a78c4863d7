# The static image viewer: each entry's images (tone-mapped at each exposure, relMSE and FLIP
# error maps, ensemble weight maps) are written by its evaluation, and linked into a case folder
# by the case's job (rule run_case, methods.smk), so a new case or method redoes only its own
# images; `viewer` copies
# the page (workflow/report/viewer/) and every case folder into results/viewer with data.js,
# the manifest holding each case's numbers from metrics.csv.

# The page's static files (copied as they are; editing one rebuilds only the `viewer` job).
VIEWER_PAGE = [f"{workflow.basedir}/workflow/report/viewer/{name}" for name in ("index.html", "viewer.js", "viewer.css")]


rule viewer:
    input:
        metrics=rules.gather_metrics.output[0],
        cases=expand(rules.run_case.output.viewer, scene=SCENES, spp=SPPS),
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
