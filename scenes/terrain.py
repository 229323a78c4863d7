"""Procedural mountains: a fractal heightfield mesh (spectral synthesis in NumPy) with a NumPy
colour texture (grass, rock, snow by height and slope), lit by a low sun and a sky."""

from __future__ import annotations

import numpy as np

from mcbench.render.curves import grid_mesh, mesh_shape
from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


GRID = 129            # heightfield vertices per side
SIZE = 10.0           # world size of the terrain (x and z)
RELIEF = 2.2          # height range


def heights(seed: int = 5) -> np.ndarray:
    """(GRID, GRID) heights: 1/f^2 power-spectrum noise (fractal), shaped into a mountain range."""
    rng = np.random.default_rng(seed)
    fx = np.fft.fftfreq(GRID)[None, :]
    fz = np.fft.fftfreq(GRID)[:, None]
    f = np.sqrt(fx ** 2 + fz ** 2)
    amplitude = np.where(f > 0, f, 1.0) ** -2.1 * (f > 0)
    spectrum = amplitude * np.exp(2j * np.pi * rng.random((GRID, GRID)))
    h = np.real(np.fft.ifft2(spectrum))
    h = (h - h.min()) / (h.max() - h.min())
    return RELIEF * h ** 1.6


def colour_texture(h: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Albedo per vertex, as an (GRID, GRID, 3) float32 image: grass low, rock on steep slopes,
    snow high, with a little per-texel noise."""
    rng = np.random.default_rng(9)
    n = normals.reshape(GRID, GRID, 3)
    slope = 1 - n[..., 1] / np.linalg.norm(n, axis=-1)          # 0 flat .. 1 vertical
    level = h / RELIEF
    grass, rock, snow = np.array([0.13, 0.25, 0.07]), np.array([0.3, 0.27, 0.24]), np.array([0.85, 0.87, 0.9])
    w_rock = np.clip((slope - 0.12) * 8, 0, 1)[..., None]
    w_snow = np.clip((level - 0.55) * 6, 0, 1)[..., None] * (1 - 0.7 * w_rock)
    albedo = (1 - w_rock) * grass + w_rock * rock
    albedo = (1 - w_snow) * albedo + w_snow * snow
    albedo *= rng.uniform(0.8, 1.2, (GRID, GRID, 1))
    return np.ascontiguousarray(np.clip(albedo, 0, 0.95), dtype=np.float32)


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 6 (diffuse outdoor
    scene: sun and sky dominate, few interreflections)."""
    import mitsuba as mi

    h = heights()
    vertices, faces, uv, normals = grid_mesh(h, SIZE, SIZE)
    texture = colour_texture(h, normals)
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 6},
        "sensor": perspective_sensor(width, height, origin=(0.0, 3.6, 6.5),
                                     target=(0.0, 0.6, -0.5), fov=50.0),
        "terrain": mesh_shape("terrain", vertices, faces, uv=uv, normals=normals,
                              bsdf={"type": "diffuse", "reflectance": {
                                  "type": "bitmap", "bitmap": mi.Bitmap(texture),
                                  "filter_type": "bilinear", "wrap_mode": "clamp"}}),
        "sun": {"type": "directional", "direction": [0.8, -0.35, 0.3],
                "irradiance": {"type": "rgb", "value": [4.0, 3.4, 2.6]}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.25, 0.35, 0.55]}},
    }


SCENE = SceneSpec(
    description="fractal terrain under a low sun: fine geometric and texture detail, long sharp "
                "shadows and soft sky light in shadowed valleys",
    category="geometry/texture", resolution=(128, 128), build=build)
