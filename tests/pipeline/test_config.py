"""The configuration means what it says: defaults from the schema only, strict types, every
method's params checked against its signature when the DAG is parsed, reserved and duplicate
names refused, and the schema agreeing with the code (metric names, DSSIM's window)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

import methods
from mcbench import BenchError
from mcbench.pipeline.config import ConfigError, key_path, load_schema, resolve_config, schema_defaults
from mcbench.analysis.metrics import DSSIM_MIN_SIZE

REPO = Path(__file__).resolve().parents[2]
CONFIGS = sorted((REPO / "workflow" / "configs").glob("*.yaml")) + [REPO / "config.yaml"]


def _every_property(schema, root, path=()):
    """(path, sub-schema) of every named property of the schema, through objects and $refs."""
    if "$ref" in schema:
        node = root
        for part in schema["$ref"][2:].split("/"):
            node = node[part]
        schema = node
    for name, sub in schema.get("properties", {}).items():
        yield path + (name,), sub
        yield from _every_property(sub, root, path + (name,))


def test_every_top_level_and_nested_key_has_its_default_in_the_schema():
    schema = load_schema()
    missing = [".".join(p) for p, sub in _every_property(schema, schema)
               if "default" not in sub and p[0] not in ("denoisers", "combiners")
               and not (len(p) >= 2 and p[-2] == "networks")]
    assert missing == []
    defaults = schema_defaults()
    assert set(defaults) == set(schema["properties"])
    assert defaults["training"]["count"] == 128 and defaults["reference"]["spp"] == 16384


def test_config_yaml_sets_only_what_the_schema_does_not_default():
    """config.yaml holds no copy of a schema default (one place per default)."""
    written = yaml.safe_load((REPO / "config.yaml").read_text())
    defaults = schema_defaults()

    def copies(value, default, path):
        if isinstance(value, dict) and isinstance(default, dict):
            for key, sub in value.items():
                yield from copies(sub, default.get(key, object()), path + [key])
        elif value == default:
            yield key_path(path)

    assert list(copies(written, defaults, [])) == []
    assert resolve_config(written)["reference"]["scene_spp"] == {
        "cornell_box": 41984, "veach_ajar": 45056, "glass_caustics": 137216, "envmap_objects": 21504,
        "fine_textures": 25600, "furball": 18432, "depth_of_field": 17408, "fog_beams": 63488}


def test_a_config_file_is_the_whole_configuration():
    narrowed = resolve_config({"scenes": ["cornell_box"]})
    assert narrowed["scenes"] == ["cornell_box"]
    # nothing is inherited from config.yaml: the per-scene reference spp stays the schema's (empty)
    assert narrowed["reference"] == {"spp": 16384, "chunks": 4, "scene_spp": {}, "source": "store", "store": ""}
    smoke = resolve_config(yaml.safe_load((REPO / "workflow/configs/smoke.yaml").read_text()))
    assert smoke["reference"] == {"spp": 1024, "chunks": 2, "scene_spp": {}, "source": "store", "store": ""}
    # a nested object given in part keeps its own values and takes the rest from the schema
    assert resolve_config({"training": {"count": 3}})["training"]["crops"] == 4


@pytest.mark.parametrize("config, key", [
    ({"spp": [4.0]}, "spp[0]"),
    ({"spp": [4, 7]}, "spp[1]"),
    ({"resolution": [DSSIM_MIN_SIZE - 1, 64]}, "resolution"),
    ({"reference": {"chunks": 2.0}}, "reference.chunks"),
    ({"seed": True}, "seed"),
    ({"render_threads": 0}, "render_threads"),
    ({"sceness": ["cornell_box"]}, "<config>"),
    ({"training": {"networks": {"kpcn": {"stepz": 3}}}}, "training.networks.kpcn"),
])
def test_invalid_values_are_refused_naming_the_key(config, key):
    with pytest.raises(ConfigError) as error:
        resolve_config(config, source="my.yaml")
    assert str(error.value).startswith(f"my.yaml: {key}")


def test_schema_resolution_minimum_is_dssims_window():
    schema = load_schema()
    items = schema["properties"]["resolution"]["oneOf"][1]["items"]
    assert items["minimum"] == DSSIM_MIN_SIZE == 11
    assert resolve_config({"resolution": [11, 11]})["resolution"] == [11, 11]


def test_schema_metric_names_are_resolved_by_the_metric_plugins():
    """The schema lists no metric names (a metric is a file metrics/<name>.py): its default names
    plugins, and a misspelt name stops the plan naming the key and the closest metric."""
    from mcbench.pipeline.plan import plan_study
    from mcbench.pipeline.registry import available_metrics

    schema = load_schema()
    assert "enum" not in schema["properties"]["metrics"]["items"]
    assert set(schema["properties"]["metrics"]["default"]) <= set(available_metrics())
    config = resolve_config({"scenes": ["cornell_box"], "metrics": ["relmse", "dsim"]}, source="my.yaml")
    with pytest.raises(BenchError, match=r"^my\.yaml: metrics\[1\]: unknown metric 'dsim' \(did you mean 'dssim'\?\)"):
        plan_study(config, source="my.yaml", is_learned=lambda module: False)


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_every_shipped_config_resolves_and_its_methods_check(path):
    config = resolve_config(yaml.safe_load(path.read_text()), source=str(path))
    table = methods.method_table(config["denoisers"], config["combiners"], is_learned=lambda m: False)
    labels = [spec["label"] for spec in table.values()]
    assert len(labels) == len(set(labels))


def _table(denoisers=("oidn", "jbf"), combiners=()):
    return methods.method_table(list(denoisers), list(combiners), is_learned=lambda module: False)


@pytest.mark.parametrize("combiner, message", [
    ({"params": {"solvr": "exact"}}, "combiners[0].params.solvr: ensemble has no parameter 'solvr'"),
    ({"params": {"solver": "exactt"}}, "combiners[0].params.solver: 'exactt' is not allowed"),
    ({"params": {"radius": 2.5}}, "combiners[0].params.radius: 2.5 is not allowed"),
    ({"params": {"filter": "no"}}, "combiners[0].params.filter: 'no' is not allowed"),
    ({"inputs": ["oidn", "nfor"]}, "combiners[0].inputs[1]: 'nfor' is not a denoiser"),
    ({"name": "noisy"}, "combiners[0].name: 'noisy' is reserved"),
    ({"name": "jbf"}, "combiners[0].name: duplicate method name 'jbf'"),
    ({"method": "oidn"}, "combiners[0].method: 'oidn' is a denoiser, not a combiner"),
])
def test_combiner_mistakes_stop_at_parse_naming_the_key(combiner, message):
    entry = {"name": "ens", "method": "ensemble", "inputs": ["oidn", "jbf"], **combiner}
    with pytest.raises(BenchError) as error:
        _table(combiners=[entry])
    assert str(error.value).startswith(message)


def test_denoiser_params_are_checked_against_the_signature():
    with pytest.raises(BenchError, match=r"denoisers\[1\].params.quality: 'best' is not allowed for oidn"):
        _table(denoisers=["jbf", {"name": "oidn_best", "method": "oidn", "params": {"quality": "best"}}])
    with pytest.raises(BenchError, match=r"denoisers\[0\].params.sigma: jbf has no parameter 'sigma'"):
        _table(denoisers=[{"name": "jbf", "params": {"sigma": 1.0}}])
    with pytest.raises(BenchError, match=r"denoisers\[0\].name: 'noisy' is reserved"):
        _table(denoisers=[{"name": "noisy", "method": "oidn"}])
    table = _table(denoisers=["jbf", {"name": "jbf3", "method": "jbf", "params": {"radius": 3, "sigma_color": 1}}])
    assert table["jbf3"]["params"] == {"radius": 3, "sigma_color": 1}


def test_default_labels_tell_variants_apart_and_duplicate_labels_stop():
    table = _table(combiners=[{"name": "ensemble", "method": "ensemble", "inputs": ["oidn", "jbf"]},
                              {"name": "ensemble_exact", "method": "ensemble", "inputs": ["oidn", "jbf"],
                               "params": {"solver": "exact"}}])
    assert table["ensemble"]["label"] == "Ensemble (oidn+jbf)"
    assert table["ensemble_exact"]["label"] == "Ensemble (oidn+jbf; solver=exact)"
    with pytest.raises(BenchError, match=r"combiners\[1\].label: 'Same' is also the label of 'a'"):
        _table(combiners=[{"name": "a", "method": "ensemble", "inputs": ["oidn", "jbf"], "label": "Same"},
                          {"name": "b", "method": "ensemble", "inputs": ["oidn", "jbf"], "label": "Same"}])
    with pytest.raises(BenchError, match="also the label of 'noisy'"):
        _table(denoisers=[{"name": "oidn", "label": "Noisy input"}])


def test_every_method_param_annotation_is_checkable():
    """Each method's config parameters carry annotations the checker understands, so a wrong
    type is caught at parse time for every method, not only for the ones tested above."""
    import typing

    from mcbench.contracts.method import SingleImageDenoiser

    simple = (bool, int, float, str, SingleImageDenoiser)

    def checkable(hint) -> bool:
        if typing.get_origin(hint) is typing.Union:
            return all(checkable(arg) for arg in typing.get_args(hint))
        return (hint in simple or typing.get_origin(hint) is typing.Literal
                or (typing.get_origin(hint) is list and typing.get_args(hint)[0] in simple))

    for name in methods.available_methods():
        module = methods.load_method(name)
        hints = typing.get_type_hints(methods.method_spec(module).run)
        for parameter in methods.method_parameters(module):
            hint = hints.get(parameter)
            assert hint is not None, f"methods/{name}.py: parameter '{parameter}' has no annotation"
            assert checkable(hint), (name, parameter, hint)


def test_schema_training_overrides_are_the_training_settings():
    """training.networks.<name> accepts exactly the settings mcbench.nn.train knows (threads
    come from the rule) and the losses it implements."""
    from mcbench.nn.losses import LOSSES
    from mcbench.nn.train import DEFAULT_SETTINGS

    overrides = load_schema()["properties"]["training"]["properties"]["networks"]["additionalProperties"]
    assert set(overrides["properties"]) == set(DEFAULT_SETTINGS) - {"threads"}
    assert overrides["properties"]["loss"]["enum"] == list(LOSSES)


def test_resolving_a_config_skips_jsonschemas_iri_grammar_and_keeps_refusing_bad_values():
    """Resolving the default config in a fresh interpreter validates it without importing
    rfc3987_syntax (its Lark grammar costs about 2 s of every process that validates a config),
    still refuses a wrong type, and leaves the package importable afterwards."""
    import subprocess
    import sys

    code = (
        "import sys, yaml\n"
        "from mcbench.pipeline.config import ConfigError, resolve_config\n"
        "resolve_config(yaml.safe_load(open('config.yaml')), source='config.yaml')\n"
        "assert 'rfc3987_syntax' not in sys.modules and 'lark' not in sys.modules, 'grammar imported'\n"
        "try:\n"
        "    resolve_config({'spp': [4.0]}, source='c.yaml')\n"
        "except ConfigError as error:\n"
        "    assert 'spp[0]' in str(error), error\n"
        "else:\n"
        "    raise AssertionError('4.0 spp accepted')\n"
        "import importlib.util\n"
        "if importlib.util.find_spec('rfc3987_syntax'):\n"
        "    import rfc3987_syntax  # still importable by other code\n"
        "print('ok')\n"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=Path(__file__).resolve().parents[2], capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr
