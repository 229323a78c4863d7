"""Which job makes each per-method file (mcbench.pipeline.jobs), and the warm workers' file cache."""

from __future__ import annotations

import itertools
import os

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mcbench.io.file_cache import cached_read, clear_cache
from mcbench.pipeline.jobs import (batch_name, batch_text, missing_batches, read_batch, spec_text, target_batch_names,
                                   write_if_changed)
from mcbench.pipeline.logs import run_logged

SCENES = ["a", "b", "c"]
SPPS = [4, 16]
ITEMS = ["oidn", "jbf", "ens"]


@settings(max_examples=200, deadline=None)
@given(st.sets(st.tuples(st.sampled_from(SCENES), st.sampled_from(SPPS), st.sampled_from(ITEMS))))
def test_every_missing_file_is_in_exactly_one_batch_whose_cases_lack_exactly_its_items(present):
    cases = list(itertools.product(SCENES, SPPS))
    batches = missing_batches(cases, ITEMS, lambda scene, spp, item: (scene, spp, item) in present)
    covered = [(scene, spp, item) for b in batches for scene in b["scenes"] for spp in b["spps"] for item in b["items"]]
    missing = {(s, n, i) for s, n in cases for i in ITEMS} - present
    assert sorted(covered) == sorted(missing)                    # each missing file once, nothing else
    for b in batches:
        assert b["items"] == [i for i in ITEMS if i in b["items"]]   # dependency order kept
        for scene, spp in itertools.product(b["scenes"], b["spps"]):
            lacking = [i for i in ITEMS if (scene, spp, i) not in present]
            assert lacking == b["items"]                         # a product of cases lacking exactly these


def test_from_scratch_is_one_batch_of_every_item_over_every_case():
    cases = list(itertools.product(SCENES, SPPS))
    assert missing_batches(cases, ITEMS, lambda *key: False) == [{"items": ITEMS, "scenes": SCENES, "spps": SPPS}]
    assert missing_batches(cases, ITEMS, lambda *key: True) == []


def test_a_new_method_is_one_batch_of_itself():
    cases = list(itertools.product(SCENES, SPPS))
    batches = missing_batches(cases, ITEMS + ["new"], lambda scene, spp, item: item != "new")
    assert batches == [{"items": ["new"], "scenes": SCENES, "spps": SPPS}]


def test_batch_names_are_stable_and_distinct():
    one = {"items": ["jbf"], "scenes": ["a"], "spps": [4]}
    assert batch_name("run_methods", one) == batch_name("run_methods", dict(one))
    assert batch_name("run_methods", one) != batch_name("run_methods", {**one, "spps": [16]})
    assert batch_name("run_methods", one).startswith("run_methods_")


def test_a_recorded_batch_reads_back_as_the_same_rule_and_a_foreign_record_is_refused(tmp_path):
    """A process started for target jobs defines a batch rule from the main process's record:
    the record reads back to the batch of the same name; a record of another batch, a damaged or
    a missing one stops the parse naming the file (a wrong rule would remake other files)."""
    batch = {"items": ["oidn", "noisy:metrics"], "scenes": ["a", "b"], "spps": [4, 16]}
    name = batch_name("case_batch", batch)
    path = tmp_path / f"{name}.json"
    write_if_changed(path, batch_text(batch))
    assert read_batch(path, name, "case_batch") == batch
    other = batch_name("case_batch", {**batch, "spps": [4]})
    with pytest.raises(ValueError, match=f"{path}.*not batch rule"):
        read_batch(path, other, "case_batch")
    path.write_text("{not json")
    with pytest.raises(ValueError, match=str(path)):
        read_batch(path, name, "case_batch")
    with pytest.raises(ValueError, match="missing.json"):
        read_batch(tmp_path / "missing.json", name, "case_batch")


def test_the_batch_rules_a_command_line_targets_are_read_from_its_target_jobs():
    """How Snakemake starts a spawned or cluster job: ``--target-jobs RULE:WILDCARDS ...``."""
    argv = ["python", "-m", "snakemake", "--snakefile", "Snakefile", "--target-jobs",
            "case_batch_0123456789ab:scene=a,spp=4", "'run_method:method=oidn,scene=a,spp=4'",
            "case_batch_0123456789ab:scene=a,spp=16", "\"case_batch_ffffffffffff:scene=b,spp=4\"",
            "--cores", "1", "case_batch_eeeeeeeeeeee:scene=c,spp=4"]
    assert target_batch_names(argv, "case_batch") == ["case_batch_0123456789ab", "case_batch_ffffffffffff"]
    assert target_batch_names(["x", "--target-jobs=case_batch_1:scene=a,spp=4"], "case_batch") == ["case_batch_1"]
    assert target_batch_names(["snakemake", "--cores", "2"], "case_batch") == []


def test_a_log_on_a_full_disk_fails_the_step_naming_the_log_and_the_reason(capfd):
    """/dev/full takes the open and refuses every write (ENOSPC): the step fails, and the terminal
    line names the log and why, not a bare errno without a file."""
    def chatty_step():
        os.write(1, b"x" * 100_000)                  # as a C++ library writes: to fd 1

    with pytest.raises(SystemExit):
        run_logged("/dev/full", chatty_step)
    err = capfd.readouterr().err
    assert "/dev/full: cannot write the log (No space left on device)" in err


def test_a_failing_step_with_a_writable_log_puts_the_traceback_there(tmp_path, capfd):
    log = tmp_path / "step.log"

    def failing_step():
        raise ValueError("results/renders/a/spp4.exr: not an EXR")

    with pytest.raises(SystemExit):
        run_logged(str(log), failing_step)
    err = capfd.readouterr().err
    assert "ERROR: results/renders/a/spp4.exr: not an EXR" in err and f"(full traceback in {log})" in err
    assert "Traceback" in log.read_text() and "not an EXR" in log.read_text()
    assert run_logged(str(log), lambda: 7) == 7


def test_a_spec_file_keeps_its_mtime_until_the_spec_changes(tmp_path):
    path = tmp_path / "specs" / "jbf.json"
    assert write_if_changed(path, spec_text({"module": "jbf", "params": {"radius": 7}}))
    os.utime(path, ns=(1_000_000_000, 1_000_000_000))
    assert not write_if_changed(path, spec_text({"params": {"radius": 7}, "module": "jbf"}))   # same spec
    assert path.stat().st_mtime_ns == 1_000_000_000
    assert write_if_changed(path, spec_text({"module": "jbf", "params": {"radius": 9}}))
    assert path.stat().st_mtime_ns > 1_000_000_000
    assert not list(tmp_path.glob("specs/.*"))                   # no temporary file left


def test_the_file_cache_rereads_a_rewritten_file_and_hands_out_read_only_arrays(tmp_path):
    clear_cache()
    path = tmp_path / "values.npy"
    np.save(path, np.arange(4.0))
    reads = []

    def reader(p):
        reads.append(p)
        return {"values": np.load(p)}

    first = cached_read(str(path), reader)
    assert cached_read(str(path), reader) is first and len(reads) == 1
    with pytest.raises(ValueError):
        first["values"][0] = 5.0                                 # an in-place write fails loudly
    stat = path.stat()
    with open(path, "r+b") as handle:                            # changed in place, mtime set back
        handle.seek(-8, 2)
        handle.write(np.float64(9.0).tobytes())
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    again = cached_read(str(path), reader)
    assert len(reads) == 2 and again["values"][-1] == 9.0         # ctime changed: read again
    with pytest.raises(FileNotFoundError):
        cached_read(str(tmp_path / "missing.npy"), reader)       # the reader's own error
