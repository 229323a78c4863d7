# Errors of every candidate and of the noisy input against the reference, per test case.


rule case_metrics:
    input:
        unpack(case_outputs),
        reference=f"{RESULTS}/references/{{scene}}.exr",
        render=f"{RESULTS}/renders/{{scene}}/spp{{spp}}.exr",
    output:
        f"{RESULTS}/metrics/{{scene}}/spp{{spp}}.csv",
    params:
        candidates=CANDIDATES,
        metrics=config["metrics"],
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/metrics/{{scene}}_spp{{spp}}.log",
    script:
        "../scripts/case_metrics.py"


rule gather_metrics:
    input:
        all_case_metrics,
    output:
        f"{RESULTS}/metrics.csv",
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/gather_metrics.log",
    script:
        "../scripts/gather_metrics.py"


rule gather_timings:
    input:
        all_timing_records,
    output:
        f"{RESULTS}/timings.csv",
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/gather_timings.log",
    script:
        "../scripts/gather_timings.py"
