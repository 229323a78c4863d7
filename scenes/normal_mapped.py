"""A bump-mapped brick wall, a normal-mapped rippled floor and a bumpy sphere, all from NumPy
height maps, lit by a grazing directional light and a dim sky."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import bitmap_texture, diffuse, perspective_sensor, quad
from mcbench.contracts.scene import SceneSpec


LIGHT_DIRECTION = (1.0, -0.22, -0.28)   # from the left, ~12 deg above the floor, grazing the wall


def brick_height(size: int = 256, rows: int = 8, cols: int = 4, seed: int = 3) -> np.ndarray:
    """(size, size) height in [0, 1]: raised bricks (running bond) with bevelled mortar grooves
    and a little seeded roughness."""
    y, x = (np.indices((size, size)) + 0.5) / size
    row = np.floor(y * rows)
    xs = x * cols + 0.5 * (row % 2)
    fy, fx = y * rows - row, xs - np.floor(xs)
    edge = np.minimum(np.minimum(fy, 1 - fy) / rows, np.minimum(fx, 1 - fx) / cols)
    height = np.clip(edge / 0.012, 0.0, 1.0)          # mortar ~ 1.2 % of the texture wide
    rng = np.random.default_rng(seed)
    return (0.85 * height + 0.15 * rng.random((size, size))).astype(np.float32)


def brick_albedo(height: np.ndarray, seed: int = 4) -> np.ndarray:
    """Brick colours varying per brick, light grey mortar where the height is low."""
    rng = np.random.default_rng(seed)
    size = height.shape[0]
    tint = np.kron(rng.uniform(0.7, 1.1, (8, 4)), np.ones((size // 8, size // 4)))
    brick = tint[..., None] * np.array([0.55, 0.22, 0.12])
    mortar = np.array([0.6, 0.58, 0.55])
    t = np.clip(height / 0.6, 0, 1)[..., None]
    return (t * brick + (1 - t) * mortar).astype(np.float32)


def ripple_normals(size: int = 256, amplitude: float = 0.02) -> np.ndarray:
    """(size, size, 3) tangent-space normal map in [0, 1] of circular ripples from two centres."""
    y, x = (np.indices((size, size)) + 0.5) / size
    height = np.zeros((size, size))
    for cx, cy, k in ((0.3, 0.4, 60.0), (0.75, 0.7, 45.0)):
        r = np.hypot(x - cx, y - cy)
        height += amplitude * np.sin(k * r) * np.exp(-2.5 * r)
    gy, gx = np.gradient(height, 1.0 / size)
    normal = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    return (0.5 * normal + 0.5).astype(np.float32)


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 5."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    bricks = brick_height()
    rng = np.random.default_rng(5)
    bumps = np.kron(rng.random((32, 64)), np.ones((4, 4))).astype(np.float32)
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 5},
        "sensor": perspective_sensor(width, height, origin=(0.3, 1.2, 3.4),
                                     target=(-0.1, 0.7, 0.0), fov=50.0),
        "sun": {"type": "directional", "direction": list(LIGHT_DIRECTION),
                "irradiance": {"type": "rgb", "value": [9.0, 8.1, 6.9]}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.08, 0.1, 0.14]}},
        "wall": quad((0, 1.5, -0.5), (2.5, 0, 0), (0, 1.5, 0),
                     {"type": "bumpmap", "scale": 0.8,
                      "height": bitmap_texture(bricks, to_uv=T().scale([2, 1.2, 1])),
                      "bsdf": diffuse(bitmap_texture(brick_albedo(bricks),
                                                     to_uv=T().scale([2, 1.2, 1])))}),
        "floor": quad((0, 0, 1.5), (2.5, 0, 0), (0, 0, -2.0),
                      {"type": "normalmap",
                       "normalmap": bitmap_texture(ripple_normals(), raw=True),
                       "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1,
                                "diffuse_reflectance": {"type": "rgb",
                                                        "value": [0.35, 0.4, 0.42]}}}),
        "bumpy_sphere": {"type": "sphere", "center": [0.6, 0.45, 0.6], "radius": 0.45,
                         "bsdf": {"type": "bumpmap", "scale": 0.4,
                                  "height": bitmap_texture(bumps),
                                  "bsdf": {"type": "roughconductor", "material": "Cu",
                                           "distribution": "ggx", "alpha": 0.15}}},
    }


SCENE = SceneSpec(
    description="shading detail from bump and normal maps under grazing light: the geometric "
                "normal feature is flat, so the relief exists only in the noisy colour and "
                "(partly) the shading-normal feature",
    category="texture", resolution=(128, 128), build=build)
