"""Four spheres of different materials on a checkered floor, lit only by a procedural HDR
environment map (sky gradient plus a small, very bright sun)."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


SUN_ELEVATION_DEG = 38.0   # above the horizon
SUN_AZIMUTH_U = 0.917      # behind-left of the objects as seen by the camera: shadows point at it
SUN_RADIUS_DEG = 2.5       # angular radius (Gaussian sigma) of the sun blob
SUN_RADIANCE = 400.0       # peak radiance; sky ~1: the sun gives ~2x the sky irradiance


def sky_environment(height: int = 128, sun_radiance: float = SUN_RADIANCE) -> np.ndarray:
    """Lat-long HDR environment map, float32 (height, 2*height, 3), linear radiance.

    Row 0 is the zenith (+Y in Mitsuba's ``envmap``), the last row the nadir. Above the
    horizon a gradient from a bright whitish horizon to a blue zenith; below it a dim brown
    ground; plus a Gaussian sun blob at ``SUN_ELEVATION_DEG`` / ``SUN_AZIMUTH_U``.
    """
    width = 2 * height
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    elevation = (0.5 - v) * np.pi                           # radians, +pi/2 at the zenith
    up = np.clip(np.sin(elevation), 0.0, 1.0)[:, None] ** 0.5
    horizon = np.array([1.0, 0.95, 0.9])
    zenith = np.array([0.2, 0.35, 0.85])
    ground = np.array([0.22, 0.18, 0.14])
    sky = (1 - up[..., None]) * horizon + up[..., None] * zenith       # (H, 1, 3)
    env = np.where((elevation > 0)[:, None, None], sky, ground) * np.ones((1, width, 1))

    # Sun: Gaussian in angular distance from its direction on the unit sphere.
    theta = elevation[:, None]                 # (H, 1)
    phi = 2 * np.pi * u[None, :]               # (1, W)
    direction = np.stack(np.broadcast_arrays(np.cos(theta) * np.cos(phi), np.sin(theta),
                                             np.cos(theta) * np.sin(phi)), axis=-1)
    sun_theta = np.radians(SUN_ELEVATION_DEG)
    sun_phi = 2 * np.pi * SUN_AZIMUTH_U
    sun = np.array([np.cos(sun_theta) * np.cos(sun_phi), np.sin(sun_theta),
                    np.cos(sun_theta) * np.sin(sun_phi)])
    angle = np.arccos(np.clip(direction @ sun, -1.0, 1.0))
    blob = np.exp(-0.5 * (angle / np.radians(SUN_RADIUS_DEG)) ** 2)
    env = env + sun_radiance * blob[..., None] * np.array([1.0, 0.92, 0.8])
    return np.ascontiguousarray(env, dtype=np.float32)


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height`` pixels; path tracer with ``max_depth`` 12
    (the glass sphere needs several bounces to show what is behind it)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 12},
        "sensor": perspective_sensor(width, height, origin=(0.0, 1.8, 6.0),
                                     target=(0.0, 0.45, 0.0), fov=42.0),
        "environment": {"type": "envmap", "bitmap": mi.Bitmap(sky_environment()), "scale": 1.0},
        "floor": {
            "type": "disk",
            "to_world": T().rotate([1, 0, 0], -90).scale([6, 6, 1]),
            "bsdf": {"type": "diffuse", "reflectance": {
                "type": "checkerboard",
                "color0": {"type": "rgb", "value": [0.75, 0.75, 0.72]},
                "color1": {"type": "rgb", "value": [0.25, 0.25, 0.27]},
                "to_uv": T().scale([12, 12, 1])}},
        },
        "diffuse_sphere": {
            "type": "sphere", "center": [-1.65, 0.5, 0.0], "radius": 0.5,
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.15, 0.1]}},
        },
        "plastic_sphere": {
            "type": "sphere", "center": [-0.55, 0.5, 0.0], "radius": 0.5,
            "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.15,
                     "diffuse_reflectance": {"type": "rgb", "value": [0.1, 0.25, 0.7]}},
        },
        "metal_sphere": {
            "type": "sphere", "center": [0.55, 0.5, 0.0], "radius": 0.5,
            "bsdf": {"type": "roughconductor", "material": "Al", "distribution": "ggx",
                     "alpha": 0.15},
        },
        "glass_sphere": {
            "type": "sphere", "center": [1.65, 0.5, 0.0], "radius": 0.5,
            "bsdf": {"type": "dielectric", "int_ior": 1.5},
        },
    }


SCENE = SceneSpec(
    description="image-based lighting from a high-dynamic-range sky with a tiny sun: sharp sun "
                "shadows, sun glints on glossy and glass spheres, and textured floor detail",
    category="environment", resolution=(128, 128), build=build)
