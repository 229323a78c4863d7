"""A dark hall with 48 small coloured sphere lights hanging over glossy and diffuse objects."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import box, diffuse, perspective_sensor, quad
from mcbench.contracts.scene import SceneSpec


LIGHT_COUNT = 48
LIGHT_RADIUS = 0.04
LIGHT_POWER = 30.0          # radiance scale; each light's colour is a random hue


def light_colors(count: int, seed: int = 12) -> np.ndarray:
    """(count, 3) saturated random colours (seeded) with unit-ish luminance."""
    rng = np.random.default_rng(seed)
    hue = rng.random(count)
    rgb = np.clip(np.abs(((hue[:, None] * 6 + [0, 4, 2]) % 6) - 3) - 1, 0, 1)
    rgb = 0.25 + 0.75 * rgb
    return rgb / (rgb @ [0.2126, 0.7152, 0.0722])[:, None]


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 5."""
    rng = np.random.default_rng(13)
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 5},
        "sensor": perspective_sensor(width, height, origin=(0.0, 2.0, 4.8),
                                     target=(0.0, 0.6, 0.0), fov=50.0),
        "floor": quad((0, 0, 0), (4, 0, 0), (0, 0, -4),
                      {"type": "roughplastic", "distribution": "ggx", "alpha": 0.08,
                       "diffuse_reflectance": {"type": "rgb", "value": [0.3, 0.3, 0.32]}}),
        "back_wall": quad((0, 2, -2.5), (4, 0, 0), (0, 2, 0), diffuse([0.5, 0.5, 0.5])),
        "metal_sphere": {"type": "sphere", "center": [-0.9, 0.5, 0.0], "radius": 0.5,
                         "bsdf": {"type": "roughconductor", "material": "Al",
                                  "distribution": "ggx", "alpha": 0.1}},
        "white_sphere": {"type": "sphere", "center": [0.9, 0.5, -0.3], "radius": 0.5,
                         "bsdf": diffuse(0.8)},
        "pillar": box((0.0, 0.6, -0.9), (0.2, 0.6, 0.2), diffuse([0.7, 0.6, 0.45]), 30),
        "low_box": box((0.3, 0.15, 0.9), (0.4, 0.15, 0.25), diffuse([0.2, 0.45, 0.6]), -15),
    }
    colors = light_colors(LIGHT_COUNT)
    positions = np.column_stack([rng.uniform(-2.5, 2.5, LIGHT_COUNT),
                                 rng.uniform(1.3, 2.6, LIGHT_COUNT),
                                 rng.uniform(-2.2, 1.5, LIGHT_COUNT)])
    for k in range(LIGHT_COUNT):
        scene[f"light{k:02d}"] = {
            "type": "sphere", "center": [float(x) for x in positions[k]], "radius": LIGHT_RADIUS,
            "emitter": {"type": "area", "radiance": {
                "type": "rgb", "value": [float(c) * LIGHT_POWER for c in colors[k]]}}}
    return scene


SCENE = SceneSpec(
    description="many small emitters of different colours: next-event estimation picks one "
                "light per vertex, so each pixel sees a random subset, giving coloured noise, "
                "many overlapping soft shadows and small bright highlights",
    category="many-lights", resolution=(128, 128), build=build)
