"""Our relMSE scores beside the paper's Table 3 (Zheng et al. 2021 Sec. 5.3.3-5.3.4): per
candidate of Table 3 and spp ours and the paper's (:func:`paper_comparison`), and the Kendall
tau of the two orderings (:func:`paper_kendall`)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from mcbench.analysis import pool
from mcbench.analysis.study.data import finite_or_none

__all__ = ["PAPER_TABLE3_BASES", "PAPER_COLUMNS", "paper_comparison", "paper_kendall"]

# the columns of paper_comparison (and of paper_table3.csv)
PAPER_COLUMNS = ["id", "candidate", "spp", "ours", "paper", "difference", "note"]
# The base denoisers among the paper's Table 3 rows (KPCN, MCGAN, NFOR, OIDN, OptiX, RDFC).
PAPER_TABLE3_BASES = tuple(cid for cid in pool.PAPER_TABLE3 if pool.candidate(cid).is_base)


def _paper_names(names) -> dict[int, str]:
    names = dict(names or {})
    return {cid: names.get(cid, pool.candidate_name(cid)) for cid in pool.PAPER_TABLE3}



def paper_comparison(ranking: pd.DataFrame, *, names: dict[int, str] | None = None) -> pd.DataFrame:
    """Our scores beside the paper's Table 3 (relMSE; Sec. 5.3.4).

    ``ranking``: index candidate names, columns spp as strings and ``Avg.`` (as
    :func:`mcbench.analysis.ranking.ranking_table`). ``names`` maps the paper's IDs to our candidate names
    (default: the pool's harness names). Long table, one row per candidate of
    :data:`mcbench.analysis.pool.PAPER_TABLE3` (ID order) and column: columns id, candidate, spp (``"4"``
    ... ``"1024"``, our extra spp, ``"Avg."`` and ``"Avg. (common spp)"`` -- both averaged over
    the spp that both tables have), ours, paper, difference (ours - paper), note. A cell one side
    lacks is empty (None) and the note says which.
    """
    mapping = _paper_names(names)
    our_spp = [c for c in ranking.columns if str(c) != "Avg."]
    paper_spp = [str(s) for s in pool.PAPER_TABLE3_SPP]
    common = [s for s in paper_spp if s in [str(c) for c in our_spp]]
    columns = paper_spp + sorted((str(c) for c in our_spp if str(c) not in paper_spp), key=int)
    rows = []
    for cid, name in mapping.items():
        paper_row = pool.PAPER_TABLE3[cid]
        have = name in ranking.index
        for spp in columns + ["Avg.", "Avg. (common spp)"]:
            paper = finite_or_none(paper_row.get(int(spp))) if spp.isdigit() else None
            ours = finite_or_none(ranking.loc[name, spp]) if have and spp in [str(c) for c in ranking.columns] else None
            note = ""
            if spp == "Avg.":
                paper = paper_row["Avg."]
                if have and common != paper_spp:
                    note = "our Avg. is over our spp, the paper's over 4–1024"
            if spp == "Avg. (common spp)":
                paper = float(np.mean([paper_row[int(s)] for s in common])) if common else None
                ours = float(np.mean([float(ranking.loc[name, s]) for s in common])) if common and have else None
                if not common:
                    note = "no spp in common"
            if not have:
                note = f"{name} not in our ranking"
            elif ours is None and spp.isdigit():
                note = "spp not in our data"
            elif paper is None and spp.isdigit():
                note = "spp not in the paper"
            diff = ours - paper if ours is not None and paper is not None else None
            rows.append({"id": cid, "candidate": name, "spp": spp, "ours": ours, "paper": paper, "difference": diff,
                         "note": note})
    return pd.DataFrame(rows, columns=PAPER_COLUMNS)


def _kendall(ours, paper) -> dict:
    ours, paper = np.asarray(ours, dtype=np.float64), np.asarray(paper, dtype=np.float64)
    if len(ours) < 2 or np.all(ours == ours[0]) or np.all(paper == paper[0]):
        return {"n": int(len(ours)), "tau": None, "p_value": None}
    result = stats.kendalltau(ours, paper)
    tau, p = finite_or_none(result.statistic), finite_or_none(result.pvalue)
    return {"n": int(len(ours)), "tau": tau, "p_value": p}


def paper_kendall(ranking: pd.DataFrame, *, names: dict[int, str] | None = None,
                  ids=None) -> pd.DataFrame:
    """Kendall tau-b (:func:`scipy.stats.kendalltau`, two-sided p-value) between our ordering of
    the Table 3 candidates in our ranking and the paper's: once by ``Avg.`` as each table has
    it, once by the mean over the spp both have. ``ids``: only these of the paper's IDs (e.g.
    :data:`PAPER_TABLE3_BASES`, the six bases of its Table 3); default all 11. Columns basis, n,
    tau, p_value (None when fewer than two candidates or one side constant)."""
    table = paper_comparison(ranking, names=names)
    if ids is not None:
        table = table[table["id"].isin(list(ids))]
    rows = []
    for basis in ("Avg.", "Avg. (common spp)"):
        chosen = table[(table["spp"] == basis)].dropna(subset=["ours", "paper"])
        rows.append({"basis": basis, **_kendall(chosen["ours"], chosen["paper"])})
    return pd.DataFrame(rows, columns=["basis", "n", "tau", "p_value"])

