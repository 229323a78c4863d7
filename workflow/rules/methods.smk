# Base denoisers and combiners, and each entry's evaluation: per-file results, so that Snakemake
# decides method by method what an edit of the config makes out of date (a new method runs alone;
# changed params rerun the method and the combiners that read it; a new metric list is new
# metrics files). A base denoiser returns its full and half-buffer results in one run; a combiner
# also reads its input methods' outputs; a learned method also reads its weights. Each entry of
# a case (the noisy input, every candidate) is evaluated into its errors
# (metrics/<scene>/spp<N>/<metric set>/<entry>.csv) and its viewer images
# (viewer_entries/<scene>/spp<N>/<entry>/).
#
# Who makes a file (common.smk CASE_JOBS, mcbench.pipeline.jobs): an existing file, its per-file
# rule (run_method, entry_metrics, entry_viewer), rerun when Snakemake finds it out of date (a
# method's spec file, render or input outputs newer); the files a case lacks, one batch job per
# case (case_batch_<key>): from scratch, every method of the case in dependency order, then every
# evaluation. All are this one rule definition (same code, no params) and run in warm worker
# processes that import once (mcbench.pipeline.pool). `snakemake -f <output EXR>` reruns one method.


for job in CASE_JOBS:

    rule:
        name:
            job["rule"]
        input:
            **job["inputs"],
        output:
            **job["outputs"],
        wildcard_constraints:
            **job["constraints"],
        threads: 1
        resources:
            **job["resources"],
        log:
            job["log"],
        run:
            run_in_pool("mcbench.pipeline.methods:run_case_items", *case_items(rule, wildcards), log=log[0],
                        scene=wildcards.scene, spp=int(wildcards.spp), threads=threads, metrics=METRIC_NAMES)

    if "items" in job:  # a missing file: its case's batch, not the per-file rules
        for single in ("run_method", "entry_metrics", "entry_viewer"):
            workflow.ruleorder(job["rule"], single)
