# Base denoisers and combiners, and each entry's evaluation: one job per test case (rule run_case,
# mcbench.pipeline.cases.run_case). The job runs the case's methods in dependency order (a base
# denoiser returns its full and half-buffer results in one run; a combiner also reads its input
# methods' outputs; a learned method also reads its weights), then evaluates each entry of the
# case (the noisy input, every candidate) into its metric values and viewer images, and writes
# the case's metrics table, viewer folder and record. Each method output and evaluation it finds
# up to date (by its key: the method's settings, its inputs', its weights' and the render's
# content; mcbench.pipeline.cases) it keeps, so an edit of the config makes only what it changes:
# a new method runs alone, changed params rerun the method and the combiners that read it, an
# added metric is the only one computed. The rule is the same whatever exists under results/.
# It runs in a warm worker process that imports once (mcbench.pipeline.worker_pool).
# `snakemake -f results/cases/<scene>/spp<N>.json` reassembles a case; delete a method's output to
# make it again.


rule run_case:
    input:
        render=rules.render_noisy.output[0],
        reference=rules.merge_reference.output[0],
        reference_check=get_reference_check,
    output:
        metrics="results/metrics/{scene}/spp{spp}.csv",
        viewer=directory("results/viewer_cases/{scene}/spp{spp}"),
        record="results/cases/{scene}/spp{spp}.json",
    params:
        plan=get_case_plan,
    threads: 1
    resources:
        **STUDY.case_resources(),
    log:
        "results/logs/cases/{scene}/spp{spp}.log",
    run:
        run_in_pool("mcbench.pipeline.cases:run_case", case_job(wildcards, output), log=log[0],
                    threads=threads)
