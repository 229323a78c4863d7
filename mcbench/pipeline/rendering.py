"""The work behind ``workflow/rules/render.smk``: noisy renders, reference chunks and their merge;
for a scene of renders made elsewhere (``scenes/<name>.yaml``, :mod:`mcbench.io.render_folders`)
the same rules import its cases and its reference from the folder instead.
"""

from __future__ import annotations

from mcbench.contracts.scene import scene_spec
from mcbench.io.exr import check_finite, check_resolution, read_layers, read_metadata, write_layers
from mcbench.io.render_folders import RenderFolder, case_files, read_case, read_reference, reference_files

__all__ = ["render_noisy", "render_reference_chunk", "merge_reference", "merged_chunks", "folder_case_files",
           "folder_reference_files", "resolution_pair"]

#: Renders are stored Zstandard-compressed (lossless; :data:`mcbench.io.exr.COMPRESSIONS`): with
#: their feature layers (albedo, normal, depth, position, visibility, each with its variance and
#: halves) they take 0.49 of their uncompressed bytes (ZIP: 0.60), for one read per case job of
#: some milliseconds more at 128 x 128 (`benchmarks/exr_compression.py`, docs/measurements.md).
RENDER_COMPRESSION = "zstd"


def folder_case_files(folder: RenderFolder, spp: int) -> list[str]:
    """The files of an imported case (the render job's inputs), sorted."""
    return sorted(str(path) for path in case_files(folder, spp)[0].values())


def folder_reference_files(folder: RenderFolder) -> list[str]:
    """The files of an imported reference (colour, and variance where given), sorted."""
    return sorted(str(path) for path in reference_files(folder).values())


def _import_case(scene: str, folder: RenderFolder, spp: int, output_path: str, resolution) -> None:
    """Write the imported case at ``spp`` as a render file: the layers the folder gives (nothing
    stands in for the others), header ``imported_from`` naming the folder."""
    layers = read_case(folder, spp)
    height, width = layers["color"].shape[:2]
    size = resolution_pair(resolution)
    if size is not None and size != (width, height):
        raise ValueError(f"{folder.path}: the renders of scene '{scene}' are {width}x{height}, the config's "
                         f"resolution {list(size)}; they are not resized (set resolution: null)")
    write_layers(output_path, layers, metadata={"scene": scene, "spp": str(spp), "resolution": f"{width}x{height}",
                                                "imported_from": str(folder.path), "layout": folder.layout,
                                                "layers": ",".join(sorted(layers))},
                 compression=RENDER_COMPRESSION)


def render_noisy(scene: str, spp: int, output_path: str, *, resolution=None, variant: str = "auto",
                 seed: int = 0, threads: int | None = None, features: str = "first_hit") -> None:
    """Render the full image and the two half buffers of one (scene, spp) to a multi-layer EXR (or
    import the case of a scene of renders made elsewhere); ``features``: where the features are
    recorded (:data:`mcbench.render.renderer.FEATURE_CONVENTIONS`, config key ``features``)."""
    from mcbench.pipeline.registry import load_scene

    module = load_scene(scene)
    folder = scene_spec(module).render_folder
    if folder is not None:
        _import_case(scene, folder, spp, output_path, resolution)
        return
    from mcbench.render.renderer import render_buffers

    layers, metadata = render_buffers(module, spp, resolution=resolution_pair(resolution),
                                      variant=variant, seed=seed, threads=threads, features=features)
    check_finite(f"{output_path} (render of scene '{scene}' at {spp} spp)", layers)
    write_layers(output_path, layers, metadata=metadata, compression=RENDER_COMPRESSION)


def render_reference_chunk(scene: str, spp: int, chunk: int, output_path: str, *, resolution=None,
                           variant: str = "auto", seed: int = 0, threads: int | None = None,
                           features: str = "first_hit") -> None:
    """Render one chunk of a reference with its own seeds (never overlapping the noisy renders),
    its features in convention ``features``."""
    from mcbench.render.renderer import render_reference_chunk as render_chunk
    from mcbench.pipeline.registry import load_scene

    layers, metadata = render_chunk(load_scene(scene), spp, chunk, resolution=resolution_pair(resolution),
                                    variant=variant, seed=seed, threads=threads, features=features)
    check_finite(f"{output_path} (reference chunk {chunk} of scene '{scene}')", layers)
    write_layers(output_path, layers, metadata=metadata)


def merge_reference(chunk_paths: list[str], output_path: str, *, scene: str | None = None) -> None:
    """Merge reference chunks (spp-weighted, float64) into the reference with its own variance; for
    a ``scene`` of renders made elsewhere, import its reference (``chunk_paths`` are then the
    folder's files, read again by :func:`mcbench.io.render_folders.read_reference`)."""
    if scene is not None:
        from mcbench.pipeline.registry import load_scene

        folder = scene_spec(load_scene(scene)).render_folder
        if folder is not None:
            layers = read_reference(folder)
            height, width = layers["color"].shape[:2]
            write_layers(output_path, layers, metadata={"scene": scene, "resolution": f"{width}x{height}",
                                                        "imported_from": str(folder.path), "layout": folder.layout,
                                                        "layers": ",".join(sorted(layers))})
            return

    layers, metadata = merged_chunks(chunk_paths)
    write_layers(output_path, layers, metadata=metadata)


def merged_chunks(chunk_paths: list[str]) -> tuple[dict, dict]:
    """The reference chunks at ``chunk_paths`` (each checked: finite, the harness's size) merged
    spp-weighted in float64 (:func:`mcbench.render.renderer.merge_reference_chunks`): layers and metadata."""
    from mcbench.render.renderer import merge_reference_chunks

    chunks = []
    for path in chunk_paths:
        layers = read_layers(path)
        check_finite(path, layers)
        check_resolution(path, layers["color"].shape)
        chunks.append((layers, read_metadata(path)))
    return merge_reference_chunks(chunks)


def resolution_pair(resolution):
    if resolution is None:
        return None
    if isinstance(resolution, int):
        return (resolution, resolution)
    return tuple(int(v) for v in resolution)
