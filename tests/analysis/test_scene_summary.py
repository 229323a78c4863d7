"""Scene report: the reference noise floor against a closed form and a simulation, the
warning when a reference is too noisy, and the gallery figure."""

import numpy as np
import pandas as pd
import pytest

from mcbench.analysis.metrics import relmse
from mcbench.analysis.scene_summary import ReferenceNoiseWarning, gallery_figure, reference_relmse_floor, scene_rows


def test_floor_closed_form():
    color = np.full((4, 4, 3), 1.0)
    variance = np.full((4, 4, 3), 0.0202)
    assert reference_relmse_floor(color, variance) == pytest.approx(0.0202 / 1.01)


def test_floor_predicts_relmse_of_a_noisy_reference_against_the_truth():
    rng = np.random.default_rng(5)
    truth = rng.gamma(2.0, 0.5, size=(64, 64, 3))
    sigma = 0.05 * truth + 0.01
    reference = truth + rng.normal(size=truth.shape) * sigma
    predicted = reference_relmse_floor(reference, sigma ** 2)
    assert relmse(reference, truth) == pytest.approx(predicted, rel=0.1)


def _metrics(best_value):
    rows = [("s", 1024, "noisy", "relmse", 1e-2), ("s", 1024, "a", "relmse", best_value),
            ("s", 1024, "b", "relmse", 1.0), ("s", 4, "a", "relmse", 1e-6)]
    return pd.DataFrame(rows, columns=["scene", "spp", "entry", "metric", "value"])


def test_scene_rows_ratio_and_warning():
    info = {"s": {"category": "diffuse", "description": "d", "reference_spp": 1024}}
    with pytest.warns(ReferenceNoiseWarning, match="scene 's'.*1024 spp"):
        table = scene_rows(_metrics(5e-4), {"s": 1e-4}, info, {})
    row = table.iloc[0]
    assert row.best_candidate == "a" and row.top_spp == 1024
    assert row.floor_ratio == pytest.approx(5.0) and not row.floor_ok
    table = scene_rows(_metrics(2e-3), {"s": 1e-4}, info, {})
    assert table.iloc[0].floor_ok


def test_gallery_writes_png(tmp_path):
    images = {f"scene_{i}": np.full((8, 8, 3), i / 3) for i in range(4)}
    path = tmp_path / "gallery.png"
    gallery_figure(images, path, columns=3)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_scene_table_as_latex_escapes_text_and_bolds_too_noisy_references():
    import pandas as pd

    from mcbench.analysis.scene_summary import scene_latex

    table = pd.DataFrame([
        {"scene": "cornell_box", "category": "diffuse", "reference_spp": 65536, "reference_relmse": 5e-6,
         "noisy_relmse": 0.0048, "best_candidate": "ens_oidn_nfor", "best_relmse": 5e-4, "floor_ratio": 100.0,
         "floor_ok": True},
        {"scene": "fog_beams", "category": "media & fog", "reference_spp": 16384, "reference_relmse": 5e-5,
         "noisy_relmse": 0.0048, "best_candidate": "kpcn", "best_relmse": 2e-4, "floor_ratio": 4.0, "floor_ok": False},
    ])
    text = scene_latex(table, caption="Scenes 100% & more")
    body = [line for line in text[text.index(r"\midrule"):text.index(r"\bottomrule")].splitlines()[1:] if line.strip()]
    assert len(body) == 2 and all(line.count(" & ") == 7 and line.rstrip().endswith(r"\\") for line in body)
    assert r"cornell\_box" in body[0] and r"ens\_oidn\_nfor" in body[0] and r"\textbf" not in body[0]
    assert body[1].rstrip().endswith(r"\textbf{4.0} \\") and r"media \& fog" in body[1]
    assert r"\caption{Scenes 100\% \& more}" in text and text.count("{") == text.count("}")
    assert text.index(r"\toprule") < text.index(r"\midrule") < text.index(r"\bottomrule")


def _two_scene_metrics():
    """Two scenes x two spp; pool candidates a, b and the noisy input n (never ranked 'best')."""
    rows = []
    values = {("s1", 512): (0.20, 0.40, 1.0), ("s1", 1024): (0.099, 0.30, 1.0),
              ("s2", 512): (0.50, 0.60, 2.0), ("s2", 1024): (0.10, 0.25, 2.0)}
    for (scene, spp), (a, b, n) in values.items():
        rows += [(scene, spp, "a", "relmse", a), (scene, spp, "b", "relmse", b), (scene, spp, "n", "relmse", n),
                 (scene, spp, "a", "smape", 9.0)]
    return pd.DataFrame(rows, columns=["scene", "spp", "entry", "metric", "value"])


def test_column_floor_ratios_and_unrankable_columns_by_closed_form():
    from mcbench.analysis.scene_summary import column_floor_ratios, unrankable_columns

    ratios = column_floor_ratios(_two_scene_metrics(), {"s1": 0.01, "s2": 0.01}, candidates=["a", "b"])
    by_case = ratios.set_index(["scene", "spp"])["floor_ratio"]
    # best pool candidate over the floor: s1 1024 is 0.099 / 0.01 = 9.9, s2 1024 exactly 10
    assert by_case[("s1", 512)] == pytest.approx(20.0) and by_case[("s1", 1024)] == pytest.approx(9.9)
    assert by_case[("s2", 512)] == pytest.approx(50.0) and by_case[("s2", 1024)] == pytest.approx(10.0)
    # 9.9 is below the 10x the scene table requires, 10.0 is not: only 1024 is marked, by s1 alone
    assert unrankable_columns(ratios) == {1024: [("s1", pytest.approx(9.9))]}
    # an unknown floor (imported reference without variance) marks nothing; a zero floor is infinite
    unknown = column_floor_ratios(_two_scene_metrics(), {"s1": None, "s2": 0.0}, candidates=["a", "b"])
    assert unknown["floor_ratio"].isna().sum() == 2 and np.isinf(unknown["floor_ratio"]).sum() == 2
    assert unrankable_columns(unknown) == {}
    with pytest.raises(ValueError, match="s2"):
        column_floor_ratios(_two_scene_metrics(), {"s1": 0.01}, candidates=["a"])


def test_ranking_markdown_marks_the_columns_the_references_cannot_rank(tmp_path):
    from mcbench.pipeline.rankings import write_rankings

    metrics = _two_scene_metrics()
    metrics = metrics[metrics["metric"] == "relmse"]
    path = tmp_path / "metrics.csv"
    metrics.to_csv(path, index=False)
    scenes = tmp_path / "scenes.csv"
    pd.DataFrame({"scene": ["s1", "s2"], "reference_relmse": [0.01, 0.01]}).to_csv(scenes, index=False)
    write_rankings(str(path), "relmse", str(tmp_path / "r.csv"), str(tmp_path / "r.md"), entries=["n", "a", "b"],
                   labels={}, tex_path=str(tmp_path / "r.tex"), scenes_csv=str(scenes), noisy="n")
    text = (tmp_path / "r.md").read_text()
    header = next(line for line in text.splitlines() if line.startswith("| candidate"))
    assert "1024 ‡" in header and "512 ‡" not in header
    assert "1024 spp (s1 9.9×)" in text
    assert r"1024 spp \ddag{}" in (tmp_path / "r.tex").read_text()
    assert list(pd.read_csv(tmp_path / "r.csv").columns) == ["candidate", "512", "1024", "Avg."]  # CSV unmarked
    write_rankings(str(path), "relmse", str(tmp_path / "q.csv"), str(tmp_path / "q.md"), entries=["n", "a", "b"],
                   labels={}, noisy="n")
    assert "‡" not in (tmp_path / "q.md").read_text()
