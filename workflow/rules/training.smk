# Training crops from the seeded procedural scene generator (mcbench.training_data), disjoint from
# the test scenes, and the learned denoisers trained on them (mcbench.nn). Not part of `all`:
#   snakemake --cores 2 training_data     # render the crops
#   snakemake --cores 2 train_kpcn        # train one network when its weights are missing
#   snakemake --cores 2 train_deep_combiner  # a learned combiner: also runs its bases on crops
# The weights in methods/weights are committed, so the main job never trains (nor renders
# crops); to retrain one, delete its .pt (a killed training resumes from its checkpoint).

rule training_example:
    output:
        [f"{RESULTS}/training/example_{{seed}}_{k}.exr" for k in range(TRAINING["crops"])],
    params:
        # the settings one example depends on (fibre_count only says how many scenes exist)
        settings={key: value for key, value in TRAINING.items() if key != "fibre_count"},
        variant=config["variant"],
        **feature_params(),
    threads: config["render_threads"]
    resources:
        **job_resources("training_example"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/training/example_{{seed}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/training/example_{{seed}}.tsv"
    script:
        "../scripts/training_example.py"


rule training_correlated:
    input:
        lambda wildcards: [rules.training_example.output[k].format(seed=wildcards.seed)
                           for k in range(COMBINER_TRAINING["crops"])],
    output:
        [f"{RESULTS}/training/correlated/{{base}}/example_{{seed}}_{k}.exr" for k in range(COMBINER_TRAINING["crops"])],
    params:
        weights=lambda wildcards: weights_digest_of(wildcards.base),
        weights_dir=WEIGHTS_DIR,
    threads: 1
    resources:
        **job_resources("training_correlated"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/training/correlated_{{base}}_{{seed}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/training/correlated_{{base}}_{{seed}}.tsv"
    script:
        "../scripts/training_correlated.py"


rule training_data:
    localrule: True
    input:
        training_crop_files(),
    default_target: False


rule train_network:
    input:
        unpack(train_network_inputs),
    output:
        weights=f"{WEIGHTS_DIR}/{{network}}.pt",
        record=f"{WEIGHTS_DIR}/{{network}}.json",
    params:
        overrides=lambda wildcards: TRAINING_OVERRIDES.get(wildcards.network, {}),
        checkpoint=f"{RESULTS}/training/checkpoints/{{network}}.ckpt",
        weights_dir=lambda wildcards, output: os.path.dirname(output.weights),
    wildcard_constraints:
        network="|".join(NETWORKS),
    # the networks train with 2 torch threads (mcbench.nn.train's default "threads")
    threads: 2
    resources:
        **job_resources("train_network"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/training/train_{{network}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/training/train_{{network}}.tsv"
    script:
        "../scripts/train_network.py"


for _network in NETWORKS:

    rule:
        name:
            f"train_{_network}"
        localrule: True
        input:
            missing_weights(_network),
        default_target: False
