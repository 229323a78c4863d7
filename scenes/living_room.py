"""A furnished living room: glossy wooden floor (NumPy plank texture), sofa, table, shelf,
rug, a framed picture, a ceiling panel light and a floor lamp with a glowing shade."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import (bitmap_texture, box, diffuse, lathe, mesh_from_arrays,
                              perspective_sensor, quad)
from mcbench.contracts.scene import SceneSpec


ROOM = (2.5, 2.6, 2.5)      # half width, height, half depth


def planks(size: int = 256, rows: int = 8, seed: int = 31) -> np.ndarray:
    """(size, size, 3) wooden planks along u: per-plank tint, grain streaks, dark seams."""
    rng = np.random.default_rng(seed)
    y, x = np.indices((size, size))
    plank = y * rows // size
    tint = rng.uniform(0.75, 1.15, rows)[plank]
    grain = 0.85 + 0.15 * np.sin(x / size * 2 * np.pi * 3 + rng.uniform(0, 6, rows)[plank]
                                 + 8 * np.sin(y / size * 2 * np.pi * 5))
    seam = ((y % (size // rows)) < 2).astype(float)
    value = tint * grain * (1 - 0.7 * seam)
    return (value[..., None] * np.array([0.42, 0.26, 0.13])).astype(np.float32)


def _room(T, width: int, height: int) -> dict:
    """The integrator, the camera, the room's floor, ceiling and walls and the ceiling light."""
    hx, hy, hz = ROOM
    wall = {"type": "twosided", "bsdf": diffuse([0.72, 0.68, 0.6])}
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 7},
        "sensor": perspective_sensor(width, height, origin=(1.9, 1.6, 2.2),
                                     target=(-0.6, 0.7, -0.8), fov=65.0),
        "floor": quad((0, 0, 0), (hx, 0, 0), (0, 0, -hz),
                      {"type": "roughplastic", "distribution": "ggx", "alpha": 0.05,
                       "diffuse_reflectance": bitmap_texture(planks(),
                                                             to_uv=T().scale([2, 2, 1]))}),
        "ceiling": quad((0, hy, 0), (hx, 0, 0), (0, 0, hz), wall),
        "wall_left": quad((-hx, hy / 2, 0), (0, 0, -hz), (0, hy / 2, 0), wall),
        "wall_right": quad((hx, hy / 2, 0), (0, 0, hz), (0, hy / 2, 0), wall),
        "wall_back": quad((0, hy / 2, -hz), (hx, 0, 0), (0, hy / 2, 0),
                          {"type": "twosided", "bsdf": diffuse([0.55, 0.62, 0.58])}),
        "wall_front": quad((0, hy / 2, hz), (-hx, 0, 0), (0, hy / 2, 0), wall),
        "ceiling_light": quad((0.3, hy - 0.01, 0.0), (0.4, 0, 0), (0, 0, 0.4),
                              emitter={"type": "area", "radiance": {"type": "rgb",
                                                                    "value": [9, 9, 9.5]}}),
    }


def _furniture(T, rng) -> dict:
    """The sofa, the coffee table on its rug, the shelf and the framed picture (its pixels
    drawn from ``rng``)."""
    fabric = diffuse([0.3, 0.38, 0.5])
    return {
        # Sofa against the back wall.
        "sofa_seat": box((-0.6, 0.22, -1.9), (1.0, 0.22, 0.4), fabric),
        "sofa_back": box((-0.6, 0.55, -2.25), (1.0, 0.4, 0.12), fabric),
        "sofa_arm_l": box((-1.55, 0.35, -1.9), (0.1, 0.35, 0.45), fabric),
        "sofa_arm_r": box((0.35, 0.35, -1.9), (0.1, 0.35, 0.45), fabric),
        "cushion": box((-1.0, 0.55, -1.95), (0.22, 0.16, 0.08), diffuse([0.75, 0.55, 0.2]), 10),
        # Coffee table on a rug.
        "rug": quad((-0.6, 0.005, -0.6), (1.1, 0, 0), (0, 0, -0.7), diffuse({
            "type": "checkerboard", "color0": {"type": "rgb", "value": [0.55, 0.15, 0.12]},
            "color1": {"type": "rgb", "value": [0.7, 0.6, 0.45]},
            "to_uv": T().scale([6, 4, 1])})),
        "table_top": box((-0.6, 0.42, -0.6), (0.55, 0.025, 0.32),
                         {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1,
                          "diffuse_reflectance": {"type": "rgb", "value": [0.15, 0.1, 0.06]}}),
        "book": box((-0.8, 0.47, -0.55), (0.15, 0.025, 0.11), diffuse([0.1, 0.3, 0.15]), 20),
        "mug": {"type": "cylinder", "p0": [-0.3, 0.445, -0.5], "p1": [-0.3, 0.56, -0.5],
                "radius": 0.045, "bsdf": diffuse(0.85)},
        # Shelf with books on the left wall.
        "shelf": box((-2.3, 0.9, 0.3), (0.2, 0.9, 0.6), diffuse([0.4, 0.25, 0.12])),
        # Framed picture on the back wall.
        "frame": box((0.9, 1.6, -2.49), (0.45, 0.32, 0.01), diffuse(0.1)),
        "picture": quad((0.9, 1.6, -2.475), (0.4, 0, 0), (0, 0.27, 0),
                        diffuse(bitmap_texture(rng.random((6, 8, 3)).astype(np.float32) * 0.8,
                                               filter_type="nearest"))),
    }


def _floor_lamp(T) -> dict:
    """Floor lamp: pole, base and an emissive-inside shade with a warm bulb."""
    shade_v, shade_f, shade_n, shade_uv = lathe([0.25, 0.15], [0.0, 0.3], segments=24,
                                                cap_bottom=False)
    return {
        "lamp_base": {"type": "cylinder", "p0": [1.5, 0, -1.8], "p1": [1.5, 0.03, -1.8],
                      "radius": 0.18, "bsdf": diffuse(0.15)},
        "lamp_pole": {"type": "cylinder", "p0": [1.5, 0, -1.8], "p1": [1.5, 1.4, -1.8],
                      "radius": 0.02, "bsdf": diffuse(0.15)},
        "lamp_shade": mesh_from_arrays(shade_v, shade_f, shade_n, shade_uv,
                                       bsdf={"type": "twosided", "bsdf": diffuse([0.9, 0.8, 0.6])},
                                       name="lamp_shade", to_world=T().translate([1.5, 1.3, -1.8])),
        "lamp_bulb": {"type": "sphere", "center": [1.5, 1.42, -1.8], "radius": 0.06,
                      "emitter": {"type": "area", "radiance": {"type": "rgb",
                                                               "value": [120, 80, 35]}}},
    }


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 7."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    rng = np.random.default_rng(32)
    scene = {**_room(T, width, height), **_furniture(T, rng), **_floor_lamp(T)}
    for k in range(7):
        scene[f"shelf_book{k}"] = box((-2.08, 1.28, 0.75 - 0.12 * k), (0.03, 0.12 + 0.02 * (k % 3), 0.05),
                                      diffuse(rng.uniform(0.1, 0.7, 3)))
    return scene


SCENE = SceneSpec(
    description="a typical interior mixing diffuse walls and furniture with a glossy floor that "
                "reflects them, two light sources of different colour and size, and many "
                "contact shadows and occlusion edges",
    category="interior", resolution=(128, 128), build=build)
