"""High-frequency textures: a pixel-scale checkerboard floor, fine stripes on a wall, and
NumPy noise textures on a cube and a sphere, under an area light and a dim sky."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import bitmap_texture, box, diffuse, perspective_sensor, quad
from mcbench.contracts.scene import SceneSpec


def stripes(size: int = 256, period: int = 4) -> np.ndarray:
    """(size, size, 3) alternating coloured stripes ``period`` texels wide, slightly tilted."""
    y, x = np.indices((size, size))
    band = ((x + 0.15 * y) // (period / 2)).astype(int) % 2
    return np.where(band[..., None] == 1, [0.8, 0.7, 0.2], [0.12, 0.15, 0.45]).astype(np.float32)


def value_noise(size: int = 128, cells: int = 32, seed: int = 7) -> np.ndarray:
    """(size, size, 3) multi-octave value noise in [0.05, 0.85] (seeded)."""
    rng = np.random.default_rng(seed)
    out = np.zeros((size, size))
    for octave, weight in ((cells, 0.5), (2 * cells, 0.3), (size, 0.2)):
        grid = rng.random((octave, octave))
        out += weight * np.kron(grid, np.ones((size // octave, size // octave)))
    tint = np.array([0.9, 0.55, 0.35])
    return (0.05 + 0.8 * out[..., None] * tint).astype(np.float32)


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 5 (the
    difficulty is spatial detail, not light transport)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    checker = (np.indices((2, 2)).sum(axis=0) % 2).astype(np.float32)
    checker_tex = bitmap_texture(0.08 + 0.72 * checker, filter_type="nearest",
                                 to_uv=T().scale([120, 120, 1]))
    rng = np.random.default_rng(11)
    speckle = (0.1 + 0.7 * (rng.random((256, 256, 1)) ** 3) * np.array([0.6, 0.8, 1.0]))
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 5},
        "sensor": perspective_sensor(width, height, origin=(0.0, 1.3, 3.6),
                                     target=(0.0, 0.5, 0.0), fov=45.0),
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.15, 0.17, 0.2]}},
        "light": quad((1.5, 3.0, 1.5), (0.6, 0, 0), (0, 0, 0.6),
                      emitter={"type": "area", "radiance": {"type": "rgb", "value": [22, 20, 18]}}),
        "floor": quad((0, 0, 0), (3, 0, 0), (0, 0, -3), diffuse(checker_tex)),
        "wall": quad((0, 1.5, -1.5), (3, 0, 0), (0, 1.5, 0),
                     diffuse(bitmap_texture(stripes(), filter_type="nearest",
                                            to_uv=T().scale([2, 1, 1])))),
        "noise_cube": box((-0.8, 0.45, -0.3), 0.45,
                          diffuse(bitmap_texture(value_noise(), filter_type="nearest")), 25.0),
        "speckle_sphere": {"type": "sphere", "center": [0.75, 0.5, 0.1], "radius": 0.5,
                           "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.2,
                                    "diffuse_reflectance": bitmap_texture(
                                        speckle, filter_type="nearest",
                                        to_uv=T().scale([2, 1, 1]))}},
    }


SCENE = SceneSpec(
    description="texture detail at and below the pixel scale (checker, stripes, value noise): "
                "the albedo feature carries it but the noisy colour hides it, so denoisers that "
                "blur across texture edges lose it and ones that trust the albedo too much alias",
    category="texture", resolution=(128, 128), build=build)
