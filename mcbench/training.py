"""Procedurally generated training scenes and training examples (noisy crops + targets).

Learned denoisers (KPCN, an OIDN-style autoencoder, ...) are trained on crops of random
scenes rendered with Mitsuba, the way Firmino et al. 2022 (Sec. 5.2) complemented their pbrt
crops with "randomly generated scenes rendered in mitsuba". Everything here is seeded: the same
``seed`` gives the same scene dict (:func:`random_scene`), the same renders and the same crops
(:func:`training_example`).

Scenes
------
:func:`random_scene` draws, from ``numpy.random.default_rng((SCENE_SALT, seed))``:

* a setting: a closed ``room`` (floor, four walls, ceiling; sometimes with the ceiling or one
  wall missing so that a sky gets in), a ``floor`` under an open sky, or objects floating in
  the ``open`` under an environment map;
* 2-7 objects: spheres, cubes, open cylinders, rectangles, disks, and NumPy meshes (torus,
  lathe vase, noise-displaced blob), each with a random material: diffuse, smooth or rough
  conductor (named metals or RGB reflectance), smooth or rough dielectric, smooth or rough
  plastic, principled; diffuse-like colours are often NumPy procedural textures (checkers,
  stripes, sinusoid noise) tiled with a random ``to_uv``;
* 1-3 lights: area rectangles, sphere lights, point and spot lights, and (always when the sky
  is visible) an ``envmap`` made from a NumPy gradient sky with a Gaussian sun blob;
* a camera on a random orbit around the objects (distance, elevation, azimuth, fov), a thin
  lens with random aperture focused on one object in 30 % of the scenes;
* a ``path`` integrator with ``max_depth`` in 4..16.

Fibre scenes: seeds from :data:`FIBRE_SEED_BASE` (32768) on draw the same kind of scene and
then add 1-2 clumps of thin fibres (:func:`_fibre_clumps`, a second stream
``default_rng((FIBRE_SALT, seed))``): a fur ball (strands radiating from a core sphere), a tuft
(strands growing up from a disc) or a fringe (strands hanging from a bar), 600-2500 strands each
as a ``linearcurve``, strand radius 0.1-0.6 pixel at 128 pixels across (so mostly sub-pixel),
with the ``hair`` BSDF (melanin from blond to black, 75 %) or a dark diffuse / random BSDF. The
first clump sits where the camera looks and fills about half the frame. They exist because the
albedo AOV of such fibres is tiny, noisy and unrelated to their (mostly specular) radiance: the
first networks, trained on the object family alone, failed on the test scene ``furball`` (see
README, learned denoisers). The fibre scenes use their own seeds, so adding them changed no
object-family scene; ``training.fibre_count`` in the config sets how many are rendered.

Only helper modules of ``scenes/`` are imported (``scenes.perspective_sensor`` and
``scenes._geometry``), never a test scene; :func:`training_scene_fingerprint` hashes a scene
dict's structure and parameters so that tests can check that no training scene equals a test
scene.

Renders and seeds
-----------------
:func:`training_example` renders each noisy spp level with exactly the conventions of
:func:`mcbench.render.render_buffers` (it reuses render.py's scene wrapper ``_load`` -- box
filter, independent sampler, ``moment(aov(albedo, sh_normal, depth, path))`` -- its pass
splitting and its float64 moment sums; see :func:`render_dict_buffers`), plus a ``target_spp``
target (mean colour and variance of that mean).

Training render seeds are disjoint from every test render seed. :func:`mcbench.render.render_seed`
puts the config's global seed (``base_seed``) in bits 31..29; the configs use 0 (and the test
``tests/test_training.py`` checks every config uses 0..6). Training renders reserve
``base_seed`` = 7 (:data:`TRAINING_BASE_SEED`) and lay out the remaining 29 bits as::

    bit 31..29  7 (training)
    bit 28..13  training scene seed, 0..65535
    bit 12      0 = noisy render, 1 = target
    bit 11..0   noisy:  bit 11..8 log2(spp) (spp a power of two, 2..32768), bit 7 half
                        (0 = A, 1 = B), bit 6..0 pass (0..127)
                target: pass (0..4095)

so no training render shares a seed with a test render (whose top bits are its base seed
0..6), nor with another training render (each field decodes back, :func:`decode_training_seed`).
Within an example the noisy levels, their halves and the target are mutually independent. In
the LLVM/CUDA variants lane ``i`` of a render is seeded with ``TEA(seed, i)``, so distinct
seeds give distinct random streams. The scalar variant (pixel seeds ``seed * W * H + ...``
wrapping around 2**32) is refused: it cannot keep the ranges disjoint. Even if a stream were
shared, the training scenes are different objects from the test scenes (distinct fingerprints),
so no training image would reproduce a test image's noise.

Crops
-----
``crops_per_image`` crops of ``crop_size`` x ``crop_size`` pixels at seeded random positions,
pairwise disjoint (rejection sampling, falling back to random cells of a tiling). Each crop
holds ``<layer>_spp<N>`` for every layer of :data:`mcbench.buffers.ALL_LAYERS` and noisy level
``N``, plus ``target`` (H, W, 3) and ``target_variance`` (H, W, 3).

CLI::

    python -m mcbench.training --out DIR --first-seed S --count N --resolution 128 128 \\
        --crop 64 --crops 2 --spp 4 16 64 256 --target-spp 4096

writes ``DIR/example_<seed>_<k>.exr`` (atomic, :func:`mcbench.exr.write_layers`).
"""

from __future__ import annotations

import argparse
import hashlib
import math
import struct
import sys
import time
from types import SimpleNamespace

import numpy as np

from mcbench import BenchError
from mcbench.buffers import ALL_LAYERS

__all__ = ["TRAINING_BASE_SEED", "MAX_TRAINING_SEED", "FIBRE_SEED_BASE", "training_seeds",
           "is_fibre_seed", "random_scene", "training_example",
           "training_render_seed", "decode_training_seed", "render_dict_buffers",
           "render_dict_target", "crop_boxes", "scene_fingerprint", "training_scene_fingerprint",
           "main"]

TRAINING_BASE_SEED = 7          # bits 31..29 of every training render seed (configs use 0..6)
MAX_TRAINING_SEED = (1 << 16) - 1
FIBRE_SEED_BASE = 1 << 15       # seeds >= this are fibre scenes (object family below)
SCENE_SALT = 0x7A1D5CE7         # mixed into the scene RNG so scene streams are ours alone
FIBRE_SALT = 0x0F1B4E55
FIBRE_REFERENCE_WIDTH = 128     # strand radii are drawn in pixels of a 128-pixel-wide film
CROP_SALT = 0x0C509B0C
FINGERPRINT_SIZE = (32, 24)     # film size used by training_scene_fingerprint (film size is
                                # excluded from fingerprints anyway)

METALS = ("Au", "Ag", "Al", "Cu", "Cr", "W", "Ir", "Mo", "Rh", "TiN")


# --------------------------------------------------------------------------- seeds

def training_render_seed(scene_seed: int, kind: str, spp: int | None = None,
                         half: int | None = None, pass_index: int = 0) -> int:
    """32-bit Mitsuba seed of one training render pass (layout in the module docstring).

    ``kind`` is ``"noisy"`` (needs ``spp``, a power of two 2..32768, and ``half`` 0/1) or
    ``"target"``. Raises :class:`BenchError` for fields out of range.
    """
    scene_seed, pass_index = int(scene_seed), int(pass_index)
    if not 0 <= scene_seed <= MAX_TRAINING_SEED:
        raise BenchError(f"training seed {scene_seed} out of range 0..{MAX_TRAINING_SEED}")
    if kind == "noisy":
        spp = int(spp)
        if spp < 2 or spp & (spp - 1) or spp > 1 << 15:
            raise BenchError(f"training spp levels must be powers of two 2..32768, got {spp}")
        if half not in (0, 1):
            raise ValueError(f"half must be 0 (A) or 1 (B), got {half!r}")
        if not 0 <= pass_index < 1 << 7:
            raise BenchError(f"noisy pass index {pass_index} out of range 0..127 (lower the spp "
                             f"or the resolution)")
        low = (int(math.log2(spp)) << 8) | (half << 7) | pass_index
    elif kind == "target":
        if not 0 <= pass_index < 1 << 12:
            raise BenchError(f"target pass index {pass_index} out of range 0..4095 (lower the "
                             f"target spp or the resolution)")
        low = (1 << 12) | pass_index
    else:
        raise ValueError(f"kind must be 'noisy' or 'target', got {kind!r}")
    return (TRAINING_BASE_SEED << 29) | (scene_seed << 13) | low


def decode_training_seed(seed: int) -> dict:
    """Inverse of :func:`training_render_seed` (raises ValueError for a non-training seed)."""
    if seed >> 29 != TRAINING_BASE_SEED:
        raise ValueError(f"seed {seed} is not a training render seed (base {seed >> 29})")
    out = {"scene_seed": (seed >> 13) & 0xFFFF}
    if (seed >> 12) & 1:
        out.update(kind="target", pass_index=seed & 0xFFF)
    else:
        out.update(kind="noisy", spp=1 << ((seed >> 8) & 0xF), half=(seed >> 7) & 1,
                   pass_index=seed & 0x7F)
    return out


def is_fibre_seed(seed: int) -> bool:
    """Whether training scene ``seed`` belongs to the fibre family (seed >= 32768)."""
    return int(seed) >= FIBRE_SEED_BASE


def training_seeds(settings: dict) -> list[int]:
    """Scene seeds of a config's ``training`` section: ``first_seed .. first_seed + count - 1``
    (object family, must stay below :data:`FIBRE_SEED_BASE`) then ``fibre_count`` (default 0)
    fibre scenes from :data:`FIBRE_SEED_BASE` on. Raises :class:`BenchError` naming the key."""
    first, count = int(settings["first_seed"]), int(settings["count"])
    fibres = int(settings.get("fibre_count", 0))
    if first < 0 or count < 1 or first + count > FIBRE_SEED_BASE:
        raise BenchError(f"training.first_seed + training.count must stay within 0..{FIBRE_SEED_BASE} "
                         f"(fibre scenes start there), got {first} + {count}")
    if not 0 <= fibres <= MAX_TRAINING_SEED + 1 - FIBRE_SEED_BASE:
        raise BenchError(f"training.fibre_count must be 0..{MAX_TRAINING_SEED + 1 - FIBRE_SEED_BASE}, "
                         f"got {fibres}")
    return list(range(first, first + count)) + list(range(FIBRE_SEED_BASE, FIBRE_SEED_BASE + fibres))


# --------------------------------------------------------------------------- textures

def _texture_array(rng: np.random.Generator, size: int = 128) -> tuple[str, np.ndarray]:
    """A tileable procedural texture (size, size, 3) in [0.02, 0.9]: checkers, stripes, noise."""
    kind = str(rng.choice(["checkers", "stripes", "noise"]))
    c0, c1 = rng.uniform(0.02, 0.9, 3), rng.uniform(0.02, 0.9, 3)
    y, x = np.mgrid[0:size, 0:size] / size
    if kind == "checkers":
        n = int(rng.integers(2, 9))
        t = ((np.floor(x * n) + np.floor(y * n)) % 2)
    elif kind == "stripes":
        n = int(rng.integers(2, 12))
        fx, fy = [(n, 0), (0, n), (n, n), (n, -n)][int(rng.integers(4))]
        phase = np.sin(2 * np.pi * (fx * x + fy * y))
        t = (phase > rng.uniform(-0.6, 0.6)).astype(float) if rng.random() < 0.6 else 0.5 + 0.5 * phase
    else:  # sum of random tileable sinusoids
        t = np.zeros_like(x)
        for octave in range(4):
            for _ in range(3):
                fx, fy = rng.integers(-2 ** (octave + 1), 2 ** (octave + 1) + 1, 2)
                t += 0.5 ** octave * np.sin(2 * np.pi * (fx * x + fy * y) + rng.uniform(0, 2 * np.pi))
        t = (t - t.min()) / max(t.max() - t.min(), 1e-6)
    image = (1 - t[..., None]) * c0 + t[..., None] * c1
    return kind, np.clip(image, 0.02, 0.9).astype(np.float32)


def _color_or_texture(rng: np.random.Generator, textured: float = 0.45) -> dict:
    from scenes._geometry import bitmap_texture, rgb
    import mitsuba as mi

    if rng.random() < textured:
        _, image = _texture_array(rng)
        tile = float(rng.uniform(1, 6))
        return bitmap_texture(image, filter_type=str(rng.choice(["bilinear", "nearest"])),
                              to_uv=mi.ScalarTransform4f().scale([tile, tile, 1]))
    return rgb(rng.uniform(0.03, 0.85, 3))


def _material(rng: np.random.Generator) -> dict:
    """A random BSDF dict (two-sided where it matters for open shapes)."""
    from scenes._geometry import rgb

    kind = str(rng.choice(["diffuse", "diffuse", "conductor", "roughconductor", "dielectric",
                           "roughdielectric", "plastic", "roughplastic", "principled"]))
    alpha = float(np.exp(rng.uniform(np.log(0.03), np.log(0.5))))
    if kind == "diffuse":
        bsdf = {"type": "diffuse", "reflectance": _color_or_texture(rng)}
    elif kind in ("conductor", "roughconductor"):
        bsdf = {"type": kind}
        if rng.random() < 0.6:
            bsdf["material"] = str(rng.choice(METALS))
        else:
            bsdf["specular_reflectance"] = rgb(rng.uniform(0.3, 0.95, 3))
        if kind == "roughconductor":
            bsdf.update(distribution=str(rng.choice(["ggx", "beckmann"])), alpha=alpha)
    elif kind in ("dielectric", "roughdielectric"):
        bsdf = {"type": kind, "int_ior": float(rng.uniform(1.3, 1.8)), "ext_ior": 1.0}
        if kind == "roughdielectric":
            bsdf.update(distribution="ggx", alpha=alpha)
        if rng.random() < 0.3:
            bsdf["specular_transmittance"] = rgb(rng.uniform(0.5, 1.0, 3))
    elif kind in ("plastic", "roughplastic"):
        bsdf = {"type": kind, "diffuse_reflectance": _color_or_texture(rng),
                "int_ior": float(rng.uniform(1.4, 1.7))}
        if kind == "roughplastic":
            bsdf.update(distribution="ggx", alpha=alpha)
    else:
        bsdf = {"type": "principled", "base_color": _color_or_texture(rng),
                "metallic": float(rng.choice([0.0, rng.uniform(0, 1), 1.0])),
                "roughness": float(rng.uniform(0.05, 0.9)),
                "specular": float(rng.uniform(0.2, 0.8))}
    return bsdf


def _two_sided(bsdf: dict) -> dict:
    """Open surfaces (rectangles, disks, cylinders) seen from behind: wrap non-transmissive BSDFs."""
    if bsdf["type"] in ("dielectric", "roughdielectric"):
        return bsdf
    return {"type": "twosided", "bsdf": bsdf}


# --------------------------------------------------------------------------- geometry

def _rotation(rng: np.random.Generator):
    import mitsuba as mi

    axis = rng.normal(size=3)
    axis /= max(np.linalg.norm(axis), 1e-9)
    return mi.ScalarTransform4f().rotate([float(a) for a in axis], float(rng.uniform(0, 360)))


def _blob(rng: np.random.Generator, segments: int = 48, rows: int = 24):
    """Unit sphere (lathe) displaced radially by a smooth random field: flat-shaded arrays."""
    from scenes._geometry import lathe

    t = np.linspace(0.05, np.pi - 0.05, rows)
    vertices, faces, _, uv = lathe(np.sin(t), -np.cos(t), segments=segments, cap_bottom=True,
                                   cap_top=True)
    field = np.zeros(len(vertices))
    for _ in range(6):
        k = rng.normal(size=3) * rng.uniform(1.0, 4.0)
        field += np.sin(vertices @ k + rng.uniform(0, 2 * np.pi)) / 6
    vertices = vertices * (1.0 + float(rng.uniform(0.1, 0.35)) * field)[:, None]
    return vertices, faces, uv


def _shape(rng: np.random.Generator, center, size: float, index: int):
    """One random object at ``center`` (world units) of about ``size`` half extent."""
    import mitsuba as mi
    from scenes._geometry import lathe, mesh_from_arrays, torus

    T = mi.ScalarTransform4f
    kind = str(rng.choice(["sphere", "sphere", "cube", "cylinder", "rectangle", "disk", "mesh"]))
    bsdf = _material(rng)
    c = [float(x) for x in center]
    if kind == "sphere":
        return {"type": "sphere", "center": c, "radius": float(size), "bsdf": bsdf}
    if kind == "cube":
        half = size * rng.uniform(0.5, 1.0, 3)
        return {"type": "cube", "bsdf": bsdf,
                "to_world": T().translate(c) @ _rotation(rng) @ T().scale([float(h) for h in half])}
    if kind == "cylinder":
        radius = float(size * rng.uniform(0.3, 0.7))
        length = float(size * rng.uniform(1.0, 2.0))
        return {"type": "cylinder", "radius": radius, "bsdf": _two_sided(bsdf),
                "to_world": T().translate(c) @ _rotation(rng) @ T().translate([0, 0, -length / 2])
                .scale([1, 1, length])}
    if kind in ("rectangle", "disk"):
        scale = [float(size * rng.uniform(0.6, 1.4)), float(size * rng.uniform(0.6, 1.4)), 1.0]
        return {"type": kind, "bsdf": _two_sided(bsdf),
                "to_world": T().translate(c) @ _rotation(rng) @ T().scale(scale)}
    mesh_kind = str(rng.choice(["torus", "vase", "blob"]))
    if mesh_kind == "torus":
        v, f, n, uv = torus(1.0, float(rng.uniform(0.2, 0.45)), segments=48, ring_segments=16)
        scale = size / (1.0 + 0.45)
    elif mesh_kind == "vase":
        h = np.linspace(0.0, 1.0, 24)
        a, b = rng.uniform(0.2, 0.5, 2)
        r = 0.35 + a * np.sin(np.pi * h * rng.uniform(0.8, 2.0)) * (1 - 0.5 * h) + 0.1 * b
        v, f, n, uv = lathe(np.maximum(r, 0.05), 2.0 * h - 1.0, segments=48, cap_bottom=True,
                            cap_top=bool(rng.random() < 0.5))
        scale = size
        bsdf = _two_sided(bsdf)
    else:
        v, f, uv = _blob(rng)
        n = None
        scale = size / 1.35
    to_world = T().translate(c) @ _rotation(rng) @ T().scale(float(scale))
    return mesh_from_arrays(v, f, normals=n, uv=uv, bsdf=bsdf, name=f"mesh_{index}",
                            to_world=to_world)


def _room(rng: np.random.Generator, half: float, height: float, open_side: str | None) -> dict:
    """Inward-facing floor, walls and ceiling of a room (``open_side`` names one left out)."""
    from scenes._geometry import quad

    faces = {
        "floor": ((0, 0, 0), (0, 1, 0)), "ceiling": ((0, height, 0), (0, -1, 0)),
        "wall_px": ((half, height / 2, 0), (-1, 0, 0)), "wall_nx": ((-half, height / 2, 0), (1, 0, 0)),
        "wall_pz": ((0, height / 2, half), (0, 0, -1)), "wall_nz": ((0, height / 2, -half), (0, 0, 1)),
    }
    out = {}
    wall_color = rng.uniform(0.25, 0.85, 3)
    for name, (center, normal) in faces.items():
        if name == open_side:
            continue
        n = np.asarray(normal, dtype=float)
        u = (np.array([1.0, 0, 0]) if abs(n[0]) < 0.5 else np.array([0, 0, 1.0])) * half
        v = np.cross(n, u)          # u x v = n |u|^2: the front face looks into the room
        if name.startswith("wall"):
            # u horizontal (half), v vertical (height / 2)
            v = v / np.linalg.norm(v) * (height / 2)
        if name == "floor" and rng.random() < 0.6:
            bsdf = _material(rng) if rng.random() < 0.3 else {
                "type": "diffuse", "reflectance": _color_or_texture(rng, textured=0.8)}
        elif rng.random() < 0.25:
            bsdf = {"type": "diffuse", "reflectance": _color_or_texture(rng, textured=0.7)}
        else:
            tint = wall_color * rng.uniform(0.8, 1.2, 3)
            bsdf = {"type": "diffuse", "reflectance": {"type": "rgb",
                                                       "value": [float(x) for x in np.clip(tint, 0.05, 0.9)]}}
        if bsdf["type"] in ("dielectric", "roughdielectric"):
            bsdf = {"type": "diffuse", "reflectance": _color_or_texture(rng)}
        out[name] = quad(center, u, v, bsdf=bsdf)
    return out


def _light_color(rng: np.random.Generator) -> np.ndarray:
    warm, cool = np.array([1.0, 0.78, 0.55]), np.array([0.75, 0.87, 1.0])
    t = rng.uniform()
    color = (1 - t) * warm + t * cool
    return color / color.mean()


def _envmap(rng: np.random.Generator) -> dict:
    import mitsuba as mi
    from scenes._geometry import gradient_sky

    sun = rng.random() < 0.7
    sky = gradient_sky(height=64, zenith=rng.uniform(0.05, 0.5, 3) * [0.6, 0.8, 1.2],
                       horizon=rng.uniform(0.4, 1.0, 3), ground=rng.uniform(0.05, 0.35, 3),
                       sun_elevation_deg=float(rng.uniform(8, 75)) if sun else None,
                       sun_azimuth_deg=float(rng.uniform(0, 360)),
                       sun_radius_deg=float(rng.uniform(1.5, 5.0)),
                       sun_radiance=float(np.exp(rng.uniform(np.log(30), np.log(600)))) if sun else 0.0,
                       sun_color=_light_color(rng))
    return {"type": "envmap", "bitmap": mi.Bitmap(sky), "scale": float(rng.uniform(0.5, 2.0)),
            "to_world": mi.ScalarTransform4f().rotate([0, 1, 0], float(rng.uniform(0, 360)))}


def _lights(rng: np.random.Generator, count: int, top: float, target) -> dict:
    """``count`` random local lights around the objects; ``top`` caps their height."""
    import mitsuba as mi
    from scenes._geometry import quad

    out = {}
    for i in range(count):
        kind = str(rng.choice(["area", "area", "sphere", "point", "spot"]))
        azimuth = rng.uniform(0, 2 * np.pi)
        radius = rng.uniform(0.5, 3.0)
        y = float(min(top - 0.05, rng.uniform(1.8, 4.0)))
        position = np.array([radius * np.cos(azimuth), y, radius * np.sin(azimuth)])
        distance = float(np.linalg.norm(position - np.asarray(target)))
        color = _light_color(rng) * float(np.exp(rng.uniform(np.log(0.4), np.log(2.5))))
        if kind == "area":
            width, depth = rng.uniform(0.2, 0.9, 2)
            area = 4 * width * depth
            radiance = color * 3.0 * distance ** 2 / area
            out[f"light_{i}"] = quad(position, (float(width), 0, 0), (0, 0, float(-depth)),
                                     emitter={"type": "area", "radiance": {
                                         "type": "rgb", "value": [float(x) for x in radiance]}})
            # quad's front face is u x v = (0, -1, 0) here: the light shines downwards
            out[f"light_{i}"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb",
                                                                            "value": [0.0, 0.0, 0.0]}}
        elif kind == "sphere":
            r = float(rng.uniform(0.05, 0.3))
            radiance = color * 1.0 * distance ** 2 / r ** 2
            out[f"light_{i}"] = {"type": "sphere", "center": [float(x) for x in position],
                                 "radius": r, "emitter": {"type": "area", "radiance": {
                                     "type": "rgb", "value": [float(x) for x in radiance]}}}
        elif kind == "point":
            intensity = color * 3.0 * distance ** 2 / np.pi
            out[f"light_{i}"] = {"type": "point", "position": [float(x) for x in position],
                                 "intensity": {"type": "rgb", "value": [float(x) for x in intensity]}}
        else:
            cutoff = float(rng.uniform(15, 50))
            intensity = color * 4.0 * distance ** 2 / np.pi
            aim = np.asarray(target) + rng.normal(scale=0.4, size=3)
            out[f"light_{i}"] = {
                "type": "spot", "cutoff_angle": cutoff,
                "beam_width": float(cutoff * rng.uniform(0.5, 0.95)),
                "intensity": {"type": "rgb", "value": [float(x) for x in intensity]},
                "to_world": mi.ScalarTransform4f().look_at(
                    origin=[float(x) for x in position], target=[float(x) for x in aim],
                    up=[0, 1, 0] if abs(aim[0] - position[0]) + abs(aim[2] - position[2]) > 1e-3
                    else [1, 0, 0])}
    return out


# --------------------------------------------------------------------------- fibres

def _fibre_bsdf(rng: np.random.Generator) -> dict:
    """Hair BSDF (75 %: eumelanin log-uniform 0.05..8, blond to black), dark diffuse (15 %) or a
    random material (10 %, dielectrics replaced by diffuse: curves have no inside)."""
    from scenes._curves import hair_bsdf
    from scenes._geometry import rgb

    u = rng.random()
    if u < 0.75:
        return hair_bsdf(eumelanin=float(np.exp(rng.uniform(np.log(0.05), np.log(8.0)))),
                         pheomelanin=float(rng.uniform(0.0, 1.5)),
                         longitudinal=float(rng.uniform(0.1, 0.45)),
                         azimuthal=float(rng.uniform(0.2, 0.6)))
    if u < 0.9:
        return {"type": "diffuse", "reflectance": rgb(np.exp(rng.uniform(np.log(0.005), np.log(0.12), 3)))}
    bsdf = _material(rng)
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


def _fibre_clumps(rng: np.random.Generator, scene: dict, target, distance: float, fov: float,
                  centers) -> None:
    """Add 1-2 fibre clumps to ``scene`` (see the module docstring): the first at the camera
    ``target`` filling about half the frame, a second (40 %) at a random object centre."""
    from scenes._curves import curve_shape
    from scenes._geometry import rgb

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
            core_bsdf = (_material(rng) if rng.random() < 0.5 else
                         {"type": "diffuse", "reflectance": rgb(rng.uniform(0.01, 0.3, 3))})
            scene[f"fibre_core_{i}"] = {"type": "sphere", "center": [float(x) for x in center],
                                        "radius": core, "bsdf": core_bsdf}


# --------------------------------------------------------------------------- scenes

def _ensure_variant() -> None:
    import mitsuba as mi

    if mi.variant() is None:
        from mcbench.render import pick_variant
        pick_variant("auto")


def random_scene(seed: int, width: int, height: int) -> dict:
    """A complete Mitsuba scene dict (integrator and ``perspective``/``thinlens`` sensor
    included, film ``width`` x ``height``) drawn from ``seed``; see the module docstring.
    Sets a Mitsuba variant (``pick_variant("auto")``) when none is set."""
    from scenes import perspective_sensor
    from scenes._geometry import thinlens_sensor

    _ensure_variant()
    seed = int(seed)
    if not 0 <= seed <= MAX_TRAINING_SEED:
        raise BenchError(f"training seed {seed} out of range 0..{MAX_TRAINING_SEED}")
    rng = np.random.default_rng((SCENE_SALT, seed))
    setting = str(rng.choice(["room", "room", "floor", "open"]))
    scene: dict = {"type": "scene",
                   "integrator": {"type": "path", "max_depth": int(rng.integers(4, 17))}}

    # Objects in a disc of radius ~1.6 around the origin, resting on y = 0 (or floating).
    count = int(rng.integers(2, 8))
    centers, sizes = [], []
    for i in range(count):
        for _ in range(30):
            size = float(rng.uniform(0.2, 0.7))
            angle, radius = rng.uniform(0, 2 * np.pi), 1.6 * np.sqrt(rng.uniform())
            lift = size if setting != "open" and rng.random() < 0.8 else float(rng.uniform(size, 1.8))
            center = np.array([radius * np.cos(angle), lift, radius * np.sin(angle)])
            if all(np.linalg.norm(center - c) > 0.8 * (size + s) for c, s in zip(centers, sizes)):
                break
        centers.append(center)
        sizes.append(size)
        scene[f"object_{i}"] = _shape(rng, center, size, i)
    target = np.mean(centers, axis=0) * 0.5 + rng.normal(scale=0.2, size=3)
    target[1] = float(np.clip(target[1], 0.2, 1.2))

    # Camera on an orbit around the target.
    distance = float(rng.uniform(3.0, 5.0))
    elevation = np.radians(rng.uniform(3, 45))
    azimuth = rng.uniform(0, 2 * np.pi)
    origin = target + distance * np.array([np.cos(elevation) * np.cos(azimuth), np.sin(elevation),
                                           np.cos(elevation) * np.sin(azimuth)])
    origin[1] = max(origin[1], 0.15)
    fov = float(rng.uniform(25, 60))

    # Setting and lights.
    sky_visible = setting != "room"
    if setting == "room":
        half = 6.0
        room_height = float(max(rng.uniform(3.5, 5.0), origin[1] + 0.6))
        open_side = str(rng.choice(["ceiling", "wall_px", "wall_nx", "wall_pz", "wall_nz"])) \
            if rng.random() < 0.3 else None
        sky_visible = open_side is not None
        scene.update(_room(rng, half, room_height, open_side))
        top = room_height
    else:
        top = 5.0
        if setting == "floor":
            from scenes._geometry import quad
            bsdf = (_material(rng) if rng.random() < 0.3 else
                    {"type": "diffuse", "reflectance": _color_or_texture(rng, textured=0.7)})
            if bsdf["type"] in ("dielectric", "roughdielectric"):
                bsdf = {"type": "diffuse", "reflectance": _color_or_texture(rng)}
            scene["floor"] = quad((0, 0, 0), (20, 0, 0), (0, 0, -20), bsdf=bsdf)
    local_lights = int(rng.integers(1, 4)) if not sky_visible else int(rng.integers(0, 3))
    scene.update(_lights(rng, local_lights, top, target))
    if sky_visible:
        scene["environment"] = _envmap(rng)

    if rng.random() < 0.3:
        focus = centers[int(rng.integers(len(centers)))]
        scene["sensor"] = thinlens_sensor(
            width, height, origin=origin.tolist(), target=target.tolist(), fov=fov,
            aperture_radius=float(np.exp(rng.uniform(np.log(0.01), np.log(0.12)))),
            focus_distance=float(np.linalg.norm(focus - origin)))
    else:
        scene["sensor"] = perspective_sensor(width, height, origin=origin.tolist(),
                                             target=target.tolist(), fov=fov)
    if is_fibre_seed(seed):
        _fibre_clumps(np.random.default_rng((FIBRE_SALT, seed)), scene, target, distance, fov, centers)
    return scene


# --------------------------------------------------------------------------- fingerprints

def _feed(h, obj, path: str = "") -> None:
    """Feed a canonical serialisation of ``obj`` into hash ``h`` (film size excluded)."""
    import mitsuba as mi

    if isinstance(obj, dict):
        h.update(b"{")
        is_film = obj.get("type") == "hdrfilm"
        for key in sorted(obj):
            if is_film and key in ("width", "height"):
                continue
            h.update(key.encode() + b":")
            _feed(h, obj[key], path + "." + key)
        h.update(b"}")
    elif isinstance(obj, (list, tuple)):
        h.update(b"[")
        for item in obj:
            _feed(h, item, path)
        h.update(b"]")
    elif isinstance(obj, (bool, np.bool_)):
        h.update(b"b1" if obj else b"b0")
    elif isinstance(obj, (int, np.integer)):
        h.update(b"i" + str(int(obj)).encode())
    elif isinstance(obj, (float, np.floating)):
        h.update(b"f" + struct.pack("<d", float(obj)))
    elif isinstance(obj, str):
        h.update(b"s" + obj.encode())
    elif isinstance(obj, np.ndarray):
        _feed_array(h, obj)
    elif hasattr(obj, "matrix") and "Transform" in type(obj).__name__:
        _feed_array(h, np.array(obj.matrix, dtype=np.float64))
    elif isinstance(obj, mi.Bitmap):
        _feed_array(h, np.array(obj))
    elif isinstance(obj, mi.Object):
        h.update(b"O" + type(obj).__name__.encode())
        params = mi.traverse(obj)
        for key in sorted(params.keys()):
            h.update(key.encode() + b"=")
            try:
                value = params[key]
                # np.array() of a Mitsuba transform is not its matrix (it changes run to run)
                _feed_array(h, np.array(value.matrix if hasattr(value, "matrix") else value))
            except Exception:   # a parameter that is no array (or cannot be read)
                h.update(b"?")
    else:
        try:
            _feed_array(h, np.array(obj))
        except Exception:
            h.update(b"r" + type(obj).__name__.encode())


def _feed_array(h, array: np.ndarray) -> None:
    array = np.ascontiguousarray(array)
    h.update(b"a" + str(array.dtype).encode() + str(array.shape).encode())
    h.update(array.tobytes())


def scene_fingerprint(desc: dict) -> str:
    """SHA-256 (hex) of a scene dict's structure and parameters: keys, types, numbers, strings,
    transforms, bitmaps and Mitsuba objects (meshes: all their traversable parameters, BSDF
    included). The film's width and height are left out, so the fingerprint names the scene,
    not the image size."""
    h = hashlib.sha256()
    _feed(h, desc)
    return h.hexdigest()


def training_scene_fingerprint(seed: int) -> str:
    """:func:`scene_fingerprint` of ``random_scene(seed, ...)``."""
    return scene_fingerprint(random_scene(seed, *FINGERPRINT_SIZE))


# --------------------------------------------------------------------------- rendering

def _render_sums_of_dict(desc: dict, key: str, spp: int, seeds_of, variant: str,
                         width: int, height: int, label_spp: int) -> dict:
    """Float64 moment sums (render.py's ``_render_sums``) of ``spp`` samples of scene dict
    ``desc``, split into render.py's passes, pass ``p`` seeded with ``seeds_of(p)``."""
    from mcbench import render

    module = SimpleNamespace(build=lambda w, h: dict(desc))   # _load mutates the dict it gets
    scene_object, _ = render._load(key, module, width, height, variant)
    pass_spp = render.passes_for(spp, width, height, variant)
    seeds = [seeds_of(p) for p in range(len(pass_spp))]
    return render._render_sums(key, scene_object, pass_spp, seeds, variant, width, height,
                               label_spp), seeds


def _check_variant(variant: str) -> str:
    from mcbench.render import pick_variant

    variant = pick_variant(variant)
    if variant.startswith("scalar"):
        raise BenchError("mcbench.training: scalar variants cannot keep training render seeds "
                         "disjoint from the test renders' seeds; use llvm_ad_rgb or cuda_ad_rgb")
    return variant


def _film_size(desc: dict) -> tuple[int, int]:
    sensor = next(v for v in desc.values() if isinstance(v, dict)
                  and v.get("type") in ("perspective", "thinlens", "orthographic"))
    return int(sensor["film"]["width"]), int(sensor["film"]["height"])


def render_dict_buffers(desc: dict, spp: int, seed_of, *, key: str, variant: str = "auto"
                        ) -> tuple[dict[str, np.ndarray], list[int]]:
    """Noisy buffers of a scene *dict* with the conventions of :func:`mcbench.render.render_buffers`.

    ``seed_of(half, pass_index)`` gives the 32-bit seed of each pass; ``key`` names the scene
    in error messages and in render.py's scene cache (drop it with :func:`forget`). Returns
    the float32 layers of :data:`ALL_LAYERS` and the list of seeds used (A then B).
    """
    from mcbench.render import buffers_from_moment_sums, pick_variant

    variant = pick_variant(variant)
    width, height = _film_size(desc)
    half_spp = int(spp) // 2
    sums, used = {}, []
    for half, suffix in ((0, "_a"), (1, "_b")):
        sums[suffix], seeds = _render_sums_of_dict(desc, key, half_spp,
                                                   lambda p, half=half: seed_of(half, p),
                                                   variant, width, height, spp)
        used += seeds
    layers = buffers_from_moment_sums(sums["_a"], sums["_b"], half_spp)
    return layers, used


def render_dict_target(desc: dict, spp: int, seed_of, *, key: str, variant: str = "auto"
                       ) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """High-spp target of a scene dict: float32 mean colour (H, W, 3), variance of that mean
    (H, W, 3) and the seeds used (pass ``p`` seeded with ``seed_of(p)``)."""
    from mcbench.render import moments_to_mean_variance, pick_variant

    variant = pick_variant(variant)
    width, height = _film_size(desc)
    sums, seeds = _render_sums_of_dict(desc, key, int(spp), seed_of, variant, width, height, spp)
    mean, variance = moments_to_mean_variance(*sums["color"], int(spp))
    return mean.astype(np.float32), variance.astype(np.float32), seeds


def forget(key: str) -> None:
    """Drop the cached Mitsuba scenes of ``key`` from render.py's per-process cache."""
    from mcbench import render

    for cache_key in [k for k in render._scene_cache if k[0] == key]:
        del render._scene_cache[cache_key]


# --------------------------------------------------------------------------- examples

def crop_boxes(seed: int, width: int, height: int, crop_size: int, count: int
               ) -> list[tuple[int, int, int, int]]:
    """``count`` pairwise disjoint crops ``(x0, y0, x1, y1)`` (x1, y1 exclusive) of
    ``crop_size``² inside a ``width`` x ``height`` image, at positions drawn from ``seed``.

    Rejection sampling of uniform positions; if that stalls, random distinct cells of a tiling
    of the image (always disjoint). Raises :class:`BenchError` when the crops cannot fit.
    """
    c = int(crop_size)
    if c < 1 or c > width or c > height:
        raise BenchError(f"crop size {c} does not fit a {width}x{height} image")
    cells = (width // c) * (height // c)
    if count > cells:
        raise BenchError(f"{count} disjoint {c}x{c} crops do not fit a {width}x{height} image "
                         f"(at most {cells})")
    rng = np.random.default_rng((CROP_SALT, int(seed), width, height, c, count))
    boxes: list[tuple[int, int, int, int]] = []
    for _ in range(200 * max(count, 1)):
        if len(boxes) == count:
            return boxes
        x0, y0 = int(rng.integers(0, width - c + 1)), int(rng.integers(0, height - c + 1))
        if all(x0 + c <= bx0 or bx1 <= x0 or y0 + c <= by0 or by1 <= y0
               for bx0, by0, bx1, by1 in boxes):
            boxes.append((x0, y0, x0 + c, y0 + c))
    # Fallback: random cells of a tiling with a random offset (disjoint by construction).
    ox, oy = int(rng.integers(0, width - (width // c) * c + 1)), int(rng.integers(0, height - (height // c) * c + 1))
    chosen = rng.choice(cells, size=count, replace=False)
    columns = width // c
    return [(ox + int(k % columns) * c, oy + int(k // columns) * c,
             ox + int(k % columns) * c + c, oy + int(k // columns) * c + c) for k in chosen]


def training_example(seed: int, spp_levels, target_spp: int, resolution, crop_size: int,
                     crops_per_image: int, variant: str = "auto"
                     ) -> list[tuple[dict[str, np.ndarray], dict]]:
    """Render training scene ``seed`` and cut it into crops.

    ``spp_levels``: noisy spp levels (powers of two >= 2), each rendered as full + half buffers
    with every layer of :data:`ALL_LAYERS` (render_buffers' conventions); ``target_spp``: spp of
    the target (mean colour ``target`` and ``target_variance``, the variance of that mean);
    ``resolution``: ``(width, height)``. Render seeds come from :func:`training_render_seed`
    (base seed 7, disjoint from all test render seeds -- see the module docstring).

    Returns ``crops_per_image`` pairs ``(layers, metadata)``: layers ``<layer>_spp<N>`` for
    every layer and level plus ``target`` and ``target_variance``, each cropped to
    ``crop_size``²; metadata (strings): seed, crop index, crop box ``x0,y0,x1,y1``, spp levels,
    target spp, resolution, variant, mitsuba version, scene fingerprint, render seconds.
    """
    import mitsuba as mi

    seed = int(seed)
    levels = sorted({int(s) for s in spp_levels})
    if not levels:
        raise BenchError("training_example: no spp levels given")
    for spp in levels:
        training_render_seed(seed, "noisy", spp=spp, half=0)    # validates the level
    if int(target_spp) < 2:
        raise BenchError(f"target spp must be >= 2, got {target_spp}")
    width, height = (int(x) for x in resolution)
    variant = _check_variant(variant)
    boxes = crop_boxes(seed, width, height, crop_size, crops_per_image)
    start = time.perf_counter()
    desc = random_scene(seed, width, height)
    fingerprint = scene_fingerprint(desc)
    key = f"training-{seed}"
    full: dict[str, np.ndarray] = {}
    try:
        for spp in levels:
            layers, _ = render_dict_buffers(
                desc, spp, lambda half, p, spp=spp: training_render_seed(seed, "noisy", spp, half, p),
                key=key, variant=variant)
            for name, layer in layers.items():
                full[f"{name}_spp{spp}"] = layer
        full["target"], full["target_variance"], _ = render_dict_target(
            desc, int(target_spp), lambda p: training_render_seed(seed, "target", pass_index=p),
            key=key, variant=variant)
    finally:
        forget(key)
    seconds = time.perf_counter() - start
    for name, layer in full.items():
        if not np.all(np.isfinite(layer)):
            raise BenchError(f"training scene {seed}: layer {name} has NaN/Inf")
    out = []
    for k, (x0, y0, x1, y1) in enumerate(boxes):
        layers = {name: np.ascontiguousarray(layer[y0:y1, x0:x1]) for name, layer in full.items()}
        metadata = {"seed": str(seed), "crop": str(k), "crop_box": f"{x0},{y0},{x1},{y1}",
                    "spp_levels": ",".join(map(str, levels)), "target_spp": str(int(target_spp)),
                    "resolution": f"{width}x{height}", "variant": variant,
                    "mitsuba": mi.__version__, "fingerprint": fingerprint,
                    "seconds": f"{seconds:.3f}"}
        out.append((layers, metadata))
    return out


# --------------------------------------------------------------------------- CLI

def main(argv: list[str] | None = None) -> int:
    from mcbench.exr import write_layers
    from mcbench.render import set_threads

    parser = argparse.ArgumentParser(prog="python -m mcbench.training",
                                     description="Render procedural training examples to EXR crops.")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--first-seed", type=int, required=True)
    parser.add_argument("--count", type=int, default=1)
    parser.add_argument("--resolution", type=int, nargs=2, default=(128, 128), metavar=("W", "H"))
    parser.add_argument("--crop", type=int, default=64)
    parser.add_argument("--crops", type=int, default=2)
    parser.add_argument("--spp", type=int, nargs="+", default=[4, 16, 64, 256])
    parser.add_argument("--target-spp", type=int, default=4096)
    parser.add_argument("--variant", default="auto")
    parser.add_argument("--threads", type=int, default=None)
    args = parser.parse_args(argv)
    try:
        variant = _check_variant(args.variant)
        set_threads(args.threads)
        for seed in range(args.first_seed, args.first_seed + args.count):
            crops = training_example(seed, args.spp, args.target_spp, tuple(args.resolution),
                                     args.crop, args.crops, variant=variant)
            for k, (layers, metadata) in enumerate(crops):
                write_layers(f"{args.out}/example_{seed}_{k}.exr", layers, metadata)
            print(f"seed {seed}: {len(crops)} crops, {crops[0][1]['seconds']} s", file=sys.stderr)
    except BenchError as exc:
        print(f"mcbench.training: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
