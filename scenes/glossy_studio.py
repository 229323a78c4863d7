"""Product shot: glossy and rough plastic and principled objects on a seamless curved backdrop,
under two large soft area lights and a thin rim strip light."""

from __future__ import annotations

import numpy as np

from mcbench.render.curves import mesh_shape
from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


def backdrop(n: int = 32, width: float = 8.0, radius: float = 1.2, depth: float = 3.0):
    """Seamless studio sweep: floor plane bending up (quarter circle) into a back wall.
    Returns vertices, faces, normals of a (2, n) strip mesh."""
    s = np.concatenate([np.linspace(-depth, 0, n // 4, endpoint=False),          # floor (z from front)
                        np.linspace(0, np.pi / 2, n // 2, endpoint=False),        # bend
                        np.linspace(0, 3.0, n // 4)])                             # back wall
    kind = np.repeat([0, 1, 2], [n // 4, n // 2, n // 4])
    y = np.where(kind == 0, 0.0, np.where(kind == 1, radius * (1 - np.cos(s)), radius + s))
    z = np.where(kind == 0, -s - 1.0, np.where(kind == 1, -1.0 - radius * np.sin(s), -1.0 - radius))
    ny = np.where(kind == 0, 1.0, np.where(kind == 1, np.cos(s), 0.0))
    nz = np.where(kind == 0, 0.0, np.where(kind == 1, np.sin(s), 1.0))
    m = len(s)
    vertices = np.concatenate([np.stack([np.full(m, x), y, z], 1) for x in (-width / 2, width / 2)])
    normals = np.concatenate([np.stack([np.zeros(m), ny, nz], 1)] * 2)
    i = np.arange(m - 1)
    faces = np.concatenate([np.stack([i, i + 1, i + m], 1), np.stack([i + 1, i + m + 1, i + m], 1)])
    return vertices, faces, normals


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 8 (glossy-glossy
    interreflections between the objects)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    v, f, n = backdrop()
    rgb = lambda *c: {"type": "rgb", "value": list(c)}  # noqa: E731
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "sensor": perspective_sensor(width, height, origin=(0.0, 1.4, 4.5),
                                     target=(0.0, 0.45, 0.0), fov=34.0),
        "backdrop": mesh_shape("backdrop", v, f, normals=n, bsdf={
            "type": "diffuse", "reflectance": rgb(0.62, 0.62, 0.64)}),
        "red_plastic_sphere": {"type": "sphere", "center": [-1.0, 0.45, 0.2], "radius": 0.45,
                               "bsdf": {"type": "plastic", "diffuse_reflectance": rgb(0.6, 0.05, 0.04)}},
        "rough_blue_cube": {"type": "cube",
                            "to_world": T().translate([0.05, 0.35, -0.35]).rotate([0, 1, 0], 25).scale(0.35),
                            "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.25,
                                     "diffuse_reflectance": rgb(0.1, 0.2, 0.55)}},
        "principled_gold_sphere": {"type": "sphere", "center": [0.95, 0.4, 0.35], "radius": 0.4,
                                   "bsdf": {"type": "principled", "base_color": rgb(0.9, 0.7, 0.35),
                                            "metallic": 0.85, "roughness": 0.25,
                                            "clearcoat": 0.6, "clearcoat_gloss": 0.9}},
        "principled_white_cylinder": {
            "type": "cylinder", "radius": 0.2,
            "to_world": T().translate([-0.15, 0.0, 0.55]).rotate([1, 0, 0], -90).scale([1, 1, 0.6]),
            "bsdf": {"type": "principled", "base_color": rgb(0.85, 0.85, 0.8), "roughness": 0.35,
                     "specular": 0.7, "sheen": 0.3}},
        "cylinder_cap": {"type": "disk",
                         "to_world": T().translate([-0.15, 0.6, 0.55]).rotate([1, 0, 0], -90).scale(0.2),
                         "bsdf": {"type": "principled", "base_color": rgb(0.85, 0.85, 0.8),
                                  "roughness": 0.35}},
        "softbox_left": {"type": "rectangle",
                         "to_world": T().look_at(origin=[-2.6, 2.2, 2.0], target=[0, 0.4, 0], up=[0, 1, 0])
                                        .scale([0.9, 1.2, 1]),
                         "emitter": {"type": "area", "radiance": rgb(6.0, 6.0, 6.0)}},
        "softbox_right": {"type": "rectangle",
                          "to_world": T().look_at(origin=[2.8, 1.8, 1.2], target=[0, 0.4, 0], up=[0, 1, 0])
                                         .scale([0.7, 1.0, 1]),
                          "emitter": {"type": "area", "radiance": rgb(3.5, 3.6, 4.0)}},
        "rim_strip": {"type": "rectangle",
                      "to_world": T().look_at(origin=[0.0, 3.0, -1.2], target=[0, 0.4, 0.2], up=[0, 0, 1])
                                     .scale([2.0, 0.08, 1]),
                      "emitter": {"type": "area", "radiance": rgb(25.0, 25.0, 25.0)}},
    }


SCENE = SceneSpec(
    description="studio product shot: broad glossy highlights and reflections of large area lights "
                "on plastic, clear-coated and metallic surfaces over a smooth gradient backdrop",
    category="glossy", resolution=(128, 128), build=build)
