"""Five tilted glass slabs stacked in depth in front of a colourful NumPy-textured backdrop,
lit by an area light: the backdrop is seen through long chains of specular refractions."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


PANES = 5


def backdrop_texture(size: int = 256, seed: int = 6) -> np.ndarray:
    """(size, size, 3) float32: coloured stripes crossed with a fine checkerboard."""
    rng = np.random.default_rng(seed)
    palette = rng.uniform(0.1, 0.9, (12, 3))
    u = np.arange(size) / size
    stripes = palette[(u * 12).astype(int)]                                  # (size, 3) along x
    checker = (((u[:, None] * 16).astype(int) + (u[None, :] * 16).astype(int)) % 2)[..., None]
    image = stripes[None, :, :] * (0.55 + 0.45 * checker)
    return np.ascontiguousarray(image, dtype=np.float32)


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 24 (5 slabs are 10
    interfaces one way; the light also has to reach the backdrop through them)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 24},
        "sensor": perspective_sensor(width, height, origin=(0.4, 1.1, 4.2),
                                     target=(0.0, 0.9, 0.0), fov=38.0),
        "backdrop": {"type": "rectangle",
                     "to_world": T().translate([0, 1.2, -1.6]).scale([2.4, 1.6, 1]),
                     "bsdf": {"type": "diffuse", "reflectance": {
                         "type": "bitmap", "bitmap": mi.Bitmap(backdrop_texture())}}},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale([4, 4, 1]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.45, 0.45, 0.45]}}},
        "light": {"type": "rectangle",
                  "to_world": T().look_at(origin=[0.5, 3.5, 3.0], target=[0, 0.8, -1.0], up=[0, 1, 0])
                                 .scale([1.2, 0.8, 1]),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [7.0, 7.0, 7.0]}}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.1, 0.1, 0.12]}},
    }
    for i in range(PANES):
        scene[f"glass_pane_{i}"] = {
            "type": "cube",
            "to_world": T().translate([-0.15 + 0.1 * i, 0.9 + 0.05 * i, 0.9 - 0.45 * i])
                           .rotate([0, 1, 0], -20 + 10 * i).rotate([1, 0, 0], 6 - 3 * i)
                           .scale([0.8 - 0.05 * i, 0.8 - 0.04 * i, 0.04]),
            "bsdf": {"type": "dielectric", "int_ior": 1.5 + 0.02 * i},
        }
    return scene


SCENE = SceneSpec(
    description="long specular chains: a backdrop seen through up to ten refracting glass "
                "interfaces, with internal reflections, displaced and doubled texture edges",
    category="glossy/glass", resolution=(128, 128), build=build)
