"""A small bathroom: walls and floor with NumPy tile textures, a mirror over a glossy ceramic
basin on a counter, a chrome tap, lit by small bright bulbs above the mirror."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


ROOM = (3.0, 2.6, 3.0)    # x, y, z; floor at y = 0; back wall (with the mirror) at z = -1.5


def tile_texture(size: int = 128, count: int = 8, colour=(0.8, 0.82, 0.8), seed: int = 1) -> np.ndarray:
    """(size, size, 3) float32 square tiles with grout lines and slight per-tile colour variation."""
    rng = np.random.default_rng(seed)
    u = (np.arange(size) + 0.5) / size * count
    edge = np.minimum(u % 1.0, 1 - u % 1.0)
    grout = (np.minimum(edge[:, None], edge[None, :]) < 0.05)[..., None]
    tint = np.repeat(np.repeat(rng.uniform(0.9, 1.05, (count, count, 1)), size // count, 0), size // count, 1)
    return np.ascontiguousarray(np.where(grout, 0.3, tint * np.array(colour)), dtype=np.float32)


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 8 (mirror - ceramic -
    wall chains)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    w, h, d = ROOM
    wall_tiles = {"type": "diffuse", "reflectance": {
        "type": "bitmap", "bitmap": mi.Bitmap(tile_texture()), "to_uv": T().scale([2, 2, 1])}}
    floor_tiles = {"type": "diffuse", "reflectance": {
        "type": "bitmap", "bitmap": mi.Bitmap(tile_texture(count=4, colour=(0.3, 0.32, 0.36), seed=2)),
        "to_uv": T().scale([3, 3, 1])}}
    ceramic = {"type": "roughplastic", "distribution": "ggx", "alpha": 0.05,
               "diffuse_reflectance": {"type": "rgb", "value": [0.85, 0.85, 0.83]}}
    chrome = {"type": "roughconductor", "material": "Cr", "distribution": "ggx", "alpha": 0.03}
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "sensor": perspective_sensor(width, height, origin=(0.9, 1.6, 1.35),
                                     target=(-0.1, 1.0, -1.5), fov=60.0),
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale([w / 2, d / 2, 1]),
                  "bsdf": floor_tiles},
        "ceiling": {"type": "rectangle",
                    "to_world": T().translate([0, h, 0]).rotate([1, 0, 0], 90).scale([w / 2, d / 2, 1]),
                    "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.8, 0.8]}}},
        "mirror": {"type": "rectangle",
                   "to_world": T().translate([-0.1, 1.55, -d / 2 + 0.01]).scale([0.6, 0.45, 1]),
                   "bsdf": {"type": "conductor", "material": "Ag"}},
        "counter": {"type": "cube",
                    "to_world": T().translate([-0.1, 0.42, -d / 2 + 0.3]).scale([0.8, 0.42, 0.3]),
                    "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.25, 0.18, 0.12]}}},
        "basin": {"type": "sphere", "center": [-0.1, 0.88, -d / 2 + 0.32], "radius": 0.24,
                  "bsdf": ceramic},
        "tap": {"type": "cylinder", "radius": 0.025,
                "to_world": T().translate([-0.1, 0.84, -d / 2 + 0.06]).rotate([1, 0, 0], -90).scale([1, 1, 0.35]),
                "bsdf": chrome},
        "tap_spout": {"type": "cylinder", "radius": 0.02,
                      "to_world": T().translate([-0.1, 1.17, -d / 2 + 0.06]).scale([1, 1, 0.16]),
                      "bsdf": chrome},
    }
    for i, x in enumerate((-0.55, -0.1, 0.35)):
        scene[f"bulb_{i}"] = {"type": "sphere", "center": [x, 2.12, -d / 2 + 0.12], "radius": 0.035,
                              "emitter": {"type": "area", "radiance": {"type": "rgb",
                                                                       "value": [220.0, 190.0, 150.0]}}}
    walls = {"back": T().translate([0, h / 2, -d / 2]).scale([w / 2, h / 2, 1]),
             "front": T().translate([0, h / 2, d / 2]).rotate([0, 1, 0], 180).scale([w / 2, h / 2, 1]),
             "left": T().translate([-w / 2, h / 2, 0]).rotate([0, 1, 0], 90).scale([d / 2, h / 2, 1]),
             "right": T().translate([w / 2, h / 2, 0]).rotate([0, 1, 0], -90).scale([d / 2, h / 2, 1])}
    for name, transform in walls.items():
        scene[f"wall_{name}"] = {"type": "rectangle", "to_world": transform, "bsdf": wall_tiles}
    return scene


SCENE = SceneSpec(
    description="interior with a mirror and small bright bulbs: mirrored view of the room, glossy "
                "ceramic and chrome reflections, high-frequency tile texture and grout lines",
    category="glossy/interior", resolution=(128, 128), build=build)
