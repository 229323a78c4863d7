"""Which job makes each per-method and per-entry file: the batches of what is missing.

A study's method outputs and evaluations are per (case, method) and per (case, entry) files, so
that an edit of the config makes out of date only what it changes. Making each with a job of its
own from scratch would cost Snakemake's scheduler more than the work (its per-job cost grows with
the thousands of jobs ready at once: about 0.3 s of its CPU a job at the default study's 12 000),
so the files that do not exist yet are made by *batches*: one job per case makes every missing
file of that case in one call (and from scratch, all of them). A file that exists belongs to the
per-file rule, which Snakemake runs again only when it finds the file out of date. The rule
that makes a file is thus chosen by whether it exists (never by whether it is up to date: that
stays Snakemake's decision), and both rules record the same things for it (no ``params``; the
method's parameters are an input file, its spec; the same ``run:`` code), so the next run sees a
batch's file exactly as if the per-file rule had made it.

:func:`missing_batches` groups the cases by the set of items they lack, and splits each group
so that its cases are a product of scenes and spp levels (a rule's wildcard constraints).

A batch depends on what existed when the workflow was parsed, but its job may run in a process
that parses the workflow again later (a SLURM job, a ``run:`` job spawned without
``--force-use-threads``), when other jobs have made more files and the batches differ. So the
main process records each batch it defines (:func:`batch_text`, under ``results/specs/batches/``)
and a process started for target jobs defines the batch rules it is asked for from those records
(:func:`target_batch_names`, :func:`read_batch`), not from the files it finds.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections import defaultdict
from pathlib import Path

__all__ = ["missing_batches", "batch_name", "batch_text", "read_batch", "target_batch_names", "write_if_changed",
           "spec_text"]


def missing_batches(cases: list[tuple[str, int]], items: list[str], exists) -> list[dict]:
    """The batches of missing items: ``[{"items": [...], "scenes": [...], "spps": [...]}]``.

    ``cases``: (scene, spp) in the study's order; ``items``: the names a case may lack (in the
    order a batch must make them: dependency order); ``exists(scene, spp, item)``: whether the
    file is there. Every (case, item) that does not exist is in exactly one batch; the cases of
    a batch are ``scenes`` x ``spps`` (all of them lacking exactly ``items``). Deterministic.
    """
    by_missing: dict[tuple[str, ...], list[tuple[str, int]]] = defaultdict(list)
    for scene, spp in cases:
        lacking = tuple(item for item in items if not exists(scene, spp, item))
        if lacking:
            by_missing[lacking].append((scene, int(spp)))
    batches = []
    for lacking, members in by_missing.items():
        spps_of: dict[str, list[int]] = defaultdict(list)
        for scene, spp in members:
            spps_of[scene].append(spp)
        by_spps: dict[tuple[int, ...], list[str]] = defaultdict(list)
        for scene, spps in spps_of.items():
            by_spps[tuple(sorted(spps))].append(scene)
        for spps, scenes in by_spps.items():
            batches.append({"items": list(lacking), "scenes": scenes, "spps": list(spps)})
    return batches


def batch_name(prefix: str, batch: dict) -> str:
    """A rule name for ``batch``, the same for the same batch in every parse (a cluster job
    finds its rule again by name)."""
    key = json.dumps([batch["items"], batch["scenes"], batch["spps"]])
    return f"{prefix}_{hashlib.sha256(key.encode()).hexdigest()[:12]}"


def batch_text(batch: dict) -> str:
    """The canonical JSON record of ``batch`` (items, scenes, spps), as :func:`read_batch` reads it."""
    return json.dumps({"items": list(batch["items"]), "scenes": list(batch["scenes"]),
                       "spps": [int(s) for s in batch["spps"]]}, indent=1) + "\n"


def read_batch(path: str | os.PathLike, name: str, prefix: str) -> dict:
    """The batch recorded in ``path`` for the rule ``name``; ``ValueError`` naming the file when
    it is missing, unreadable, or does not hash to ``name`` (a record from another batch)."""
    path = Path(path)
    try:
        batch = json.loads(path.read_text())
        items, scenes, spps = batch["items"], batch["scenes"], [int(s) for s in batch["spps"]]
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ValueError(f"{path}: the record of batch rule {name!r} cannot be read ({error}); it is written "
                         "by the main Snakemake process that schedules the batch: run snakemake again") from None
    batch = {"items": items, "scenes": scenes, "spps": spps}
    if batch_name(prefix, batch) != name:
        raise ValueError(f"{path}: this record is not batch rule {name!r} (it hashes to "
                         f"{batch_name(prefix, batch)!r}); run snakemake again")
    return batch


def target_batch_names(argv: list[str], prefix: str) -> list[str]:
    """The batch rules among the target jobs on a Snakemake command line (``--target-jobs
    RULE:WILDCARDS ...``, how Snakemake starts a process that runs jobs scheduled elsewhere: a
    cluster job, a spawned ``run:`` job), in their order, each once. Snakemake parses the
    workflow before it hands its settings to the workflow, so the command line is what a
    Snakefile can read while it is parsed."""
    targets, taking = [], False
    for arg in argv:
        if arg.startswith("--target-jobs="):
            targets.append(arg.split("=", 1)[1])
            taking = True
        elif arg == "--target-jobs":
            taking = True
        elif arg.startswith("-"):
            taking = False
        elif taking:
            targets.append(arg)
    names = [t.strip("'\"").split(":", 1)[0] for t in targets]
    return list(dict.fromkeys(n for n in names if n.startswith(prefix + "_")))


def spec_text(spec: dict) -> str:
    """The canonical JSON of a method's spec (module, params, inputs, weights digest)."""
    return json.dumps(spec, sort_keys=True, indent=1, default=str) + "\n"


def write_if_changed(path: str | os.PathLike, text: str) -> bool:
    """Write ``text`` to ``path`` (atomically) unless it holds it already; whether it wrote.

    A spec file keeps its modification time while its content is unchanged, so the outputs that
    take it as an input are out of date exactly when the spec changed."""
    path = Path(path)
    try:
        if path.read_text() == text:
            return False
    except (FileNotFoundError, UnicodeDecodeError):
        pass
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
    return True
