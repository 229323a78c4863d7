"""The method plugin contract: :class:`MethodSpec`, what every ``methods/<name>.py`` exports as
its module-level ``METHOD``, and :class:`LearnedSpec`, what a learned method adds in its
``learned=`` field (its network, how it is trained).

Constructing either checks the names (a misspelt field is refused with the closest known name; a
learned method's field given to :class:`MethodSpec` is refused naming ``learned=LearnedSpec(...)``)
and every value against its annotation, so a plugin that imports has a well-formed declaration.
The registry (``methods/__init__.py``) reads ``METHOD`` through :func:`method_spec` and refuses a
module whose top level defines a hook of the contract that the declaration does not carry
(:func:`stray_hooks`). Consumers below the plugins receive the module or its declaration, never a
method's name. Importing this module imports neither torch nor any plugin.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from types import ModuleType
from typing import Callable, Literal, NewType, Optional

from mcbench import BenchError
from mcbench.contracts.fields import SpecError, checked, declaration, field_names

__all__ = ["KINDS", "SPEC_ATTRIBUTE", "WEIGHTS_ARGUMENT", "COMPARISON_ROLES", "SingleImageDenoiser", "MethodSpec",
           "LearnedSpec", "SpecError", "method_spec", "stray_hooks"]

#: The kinds of method and the name of the function each one's ``run`` is by convention.
KINDS = {"denoiser": "denoise", "combiner": "combine"}
#: The module-level name of a plugin's declaration.
SPEC_ATTRIBUTE = "METHOD"
#: The keyword argument through which the runner hands a learned method's ``run`` its weights file.
WEIGHTS_ARGUMENT = "weights_file"
#: The annotation of a config parameter naming a single-image denoiser (:attr:`MethodSpec.single_image`);
#: the registry checks a config's value against the methods that declare themselves so.
SingleImageDenoiser = NewType("SingleImageDenoiser", str)
#: What a combiner is in the comparison tables of Zheng et al. Sec. 5.2 (``mcbench.analysis.comparison_tables``).
COMPARISON_ROLES = ("ensemble", "one-hot selection", "naive average")


@checked
@dataclass(frozen=True, kw_only=True, eq=False)
class LearnedSpec:
    """What a learned method adds (``METHOD = MethodSpec(..., learned=LearnedSpec(...))``):

    * ``network`` -- the architecture hyperparameters, ``build_network(**network)``.
    * ``build_network`` -- ``f(**network) -> torch.nn.Module``; importing the plugin must not
      import torch (the classes come from a cached ``network_classes()``).
    * ``training`` -- the training settings (keys of ``mcbench.nn.train.DEFAULT_SETTINGS``).
    * ``critic``, ``build_critic`` -- the critic of adversarial training and its builder (together).
    * ``augment_batch`` -- ``f(batch: dict, rng) -> dict``: the method's own augmentation of each
      training batch.
    * ``correlated_bases`` -- a learned combiner's base denoisers, whose results on the training
      crops it is trained on.
    * ``training_keys`` -- a learned combiner's extra network inputs ``{key: channels}``
      (``mcbench.nn.crops``).
    * ``weights_read`` -- ``f(params) -> tuple[str, ...]``: the weights files (names in the
      weights folder, without ``.pt``) the method reads with these params, when that is not just
      its own (a variant's network, a learned base it re-runs); the case's key covers each.

    The method's ``run`` takes the keyword ``weights_file`` (:data:`WEIGHTS_ARGUMENT`): the runner
    passes the weights the case's key covers (``<weights_dir>/<name>.pt``).
    """

    network: dict
    build_network: Callable
    training: dict
    critic: Optional[dict] = None
    build_critic: Optional[Callable] = None
    augment_batch: Optional[Callable] = None
    correlated_bases: Optional[tuple[str, ...]] = None
    training_keys: Optional[dict[str, int]] = None
    weights_read: Optional[Callable] = None

    def __post_init__(self) -> None:
        if (self.critic is None) != (self.build_critic is None):
            raise SpecError("LearnedSpec fields critic, build_critic go together: one is set, the other not")


_LEARNED_FIELDS = {name: "learned=LearnedSpec(...) (a learned method's field)" for name in field_names(LearnedSpec)}


@checked(elsewhere=_LEARNED_FIELDS)
@dataclass(frozen=True, kw_only=True, eq=False)
class MethodSpec:
    """What a method module declares (``METHOD = MethodSpec(...)``); fields, keyword-only:

    * ``kind`` -- ``"denoiser"`` or ``"combiner"``.
    * ``label`` -- the name shown in tables (a stand-in says so, e.g. ``"OptiX† (our autoencoder)"``).
    * ``run`` -- a denoiser's ``denoise(buffers: RenderBuffers, *, <params>) -> Denoised`` (the
      denoised full image and the two denoised half buffers) or a combiner's
      ``combine(buffers, inputs: list[Denoised], *, <params>) -> Denoised``. Its keyword
      parameters after ``buffers`` (and ``inputs``), each annotated, are the method's config
      parameters (``methods.check_params``); ``name``, ``scene`` and ``spp`` receive the method's
      config name and the case unless the config sets them; ``weights_file`` is a learned
      method's weights, passed by the runner.
    * ``render_layers`` -- the render layers the method reads (None: all).
    * ``image_quantities`` -- a single-image denoiser (one that filters each of the full image and
      the halves on its own) names the quantities it reads of each image, e.g.
      ``("color", "albedo", "normal")``; it may then run on renders imported without half buffers.
    * ``denoise_image`` -- ``f(ImageBuffers) -> (H, W, 3)`` radiance with default params: the
      method on one image (progressive denoising's divergence re-runs it). A learned denoiser's
      network is such a function too (:attr:`single_image`).
    * ``check_config`` -- ``f(params, *, config_key)``: checks of param values no annotation
      describes (raise ``ValueError`` naming ``config_key``), run when the DAG is parsed.
    * ``params_layers`` -- ``f(params) -> tuple[str, ...]``: render layers the method needs with
      these params beyond what ``render_layers`` / ``image_quantities`` say.
    * ``warm_up`` -- False: no untimed warm-up run on a crop before the timed run.
    * ``program_seconds`` -- ``f() -> float``: the recorded time of a run is what it returns
      after the run (an external program's wall time), not the wall time of ``run``.
    * ``required_files`` -- ``f(params, *, name, scene, spp) -> list[str]``: files each case
      needs, checked when the DAG is parsed.
    * ``reads_rows`` -- True: the method reads its render and inputs by rows inside ``run``.
    * ``inputs`` -- a combiner that combines exactly this many inputs (None: any number).
    * ``comparison_role`` -- what a combiner is in the Sec. 5.2 comparison tables (one of
      :data:`COMPARISON_ROLES`; None: in none).
    * ``learned`` -- a learned method's network and training (:class:`LearnedSpec`).
    """

    kind: Literal["denoiser", "combiner"]
    label: str
    run: Callable
    render_layers: Optional[tuple[str, ...]] = None
    image_quantities: Optional[tuple[str, ...]] = None
    denoise_image: Optional[Callable] = None
    check_config: Optional[Callable] = None
    params_layers: Optional[Callable] = None
    warm_up: bool = True
    program_seconds: Optional[Callable] = None
    required_files: Optional[Callable] = None
    reads_rows: bool = False
    inputs: Optional[int] = None
    comparison_role: Optional[Literal["ensemble", "one-hot selection", "naive average"]] = None
    learned: Optional[LearnedSpec] = None

    def __post_init__(self) -> None:
        if not self.label:
            raise SpecError("MethodSpec field 'label' must not be empty")
        if self.kind != "combiner" and (self.inputs is not None or self.comparison_role is not None):
            raise SpecError(f"MethodSpec fields inputs, comparison_role are for a combiner, set for a {self.kind}")
        if self.inputs is not None and self.inputs < 1:
            raise SpecError(f"MethodSpec field 'inputs' must be at least 1, got {self.inputs}")
        if self.learned is not None:
            combiner_fields = (self.learned.correlated_bases, self.learned.training_keys)
            if self.kind == "combiner" and None in combiner_fields:
                raise SpecError("LearnedSpec of a combiner sets correlated_bases and training_keys")
            if self.kind == "denoiser" and combiner_fields != (None, None):
                raise SpecError("LearnedSpec fields correlated_bases, training_keys are for a learned combiner")
        takes_weights = WEIGHTS_ARGUMENT in inspect.signature(self.run).parameters
        if takes_weights != (self.learned is not None):
            raise SpecError(f"MethodSpec field 'run': a learned method's run takes the keyword "
                            f"'{WEIGHTS_ARGUMENT}' (its weights, passed by the runner), any other method's not; "
                            f"{getattr(self.run, '__name__', 'run')}() {'does' if takes_weights else 'does not'}")

    @property
    def single_image(self) -> bool:
        """Whether the method is a denoiser that runs on one image alone: it declares
        ``denoise_image``, or it is a learned denoiser (its network takes one image's buffers)."""
        return self.kind == "denoiser" and (self.denoise_image is not None or self.learned is not None)


#: Module-level names of the contract's hooks besides each field's own name and its upper case
#: (``render_layers``/``RENDER_LAYERS``): a module defining one of them at its top level that its
#: declaration does not carry is refused (:func:`stray_hooks`).
_OTHER_HOOK_NAMES = {"run": tuple(KINDS.values()), "program_seconds": ("TIMES_ITSELF",)}


def _declared_hooks(spec: MethodSpec) -> dict:
    """Every field of ``spec`` and of its :class:`LearnedSpec` (None when it has none) by name."""
    hooks = {name: getattr(spec, name) for name in field_names(MethodSpec) if name != "learned"}
    hooks.update({name: getattr(spec.learned, name, None) for name in field_names(LearnedSpec)})
    return hooks


def stray_hooks(module: ModuleType, spec: MethodSpec) -> list[str]:
    """Top-level names of ``module`` that are hooks of the contract (a field's name, in lower or
    upper case, ``denoise``/``combine`` for ``run``, ``TIMES_ITSELF`` for ``program_seconds``)
    whose value ``spec`` does not carry in that field, e.g. a ``check_config`` function the
    declaration forgot, or a ``build_network`` without ``learned``. Each is named with the field to set."""
    stray = []
    for name, declared in _declared_hooks(spec).items():
        where = f"learned=LearnedSpec({name}=...)" if name in field_names(LearnedSpec) else f"{name}="
        for attribute in dict.fromkeys((name, name.upper(), *_OTHER_HOOK_NAMES.get(name, ()))):
            if attribute in vars(module) and not _carried(vars(module)[attribute], declared):
                stray.append(f"{attribute} (set {where} in {SPEC_ATTRIBUTE})")
    return stray


def _carried(value, declared) -> bool:
    return value is declared or (not callable(value) and type(value) is type(declared) and value == declared)


def method_spec(module: ModuleType) -> MethodSpec:
    """The declaration ``METHOD`` of method module ``module``; a :class:`BenchError` naming
    ``methods/<name>.py`` when it has none or something else under that name."""
    return declaration(module, SPEC_ATTRIBUTE, MethodSpec, "methods")
