"""Five metal spheres and a brushed-looking panel of increasing roughness (alpha 0.01 to 0.5),
lit by an area light and a sky environment map."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import bitmap_texture, gradient_sky, perspective_sensor, quad
from mcbench.contracts.scene import SceneSpec


# (material, GGX alpha) of the spheres from left to right.
METALS = (("Au", 0.01), ("Cu", 0.05), ("Al", 0.12), ("Ag", 0.25), ("Cr", 0.5))


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 8
    (metal-metal interreflections between neighbouring spheres)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    checks = (np.indices((8, 8)).sum(axis=0) % 2).astype(np.float32)
    floor_tex = bitmap_texture(0.15 + 0.45 * checks[..., None] * np.array([1.0, 0.95, 0.9]),
                               filter_type="nearest", to_uv=T().scale([3, 3, 1]))
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "sensor": perspective_sensor(width, height, origin=(0.0, 1.9, 6.6),
                                     target=(0.0, 0.45, 0.0), fov=40.0),
        "sky": {"type": "envmap", "scale": 0.6,
                "bitmap": mi.Bitmap(gradient_sky(64, sun_elevation_deg=None)),
                "to_world": T().rotate([0, 1, 0], 30)},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale([5, 5, 1]),
                  "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.2,
                           "diffuse_reflectance": floor_tex}},
        "back_panel": {"type": "rectangle",
                       "to_world": T().translate([0, 0.7, -1.2]).scale([2.8, 0.7, 1]),
                       "bsdf": {"type": "roughconductor", "material": "Al",
                                "distribution": "ggx", "alpha_u": 0.03, "alpha_v": 0.3}},
        "light": quad((-1.5, 3.0, 1.5), (0.5, 0, 0), (0, 0.0, 0.5),
                      emitter={"type": "area", "radiance": {"type": "rgb", "value": [25, 24, 22]}}),
    }
    # quad((0,3,0), (0.5,0,0), (0,0,0.5)) faces -Y (u x v = -y): towards the floor.
    for i, (material, alpha) in enumerate(METALS):
        x = -2.0 + i * 1.0
        scene[f"sphere_{material}"] = {
            "type": "sphere", "center": [x, 0.42, 0.0], "radius": 0.42,
            "bsdf": {"type": "roughconductor", "material": material, "distribution": "ggx",
                     "alpha": alpha}}
    return scene


SCENE = SceneSpec(
    description="conductors from mirror-like (alpha 0.01) to rough (alpha 0.5): sharp reflections "
                "of the sky and the light, near-specular glints that stay noisy, and glossy "
                "blur whose width a denoiser must keep per material",
    category="glossy", resolution=(128, 128), build=build)
