"""The 39-candidate pool (mcbench.analysis.pool) against an independent transcription of its
sources and the paper's constraints, and its expansion into a config's methods."""

import pytest

from mcbench.analysis import pool
from mcbench.pipeline.config import resolve_config

# The pool as the study fixes it (Zheng et al. 2021, Sec. 5.3.1: sizes from the case counts of
# Tables 1-2, the 12 ensembles the text and Table 3 name, IDs in lexicographic order of the member
# tuples within a size, which forces #31; the rest filled by that order and the paper's stated
# intent): ID | members (paper numbers of the bases) | source (its first word is pool.py's).
POOL_ROWS = """
 9 | 1,3             | filled (homogeneous, learned)
10 | 1,4             | paper
11 | 1,8             | filled
12 | 3,4             | filled
13 | 4,6             | filled
14 | 4,8             | filled (homogeneous, classical)
15 | 6,8             | filled (Fig. 12)
16 | 7,8             | paper
17 | 1,3,8           | filled
18 | 1,4,8           | paper
19 | 1,6,7           | filled (homogeneous, learned)
20 | 1,6,8           | paper
21 | 2,6,8           | filled (with NFOR-DC)
22 | 3,7,8           | filled (Fig. 11)
23 | 4,6,8           | filled
24 | 6,7,8           | paper
25 | 1,3,4,8         | filled (Fig. 1)
26 | 1,4,6,7         | filled
27 | 1,4,6,8         | paper
28 | 3,5,6,7         | paper
29 | 4,5,6,8         | paper
30 | 4,6,7,8         | paper
31 | 5,6,7,8         | forced (by the order)
32 | 1,3,4,6,8       | filled
33 | 1,4,6,7,8       | paper
34 | 3,4,6,7,8       | filled
35 | 1,3,4,6,7,8     | paper
36 | 2,3,4,6,7,8     | filled
37 | 2,4,5,6,7,8     | filled
38 | 3,4,5,6,7,8     | filled
39 | 1,2,3,4,5,6,7,8 | paper
"""

# Table 3 of Zheng et al. 2021 (relMSE ranking scores, 40 entries, mean over the paper's 30
# scenes), as printed: candidate | 4 | 8 | 16 | 32 | 64 | 128 | 256 | 512 | 1024 spp | Avg.
TABLE3_ROWS = """
#1 KPCN | 16.5 | 15.0 | 15.0 | 16.0 | 15.7 | 16.8 | 16.7 | 15.4 | 12.8 | 15.5
#3 MCGAN | 15.9 | 14.2 | 12.7 | 10.5 | 7.8 | 5.9 | 4.6 | 3.5 | 2.6 | 8.6
#4 NFOR | 5.0 | 5.1 | 5.8 | 8.1 | 9.7 | 11.4 | 12.3 | 12.5 | 14.0 | 9.3
#6 OIDN | 23.8 | 17.7 | 12.0 | 8.9 | 7.0 | 6.6 | 5.2 | 4.9 | 4.2 | 10.0
#7 OptiX | 12.4 | 9.9 | 7.5 | 6.5 | 5.9 | 5.0 | 5.0 | 4.6 | 4.5 | 6.8
#8 RDFC | 10.9 | 10.0 | 10.7 | 10.4 | 11.8 | 12.9 | 14.6 | 16.8 | 18.1 | 12.9
#16 (#7+#8) | 21.7 | 18.6 | 17.3 | 16.2 | 17.5 | 18.5 | 19.3 | 21.4 | 22.0 | 19.2
#24 (#16+#6) | 28.6 | 24.8 | 22.4 | 19.4 | 19.5 | 19.1 | 19.3 | 21.0 | 21.3 | 21.7
#30 (#24+#4) | 20.7 | 22.0 | 23.2 | 24.0 | 25.1 | 26.7 | 27.4 | 27.7 | 27.9 | 25.0
#33 (#30+#1) | 23.5 | 25.9 | 28.0 | 29.1 | 29.3 | 31.0 | 31.1 | 31.5 | 31.8 | 29.0
#35 (#33+#3) | 21.1 | 23.4 | 27.0 | 28.5 | 29.4 | 29.4 | 28.4 | 27.6 | 26.3 | 26.8
"""


def _pool_rows():
    for line in POOL_ROWS.strip().splitlines():
        number, members, source = (field.strip() for field in line.split("|"))
        yield int(number), members, source


def test_pool_matches_the_transcribed_rows():
    rows = list(_pool_rows())
    assert [cid for cid, _, _ in rows] == list(range(9, 40))
    for cid, members, source in rows:
        assert pool.members_of(cid) == tuple(int(m) for m in members.split(",")), cid
        assert pool.ENSEMBLES[cid][1] == source.split()[0], cid


def test_table3_matches_the_paper():
    found = 0
    for line in TABLE3_ROWS.strip().splitlines():
        label, *values = (field.strip() for field in line.split("|"))
        cid = int(label.split()[0].lstrip("#"))
        assert [pool.PAPER_TABLE3[cid][s] for s in pool.PAPER_TABLE3_SPP] + [pool.PAPER_TABLE3[cid]["Avg."]] \
            == [float(v) for v in values], cid
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
