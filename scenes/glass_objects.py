"""Transparent objects on a light floor: a rough-glass sphere, a clear glass block, a glass vase
(NumPy lathe mesh) and two thin glass panes, lit by a small area light that casts caustics."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import box, diffuse, lathe, mesh_from_arrays, perspective_sensor, quad
from mcbench.contracts.scene import SceneSpec


def vase_mesh():
    """Closed glass vase: outer wall, lip and inner wall as one lathe profile (watertight)."""
    t = np.linspace(0, 1, 12)
    outer_r = 0.22 + 0.12 * np.sin(np.pi * t * 1.2) - 0.08 * t
    outer_y = 0.9 * t
    inner_r = outer_r[::-1] - 0.03
    inner_y = np.maximum(outer_y[::-1], 0.05)
    radius = np.concatenate([[0.0], outer_r, inner_r, [0.0]])
    height = np.concatenate([[0.0], outer_y, inner_y, [0.05]])
    return lathe(radius, height, segments=32, cap_bottom=False)


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 12 (light
    crosses up to four glass interfaces, plus internal reflections)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    glass = {"type": "dielectric", "int_ior": 1.5}
    v, f, n, uv = vase_mesh()
    checks = (np.indices((2, 2)).sum(axis=0) % 2).astype(np.float32)
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 12},
        "sensor": perspective_sensor(width, height, origin=(0.3, 1.6, 4.0),
                                     target=(0.0, 0.45, 0.0), fov=42.0),
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.05, 0.06, 0.08]}},
        "light": quad((1.6, 2.6, -0.8), (0.15, 0, 0), (0, 0, 0.15),
                      emitter={"type": "area", "radiance": {"type": "rgb",
                                                            "value": [250, 240, 215]}}),
        "floor": quad((0, 0, 0), (4, 0, 0), (0, 0, -4), diffuse({
            "type": "checkerboard", "color0": {"type": "rgb", "value": [0.75, 0.73, 0.7]},
            "color1": {"type": "rgb", "value": [0.45, 0.43, 0.4]},
            "to_uv": T().scale([10, 10, 1])})),
        "back_wall": quad((0, 1.5, -1.8), (4, 0, 0), (0, 1.5, 0), diffuse([0.55, 0.5, 0.45])),
        "rough_sphere": {"type": "sphere", "center": [-1.0, 0.4, 0.3], "radius": 0.4,
                         "bsdf": {"type": "roughdielectric", "distribution": "ggx",
                                  "alpha": 0.15, "int_ior": 1.5}},
        "glass_block": box((0.15, 0.3, 0.5), (0.25, 0.3, 0.25), glass, rotate_y_deg=30),
        "vase": mesh_from_arrays(v, f, n, uv, bsdf=glass, name="vase",
                                 to_world=T().translate([0.9, 0.0, -0.2])),
        "pane_a": quad((-0.3, 0.5, -0.8), (0.45, 0, 0.15), (0, 0.5, 0),
                       {"type": "thindielectric", "int_ior": 1.5}),
        "pane_b": quad((-1.3, 0.45, -0.6), (0.35, 0, -0.2), (0, 0.45, 0),
                       {"type": "thindielectric", "int_ior": 1.5}),
        "colored_ball": {"type": "sphere", "center": [-0.3, 0.2, -1.2], "radius": 0.2,
                         "bsdf": diffuse([0.8, 0.2, 0.1])},
    }


SCENE = SceneSpec(
    description="transparency: refraction through clear and rough glass, thin-pane reflections "
                "and caustics on the floor; the first-hit features describe the glass surface, "
                "not what is seen through it",
    category="glossy/glass", resolution=(128, 128), build=build)
