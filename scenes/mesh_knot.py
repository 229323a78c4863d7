"""Two (2, 3) torus-knot tube meshes built in NumPy: a coarse faceted one in rough copper (flat
shading) and the same coarse mesh in rough plastic with smooth interpolated vertex normals."""

from __future__ import annotations

import numpy as np

from mcbench.render.curves import mesh_shape
from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


SEGMENTS, SIDES = 96, 10      # coarse on purpose: visible facets on the flat-shaded knot
TUBE_RADIUS = 0.13


def torus_knot(p: int = 2, q: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (V, 3), faces (F, 3) and smooth vertex normals (V, 3) of a tube around the (p, q)
    torus knot of overall radius ~1, centred at the origin in the XY plane."""
    t = np.linspace(0, 2 * np.pi, SEGMENTS, endpoint=False)

    def centre(s):
        r = 0.65 + 0.3 * np.cos(q * s)
        return np.stack([r * np.cos(p * s), r * np.sin(p * s), 0.3 * np.sin(q * s)], axis=-1)

    c = centre(t)
    tangent = centre(t + 1e-4) - centre(t - 1e-4)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.cross(tangent, np.array([0.0, 0.0, 1.0]))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    binormal = np.cross(tangent, normal)
    a = np.linspace(0, 2 * np.pi, SIDES, endpoint=False)
    ring = (np.cos(a)[None, :, None] * normal[:, None, :] + np.sin(a)[None, :, None] * binormal[:, None, :])
    vertices = (c[:, None, :] + TUBE_RADIUS * ring).reshape(-1, 3)
    i = np.arange(SEGMENTS)[:, None]
    j = np.arange(SIDES)[None, :]
    v00 = (i * SIDES + j).ravel()
    v10 = (((i + 1) % SEGMENTS) * SIDES + j).ravel()
    v01 = (i * SIDES + (j + 1) % SIDES).ravel()
    v11 = (((i + 1) % SEGMENTS) * SIDES + (j + 1) % SIDES).ravel()
    faces = np.concatenate([np.stack([v00, v11, v10], 1), np.stack([v00, v01, v11], 1)])  # outward
    return vertices, faces, ring.reshape(-1, 3)


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 8 (glossy metal
    reflects the other knot and the floor several times)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    vertices, faces, normals = torus_knot()
    rot = np.radians(-70.0)
    tilt = np.array([[1, 0, 0], [0, np.cos(rot), -np.sin(rot)], [0, np.sin(rot), np.cos(rot)]])
    v = vertices @ tilt.T
    n = normals @ tilt.T
    left = v + np.array([-1.05, 0.55, 0.0])
    right = v + np.array([1.05, 0.55, 0.0])
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "sensor": perspective_sensor(width, height, origin=(0.0, 2.6, 4.6),
                                     target=(0.0, 0.4, 0.0), fov=40.0),
        "knot_flat_copper": mesh_shape("knot_flat", left, faces, bsdf={
            "type": "roughconductor", "material": "Cu", "distribution": "ggx", "alpha": 0.2}),
        "knot_smooth_plastic": mesh_shape("knot_smooth", right, faces, normals=n, bsdf={
            "type": "roughplastic", "distribution": "ggx", "alpha": 0.1,
            "diffuse_reflectance": {"type": "rgb", "value": [0.1, 0.35, 0.15]}}),
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale([6, 6, 1]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.55, 0.52, 0.5]}}},
        "light": {"type": "rectangle",
                  "to_world": T().look_at(origin=[-1.0, 3.5, 2.0], target=[0, 0, 0], up=[0, 1, 0])
                                 .scale([1.0, 0.6, 1]),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [10.0, 9.5, 9.0]}}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.15, 0.16, 0.2]}},
    }


SCENE = SceneSpec(
    description="glossy meshes: faceted geometry with flat vs interpolated shading normals, "
                "glossy interreflections and highlights on curved tubes under an area light",
    category="glossy", resolution=(128, 128), build=build)
