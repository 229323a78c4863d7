"""A dark closed room lit only through two small windows by a sky with a bright sun; sun
patches on the floor are thousands of times brighter than the dim corners."""

from __future__ import annotations

from mcbench.render.geometry import box, diffuse, gradient_sky, perspective_sensor, quad
from mcbench.contracts.scene import SceneSpec


ROOM = (2.0, 2.4, 2.0)                       # half width, height, half depth
WINDOWS = ((-1.2, -0.6), (0.4, 1.0))          # x ranges of the two windows in the wall z = -2
WINDOW_Y = (1.0, 1.7)
SUN_DIRECTION = (0.25, -0.55, 0.8)            # light travels into the room (towards +z)


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 8."""
    import mitsuba as mi

    hx, hy, hz = ROOM
    wall = {"type": "twosided", "bsdf": diffuse([0.6, 0.58, 0.55])}
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "sensor": perspective_sensor(width, height, origin=(1.5, 1.4, 1.8),
                                     target=(-0.6, 0.7, -1.2), fov=65.0),
        "sky": {"type": "envmap", "scale": 2.0,
                "bitmap": mi.Bitmap(gradient_sky(64, zenith=(0.3, 0.5, 1.0)))},
        "sun": {"type": "directional", "direction": list(SUN_DIRECTION),
                "irradiance": {"type": "rgb", "value": [30.0, 27.0, 22.0]}},
        "floor": quad((0, 0, 0), (hx, 0, 0), (0, 0, -hz), diffuse([0.35, 0.25, 0.18])),
        "ceiling": quad((0, hy, 0), (hx, 0, 0), (0, 0, hz), wall),
        "wall_left": quad((-hx, hy / 2, 0), (0, 0, -hz), (0, hy / 2, 0), wall),
        "wall_right": quad((hx, hy / 2, 0), (0, 0, hz), (0, hy / 2, 0), wall),
        "wall_front": quad((0, hy / 2, hz), (-hx, 0, 0), (0, hy / 2, 0), wall),
        "sofa": box((-1.2, 0.3, 0.6), (0.5, 0.3, 0.9), diffuse([0.25, 0.3, 0.45])),
        "table": box((0.2, 0.4, -0.2), (0.45, 0.03, 0.45), diffuse([0.45, 0.3, 0.18])),
        "table_leg": {"type": "cylinder", "p0": [0.2, 0, -0.2], "p1": [0.2, 0.38, -0.2],
                      "radius": 0.05, "bsdf": diffuse([0.2, 0.2, 0.2])},
        "vase": {"type": "sphere", "center": [0.2, 0.58, -0.2], "radius": 0.15,
                 "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1,
                          "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.1, 0.1]}}},
        "cabinet": box((1.5, 0.6, -1.6), (0.4, 0.6, 0.3), diffuse([0.5, 0.45, 0.4])),
    }
    # Window wall z = -hz: solid strips around two openings.
    (a0, a1), (b0, b1) = WINDOWS
    y0, y1 = WINDOW_Y
    pieces = [((-hx, a0), (0, hy)), ((a1, b0), (0, hy)), ((b1, hx), (0, hy)),
              ((a0, a1), (0, y0)), ((a0, a1), (y1, hy)), ((b0, b1), (0, y0)), ((b0, b1), (y1, hy))]
    for k, ((xa, xb), (ya, yb)) in enumerate(pieces):
        scene[f"window_wall{k}"] = quad(((xa + xb) / 2, (ya + yb) / 2, -hz), ((xb - xa) / 2, 0, 0),
                                        (0, (yb - ya) / 2, 0), wall)
    return scene


SCENE = SceneSpec(
    description="high dynamic range interior: small windows admit a sun and sky that next-event "
                "estimation mostly misses, so the dim room is lit by rare, very bright paths "
                "(fireflies) around sharp sunlit patches",
    category="indirect", resolution=(128, 128), build=build)
