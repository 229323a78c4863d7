# Helpers shared by the rules: config validation, the method table, input functions.

import functools
import os
import sys
from pathlib import Path

from snakemake.utils import validate

sys.path.insert(0, str(Path(workflow.basedir)))  # methods/, scenes/, mcbench/ from a checkout

from mcbench import BenchError  # noqa: E402
from mcbench.training import training_seeds  # noqa: E402


validate(config, schema="../schemas/config.schema.yaml")

RESULTS = "results"
# Learned methods' weights: the committed methods/weights of this checkout unless the config
# names another folder (relative to the working directory).
WEIGHTS_DIR = config.get("weights_dir") or str(Path(workflow.basedir) / "methods" / "weights")


def _method_table(config):
    """Ordered {candidate name: {kind, module, params, inputs, label}} from the config.

    Every module name is checked against methods/ here, so a typo stops the run before any
    job starts, with an error naming the config key.
    """
    from methods import load_method
    from mcbench.nn.train import is_learned_method

    table = {}
    for index, entry in enumerate(config["denoisers"]):
        entry = {"name": entry} if isinstance(entry, str) else dict(entry)
        key = f"denoisers[{index}]"
        method_module = load_method(entry.get("method", entry["name"]), kind="denoiser", config_key=key)
        if entry["name"] in table:
            raise BenchError(f"{key}: duplicate method name '{entry['name']}'")
        module_name = method_module.__name__.split(".")[-1]
        table[entry["name"]] = {"kind": "denoiser", "module": module_name,
                                "params": entry.get("params", {}), "inputs": [],
                                "label": entry.get("label", method_module.LABEL),
                                "learned": is_learned_method(method_module)}
    for index, entry in enumerate(config.get("combiners", [])):
        key = f"combiners[{index}]"
        method_module = load_method(entry["method"], kind="combiner", config_key=key)
        if entry["name"] in table:
            raise BenchError(f"{key}: duplicate method name '{entry['name']}'")
        for position, name in enumerate(entry["inputs"]):
            if name not in table:
                raise BenchError(f"{key}.inputs[{position}]: '{name}' is not a denoiser or an "
                                 f"earlier combiner in config.yaml")
        table[entry["name"]] = {"kind": "combiner", "module": method_module.__name__.split(".")[-1],
                                "params": entry.get("params", {}), "inputs": list(entry["inputs"]),
                                "label": entry.get("label", f"{method_module.LABEL} ({'+'.join(entry['inputs'])})"),
                                "learned": False}
    return table


def _check_scenes(config):
    from scenes import load_scene

    for index, name in enumerate(config["scenes"]):
        load_scene(name, config_key=f"scenes[{index}]")


METHODS = _method_table(config)
_check_scenes(config)
SCENES = list(config["scenes"])
SPPS = sorted(config["spp"])
CANDIDATES = list(METHODS)
LABELS = {name: spec["label"] for name, spec in METHODS.items()}
LABELS["noisy"] = "Noisy input"
REFERENCE_CHUNKS = config["reference"]["chunks"]


def _reference_spp_table(config):
    """Reference spp per scene: ``reference.scene_spp[scene]`` or ``reference.spp``."""
    per_scene = config["reference"].get("scene_spp", {})
    for name in per_scene:
        if name not in SCENES:
            raise BenchError(f"reference.scene_spp: '{name}' is not one of the configured scenes")
    table = {scene: int(per_scene.get(scene, config["reference"]["spp"])) for scene in SCENES}
    for scene, spp in table.items():
        key = f"reference.scene_spp.{scene}" if scene in per_scene else "reference.spp"
        if spp % REFERENCE_CHUNKS or (spp // REFERENCE_CHUNKS) % 2:
            raise BenchError(f"{key}: {spp} spp must split into {REFERENCE_CHUNKS} chunks (reference.chunks) "
                             f"of an even spp each")
    return table


REFERENCE_SPP = _reference_spp_table(config)


def reference_chunk_spp(wildcards):
    return REFERENCE_SPP[wildcards.scene] // REFERENCE_CHUNKS


def reference_path(scene):
    return f"{RESULTS}/references/{scene}.exr"


wildcard_constraints:
    scene="[A-Za-z][A-Za-z0-9_]*",
    method="[A-Za-z][A-Za-z0-9_]*",
    spp=r"\d+",
    chunk=r"\d+",
    seed=r"\d+",
    metric="relmse|smape|dssim",


def render_path(scene, spp):
    return f"{RESULTS}/renders/{scene}/spp{spp}.exr"


def output_path(scene, spp, method):
    return f"{RESULTS}/outputs/{scene}/spp{spp}/{method}.exr"


def method_inputs(wildcards):
    """Outputs of the methods a combiner takes (empty for a base denoiser)."""
    spec = METHODS[wildcards.method]
    return [output_path(wildcards.scene, wildcards.spp, name) for name in spec["inputs"]]


def weights_file(network):
    return f"{WEIGHTS_DIR}/{network}.pt"


def method_weights(wildcards):
    """A learned method's weights as an input only while they are missing (then the train rule
    makes them). Present weights are not an input, so nothing of the training part of the DAG
    (crops, train rule) is ever planned by the main job, even on a clean checkout without
    training data; a change of the weights reruns the method through `weights_digest`."""
    spec = METHODS[wildcards.method]
    return missing_weights(spec["module"]) if spec["learned"] else []


def weights_digest(wildcards):
    """SHA-256 of a learned method's present weights ("" otherwise): a params entry, so the
    provenance trigger reruns the method when its weights change."""
    spec = METHODS[wildcards.method]
    path = Path(weights_file(spec["module"]))
    if not spec["learned"] or not path.exists():
        return ""
    return _file_digest(str(path), path.stat().st_mtime_ns)


@functools.lru_cache(maxsize=None)
def _file_digest(path, mtime_ns):
    """SHA-256 of a file, cached per (path, modification time) while the DAG is built."""
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def missing_weights(network):
    """The weights file of ``network`` if it is missing, else nothing: `train_<name>` trains
    only what is missing (the train rule's provenance triggers never retrain present weights)."""
    path = weights_file(network)
    return [] if Path(path).exists() else [path]


def train_network_inputs(wildcards):
    """Training crops of a network whose weights are missing; none once the weights exist, so
    an explicit `train_<name>` with committed weights has nothing to do."""
    return ancient(training_crop_files()) if missing_weights(wildcards.network) else []


def case_outputs(wildcards):
    return {name: output_path(wildcards.scene, wildcards.spp, name) for name in CANDIDATES}


def all_timing_records(wildcards=None):
    return [f"{RESULTS}/outputs/{scene}/spp{spp}/{method}.json"
            for scene in SCENES for spp in SPPS for method in CANDIDATES]


def all_case_metrics(wildcards=None):
    return [f"{RESULTS}/metrics/{scene}/spp{spp}.csv" for scene in SCENES for spp in SPPS]


# Training data and learned methods (rules in training.smk).

TRAINING = {
    "first_seed": 0,
    "count": 64,
    "resolution": [128, 128],
    "crop": 64,
    "crops": 2,
    "spp": [4, 16, 64, 256],
    "target_spp": 4096,
    **{key: value for key, value in config.get("training", {}).items() if key != "networks"},
}
TRAINING_OVERRIDES = config.get("training", {}).get("networks", {})
TRAINING_SEEDS = training_seeds(TRAINING)


def training_crop_files():
    return [f"{RESULTS}/training/example_{seed}_{k}.exr" for seed in TRAINING_SEEDS for k in range(TRAINING["crops"])]


def _learned_networks():
    """Every learned method module in methods/ (those declaring NETWORK, TRAINING, build_network)."""
    from methods import available_methods, load_method
    from mcbench.nn.train import is_learned_method

    modules = {name: load_method(name) for name in available_methods()}
    return sorted(name for name, module in modules.items() if is_learned_method(module))


NETWORKS = _learned_networks()
for _name in TRAINING_OVERRIDES:
    if _name not in NETWORKS:
        raise BenchError(f"training.networks: '{_name}' is not a learned method; learned: {', '.join(NETWORKS)}")
