"""A small tree: a trunk with a crown of a few hundred alpha-masked leaf quads (one NumPy mesh,
``mask`` BSDF with a NumPy leaf-shaped opacity map), backlit by a low sun and a sky."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import (bitmap_texture, diffuse, gradient_sky, mesh_from_arrays,
                              perspective_sensor)
from mcbench.contracts.scene import SceneSpec


LEAF_COUNT = 260
LEAF_SIZE = 0.14                       # half length of a leaf quad, world units
CROWN_CENTER = (0.0, 1.9, 0.0)
CROWN_RADII = (1.0, 0.75, 1.0)
SUN_DIRECTION = (-0.25, -0.45, 0.85)   # towards the camera: the crown is backlit


def leaf_opacity(size: int = 64) -> np.ndarray:
    """(size, size) opacity: a pointed leaf blade along v with a thin gap as the midrib."""
    v, u = (np.indices((size, size)) + 0.5) / size
    half_width = 0.42 * np.sin(np.pi * v) ** 0.8
    inside = np.abs(u - 0.5) < half_width
    return inside.astype(np.float32)


def leaf_mesh(seed: int = 21):
    """Vertices, faces and uv of ``LEAF_COUNT`` randomly placed and oriented quads in an
    ellipsoidal crown (seeded)."""
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(LEAF_COUNT, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radius = rng.random(LEAF_COUNT) ** (1 / 3)
    centers = np.asarray(CROWN_CENTER) + directions * radius[:, None] * np.asarray(CROWN_RADII)
    # Leaf axis: roughly outward and downward-drooping, plus a random side vector.
    axis = directions + rng.normal(scale=0.6, size=(LEAF_COUNT, 3)) + [0, -0.4, 0]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    side = np.cross(axis, rng.normal(size=(LEAF_COUNT, 3)))
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    a, s = axis * LEAF_SIZE, side * LEAF_SIZE * 0.6
    corners = np.stack([centers - a - s, centers - a + s, centers + a + s, centers + a - s], 1)
    vertices = corners.reshape(-1, 3)
    base = 4 * np.arange(LEAF_COUNT)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    uv = np.tile([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], (LEAF_COUNT, 1))
    return vertices, faces, uv


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 12 (each
    pass through a transparent part of a leaf quad is a null interaction that counts as a
    bounce)."""
    import mitsuba as mi

    leaf_bsdf = {"type": "mask", "opacity": bitmap_texture(leaf_opacity(), wrap_mode="clamp"),
                 "bsdf": {"type": "principledthin", "roughness": 0.5, "diff_trans": 0.6,
                          "base_color": {"type": "rgb", "value": [0.18, 0.45, 0.08]}}}
    vertices, faces, uv = leaf_mesh()
    bark = diffuse([0.25, 0.17, 0.1])
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 12},
        "sensor": perspective_sensor(width, height, origin=(0.8, 1.2, 4.3),
                                     target=(0.0, 1.45, 0.0), fov=48.0),
        "sky": {"type": "envmap", "scale": 0.8,
                "bitmap": mi.Bitmap(gradient_sky(64, zenith=(0.25, 0.45, 1.0),
                                                 horizon=(1.0, 0.9, 0.75)))},
        "sun": {"type": "directional", "direction": list(SUN_DIRECTION),
                "irradiance": {"type": "rgb", "value": [5.0, 4.3, 3.2]}},
        "ground": {"type": "disk",
                   "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], -90).scale(8.0),
                   "bsdf": diffuse([0.3, 0.35, 0.15])},
        "leaves": mesh_from_arrays(vertices, faces, uv=uv, bsdf=leaf_bsdf, name="leaves"),
        "trunk": {"type": "cylinder", "p0": [0, 0, 0], "p1": [0, 1.9, 0], "radius": 0.09,
                  "bsdf": bark},
    }
    for k, (dx, dz) in enumerate(((0.7, 0.2), (-0.6, 0.3), (0.1, -0.7), (-0.2, 0.6))):
        scene[f"branch{k}"] = {"type": "cylinder", "p0": [0, 1.3 + 0.15 * k, 0],
                               "p1": [dx, 2.1 + 0.1 * k, dz], "radius": 0.035, "bsdf": bark}
    return scene


SCENE = SceneSpec(
    description="alpha-masked foliage backlit by the sun: leaf edges come from the opacity map, "
                "not geometry, sun speckles through the crown and dappled shadows are "
                "high-contrast and noisy, and the translucent leaves glow only indirectly",
    category="foliage", resolution=(128, 128), build=build)
