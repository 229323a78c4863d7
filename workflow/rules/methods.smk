# Base denoisers and combiners: one output file (and timing record) per (scene, spp, method), so
# that Snakemake decides method by method what an edit of the config makes out of date (a new
# method runs alone; changed params rerun the method and the combiners that read it). A base
# denoiser returns its full and half-buffer results in one run; a combiner also reads its input
# methods' outputs; a learned method also reads its weights.
#
# Who makes a file (common.smk, mcbench.pipeline.jobs): an existing file, rule run_method (one job
# per method and case, rerun when Snakemake finds it out of date: its spec file, render or input
# outputs newer); the files that do not exist yet, one batch job per case (run_methods_<key>):
# from scratch every method of the case in one job, in dependency order. Both are this one rule
# definition (same code, no params), and both run in warm worker processes that import once
# (mcbench.pipeline.pool). `snakemake -f <output EXR>` reruns one method.


for job in METHOD_JOBS:

    rule:
        name:
            job["rule"]
        input:
            render=rules.render_noisy.output[0],
            inputs=job["inputs"],
            specs=job["specs"],
            weights=job["weights"],
        output:
            exr=job["exr"],
            timing=job["timing"],
        wildcard_constraints:
            **job["constraints"],
        threads: 1
        resources:
            **job_resources("run_method", batch=job["batch"]),
        log:
            job["log"],
        run:
            run_in_pool("mcbench.pipeline.methods:run_methods", method_entries(rule, wildcards), input.render,
                        log=log[0], scene=wildcards.scene, spp=int(wildcards.spp), threads=threads)

    if job["methods"]:  # a missing file: its batch, not run_method
        workflow.ruleorder(job["rule"], "run_method")


