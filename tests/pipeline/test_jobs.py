"""Which job makes each per-method file (mcbench.pipeline.jobs), and the warm workers' file cache."""

from __future__ import annotations

import itertools
import os

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mcbench.io.file_cache import cached_read, clear_cache
from mcbench.pipeline.jobs import batch_name, missing_batches, spec_text, write_if_changed

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
