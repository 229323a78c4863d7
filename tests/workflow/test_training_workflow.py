"""The training DAG of a learned combiner whose base is learned too (the deep combiner over KPCN):
the combiner's training inputs are its bases' results on the training crops, made with the base's
weights, so a base trained in the same run comes first (as when every network is retrained on
new features), and weights that exist already are taken as they are. Dry runs of a one-crop training config; the crops and
the bases' results exist and are older than any weights, as after a finished crop stage. (Where a
learned base's weights are missing but stale results of it exist, Snakemake keeps those results:
an output is not remade for a missing input; the combiner's training then refuses them by the
weights digest they record, tests/pipeline/test_training.py.)"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path

import pytest
import yaml

from tests.conftest import run_snakemake as snakemake

CONFIG = {"scenes": ["cornell_box"], "spp": [4], "denoisers": ["nfor", "kpcn"],
          "combiners": [{"name": "kpcn_dc", "method": "deep_combiner", "inputs": ["kpcn"]}],
          "study": {"pool": False}, "weights_dir": "weights",
          "training": {"count": 1, "fibre_count": 0, "crops": 1,
                       "combiners": {"count": 1, "fibre_count": 0, "crops": 1}}}
BASES = ("nfor", "kpcn", "oidn")   # the deep combiner's declared correlated_bases


@pytest.fixture()
def workdir(tmp_path) -> Path:
    """A training folder with its crop and its bases' results made a minute ago (after the
    checkout's scripts, which are their code), and no weights."""
    made = time.time() - 60
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(CONFIG))
    files = [tmp_path / "results/training/example_0_0.exr"]
    files += [tmp_path / f"results/training/correlated/{base}/example_0_0.exr" for base in BASES]
    for path in files:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.touch()
        os.utime(path, (made, made))
    (tmp_path / "weights").mkdir()
    return tmp_path


def _planned(workdir: Path, *targets: str, options: tuple[str, ...] = ()) -> tuple[dict[str, int], str]:
    """The job counts of a dry run of ``targets`` (with Snakemake's ``options``) and its output."""
    result = snakemake(workdir, "-n", *options, "--", *targets)
    text = result.stdout + result.stderr
    return {rule: int(n) for rule, n in re.findall(r"^(\w+)\s+(\d+)$", text, flags=re.MULTILINE)}, text


def test_a_combiner_over_an_untrained_base_trains_the_base_first_and_then_its_results(workdir):
    for path in (workdir / "results/training/correlated").glob("*/*.exr"):
        path.unlink()                    # crops made, no base results yet
    counts, text = _planned(workdir, "train_deep_combiner")
    # KPCN trained (train_network), its results on the crop made with those weights, then the
    # combiner trained (its own rule: a Snakemake rule may not depend on itself)
    assert counts.get("train_network") == 1 and "network=kpcn" in text
    assert counts.get("training_correlated") == len(BASES) and "base=kpcn" in text
    assert counts.get("train_combiner") == 1 and "network=deep_combiner" in text


def test_existing_base_weights_are_not_an_input_of_its_results(workdir):
    """Weights that exist are not an input of the base's results (StudyPlan's base_weights): their
    training job stays out of the DAG (under the input rerun trigger it would run again, deleting
    them), and their mtime remakes nothing; new weights remake only that base's results through
    their digest, a parameter of the rule (a real run: tests/workflow/test_workflow.py,
    test_a_base_trained_here_is_not_trained_again_for_its_combiners_training)."""
    weights = workdir / "weights" / "kpcn.pt"
    weights.touch()                      # newer than the crop's KPCN results
    for triggers in ((), ("--rerun-triggers", "mtime", "params", "input", "software-env", "code")):
        counts, text = _planned(workdir, "train_deep_combiner", options=triggers)
        assert "train_network" not in counts and "training_correlated" not in counts, text[-2000:]
        assert counts.get("train_combiner") == 1
