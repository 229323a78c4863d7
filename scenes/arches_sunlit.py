"""A colonnade interior: a hall of columns (cylinders) carrying stepped arches (boxes), closed
on three sides; sunlight enters only through the openings of the arcade on one side."""

from __future__ import annotations

from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


HALL = (6.0, 4.0, 12.0)    # width (x), height (y), length (z); floor at y = 0, centred in x and z
BAYS = 5                   # arcade openings on the sunlit (+x) side


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 10 (most of the
    hall is lit by light that has bounced off the sunlit floor patches several times)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    w, h, l = HALL
    stone = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.72, 0.66, 0.56]}}
    floor = {"type": "diffuse", "reflectance": {"type": "checkerboard",
             "color0": {"type": "rgb", "value": [0.6, 0.55, 0.48]},
             "color1": {"type": "rgb", "value": [0.35, 0.3, 0.26]}, "to_uv": T().scale([6, 12, 1])}}
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 10},
        "sensor": perspective_sensor(width, height, origin=(-2.2, 1.6, 5.3),
                                     target=(0.8, 1.4, -2.0), fov=65.0),
        "sun": {"type": "directional", "direction": [-0.75, -0.55, -0.35],
                "irradiance": {"type": "rgb", "value": [9.0, 8.0, 6.5]}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.35, 0.45, 0.7]}},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale([w / 2 + 3, l / 2 + 1, 1]),
                  "bsdf": floor},
        "ceiling": {"type": "cube", "to_world": T().translate([0, h + 0.15, 0]).scale([w / 2 + 0.5, 0.15, l / 2 + 0.5]),
                    "bsdf": stone},
        "wall_left": {"type": "cube", "to_world": T().translate([-w / 2 - 0.15, h / 2, 0]).scale([0.15, h / 2, l / 2]),
                      "bsdf": stone},
        "wall_back": {"type": "cube", "to_world": T().translate([0, h / 2, -l / 2 - 0.15]).scale([w / 2 + 0.3, h / 2, 0.15]),
                      "bsdf": stone},
        "wall_front": {"type": "cube", "to_world": T().translate([0, h / 2, l / 2 + 0.15]).scale([w / 2 + 0.3, h / 2, 0.15]),
                       "bsdf": stone},
        # Sunlit side: piers between the openings and a wall band above them.
        "arcade_band": {"type": "cube", "to_world": T().translate([w / 2 + 0.2, h - 0.5, 0]).scale([0.2, 0.5, l / 2]),
                        "bsdf": stone},
    }
    bay = l / BAYS
    for i in range(BAYS + 1):
        z = -l / 2 + i * bay
        scene[f"arcade_pier_{i}"] = {"type": "cube",
                                     "to_world": T().translate([w / 2 + 0.2, (h - 1.0) / 2, z]).scale([0.2, (h - 1.0) / 2, 0.35]),
                                     "bsdf": stone}
    for i in range(BAYS):
        z = -l / 2 + (i + 0.5) * bay
        # Stepped "arch" over each opening: two boxes narrowing the top corners.
        for j, (dy, dz) in enumerate(((0.25, bay / 2 - 0.35), (0.6, bay / 2 - 0.8))):
            for sign in (-1, 1):
                scene[f"arch_{i}_{j}_{'ab'[sign > 0]}"] = {
                    "type": "cube",
                    "to_world": T().translate([w / 2 + 0.2, h - 1.0 - dy / 2, z + sign * (bay / 2 - dz / 2 - 0.35 + dz / 2)])
                                   .scale([0.2, dy / 2, max(bay / 2 - 0.35 - dz, 0.05) / 2 + 0.2]),
                    "bsdf": stone}
        # A row of free-standing columns inside the hall, each with an arch-like lintel.
        scene[f"column_{i}"] = {"type": "cylinder", "radius": 0.22,
                                "to_world": T().translate([0.6, 0.0, z]).rotate([1, 0, 0], -90).scale([1, 1, h - 0.6]),
                                "bsdf": stone}
        scene[f"column_capital_{i}"] = {"type": "cube",
                                        "to_world": T().translate([0.6, h - 0.45, z]).scale([0.35, 0.15, 0.35]),
                                        "bsdf": stone}
    scene["inner_lintel"] = {"type": "cube", "to_world": T().translate([0.6, h - 0.15, 0]).scale([0.3, 0.15, l / 2]),
                             "bsdf": stone}
    return scene


SCENE = SceneSpec(
    description="sunlit interior lit mostly indirectly: small sharp sun patches, the rest of the "
                "hall lit by multi-bounce diffuse light and sky light through the arcade",
    category="diffuse/interior", resolution=(128, 128), build=build)
