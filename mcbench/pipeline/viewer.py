"""The work behind ``workflow/rules/viewer.smk``: each case's viewer images and the static viewer.
"""

from __future__ import annotations

import os
from pathlib import Path


from mcbench import METRICS_COLUMNS, NOISY, BenchError
from mcbench.io.checksums import crc32_hex
from mcbench.io.tables import read_json, read_table, write_json


#: Key of a viewer case record holding the CRC-32 of each image file it names (checked on assembly).
FILE_CHECKSUMS = "files_crc32"


def _check_case_record(record: dict, record_path: Path) -> None:
    """Refuse a case record whose fields do not have the shape :func:`assemble_viewer_case` writes."""
    def strings(mapping) -> bool:
        return isinstance(mapping, dict) and all(isinstance(k, str) and isinstance(v, str) for k, v in mapping.items())

    sizes = [record.get("width"), record.get("height")]
    problems = []
    if not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in sizes):
        problems.append(f"width/height {sizes}")
    for key in ("images", "errors"):
        value = record.get(key)
        if not (isinstance(value, dict) and all(strings(files) for files in value.values())):
            problems.append(f"'{key}'")
    weights = record.get("weights")
    if not (isinstance(weights, dict) and all(isinstance(maps, list) and all(strings(m) and set(m) == {"input", "file"}
                                                                         for m in maps)
                                           for maps in weights.values())):
        problems.append("'weights'")
    if problems:
        raise BenchError(f"{record_path}: not a viewer case record (bad {', '.join(problems)}); rerun the job "
                         f"that writes it")


def _check_case_files(case_dir: Path, record: dict, record_path: Path) -> None:
    """Refuse a case folder whose images are missing, differ from the checksums of its record or
    are not of the record's size."""
    from PIL import Image

    from mcbench.analysis.viewer_images import case_files

    _check_case_record(record, record_path)
    checksums = record.get(FILE_CHECKSUMS)
    files = case_files(record)
    if not isinstance(checksums, dict) or set(checksums) != files:
        raise BenchError(f"{record_path}: the case record's checksums ({FILE_CHECKSUMS}) do not list its "
                         f"images; rerun the job that writes {case_dir}")
    for name in sorted(files):
        path = case_dir / name
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise BenchError(f"{path}: cannot read the viewer image ({exc.strerror or exc})") from exc
        if crc32_hex(data) != checksums[name]:
            raise BenchError(f"{path}: the viewer image does not match its checksum in {record_path} "
                             f"(damaged after it was written); rerun the job that writes {case_dir}")
        with Image.open(path) as image:                 # the header only
            if image.size != (record["width"], record["height"]):
                raise BenchError(f"{path}: the viewer image is {image.size[0]}x{image.size[1]}, its record "
                                 f"{record_path} says {record['width']}x{record['height']}")


def write_viewer(metrics_csv: str, case_dirs: list[str], output_dir: str, *, cases: list[tuple[str, int]],
                 candidates: list[str], labels: dict[str, str], metric_names: list[str],
                 static_dir: str) -> dict:
    """The static image viewer in ``output_dir``: the page of ``static_dir`` (index.html,
    viewer.js, viewer.css), every case folder (``case_dirs[i]`` holds ``cases[i]``, written by
    :func:`assemble_viewer_case`) and ``data.js``, the manifest with each case's numbers from
    ``metrics_csv`` (every entry must have every metric of ``metric_names``) and each metric's
    label, direction and map scale from its declaration (``metrics/<name>.py``). Returns the manifest."""
    from mcbench.analysis.viewer_images import CASE_RECORD, assemble_viewer, build_manifest, case_numbers, directory_bytes
    from mcbench.pipeline.registry import load_metrics

    if len(case_dirs) != len(cases):
        raise BenchError(f"{output_dir}: {len(case_dirs)} case folders for {len(cases)} cases")
    metrics = read_table(metrics_csv, columns=METRICS_COLUMNS)
    entries = [NOISY] + list(candidates)
    fragments, numbers = {}, {}
    for (scene, spp), case_dir in zip(cases, case_dirs):
        record_path = Path(case_dir) / CASE_RECORD
        record = read_json(record_path)                      # BenchError naming the file
        if (record.get("scene"), record.get("spp")) != (scene, int(spp)):
            raise BenchError(f"{record_path}: holds case ({record.get('scene')}, {record.get('spp')}), "
                             f"expected ({scene}, {spp})")
        _check_case_files(Path(case_dir), record, record_path)
        record = {key: value for key, value in record.items() if key != FILE_CHECKSUMS}
        fragments[(scene, int(spp))] = record
        numbers[(scene, int(spp))] = case_numbers(metrics, scene=scene, spp=int(spp), entries=entries,
                                                  metric_names=metric_names, source=metrics_csv)
    scenes = list(dict.fromkeys(scene for scene, _ in cases))
    spps = sorted({int(spp) for _, spp in cases})
    specs = load_metrics(metric_names, config_key="metric_names")
    manifest = build_manifest(scenes=scenes, spps=spps, entries=entries, labels=labels,
                              metric_names=metric_names, cases=fragments, numbers=numbers,
                              metric_labels={name: spec.label for name, spec in specs.items()},
                              lower_is_better={name: spec.lower_is_better for name, spec in specs.items()},
                              error_scales={name: spec.map_scale for name, spec in specs.items()
                                            if spec.map_scale is not None})
    assemble_viewer(output_dir, static_dir=static_dir, case_dirs=dict(zip(fragments, case_dirs)),
                    manifest=manifest)
    print(f"viewer: {len(cases)} cases, {directory_bytes(output_dir) / 1e6:.2f} MB in {output_dir}", flush=True)
    return manifest


def assemble_viewer_case(entry_dirs: dict[str, str], case_dir: str, *, scene: str, spp: int) -> dict:
    """One case's viewer folder from its entries' folders (``entry_dirs``: {entry: folder written
    by :func:`mcbench.pipeline.evaluation.evaluate_entry_values`}, the noisy entry first): every entry's
    images hard-linked (or copied) into ``case_dir`` after checking them against their record's
    CRC-32s, and the merged fragment with the checksums as ``case.json`` (what
    :func:`write_viewer` reads). Refused, naming the record, when an entry's folder holds another
    case or entry, or an image differs from its checksum."""
    import shutil

    from mcbench.analysis.viewer_images import CASE_RECORD, case_files, merge_fragments
    from mcbench.pipeline.evaluation import ENTRY_RECORD

    fragments, checksums = [], {}
    case_path = Path(case_dir)
    case_path.mkdir(parents=True, exist_ok=True)
    for entry, folder in entry_dirs.items():
        record_path = Path(folder) / ENTRY_RECORD
        record = read_json(record_path)
        if (record.get("scene"), record.get("spp"), record.get("entry")) != (scene, int(spp), entry):
            raise BenchError(f"{record_path}: holds entry {record.get('entry')!r} of case ({record.get('scene')}, "
                             f"{record.get('spp')}), expected {entry!r} of ({scene}, {spp}); rerun the job that writes it")
        fragment = {key: value for key, value in record.items() if key not in ("scene", "spp", "entry", "key", FILE_CHECKSUMS)}
        _check_case_files(Path(folder), {**fragment, FILE_CHECKSUMS: record.get(FILE_CHECKSUMS)}, record_path)
        for name in sorted(case_files(fragment)):
            target = case_path / name
            if target.exists():
                target.unlink()
            try:
                os.link(Path(folder) / name, target)
            except OSError:
                shutil.copyfile(Path(folder) / name, target)
        fragments.append(fragment)
        checksums.update(record[FILE_CHECKSUMS])
    fragment = merge_fragments(fragments)
    write_json(case_path / CASE_RECORD, {"scene": scene, "spp": int(spp), **fragment, FILE_CHECKSUMS: checksums})
    return fragment
