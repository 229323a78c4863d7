"""A closed room lit only through a door left ajar (after Veach's "ajar door" scene): a bright
light in a small vestibule outside, a white glossy teapot on a table inside."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import box, diffuse, lathe, mesh_from_arrays, perspective_sensor, quad, torus
from mcbench.contracts.scene import SceneSpec


ROOM = (2.0, 2.6, 2.0)        # half width (x), height (y), half depth (z); door wall at z = -2
DOOR = (0.2, 1.2, 2.0)        # door opening: x from 0.2 to 1.2, y from 0 to 2.0
DOOR_ANGLE_DEG = 10.0         # how far the door is open (into the vestibule, hinge at x = 0.2)
LIGHT_RADIANCE = 400.0


def teapot(center, scale, bsdf) -> list:
    """Teapot-like meshes: lathe body and lid, torus handle, tapered spout (cylinder)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    t = np.linspace(0.0, 1.0, 14)
    body_r = 0.55 * np.sin(np.pi * (0.12 + 0.8 * t)) + 0.08
    body_y = 0.75 * t
    v, f, n, uv = lathe(np.append(body_r, [0.16, 0.05, 0.0]),
                        np.append(body_y, [0.83, 0.9, 0.92]), segments=28)
    place = T().translate(list(center)).scale(scale)
    parts = [mesh_from_arrays(v, f, n, uv, bsdf=bsdf, name="teapot_body", to_world=place)]
    v, f, n, uv = torus(0.22, 0.05, segments=12, ring_segments=8, arc=np.pi)
    handle = place @ T().translate([-0.5, 0.4, 0.0]).rotate([1, 0, 0], 90).rotate([0, 0, 1], 90)
    parts.append(mesh_from_arrays(v, f, n, uv, bsdf=bsdf, name="teapot_handle", to_world=handle))
    spout = {"type": "cylinder", "p0": [0.45, 0.3, 0.0], "p1": [0.85, 0.7, 0.0], "radius": 0.06,
             "to_world": place, "bsdf": bsdf}
    parts.append(spout)
    return parts


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 8 (light
    reaches the visible room only after 2-4 diffuse bounces)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    hx, hy, hz = ROOM
    x0, x1, door_top = DOOR
    wall = {"type": "twosided", "bsdf": diffuse([0.7, 0.68, 0.62])}
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "sensor": perspective_sensor(width, height, origin=(-1.5, 1.6, 1.85),
                                     target=(0.3, 0.8, -1.2), fov=62.0),
        # Room: rectangles facing inwards.
        "floor": quad((0, 0, 0), (hx, 0, 0), (0, 0, -hz), diffuse([0.45, 0.33, 0.22])),
        "ceiling": quad((0, hy, 0), (hx, 0, 0), (0, 0, hz), wall),
        "wall_left": quad((-hx, hy / 2, 0), (0, 0, -hz), (0, hy / 2, 0), wall),
        "wall_right": quad((hx, hy / 2, 0), (0, 0, hz), (0, hy / 2, 0), wall),
        "wall_front": quad((0, hy / 2, hz), (-hx, 0, 0), (0, hy / 2, 0), wall),
        # Door wall (z = -hz) with an opening: left part, right part, lintel above the door.
        "wall_door_left": quad(((x0 - hx) / 2, hy / 2, -hz), ((x0 + hx) / 2, 0, 0),
                               (0, hy / 2, 0), wall),
        "wall_door_right": quad(((x1 + hx) / 2, hy / 2, -hz), ((hx - x1) / 2, 0, 0),
                                (0, hy / 2, 0), wall),
        "wall_lintel": quad(((x0 + x1) / 2, (door_top + hy) / 2, -hz), ((x1 - x0) / 2, 0, 0),
                            (0, (hy - door_top) / 2, 0), wall),
        # The door: a thin slab hinged at x = x0, opened slightly into the vestibule.
        "door": {"type": "cube", "bsdf": diffuse([0.5, 0.35, 0.2]),
                 "to_world": T().translate([x0, 0, -hz - 0.03]).rotate([0, 1, 0], DOOR_ANGLE_DEG)
                 .translate([(x1 - x0) / 2, door_top / 2, 0])
                 .scale([(x1 - x0) / 2 - 0.01, door_top / 2 - 0.01, 0.025])},
        # Vestibule behind the door wall: closed box, bright ceiling panel.
        "vest_floor": quad(((x0 + x1) / 2, 0, -hz - 0.8), (1.2, 0, 0), (0, 0, -0.8), wall),
        "vest_back": quad(((x0 + x1) / 2, hy / 2, -hz - 1.6), (1.2, 0, 0), (0, hy / 2, 0), wall),
        "vest_left": quad(((x0 + x1) / 2 - 1.2, hy / 2, -hz - 0.8), (0, 0, -0.8), (0, hy / 2, 0),
                          wall),
        "vest_right": quad(((x0 + x1) / 2 + 1.2, hy / 2, -hz - 0.8), (0, 0, 0.8),
                           (0, hy / 2, 0), wall),
        "vest_light": quad(((x0 + x1) / 2, hy - 0.01, -hz - 1.0), (0.6, 0, 0), (0, 0, 0.4),
                           emitter={"type": "area", "radiance": {
                               "type": "rgb", "value": [LIGHT_RADIANCE, 0.9 * LIGHT_RADIANCE,
                                                        0.75 * LIGHT_RADIANCE]}}),
        "vest_ceiling": quad(((x0 + x1) / 2, hy, -hz - 0.8), (1.2, 0, 0), (0, 0, 0.8), wall),
        # Furniture: a table with the teapot, a chair-like block.
        "table_top": box((-0.3, 0.72, -0.2), (0.7, 0.03, 0.45), diffuse([0.35, 0.22, 0.12])),
        "table_base": {"type": "cylinder", "p0": [-0.3, 0, -0.2], "p1": [-0.3, 0.7, -0.2],
                       "radius": 0.08, "bsdf": diffuse([0.2, 0.15, 0.1])},
        "block": box((1.3, 0.35, 0.9), (0.35, 0.35, 0.35), diffuse([0.3, 0.4, 0.55]), 25.0),
    }
    glossy_white = {"type": "roughplastic", "distribution": "ggx", "alpha": 0.08,
                    "diffuse_reflectance": {"type": "rgb", "value": [0.85, 0.85, 0.85]}}
    for i, part in enumerate(teapot((-0.3, 0.75, -0.2), 0.55, glossy_white)):
        scene[f"teapot_{i}"] = part
    return scene


SCENE = SceneSpec(
    description="light enters only through a narrow door gap: almost all of the room is lit by "
                "multi-bounce indirect light that next-event estimation cannot reach, giving "
                "very noisy, slowly converging diffuse and glossy interreflection",
    category="indirect", resolution=(128, 128), build=build)
