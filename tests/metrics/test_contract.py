"""The metric plugin contract (:mod:`mcbench.contracts.metric`) and its registry (``metrics/``):
every shipped metric loads and keeps it, a broken declaration or a misspelt name is refused
naming the field, the file or the config key with the closest name, and a metric added as one
file reaches the case table, the viewer and the tables' text with no other edit."""

from __future__ import annotations

import dataclasses
import json
import sys
import textwrap

import pandas as pd
import pytest

import metrics
from mcbench import NOISY
from mcbench.contracts.metric import ColourScale, MetricSpec, MetricSpecError
from mcbench.io.buffers import Denoised
from mcbench.io.exr import write_layers
from mcbench.pipeline.registry import available_metrics, load_metric
from tests.conftest import REPO, case_job

SCENE, SPP = "box", 8


def value(image, reference):
    return 0.0


@pytest.mark.parametrize("name", available_metrics())
def test_every_metric_loads_and_keeps_the_contract(name):
    spec = load_metric(name)
    assert spec.name == name and spec.label and spec.lower_is_better
    assert (spec.error_map is None) == (spec.map_scale is None)


def test_a_misspelt_field_is_refused_naming_the_closest_field():
    with pytest.raises(MetricSpecError, match=r"MetricSpec has no field 'lower_is_beter' \(did you mean "
                                              r"'lower_is_better'\?\)"):
        MetricSpec(name="mae", label="MAE", value=value, lower_is_beter=True)


@pytest.mark.parametrize(("fields", "message"), [
    ({"name": "Mean error"}, r"field 'name' must be a str of lower-case letters"),
    ({"label": ""}, r"field 'label' must be a non-empty str"),
    ({"value": 3.0}, r"field 'value' must be a function, got 3\.0"),
    ({"lower_is_better": "yes"}, r"field 'lower_is_better' must be bool, got 'yes'"),
    ({"error_map": value}, r"fields 'error_map' and 'map_scale' go together"),
    ({"value_and_map": value}, r"field 'value_and_map' needs 'error_map'"),
    ({"error_map": value, "map_scale": ColourScale("other", "viridis", 0.0, 1.0, False, "d")},
     r"field 'map_scale' is named 'other'; a metric's scale takes the metric's name 'mae'"),
    ({"reads_reference_variance": True, "error_map": value,
      "map_scale": ColourScale("mae", "viridis", 0.0, 1.0, False, "d")}, r"reads the reference's variance has no map"),
])
def test_a_field_of_the_wrong_value_is_refused_naming_it(fields, message):
    with pytest.raises(MetricSpecError, match=message):
        MetricSpec(**{"name": "mae", "label": "MAE", "value": value, **fields})


def test_a_declaration_is_frozen():
    spec = load_metric("smape")
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.label = "other"


@pytest.fixture
def scratch_metric(tmp_path, monkeypatch):
    """A function writing ``metrics/<name>.py`` into a scratch folder on the registry's search
    path (``metrics.__path__``): the one file a new metric is."""
    folder = tmp_path / "plugins"
    folder.mkdir()
    monkeypatch.setattr(metrics, "__path__", [*metrics.__path__, str(folder)])
    written = []

    def write(name: str, body: str) -> None:
        (folder / f"{name}.py").write_text(textwrap.dedent(body))
        written.append(f"metrics.{name}")

    yield write
    for module in written:
        sys.modules.pop(module, None)


def test_the_registry_names_the_key_and_the_closest_metric():
    with pytest.raises(metrics.UnknownMetricError, match=r"^metrics\[2\]: unknown metric 'smap' \(did you mean "
                                                         r"'smape'\?\); available: dssim, flip, relmse"):
        load_metric("smap", config_key="metrics[2]")


@pytest.mark.parametrize(("body", "message"), [
    ("X = 1\n", r"metrics\[0\]: metrics/scratch\.py declares no METRIC = MetricSpec"),
    ("from mcbench.contracts.metric import MetricSpec\nMETRIC = MetricSpec(name='other', label='S', value=len)\n",
     r"metrics/scratch\.py declares the metric 'other'; its name must be its file's, 'scratch'"),
    ("from mcbench.contracts.metric import MetricSpec\nMETRIC = MetricSpec(name='scratch', label='S', value=len, "
     "lower_is_beter=True)\n",
     r"metrics\[0\]: metrics/scratch\.py: MetricSpec has no field 'lower_is_beter' \(did you mean 'lower_is_better'\?\)"),
])
def test_the_registry_refuses_a_broken_plugin_naming_the_file(scratch_metric, body, message):
    scratch_metric("scratch", body)
    with pytest.raises(metrics.UnknownMetricError, match=message):
        load_metric("scratch", config_key="metrics[0]")


MAE_PLUGIN = '''
    """Mean absolute error (a metric added by this one file)."""
    import numpy as np

    from mcbench.contracts.metric import ColourScale, MetricSpec


    def mae_map(image, reference):
        return np.mean(np.abs(np.asarray(image, np.float64) - np.asarray(reference, np.float64)), axis=-1)


    def mae(image, reference):
        return float(np.mean(mae_map(image, reference)))


    METRIC = MetricSpec(name="mae", label="Mean absolute error", value=mae, error_map=mae_map,
                        map_scale=ColourScale("mae", "inferno", 0.0, 1.0, log=False, description="per-pixel MAE"))
    '''


def test_an_added_metric_file_reaches_the_case_table_the_viewer_and_the_tables(scratch_metric, tmp_path,
                                                                               make_render_buffers):
    """A metric added as one file (mean absolute error with a map) and named in the case's metrics:
    the case job computes it for every entry (its values the plugin's), draws its error map beside
    relMSE's, the viewer's manifest labels it and draws its legend, and the ranking's text names
    it by its label; nothing else is edited."""
    from mcbench.pipeline.cases import run_case
    from mcbench.pipeline.rankings import write_extras_rankings
    from mcbench.pipeline.viewer import write_viewer

    scratch_metric("mae", MAE_PLUGIN)
    buffers = make_render_buffers(spp=SPP, half_std=0.05, seed=7)
    truth = make_render_buffers(spp=SPP, half_std=0.0).color
    write_layers(tmp_path / "render.exr", buffers.layers, metadata={"spp": SPP, "scene": SCENE})
    write_layers(tmp_path / "reference.exr", {"color": truth}, metadata={"spp": 4096, "scene": SCENE})
    case = tmp_path / "case"
    record = run_case(case_job(case, scene=SCENE, spp=SPP, render=tmp_path / "render.exr",
                               reference=tmp_path / "reference.exr", metrics=["relmse", "mae"],
                               methods=[("jbf", "jbf", {}, [])]))
    assert record["made"]["metrics"] == [NOISY, "jbf"]
    table = pd.read_csv(case / "case.csv")
    assert list(zip(table.entry, table.metric)) == [(NOISY, "relmse"), (NOISY, "mae"), ("jbf", "relmse"),
                                                        ("jbf", "mae")]
    spec = load_metric("mae")
    expected = spec.value(buffers.color, truth)
    assert table.set_index(["entry", "metric"]).loc[(NOISY, "mae"), "value"] == expected
    fragment = json.loads((case / "viewer_case" / "case.json").read_text())
    assert fragment["errors"]["jbf"] == {"relmse": "jbf_relmse.png", "mae": "jbf_mae.png"}

    table.to_csv(tmp_path / "metrics.csv", index=False)
    viewer = tmp_path / "viewer"
    manifest = write_viewer(str(tmp_path / "metrics.csv"), [str(case / "viewer_case")], str(viewer),
                            cases=[(SCENE, SPP)], candidates=["jbf"], labels={NOISY: "Noisy", "jbf": "JBF"},
                            metric_names=["relmse", "mae"], static_dir=str(REPO / "workflow" / "report" / "viewer"))
    assert manifest["maps"] == ["relmse", "mae"] and manifest["metric_labels"]["mae"] == "Mean absolute error"
    assert manifest["scales"]["mae"]["colormap"] == "inferno" and (viewer / manifest["scales"]["mae"]["legend"]).is_file()
    jbf = Denoised.load(case / "outputs" / "jbf.exr").full
    assert manifest["cases"][SCENE][str(SPP)]["numbers"]["jbf"]["mae"] == spec.value(jbf, truth)
    write_extras_rankings(str(tmp_path / "metrics.csv"), "mae", str(tmp_path / "e.csv"), str(tmp_path / "e.md"),
                          pool=[NOISY], extras=["jbf"], labels={NOISY: "Noisy", "jbf": "JBF"})
    assert (tmp_path / "e.md").read_text().startswith("# Extra methods by Mean absolute error\n")


def test_a_metric_where_higher_is_better_is_refused_when_the_study_is_planned(scratch_metric):
    """The rankings and the study score lower values as better: such a metric is refused naming its
    key and file, before any job."""
    from mcbench import BenchError
    from mcbench.pipeline.config import resolve_config
    from mcbench.pipeline.plan import plan_study

    scratch_metric("psnr", '''
        from mcbench.contracts.metric import MetricSpec
        METRIC = MetricSpec(name="psnr", label="PSNR", value=len, lower_is_better=False)
        ''')
    config = resolve_config({"scenes": ["cornell_box"], "metrics": ["relmse", "psnr"]}, source="my.yaml")
    with pytest.raises(BenchError, match=r"my\.yaml: metrics\[1\]: metrics/psnr\.py declares lower_is_better=False"):
        plan_study(config, source="my.yaml", is_learned=lambda module: False)


def test_the_report_captions_name_a_metric_by_its_plugins_label():
    """No caption lists the metrics' labels: a caption about one metric renders the label its rule
    passes (``params.metric_label``, from the metric's plugin), so an added metric is named right."""
    import re
    import types

    import jinja2

    captions = sorted((REPO / "workflow" / "report").glob("*.rst"))
    rules = "\n".join(p.read_text() for p in sorted((REPO / "workflow" / "rules").glob("*.smk")))
    labelled = [p for p in captions if "snakemake.params.metric_label" in p.read_text()]
    assert {p.name for p in labelled} >= {"ranking.rst", "extras.rst", "comparisons_onehot.rst",
                                          "comparisons_ranking.rst", "error_curves.rst", "speed_error.rst"}
    stand_in = types.SimpleNamespace(params=types.SimpleNamespace(metric_label="Mean absolute error", metric="mae"),
                                     wildcards=types.SimpleNamespace(metric="mae"), config={})
    for path in captions:
        text = path.read_text()
        assert not re.search(r"set names\s*=|\"relmse\"\s*:", text), f"{path.name} lists metric labels"
        if path in labelled:
            assert "Mean absolute error" in jinja2.Template(text).render(snakemake=stand_in), path.name
    for block in re.split(r"\nrule ", rules):
        uses = {name for name in re.findall(r'caption="\.\./report/(\w+\.rst)"', block)}
        if uses & {p.name for p in labelled}:
            assert "metric_label=" in block, f"rule {block.split(':')[0]} renders a metric label it does not pass"
