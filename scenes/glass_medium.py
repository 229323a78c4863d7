"""A glass sphere of milk and a glass cube of orange juice: dense, highly scattering media
behind dielectric boundaries, on a floor lit by one area light."""

from __future__ import annotations

from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; ``volpath`` with ``max_depth`` 16 (high-albedo media
    need many scattering events; Russian roulette trims the long paths)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    return {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": 16, "rr_depth": 6},
        "sensor": perspective_sensor(width, height, origin=(0.0, 1.5, 3.8),
                                     target=(0.0, 0.45, 0.0), fov=36.0),
        "milk": {"type": "homogeneous", "sigma_t": 8.0,
                 "albedo": {"type": "rgb", "value": [0.97, 0.96, 0.93]}},
        "juice": {"type": "homogeneous", "sigma_t": 4.0,
                  "albedo": {"type": "rgb", "value": [0.96, 0.6, 0.15]}},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale([4, 4, 1]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.55]}}},
        "back_wall": {"type": "rectangle", "to_world": T().translate([0, 2, -1.5]).scale([4, 2, 1]),
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.35, 0.4, 0.45]}}},
        "milk_sphere": {"type": "sphere", "center": [-0.6, 0.5, 0.0], "radius": 0.5,
                        "bsdf": {"type": "dielectric", "int_ior": 1.35},
                        "interior": {"type": "ref", "id": "milk"}},
        "juice_cube": {"type": "cube",
                       "to_world": T().translate([0.65, 0.4, -0.1]).rotate([0, 1, 0], 30).scale(0.4),
                       "bsdf": {"type": "dielectric", "int_ior": 1.35},
                       "interior": {"type": "ref", "id": "juice"}},
        "light": {"type": "rectangle",
                  "to_world": T().look_at(origin=[1.5, 2.8, 1.5], target=[0, 0, 0], up=[0, 1, 0])
                                 .scale(0.5),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [30.0] * 3}}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.08] * 3}},
    }


SCENE = SceneSpec(
    description="dense scattering media inside glass (milk, juice): subsurface-like transport with "
                "long volumetric random walks behind refracting boundaries, caustics on the floor",
    category="volume/glass", resolution=(128, 128), build=build)
