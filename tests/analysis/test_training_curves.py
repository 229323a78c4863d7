"""The validation-curve page of training records (mcbench.analysis.training_curves): the round it
marks as kept is the one the trainer keeps (lowest validation loss at a round's end, not the
lowest validation anywhere), and the page and curves are written from a weights folder."""

from __future__ import annotations

import json

import pytest

from mcbench.analysis.training_curves import kept_round, main, network_section

HISTORY = [  # two rounds of 2000 steps; the lowest loss of all is mid-round (step 3000)
    {"step": 1000, "round": 1, "train_loss": 0.30, "validation_loss": 0.20, "validation_relmse": 0.5},
    {"step": 2000, "round": 1, "train_loss": 0.20, "validation_loss": 0.12, "validation_relmse": 0.4},
    {"step": 3000, "round": 2, "train_loss": 0.15, "validation_loss": 0.10, "validation_relmse": 0.3},
    {"step": 4000, "round": 2, "train_loss": 0.14, "validation_loss": 0.119, "validation_relmse": 0.35},
]
RECORD = {"label": "Net†", "loss": "l1", "settings": {"steps": 2000, "rounds": 3, "plateau": 0.02},
          "steps_run": 4000, "rounds_run": 2, "stopped_by": "plateau", "history": HISTORY, "seconds": 600.0,
          "threads": 1, "cpu": {"model": "AMD EPYC 9R14"}, "data": {"features": "tungsten"}}


def test_the_kept_round_is_the_best_round_end_not_the_best_validation():
    assert kept_round(HISTORY, 2000)["step"] == 4000            # 0.119 < 0.12 at the round ends
    assert kept_round(HISTORY[:3], 2000)["step"] == 2000
    assert kept_round(HISTORY[:1], 2000) is None


def test_a_network_section_names_the_cpu_the_rule_and_the_kept_row():
    text = "\n".join(network_section("net", RECORD))
    assert "AMD EPYC 9R14" in text and "1 torch thread(s)" in text and "10.0 minutes" in text
    assert "ran 4000 steps in 2 round(s), stopped by plateau; kept: round 2" in text
    assert "| 4000 | 2 | 0.14 | 0.119 (kept) | 0.35 |" in text
    assert text.count("(kept)") == 1 and "features: tungsten" in text
    vm = {**RECORD, "cpu": {"model": "AMD EPYC", "family": "25", "model_number": "17", "avx512f": True}}
    assert "of AMD EPYC (family 25 model 17, AVX-512)" in "\n".join(network_section("net", vm))


def test_the_page_and_curves_are_written_from_a_weights_folder(tmp_path):
    (tmp_path / "weights").mkdir()
    (tmp_path / "weights" / "net.json").write_text(json.dumps(RECORD))
    main([str(tmp_path / "weights"), "--out", str(tmp_path / "docs" / "training.md")])
    page = (tmp_path / "docs" / "training.md").read_text()
    assert "![net](training/net.png)" in page
    assert (tmp_path / "docs" / "training" / "net.png").read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(ValueError, match="no training records"):
        main([str(tmp_path / "docs" / "training")])


def test_the_summary_gives_each_network_its_rounds_losses_and_the_compared_loss(tmp_path):
    from mcbench.analysis.training_curves import summary_table

    record = {**RECORD, "validation": {"loss": 0.119, "per_spp": {
        "4": {"relmse": 0.05, "noisy_relmse": 2.5}, "16": {"relmse": 0.02, "noisy_relmse": 0.35}}}}
    first_hit = {**RECORD, "data": {}, "validation": {"loss": 0.125}}
    lines = summary_table({"net": record}, compare={"net": first_hit})
    assert lines[2] == "| `net` | tungsten | 2 (plateau) | 4000 | 10 | 1 | 0.119 | — | 0.125 | 0.05 (2.5) / 0.02 (0.35) / — |"
    assert summary_table({"net": first_hit})[2].startswith("| `net` | first_hit | 2 (plateau) | 4000 | 10 | 1 | 0.125 | — |")
    combiner = {**record, "validation": {"loss": 0.1, "per_spp": {"4": {"correlated_loss": 0.3, "relmse": 0.2, "noisy_relmse": 2.0},
                                                                 "16": {"correlated_loss": 0.1, "relmse": 0.1, "noisy_relmse": 0.3}}}}
    assert "| 0.1 | 0.2 |" in summary_table({"dc": combiner})[2]          # the inputs' mean over the levels
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "net.json").write_text(json.dumps(record))
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "net.json").write_text(json.dumps(first_hit))
    main([str(tmp_path / "a"), "--out", str(tmp_path / "training.md"), "--compare", str(tmp_path / "b")])
    page = (tmp_path / "training.md").read_text()
    assert f"--out {tmp_path / 'training.md'} --compare {tmp_path / 'b'}" in page and "| 0.119 | — | 0.125 |" in page

