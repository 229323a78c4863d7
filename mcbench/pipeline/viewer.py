"""The work behind ``workflow/rules/viewer.smk``: each case's viewer images and the static viewer.
"""

from __future__ import annotations

from pathlib import Path


from mcbench import NOISY, BenchError
from mcbench.io.exr import check_finite, read_layers
from mcbench.io.tables import read_json, read_table, write_json


def write_viewer_case(scene: str, spp: int, reference_path: str, render_path: str,
                      candidate_paths: dict[str, str], case_dir: str, *,
                      weight_inputs: dict[str, list[str]], flip_maps_path: str | None = None) -> dict:
    """One case's images of the static viewer (mcbench.analysis.viewer.write_case_images) in
    ``case_dir``, with its manifest fragment as ``case.json``: the reference, the noisy input
    and every candidate tone-mapped at each exposure, their relMSE and FLIP error maps, and
    the filtered weight maps of each candidate that ``weight_inputs`` gives inputs
    ({candidate: input names}) and whose EXR holds ``weights_filtered_{i}`` for each input.
    ``flip_maps_path``: the case's FLIP maps from :func:`compute_case_metrics` (else evaluated here)."""
    from mcbench.analysis.viewer import CASE_RECORD, write_case_images

    reference = read_layers(reference_path, ["color"])
    check_finite(reference_path, reference)
    reference = reference["color"]
    sources = {NOISY: render_path, **candidate_paths}
    images, weights = {}, {}
    for name, path in sources.items():
        layers = read_layers(path)
        check_finite(path, layers)
        if layers.get("color") is None or layers["color"].shape != reference.shape:
            shape = None if layers.get("color") is None else layers["color"].shape
            raise BenchError(f"{path}: color of shape {shape} does not match reference {reference_path} "
                             f"of shape {reference.shape}")
        images[name] = layers["color"]
        inputs = weight_inputs.get(name, [])
        if inputs and all(f"weights_filtered_{i}" in layers for i in range(len(inputs))):
            weights[name] = [(input_name, layers[f"weights_filtered_{i}"]) for i, input_name in enumerate(inputs)]
    flip_maps = None
    if flip_maps_path is not None:
        flip_maps = read_layers(flip_maps_path, list(sources))
        check_finite(flip_maps_path, flip_maps)
    fragment = write_case_images(case_dir, reference=reference, images=images, weights=weights, flip_maps=flip_maps)
    write_json(Path(case_dir) / CASE_RECORD, {"scene": scene, "spp": int(spp), **fragment})
    return fragment


def write_viewer(metrics_csv: str, case_dirs: list[str], output_dir: str, *, cases: list[tuple[str, int]],
                 candidates: list[str], labels: dict[str, str], metric_names: list[str],
                 static_dir: str) -> dict:
    """The static image viewer in ``output_dir``: the page of ``static_dir`` (index.html,
    viewer.js, viewer.css), every case folder (``case_dirs[i]`` holds ``cases[i]``, written by
    :func:`write_viewer_case`) and ``data.js``, the manifest with each case's numbers from
    ``metrics_csv`` (every entry must have every metric of ``metric_names``). Returns the manifest."""
    from mcbench.analysis.viewer import CASE_RECORD, assemble_viewer, build_manifest, case_numbers, directory_bytes

    if len(case_dirs) != len(cases):
        raise BenchError(f"{output_dir}: {len(case_dirs)} case folders for {len(cases)} cases")
    metrics = read_table(metrics_csv)
    entries = [NOISY] + list(candidates)
    fragments, numbers = {}, {}
    for (scene, spp), case_dir in zip(cases, case_dirs):
        record_path = Path(case_dir) / CASE_RECORD
        try:
            record = read_json(record_path)
        except (OSError, ValueError) as exc:
            raise BenchError(f"{record_path}: cannot read the viewer case record ({exc})") from exc
        if (record.get("scene"), record.get("spp")) != (scene, int(spp)):
            raise BenchError(f"{record_path}: holds case ({record.get('scene')}, {record.get('spp')}), "
                             f"expected ({scene}, {spp})")
        fragments[(scene, int(spp))] = record
        numbers[(scene, int(spp))] = case_numbers(metrics, scene=scene, spp=int(spp), entries=entries,
                                                  metric_names=metric_names, source=metrics_csv)
    scenes = list(dict.fromkeys(scene for scene, _ in cases))
    spps = sorted({int(spp) for _, spp in cases})
    manifest = build_manifest(scenes=scenes, spps=spps, entries=entries, labels=labels,
                              metric_names=metric_names, cases=fragments, numbers=numbers)
    assemble_viewer(output_dir, static_dir=static_dir, case_dirs=dict(zip(fragments, case_dirs)),
                    manifest=manifest)
    print(f"viewer: {len(cases)} cases, {directory_bytes(output_dir) / 1e6:.2f} MB in {output_dir}", flush=True)
    return manifest
