"""Curly hair: helical B-spline ringlets (drawn as fine ``linearcurve`` polylines) with the ``hair`` BSDF hanging from a head-like
sphere, lit by a rectangular area light and a NumPy sky environment map."""

from __future__ import annotations

import numpy as np

from mcbench.render.curves import bspline_polyline, curve_shape, hair_bsdf
from mcbench.render.geometry import perspective_sensor
from mcbench.contracts.scene import SceneSpec


STRANDS = 450           # hair strands
POINTS = 28             # B-spline control points per strand
HEAD_RADIUS = 0.5
HANG_LENGTH = 0.9       # length below the equator of the head
CURL_RADIUS = 0.045     # helix radius of a ringlet
CURL_TURNS = 5.0
STRAND_RADIUS = 0.0045


def sky(height: int = 32) -> np.ndarray:
    """Small lat-long sky map (height, 2*height, 3): bluish above, warm dim ground below."""
    v = (np.arange(height) + 0.5) / height
    up = np.clip(np.cos(np.pi * v), -1, 1)[:, None, None]
    top = np.array([0.35, 0.45, 0.7])
    horizon = np.array([0.8, 0.75, 0.7])
    ground = np.array([0.15, 0.12, 0.1])
    env = np.where(up > 0, (1 - up) * horizon + up * top, ground)
    return np.ascontiguousarray(np.broadcast_to(env, (height, 2 * height, 3)), dtype=np.float32)


def strands(seed: int = 11) -> list[np.ndarray]:
    """Control points of each strand: over the scalp to the head's equator, then hanging down,
    wound around its centre line as a helix with a random phase and slightly random radius."""
    rng = np.random.default_rng(seed)
    # Roots on the upper back of the head (away from the camera at +z, so the face side is bare).
    phi = rng.uniform(0.0, 2 * np.pi, STRANDS)
    theta0 = np.arccos(rng.uniform(0.35, 1.0, STRANDS))             # polar angle of the root
    t = np.linspace(0.0, 1.0, POINTS)[None, :]
    split = 0.3                                                      # first 30 %: over the scalp
    over = np.clip(t / split, 0, 1)
    theta = theta0[:, None] + over * (np.pi / 2 - theta0[:, None])
    r = HEAD_RADIUS + 0.015
    base = np.stack([r * np.sin(theta) * np.cos(phi)[:, None], r * np.cos(theta),
                     r * np.sin(theta) * np.sin(phi)[:, None]], axis=-1)
    drop = np.clip((t - split) / (1 - split), 0, 1) * HANG_LENGTH * rng.uniform(0.7, 1.1, (STRANDS, 1))
    base[..., 1] -= drop
    # Helix around the hanging part: in the plane spanned by the radial and tangential directions.
    radial = np.stack([np.cos(phi), np.zeros_like(phi), np.sin(phi)], axis=-1)[:, None, :]
    tangent = np.stack([-np.sin(phi), np.zeros_like(phi), np.cos(phi)], axis=-1)[:, None, :]
    phase = rng.uniform(0, 2 * np.pi, (STRANDS, 1))
    angle = phase + 2 * np.pi * CURL_TURNS * t
    amplitude = CURL_RADIUS * rng.uniform(0.7, 1.3, (STRANDS, 1)) * np.clip(
        (t - split * 0.7) / 0.2, 0, 1)
    offset = amplitude[..., None] * (np.cos(angle)[..., None] * tangent
                                     + (1 + np.sin(angle))[..., None] * radial)
    points = base + offset + np.array([0.0, 0.3, 0.0])
    return list(points)


def build(width: int, height: int) -> dict:
    """Scene dict at ``width`` x ``height``; path tracer with ``max_depth`` 8 (blond hair
    transmits most light: many fibre-to-fibre bounces carry visible energy)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "sensor": perspective_sensor(width, height, origin=(1.9, 0.5, -2.2),
                                     target=(0.0, 0.0, 0.0), fov=40.0),
        "environment": {"type": "envmap", "bitmap": mi.Bitmap(sky()), "scale": 0.6},
        "key_light": {
            "type": "rectangle",
            "to_world": T().look_at(origin=[2.5, 2.5, -1.0], target=[0, 0.2, 0], up=[0, 1, 0])
                           .scale([0.6, 0.6, 1]),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [14.0, 13.0, 12.0]}},
        },
        "head": {
            "type": "sphere", "center": [0.0, 0.3, 0.0], "radius": HEAD_RADIUS,
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.45, 0.38]}},
        },
        "floor": {
            "type": "rectangle",
            "to_world": T().translate([0, -0.9, 0]).rotate([1, 0, 0], -90).scale([5, 5, 1]),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.4, 0.4, 0.42]}},
        },
        # The helices are B-spline control polygons, evaluated in NumPy and drawn as linear
        # segments: Mitsuba 3.9.1's ``bsplinecurve`` segfaulted on these strands at some seeds.
        "hair": curve_shape(bspline_polyline(np.array(strands()), 2), STRAND_RADIUS,
                            kind="linearcurve",
                            bsdf=hair_bsdf(eumelanin=0.2, pheomelanin=0.5, longitudinal=0.2,
                                           azimuthal=0.3)),
    }


SCENE = SceneSpec(
    description="curly blond hair: thin helical strands with glossy, anisotropic hair highlights "
                "and long transmissive multiple-scattering paths under env-map and area light",
    category="hair/fur", resolution=(128, 128), build=build)
