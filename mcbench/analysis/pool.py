"""The 39-candidate pool of Zheng et al. 2021, Sec. 5.3.1, as data.

Eight base denoisers by the paper's number and 31 ensembles #9-#39 of them, with provenance:
the paper names 12 ensembles (``"paper"``, in the text and Table 3; its sizes follow from the case
counts behind Tables 1-2), its ID order (lexicographic in the member tuples within a size)
forces #31 (``"forced"``), the other 18 are our choice (``"filled"``; heterogeneous and
homogeneous sets, DC variants, the combinations of the paper's figures). Everything the study
reports about the pool says which rows are filled.

Harness names
-------------
The bases are the harness's methods ``kpcn``, ``nfor_dc``, ``mcgan``, ``nfor``, ``kpcn_dc``,
``oidn``, ``optix_ae``, ``rdfc`` (the learned ones and the DC variants trained by us, †; #7 is
our autoencoder standing in for OptiX, which has no CPU build). Ensemble #k is the combiner
``ens<k>`` (``ens09`` … ``ens39``) of module ``ensemble`` with its members as inputs in the
paper's ID order and the module's default parameters (the paper's method).

:func:`pool_methods` expands the pool (or a subset of its IDs) into config entries, so the
config holds one key (``study.pool``) instead of 31 combiner lines; :func:`expand_methods` merges
them with a config's own ``denoisers``/``combiners`` (the user's lines may add ensembles or other
methods; a line that duplicates a pool member stops the run, naming it).

Also here: the paper's Table 3 (relMSE scores, 40 entries, 30 scenes), its recommendations
(Sec. 5.3.5-5.3.6) and the spp bands they use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mcbench import BenchError

__all__ = ["BASES", "BASE_LABELS", "LEARNED_IDS", "CLASSICAL_IDS", "DC_IDS", "DC_COMBINERS", "ENSEMBLES",
           "Candidate", "POOL", "POOL_IDS", "ENSEMBLE_IDS", "candidate", "candidate_name", "pool_names",
           "members_of", "is_homogeneous", "has_dc", "PAPER_TABLE3", "PAPER_TABLE3_SPP", "PAPER_RECOMMENDATIONS",
           "PAPER_NAMED_IDS", "FEWER_THAN", "SPP_BANDS", "spp_band_members", "pool_methods", "expand_methods", "PoolError"]


class PoolError(BenchError):
    """A config whose methods clash with the candidate pool."""


# paper number -> harness method name
BASES: dict[int, str] = {1: "kpcn", 2: "nfor_dc", 3: "mcgan", 4: "nfor", 5: "kpcn_dc", 6: "oidn",
                         7: "optix_ae", 8: "rdfc"}
BASE_LABELS: dict[int, str] = {1: "#1 KPCN†", 2: "#2 NFOR-DC†", 3: "#3 MCGAN†", 4: "#4 NFOR", 5: "#5 KPCN-DC†",
                               6: "#6 OIDN", 7: "#7 OptiX† (our autoencoder)", 8: "#8 RDFC"}
# Short member names in ensemble labels.
_SHORT = {1: "KPCN", 2: "NFOR-DC", 3: "MCGAN", 4: "NFOR", 5: "KPCN-DC", 6: "OIDN", 7: "OptiX†", 8: "RDFC"}
# Learned and classical bases (Sec. 5.3.4: "only learning-based denoisers such as KPCN, or only
# non-learning-based ones such as NFOR"). Our choice: a DC variant counts as learned -- its output
# is a network's combination of the base with the noisy input; #28 {3,5,6,7} is the paper's
# example of a homogeneous (learned) set, which this classification reproduces.
LEARNED_IDS = frozenset({1, 2, 3, 5, 6, 7})
CLASSICAL_IDS = frozenset({4, 8})
DC_IDS = frozenset({2, 5})
# The DC variants are combiners of the harness (the deep combiner over NFOR and over KPCN).
DC_COMBINERS: dict[int, dict] = {
    2: {"name": "nfor_dc", "method": "deep_combiner", "inputs": ["nfor"], "label": BASE_LABELS[2]},
    5: {"name": "kpcn_dc", "method": "deep_combiner", "inputs": ["kpcn"], "label": BASE_LABELS[5]},
}

# ensemble ID -> (members by base number, source)
ENSEMBLES: dict[int, tuple[tuple[int, ...], str]] = {
    9: ((1, 3), "filled"), 10: ((1, 4), "paper"), 11: ((1, 8), "filled"), 12: ((3, 4), "filled"),
    13: ((4, 6), "filled"), 14: ((4, 8), "filled"), 15: ((6, 8), "filled"), 16: ((7, 8), "paper"),
    17: ((1, 3, 8), "filled"), 18: ((1, 4, 8), "paper"), 19: ((1, 6, 7), "filled"), 20: ((1, 6, 8), "paper"),
    21: ((2, 6, 8), "filled"), 22: ((3, 7, 8), "filled"), 23: ((4, 6, 8), "filled"), 24: ((6, 7, 8), "paper"),
    25: ((1, 3, 4, 8), "filled"), 26: ((1, 4, 6, 7), "filled"), 27: ((1, 4, 6, 8), "paper"),
    28: ((3, 5, 6, 7), "paper"), 29: ((4, 5, 6, 8), "paper"), 30: ((4, 6, 7, 8), "paper"),
    31: ((5, 6, 7, 8), "forced"),
    32: ((1, 3, 4, 6, 8), "filled"), 33: ((1, 4, 6, 7, 8), "paper"), 34: ((3, 4, 6, 7, 8), "filled"),
    35: ((1, 3, 4, 6, 7, 8), "paper"), 36: ((2, 3, 4, 6, 7, 8), "filled"), 37: ((2, 4, 5, 6, 7, 8), "filled"),
    38: ((3, 4, 5, 6, 7, 8), "filled"), 39: ((1, 2, 3, 4, 5, 6, 7, 8), "paper"),
}


@dataclass(frozen=True)
class Candidate:
    """One candidate of the pool: ``id`` (1-39), harness method ``name``, ``members`` (base
    numbers; ``(id,)`` for a base), ``source`` (``"paper"``, ``"filled"``, ``"forced"``) and the
    table ``label``."""

    id: int
    name: str
    members: tuple[int, ...]
    source: str
    label: str

    @property
    def size(self) -> int:
        """Number of base denoisers (1 for a base)."""
        return len(self.members)

    @property
    def is_base(self) -> bool:
        return self.id in BASES


def candidate_name(candidate_id: int) -> str:
    """Harness method name of candidate ``candidate_id`` (a base's module name, ``ens<id>``)."""
    if candidate_id in BASES:
        return BASES[candidate_id]
    if candidate_id in ENSEMBLES:
        return f"ens{candidate_id:02d}"
    raise PoolError(f"no candidate #{candidate_id} in the pool (1-39)")


def _ensemble_label(candidate_id: int, members: tuple[int, ...], source: str) -> str:
    mark = "" if source == "paper" else f" ({source})"
    return f"#{candidate_id} " + "+".join(_SHORT[m] for m in members) + mark


def _build_pool() -> tuple[Candidate, ...]:
    bases = [Candidate(i, name, (i,), "paper", BASE_LABELS[i]) for i, name in BASES.items()]
    ensembles = [Candidate(i, candidate_name(i), members, source, _ensemble_label(i, members, source))
                 for i, (members, source) in ENSEMBLES.items()]
    return tuple(bases + ensembles)


POOL: tuple[Candidate, ...] = _build_pool()
POOL_IDS: tuple[int, ...] = tuple(c.id for c in POOL)
ENSEMBLE_IDS: tuple[int, ...] = tuple(ENSEMBLES)
_BY_ID = {c.id: c for c in POOL}
_BY_NAME = {c.name: c for c in POOL}


def candidate(key: int | str) -> Candidate:
    """The candidate of an ID (1-39) or a harness name (``"ens27"``, ``"kpcn"``)."""
    found = _BY_ID.get(key) if isinstance(key, int) else _BY_NAME.get(key)
    if found is None:
        raise PoolError(f"no candidate {key!r} in the pool")
    return found


def pool_names(ids=None) -> list[str]:
    """Harness names of the candidates ``ids`` (all 39 by default), in ID order."""
    chosen = POOL_IDS if ids is None else sorted(set(int(i) for i in ids))
    return [candidate(i).name for i in chosen]


def members_of(candidate_id: int) -> tuple[int, ...]:
    """Base numbers of a candidate (``(id,)`` for a base)."""
    return candidate(candidate_id).members


def is_homogeneous(members) -> bool:
    """True when every member is learned, or every member classical (Sec. 5.3.4; DC counts as learned)."""
    members = set(members)
    return members <= LEARNED_IDS or members <= CLASSICAL_IDS


def has_dc(members) -> bool:
    """True when a DC variant (#2 NFOR-DC, #5 KPCN-DC) is a member."""
    return bool(set(members) & DC_IDS)


# Table 3 of the paper: relMSE scores (40 entries, mean over its 30 scenes), per spp and Avg.
PAPER_TABLE3_SPP: tuple[int, ...] = (4, 8, 16, 32, 64, 128, 256, 512, 1024)
_T3 = {
    1: (16.5, 15.0, 15.0, 16.0, 15.7, 16.8, 16.7, 15.4, 12.8, 15.5),
    3: (15.9, 14.2, 12.7, 10.5, 7.8, 5.9, 4.6, 3.5, 2.6, 8.6),
    4: (5.0, 5.1, 5.8, 8.1, 9.7, 11.4, 12.3, 12.5, 14.0, 9.3),
    6: (23.8, 17.7, 12.0, 8.9, 7.0, 6.6, 5.2, 4.9, 4.2, 10.0),
    7: (12.4, 9.9, 7.5, 6.5, 5.9, 5.0, 5.0, 4.6, 4.5, 6.8),
    8: (10.9, 10.0, 10.7, 10.4, 11.8, 12.9, 14.6, 16.8, 18.1, 12.9),
    16: (21.7, 18.6, 17.3, 16.2, 17.5, 18.5, 19.3, 21.4, 22.0, 19.2),
    24: (28.6, 24.8, 22.4, 19.4, 19.5, 19.1, 19.3, 21.0, 21.3, 21.7),
    30: (20.7, 22.0, 23.2, 24.0, 25.1, 26.7, 27.4, 27.7, 27.9, 25.0),
    33: (23.5, 25.9, 28.0, 29.1, 29.3, 31.0, 31.1, 31.5, 31.8, 29.0),
    35: (21.1, 23.4, 27.0, 28.5, 29.4, 29.4, 28.4, 27.6, 26.3, 26.8),
}
PAPER_TABLE3: dict[int, dict[object, float]] = {
    cid: {**dict(zip(PAPER_TABLE3_SPP, row[:-1])), "Avg.": row[-1]} for cid, row in _T3.items()}

# The paper's recommendations (Sec. 5.3.5-5.3.6), by ensemble ID. Sec. 5.3.6: #27 "the overall
# best choice"; "if users would like to use fewer base denoisers, combination #20 ... is also a
# good choice" -- read by the study both as the second place overall and as the best ensemble
# with fewer members than #27 (``fewer``: size < FEWER_THAN).
PAPER_RECOMMENDATIONS: dict[str, dict[object, object]] = {
    "size": {2: 10, 3: 20, 4: 27},
    "band": {"low": 20, "medium": 27, "high": 18},
    "overall": {"best": 27, "second": 20, "fewer": 20},
}
FEWER_THAN = 4                  # the size of #27, the paper's overall best
# The ensembles the paper itself names (source "paper"; 12 of the 31).
PAPER_NAMED_IDS: tuple[int, ...] = tuple(i for i, (_, source) in ENSEMBLES.items() if source == "paper")
# spp bands of Sec. 5.3.5, inclusive: "Low (4-32 spp)", "Medium (32-256 spp)", "High (>256 spp)".
# 32 spp is in both low and medium, as the paper's text has it (our reading, kept literal).
SPP_BANDS: dict[str, tuple[float, float]] = {"low": (4, 32), "medium": (32, 256), "high": (257, math.inf)}


def spp_band_members(spps, band: str) -> list[int]:
    """The spp of ``spps`` that fall in ``band`` (``low``, ``medium``, ``high``; inclusive bounds)."""
    low, high = SPP_BANDS[band]
    return [int(s) for s in sorted(spps) if low <= int(s) <= high]


def pool_methods(ids=None) -> tuple[list[str], list[dict]]:
    """Config entries of the pool (or of the candidates ``ids`` and what they need).

    Returns ``(denoisers, combiners)``: the base denoisers by module name, then the DC combiners
    and the ensembles as combiner entries ``{name, method, inputs, label}``, dependencies first.
    Asking for an ensemble brings its members; asking for #2 brings #4, #5 brings #1.
    """
    wanted = set(POOL_IDS if ids is None else (int(i) for i in ids))
    unknown = sorted(wanted - set(POOL_IDS))
    if unknown:
        raise PoolError(f"study.ensembles: no candidate(s) {unknown} in the pool (1-39)")
    needed = set(wanted)
    for cid in wanted:
        needed |= set(members_of(cid))
    if 2 in needed:
        needed.add(4)
    if 5 in needed:
        needed.add(1)
    denoisers = [BASES[i] for i in sorted(needed) if i in BASES and i not in DC_IDS]
    combiners = [dict(DC_COMBINERS[i], inputs=list(DC_COMBINERS[i]["inputs"])) for i in sorted(needed & DC_IDS)]
    for cid in sorted(needed - set(BASES)):
        c = candidate(cid)
        combiners.append({"name": c.name, "method": "ensemble", "inputs": [BASES[m] for m in c.members],
                          "label": c.label})
    return denoisers, combiners


def _entry_name(entry) -> str:
    return entry if isinstance(entry, str) else entry["name"]


def _entry_module(entry) -> str:
    return entry if isinstance(entry, str) else entry.get("method", entry["name"])


def expand_methods(config: dict) -> tuple[list[tuple[str, object]], list[tuple[str, dict]]]:
    """A resolved config's method entries with the pool merged in, each with its config key.

    Returns ``(denoisers, combiners)``, lists of ``(config key, entry)``: the key names where an
    entry comes from in error messages (``denoisers[2]``, ``combiners[5]`` for the config's own
    lines, ``study.pool (#27)`` for the pool's). With ``study.pool`` false these are the config's
    own entries. With it true the pool's bases come first among the denoisers (the config's
    denoisers that are not pool bases follow), the DC combiners and ensembles first among the
    combiners (so the config's combiners may take them as inputs). ``study.ensembles`` (IDs)
    narrows the pool to those candidates and what they need. A config line that redefines a pool
    name differently, or a full ensemble (no params) over a pool ensemble's member set, stops with
    a :class:`PoolError` naming the line: two entries for one candidate would move every score.
    """
    own_denoisers = [(f"denoisers[{i}]", e) for i, e in enumerate(config.get("denoisers", []))]
    own_combiners = [(f"combiners[{i}]", e) for i, e in enumerate(config.get("combiners", []))]
    study = config.get("study", {})
    if not study.get("pool", False):
        return own_denoisers, own_combiners
    ids = study.get("ensembles")
    pool_denoisers, pool_combiners = pool_methods(None if ids is None else ids)
    pool_by_name = {c["name"]: c for c in pool_combiners}
    pool_sets = {frozenset(c["inputs"]): c["name"] for c in pool_combiners if c["method"] == "ensemble"}
    ids_of = {c.name: c.id for c in POOL}

    denoisers = [(f"study.pool (#{ids_of[name]} {name})", name) for name in pool_denoisers]
    for key, entry in own_denoisers:
        name = _entry_name(entry)
        if name in pool_denoisers:
            if not isinstance(entry, str) and (entry.get("params") or _entry_module(entry) != name):
                raise PoolError(f"{key}: '{name}' is a base of the candidate pool (study.pool) and may not be "
                                f"redefined; give the variant another name")
            continue
        denoisers.append((key, entry))

    combiners = [(f"study.pool (#{ids_of[c['name']]} {c['name']})", c) for c in pool_combiners]
    for key, entry in own_combiners:
        name = entry["name"]
        if name in pool_by_name:
            mine = pool_by_name[name]
            if entry.get("method") != mine["method"] or list(entry.get("inputs", [])) != mine["inputs"] \
                    or entry.get("params"):
                raise PoolError(f"{key}: '{name}' is a candidate of the pool (study.pool) and may not be "
                                f"redefined; give the variant another name")
            continue
        if entry.get("method") == "ensemble" and not entry.get("params") \
                and frozenset(entry.get("inputs", [])) in pool_sets:
            raise PoolError(f"{key}: '{name}' is the ensemble of {'+'.join(entry['inputs'])}, candidate "
                            f"'{pool_sets[frozenset(entry['inputs'])]}' of the pool (study.pool) already; "
                            f"remove the line or set study.pool: false")
        combiners.append((key, entry))
    return denoisers, combiners
