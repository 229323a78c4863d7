"""Damaged files at every stage (generated): the job that reads one stops naming it, nothing else is
touched, no output is written from it.

A small finished case is built once (a synthetic render with bins, a reference, the outputs and
timing records of two base denoisers, a combiner and the ensemble, the case job's metrics CSV and
viewer case (:func:`mcbench.pipeline.cases.run_case` on those outputs), the gathered
``metrics.csv``, Snakemake benchmark records, a copy of committed weights).
Each generated damage picks one of those files and one way to damage it:

* bytes: truncated at a random offset (zero length included), one bit flipped in the first
  kilobytes (the header) or anywhere after them (the pixels / the numbers), a run of garbage bytes,
  replaced by a folder, by a symlink loop, or deleted;
* meaning, written back *with a valid checksum* (as another program or a bug would write it):
  for an EXR a layer renamed or dropped, the image cropped (wrong size), half-float pixels, NaN or
  Inf injected; for a CSV a row dropped or duplicated, a value made NaN or text, a column renamed;
  for a JSON record a key dropped, a number made NaN or text, a list instead of the record.

Then every job (pipeline step) that reads the file runs on a copy of the case, and the property is:
either the step raises :class:`mcbench.BenchError` whose message names the damaged file, wrote no
output, and left every other file of the case byte-identical; or the damage did not change what
the step computes (e.g. a flipped bit in a header field nobody reads): its outputs equal the
undamaged run's, timing fields excepted. A crash without the file's name, an output written from a
damaged input, or a changed number fails. Every example is reproducible from its id
(``<seed>``): the damage is drawn by ``numpy.random.default_rng(seed)``.

The default suite draws :data:`DEFAULT_DAMAGES`; the fuzz tier (``python -m pytest -q -m fuzz``)
draws :data:`FUZZ_DAMAGES` more.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from mcbench import BenchError
from mcbench.io.buffers import REQUIRED_LAYERS
from mcbench.io.exr import read_layers, read_metadata, write_layers
from mcbench.io.tables import write_csv, write_text
from tests.conftest import REPO, build_render_buffers, case_job

SCENE, SPP = "cornell_box", 8        # a real scene name: the scene table imports its module
HEIGHT, WIDTH = 20, 24
METRICS = ["relmse", "smape", "dssim"]
BASES = ["oidn", "jbf"]
COMBINERS = {"naive": "naive_average", "ens": "ensemble"}
CANDIDATES = BASES + list(COMBINERS)
ENTRIES = ["noisy", *CANDIDATES]          # what the gathered table and the ranking hold
LABELS = {name: name for name in ["noisy", *CANDIDATES]}
DEFAULT_DAMAGES = 60
FUZZ_DAMAGES = 360


def _entry(tree: Path, name: str, module: str, inputs=()) -> dict:
    return {"name": name, "module": module, "params": {},
            "input_paths": [str(tree / "methods" / f"{i}.exr") for i in inputs],
            "exr": str(tree / "methods" / f"{name}.exr"), "timing": str(tree / "timings" / f"{name}.json")}


def _benchmark_record(path: Path, cpu_time: float) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
                    f"1.5\t0:00:01\t100.0\t200.0\t90.0\t95.0\t0.0\t1.0\t50.0\t{cpu_time}\n")


def build_case(tree: Path) -> None:
    """The finished case every damage starts from (see the module docstring)."""
    from mcbench.pipeline.method_runs import run_methods
    from mcbench.pipeline.evaluation import gather_tables

    render = build_render_buffers(height=HEIGHT, width=WIDTH, spp=SPP, bins=True, seed=3)
    write_layers(tree / "render.exr", render.layers,
                 metadata={"scene": SCENE, "spp": SPP, "resolution": f"{WIDTH}x{HEIGHT}"})
    truth = build_render_buffers(height=HEIGHT, width=WIDTH, half_std=0.0).color
    rng = np.random.default_rng(4)
    write_layers(tree / "reference.exr", {"color": truth + 0.001 * rng.standard_normal(truth.shape),
                                          "variance": np.full(truth.shape, 1e-6)},
                 metadata={"scene": SCENE, "spp": 4096, "resolution": f"{WIDTH}x{HEIGHT}"})
    entries = [_entry(tree, "oidn", "oidn"), _entry(tree, "jbf", "jbf"),
               _entry(tree, "naive", "naive_average", BASES)]
    run_methods(entries, str(tree / "render.exr"), scene=SCENE, spp=SPP)
    run_methods([_entry(tree, "ens", "ensemble", BASES)], str(tree / "render.exr"), scene=SCENE, spp=SPP)
    _run_case(tree, tree, cache=tree / "cache")
    gather_tables([str(tree / "case.csv")], str(tree / "metrics.csv"), entries=ENTRIES,
                  metric_names=METRICS, cases=[(SCENE, SPP)])
    _benchmark_record(tree / "benchmarks" / f"{SCENE}_spp{SPP}.tsv", 2.5)
    _benchmark_record(tree / "benchmarks" / f"{SCENE}_chunk0.tsv", 40.0)
    weights = tree / "weights"
    weights.mkdir()
    for name in ("kpcn.pt", "kpcn.json"):          # the weights and their record (with their SHA-256)
        shutil.copyfile(REPO / "methods" / "weights" / name, weights / name)


# --- the jobs that read the case's files: name -> (files it reads, run(tree, out)) -----------------

def _run_combiner(tree: Path, out: Path) -> None:
    from mcbench.pipeline.method_runs import run_methods

    entry = _entry(tree, "naive", "naive_average", BASES)
    entry.update(exr=str(out / "naive.exr"), timing=str(out / "naive.json"))
    run_methods([entry], str(tree / "render.exr"), scene=SCENE, spp=SPP)


def _run_ensemble(tree: Path, out: Path) -> None:   # reads its render and inputs by rows
    from mcbench.pipeline.method_runs import run_methods

    entry = _entry(tree, "ens", "ensemble", BASES)
    entry.update(exr=str(out / "ens.exr"), timing=str(out / "ens.json"))
    run_methods([entry], str(tree / "render.exr"), scene=SCENE, spp=SPP)


def _run_base(tree: Path, out: Path) -> None:
    from mcbench.pipeline.method_runs import run_methods

    entry = _entry(tree, "jbf", "jbf")
    entry.update(exr=str(out / "jbf.exr"), timing=str(out / "jbf.json"))
    run_methods([entry], str(tree / "render.exr"), scene=SCENE, spp=SPP)


def _run_case(tree: Path, out: Path, *, cache: Path | None = None) -> None:
    """The case job (the code of rule run_case) on the case's method outputs: its metrics CSV, viewer
    case and record in ``out``; the entries' kept values and images (the job's cache, no output of
    the rule) beside ``out``, fresh each run."""
    from mcbench.pipeline.cases import run_case

    images = {name: tree / "methods" / f"{name}.exr" for name in CANDIDATES}
    cache = cache if cache is not None else out.parent / f"{out.name}_cache"
    run_case(case_job(out, scene=SCENE, spp=SPP, render=tree / "render.exr", reference=tree / "reference.exr",
                      metrics=METRICS, images=images, weight_inputs={"ens": BASES}, cache=cache))


def _run_gather(tree: Path, out: Path) -> None:
    from mcbench.pipeline.evaluation import gather_tables

    gather_tables([str(tree / "case.csv")], str(out / "metrics.csv"), entries=ENTRIES,
                  metric_names=METRICS, cases=[(SCENE, SPP)])


def _run_timings(tree: Path, out: Path) -> None:
    from mcbench.pipeline.evaluation import gather_timings

    gather_timings([str(tree / "timings" / f"{name}.json") for name in CANDIDATES], str(out / "timings.csv"))


def _run_rankings(tree: Path, out: Path) -> None:
    from mcbench.pipeline.rankings import write_rankings

    write_rankings(str(tree / "metrics.csv"), "relmse", str(out / "ranking.csv"), str(out / "ranking.md"),
                   entries=ENTRIES, labels=LABELS)


def _run_scene_table(tree: Path, out: Path) -> None:
    from mcbench.pipeline.rankings import write_scene_table

    write_scene_table(str(tree / "metrics.csv"), {SCENE: str(tree / "reference.exr")}, {SCENE: 4096},
                      str(out / "scenes.csv"), str(out / "scenes.md"),
                      noisy_records=[str(tree / "benchmarks" / f"{SCENE}_spp{SPP}.tsv")],
                      reference_records=[str(tree / "benchmarks" / f"{SCENE}_chunk0.tsv")])


def _run_viewer(tree: Path, out: Path) -> None:
    from mcbench.pipeline.viewer import write_viewer

    write_viewer(str(tree / "metrics.csv"), [str(tree / "viewer_case")], str(out / "viewer"),
                 cases=[(SCENE, SPP)], candidates=CANDIDATES, labels=LABELS, metric_names=METRICS,
                 static_dir=str(REPO / "workflow" / "report" / "viewer"))


def _run_weights(tree: Path, out: Path) -> None:
    from mcbench.io.weights import load_weights

    blob = load_weights(tree / "weights" / "kpcn.pt")
    import torch

    digest = {key: float(torch.as_tensor(value, dtype=torch.float64).sum())
              for key, value in sorted(blob["state_dict"].items())}
    (out / "weights_digest.json").write_text(json.dumps(digest, sort_keys=True))


STEPS = {
    "base method": _run_base, "combiner": _run_combiner, "ensemble (by rows)": _run_ensemble,
    "case job": _run_case, "gather metrics": _run_gather, "gather timings": _run_timings,
    "ranking table": _run_rankings, "scene table": _run_scene_table, "viewer": _run_viewer, "weights": _run_weights,
}

#: Each damageable file (relative to the case) and the steps that read it.
TARGETS = {
    "render.exr": ["base method", "combiner", "ensemble (by rows)", "case job"],
    "reference.exr": ["case job", "scene table"],
    "methods/oidn.exr": ["combiner", "ensemble (by rows)", "case job"],
    "methods/ens.exr": ["case job"],
    "timings/jbf.json": ["gather timings"],
    "case.csv": ["gather metrics"],
    "metrics.csv": ["ranking table", "scene table", "viewer"],
    f"benchmarks/{SCENE}_chunk0.tsv": ["scene table"],
    "viewer_case/case.json": ["viewer"],
    "viewer_case/ens_relmse.png": ["viewer"],
    "viewer_case/jbf_ev0.jpg": ["viewer"],
    "weights/kpcn.pt": ["weights"],
    "weights/kpcn.json": ["weights"],
}

BYTE_DAMAGES = ("truncate", "empty", "flip_header", "flip_body", "garbage", "folder", "symlink_loop", "delete")
EXR_DAMAGES = ("rename_layer", "drop_layer", "crop", "half_pixels", "nan", "inf")
CSV_DAMAGES = ("drop_row", "duplicate_row", "nan_value", "text_value", "rename_column")
JSON_DAMAGES = ("drop_key", "nan_number", "text_number", "not_a_record")


def _flip(data: bytearray, rng, lo: int, hi: int) -> str:
    offset = int(rng.integers(lo, max(lo + 1, hi)))
    bit = int(rng.integers(8))
    data[offset] ^= 1 << bit
    return f"bit {bit} of byte {offset}"


def damage(path: Path, kind: str, rng) -> str:
    """Damage the file at ``path`` in the way ``kind`` (see the module docstring); returns a note."""
    data = bytearray(path.read_bytes()) if path.is_file() else bytearray()
    size = len(data)
    if kind == "truncate":
        cut = int(rng.integers(0, size))
        path.write_bytes(bytes(data[:cut]))
        return f"truncated to {cut} of {size} bytes"
    if kind == "empty":
        path.write_bytes(b"")
        return "zero length"
    if kind == "flip_header":
        note = _flip(data, rng, 0, min(size, 2048))
        path.write_bytes(bytes(data))
        return note
    if kind == "flip_body":
        note = _flip(data, rng, min(size - 1, 2048), size)
        path.write_bytes(bytes(data))
        return note
    if kind == "garbage":
        start = int(rng.integers(0, size))
        length = int(rng.integers(1, 64))
        data[start:start + length] = rng.integers(0, 256, min(length, size - start), dtype=np.uint8).tobytes()
        path.write_bytes(bytes(data))
        return f"{length} garbage bytes at {start}"
    if kind == "folder":
        path.unlink()
        path.mkdir()
        return "replaced by a folder"
    if kind == "symlink_loop":
        path.unlink()
        os.symlink(path.name, path)
        return "replaced by a symlink to itself"
    if kind == "delete":
        path.unlink()
        return "deleted"
    if path.suffix == ".exr":
        return _damage_exr(path, kind, rng)
    if path.suffix in (".csv", ".tsv"):
        return _damage_table(path, kind, rng)
    return _damage_json(path, kind, rng)


def _damage_exr(path: Path, kind: str, rng) -> str:
    layers = read_layers(path)
    metadata = read_metadata(path)
    names = sorted(layers)
    name = names[int(rng.integers(len(names)))]
    if name not in ("color", "color_a", "color_b", *REQUIRED_LAYERS) and kind in ("rename_layer", "drop_layer"):
        name = "color"                              # damage a layer that is read
    dtype = np.float32
    if kind == "rename_layer":
        layers[name + "_x"] = layers.pop(name)
    elif kind == "drop_layer":
        del layers[name]
    elif kind == "crop":
        rows = 1 + int(rng.integers(3))
        layers = {k: v[:-rows] for k, v in layers.items()}
    elif kind == "half_pixels":
        dtype = np.float16
        layers = {k: v.astype(np.float64) * (1 + 1e-3) for k, v in layers.items()}  # a value half cannot hold
        name = "every layer"
    elif kind in ("nan", "inf"):
        y, x = int(rng.integers(HEIGHT)), int(rng.integers(WIDTH))
        layers[name] = layers[name].copy()
        layers[name][y, x] = np.nan if kind == "nan" else np.inf
    write_layers(path, layers, metadata=metadata, dtype=dtype)   # a valid checksum: only meaning can tell
    return f"{kind} ({name}), rewritten with a valid checksum"


def _damage_table(path: Path, kind: str, rng) -> str:
    import pandas as pd

    sep = "\t" if path.suffix == ".tsv" else ","
    frame = pd.read_csv(path, sep=sep)
    row = int(rng.integers(len(frame)))
    numeric = [c for c in frame.columns if pd.api.types.is_numeric_dtype(frame[c])]
    column = numeric[int(rng.integers(len(numeric)))] if numeric else frame.columns[0]
    if kind == "drop_row":
        frame = frame.drop(index=row)
    elif kind == "duplicate_row":
        frame = pd.concat([frame, frame.iloc[[row]]], ignore_index=True)
    elif kind == "nan_value":
        frame[column] = frame[column].astype(float)
        frame.loc[row, column] = np.nan
    elif kind == "text_value":
        frame[column] = frame[column].astype(object)
        frame.loc[row, column] = "n/a"
    elif kind == "rename_column":
        column = frame.columns[int(rng.integers(len(frame.columns)))]
        frame = frame.rename(columns={column: column + "_x"})
    if path.suffix == ".tsv":
        path.write_text(frame.to_csv(sep="\t", index=False))   # Snakemake's records have no checksum
    else:
        write_csv(path, frame)
    return f"{kind} (row {row}, column {column}), rewritten with a valid checksum"


def _damage_json(path: Path, kind: str, rng) -> str:
    record = json.loads(path.read_text())
    numeric = sorted(k for k, v in record.items() if isinstance(v, (int, float)) and not isinstance(v, bool))
    keys = sorted(record)
    if kind == "drop_key":
        key = keys[int(rng.integers(len(keys)))]
        del record[key]
        text = json.dumps(record)
    elif kind in ("nan_number", "text_number"):
        key = numeric[int(rng.integers(len(numeric)))] if numeric else keys[0]
        record[key] = float("nan") if kind == "nan_number" else "fast"
        text = json.dumps(record)                  # NaN as the bare token Python's json writes
    else:
        key = "-"
        text = json.dumps([record])
    write_text(path, text)
    return f"{kind} ({key}), rewritten with a valid checksum"


def damages_for(path: str) -> tuple[str, ...]:
    suffix = Path(path).suffix
    semantic = {".exr": EXR_DAMAGES, ".csv": CSV_DAMAGES, ".tsv": CSV_DAMAGES, ".json": JSON_DAMAGES}
    return BYTE_DAMAGES + semantic.get(suffix, ())


# --- running the property -----------------------------------------------------------------------

def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and not p.is_symlink()}


TIMING_KEYS = ("seconds", "machine", "threads")


def _comparable(root: Path) -> dict:
    """What a step computed, timing fields excepted: EXR pixels, CSV/JSON content, other bytes."""
    out = {}
    for p in sorted(root.rglob("*")):
        if not p.is_file() or p.name.endswith(".crc32"):
            continue
        key = str(p.relative_to(root))
        if p.suffix == ".exr":
            out[key] = {name: layer.tobytes() for name, layer in sorted(read_layers(p).items())}
        elif p.suffix == ".json" and p.parent.name != "viewer_case":
            out[key] = {k: v for k, v in json.loads(p.read_text()).items() if k not in TIMING_KEYS}
        elif p.name == "timings.csv":
            import pandas as pd

            out[key] = pd.read_csv(p).drop(columns=["seconds", "machine"], errors="ignore").to_csv()
        else:
            out[key] = p.read_bytes()
    return out


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    """The finished case and each step's outputs on it: ``(tree, {step: comparable outputs})``."""
    tree = tmp_path_factory.mktemp("case")
    build_case(tree)
    absent = [target for target in TARGETS if not (tree / target).is_file()]
    assert not absent, f"the case lacks the damage targets {absent}"
    outputs = {}
    for name, step in STEPS.items():
        out = tmp_path_factory.mktemp("out")
        step(tree, out)
        outputs[name] = _comparable(out)
    return tree, outputs


def check_damage(seed: int, pristine, tmp_path) -> tuple[str, str, str, list[str]]:
    """Draw damage ``seed``, apply it to a copy of the case and check every step that reads the file.
    Returns (file, kind, note, outcome per step: 'refused' or 'harmless')."""
    tree, expected = pristine
    rng = np.random.default_rng(seed)
    targets = sorted(TARGETS)
    target = targets[int(rng.integers(len(targets)))]
    kinds = damages_for(target)
    kind = kinds[int(rng.integers(len(kinds)))]
    case = tmp_path / "case"
    shutil.copytree(tree, case, symlinks=True)
    path = case / target
    note = damage(path, kind, rng)
    before = _files(case)
    outcomes = []
    for step_name in TARGETS[target]:
        out = tmp_path / f"out_{len(outcomes)}"
        out.mkdir()
        where = f"damage {seed}: {target} {note}; step '{step_name}'"
        try:
            STEPS[step_name](case, out)
        except BenchError as error:
            assert str(path) in str(error), f"{where}: the error does not name the file: {error}"
            written = [str(p) for p in out.rglob("*") if p.is_file()]
            assert not written, f"{where}: refused, but wrote {written}"
            outcomes.append("refused")
        else:
            assert _comparable(out) == expected[step_name], \
                f"{where}: accepted, and its outputs differ from the undamaged case's"
            outcomes.append("harmless")
        assert _files(case) == before, f"{where}: changed the case's other files"
    return target, kind, note, outcomes


@pytest.mark.parametrize("seed", range(DEFAULT_DAMAGES))
def test_a_damaged_file_is_refused_naming_it_or_changes_nothing(seed, pristine, tmp_path):
    check_damage(seed, pristine, tmp_path)


@pytest.mark.fuzz
@pytest.mark.parametrize("seed", range(DEFAULT_DAMAGES, DEFAULT_DAMAGES + FUZZ_DAMAGES))
def test_fuzz_damaged_files(seed, pristine, tmp_path):
    check_damage(seed, pristine, tmp_path)


def test_every_target_and_damage_kind_is_drawn():
    """The generator covers every file and every damage kind its files allow, in the fuzz tier's seeds."""
    drawn = set()
    for seed in range(DEFAULT_DAMAGES + FUZZ_DAMAGES):
        rng = np.random.default_rng(seed)
        targets = sorted(TARGETS)
        target = targets[int(rng.integers(len(targets)))]
        kinds = damages_for(target)
        drawn.add((target, kinds[int(rng.integers(len(kinds)))]))
    wanted = {(target, kind) for target in TARGETS for kind in damages_for(target)}
    assert len(drawn) >= 0.9 * len(wanted), sorted(wanted - drawn)
