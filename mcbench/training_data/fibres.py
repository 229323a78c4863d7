"""Clumps of thin fibres added to the fibre family of training scenes.

Fibre scenes (seeds from :data:`mcbench.render.seeds.FIBRE_SEED_BASE`, 32768, on) draw the same kind
of scene as the object family and then add 1-2 clumps of thin fibres
(:func:`add_fibre_clumps`, from a second stream ``default_rng((FIBRE_SALT, seed))``): a fur
ball (strands radiating from a core sphere), a tuft (strands growing up from a disc) or a
fringe (strands hanging from a bar), 600-2500 strands each as a ``linearcurve``, strand radius
0.1-0.6 pixel at 128 pixels across (so mostly sub-pixel), with the ``hair`` BSDF (melanin from
blond to black, 75 %) or a dark diffuse / random BSDF. The first clump sits where the camera
looks and fills about half the frame. They exist because the albedo AOV of such fibres is
tiny, noisy and unrelated to their (mostly specular) radiance: the first networks, trained on
the object family alone, failed on the test scene ``furball`` (see README, learned
denoisers). The fibre scenes use their own seeds, so adding them changed no object-family
scene; ``training.fibre_count`` in the config sets how many are rendered.
"""

from __future__ import annotations

import numpy as np

from mcbench.render.curves import curve_shape, hair_bsdf
from mcbench.render.geometry import rgb
from mcbench.training_data.materials import random_material

__all__ = ["FIBRE_SALT", "FIBRE_REFERENCE_WIDTH", "add_fibre_clumps"]

FIBRE_SALT = 0x0F1B4E55         # mixed into the fibre RNG so fibre streams are their own
FIBRE_REFERENCE_WIDTH = 128     # strand radii are drawn in pixels of a 128-pixel-wide film


def _fibre_bsdf(rng: np.random.Generator) -> dict:
    """Hair BSDF (75 %: eumelanin log-uniform 0.05..8, blond to black), dark diffuse (15 %) or a
    random material (10 %, dielectrics replaced by diffuse: curves have no inside)."""
    u = rng.random()
    if u < 0.75:
        return hair_bsdf(eumelanin=float(np.exp(rng.uniform(np.log(0.05), np.log(8.0)))),
                         pheomelanin=float(rng.uniform(0.0, 1.5)),
                         longitudinal=float(rng.uniform(0.1, 0.45)),
                         azimuthal=float(rng.uniform(0.2, 0.6)))
    if u < 0.9:
        return {"type": "diffuse", "reflectance": rgb(np.exp(rng.uniform(np.log(0.005), np.log(0.12), 3)))}
    bsdf = random_material(rng)
    if bsdf["type"] in ("dielectric", "roughdielectric"):
        bsdf = {"type": "diffuse", "reflectance": rgb(rng.uniform(0.02, 0.6, 3))}
    return bsdf


def _strands(rng: np.random.Generator, kind: str, center, radius: float, count: int,
             segments: int) -> tuple[np.ndarray, float]:
    """Control points (count, segments, 3) of one clump of ``kind`` ("fur", "tuft", "fringe")
    of about ``radius`` world units around ``center``; also the core radius (0 without core)."""
    center = np.asarray(center, dtype=np.float64)
    t = np.linspace(0.0, 1.0, segments)[None, :, None]
    if kind == "fur":
        core = radius * float(rng.uniform(0.35, 0.65))
        root = rng.normal(size=(count, 3))
        root /= np.linalg.norm(root, axis=1, keepdims=True)
        bend = rng.normal(scale=float(rng.uniform(0.1, 0.5)), size=(count, 3))
        bend -= (bend * root).sum(1, keepdims=True) * root
        base = center + core * 0.98 * root
        direction = root[:, None, :] + t * bend[:, None, :] + t ** 2 * np.array([0.0, -0.25, 0.0])
        length = (radius - core) * rng.uniform(0.6, 1.2, size=(count, 1))
    elif kind == "tuft":
        core = 0.0
        angle, r = rng.uniform(0, 2 * np.pi, count), 0.5 * radius * np.sqrt(rng.uniform(size=count))
        base = center + np.stack([r * np.cos(angle), np.zeros(count), r * np.sin(angle)], axis=1)
        base[:, 1] = center[1] - 0.5 * radius
        lean = rng.normal(scale=float(rng.uniform(0.15, 0.6)), size=(count, 3))
        lean[:, 1] = 0.0
        direction = np.array([0.0, 1.0, 0.0]) + t * lean[:, None, :] - t ** 2 * np.array([0.0, 0.3, 0.0])
        length = radius * rng.uniform(0.6, 1.4, size=(count, 1))
    else:   # fringe: strands hanging from a horizontal bar, with a wave
        core = 0.0
        axis = rng.normal(size=3)
        axis[1] = 0.0
        axis /= max(np.linalg.norm(axis), 1e-9)
        s = rng.uniform(-1, 1, count)
        base = center + radius * s[:, None] * axis + np.array([0.0, 0.6 * radius, 0.0])
        base += rng.normal(scale=0.03 * radius, size=(count, 3))
        phase = rng.uniform(0, 2 * np.pi, (count, 1, 1))
        wave = np.sin(2 * np.pi * float(rng.uniform(0.5, 2.0)) * t + phase) * float(rng.uniform(0, 0.4))
        side = np.cross(axis, [0.0, 1.0, 0.0])
        direction = np.array([0.0, -1.0, 0.0]) + wave * side
        length = 1.2 * radius * rng.uniform(0.7, 1.3, size=(count, 1))
    steps = direction / np.maximum(np.linalg.norm(direction, axis=2, keepdims=True), 1e-9)
    steps = steps * (length / (segments - 1))[:, None, :]
    points = base[:, None, :] + np.cumsum(steps, axis=1) - steps[:, :1]
    return points, core


def add_fibre_clumps(rng: np.random.Generator, scene: dict, target, distance: float, fov: float,
                  centers) -> None:
    """Add 1-2 fibre clumps to ``scene`` (see the module docstring): the first at the camera
    ``target`` filling about half the frame, a second (40 %) at a random object centre."""
    half_frame = distance * np.tan(np.radians(fov) / 2)
    pixel = 2 * half_frame / FIBRE_REFERENCE_WIDTH
    clumps = 1 + int(rng.random() < 0.4)
    for i in range(clumps):
        center = np.asarray(target if i == 0 else centers[int(rng.integers(len(centers)))], dtype=float)
        radius = float(half_frame * rng.uniform(0.25, 0.6) * (1.0 if i == 0 else 0.6))
        kind = str(rng.choice(["fur", "fur", "tuft", "fringe"]))
        count = int(rng.integers(600, 2501))
        segments = int(rng.integers(3, 6))
        points, core = _strands(rng, kind, center, radius, count, segments)
        root_radius = pixel * float(rng.uniform(0.1, 0.6))
        radii = root_radius * np.linspace(1.0, float(rng.uniform(0.2, 1.0)), segments)
        scene[f"fibres_{i}"] = curve_shape(points, np.broadcast_to(radii, (count, segments)),
                                           kind="linearcurve", bsdf=_fibre_bsdf(rng))
        if core > 0:
            core_bsdf = (random_material(rng) if rng.random() < 0.5 else
                         {"type": "diffuse", "reflectance": rgb(rng.uniform(0.01, 0.3, 3))})
            scene[f"fibre_core_{i}"] = {"type": "sphere", "center": [float(x) for x in center],
                                        "radius": core, "bsdf": core_bsdf}
