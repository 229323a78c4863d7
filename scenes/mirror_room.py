"""A room with a full mirror wall and a glossy floor reflecting diffuse objects, lit by a
ceiling panel."""

from __future__ import annotations

from mcbench.render.geometry import box, diffuse, perspective_sensor, quad
from mcbench.contracts.scene import SceneSpec


ROOM = (2.0, 2.5, 2.0)     # half width, height, half depth; the mirror is the wall at x = +2


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 8
    (camera - mirror - floor - object - light needs 4 bounces before the light)."""
    hx, hy, hz = ROOM
    wall = {"type": "twosided", "bsdf": diffuse([0.65, 0.63, 0.6])}
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "sensor": perspective_sensor(width, height, origin=(-1.7, 1.5, 1.8),
                                     target=(1.0, 0.6, -0.6), fov=60.0),
        "floor": quad((0, 0, 0), (hx, 0, 0), (0, 0, -hz),
                      {"type": "roughplastic", "distribution": "ggx", "alpha": 0.06,
                       "diffuse_reflectance": {"type": "rgb", "value": [0.25, 0.2, 0.16]}}),
        "ceiling": quad((0, hy, 0), (hx, 0, 0), (0, 0, hz), wall),
        "wall_left": quad((-hx, hy / 2, 0), (0, 0, -hz), (0, hy / 2, 0),
                          {"type": "twosided", "bsdf": diffuse([0.2, 0.35, 0.6])}),
        "mirror": quad((hx, hy / 2, 0), (0, 0, hz), (0, hy / 2, 0),
                       {"type": "conductor", "material": "Ag"}),
        "wall_back": quad((0, hy / 2, -hz), (hx, 0, 0), (0, hy / 2, 0), wall),
        "wall_front": quad((0, hy / 2, hz), (-hx, 0, 0), (0, hy / 2, 0), wall),
        "light": quad((0, hy - 0.01, 0), (0.5, 0, 0), (0, 0, 0.5),
                      emitter={"type": "area", "radiance": {"type": "rgb", "value": [14, 13, 12]}}),
        "red_cube": box((0.6, 0.35, -0.8), 0.35, diffuse([0.7, 0.12, 0.1]), rotate_y_deg=30),
        "green_sphere": {"type": "sphere", "center": [-0.2, 0.4, 0.4], "radius": 0.4,
                         "bsdf": diffuse([0.15, 0.6, 0.2])},
        "yellow_cylinder": {"type": "cylinder", "p0": [1.2, 0.0, 0.6], "p1": [1.2, 1.1, 0.6],
                            "radius": 0.22, "bsdf": diffuse([0.8, 0.65, 0.1])},
        "cylinder_cap": {"type": "disk", "bsdf": diffuse([0.8, 0.65, 0.1]),
                         "to_world": __import__("mitsuba").ScalarTransform4f()
                         .translate([1.2, 1.1, 0.6]).rotate([1, 0, 0], -90).scale(0.22)},
        "tall_box": box((-1.2, 0.7, -1.3), (0.3, 0.7, 0.3), diffuse([0.75, 0.75, 0.72]),
                        rotate_y_deg=-20),
    }


SCENE = SceneSpec(
    description="specular paths: a mirror wall doubles the room, a glossy floor smears "
                "reflections; reflected objects have the mirror's features (normal, depth) but "
                "their own shading, so feature-guided denoisers over-blur them",
    category="specular", resolution=(128, 128), build=build)
