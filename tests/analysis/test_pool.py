"""The 39-candidate pool (mcbench.analysis.pool) against the shared study file and the paper's constraints,
and its expansion into a config's methods."""

import re
from pathlib import Path

import pytest

from mcbench.analysis import pool
from mcbench.pipeline.config import resolve_config

SHARED_POOL = Path(__file__).resolve().parents[3] / "shared" / "study" / "candidate-pool.md"


def _shared_text():
    if not SHARED_POOL.exists():
        pytest.skip(f"{SHARED_POOL} not present (../shared beside the checkout)")
    return SHARED_POOL.read_text()


def test_pool_matches_the_shared_file_row_by_row():
    rows = re.findall(r"^\| (\d+) \| ([\d,…]+) \| (\w+)", _shared_text(), flags=re.M)
    assert len(rows) == 31
    for number, members, source in rows:
        cid = int(number)
        if "…" in members:                       # "1,…,8"
            low, high = members.split(",…,")
            expected = tuple(range(int(low), int(high) + 1))
        else:
            expected = tuple(int(m) for m in members.split(","))
        assert pool.members_of(cid) == expected, cid
        assert pool.ENSEMBLES[cid][1] == source, cid


def test_table3_matches_the_shared_file():
    text = _shared_text()
    found = 0
    for line in text.splitlines():
        match = re.match(r"^\| #(\d+)[^|]*\|((?: [\d.]+ \|){10})$", line)
        if match:
            values = [float(v) for v in match.group(2).split("|") if v.strip()]
            cid = int(match.group(1))
            assert [pool.PAPER_TABLE3[cid][s] for s in pool.PAPER_TABLE3_SPP] + [pool.PAPER_TABLE3[cid]["Avg."]] \
                == values, cid
            found += 1
    assert found == len(pool.PAPER_TABLE3) == 11


def test_pool_obeys_the_papers_constraints():
    sizes = [len(pool.members_of(i)) for i in pool.ENSEMBLE_IDS]
    assert {s: sizes.count(s) for s in set(sizes)} == {2: 8, 3: 8, 4: 7, 5: 3, 6: 4, 8: 1}
    assert len(pool.POOL) == 39 and pool.POOL_IDS == tuple(range(1, 40))
    # within a size, IDs follow the lexicographic order of the member tuples
    for size in set(sizes):
        ids = [i for i in pool.ENSEMBLE_IDS if len(pool.members_of(i)) == size]
        assert [pool.members_of(i) for i in ids] == sorted(pool.members_of(i) for i in ids)
    named = {10: (1, 4), 16: (7, 8), 18: (1, 4, 8), 20: (1, 6, 8), 24: (6, 7, 8), 27: (1, 4, 6, 8),
             28: (3, 5, 6, 7), 29: (4, 5, 6, 8), 30: (4, 6, 7, 8), 33: (1, 4, 6, 7, 8), 35: (1, 3, 4, 6, 7, 8),
             39: tuple(range(1, 9))}
    for cid, members in named.items():
        assert pool.members_of(cid) == members and pool.ENSEMBLES[cid][1] == "paper"
    assert len({pool.members_of(i) for i in pool.ENSEMBLE_IDS}) == 31       # no set twice
    assert pool.is_homogeneous(pool.members_of(28)) and not pool.is_homogeneous(pool.members_of(27))
    assert pool.has_dc(pool.members_of(29)) and not pool.has_dc(pool.members_of(27))


def test_default_config_expands_into_the_whole_pool_once():
    from methods import config_method_table

    table = config_method_table(resolve_config({}), is_learned=lambda module: False)
    names = pool.pool_names()
    assert all(name in table for name in names)
    for cid in pool.ENSEMBLE_IDS:
        spec = table[pool.candidate_name(cid)]
        assert spec["module"] == "ensemble" and spec["params"] == {}
        assert spec["inputs"] == [pool.BASES[m] for m in pool.members_of(cid)]
    assert table["nfor_dc"]["inputs"] == ["nfor"] and table["kpcn_dc"]["inputs"] == ["kpcn"]
    # no other full ensemble over a pool member set (it would be the same candidate twice)
    pool_sets = {frozenset(table[n]["inputs"]) for n in names if n.startswith("ens")}
    others = [n for n, s in table.items() if s["module"] == "ensemble" and not s["params"] and n not in names]
    assert all(frozenset(table[n]["inputs"]) not in pool_sets for n in others)


def test_a_subset_brings_what_it_needs_and_only_that():
    denoisers, combiners = pool.pool_methods([29])
    assert denoisers == ["kpcn", "nfor", "oidn", "rdfc"]                 # #5 KPCN-DC needs KPCN
    assert [c["name"] for c in combiners] == ["kpcn_dc", "ens29"]
    assert combiners[-1]["inputs"] == ["nfor", "kpcn_dc", "oidn", "rdfc"]
    with pytest.raises(pool.PoolError, match=r"\[40\]"):
        pool.pool_methods([40])


def test_clashing_config_lines_stop_naming_the_line():
    base = {"denoisers": ["oidn"], "study": {"ensembles": [10]}}
    duplicate = resolve_config({**base, "combiners": [{"name": "mine", "method": "ensemble", "inputs": ["nfor", "kpcn"]}]})
    with pytest.raises(pool.PoolError, match=r"combiners\[0\].*ens10"):
        pool.expand_methods(duplicate)
    redefined = resolve_config({**base, "combiners": [{"name": "ens10", "method": "ensemble", "inputs": ["kpcn", "nfor"],
                                                       "params": {"solver": "exact"}}]})
    with pytest.raises(pool.PoolError, match=r"combiners\[0\]: 'ens10'"):
        pool.expand_methods(redefined)
    variant = resolve_config({**base, "combiners": [{"name": "ens10_exact", "method": "ensemble",
                                                     "inputs": ["kpcn", "nfor"], "params": {"solver": "exact"}}]})
    denoisers, combiners = pool.expand_methods(variant)
    assert [k for k, _ in combiners] == ["study.pool (#10 ens10)", "combiners[0]"]
    assert [e for _, e in denoisers] == ["kpcn", "nfor", "oidn"]
    off = resolve_config({**base, "combiners": [], "study": {"pool": False}})
    assert pool.expand_methods(off) == ([("denoisers[0]", "oidn")], [])
