"""The work behind ``workflow/rules/training.smk``: training crops, the bases' results on them
(the correlated inputs of learned combiners), and training a learned method by name.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from mcbench import BenchError
from mcbench.contracts.method import method_spec
from mcbench.io.buffers import RenderBuffers
from mcbench.io.exr import check_finite, read_layers, read_metadata, write_layers
from mcbench.io.weights import file_sha256, is_learned_method, record_path, weights_folder, weights_path
from mcbench.pipeline.method_runs import method_function
from mcbench.pipeline.rendering import resolution_pair


def write_training_example(seed: int, output_paths: list[str], *, spp_levels, target_spp: int, resolution,
                           crop_size: int, variant: str = "auto", threads: int | None = None,
                           features: str = "first_hit") -> None:
    """Render training scene ``seed`` (mcbench.training_data) and write one EXR per crop; its
    features in convention ``features`` (config key ``features``)."""
    from mcbench.training_data import training_example
    from mcbench.render.variants import set_threads

    set_threads(threads)
    crops = training_example(seed, list(spp_levels), target_spp, resolution_pair(resolution), crop_size,
                             len(output_paths), variant=variant, features=features)
    for path, (layers, metadata) in zip(output_paths, crops):
        check_finite(f"{path} (training scene {seed})", layers)
        write_layers(path, layers, metadata=metadata)


SURE_SUFFIX = "+sure"   # a training base "<name>+sure" also writes SURE's divergence term

#: Metadata key of a base's results on a training crop: the SHA-256 of the weights it ran with
#: ("" for a base that learns nothing), checked against the base's weights when a combiner trains.
BASE_WEIGHTS_KEY = "base_weights_sha256"


def base_weights_sha256(base: str, weights_dir: str | None) -> str:
    """The SHA-256 of the weights that training base ``base`` (``<name>`` or ``<name>+sure``) runs
    with, from weights folder ``weights_dir`` (default the committed ones); "" for a base that
    learns nothing."""
    from mcbench.pipeline.registry import load_method

    name = base.removesuffix(SURE_SUFFIX)
    if not is_learned_method(load_method(name, kind="denoiser", config_key=f"base '{base}'")):
        return ""
    path = weights_path(weights_folder(weights_dir), name)
    if not path.exists():
        raise BenchError(f"{path}: weights of base '{name}' are missing; train them first "
                         f"(`snakemake --cores 2 train_{name}`) or fix weights_dir")
    return file_sha256(path)


def check_base_results(correlated_files: dict[str, list[str]], *, weights_dir: str | None) -> None:
    """Refuse base results on training crops that a base made with other weights than the ones in
    ``weights_dir`` (a retrained base, or results made before weights were recorded): a combiner
    trained on them would learn from a base it never sees in a study. The error names the file and
    the folder to delete."""
    for base, files in correlated_files.items():
        expected = base_weights_sha256(base, weights_dir)
        if not expected:
            continue
        for path in files:
            made_with = read_metadata(path).get(BASE_WEIGHTS_KEY)
            if made_with != expected:
                raise BenchError(
                    f"{path}: results of base '{base}' made with "
                    f"{'unrecorded weights' if made_with is None else 'weights ' + made_with[:12]}, not its "
                    f"weights in {weights_folder(weights_dir)} ({expected[:12]}); delete "
                    f"{Path(path).parent} and run the combiner's training again")


def write_correlated_training_inputs(base: str, crop_paths: list[str], output_paths: list[str], *,
                                     weights_dir: str | None = None, threads: int | None = None) -> None:
    """Run base denoiser ``base`` (``methods/<base>.py``; a learned one with its weights in
    ``weights_dir``, default the committed ones)
    on every noisy level of each training crop and write its results, the correlated inputs of
    the deep combiner's training (Back et al. 2020 Sec. 5): per level ``N`` the layers
    ``correlated_spp<N>``, ``correlated_a_spp<N>``, ``correlated_b_spp<N>`` and, for a base that
    writes sub-buffer results (:data:`mcbench.io.buffers.SUB_OUTPUTS`, e.g. kpcn),
    ``correlated<half>_sub<j>_spp<N>``.

    ``base`` ``<name>+sure`` (progressive denoising's training data): also the divergence term of
    SURE of each image, ``divergence<half>_spp<N>`` (Eq. 2 with K = 1, ε = 1e-4, the base's
    single-image function re-run on the perturbed colour; ``mcbench.filters.sure.divergence_map``,
    seeded by crop, level and image)."""
    from mcbench.io.buffers import SUB_OUTPUTS
    from mcbench.nn.crops import HALF_OF, crop_render_layers
    from mcbench.render.variants import set_threads
    from mcbench.pipeline.registry import load_method

    if threads:
        set_threads(threads)
        _torch_threads(int(threads))
    name, with_sure = (base[:-len(SURE_SUFFIX)], True) if base.endswith(SURE_SUFFIX) else (base, False)
    folder = weights_folder(weights_dir)
    denoise = method_function(load_method(name, kind="denoiser", config_key=f"base '{base}'"), weights_dir=folder)
    made_with = base_weights_sha256(base, weights_dir)
    if with_sure:
        from mcbench.filters.sure import divergence_map
        from mcbench.io.buffers import IMAGE_INDEX
        from mcbench.pipeline.registry import single_image_function
        denoise_image = single_image_function(name, weights_dir=folder)
    if len(crop_paths) != len(output_paths):
        raise BenchError(f"{len(crop_paths)} crops for {len(output_paths)} outputs of base '{base}'")
    for crop_path, output_path in zip(crop_paths, output_paths):
        meta = read_metadata(crop_path)
        if "spp_levels" not in meta:
            raise BenchError(f"{crop_path}: not a training crop (no spp_levels metadata)")
        levels = [int(v) for v in meta["spp_levels"].split(",")]
        layers = read_layers(crop_path)
        check_finite(crop_path, layers)
        out, start = {}, time.perf_counter()
        for level in levels:
            buffers = RenderBuffers(layers=crop_render_layers(layers, level), spp=level,
                                    source=f"{crop_path} at {level} spp")
            result = denoise(buffers)
            for half, which in HALF_OF.items():
                out[f"correlated{half}_spp{level}"] = result.image(which)
                extras = result.extras or {}
                for j, sub_name in enumerate(SUB_OUTPUTS[which]):
                    if sub_name in extras:
                        out[f"correlated{half}_sub{j}_spp{level}"] = extras[sub_name]
                if with_sure:
                    seed = [int(meta.get("seed", 0)), int(meta.get("crop", 0)), level, IMAGE_INDEX[which]]
                    out[f"divergence{half}_spp{level}"] = divergence_map(
                        denoise_image, buffers.image(which), seed=seed).astype(np.float32)
        check_finite(f"{output_path} (results of '{base}' on {crop_path})", out)
        write_layers(output_path, out, metadata={"base": base, "seed": meta.get("seed", ""),
                                                 "crop": meta.get("crop", ""), "spp_levels": meta["spp_levels"],
                                                 BASE_WEIGHTS_KEY: made_with,
                                                 "seconds": f"{time.perf_counter() - start:.3f}"})


def _torch_threads(threads: int) -> None:
    """torch's thread count, where torch is installed."""
    try:
        import torch
    except ImportError:
        return
    torch.set_num_threads(threads)


def learned_method(name: str):
    """``methods/<name>.py`` checked to be a learned method (its declaration sets ``learned``): a
    denoiser, or a combiner trained on base results (its ``correlated_bases``, ``training_keys``;
    :class:`mcbench.contracts.method.MethodSpec` refuses a learned combiner without them)."""
    from mcbench.io.weights import check_learned_method
    from mcbench.pipeline.registry import load_method

    return check_learned_method(load_method(name, config_key=f"network '{name}'"))


def training_data(name: str, crop_files: list[str], correlated_files: dict[str, list[str]] | None = None, *,
                  weights_dir: str | None = None):
    """The training data of learned method ``name``: its crops (a denoiser: the crop paths
    themselves) or, for a combiner, :func:`mcbench.nn.crops.load_combiner_crops` over the results
    of its ``correlated_bases`` (``correlated_files``: {base: files, one per crop}), each made
    with its base's weights in ``weights_dir`` (:func:`check_base_results`)."""
    spec = method_spec(learned_method(name))
    if spec.kind != "combiner":
        return list(crop_files)
    spec = spec.learned
    from mcbench.nn.crops import load_combiner_crops

    correlated_files = correlated_files or {}
    missing = [b for b in spec.correlated_bases if b not in correlated_files]
    if missing:
        raise BenchError(f"{name}: no results of base(s) {missing} for its training")
    results = {b: correlated_files[b] for b in spec.correlated_bases}
    check_base_results(results, weights_dir=weights_dir)
    return load_combiner_crops(crop_files, results, spec.training_keys)


def train_learned_method(name: str, crop_files: list[str], *args, correlated_files=None, weights_dir=None,
                         **kwargs):
    """Train ``methods/<name>.py`` (:func:`mcbench.nn.train.train_network`) on
    :func:`training_data` (the step resolves the name, core never imports methods); a combiner's
    bases ran with the weights in ``weights_dir``."""
    from mcbench.nn.train import train_network

    kwargs.setdefault("provenance", training_provenance())
    data = training_data(name, crop_files, correlated_files, weights_dir=weights_dir)
    return train_network(learned_method(name), data, *args, **kwargs)


def training_provenance() -> dict:
    """What a training record adds about the machine: the CPU (model, family, ISA flags, cores;
    :func:`mcbench.pipeline.provenance.cpu_info`)."""
    from mcbench.pipeline.provenance import cpu_info

    return {"cpu": cpu_info()}


def train_progressive_variant(variant: str, data: str = "results/training", steps: int | None = None,
                              threads: int | None = None, weights_dir: str | None = None, *,
                              rounds: int | None = None, plateau: float | None = None) -> dict:
    """Train progressive denoising's h_NN (``methods/progressive.py``): ``full`` (the committed
    ``progressive.pt``) or an ablation of its ``VARIANTS`` (``no_sure``, ``no_fact``; Firmino et al.
    2022 Table 4), on the crops with results of its declared ``correlated_bases`` under
    ``<data>/correlated/``; weights and record in ``weights_dir`` (default ``methods/weights/``), checkpoint
    ``results/training/checkpoints/<name>.ckpt`` (a run resumes from it); ``rounds`` and
    ``plateau``: the stopping rule (:mod:`mcbench.nn.train`)."""
    import sys

    from mcbench.nn.crops import crop_paths
    from mcbench.nn.train import correlated_paths, train_network
    from mcbench.pipeline.registry import load_method

    progressive = load_method("progressive", kind="combiner", config_key="progressive training")
    if variant != "full" and variant not in progressive.VARIANTS:
        raise BenchError(f"unknown progressive variant '{variant}'; known: full, {', '.join(progressive.VARIANTS)}")
    module = progressive if variant == "full" else progressive.variant_module(variant)
    files, correlated = correlated_paths(data, method_spec(progressive).learned.correlated_bases, crop_paths(data))
    crops = training_data("progressive", [str(f) for f in files],
                          {b: [str(f) for f in fs] for b, fs in correlated.items()}, weights_dir=weights_dir)
    name = "progressive" if variant == "full" else f"progressive_{variant}"
    folder = weights_folder(weights_dir)
    return train_network(module, crops, weights_path(folder, name), record_path(folder, name),
                         f"results/training/checkpoints/{name}.ckpt",
                         {key: value for key, value in
                          {"steps": steps, "threads": threads, "rounds": rounds, "plateau": plateau}.items()
                          if value is not None},
                         log=lambda message: print(message, file=sys.stderr, flush=True),
                         provenance=training_provenance())


def main(argv: list[str] | None = None) -> int:
    """``python -m mcbench.pipeline.training progressive full|no_sure|no_fact [--steps N] [--threads N]
    [--weights-dir D] [--rounds N] [--plateau F]``
    trains progressive denoising's network or an ablation; ``python -m mcbench.pipeline.training
    evaluate|train <name> ...`` is :func:`mcbench.nn.train.main` with the methods registry (e.g. to
    re-evaluate committed weights on the validation crops)."""
    import argparse
    import sys

    from mcbench.pipeline.freed_memory import keep_freed_memory

    keep_freed_memory()   # a process of its own: its steps reuse the heap instead of page-faulting
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["progressive"]:
        parser = argparse.ArgumentParser(prog="python -m mcbench.pipeline.training progressive",
                                         description="Train progressive denoising's h_NN (full) or an ablation.")
        parser.add_argument("variant", choices=["full", "no_fact", "no_sure"])
        parser.add_argument("--data", default="results/training")
        parser.add_argument("--steps", type=int, default=None, help="training steps (default TRAINING['steps'])")
        parser.add_argument("--threads", type=int, default=None, help="torch threads (default 2)")
        parser.add_argument("--weights-dir", default=None, help="folder of the weights (default: methods/weights)")
        parser.add_argument("--rounds", type=int, default=None,
                            help="at most this many rounds of its steps (stopping rule of mcbench.nn.train; default 1)")
        parser.add_argument("--plateau", type=float, default=None,
                            help="stop after a round improving the validation loss by less than this (default 0.02)")
        arguments = parser.parse_args(argv[1:])
        train_progressive_variant(arguments.variant, arguments.data, arguments.steps, arguments.threads,
                                  arguments.weights_dir, rounds=arguments.rounds, plateau=arguments.plateau)
        return 0
    from mcbench.nn.train import main as train_main

    return train_main(argv, load_method=learned_method, load_data=training_data, provenance=training_provenance())


if __name__ == "__main__":
    raise SystemExit(main())
