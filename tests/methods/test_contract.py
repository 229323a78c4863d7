"""The contract every module in ``methods/`` must keep, so a new method is tested the moment its
file exists: it loads through the registry with a well-formed declaration
(:class:`mcbench.contracts.method.MethodSpec`), returns a :class:`mcbench.io.buffers.Denoised` whose
full, A and B images are finite float (H, W, 3) arrays, and the same input gives the same output.
Hard cases: fireflies, black regions, a 1x1 image, and for combiners identical inputs and an
input equal to the noisy image.

The declaration itself: every field of :class:`MethodSpec` and :class:`LearnedSpec` is documented
(its docstring and ``docs/methods.md``) and type-checked, a learned method's fields are accepted
only in its ``learned=LearnedSpec(...)``, and the registry refuses scratch plugins that break each
rule (no declaration, a misspelt field, a wrong type, fields that go together, a top-level hook the
declaration does not carry), naming the plugin's file.

A method that fails a hard case is listed in ``KNOWN_FAILURES`` (strict xfail, so fixing it
makes the test fail until the entry is removed).
"""

from __future__ import annotations

from pathlib import Path

import dataclasses
import sys
import textwrap

import numpy as np
import pytest

import methods
from mcbench.io.buffers import SUB_OUTPUTS, Denoised, RenderBuffers
from mcbench.contracts.fields import SpecError, field_names
from mcbench.contracts.method import LearnedSpec, MethodSpec
from mcbench.io.weights import COMMITTED_WEIGHTS
from methods import UnknownMethodError, available_methods, load_method, method_spec

ROOT = Path(__file__).resolve().parents[2]

HEIGHT, WIDTH = 12, 10
DENOISER_CASES = ("fireflies", "black_region", "one_pixel")
COMBINER_CASES = DENOISER_CASES + ("identical_inputs", "input_is_noisy_image")

# (method, case) -> reason; keep in sync with the methods' own limitations
KNOWN_FAILURES: dict[tuple[str, str], str] = {
}


def method_kind(name: str) -> str:
    """The declared kind of methods/<name>.py, or "unknown" if it does not load (the basic test
    then fails with the loader's error)."""
    try:
        return method_spec(load_method(name)).kind
    except Exception:  # noqa: BLE001 -- reported by test_loads_and_keeps_the_contract
        return "unknown"


#: methods whose results are read from files made elsewhere, not computed from the render: they do
#: not depend on the synthetic input, so the run-based checks here do not apply
#: (tests/methods/test_precomputed.py checks them)
READERS = {"precomputed"}


def computing_methods() -> list[str]:
    return [n for n in available_methods() if n not in READERS]


def case_params():
    params = []
    for name in computing_methods():
        cases = COMBINER_CASES if method_kind(name) == "combiner" else DENOISER_CASES
        for case in cases:
            marks = ()
            if (name, case) in KNOWN_FAILURES:
                marks = pytest.mark.xfail(strict=True, reason=KNOWN_FAILURES[(name, case)])
            params.append(pytest.param(name, case, marks=marks, id=f"{name}-{case}"))
    return params


def blurred(image: np.ndarray) -> np.ndarray:
    """3x3 box mean with edge replication, float32: a stand-in base denoiser output."""
    h, w = image.shape[:2]
    padded = np.pad(np.asarray(image, np.float64), ((1, 1), (1, 1), (0, 0)), mode="edge")
    total = sum(padded[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3))
    return (total / 9).astype(np.float32)


def sub_outputs(buffers, filtered) -> dict:
    """``filtered`` applied to each image's two sub-buffers, as :data:`SUB_OUTPUTS` extras (what
    a kernel-exposing base such as KPCN writes)."""
    return {name: filtered(color) for which in ("full", "a", "b")
            for name, (color, _) in zip(SUB_OUTPUTS[which], buffers.sub_images(which))}


def synthetic_inputs(buffers) -> list[Denoised]:
    """Two base outputs for combiners: a blurred copy of each image and a biased one, each with
    its results on the sub-buffers."""
    images = (buffers.color, buffers.color_a, buffers.color_b)

    def biased_blur(x):
        return blurred(x) * np.float32(0.9) + np.float32(0.02)

    smooth = Denoised(*(blurred(x) for x in images), extras=sub_outputs(buffers, blurred))
    biased = Denoised(*(biased_blur(x) for x in images), extras=sub_outputs(buffers, biased_blur))
    return [smooth, biased]


def with_layers(buffers, **changes):
    """A copy of ``buffers`` with some layers replaced (arrays copied as float32)."""
    layers = {name: value.copy() for name, value in buffers.layers.items()}
    layers.update({name: np.asarray(value, np.float32) for name, value in changes.items()})
    return type(buffers)(layers=layers, spp=buffers.spp)


def hard_case(case: str, build):
    """(buffers, combiner inputs) of the named hard case; ``build`` is make_render_buffers."""
    if case == "one_pixel":
        buffers = build(height=1, width=1, seed=3, bins=True)
        return buffers, synthetic_inputs(buffers)
    buffers = build(height=HEIGHT, width=WIDTH, seed=4, bins=True)
    if case == "fireflies":
        layers = {name: buffers.layers[name].copy() for name in
                  ("color_a", "color_b", "variance_a", "variance_b", "color_bin0", "color_bin2",
                   "variance_bin0", "variance_bin2")}
        for (y, x), half, in_bin in (((2, 3), "a", 0), ((7, 8), "b", 2), ((10, 1), "a", 0)):
            layers[f"color_bin{in_bin}"][y, x] *= 1e4             # one sample subset holds the spike
            layers[f"variance_bin{in_bin}"][y, x] = layers[f"color_bin{in_bin}"][y, x] ** 2
            layers["color_" + half][y, x] = (layers[f"color_bin{in_bin}"][y, x]
                                             + buffers.layers[f"color_bin{in_bin + 1}"][y, x]) / 2
            layers["variance_" + half][y, x] = layers["color_" + half][y, x] ** 2
        layers["color"] = (layers["color_a"].astype(np.float64) + layers["color_b"]) / 2
        layers["variance"] = (layers["variance_a"].astype(np.float64) + layers["variance_b"]) / 4
        buffers = with_layers(buffers, **layers)
        inputs = synthetic_inputs(buffers)
        inputs[1] = Denoised(inputs[1].full, inputs[1].a.copy(), inputs[1].b, extras=inputs[1].extras)
        inputs[1].a[5, 5] *= 1e4                        # a firefly left in one base output
        return buffers, inputs
    if case == "black_region":
        black = {}
        for name, value in buffers.layers.items():
            black[name] = value.copy()
            black[name][:, : WIDTH // 2] = 0.0           # colour, variance and all features
        buffers = with_layers(buffers, **black)
        return buffers, synthetic_inputs(buffers)
    if case == "identical_inputs":
        smooth = synthetic_inputs(buffers)[0]
        return buffers, [smooth, Denoised(smooth.full.copy(), smooth.a.copy(), smooth.b.copy(),
                                          extras=dict(smooth.extras))]
    if case == "input_is_noisy_image":
        noisy = Denoised(buffers.color.copy(), buffers.color_a.copy(), buffers.color_b.copy(),
                         extras=sub_outputs(buffers, lambda x: x.copy()))
        return buffers, [noisy, synthetic_inputs(buffers)[0]]
    raise ValueError(f"unknown hard case {case!r}")


#: params a method cannot run without (no default): the external program runs the example's box filter
REQUIRED_PARAMS = {"external": {"command": ["{python}", str(Path(__file__).resolve().parents[2] / "examples" / "box_denoiser"
                                                            / "box_filter.py"),
                                            "--in", "{input_dir}", "--out", "{output_dir}", "--name", "{name}"]}}


def run(module, buffers, inputs) -> Denoised:
    """A denoiser on ``buffers``; a combiner on ``buffers`` and ``inputs`` (its first ``inputs``
    when it declares how many it takes, e.g. the deep combiner's one)."""
    spec = method_spec(module)
    name = module.__name__.split(".")[-1]
    weights = {"weights_file": COMMITTED_WEIGHTS / f"{name}.pt"} if spec.learned else {}
    if spec.kind == "combiner":
        return spec.run(buffers, inputs[:spec.inputs or len(inputs)], **weights)
    return spec.run(buffers, **REQUIRED_PARAMS.get(name, {}), **weights)


def assert_valid_output(result, shape):
    assert isinstance(result, Denoised), type(result)
    for which in ("full", "a", "b"):
        image = np.asarray(getattr(result, which))
        assert image.shape == shape + (3,), (which, image.shape)
        assert np.issubdtype(image.dtype, np.floating), (which, image.dtype)
        assert np.isfinite(image).all(), f"{which}: {np.count_nonzero(~np.isfinite(image))} non-finite"


@pytest.mark.parametrize("name", available_methods())
def test_loads_and_keeps_the_contract(name, make_render_buffers):
    module = load_method(name)
    spec = method_spec(module)
    assert spec.label and spec.run is getattr(module, methods.KINDS[spec.kind])   # denoise/combine by name
    if name in READERS:
        return
    buffers = make_render_buffers(height=HEIGHT, width=WIDTH, seed=1, bins=True)
    inputs = synthetic_inputs(buffers)
    first = run(module, buffers, inputs)
    assert_valid_output(first, (HEIGHT, WIDTH))
    second = run(module, buffers, inputs)
    for which in ("full", "a", "b"):
        assert np.array_equal(getattr(first, which), getattr(second, which)), \
            f"{name}: {which} differs between two runs on the same input"
    # the output depends on the input (a method returning a constant would pass the above)
    other = make_render_buffers(height=HEIGHT, width=WIDTH, seed=2, bins=True)
    assert not np.array_equal(run(module, other, synthetic_inputs(other)).full, first.full)


@pytest.mark.parametrize("name", [n for n in computing_methods() if method_spec(load_method(n)).render_layers])
def test_declared_render_layers_are_all_the_method_reads(name, make_render_buffers):
    """A method declaring render_layers gets only those (and colour) from a job
    (mcbench.pipeline.method_runs.render_layers): on such a render it must give exactly its full-render result."""
    module = load_method(name)
    buffers = make_render_buffers(height=HEIGHT, width=WIDTH, seed=1, bins=True)
    inputs = synthetic_inputs(buffers)
    kept = {key: buffers.layers[key] for key in ("color", *method_spec(module).render_layers)}
    assert len(kept) < len(buffers.layers)
    narrowed = RenderBuffers(layers=kept, spp=buffers.spp, source=buffers.source)
    full, narrow = run(module, buffers, inputs), run(module, narrowed, inputs)
    for which in ("full", "a", "b"):
        assert np.array_equal(getattr(full, which), getattr(narrow, which)), which


@pytest.mark.parametrize(("name", "case"), case_params())
def test_hard_case_gives_finite_output(name, case, make_render_buffers):
    module = load_method(name)
    buffers, inputs = hard_case(case, make_render_buffers)
    result = run(module, buffers, inputs)
    assert_valid_output(result, buffers.shape)


def default_config_variants():
    """Distinct (module, params) of the default study's non-learned combiners that set params
    (the ablations and one-hot variants of Sec. 5.2): each keeps the contract on the hard cases."""
    from mcbench.pipeline.config import resolve_config
    from mcbench.io.weights import is_learned_method

    seen, params = set(), []
    for entry in resolve_config({})["combiners"]:
        module_name, options = entry.get("method", entry["name"]), entry.get("params") or {}
        key = (module_name, tuple(sorted(options.items())))
        if not options or key in seen or is_learned_method(load_method(module_name)):
            continue
        seen.add(key)
        label = ",".join(f"{k}={v}" for k, v in sorted(options.items()))
        params += [pytest.param(module_name, dict(options), case, id=f"{module_name}[{label}]-{case}")
                   for case in COMBINER_CASES]
    return params


@pytest.mark.parametrize(("name", "options", "case"), default_config_variants())
def test_default_config_variants_give_finite_output(name, options, case, make_render_buffers):
    combine = method_spec(load_method(name)).run
    buffers, inputs = hard_case(case, make_render_buffers)
    result = combine(buffers, inputs, **options)
    assert_valid_output(result, buffers.shape)
    again = combine(buffers, inputs, **options)
    assert np.array_equal(result.full, again.full), f"{name} {options}: not deterministic"


# ---------------------------------------------------------------------------------------------
# The declaration: documented, type-checked, and refused by the registry when it is broken


def test_every_field_is_documented():
    """The contract is read from the types: each field of MethodSpec and LearnedSpec is described
    in its docstring and in docs/methods.md (a new field without documentation fails here)."""
    docs = (ROOT / "docs" / "methods.md").read_text()
    for spec_class in (MethodSpec, LearnedSpec):
        for name in field_names(spec_class):
            assert f"``{name}``" in spec_class.__doc__, f"{spec_class.__name__}'s docstring does not describe {name}"
            assert f"\n| `{name}` |" in docs, f"docs/methods.md: no row of the contract's table for field {name}"


def _valid_fields() -> dict:
    return {"kind": "denoiser", "label": "Scratch", "run": lambda buffers: None}


def _learned_fields() -> dict:
    return {"network": {}, "training": {}, "build_network": lambda **arch: None}


def _learned_run(buffers, *, weights_file):
    return None


@pytest.mark.parametrize("field", [f for f in field_names(MethodSpec) if f != "learned"])
def test_each_field_refuses_a_value_of_another_type(field):
    """Every field's annotation is checked: an object of no declared type is refused, naming the field."""
    with pytest.raises(SpecError, match=rf"MethodSpec field '{field}' must be"):
        MethodSpec(**{**_valid_fields(), field: object()})


@pytest.mark.parametrize("field", field_names(LearnedSpec))
def test_each_learned_field_refuses_a_value_of_another_type(field):
    with pytest.raises(SpecError, match=rf"LearnedSpec field '{field}' must be"):
        LearnedSpec(**{**_learned_fields(), field: object()})


def test_a_learned_methods_fields_are_accepted_only_in_its_learned_spec():
    """network, training, build_network, ... given to MethodSpec itself are refused, naming
    ``learned=LearnedSpec(...)``; a learned method's run takes ``weights_file``, no other method's does."""
    for field, value in _learned_fields().items():
        with pytest.raises(SpecError, match=rf"MethodSpec has no field '{field}': it goes in learned=LearnedSpec"):
            MethodSpec(**_valid_fields(), **{field: value})
    spec = MethodSpec(**{**_valid_fields(), "run": _learned_run}, learned=LearnedSpec(**_learned_fields()))
    assert spec.learned.network == {} and spec.single_image
    with pytest.raises(SpecError, match="MethodSpec field 'learned' must be Optional\\[LearnedSpec\\]"):
        MethodSpec(**{**_valid_fields(), "run": _learned_run}, learned=_learned_fields())
    with pytest.raises(SpecError, match="a learned method's run takes the keyword 'weights_file'.*does not"):
        MethodSpec(**_valid_fields(), learned=LearnedSpec(**_learned_fields()))
    with pytest.raises(SpecError, match="any other method's not; _learned_run\\(\\) does"):
        MethodSpec(**{**_valid_fields(), "run": _learned_run})
    with pytest.raises(SpecError, match="LearnedSpec has no field 'netwrok' \\(did you mean 'network'\\?\\)"):
        LearnedSpec(netwrok={}, training={}, build_network=lambda **arch: None)


def test_fields_that_go_together_and_misplaced_fields_are_refused():
    MethodSpec(**_valid_fields())                         # the minimal declaration is valid
    learned_run = {**_valid_fields(), "run": _learned_run}
    with pytest.raises(SpecError, match="LearnedSpec of a combiner sets correlated_bases and training_keys"):
        MethodSpec(**{**learned_run, "kind": "combiner"}, learned=LearnedSpec(**_learned_fields()))
    with pytest.raises(SpecError, match="correlated_bases, training_keys are for a learned combiner"):
        MethodSpec(**learned_run, learned=LearnedSpec(**_learned_fields(), correlated_bases=("oidn",)))
    with pytest.raises(SpecError, match="critic, build_critic go together"):
        LearnedSpec(**_learned_fields(), critic={})
    with pytest.raises(SpecError, match="inputs, comparison_role are for a combiner"):
        MethodSpec(**_valid_fields(), inputs=1)
    with pytest.raises(SpecError, match=r"MethodSpec needs the field\(s\) run"):
        MethodSpec(kind="denoiser", label="Scratch")
    with pytest.raises(SpecError, match=r"LearnedSpec needs the field\(s\) training"):
        LearnedSpec(network={}, build_network=lambda **arch: None)
    with pytest.raises(SpecError, match="'label' must not be empty"):
        MethodSpec(**{**_valid_fields(), "label": ""})
    with pytest.raises(SpecError, match="field 'warm_up' must be bool"):
        MethodSpec(**_valid_fields(), warm_up=0)
    with pytest.raises(SpecError, match="field 'inputs' must be Optional\\[int\\], got True"):
        MethodSpec(**{**_valid_fields(), "kind": "combiner"}, inputs=True)
    with pytest.raises(SpecError, match="field 'training_keys' must be .*got \\{'color': 3.0\\}"):
        LearnedSpec(**_learned_fields(), training_keys={"color": 3.0})
    spec = MethodSpec(**_valid_fields())
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.label = "other"


@pytest.fixture
def scratch_plugin(tmp_path, monkeypatch):
    """A function writing ``methods/<name>.py`` into a scratch folder on the registry's search path
    (``methods.__path__``) and loading it with :func:`methods.load_method`."""
    folder = tmp_path / "plugins"
    folder.mkdir()
    monkeypatch.setattr(methods, "__path__", [*methods.__path__, str(folder)])
    written = []

    def load(name: str, body: str, kind: str | None = None):
        (folder / f"{name}.py").write_text("from mcbench.contracts.method import LearnedSpec, MethodSpec\n\n\n"
                                           "def denoise(buffers, *, radius: int = 1):\n    return buffers\n\n"
                                           + textwrap.dedent(body))
        written.append(f"methods.{name}")
        return load_method(name, kind=kind, config_key="denoisers[0]")

    yield load
    for module in written:
        sys.modules.pop(module, None)


def test_a_valid_scratch_plugin_loads(scratch_plugin):
    module = scratch_plugin("scratch_ok", """
        RENDER_LAYERS = ("color",)        # a leftover the declaration carries: allowed
        METHOD = MethodSpec(kind="denoiser", label="Scratch", run=denoise, render_layers=("color",))
        """)
    assert method_spec(module).render_layers == ("color",)
    assert list(methods.method_parameters(module)) == ["radius"]


@pytest.mark.parametrize(("name", "body", "message"), [
    ("scratch_none", "", r"methods/scratch_none\.py: METHOD must be a mcbench\.contracts\.method\.MethodSpec.*found none"),
    ("scratch_dict", "METHOD = {'kind': 'denoiser', 'label': 'Scratch', 'run': denoise}\n",
     r"methods/scratch_dict\.py: METHOD must be .*found a dict"),
    ("scratch_misspelt", "METHOD = MethodSpec(kind='denoiser', label='Scratch', run=denoise, rendr_layers=('color',))\n",
     r"denoisers\[0\]: methods/scratch_misspelt\.py: MethodSpec has no field 'rendr_layers' "
     r"\(did you mean 'render_layers'\?\)"),
    ("scratch_case", "METHOD = MethodSpec(kind='denoiser', label='Scratch', run=denoise, Warm_Up=False)\n",
     r"methods/scratch_case\.py: MethodSpec has no field 'Warm_Up' \(did you mean 'warm_up'\?\)"),
    ("scratch_type", "METHOD = MethodSpec(kind='denoiser', label='Scratch', run=denoise, render_layers=['color'])\n",
     r"methods/scratch_type\.py: MethodSpec field 'render_layers' must be Optional\[tuple\[str, \.\.\.\]\], "
     r"got \['color'\]"),
    ("scratch_kind", "METHOD = MethodSpec(kind='denoser', label='Scratch', run=denoise)\n",
     r"methods/scratch_kind\.py: MethodSpec field 'kind' must be Literal\['denoiser', 'combiner'\]"),
    ("scratch_hook", "def check_config(params, *, config_key):\n    pass\n\n"
                     "METHOD = MethodSpec(kind='denoiser', label='Scratch', run=denoise)\n",
     r"methods/scratch_hook\.py defines hook\(s\) of the method contract that its METHOD does not carry: "
     r"check_config \(set check_config= in METHOD\)"),
    ("scratch_legacy", "KIND = 'combiner'\nRENDER_LAYERS = ('color',)\nTIMES_ITSELF = True\n"
                       "METHOD = MethodSpec(kind='denoiser', label='Scratch', run=denoise, render_layers=('albedo',))\n",
     r"methods/scratch_legacy\.py defines .*: KIND \(set kind= in METHOD\), RENDER_LAYERS \(set render_layers= "
     r"in METHOD\), TIMES_ITSELF \(set program_seconds= in METHOD\)"),
    ("scratch_network", "def build_network(**arch):\n    pass\n\n"
                        "METHOD = MethodSpec(kind='denoiser', label='Scratch', run=denoise)\n",
     r"methods/scratch_network\.py defines .*: build_network \(set learned=LearnedSpec\(build_network=\.\.\.\) in METHOD\)"),
    ("scratch_learned", "METHOD = MethodSpec(kind='denoiser', label='Scratch', run=denoise, network={'width': 8})\n",
     r"methods/scratch_learned\.py: MethodSpec has no field 'network': it goes in learned=LearnedSpec"),
    ("scratch_run", "METHOD = MethodSpec(kind='denoiser', label='Scratch', run=lambda buffers: buffers)\n",
     r"methods/scratch_run\.py defines .*: denoise \(set run= in METHOD\)"),
])
def test_the_registry_refuses_a_broken_declaration_naming_the_file(scratch_plugin, name, body, message):
    with pytest.raises(UnknownMethodError, match=message):
        scratch_plugin(name, body)


def test_the_registry_refuses_the_wrong_kind(scratch_plugin):
    with pytest.raises(UnknownMethodError, match=r"'scratch_kinds' is a denoiser, not a combiner"):
        scratch_plugin("scratch_kinds", "METHOD = MethodSpec(kind='denoiser', label='Scratch', run=denoise)\n",
                       kind="combiner")


def legacy_reads(text: str) -> list[str]:
    """Reads of a contract hook off a module instead of its declaration in ``text``: ``x.RENDER_LAYERS``
    (a field's name in upper case) or ``getattr(x, "check_config", ...)``/``hasattr`` of such a
    name or of a function field's own name (``check_config``, ``build_network``, ...)."""
    import re
    import typing

    names = [n.upper() for spec in (MethodSpec, LearnedSpec) for n in field_names(spec)] + ["TIMES_ITSELF"]
    functions = [name for spec in (MethodSpec, LearnedSpec) for name, hint in typing.get_type_hints(spec).items()
                 if "Callable" in str(hint)]
    attribute = re.compile(rf"\.({'|'.join(names)})\b")
    by_name = re.compile(rf"\b(?:getattr|hasattr)\([^,()]+,\s*[\"']({'|'.join(names + functions)})[\"']")
    return [m.group(0) for pattern in (attribute, by_name) for m in pattern.finditer(text)]


def test_no_consumer_reads_a_hook_off_the_module():
    """The core, the workflow, the benchmarks, the tools and the tests read a method's hooks from its
    declaration (``method_spec(module).render_layers``), never off the module."""
    assert legacy_reads('layers = getattr(module, "RENDER_LAYERS", None)\nif hasattr(m, "check_config"):\n'
                        'x = module.TRAINING_KEYS\n') == \
        ['.TRAINING_KEYS', 'getattr(module, "RENDER_LAYERS"', 'hasattr(m, "check_config"']
    found = {}
    for folder in ("mcbench", "methods", "workflow", "benchmarks", "tools", "tests", "examples"):
        for path in sorted((ROOT / folder).rglob("*")):
            if path.suffix in (".py", ".smk") and path != Path(__file__).resolve() and path.is_file():
                reads = legacy_reads(path.read_text(errors="replace"))
                if reads:
                    found[str(path.relative_to(ROOT))] = reads
    assert not found, found
