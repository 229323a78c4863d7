"""The work behind ``workflow/rules/render.smk``: noisy renders, reference chunks and their merge.
"""

from __future__ import annotations



from mcbench.io.exr import check_finite, check_resolution, read_layers, read_metadata, write_layers


def render_noisy(scene: str, spp: int, output_path: str, *, resolution=None, variant: str = "auto",
                 seed: int = 0, threads: int | None = None) -> None:
    """Render the full image and the two half buffers of one (scene, spp) to a multi-layer EXR."""
    from mcbench.render.renderer import render_buffers
    from mcbench.pipeline.registry import load_scene

    layers, metadata = render_buffers(load_scene(scene), spp, resolution=resolution_pair(resolution),
                                      variant=variant, seed=seed, threads=threads)
    check_finite(f"{output_path} (render of scene '{scene}' at {spp} spp)", layers)
    write_layers(output_path, layers, metadata=metadata)


def render_reference_chunk(scene: str, spp: int, chunk: int, output_path: str, *, resolution=None,
                           variant: str = "auto", seed: int = 0, threads: int | None = None) -> None:
    """Render one chunk of a reference with its own seeds (never overlapping the noisy renders)."""
    from mcbench.render.renderer import render_reference_chunk as render_chunk
    from mcbench.pipeline.registry import load_scene

    layers, metadata = render_chunk(load_scene(scene), spp, chunk, resolution=resolution_pair(resolution),
                                    variant=variant, seed=seed, threads=threads)
    check_finite(f"{output_path} (reference chunk {chunk} of scene '{scene}')", layers)
    write_layers(output_path, layers, metadata=metadata)


def merge_reference(chunk_paths: list[str], output_path: str) -> None:
    """Merge reference chunks (spp-weighted, float64) into the reference with its own variance."""
    from mcbench.render.renderer import merge_reference_chunks

    chunks = []
    for path in chunk_paths:
        layers = read_layers(path)
        check_finite(path, layers)
        check_resolution(path, layers["color"].shape)
        chunks.append((layers, read_metadata(path)))
    layers, metadata = merge_reference_chunks(chunks)
    write_layers(output_path, layers, metadata=metadata)


def resolution_pair(resolution):
    if resolution is None:
        return None
    if isinstance(resolution, int):
        return (resolution, resolution)
    return tuple(int(v) for v in resolution)
