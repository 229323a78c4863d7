"""A swimming pool: a wavy water surface (dielectric mesh from a NumPy sum of waves) over a
tiled floor (NumPy tile texture), lit by a small bright sun-like sphere light and a sky."""

from __future__ import annotations

import numpy as np

from mcbench.render.curves import grid_mesh, mesh_shape
from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


POOL = (4.0, 1.0, 4.0)   # x size, depth, z size; water surface at y = 0, floor at y = -depth
GRID = 80                # water mesh vertices per side


def tiles(size: int = 256, count: int = 16) -> np.ndarray:
    """(size, size, 3) float32 image of ``count`` x ``count`` light blue tiles with dark grout."""
    rng = np.random.default_rng(2)
    u = (np.arange(size) + 0.5) / size * count
    cell = np.minimum(u % 1.0, 1 - u % 1.0)
    grout = (np.minimum(cell[:, None], cell[None, :]) < 0.06)[..., None]
    tint = rng.uniform(0.85, 1.1, (count, count, 1))
    tint = np.repeat(np.repeat(tint, size // count, 0), size // count, 1)
    image = np.where(grout, np.array([0.15, 0.15, 0.17]), tint * np.array([0.55, 0.75, 0.85]))
    return np.ascontiguousarray(image, dtype=np.float32)


def waves(n: int = GRID, seed: int = 4) -> np.ndarray:
    """(n, n) water heights: a sum of a few random directional sine waves."""
    rng = np.random.default_rng(seed)
    x, z = np.meshgrid(np.linspace(-POOL[0] / 2, POOL[0] / 2, n), np.linspace(-POOL[2] / 2, POOL[2] / 2, n))
    h = np.zeros_like(x)
    for _ in range(6):
        angle, k = rng.uniform(0, 2 * np.pi), rng.uniform(3.0, 9.0)
        h += 0.025 / (1 + 0.2 * k) * np.sin(k * (np.cos(angle) * x + np.sin(angle) * z)
                                            + rng.uniform(0, 2 * np.pi))
    return h


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 10 (camera - water -
    floor - water - light is already 4 bounces, plus wall and total internal reflections)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    w, d, l = POOL
    vertices, faces, uv, normals = grid_mesh(waves(), w, l)
    tile_bsdf = {"type": "diffuse", "reflectance": {"type": "bitmap", "bitmap": mi.Bitmap(tiles()),
                                                    "to_uv": T().scale([2, 2, 1])}}
    walls = {}
    for i, angle in enumerate((0, 90, 180, 270)):
        walls[f"pool_wall_{i}"] = {
            "type": "rectangle",
            "to_world": T().rotate([0, 1, 0], angle).translate([0, -d / 2, -w / 2])
                           .scale([w / 2, d / 2, 1]),
            "bsdf": tile_bsdf}
    deck = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.58, 0.52]}}
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 10},
        "sensor": perspective_sensor(width, height, origin=(0.0, 2.4, 3.6),
                                     target=(0.0, -0.6, 0.0), fov=50.0),
        "floor": {"type": "rectangle",
                  "to_world": T().translate([0, -d, 0]).rotate([1, 0, 0], -90).scale([w / 2, l / 2, 1]),
                  "bsdf": tile_bsdf},
        "water": mesh_shape("water", vertices, faces, normals=normals,
                            bsdf={"type": "dielectric", "int_ior": 1.33, "ext_ior": 1.0}),
        "sun": {"type": "sphere", "center": [-3.0, 6.0, -4.0], "radius": 0.35,
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [600.0, 560.0, 500.0]}}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.3, 0.4, 0.6]}},
    }
    scene.update(walls)
    # Pool deck: four slabs at y = 0 framing the pool opening.
    m = 3.0
    for name, (cx, cz, sx, sz) in {"back": (0, -(l / 2 + m / 2), w / 2 + m, m / 2),
                                   "front": (0, l / 2 + m / 2, w / 2 + m, m / 2),
                                   "left": (-(w / 2 + m / 2), 0, m / 2, l / 2),
                                   "right": (w / 2 + m / 2, 0, m / 2, l / 2)}.items():
        scene[f"deck_{name}"] = {"type": "rectangle",
                                 "to_world": T().translate([cx, 0.0, cz]).rotate([1, 0, 0], -90)
                                                .scale([sx, sz, 1]),
                                 "bsdf": deck}
    return scene


SCENE = SceneSpec(
    description="refractive caustics: sunlight focused by a wavy water surface onto the pool "
                "floor (specular-diffuse-specular paths) seen through the refracting waves",
    category="glossy/glass", resolution=(128, 128), build=build)
