"""A study as the workflow sets it up: the resolved config, its plan, the weights folder, the
resource requests, and the logic of the rules' input functions.

``workflow/rules/common.smk`` builds one :class:`StudySetup` with :func:`setup_study` when the
Snakefile is parsed and reads everything else from it and from its plan
(:class:`mcbench.pipeline.study_plan.StudyPlan`); its ``get_*`` input functions unpack Snakemake's
wildcards and call the methods here. Parsing reads the config and the package's own files (the
schema, the fitted job costs) and nothing under ``results/``. The input functions run while the
DAG is built: they look at the weights files only (a learned method's weights must exist before
a case runs it, and ``train_<network>`` trains only missing weights).
"""

from __future__ import annotations

import copy
import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

from mcbench import NOISY, BenchError
from mcbench.analysis.study.study_figures import STUDY_FIGURES, curve_candidates, paper_recommended
from mcbench.contracts.method import method_spec
from mcbench.io.weights import check_trained_features, file_sha256, is_learned_method
from mcbench.pipeline.config import config_digest, resolve_config
from mcbench.pipeline.plan import plan_study
from mcbench.pipeline.reference_sources import STORE_FOLDER
from mcbench.pipeline.registry import available_metrics, load_method, load_metric
from mcbench.pipeline.rendering import folder_case_files, folder_reference_files
from mcbench.pipeline.resources import StudyRequests, load_job_costs
from mcbench.pipeline.study_plan import StudyPlan
from mcbench.pipeline.training import SURE_SUFFIX

__all__ = ["METRIC_PATTERN", "STUDY_FIGURES", "StudySetup", "setup_study"]

#: The ``metric`` wildcard's pattern: any metric plugin of ``metrics/``.
METRIC_PATTERN = "|".join(available_metrics())


@dataclass(frozen=True)
class StudySetup:
    """A resolved ``config`` (schema defaults filled in, validated), its ``source`` (the config
    files), its ``plan``, the learned methods' ``weights_dir`` and the jobs' ``requests``."""

    config: Mapping
    source: str
    plan: StudyPlan
    weights_dir: str
    requests: StudyRequests
    _digests: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def digest(self) -> str:
        """The resolved config's digest (:func:`mcbench.pipeline.config.config_digest`)."""
        return config_digest(dict(self.config))

    @property
    def summary(self) -> str:
        """What the workflow logs when it is parsed: the config's files and digest, and where the
        references come from (the reference store or this run's renders, and why)."""
        lines = [f"mcbench: configuration {self.source} with the schema's defaults, digest {self.digest}"]
        return "\n".join(lines + [f"mcbench: {note}" for note in self.plan.cases.reference_notes])

    @property
    def feature_params(self) -> dict:
        """The render rules' ``features`` param: empty for the default ``first_hit`` convention
        (the params of a finished study's renders stay the same), ``{"features": <convention>}``
        otherwise (the params trigger reruns every render, and what follows, when it changes)."""
        features = self.config["features"]
        return {} if features == "first_hit" else {"features": features}

    @functools.cached_property
    def metric_labels(self) -> dict[str, str]:
        """How the report's captions name each configured metric: its plugin's label."""
        return {name: load_metric(name).label for name in self.plan.ranking.metrics}

    # -- learned methods' weights ----------------------------------------------------------------

    def weights_file(self, module: str) -> str:
        """The weights file of method module ``module`` in the weights folder."""
        return f"{self.weights_dir}/{module}.pt"

    def check_weights(self, name: str) -> None:
        """Raise :class:`mcbench.BenchError` naming the folder when learned method ``name`` has no
        weights (a mistyped ``weights_dir`` would otherwise plan hours of training renders), or
        when its weights were trained on other features than the config's."""
        spec = self.plan.methods[name]
        if not spec.learned:
            return
        if not Path(self.weights_file(spec.module)).exists():
            raise BenchError(f"no weights for {spec.module} in {self.weights_dir} (weights_dir); train them "
                             f"with `snakemake --cores 2 train_{spec.module}` or fix weights_dir")
        check_trained_features(Path(self.weights_dir) / f"{spec.module}.json", self.config["features"],
                               name=spec.module)

    def weights_sha256(self, module: str) -> str:
        """SHA-256 of the weights of method module ``module`` ("" when it has none), computed once
        per file and modification time."""
        path = Path(self.weights_file(module))
        if not path.exists():
            return ""
        key = (str(path), path.stat().st_mtime_ns)
        if key not in self._digests:
            self._digests[key] = file_sha256(path)
        return self._digests[key]

    def missing_weights(self, network: str) -> list[str]:
        """The weights file of ``network`` if it is missing, else nothing: ``train_<network>``
        trains only what is missing."""
        path = self.weights_file(network)
        return [] if Path(path).exists() else [path]

    @functools.cached_property
    def case_plan(self) -> dict:
        """Rule run_case's params (:meth:`StudyPlan.case_plan`), the same for every case: new
        weights rerun every case. Checks first that every learned method has its weights."""
        for name in self.plan.methods:
            self.check_weights(name)
        return self.plan.case_plan({module: self.weights_sha256(module) for module in self.plan.weights_names()})

    def case_job(self, scene: str, spp: int, outputs: Mapping) -> dict:
        """What run_case's job makes in one case (:meth:`StudyPlan.case_job`)."""
        return self.plan.case_job(scene, int(spp), outputs=outputs)

    # -- training --------------------------------------------------------------------------------

    def combiner_bases(self, network: str) -> tuple[str, ...]:
        """The base denoisers a learned combiner is trained on (its declared ``correlated_bases``);
        () for a denoiser."""
        if network not in self.plan.training.networks:
            return ()
        return tuple(method_spec(load_method(network)).learned.correlated_bases or ())

    def trained_networks(self, *, combiners: bool) -> tuple[str, ...]:
        """The config's trained networks that are learned combiners (``combiners=True``: they
        train on their bases' results) or denoisers. Two rules train them: a rule may not depend
        on itself in Snakemake, and a combiner's inputs need a learned base's weights."""
        return tuple(name for name in self.plan.training.networks if bool(self.combiner_bases(name)) == combiners)

    def base_weights(self, base: str) -> list[str]:
        """The weights file that a combiner's base ``base`` (``<name>`` or ``<name>+sure``) makes its
        correlated training inputs with, while it is missing: an input of those inputs, so that a
        base trained in the same run (``train_<base>``) comes first and is what the combiner learns
        from. Nothing once the weights exist (weights made by another run, e.g. ``train_<base>``
        before ``train_<combiner>``, remake the inputs through their digest, a parameter of the
        rule): as an input, existing weights would put their training job in the DAG, and under
        Snakemake's ``input`` rerun trigger that job (whose planned inputs are none once its weights
        exist, :meth:`train_inputs`) runs again, deleting the weights first. Nothing for a base
        that learns nothing."""
        name = base.removesuffix(SURE_SUFFIX)
        return self.missing_weights(name) if is_learned_method(load_method(name)) else []

    def training_crops(self, patterns: list[str]) -> list[str]:
        """The training crops of every training seed (``patterns``: the crop files of one seed)."""
        return [pattern.format(seed=seed) for pattern in patterns for seed in self.plan.training.seeds]

    def combiner_crops(self, patterns: list[str], **wildcards) -> list[str]:
        """The crops the learned combiners train on: the first ``training.combiners.crops`` of
        ``patterns`` (the files of one seed) for each of their seeds, with ``wildcards``."""
        training = self.plan.training
        return [patterns[k].format(seed=seed, **wildcards)
                for seed in training.combiner_seeds for k in range(training.combiner_settings["crops"])]

    def train_inputs(self, network: str, crops: list[str], correlated: list[str]) -> dict[str, list[str]]:
        """The training inputs of ``network`` while its weights are missing, none once they exist:
        its crops (``crops``: the patterns of one seed's crops), and for a learned combiner the
        combiners' crops and its bases' results on them (``correlated``: their patterns)."""
        if not self.missing_weights(network):
            return {}
        bases = self.combiner_bases(network)
        if not bases:
            return {"crops": self.training_crops(crops)}
        return {"crops": self.combiner_crops(crops),
                **{f"correlated_{base}": self.combiner_crops(correlated, base=base) for base in bases}}

    # -- renders and references ------------------------------------------------------------------

    def imported_case_files(self, scene: str, spp: int) -> list[str]:
        """The folder's files of an imported case; nothing for a scene that Mitsuba renders."""
        folder = self.plan.cases.render_folders.get(scene)
        return [] if folder is None else folder_case_files(folder, int(spp))

    def reference_inputs(self, scene: str, chunk: str) -> list[str]:
        """A reference's inputs: its chunks (``chunk``: their pattern) for a rendered reference, the
        store's EXR for a stored one (its record, read through the rule's params, is not an input:
        it is rule store_reference's output, and as an input it would make the run's DAG render the
        reference again to store it, with ``--forceall`` or from a folder where the store's path
        reads alike), the folder's reference files for an imported one."""
        cases = self.plan.cases
        source = cases.reference_source(scene)
        if source == "render":
            return self.reference_inputs_rendered(scene, chunk)
        if source == "store":
            return [str(Path(cases.stored_references[scene]).with_suffix(".exr"))]
        return folder_reference_files(cases.render_folders[scene])

    def store_inputs(self, scene: str, chunk: str, merged: str) -> list[str]:
        """What rule store_reference stores of ``scene``: the reference this run merges from its
        chunks (``merged``: its pattern) where this run renders it, so that a finished run's
        references are stored without rendering them again; else (a scene whose reference this
        run takes from the store) its chunks (``chunk``: their pattern), rendered afresh."""
        if self.plan.cases.reference_source(scene) == "render":
            return [merged.format(scene=scene)]
        return self.reference_inputs_rendered(scene, chunk)

    def reference_inputs_rendered(self, scene: str, chunk: str) -> list[str]:
        """The chunks (``chunk``: their pattern) of ``scene``'s reference as this config renders
        them, whatever the reference's source (the store's input, rule store_reference)."""
        if scene in self.plan.cases.render_folders:
            raise BenchError(f"scene '{scene}' is a folder of renders made elsewhere: its reference is not stored")
        return [chunk.format(scene=scene, chunk=k) for k in range(self.plan.cases.reference_chunks)]

    def reference_checks(self, scene: str, check: str) -> list[str]:
        """The check of a stored reference (``check``: its pattern) that a case of ``scene`` waits
        for; nothing for a reference rendered here or imported."""
        return [check.format(scene=scene)] if self.plan.cases.reference_source(scene) == "store" else []

    def checked_render(self, scene: str, render: str) -> str:
        """The render a stored reference is checked against: this run's highest-spp render of
        ``scene`` (``render``: the renders' pattern)."""
        return render.format(scene=scene, spp=max(self.plan.cases.spps))

    @property
    def stored_scene_pattern(self) -> str:
        """The ``scene`` wildcard of rule stored_reference: the scenes whose reference comes from
        the store (a pattern that matches nothing when there is none)."""
        stored = self.plan.cases.stored_scenes
        return f"(?:{'|'.join(stored)})(?![A-Za-z0-9_])" if stored else "(?!x)x"

    @property
    def merged_scene_pattern(self) -> str:
        """The ``scene`` wildcard of rule merge_reference: every scene name but the stored ones (a
        name is excluded where no name character follows it: the wildcard sits inside a path)."""
        stored = self.plan.cases.stored_scenes
        return (f"(?!(?:{'|'.join(stored)})(?![A-Za-z0-9_]))" if stored else "") + "[A-Za-z][A-Za-z0-9_]*"

    @property
    def store_folder(self) -> str:
        """The reference store's folder (``reference.store``, else the repository's ``references/``),
        relative to the working directory when it lies below it."""
        folder = Path(self.config["reference"]["store"] or STORE_FOLDER).resolve()
        return str(folder.relative_to(Path.cwd())) if folder.is_relative_to(Path.cwd()) else str(folder)

    def store_records(self, pattern: str) -> list[str]:
        """The store records ``store_references`` writes (``pattern``: rule store_reference's
        output, wildcards ``resolution`` and ``scene``): one per scene this run can render."""
        cases = self.plan.cases
        return [pattern.format(resolution="{}x{}".format(*cases.resolutions[scene]), scene=scene)
                for scene in cases.scenes if scene not in cases.render_folders]

    def render_cost_records(self, noisy: str, chunk: str) -> dict[str, list[str]]:
        """The benchmark records of the noisy renders and of the reference chunks this run renders
        (``noisy``, ``chunk``: their patterns), the scene table's CPU-hours."""
        cases = self.plan.cases
        return {"noisy": [noisy.format(scene=scene, spp=spp) for scene, spp in cases.pairs],
                "reference": [chunk.format(scene=scene, chunk=k) for scene in cases.rendered_references
                              for k in range(cases.reference_chunks)]}

    # -- tables and figures ----------------------------------------------------------------------

    @property
    def curve_entries(self) -> list[str]:
        """The error curves' lines: the noisy input and, with the paper's pool, its bases and the
        paper's recommended ensembles (40 lines would hide each other), otherwise every ranked
        candidate."""
        ranking = self.plan.ranking
        if not ranking.pool_study:
            return [NOISY, *ranking.ranked]
        return [NOISY, *(name for name in curve_candidates(paper_recommended()) if name in ranking.ranked)]

    # -- cluster resources -----------------------------------------------------------------------

    def resources(self, rule: str) -> dict:
        """The ``resources:`` of a rule's jobs (:meth:`StudyRequests.request`): mem_mb and runtime
        as functions of the job's wildcards and attempt, and the GPUs of a rendering rule."""
        requests = self.requests

        def request(wildcards, attempt):
            return requests.request(rule, scene=getattr(wildcards, "scene", None), spp=getattr(wildcards, "spp", None),
                                    network=getattr(wildcards, "network", None), attempt=attempt)

        return {"mem_mb": lambda wildcards, attempt: request(wildcards, attempt)["mem_mb"],
                "runtime": lambda wildcards, attempt: request(wildcards, attempt)["runtime"],
                **requests.gpu_resources(rule)}

    def case_resources(self) -> dict:
        """The ``resources:`` of a case's job (:meth:`StudyRequests.case_request`)."""
        requests = self.requests
        return {"mem_mb": lambda wildcards, attempt: requests.case_request(wildcards.scene, attempt=attempt)["mem_mb"],
                "runtime": lambda wildcards, attempt: requests.case_request(wildcards.scene, attempt=attempt)["runtime"]}


def setup_study(config: Mapping, *, source: str = "config") -> StudySetup:
    """The study of ``config`` as its file gave it: resolved with the schema's defaults and
    validated (:func:`mcbench.pipeline.config.resolve_config`), planned with every check that
    stops a config before any job (:func:`mcbench.pipeline.plan.plan_study`; errors name
    ``source`` and the key, and say so when the key holds a default the config never wrote).
    Learned methods' weights: ``weights_dir``, else the committed ``methods/weights``."""
    written = copy.deepcopy(dict(config))
    resolved = resolve_config(dict(config), source=source)
    plan = plan_study(resolved, written=written, source=source, is_learned=is_learned_method)
    requests = StudyRequests(plan, load_job_costs(), gpus=resolved["gpus"], gpu_model=resolved["gpu_model"] or "",
                             variant=resolved["variant"])
    return StudySetup(config=resolved, source=source, plan=plan,
                      weights_dir=plan.paths.weights_dir, requests=requests)
