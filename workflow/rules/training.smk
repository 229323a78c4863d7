# Training crops from the seeded procedural scene generator (mcbench.training_data), disjoint from
# the test scenes, and the learned denoisers trained on them (mcbench.nn). Not part of `all`:
#   snakemake --cores 2 training_data     # render the crops
#   snakemake --cores 2 train_kpcn        # train one network when its weights are missing
#   snakemake --cores 2 train_deep_combiner  # a learned combiner: also runs its bases on crops
# The weights in methods/weights are committed, so the main job never trains (nor renders
# crops); to retrain one, delete its .pt (a killed training resumes from its checkpoint).

rule training_example:
    output:
        [f"results/training/example_{{seed}}_{k}.exr" for k in range(PLAN.training.settings["crops"])],
    params:
        # the settings one example depends on (fibre_count only says how many scenes exist)
        settings={key: value for key, value in PLAN.training.settings.items() if key != "fibre_count"},
        variant=config["variant"],
        **STUDY.feature_params,
    threads: config["render_threads"]
    resources:
        **STUDY.resources("training_example"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/training/example_{seed}.log",
    benchmark:
        "results/benchmarks/training/example_{seed}.tsv"
    script:
        "../scripts/training_example.py"


rule training_correlated:
    input:
        crops=list(rules.training_example.output)[: PLAN.training.combiner_settings["crops"]],
        weights=lambda wildcards: STUDY.base_weights(wildcards.base),
    output:
        [f"results/training/correlated/{{base}}/example_{{seed}}_{k}.exr" for k in range(PLAN.training.combiner_settings["crops"])],
    params:
        weights=lambda wildcards: STUDY.weights_sha256(wildcards.base),
        weights_dir=STUDY.weights_dir,
    threads: 1
    resources:
        **STUDY.resources("training_correlated"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/training/correlated_{base}_{seed}.log",
    benchmark:
        "results/benchmarks/training/correlated_{base}_{seed}.tsv"
    script:
        "../scripts/training_correlated.py"


rule training_data:
    localrule: True
    input:
        get_training_crops(),
    default_target: False


rule train_network:
    input:
        unpack(get_train_inputs),
    output:
        weights=f"{STUDY.weights_dir}/{{network}}.pt",
        record=f"{STUDY.weights_dir}/{{network}}.json",
    params:
        overrides=lambda wildcards: PLAN.training.overrides.get(wildcards.network, {}),
        checkpoint="results/training/checkpoints/{network}.ckpt",
        weights_dir=lambda wildcards, output: os.path.dirname(output.weights),
    wildcard_constraints:
        network="|".join(STUDY.trained_networks(combiners=False)) or "^$",
    # the networks train with 2 torch threads (mcbench.nn.train's default "threads")
    threads: 2
    resources:
        **STUDY.resources("train_network"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/training/train_{network}.log",
    benchmark:
        "results/benchmarks/training/train_{network}.tsv"
    script:
        "../scripts/train_network.py"


# A learned combiner trains on its bases' results, made with a learned base's weights, which
# train_network makes: a rule of its own (a Snakemake rule may not depend on itself).
use rule train_network as train_combiner with:
    wildcard_constraints:
        network="|".join(STUDY.trained_networks(combiners=True)) or "^$",


for _network in PLAN.training.networks:

    rule:
        name:
            f"train_{_network}"
        localrule: True
        input:
            # its weights while they are missing (looked for when the DAG is built, not parsed)
            lambda wildcards, network=_network: STUDY.missing_weights(network),
        default_target: False
