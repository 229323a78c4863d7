"""The plan of a study as typed values: what ``workflow/rules/*.smk`` read from a resolved config.

:func:`mcbench.pipeline.plan.plan_study` builds a :class:`StudyPlan` (every check that stops a
config before any job happens there); the rules read their names from it and build each case's
job with :meth:`StudyPlan.case_job`. Everything here is a frozen value computed from the config
alone: nothing is read from ``results/`` and nothing is written, so the rules are the same in
the main Snakemake process, a SLURM job and a spawned job, whatever exists.

Vocabulary (``docs/architecture.md``): a *case* is a scene at one spp; a *method* is a base
denoiser or a combiner of the config; a *candidate* is a method whose output is scored (every
method of the config); an *entry* is a row of a case's tables: the noisy input or a candidate.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

from mcbench import METRICS_COLUMNS, NOISY
from mcbench.io.weights import COMMITTED_WEIGHTS, WEIGHTS_SUFFIX

__all__ = ["frozen_mapping", "MethodPlan", "CasePlan", "RankingPlan", "TrainingPlan", "SideStudyPlan", "StudyPaths", "StudyPlan",
           "weights_digest"]


def frozen_mapping(mapping: Mapping) -> Mapping:
    """A read-only view of a copy of ``mapping`` (a plan's tables are not edited after planning)."""
    return MappingProxyType(dict(mapping))


@dataclass(frozen=True)
class MethodPlan:
    """One method of the config: ``kind`` ("denoiser" or "combiner"), its ``module`` (plugin
    file name), ``params``, ``inputs`` (method names, earlier in the plan), table ``label``,
    whether it is ``learned`` (reads weights), the ``config_key`` it comes from and its role in
    the Sec. 5.2 comparisons (``comparison_role``, declared by its module) and the weights files
    it reads (``weights``: names in the weights folder; a learned method's own, or what its
    declaration's ``weights_read`` says for its params)."""

    name: str
    kind: str
    module: str
    params: Mapping
    inputs: tuple[str, ...]
    label: str
    learned: bool
    config_key: str = ""
    comparison_role: str | None = None
    weights: tuple[str, ...] = ()

    def as_dict(self) -> dict:
        """The method as plain data (for a script's params or a table)."""
        return {"kind": self.kind, "module": self.module, "params": dict(self.params), "inputs": list(self.inputs),
                "label": self.label, "learned": self.learned, "comparison_role": self.comparison_role}


@dataclass(frozen=True)
class CasePlan:
    """The test cases: ``scenes`` (config order) x ``spps`` (sorted); the reference spp of each
    rendered scene (None for a folder of renders made elsewhere), its chunks, the folders of
    imported scenes and each scene's image size."""

    scenes: tuple[str, ...]
    spps: tuple[int, ...]
    reference_spp: Mapping
    reference_chunks: int
    render_folders: Mapping
    resolutions: Mapping = field(default_factory=lambda: frozen_mapping({}))   # scene -> (width, height)
    reference_sources: Mapping = field(default_factory=lambda: frozen_mapping({}))   # scene -> store|render|folder
    stored_references: Mapping = field(default_factory=lambda: frozen_mapping({}))   # scene -> store record path
    reference_notes: tuple = ()                                       # why each reference comes from where
    keep_outputs: str = "read"                                        # read | all (config keep_outputs)

    def reference_source(self, scene: str) -> str:
        """Where the reference of ``scene`` comes from: ``store``, ``render`` or ``folder``."""
        return self.reference_sources.get(scene, "folder" if scene in self.render_folders else "render")

    @property
    def rendered_references(self) -> list[str]:
        """The scenes whose reference this run renders (chunks, then their merge)."""
        return [scene for scene in self.scenes if self.reference_source(scene) == "render"]

    @property
    def stored_scenes(self) -> list[str]:
        """The scenes whose reference comes from the store (and is checked against this run's render)."""
        return [scene for scene in self.scenes if self.reference_source(scene) == "store"]

    def pixels(self, scene: str) -> int:
        """Pixels of a scene's images (the config's resolution, else the scene's own)."""
        width, height = self.resolutions[scene]
        return int(width) * int(height)

    @property
    def pairs(self) -> list[tuple[str, int]]:
        """(scene, spp) of every case, scene-major."""
        return [(scene, spp) for scene in self.scenes for spp in self.spps]

    @property
    def rendered_scenes(self) -> list[str]:
        return [scene for scene in self.scenes if scene not in self.render_folders]

    @property
    def case_list(self) -> list[dict]:
        """Every case as ``{"scene": ..., "spp": ...}``, scene-major (a rule's params)."""
        return [{"scene": scene, "spp": spp} for scene, spp in self.pairs]

    def chunk_spp(self, scene: str) -> int:
        """The samples of one reference chunk of a rendered scene."""
        return self.reference_spp[scene] // self.reference_chunks


@dataclass(frozen=True)
class RankingPlan:
    """What the tables rank: every ``candidate`` (plan order), the ``ranked`` pool and the
    ``extras`` scored beside it, whether the pool is the paper's (``pool_study``) and its note,
    the table ``labels`` of every entry and the ``metrics``."""

    candidates: tuple[str, ...]
    ranked: tuple[str, ...]
    extras: tuple[str, ...]
    pool_study: bool
    pool_note: str
    labels: Mapping
    metrics: tuple[str, ...]

    @property
    def entries(self) -> list[str]:
        """A case's entries: the noisy input, then every candidate."""
        return [NOISY, *self.candidates]

    @property
    def ranked_entries(self) -> list[str]:
        """The entries of the ranking tables: the noisy input, then the ranked pool."""
        return [NOISY, *self.ranked]

    @property
    def table_order(self) -> list[str] | None:
        """The ranking tables' row order: with the paper's pool, the pool then the noisy input
        (ID order); else None (by score)."""
        return [*self.ranked, NOISY] if self.pool_study else None

    @property
    def speed_metric(self) -> str:
        """The speed-against-error figure's metric: relMSE (the paper's), else the first metric."""
        return "relmse" if "relmse" in self.metrics else self.metrics[0]

    @property
    def progressive_metrics(self) -> list[str]:
        """The metrics of progressive denoising's tables: relMSE and SMAPE where configured, else
        the first metric."""
        return [m for m in ("relmse", "smape") if m in self.metrics] or list(self.metrics[:1])


@dataclass(frozen=True)
class TrainingPlan:
    """The training crops' ``settings`` and ``seeds``, per-network ``overrides``, the learned
    ``networks`` of the config, and the learned combiners' crops (``combiner_settings``,
    ``combiner_seeds``)."""

    settings: Mapping
    seeds: tuple[int, ...]
    overrides: Mapping
    networks: tuple[str, ...]
    combiner_settings: Mapping
    combiner_seeds: tuple[int, ...]


@dataclass(frozen=True)
class SideStudyPlan:
    """The oracle study's and progressive denoising's scenes and downscale factors (None when the
    config has none), and progressive denoising's entries (entry -> the method it mixes)."""

    oracle_scene: str | None
    oracle_downscale: int | None
    progressive: Mapping
    progressive_scene: str | None
    progressive_downscale: int | None


@dataclass(frozen=True)
class StudyPaths:
    """Where a study's files go, relative to the working directory: a case's render and
    reference, each method's output and timing record, each entry's kept metric values and viewer
    images, the case job's outputs, and the learned methods' weights (``weights_dir``: the
    config key of that name, or the committed ``methods/weights`` when it is empty)."""

    results: str = "results"
    weights_dir: str = str(COMMITTED_WEIGHTS)

    def weights(self, module: str) -> str:
        """The weights file of learned method module ``module``."""
        return f"{self.weights_dir}/{module}{WEIGHTS_SUFFIX}"

    def render(self, scene: str, spp: int) -> str:
        return f"{self.results}/renders/{scene}/spp{spp}.exr"

    def reference(self, scene: str) -> str:
        return f"{self.results}/references/{scene}.exr"

    def method_output(self, scene: str, spp: int, method: str) -> str:
        return f"{self.results}/outputs/{scene}/spp{spp}/{method}.exr"

    def method_timing(self, scene: str, spp: int, method: str) -> str:
        return f"{self.results}/outputs/{scene}/spp{spp}/{method}.json"

    def entry_values(self, scene: str, spp: int, entry: str) -> str:
        return f"{self.results}/metrics/{scene}/spp{spp}/values/{entry}.json"

    def entry_viewer(self, scene: str, spp: int, entry: str) -> str:
        return f"{self.results}/viewer_entries/{scene}/spp{spp}/{entry}"

    def entry_image(self, scene: str, spp: int, entry: str) -> str:
        """The image an entry's evaluation reads: the render for the noisy input, else the method's output."""
        return self.render(scene, spp) if entry == NOISY else self.method_output(scene, spp, entry)


@dataclass(frozen=True)
class StudyPlan:
    """Everything the rules plan for a resolved config (:func:`mcbench.pipeline.plan.plan_study`)."""

    methods: Mapping  # name -> MethodPlan, in dependency order
    cases: CasePlan
    ranking: RankingPlan
    training: TrainingPlan
    side: SideStudyPlan
    paths: StudyPaths = field(default_factory=StudyPaths)

    def case_plan(self, weights_sha256: Mapping) -> dict:
        """What a case's job depends on besides its files (the same for every case; rule
        run_case's params): the methods in dependency order with their settings and, for a
        learned method, the SHA-256 of the weights it reads (``weights_sha256``: weights name ->
        digest, :meth:`weights_names`), the entries, the metrics and the columns of the case's
        metrics table (a table written with other columns is remade)."""
        return {"methods": [{"name": m.name, "module": m.module, "params": dict(m.params), "inputs": list(m.inputs),
                             **({"weights_sha256": weights_digest(m.weights, weights_sha256)} if m.learned else {})}
                            for m in self.methods.values()],
                "entries": self.ranking.entries, "metrics": list(self.ranking.metrics),
                "table_columns": list(METRICS_COLUMNS), "keep_outputs": self.cases.keep_outputs}

    def case_job(self, scene: str, spp: int, *, outputs: Mapping) -> dict:
        """The description of one case's job (:func:`mcbench.pipeline.cases.run_case`): its
        render and reference, its methods in dependency order with their files and weights
        (:meth:`StudyPaths.weights` for a learned method: the file its key covers and its run
        reads), its entries' evaluations and the job's ``outputs`` (``metrics``, ``viewer``, ``record``)."""
        paths, spp = self.paths, int(spp)
        methods = [{"name": m.name, "module": m.module, "params": dict(m.params), "inputs": list(m.inputs),
                    "weights": paths.weights(m.module) if m.learned else None,
                    "weights_read": [paths.weights(name) for name in m.weights],
                    "exr": paths.method_output(scene, spp, m.name), "timing": paths.method_timing(scene, spp, m.name)}
                   for m in self.methods.values()]
        entries = [{"entry": entry, "image": paths.entry_image(scene, spp, entry),
                    "values": paths.entry_values(scene, spp, entry), "viewer": paths.entry_viewer(scene, spp, entry),
                    "weight_inputs": list(self.methods[entry].inputs) if entry in self.methods else []}
                   for entry in self.ranking.entries]
        return {"scene": scene, "spp": spp, "render": paths.render(scene, spp), "reference": paths.reference(scene),
                "metrics": list(self.ranking.metrics), "methods": methods, "entries": entries,
                "keep_outputs": self.cases.keep_outputs,
                "outputs": {key: str(outputs[key]) for key in ("metrics", "viewer", "record")}}

    @property
    def method_inputs(self) -> dict[str, list[str]]:
        """Each method's input methods (method name -> names)."""
        return {name: list(m.inputs) for name, m in self.methods.items()}

    @property
    def comparison_methods(self) -> dict[str, dict]:
        """The method table the comparison tables read: each method's module, kind, inputs,
        params, label and comparison role."""
        return {name: {key: m.as_dict()[key] for key in ("module", "kind", "inputs", "params", "label",
                                                         "comparison_role")}
                for name, m in self.methods.items()}

    def weights_names(self) -> list[str]:
        """The weights files the methods read (names in the weights folder), each once, in plan order."""
        return list(dict.fromkeys(name for m in self.methods.values() for name in m.weights))


def weights_digest(names, digests: Mapping) -> str:
    """The digest of the weights ``names`` a method reads: the SHA-256 of the one file (of its own
    weights, as a method reading only those has it), else the files' digests joined by ``+``."""
    return digests[names[0]] if len(names) == 1 else "+".join(digests[name] for name in names)
