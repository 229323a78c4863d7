"""Where each scene's reference comes from: the repository's reference store, or this run's renders.

A rendered scene's reference is taken from the store (:mod:`mcbench.io.reference_store`, folder
``references/`` of the repository) when the config asks for it (``reference: {source: store}``, the
default) and the store holds one whose identity equals this run's (:func:`reference_identity`: the
scene's digest, the resolution, the Mitsuba version, the colour mode); otherwise it is rendered as
the config says (``reference.spp`` / ``scene_spp``, ``chunks``), and the plan says why
(:attr:`ReferenceSource.reason`, printed once when the DAG is planned). A scene of renders made
elsewhere imports its folder's reference.

A stored reference is then checked against this run's own highest-spp noisy render of the scene
(:func:`check_stored_reference`, the block test of :mod:`mcbench.analysis.reference_check`) before
any case uses it: a reference that disagrees stops the run, naming the scene and the test's numbers.

The scene's digest (:func:`scene_digest`) covers the files the scene is made of: a Python scene's
module and the ``mcbench.render`` modules it builds with (followed through their own imports of
``mcbench.render``), or an XML scene's file and the files it names (``filename`` values). It does
not cover the renderer's code: a renderer whose images differ in expectation is what the
statistical check is for.
"""

from __future__ import annotations

import ast
import dataclasses
import hashlib
import importlib.metadata
import re
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from mcbench import BenchError
from mcbench.io.reference_store import (StoredReference, identity_mismatches, read_store_record,
                                        read_stored_layers)

__all__ = ["STORE_FOLDER", "ReferenceSource", "scene_files", "scene_digest", "reference_identity",
           "reference_source", "copy_stored_reference", "check_stored_reference", "store_reference_chunks",
           "stored_reference"]

#: The repository's reference store.
STORE_FOLDER = Path(__file__).resolve().parents[2] / "references"
_RENDER_PACKAGE = "mcbench.render"
_RENDER_FOLDER = Path(__file__).resolve().parents[1] / "render"


@dataclass(frozen=True)
class ReferenceSource:
    """How a scene's reference is made: ``kind`` ``"store"`` (``stored`` is its record),
    ``"render"`` or ``"folder"`` (a scene of renders made elsewhere), and why (``reason``)."""

    scene: str
    kind: str
    reason: str
    stored: StoredReference | None = None


def _render_module_file(name: str) -> Path | None:
    """The source file of ``mcbench.render.<module>`` for an imported name (a module, or a name
    imported from one), None for any other name."""
    parts = name.split(".")
    if parts[:2] != _RENDER_PACKAGE.split(".") or len(parts) < 3:
        return None
    path = _RENDER_FOLDER / f"{parts[2]}.py"
    return path if path.exists() else None


def _render_imports(path: Path) -> dict[str, Path]:
    """The ``mcbench.render`` modules that the Python file at ``path`` imports, with their files."""
    names = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names += [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
        elif isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
    files = {}
    for name in names:
        file = _render_module_file(name)
        if file is not None:
            files[f"{_RENDER_PACKAGE}.{file.stem}"] = file
    return files


def _xml_assets(path: Path) -> list[Path]:
    """The files an XML scene names in ``filename`` values, relative to its folder."""
    values = re.findall(r'name\s*=\s*"filename"\s+value\s*=\s*"([^"]+)"', path.read_text())
    return [(path.parent / value).resolve() for value in values]


def scene_files(module: ModuleType) -> dict[str, Path]:
    """The files scene ``module`` is made of, by a machine-independent name: its own file
    (``scene:<file name>``, the module's ``__file__``) and either the ``mcbench.render`` modules it
    builds with (Python) or the assets its XML names (``asset:<path relative to the XML's folder>``)."""
    source = Path(module.__file__)
    if source.suffix == ".xml":
        files = {f"scene:{source.name}": source}
        for asset in _xml_assets(source):
            if not asset.exists():
                raise BenchError(f"{source}: names the file {asset}, which does not exist")
            name = asset.relative_to(source.parent) if asset.is_relative_to(source.parent) else asset.name
            files[f"asset:{name}"] = asset
        return files
    source = Path(module.__file__)
    files = {f"scene:{source.name}": source}
    pending = dict(_render_imports(source))
    while pending:
        name, path = pending.popitem()
        if f"module:{name}" not in files:
            files[f"module:{name}"] = path
            pending.update(_render_imports(path))
    return files


def scene_digest(module: ModuleType) -> str:
    """SHA-256 over the names and bytes of :func:`scene_files`, hex."""
    digest = hashlib.sha256()
    for name, path in sorted(scene_files(module).items()):
        data = path.read_bytes()
        digest.update(f"{name}\0{len(data)}\0".encode())
        digest.update(data)
    return digest.hexdigest()


def reference_identity(scene: str, module: ModuleType, resolution: tuple[int, int]) -> dict:
    """What a stored reference must equal to stand for this run's reference of ``scene`` at
    ``resolution`` = (width, height) (:data:`mcbench.io.reference_store.IDENTITY_KEYS`). Every
    variant the config accepts renders RGB, so the colour mode is ``rgb``."""
    return {"scene": scene, "scene_digest": scene_digest(module),
            "resolution": f"{int(resolution[0])}x{int(resolution[1])}",
            "mitsuba": importlib.metadata.version("mitsuba"), "color_mode": "rgb"}


def reference_source(scene: str, module: ModuleType, resolution: tuple[int, int], *, requested: str,
                     store: str | Path = STORE_FOLDER) -> ReferenceSource:
    """Where the reference of ``scene`` comes from when the config asks for ``requested``
    (``"store"`` or ``"render"``): the store only when it holds a reference of this identity."""
    if getattr(getattr(module, "SCENE", None), "render_folder", None) is not None:
        return ReferenceSource(scene, "folder", "imported from the scene's folder of renders")
    if requested == "render":
        return ReferenceSource(scene, "render", "rendered: reference.source is 'render'")
    if requested != "store":
        raise ValueError(f"config key 'reference.source': {requested!r}; expected 'store' or 'render'")
    stored = read_store_record(store, scene, resolution)
    if stored is None:
        return ReferenceSource(scene, "render", f"rendered: the store {store} has no reference of "
                               f"'{scene}' at {resolution[0]}x{resolution[1]}")
    mismatches = identity_mismatches(stored, reference_identity(scene, module, resolution))
    if mismatches:
        return ReferenceSource(scene, "render", f"rendered: the stored reference {stored.record_path} is of "
                               "another scene or renderer (" + "; ".join(mismatches) + ")")
    return ReferenceSource(scene, "store", f"from the store: {stored.record_path}", stored)


def stored_reference(record_path: str, output_path: str) -> None:
    """Write the stored reference whose record is ``record_path`` as this run's reference file."""
    record_path = Path(record_path)
    stored = read_store_record(record_path.parent.parent, record_path.stem,
                               tuple(int(v) for v in record_path.parent.name.split("x")))
    if stored is None:
        raise BenchError(f"{record_path}: the stored reference's record is missing")
    copy_stored_reference(stored, output_path)


def copy_stored_reference(stored: StoredReference, output_path: str) -> None:
    """Write the stored reference as this run's reference file (its layers checked against the
    record on the way); the header names the store's record and the spp it was rendered with."""
    from mcbench.io.exr import write_layers

    layers = read_stored_layers(stored)
    provenance = stored.provenance
    write_layers(output_path, layers, metadata={
        "scene": stored.identity["scene"], "resolution": stored.identity["resolution"],
        "spp": str(provenance.get("spp", "")), "stored_reference": stored.record_path.name,
        "stored_sha256": stored.sha256})


def _header_spp(path: str) -> int:
    """The samples per pixel an EXR's header records (``spp``); ``BenchError`` naming the file when
    it records none (the check's variance floor needs it)."""
    from mcbench.io.exr import read_metadata, recorded_spp

    metadata = read_metadata(path)
    spp = recorded_spp(metadata)
    if spp is None:
        raise BenchError(f"{path}: its header records no samples per pixel (spp = {metadata.get('spp', '')!r}); "
                         "the reference check needs it. Render or store the file again with this version")
    return spp


def check_stored_reference(scene: str, reference_path: str, render_path: str, output_path: str) -> None:
    """Test the reference at ``reference_path`` against this run's render at ``render_path`` (both
    with their variance; :func:`mcbench.analysis.reference_check.reference_agreement`), write the
    test's numbers to ``output_path`` (JSON), and stop the run when they disagree. The samples per
    pixel behind each (their headers' ``spp``) set the render's variance floor of the test."""
    from mcbench.analysis.reference_check import reference_agreement
    from mcbench.io.exr import check_finite, read_layers
    from mcbench.io.tables import write_json

    reference = read_layers(reference_path, ["color", "variance"])
    render = read_layers(render_path, ["color", "variance"])
    check_finite(reference_path, reference)
    check_finite(render_path, render)
    if reference["color"].shape != render["color"].shape:
        raise BenchError(f"{reference_path}: reference is {reference['color'].shape}, the render "
                         f"{render_path} is {render['color'].shape}")
    agreement = reference_agreement(reference["color"], reference["variance"], render["color"], render["variance"],
                                    reference_spp=_header_spp(reference_path), render_spp=_header_spp(render_path))
    if not agreement.passed:
        raise BenchError(f"scene '{scene}': the stored reference {reference_path} disagrees with this run's "
                         f"render {render_path}: {agreement.describe()}. Its scene or the renderer differs "
                         "from the store's; set reference: {source: render} or regenerate the store")
    numbers = {key: value.item() if hasattr(value, "item") else value
               for key, value in dataclasses.asdict(agreement).items()}
    write_json(output_path, {"scene": scene, "reference": str(reference_path), "render": str(render_path),
                             "passed": True, "test": numbers, "summary": agreement.describe()})


def store_reference_chunks(scene: str, chunk_paths: list[str], record_path: str, *, features: str) -> StoredReference:
    """Put the reference of ``scene`` into the store whose record is ``record_path``
    (``<store>/<W>x<H>/<scene>.json``), with its identity and provenance (commit, Mitsuba and
    Dr.Jit versions, variant, CPU of the storing machine, spp, seeds, chunks, render seconds,
    feature convention, the scene's files). ``chunk_paths``: this run's reference chunks of the
    scene (merged spp-weighted, as the run's own reference), or the one reference a run merged from
    them (``results/references/<scene>.exr``, whose metadata holds ``chunks``, ``spp``, ``seeds``
    and the chunks' ``seconds``): a finished run's references are stored without rendering them
    again (its chunks are temporary files)."""
    from mcbench.io.exr import check_finite, read_layers, read_metadata
    from mcbench.io.reference_store import write_stored_reference
    from mcbench.pipeline.provenance import cpu_info, git_state, package_versions
    from mcbench.pipeline.registry import load_scene
    from mcbench.pipeline.rendering import merged_chunks

    first = read_metadata(chunk_paths[0]) if chunk_paths else {}
    if len(chunk_paths) == 1 and "chunks" in first:       # a merged reference
        metadata = first
        layers = read_layers(chunk_paths[0], ["color", "variance"])
        check_finite(chunk_paths[0], layers)
        chunks, seconds = int(metadata["chunks"]), float(metadata.get("seconds", 0))
    else:
        layers, metadata = merged_chunks(chunk_paths)
        chunks = len(chunk_paths)
        seconds = sum(float(read_metadata(p).get("seconds", 0)) for p in chunk_paths)
    height, width = layers["color"].shape[:2]
    module = load_scene(scene)
    identity = reference_identity(scene, module, (width, height))
    versions = package_versions()
    provenance = {"commit": git_state(STORE_FOLDER.parent)["commit"], "mitsuba": versions.get("mitsuba"),
                  "drjit": versions.get("drjit"), "variant": metadata.get("variant"), "cpu": cpu_info(),
                  "spp": int(metadata["spp"]), "seeds": metadata.get("seeds"), "seed": metadata.get("seed"),
                  "chunks": chunks, "render_seconds": seconds,
                  "features": features, "scene_files": sorted(scene_files(module))}
    stored = write_stored_reference(Path(record_path).parent.parent, scene, layers, identity=identity,
                                    provenance=provenance)
    if stored.record_path != Path(record_path):
        raise BenchError(f"{record_path}: the reference of '{scene}' is {width}x{height}; it was stored as "
                         f"{stored.record_path}")
    return stored
