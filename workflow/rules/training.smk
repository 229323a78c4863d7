# Training crops from the seeded procedural scene generator (mcbench.training), disjoint from
# the test scenes. Not part of `all`: `snakemake --cores 2 training_data`.

TRAINING = {
    "first_seed": 0,
    "count": 64,
    "resolution": [128, 128],
    "crop": 64,
    "crops": 2,
    "spp": [4, 16, 64, 256],
    "target_spp": 4096,
    **config.get("training", {}),
}
TRAINING_SEEDS = range(TRAINING["first_seed"], TRAINING["first_seed"] + TRAINING["count"])


rule training_example:
    output:
        [f"{RESULTS}/training/example_{{seed}}_{k}.exr" for k in range(TRAINING["crops"])],
    params:
        settings=TRAINING,
        variant=config.get("variant", "auto"),
    threads: config.get("render_threads", 2)
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/training/example_{{seed}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/training/example_{{seed}}.tsv"
    script:
        "../scripts/training_example.py"


rule training_data:
    input:
        [f"{RESULTS}/training/example_{seed}_{k}.exr" for seed in TRAINING_SEEDS for k in range(TRAINING["crops"])],
    default_target: False
