"""A row of objects receding from a thin-lens camera focused on the middle one; glossy and
metal spheres in the background give bright defocused highlights (bokeh)."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import bitmap_texture, box, diffuse, gradient_sky, quad, thinlens_sensor
from mcbench.contracts.scene import SceneSpec


CAMERA = (0.3, 1.3, 4.0)
FOCUS_TARGET = (0.0, 0.45, 0.0)   # the camera focuses on the middle object
APERTURE_RADIUS = 0.12            # world units: large, for strong blur


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 6."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    checks = (np.indices((2, 2)).sum(axis=0) % 2).astype(np.float32)
    floor = bitmap_texture(0.15 + 0.55 * checks[..., None] * np.array([1.0, 0.95, 0.85]),
                           filter_type="nearest", to_uv=T().scale([16, 16, 1]))
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 6},
        "sensor": thinlens_sensor(width, height, origin=CAMERA, target=FOCUS_TARGET, fov=40.0,
                                  aperture_radius=APERTURE_RADIUS),
        "sky": {"type": "envmap", "scale": 0.5, "bitmap": mi.Bitmap(gradient_sky(
            64, sun_elevation_deg=30.0, sun_azimuth_deg=-60.0, sun_radiance=150.0))},
        "light": quad((1.5, 3.0, 1.0), (0.4, 0, 0), (0, 0, 0.4),
                      emitter={"type": "area", "radiance": {"type": "rgb", "value": [30, 28, 25]}}),
        "floor": quad((0, 0, -2), (4, 0, 0), (0, 0, -6), diffuse(floor)),
        # Near (out of focus), middle (in focus), far (out of focus).
        "near_cube": box((-0.7, 0.25, 1.7), 0.25, diffuse([0.75, 0.2, 0.1]), rotate_y_deg=20),
        "near_sphere": {"type": "sphere", "center": [0.8, 0.2, 2.0], "radius": 0.2,
                        "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.05,
                                 "diffuse_reflectance": {"type": "rgb",
                                                         "value": [0.1, 0.3, 0.75]}}},
        "focus_sphere": {"type": "sphere", "center": [0.0, 0.45, 0.0], "radius": 0.45,
                         "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1,
                                  "diffuse_reflectance": {"type": "rgb",
                                                          "value": [0.8, 0.75, 0.2]}}},
        "focus_box": box((-0.9, 0.35, -0.2), (0.2, 0.35, 0.2), diffuse([0.8, 0.8, 0.78]), 35),
    }
    for k in range(6):
        x, z = -2.0 + 0.8 * k, -2.5 - 0.9 * k
        scene[f"far_sphere{k}"] = {"type": "sphere", "center": [x, 0.35, z], "radius": 0.35,
                                   "bsdf": {"type": "conductor", "material": ("Au", "Al")[k % 2]}}
    return scene


SCENE = SceneSpec(
    description="strong defocus blur from a wide thin-lens aperture: out-of-focus regions are "
                "noisy in colour and in every feature (normals and depth average over the lens), "
                "so feature-guided filters cannot separate blur from noise",
    category="camera", resolution=(128, 128), build=build)
