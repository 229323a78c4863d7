"""A dim room filled with thin homogeneous fog, lit only by a spot light shining through a
window in the left wall: visible light beams (single and multiple scattering in the fog)."""

from __future__ import annotations

from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


ROOM = (4.0, 3.0, 5.0)           # width (x), height (y), depth (z); floor at y = 0, centred in x/z
WINDOW = (-0.6, 0.6, 1.2, 2.3)   # window opening in the left wall: z0, z1, y0, y1
FOG_SIGMA_T = 0.12               # extinction per world unit (thin fog)
FOG_ALBEDO = 0.85


def _wall_with_window(T, x: float, bsdf: dict) -> dict:
    """The left wall (plane x = ``x``, facing +x) as four rectangles around the window."""
    w, h, d = ROOM
    z0, z1, y0, y1 = WINDOW
    pieces = {  # (z_min, z_max, y_min, y_max)
        "below": (-d / 2, d / 2, 0.0, y0), "above": (-d / 2, d / 2, y1, h),
        "front": (z1, d / 2, y0, y1), "back": (-d / 2, z0, y0, y1),
    }
    out = {}
    for name, (za, zb, ya, yb) in pieces.items():
        out[f"left_wall_{name}"] = {
            "type": "rectangle",
            "to_world": T().translate([x, (ya + yb) / 2, (za + zb) / 2]).rotate([0, 1, 0], 90)
                           .scale([(zb - za) / 2, (yb - ya) / 2, 1]),
            "bsdf": bsdf,
        }
    return out


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; volumetric path tracer (``volpath``) with
    ``max_depth`` 5: the beams are mostly single scattering, the room fill light needs a few more."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    w, h, d = ROOM
    white = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.7, 0.68]}}
    sensor = perspective_sensor(width, height, origin=(1.5, 1.4, 2.3), target=(-1.0, 0.9, -0.8),
                                fov=60.0)
    sensor["medium"] = {"type": "ref", "id": "fog"}
    scene = {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": 5},
        "fog": {"type": "homogeneous", "sigma_t": FOG_SIGMA_T,
                "albedo": {"type": "rgb", "value": [FOG_ALBEDO] * 3}},
        "sensor": sensor,
        # Invisible box holding the fog around room and light (null BSDF: only a medium boundary).
        "fog_volume": {"type": "cube", "to_world": T().translate([0, h / 2, 0]).scale([8, 6, 8]),
                       "bsdf": {"type": "null"}, "interior": {"type": "ref", "id": "fog"}},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale([w / 2, d / 2, 1]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.45, 0.35, 0.25]}}},
        "ceiling": {"type": "rectangle",
                    "to_world": T().translate([0, h, 0]).rotate([1, 0, 0], 90).scale([w / 2, d / 2, 1]),
                    "bsdf": white},
        "back_wall": {"type": "rectangle",
                      "to_world": T().translate([0, h / 2, -d / 2]).scale([w / 2, h / 2, 1]),
                      "bsdf": white},
        "right_wall": {"type": "rectangle",
                       "to_world": T().translate([w / 2, h / 2, 0]).rotate([0, 1, 0], -90)
                                      .scale([d / 2, h / 2, 1]),
                       "bsdf": white},
        "front_wall": {"type": "rectangle",
                       "to_world": T().translate([0, h / 2, d / 2]).rotate([0, 1, 0], 180)
                                      .scale([w / 2, h / 2, 1]),
                       "bsdf": white},
        "table": {"type": "cube", "to_world": T().translate([0.2, 0.4, -0.8]).scale([0.6, 0.4, 0.5]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.3, 0.2, 0.12]}}},
        # Spot light outside the window, shining down and into the room.
        "sun_spot": {"type": "spot",
                     "to_world": T().look_at(origin=[-w / 2 - 2.0, 3.6, 0.3],
                                             target=[0.6, 0.0, -0.4], up=[0, 1, 0]),
                     "cutoff_angle": 25.0, "beam_width": 18.0,
                     "intensity": {"type": "rgb", "value": [300.0, 270.0, 220.0]}},
    }
    scene.update(_wall_with_window(T, -w / 2, white))
    return scene


SCENE = SceneSpec(
    description="volumetric light beams through a window in a foggy room: participating-medium "
                "noise everywhere along camera rays, and a mostly indirectly lit interior",
    category="volume", resolution=(128, 128), build=build)
