"""A stage with three coloured spot lights of different cone widths and a soft area light,
casting sharp and soft shadows of a sphere, a cube, a thin pole and a perforated screen."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import bitmap_texture, box, diffuse, perspective_sensor, quad
from mcbench.contracts.scene import SceneSpec


SPOTS = (  # position, target, cutoff angle (deg), beam width (deg), colour * intensity
    ((-2.0, 3.0, 2.0), (-0.4, 0.0, 0.0), 30.0, 25.0, (90.0, 40.0, 15.0)),
    ((2.2, 2.6, 1.5), (0.6, 0.0, -0.4), 22.0, 12.0, (15.0, 35.0, 90.0)),
    ((0.0, 4.0, -0.5), (0.0, 0.0, 0.0), 40.0, 30.0, (14.0, 14.0, 12.0)),
)


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 4 (mostly
    direct light)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    holes = np.ones((64, 64), dtype=np.float32)
    y, x = np.indices((64, 64)) % 16
    holes[(x - 7.5) ** 2 + (y - 7.5) ** 2 < 25] = 0.0          # a grid of round holes
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 4},
        "sensor": perspective_sensor(width, height, origin=(0.0, 2.2, 4.5),
                                     target=(0.0, 0.5, -0.3), fov=48.0),
        "floor": quad((0, 0, 0), (4, 0, 0), (0, 0, -4), diffuse(0.7)),
        "back_wall": quad((0, 2, -1.8), (4, 0, 0), (0, 2, 0), diffuse([0.6, 0.6, 0.58])),
        "soft_light": quad((-2.5, 2.0, -0.5), (0, 0.5, 0), (0, 0, 0.5),
                           emitter={"type": "area",
                                    "radiance": {"type": "rgb", "value": [3.0, 2.8, 2.5]}}),
        "sphere": {"type": "sphere", "center": [-0.6, 0.35, 0.3], "radius": 0.35,
                   "bsdf": diffuse([0.8, 0.8, 0.8])},
        "cube": box((0.7, 0.3, 0.2), 0.3, diffuse([0.6, 0.55, 0.5]), rotate_y_deg=40),
        "pole": {"type": "cylinder", "p0": [0.1, 0, 0.9], "p1": [0.1, 1.4, 0.9], "radius": 0.025,
                 "bsdf": diffuse([0.3, 0.3, 0.3])},
        "screen": quad((0.3, 0.8, -0.9), (0.5, 0, 0.1), (0, 0.35, 0),
                       {"type": "mask", "opacity": bitmap_texture(holes, filter_type="nearest"),
                        "bsdf": {"type": "twosided", "bsdf": diffuse([0.7, 0.6, 0.3])}}),
    }
    # quad with u = (0, .5, 0), v = (0, 0, .5) faces +x: the soft light shines to the right.
    for k, (position, target, cutoff, beam, intensity) in enumerate(SPOTS):
        scene[f"spot{k}"] = {"type": "spot", "cutoff_angle": cutoff, "beam_width": beam,
                             "to_world": T().look_at(origin=list(position), target=list(target),
                                                     up=[0, 1, 0]),
                             "intensity": {"type": "rgb", "value": list(intensity)}}
    return scene


SCENE = SceneSpec(
    description="hard shadows from point-like spot lights next to soft penumbrae from an area "
                "light, and sharp spot-cone falloff edges: denoisers must keep crisp shadow and "
                "cone boundaries that no feature buffer shows",
    category="direct", resolution=(128, 128), build=build)
