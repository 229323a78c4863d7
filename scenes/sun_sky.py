"""An outdoor village square lit by Mitsuba 3.9.1's analytic ``sunsky`` emitter (Hosek-Wilkie
sky plus a physical sun disc): houses with gable roofs, columns, a statue sphere."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import box, diffuse, mesh_from_arrays, perspective_sensor
from mcbench.contracts.scene import SceneSpec


SUN_DIRECTION = (-0.55, 0.45, -0.7)   # towards the sun: low, behind-left of the houses
EXPOSURE = 2.0                        # sunsky radiance is physical; scales sun and sky together


def gable_roof(x0, x1, z0, z1, y0, ridge):
    """Vertices and faces of a gable roof (ridge along x) over the box [x0,x1] x [z0,z1]."""
    zc = 0.5 * (z0 + z1)
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, ridge, zc], [x0, ridge, zc],
                  [x0, y0, z1], [x1, y0, z1]])
    f = np.array([[0, 3, 2], [0, 2, 1],        # front slope (faces -z and up)
                  [4, 5, 2], [4, 2, 3],        # back slope
                  [0, 4, 3], [1, 2, 5]])       # gable ends
    return v, f


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 6."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    direction = np.asarray(SUN_DIRECTION) / np.linalg.norm(SUN_DIRECTION)
    roof = {"type": "twosided", "bsdf": diffuse([0.45, 0.15, 0.1])}
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 6},
        "sensor": perspective_sensor(width, height, origin=(2.5, 1.6, 6.0),
                                     target=(-0.3, 0.9, 0.0), fov=50.0),
        # sunsky's own frame is Z-up; to_world turns it Y-up. sun_direction is given in world
        # coordinates (Mitsuba maps it to the local frame with the inverse of to_world).
        "sunsky": {"type": "sunsky", "to_world": T().rotate([1, 0, 0], -90),
                   "sun_direction": [float(x) for x in direction],
                   "turbidity": 3.0, "albedo": 0.3, "sun_scale": EXPOSURE, "sky_scale": EXPOSURE},
        "ground": {"type": "disk", "to_world": T().rotate([1, 0, 0], -90).scale(200.0),
                   "bsdf": diffuse([0.4, 0.38, 0.33])},
        "statue": {"type": "sphere", "center": [0.6, 0.5, 1.4], "radius": 0.5,
                   "bsdf": {"type": "roughconductor", "material": "Cu", "distribution": "ggx",
                            "alpha": 0.08}},
        "plinth": box((-0.4, 0.15, 2.0), (0.35, 0.15, 0.35), diffuse([0.7, 0.7, 0.68]), 10),
    }
    houses = (((-3.0, -1.0), (-2.5, -0.5), 1.6, [0.8, 0.75, 0.6]),
              ((-0.6, 1.2), (-3.0, -1.2), 2.0, [0.6, 0.65, 0.75]),
              ((1.8, 3.4), (-2.0, -0.4), 1.3, [0.85, 0.8, 0.7]))
    for k, ((x0, x1), (z0, z1), wall_height, color) in enumerate(houses):
        scene[f"house{k}"] = box(((x0 + x1) / 2, wall_height / 2, (z0 + z1) / 2),
                                 ((x1 - x0) / 2, wall_height / 2, (z1 - z0) / 2), diffuse(color))
        v, f = gable_roof(x0 - 0.1, x1 + 0.1, z0 - 0.1, z1 + 0.1, wall_height,
                          wall_height + 0.7)
        scene[f"roof{k}"] = mesh_from_arrays(v, f, bsdf=roof, name=f"roof{k}")
    for k in range(4):
        scene[f"column{k}"] = {"type": "cylinder", "p0": [-2.6 + 0.7 * k, 0, 1.0],
                               "p1": [-2.6 + 0.7 * k, 1.4, 1.0], "radius": 0.1,
                               "bsdf": diffuse([0.85, 0.83, 0.8])}
    return scene


SCENE = SceneSpec(
    description="physically based sun and sky: a tiny, extremely bright sun disc gives hard "
                "shadows and bright glints next to soft blue skylight in the shadows, a "
                "dynamic range that stresses denoisers' handling of outliers",
    category="environment", resolution=(128, 128), build=build)
