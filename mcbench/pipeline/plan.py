"""What the rules plan for a configuration, decided when the DAG is parsed.

:func:`plan_study` is everything ``workflow/rules/common.smk`` computes from the resolved config
alone (the method table, the scenes and spp levels, the ranking pool and the extras, reference
spp, training seeds, the oracle's and the progressive curve's scene), with every check
that stops a config before any job, as a typed value (:mod:`mcbench.pipeline.study_plan`). The
Snakefile reads its names from it (``PLAN``), so a test
calling :func:`plan_study` checks the workflow's own logic without starting Snakemake.

Errors are :class:`mcbench.BenchError` (or a subclass) whose message starts with the config's
source and the offending key, e.g. ``config.yaml: study.ensembles[0]: ...``. An error at a key
the config does not set (its value is the schema's default) says so and how to override it
(:func:`default_note`): e.g. the default ``combiners`` naming a denoiser that the config's own
``denoisers`` dropped.

Checks here beyond the method table's (:func:`methods.method_table`):

* every ``spp`` has a render seed code (:func:`mcbench.render.seeds.spp_code`: even up to 2048,
  multiples of 2048 up to 2**21), else the render job would fail;
* every reference has *more* samples than every image it scores: ``reference.spp`` (or a
  scene's ``reference.scene_spp``) above the largest ``spp``; the oracle's and the progressive
  curve's references (block-averaged over ``downscale``², so worth that many times more samples)
  above ``oracle.spp`` and every ``progressive_curve.spp``. A reference with as many samples as
  the render it judges is no reference: its own noise is as large as the error it measures;
* every name under ``metrics`` is a plugin ``metrics/<name>.py`` (a misspelt one is named with
  its key and the closest metric) whose values are errors (lower is better: the rankings and the
  study score them so);
* ``progressive_curve.scene`` names a scene (with the key), the comparison tables' roles are
  unique (:func:`mcbench.analysis.comparison_tables.find_comparisons`, which the comparison jobs
  would otherwise raise hours later), ``training.first_seed + training.count`` fits the object
  seeds, ``training.spp`` are powers of two 2..32768 (the training render seeds) and the
  training crops fit ``training.resolution``;
* a scene of renders made elsewhere (``scenes/<name>.yaml``, :mod:`mcbench.io.render_folders`)
  has a case for every ``spp`` and a reference, at the config's ``resolution`` if one is set,
  a reference variance if a metric that reads it is computed (``relmse_corrected``), and every layer each configured
  method reads (:func:`mcbench.pipeline.method_runs.needed_layers`): a method that needs what the
  folder lacks (half buffers, variance, depth) is refused for that scene, naming the files
  that would supply it; the oracle study and the progressive curve render their scene again,
  so they take the first scene that Mitsuba renders.
"""

from __future__ import annotations

import re

from mcbench import NOISY, NOISY_LABEL, BenchError
from mcbench.analysis.comparison_tables import comparison_role, find_comparisons
from mcbench.analysis.pool import POOL
from mcbench.contracts.method import method_spec
from mcbench.contracts.scene import scene_spec
from mcbench.io.weights import COMMITTED_WEIGHTS
from mcbench.pipeline.config import ConfigError, key_path, schema_defaults
from mcbench.pipeline.oracle import oracle_size, usable_downscale
from mcbench.pipeline.reference_sources import STORE_FOLDER, reference_source
from mcbench.pipeline.registry import (available_scenes, config_method_table, load_method, load_metrics,
                                       load_scene, single_image_methods)
from mcbench.pipeline.study_plan import (CasePlan, MethodPlan, RankingPlan, SideStudyPlan, StudyPaths, StudyPlan,
                                         TrainingPlan, frozen_mapping)
from mcbench.render.seeds import FIBRE_SEED_BASE, spp_code, training_seeds

__all__ = ["plan_study", "default_note", "defaulted_key"]

# the largest spp a training render seed encodes (mcbench.render.seeds.training_render_seed)
MAX_TRAINING_SPP = 1 << 15


def plan_study(config: dict, *, written: dict | None = None, source: str = "config", is_learned=None) -> StudyPlan:
    """The plan of a resolved ``config`` (:func:`mcbench.pipeline.config.resolve_config`).

    ``written``: the config as its file gave it, before the defaults were filled in (to tell
    the keys the user set from the schema's defaults in error messages; ``None``: not known).
    ``source`` (the config file) prefixes every error. ``is_learned`` (a method module ->
    bool; default :func:`mcbench.io.weights.is_learned_method`).

    Returns a :class:`mcbench.pipeline.study_plan.StudyPlan`: the methods in dependency order,
    the cases, what the tables rank, the training crops and the side studies' scenes.
    """
    if is_learned is None:
        from mcbench.io.weights import is_learned_method as is_learned
    try:
        _check_metrics(config["metrics"])
        return _plan(config, is_learned)
    except BenchError as error:
        message = str(error)
        if not message.startswith(f"{source}: "):
            message = f"{source}: {message}"
        error.args = (message + default_note(message[len(source) + 2:], written, config, source),)
        raise


def _plan(config: dict, is_learned) -> StudyPlan:
    """The plan of ``config``, its checks in this order: the method table, the scenes and spp,
    the comparisons, the case files, the render folders, the references, the methods'
    dependency order, the training, the side studies."""
    methods = config_method_table(config, is_learned=is_learned)
    scenes, spps = _scenes_and_spps(config)
    ranking = _ranking_plan(config, methods)
    _check_comparisons(methods)
    _check_case_files(methods, scenes, spps)
    render_folders = _check_render_folders(config, methods, scenes, spps)
    reference_spp = _reference_spp(config, scenes, render_folders)
    _check_dependency_order(methods)
    training = _training_plan(config, methods)
    side = _side_study_plan(config, methods, scenes, render_folders, reference_spp)
    return StudyPlan(
        methods=frozen_mapping({name: MethodPlan(name=name, kind=spec["kind"], module=spec["module"],
                                                 params=frozen_mapping(spec["params"]), inputs=tuple(spec["inputs"]),
                                                 label=spec["label"], learned=spec["learned"],
                                                 config_key=spec.get("config_key", ""),
                                                 comparison_role=spec.get("comparison_role"),
                                                 weights=_weights_read(spec))
                                for name, spec in methods.items()}),
        cases=_case_plan(config, scenes, spps, reference_spp, render_folders),
        ranking=ranking, training=training, side=side,
        paths=StudyPaths(weights_dir=config.get("weights_dir") or str(COMMITTED_WEIGHTS)))


def _case_plan(config: dict, scenes: list[str], spps: list[int], reference_spp: dict,
               render_folders: dict) -> CasePlan:
    """The cases, each scene's image size and where its reference comes from
    (:func:`mcbench.pipeline.reference_sources.reference_source`: the store, when it holds a
    reference of this identity and ``reference.source`` is ``store``; else rendered, with why)."""
    resolutions = {scene: tuple(int(n) for n in (config["resolution"] or scene_spec(load_scene(scene)).size))
                   for scene in scenes}
    store = config["reference"]["store"] or STORE_FOLDER
    sources = {scene: reference_source(scene, load_scene(scene), resolutions[scene],
                                       requested=config["reference"]["source"], store=store) for scene in scenes}
    return CasePlan(scenes=tuple(scenes), spps=tuple(spps), reference_spp=frozen_mapping(reference_spp),
                    reference_chunks=config["reference"]["chunks"], render_folders=frozen_mapping(render_folders),
                    resolutions=frozen_mapping(resolutions),
                    reference_sources=frozen_mapping({scene: source.kind for scene, source in sources.items()}),
                    stored_references=frozen_mapping({scene: str(source.stored.record_path)
                                                      for scene, source in sources.items() if source.stored}),
                    reference_notes=_reference_notes(sources, store) if config["reference"]["source"] == "store" else (),
                    keep_outputs=config["keep_outputs"])


def _reference_notes(sources: dict, store) -> tuple[str, ...]:
    """The log's lines on where the references come from: the scenes whose reference the store
    lacks in one line, each other scene's reason in its own."""
    missing = [scene for scene, source in sources.items() if source.kind == "render" and source.stored is None
               and "has no reference" in source.reason]
    notes = [f"reference of {scene}: {source.reason}" for scene, source in sources.items()
             if source.kind != "folder" and scene not in missing]
    if missing:
        notes.append(f"references rendered (the store {store} has none of this resolution): {', '.join(missing)}")
    return tuple(notes)


def _scenes_and_spps(config: dict) -> tuple[list[str], list[int]]:
    """The config's scenes (each one that loads) and its spp levels, sorted (each one with a
    render seed code)."""
    for index, scene in enumerate(config["scenes"]):
        load_scene(scene, config_key=f"scenes[{index}]")
    for index, spp in enumerate(config["spp"]):
        try:
            spp_code(spp)
        except BenchError:
            raise ConfigError(f"spp[{index}]: {spp} spp has no render seed code (mcbench.render.seeds); use an "
                              f"even spp up to 2048 or a multiple of 2048 up to {2048 * 1024}") from None
    return list(config["scenes"]), sorted(config["spp"])


def _ranking_plan(config: dict, methods: dict) -> RankingPlan:
    """What the tables rank. With ``study.pool``: exactly the 39 candidates of Zheng et al. Sec.
    5.3.1 the config runs (:mod:`mcbench.analysis.pool`), in ID order; otherwise every candidate
    but the comparison methods of Sec. 5.2 (one-hot selection, naive averages, ablations; ranked
    in comparisons.smk). Every other method is an extra, scored in a pool that adds it alone
    (rule extras_table)."""
    candidates = list(methods)
    pool_study = config["study"]["pool"]
    if pool_study:
        ranked = [c.name for c in POOL if c.name in methods]
    else:
        ranked = [name for name in candidates if comparison_role(methods[name]) is None]
    extras = [name for name in candidates if name not in ranked]
    pool_note = ("" if not pool_study else
                 "Rows: the 39 candidates of Zheng et al. 2021 Sec. 5.3.1 in ID order (40 entries with the noisy "
                 "input, as the paper's Table 3); ensembles marked (filled) or (forced) are our choice of the "
                 "members the paper does not name (mcbench.analysis.pool)." if len(ranked) == len(POOL) else
                 f"Partial pool: {len(ranked)} of the 39 candidates (study.ensembles), {len(ranked) + 1} entries "
                 f"with the noisy input, so the scores are on another scale than the paper's 40-entry Table 3.")
    labels = {NOISY: NOISY_LABEL, **{name: spec["label"] for name, spec in methods.items()}}
    return RankingPlan(candidates=tuple(candidates), ranked=tuple(ranked), extras=tuple(extras),
                       pool_study=bool(pool_study), pool_note=pool_note, labels=frozen_mapping(labels),
                       metrics=tuple(config["metrics"]))


def _reference_spp(config: dict, scenes: list[str], render_folders: dict) -> dict:
    """Each scene's reference spp (None for a folder of renders made elsewhere: unknown), each
    above every spp it judges."""
    reference_spp = _reference_spp_table(config, [s for s in scenes if s not in render_folders],
                                         config["reference"]["chunks"])
    _check_reference_above_spp(config, reference_spp)
    reference_spp.update({scene: None for scene in render_folders})
    return reference_spp


def _check_dependency_order(methods: dict) -> None:
    """The method table's order is a dependency order: a combiner after its inputs."""
    position = {name: index for index, name in enumerate(methods)}
    for name, spec in methods.items():
        for input_name in spec["inputs"]:
            if position[input_name] > position[name]:
                raise BenchError(f"method '{name}' takes '{input_name}', which comes after it in the method table")


def _training_plan(config: dict, methods: dict) -> TrainingPlan:
    """The training crops and settings. The learned combiners' crops are a subset of the
    training scenes, checked when the config has a learned combiner (a smaller training set for
    the denoisers alone stays valid); each per-network override names a learned method."""
    training = {key: value for key, value in config["training"].items() if key not in ("networks", "combiners")}
    training_overrides = config["training"]["networks"]
    _check_training(config["training"])
    seeds = training_seeds(training)
    networks = sorted({spec["module"] for spec in methods.values() if spec["learned"]})
    combiner_training = config["training"]["combiners"]
    if any(spec["learned"] and spec["kind"] == "combiner" for spec in methods.values()):
        for key in ("count", "fibre_count", "crops"):
            if combiner_training[key] > training[key]:
                raise BenchError(f"training.combiners.{key}: {combiner_training[key]} is more than "
                                 f"training.{key} ({training[key]}), and this config has a learned combiner")
    combiner_seeds = training_seeds({**training, "count": min(combiner_training["count"], training["count"]),
                                     "fibre_count": min(combiner_training["fibre_count"], training["fibre_count"])})
    for name in training_overrides:
        if name not in networks:
            raise BenchError(f"training.networks.{name}: not a learned method of this config; "
                             f"learned: {', '.join(networks) or 'none'}")
    return TrainingPlan(settings=frozen_mapping(training), seeds=tuple(seeds),
                        overrides=frozen_mapping(training_overrides), networks=tuple(networks),
                        combiner_settings=frozen_mapping(combiner_training), combiner_seeds=tuple(combiner_seeds))


def _side_study_plan(config: dict, methods: dict, scenes: list[str], render_folders: dict,
                     reference_spp: dict) -> SideStudyPlan:
    """The oracle study's and the progressive curve's scenes and downscales, and progressive
    denoising's entries (combiners of module progressive) with the method each mixes with the
    noisy render (progressive.smk)."""
    progressive = {name: spec["inputs"][0] for name, spec in methods.items() if spec["module"] == "progressive"}
    rendered = [scene for scene in scenes if scene not in render_folders]
    oracle_scene, oracle_downscale = _oracle(config, scenes, rendered, reference_spp)
    progressive_scene, progressive_downscale = _progressive_curve(config, scenes, rendered, reference_spp,
                                                                  progressive)
    return SideStudyPlan(oracle_scene=oracle_scene, oracle_downscale=oracle_downscale,
                         progressive=frozen_mapping(progressive), progressive_scene=progressive_scene,
                         progressive_downscale=progressive_downscale)


def _check_metrics(names: list[str]) -> None:
    """Every metric is a plugin ``metrics/<name>.py`` (else an error naming ``metrics[i]`` and the
    closest name) whose values are errors: the score-and-rank tables and the study score the lower
    value better, so a metric declaring ``lower_is_better=False`` is refused, naming its file."""
    for index, (name, spec) in enumerate(load_metrics(names).items()):
        if not spec.lower_is_better:
            raise BenchError(f"metrics[{index}]: metrics/{name}.py declares lower_is_better=False, but the rankings "
                             f"and the study score lower values as better; declare the metric as an error "
                             f"(e.g. 1 - value) with lower_is_better=True")


def _check_case_files(methods: dict, scenes: list[str], spps: list[int]) -> None:
    """Files a method needs per case (its declared ``required_files``, e.g. precomputed results) exist for
    every (scene, spp) of the config; else a BenchError naming the method and the first missing
    files, before any job."""
    from pathlib import Path

    for name, spec in methods.items():
        required = method_spec(load_method(spec["module"])).required_files
        if required is None:
            continue
        missing = [path for scene in scenes for spp in spps
                   for path in required(spec["params"], name=name, scene=scene, spp=spp) if not Path(path).is_file()]
        if missing:
            shown = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
            raise BenchError(f"method '{name}' ({spec['module']}): {len(missing)} file(s) of its cases are missing: "
                             f"{shown}")


def _check_render_folders(config: dict, methods: dict, scenes: list[str], spps: list[int]) -> dict:
    """The scenes of renders made elsewhere -> their :class:`mcbench.io.render_folders.RenderFolder`,
    after checking (headers only, no pixels) that each has every case and its reference, the
    config's resolution, the reference variance the corrected relMSE needs, and every layer of
    every configured method (:func:`mcbench.pipeline.method_runs.needed_layers`)."""
    from mcbench.io.render_folders import AUTHORS_FILES, case_files, image_size, reference_files, reference_names
    from mcbench.pipeline.method_runs import needed_layers

    folders = {}
    for index, scene in enumerate(scenes):
        folder = scene_spec(load_scene(scene, config_key=f"scenes[{index}]")).render_folder
        if folder is None:
            continue
        folders[scene] = folder
        key = f"scenes[{index}] ('{scene}', renders in {folder.path}, {folder.layout} layout)"
        references = reference_files(folder)
        if "color" not in references:
            raise BenchError(f"{key}: no reference image: expected {reference_names(folder)}")
        for metric, spec in load_metrics(config["metrics"]).items():
            if spec.reads_reference_variance and "variance" not in references:
                raise BenchError(f"{key}: metric {metric} needs the reference's variance of the mean "
                                 f"({folder.path / 'reference_variance.exr'}; the OIDN naming has none): supply it "
                                 f"or leave {metric} out of metrics")
        height, width = image_size(references["color"])
        if config["resolution"] is not None and tuple(config["resolution"]) != (width, height):
            raise BenchError(f"resolution: {list(config['resolution'])}, but the renders of scene '{scene}' are "
                             f"{width}x{height} ({references['color']}) and are not resized: set resolution: null "
                             f"(every scene at its own size)")
        layers_in_all = None
        for spp in spps:
            files, missing = case_files(folder, spp)
            if missing:
                raise BenchError(f"{key}: the case at {spp} spp (spp lists it) lacks {', '.join(missing)}")
            for layer, path in files.items():
                size = image_size(path)
                if size != (height, width):
                    raise BenchError(f"{path}: {size[1]}x{size[0]} pixels, but the "
                                     f"reference {references['color']} is {width}x{height}")
            present = set(files) | {"color"}          # the full image: given, or the halves' mean
            layers_in_all = present if layers_in_all is None else layers_in_all & present
        halves = {"color_a", "color_b"} <= layers_in_all
        file_of = {layer: name for name, layer in AUTHORS_FILES.items()}
        for name, spec in methods.items():
            module = load_method(spec["module"])
            needed = needed_layers(module, halves=halves, params=spec.get("params") or {})
            lacking = [layer for layer in needed if layer not in layers_in_all]
            if not lacking and not halves and spec["kind"] == "combiner":
                lacking = ["color_a", "color_b"]    # a combiner weighs its inputs by their halves
            if lacking:
                supply = ", ".join(file_of.get(layer, layer) for layer in lacking)
                raise BenchError(f"method '{name}' ({spec['module']}) reads render layer(s) {lacking}, which scene "
                                 f"'{scene}' lacks (renders in {folder.path}, {folder.layout} layout): supply "
                                 f"{supply} in the authors' layout (mcbench.io.render_folders) or leave '{name}' "
                                 f"or the scene out of this config")
    return folders


def _reference_spp_table(config: dict, scenes: list[str], chunks: int) -> dict[str, int]:
    """Reference spp per configured scene: ``reference.scene_spp[scene]`` or ``reference.spp``.
    ``scene_spp`` may name scenes the config does not run (a narrowed ``scenes:`` keeps working),
    but each must be a scene of scenes/."""
    per_scene = config["reference"]["scene_spp"]
    known = available_scenes()
    for name in per_scene:
        if name not in known:
            raise BenchError(f"reference.scene_spp.{name}: no scene '{name}' in scenes/; "
                             f"available: {', '.join(known)}")
    table = {scene: int(per_scene.get(scene, config["reference"]["spp"])) for scene in scenes}
    for scene, spp in table.items():
        key = f"reference.scene_spp.{scene}" if scene in per_scene else "reference.spp"
        if spp % chunks or (spp // chunks) % 2:
            raise BenchError(f"{key}: {spp} spp must split into {chunks} chunks (reference.chunks) "
                             f"of an even spp each")
    return table


def _reference_key(config: dict, scene: str) -> str:
    """The key that sets ``scene``'s reference spp."""
    return f"reference.scene_spp.{scene}" if scene in config["reference"]["scene_spp"] else "reference.spp"


def _check_reference_above_spp(config: dict, reference_spp: dict[str, int]) -> None:
    """Every scene's reference has more samples than the largest noisy render it scores."""
    top = max(config["spp"])
    where = f"spp[{config['spp'].index(top)}]"
    for scene, spp in reference_spp.items():
        if spp <= top:
            key = _reference_key(config, scene)
            raise BenchError(f"{key}: the reference of '{scene}' has {spp} spp, not more than the {top}-spp renders "
                             f"it scores ({where}); a reference needs more samples than every image it judges: "
                             f"raise {key} or lower spp")


def _check_comparisons(methods: dict) -> None:
    """The comparison tables need one method per role and input set (find_comparisons); the error
    names both entries' config keys instead of stopping the comparison jobs after the run."""
    try:
        find_comparisons(methods)
    except BenchError as error:
        names = re.findall(r"'([A-Za-z][A-Za-z0-9_]*)'", str(error))[:2]
        keys = [methods[name]["config_key"] for name in names if name in methods]
        if len(keys) == 2:
            raise BenchError(f"{keys[1]}: {error} (also {keys[0]}); give one of them other inputs or "
                             f"remove it") from None
        raise


def _check_training(training: dict) -> None:
    """The training section's values that only the training jobs would refuse."""
    first, count = training["first_seed"], training["count"]
    if first + count > FIBRE_SEED_BASE:
        raise BenchError(f"training.count: training.first_seed {first} + training.count {count} passes "
                         f"{FIBRE_SEED_BASE}, where the fibre scenes' seeds start; lower either")
    for index, spp in enumerate(training["spp"]):
        if spp & (spp - 1) or spp > MAX_TRAINING_SPP:
            raise BenchError(f"training.spp[{index}]: {spp} is not a power of two 2..{MAX_TRAINING_SPP} "
                             f"(the training renders' seeds encode log2(spp))")
    width, height = training["resolution"]
    crop = training["crop"]
    if crop > min(width, height):
        raise BenchError(f"training.crop: a {crop}x{crop} crop does not fit training.resolution {width}x{height}")
    cells = (width // crop) * (height // crop)
    for key, crops in (("training.crops", training["crops"]),
                       ("training.combiners.crops", training["combiners"]["crops"])):
        if crops > cells:
            raise BenchError(f"{key}: {crops} disjoint {crop}x{crop} crops do not fit training.resolution "
                             f"{width}x{height} (at most {cells})")


def _rendered_scene(key: str, chosen: str | None, scenes: list[str], rendered: list[str]) -> str | None:
    """The scene a study that renders its scene again uses: ``chosen``, else the first scene
    Mitsuba renders (None: the config has none); refuses a scene of renders made elsewhere."""
    if chosen is not None and chosen in scenes and chosen not in rendered:
        raise BenchError(f"{key}: '{chosen}' is a scene of renders made elsewhere (scenes/{chosen}.yaml); this "
                         f"study renders its scene again: name a scene that Mitsuba renders")
    return chosen or (rendered[0] if rendered else None)


def _oracle(config: dict, scenes: list[str], rendered: list[str],
            reference_spp: dict[str, int]) -> tuple[str | None, int]:
    """The oracle study's scene and downscale (oracle.smk), checked; no scene (None, 1) when the
    config has no scene that Mitsuba renders (the study is then left out)."""
    oracle = config["oracle"]
    scene = _rendered_scene("oracle.scene", oracle["scene"], scenes, rendered)
    if scene is None:
        return None, 1
    if scene not in scenes:
        raise BenchError(f"oracle.scene: '{scene}' is not one of the config's scenes "
                         f"({', '.join(scenes)}); its reference is rendered only for those")
    module = load_scene(scene, config_key="oracle.scene")
    downscale = usable_downscale(config["resolution"], scene_spec(module).size, oracle["downscale"])
    oracle_size(config["resolution"], scene_spec(module).size, downscale)
    for index, name in enumerate(oracle["denoisers"]):
        load_method(name, kind="denoiser", config_key=f"oracle.denoisers[{index}]")
    worth = reference_spp[scene] * downscale ** 2
    if oracle["spp"] >= worth:
        raise BenchError(f"oracle.spp: {oracle['spp']} spp is not below the {worth} spp its reference is worth "
                         f"('{scene}': {reference_spp[scene]} spp averaged over {downscale}x{downscale} blocks); "
                         f"lower oracle.spp or raise {_reference_key(config, scene)}")
    return scene, downscale


def _weights_read(spec: dict) -> tuple[str, ...]:
    """The weights files (names in the weights folder) a method of the method table reads: a
    learned method's own, or what its declaration's ``weights_read`` says for its params."""
    if not spec["learned"]:
        return ()
    declared = method_spec(load_method(spec["module"])).learned
    if declared is None or declared.weights_read is None:
        return (spec["module"],)
    return tuple(declared.weights_read(dict(spec["params"])))


def _progressive_curve(config: dict, scenes: list[str], rendered: list[str], reference_spp: dict[str, int],
                       progressive: dict) -> tuple[str | None, int]:
    """The progressive curve's scene and downscale (progressive.smk), checked; its scene and
    levels only matter when the config has a progressive entry (the curve runs only then)."""
    curve = config["progressive_curve"]
    scene = _rendered_scene("progressive_curve.scene", curve["scene"], scenes, rendered)
    if scene is None:
        if progressive:
            raise BenchError(f"progressive_curve.scene: progressive denoising's curve renders its scene again, and "
                             f"every scene of this config is a folder of renders ({', '.join(scenes)}): add a "
                             f"scene that Mitsuba renders or leave out the progressive entries")
        return None, 1
    if progressive and scene not in scenes:
        raise BenchError(f"progressive_curve.scene: '{scene}' is not one of the config's scenes "
                         f"({', '.join(scenes)}); its reference is rendered only for those")
    module = load_scene(scene, config_key="progressive_curve.scene")
    downscale = usable_downscale(config["resolution"], scene_spec(module).size, curve["downscale"])
    load_method(curve["base"], kind="denoiser", config_key="progressive_curve.base")
    if progressive and curve["divergence"] not in ("none", *single_image_methods()):
        raise BenchError(f"progressive_curve.divergence: '{curve['divergence']}' has no single-image function; "
                         f"name one of none, {', '.join(single_image_methods())}")
    if progressive:
        worth = reference_spp[scene] * downscale ** 2
        top = max(curve["spp"])
        if top >= worth:
            raise BenchError(f"progressive_curve.spp[{curve['spp'].index(top)}]: {top} spp is not below the {worth} "
                             f"spp the curve's reference is worth ('{scene}': {reference_spp[scene]} spp averaged "
                             f"over {downscale}x{downscale} blocks); lower the curve's spp or raise "
                             f"{_reference_key(config, scene)}")
    return scene, downscale


# --------------------------------------------------------------------------- defaults in errors

_KEY = re.compile(r"^(?:config key '(?P<quoted>[^']+)'|(?P<plain>[A-Za-z_][A-Za-z0-9_]*(?:\[\d+\]|\.[^\s:.\[\]()']+)*))")
_PART = re.compile(r"\[(\d+)\]|\.?([^.\[\]]+)")


def _key_parts(key: str) -> list:
    return [int(index) if index else name for index, name in _PART.findall(key)]


def defaulted_key(message: str, written: dict | None, resolved: dict | None = None) -> list | None:
    """The key path (a list of parts) of the schema default that the key leading ``message``
    (``"combiners[3].inputs[1]: ..."``, ``"config key 'scenes[0]': ..."``, ``"study.pool (#27
    ens27).name: ..."``) lies in, when the config as written (``written``) does not set it;
    ``None`` when the config sets it (or ``written`` is not known)."""
    if not isinstance(written, dict):
        return None
    match = _KEY.match(message)
    if not match:
        return None
    parts = _key_parts(match.group("quoted") or match.group("plain"))
    node = written
    for depth, part in enumerate(parts):
        if isinstance(node, dict):
            if part not in node:
                return _default_prefix(parts, depth, resolved)
            node = node[part]
        elif isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
            node = node[part]
        else:
            return None
    return None


def _default_prefix(parts: list, depth: int, resolved: dict | None) -> list | None:
    """``parts[:depth + 1]`` (the first key the config does not set) extended through the
    default's objects as far as the key goes (``reference.spp``, not ``reference``), stopping at
    a list (``combiners``, not ``combiners[3].inputs[1]``); ``None`` if it has no default."""
    node = schema_defaults() if resolved is None else resolved
    for index, part in enumerate(parts):
        if not isinstance(node, dict) or part not in node:
            return None if index <= depth else parts[:index]
        node = node[part]
        if index >= depth and not isinstance(node, dict):
            return parts[:index + 1]
    return parts


def _describe_default(parts: list, resolved: dict | None) -> str:
    node = schema_defaults() if resolved is None else resolved
    for part in parts:
        node = node[part]
    if isinstance(node, (list, dict)) and len(node) > 4:
        return f"the schema's default ({len(node)} entries)"
    return f"the schema's default {node!r}"


def _mentioned_keys(message: str) -> list[str]:
    """The config keys ``message`` names after its leading one: paths with a part below a
    top-level key (``reference.chunks``, ``spp[8]``, ``training.count``)."""
    tops = "|".join(sorted(schema_defaults(), key=len, reverse=True))
    return re.findall(rf"(?<![\w.'\[])((?:{tops})(?:\.[A-Za-z_][A-Za-z0-9_]*|\[\d+\])+)", message)


def default_note(message: str, written: dict | None, resolved: dict | None = None, source: str = "config") -> str:
    """`` [combiners is not set in <source>: it is the schema's default ...; set combiners in
    the config to override it]`` for the key leading ``message`` and each other key it names
    (``reference.chunks``, ``spp[8]``) that holds a value the config never wrote, else ``""``."""
    notes = []
    for text in [message, *_mentioned_keys(message.partition(": ")[2])]:
        parts = defaulted_key(text, written, resolved)
        if parts is None:
            continue
        key = key_path(parts)
        note = (f" [{key} is not set in {source}: it is {_describe_default(parts, resolved)} from "
                f"workflow/schemas/config.schema.yaml; set {key} in the config to override it]")
        if note not in notes:
            notes.append(note)
    return "".join(notes)
