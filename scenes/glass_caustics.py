"""A glass sphere and a rough gold cube on a diffuse floor, lit by one tiny bright sphere light."""

from __future__ import annotations

from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


LIGHT_POSITION = (1.7, 1.3, 0.7)    # world units; low on the right, so the caustic falls left
LIGHT_RADIUS = 0.15                 # world units: small enough for sharp caustics, large enough
                                    # that a 64k-spp reference converges (at 0.05 its noise
                                    # floor stayed above the best 1024-spp result)
LIGHT_RADIANCE = 100.0              # W/(m^2 sr); same power as radius 0.05 at 900


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height`` pixels; path tracer with ``max_depth`` 16
    (light must pass through the sphere: camera - floor - glass - glass - light is 4 bounces,
    internal reflections in the glass add more)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 16},
        "sensor": perspective_sensor(width, height, origin=(0.0, 1.7, 4.2),
                                     target=(0.0, 0.45, 0.0), fov=38.0),
        "floor": {
            "type": "rectangle",
            "to_world": T().rotate([1, 0, 0], -90).scale([4, 4, 1]),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.6, 0.58]}},
        },
        "back_wall": {
            "type": "rectangle",
            "to_world": T().translate([0, 2, -1.6]).scale([4, 2, 1]),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.55, 0.45, 0.35]}},
        },
        "glass_sphere": {
            "type": "sphere",
            "center": [-0.55, 0.55, 0.3],
            "radius": 0.55,
            "bsdf": {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0},
        },
        "gold_cube": {
            "type": "cube",
            "to_world": T().translate([0.85, 0.35, -0.3]).rotate([0, 1, 0], 35).scale(0.35),
            "bsdf": {"type": "roughconductor", "material": "Au", "distribution": "ggx",
                     "alpha": 0.12},
        },
        "small_light": {
            "type": "sphere",
            "center": list(LIGHT_POSITION),
            "radius": LIGHT_RADIUS,
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [LIGHT_RADIANCE] * 3}},
        },
    }


SCENE = SceneSpec(
    description="caustics through a glass sphere and specular-diffuse-specular paths from a tiny "
                "bright light: heavy-tailed noise and fireflies that unidirectional path tracing "
                "converges to slowly",
    category="glossy/glass", resolution=(128, 128), build=build)
