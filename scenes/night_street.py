"""A street at night: asphalt, pavements and two rows of building facades with warm emissive
windows, lit by two street lamps (spot lights plus small glowing bulbs) under a dark sky."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 6 (diffuse street:
    the dark areas get a few bounces of lamp and window light)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    rng = np.random.default_rng(8)
    rgb = lambda *c: {"type": "rgb", "value": list(c)}  # noqa: E731
    facade = {"type": "diffuse", "reflectance": rgb(0.35, 0.3, 0.27)}
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 6},
        "sensor": perspective_sensor(width, height, origin=(0.6, 1.6, 7.0),
                                     target=(-0.2, 1.6, -4.0), fov=55.0),
        "sky": {"type": "constant", "radiance": rgb(0.004, 0.006, 0.012)},
        "road": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale([3.0, 14.0, 1]),
                 "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.3,
                          "diffuse_reflectance": rgb(0.06, 0.06, 0.065)}},
    }
    for side, x in (("left", -1), ("right", 1)):
        scene[f"pavement_{side}"] = {
            "type": "cube", "to_world": T().translate([x * 4.0, 0.075, 0]).scale([1.0, 0.075, 14.0]),
            "bsdf": {"type": "diffuse", "reflectance": rgb(0.3, 0.3, 0.3)}}
        scene[f"facade_{side}"] = {
            "type": "cube", "to_world": T().translate([x * 6.0, 5.0, 0]).scale([1.0, 5.0, 14.0]),
            "bsdf": facade}
        # Windows: three floors, eight per row; about 40 % lit with random warm colours.
        for floor in range(3):
            for k in range(8):
                z = -12.0 + 3.0 * k
                lit = rng.random() < 0.4
                name = f"window_{side}_{floor}_{k}"
                shape = {"type": "rectangle",
                         "to_world": T().translate([x * 4.99, 1.8 + 2.6 * floor, z])
                                        .rotate([0, 1, 0], -90 * x).scale([0.55, 0.7, 1])}
                if lit:
                    warmth = rng.uniform(0.6, 1.0)
                    shape["emitter"] = {"type": "area", "radiance": rgb(
                        *(rng.uniform(2.0, 6.0) * np.array([1.0, 0.75 * warmth + 0.1, 0.4 * warmth])))}
                else:
                    shape["bsdf"] = {"type": "plastic", "diffuse_reflectance": rgb(0.02, 0.02, 0.025)}  # dark glass
                scene[name] = shape
    for i, (x, z) in enumerate(((-2.8, 1.0), (2.8, -6.0))):
        sign = -1 if x < 0 else 1
        scene[f"lamp_pole_{i}"] = {"type": "cylinder", "radius": 0.06,
                                   "to_world": T().translate([x, 0.0, z]).rotate([1, 0, 0], -90).scale([1, 1, 4.0]),
                                   "bsdf": {"type": "roughconductor", "material": "Al", "alpha": 0.3}}
        scene[f"lamp_arm_{i}"] = {"type": "cylinder", "radius": 0.04,
                                  "to_world": T().translate([x, 4.0, z]).rotate([0, 1, 0], -90 * sign)
                                                 .scale([1, 1, 0.8]),
                                  "bsdf": {"type": "roughconductor", "material": "Al", "alpha": 0.3}}
        lamp = [x - sign * 0.8, 3.9, z]
        scene[f"lamp_bulb_{i}"] = {"type": "sphere", "center": lamp, "radius": 0.08,
                                   "emitter": {"type": "area", "radiance": rgb(80.0, 60.0, 30.0)}}
        scene[f"lamp_spot_{i}"] = {"type": "spot", "cutoff_angle": 55.0, "beam_width": 35.0,
                                   "to_world": T().look_at(origin=[lamp[0], 3.8, lamp[2]],
                                                           target=[lamp[0], 0.0, lamp[2]], up=[0, 0, 1]),
                                   "intensity": rgb(60.0, 45.0, 25.0)}
    return scene


SCENE = SceneSpec(
    description="night scene: high dynamic range (bright lamp bulbs and windows, pools of lamp "
                "light) with most of the image dark and lit only by faint indirect light",
    category="high dynamic range", resolution=(128, 128), build=build)
