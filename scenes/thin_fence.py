"""A wire fence (thin cylinders) and a slatted gate (thin boxes) in front of a bright sky,
casting sharp thin shadows on the ground from a low sun."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import box, diffuse, gradient_sky, perspective_sensor
from mcbench.contracts.scene import SceneSpec


WIRE_RADIUS = 0.008          # world units; at the fence ~0.3 pixels wide at 128^2
SUN_DIRECTION = (0.35, -0.55, 0.75)   # light travels towards +z: shadows fall towards the camera


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 4 (open
    outdoor scene, direct light dominates)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    metal = {"type": "roughconductor", "material": "Al", "distribution": "ggx", "alpha": 0.3}
    wood = diffuse([0.45, 0.3, 0.18])
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 4},
        "sensor": perspective_sensor(width, height, origin=(0.4, 0.9, 3.6),
                                     target=(0.0, 0.8, 0.0), fov=45.0),
        "sky": {"type": "envmap", "scale": 0.7,
                "bitmap": mi.Bitmap(gradient_sky(64, zenith=(0.25, 0.45, 1.0),
                                                 horizon=(1.2, 1.15, 1.05)))},
        "sun": {"type": "directional", "direction": list(SUN_DIRECTION),
                "irradiance": {"type": "rgb", "value": [3.0, 2.8, 2.4]}},
        "ground": {"type": "disk", "to_world": T().rotate([1, 0, 0], -90).scale(8.0),
                   "bsdf": diffuse([0.35, 0.33, 0.28])},
    }
    # Wire grid: vertical and horizontal wires between x = -2.5 and 0.6, z = 0.
    for i, x in enumerate(np.arange(-2.5, 0.61, 0.12)):
        scene[f"wire_v{i}"] = {"type": "cylinder", "p0": [float(x), 0.0, 0.0],
                               "p1": [float(x), 1.6, 0.0], "radius": WIRE_RADIUS, "bsdf": metal}
    for j, y in enumerate(np.arange(0.1, 1.61, 0.12)):
        scene[f"wire_h{j}"] = {"type": "cylinder", "p0": [-2.5, float(y), 0.0],
                               "p1": [0.6, float(y), 0.0], "radius": WIRE_RADIUS, "bsdf": metal}
    # Posts and a gate of thin slats to the right.
    for k, x in enumerate((-2.5, 0.6, 2.2)):
        scene[f"post{k}"] = box((x, 0.9, 0.0), (0.04, 0.9, 0.04), wood)
    for k, x in enumerate(np.arange(0.72, 2.12, 0.1)):
        scene[f"slat{k}"] = box((float(x), 0.7, 0.0), (0.018, 0.7, 0.01), wood)
    for k, y in enumerate((0.25, 1.15)):
        scene[f"rail{k}"] = box((1.4, y, -0.03), (0.8, 0.03, 0.015), wood)
    scene["ball"] = {"type": "sphere", "center": [-0.6, 0.3, -1.2], "radius": 0.3,
                     "bsdf": diffuse([0.7, 0.2, 0.1])}
    return scene


SCENE = SceneSpec(
    description="sub-pixel thin geometry against a bright background: wires cover a fraction of "
                "a pixel, so colour and features are fractional mixtures that denoisers smear "
                "into halos, and their thin shadows are easily blurred away",
    category="geometry", resolution=(128, 128), build=build)
