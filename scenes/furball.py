"""A ball of fur: a few thousand short, slightly bent fibres (``linearcurve``) with the ``hair``
BSDF radiating from a small sphere, lit by a soft area light and a dim constant sky."""

from __future__ import annotations

import numpy as np

from mcbench.render.curves import curve_shape, hair_bsdf
from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


FIBRES = 3000          # strands (render cost grows with the count; ~3000 keeps it cheap)
SEGMENTS = 4           # control points per strand
CORE_RADIUS = 0.45     # radius of the sphere the fur grows from (world units)
FIBRE_LENGTH = 0.28    # mean strand length
FIBRE_RADIUS = 0.006   # root radius; tips are thinner


def fibres(seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """Control points (FIBRES, SEGMENTS, 3) and radii (FIBRES, SEGMENTS) of the fur."""
    rng = np.random.default_rng(seed)
    root = rng.normal(size=(FIBRES, 3))
    root /= np.linalg.norm(root, axis=1, keepdims=True)
    # Each strand leaves the surface along the normal, bends a little sideways and droops.
    bend = rng.normal(scale=0.35, size=(FIBRES, 3))
    bend -= (bend * root).sum(1, keepdims=True) * root
    length = FIBRE_LENGTH * rng.uniform(0.7, 1.3, size=(FIBRES, 1))
    t = np.linspace(0.0, 1.0, SEGMENTS)[None, :, None]
    direction = root[:, None, :] + t * bend[:, None, :] + t ** 2 * np.array([0, -0.25, 0])
    steps = direction / np.linalg.norm(direction, axis=2, keepdims=True)
    steps = steps * (length / (SEGMENTS - 1))[:, None, :]
    points = CORE_RADIUS * 0.98 * root[:, None, :] + np.cumsum(steps, axis=1) - steps[:, :1]
    radii = FIBRE_RADIUS * np.linspace(1.0, 0.35, SEGMENTS)[None, :].repeat(FIBRES, axis=0)
    return points, radii


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 10 (light scatters
    several times between fibres before leaving the fur; hair BSDFs are mostly transmissive)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    points, radii = fibres()
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 10},
        "sensor": perspective_sensor(width, height, origin=(0.0, 0.5, 3.4),
                                     target=(0.0, 0.0, 0.0), fov=32.0),
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.12, 0.14, 0.18]}},
        "key_light": {
            "type": "rectangle",
            "to_world": T().look_at(origin=[-2.0, 2.5, 2.0], target=[0, 0, 0], up=[0, 1, 0])
                           .scale([0.8, 0.8, 1]),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [9.0, 8.5, 8.0]}},
        },
        "floor": {
            "type": "rectangle",
            "to_world": T().translate([0, -0.8, 0]).rotate([1, 0, 0], -90).scale([4, 4, 1]),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}},
        },
        "core": {
            "type": "sphere", "radius": CORE_RADIUS,
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.25, 0.15, 0.08]}},
        },
        "fur": curve_shape(points, radii, kind="linearcurve",
                           bsdf=hair_bsdf(eumelanin=0.6, pheomelanin=0.9, longitudinal=0.25,
                                          azimuthal=0.35)),
    }


SCENE = SceneSpec(
    description="sub-pixel fur fibres: thousands of thin strands with anisotropic hair "
                "scattering, heavy geometric aliasing and noisy multiple scattering inside the fur",
    category="hair/fur", resolution=(128, 128), build=build)
