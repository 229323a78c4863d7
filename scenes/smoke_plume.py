"""A rising smoke plume: a heterogeneous medium whose density comes from a procedural NumPy grid
(``gridvolume``), lit by a low sun (directional light) and a sky, over a floor."""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


GRID = (48, 32, 32)        # grid cells (y, z, x) -> NumPy shape (z, y, x) below, see density()
DENSITY_SCALE = 7.0        # peak extinction per world unit
BOX = (1.6, 2.4, 1.6)      # world size of the medium's bounding box (x, y, z), bottom at y = 0


def _smooth_noise(rng, shape, cells) -> np.ndarray:
    """Value noise: a coarse random lattice upsampled trilinearly to ``shape``."""
    coarse = rng.random(tuple(c + 2 for c in cells))
    axes = [np.linspace(0, c, s) for c, s in zip(cells, shape)]
    out = coarse
    for axis, coords in enumerate(axes):
        i = np.floor(coords).astype(int)
        f = (coords - i).reshape([-1 if a == axis else 1 for a in range(3)])
        out = (np.take(out, i, axis=axis) * (1 - f) + np.take(out, i + 1, axis=axis) * f)
    return out


def density(seed: int = 3) -> np.ndarray:
    """Density in [0, 1], float32 of shape (nz, ny, nx) as ``mi.VolumeGrid`` expects (x fastest).

    A column that widens and drifts sideways as it rises, modulated by two octaves of value noise.
    """
    rng = np.random.default_rng(seed)
    ny, nz, nx = GRID
    z, y, x = np.meshgrid(np.linspace(0, 1, nz), np.linspace(0, 1, ny), np.linspace(0, 1, nx),
                          indexing="ij")
    centre_x = 0.5 + 0.18 * np.sin(2.5 * y) * y
    centre_z = 0.5 + 0.08 * y
    width = 0.06 + 0.22 * y
    r2 = ((x - centre_x) ** 2 + (z - centre_z) ** 2) / width ** 2
    shape = (nz, ny, nx)
    noise = 0.65 * _smooth_noise(rng, shape, (4, 6, 4)) + 0.35 * _smooth_noise(rng, shape, (10, 14, 10))
    rho = np.exp(-1.5 * r2) * np.clip(2.2 * noise - 0.5, 0, None)
    rho *= np.clip(1.3 - y, 0, 1) * np.clip(y * 12, 0, 1)          # fade out at top and bottom
    return np.ascontiguousarray(np.clip(rho / rho.max(), 0, 1), dtype=np.float32)


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; ``volpath`` with ``max_depth`` 6 (grey smoke of
    albedo 0.8 keeps ~26 % of its energy after 6 scattering events)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    bx, by, bz = BOX
    box = T().translate([-bx / 2, 0.0, -bz / 2]).scale([bx, by, bz])   # unit cube [0,1]^3 -> box
    return {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": 6},
        "sensor": perspective_sensor(width, height, origin=(0.0, 1.3, 4.2),
                                     target=(0.0, 1.05, 0.0), fov=42.0),
        "smoke": {"type": "heterogeneous",
                  "sigma_t": {"type": "gridvolume", "grid": mi.VolumeGrid(density()), "to_world": box},
                  "scale": DENSITY_SCALE,
                  "albedo": {"type": "rgb", "value": [0.8, 0.8, 0.8]}},
        "smoke_box": {"type": "cube", "to_world": box @ T().translate([0.5, 0.5, 0.5]).scale(0.5),
                      "bsdf": {"type": "null"}, "interior": {"type": "ref", "id": "smoke"}},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale([5, 5, 1]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "checkerboard",
                           "color0": {"type": "rgb", "value": [0.6, 0.6, 0.6]},
                           "color1": {"type": "rgb", "value": [0.3, 0.3, 0.3]},
                           "to_uv": T().scale([10, 10, 1])}}},
        "sun": {"type": "directional", "direction": [-0.7, -0.45, -0.4],
                "irradiance": {"type": "rgb", "value": [3.2, 2.9, 2.5]}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.18, 0.22, 0.3]}},
    }


SCENE = SceneSpec(
    description="heterogeneous smoke from a NumPy density grid: delta-tracking noise, wispy "
                "detail, self-shadowing and multiple scattering with sharp sun shadows",
    category="volume", resolution=(128, 128), build=build)
