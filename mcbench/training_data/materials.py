"""Random materials, procedural NumPy textures and light colours of the training scenes.

All draws come from the generator's ``rng`` (:mod:`mcbench.training_data.generator`), so they
are reproducible per scene seed. Materials: diffuse, smooth or rough conductor (named metals
of :data:`METALS` or RGB reflectance), smooth or rough dielectric, smooth or rough plastic,
principled; diffuse-like colours are often NumPy procedural textures (checkers, stripes,
sinusoid noise) tiled with a random ``to_uv``.
"""

from __future__ import annotations

import numpy as np

from mcbench.render.geometry import bitmap_texture, rgb

__all__ = ["METALS", "texture_array", "color_or_texture", "random_material", "two_sided",
           "light_color"]

METALS = ("Au", "Ag", "Al", "Cu", "Cr", "W", "Ir", "Mo", "Rh", "TiN")


def texture_array(rng: np.random.Generator, size: int = 128) -> tuple[str, np.ndarray]:
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


def color_or_texture(rng: np.random.Generator, textured: float = 0.45) -> dict:
    """A reflectance: with probability ``textured`` a tiled procedural :func:`texture_array`
    bitmap (1..6 tiles, bilinear or nearest), else an RGB colour in [0.03, 0.85]."""
    import mitsuba as mi

    if rng.random() < textured:
        _, image = texture_array(rng)
        tile = float(rng.uniform(1, 6))
        return bitmap_texture(image, filter_type=str(rng.choice(["bilinear", "nearest"])),
                              to_uv=mi.ScalarTransform4f().scale([tile, tile, 1]))
    return rgb(rng.uniform(0.03, 0.85, 3))


def random_material(rng: np.random.Generator) -> dict:
    """A random BSDF dict (two-sided where it matters for open shapes)."""
    kind = str(rng.choice(["diffuse", "diffuse", "conductor", "roughconductor", "dielectric",
                           "roughdielectric", "plastic", "roughplastic", "principled"]))
    alpha = float(np.exp(rng.uniform(np.log(0.03), np.log(0.5))))
    if kind == "diffuse":
        bsdf = {"type": "diffuse", "reflectance": color_or_texture(rng)}
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
        bsdf = {"type": kind, "diffuse_reflectance": color_or_texture(rng),
                "int_ior": float(rng.uniform(1.4, 1.7))}
        if kind == "roughplastic":
            bsdf.update(distribution="ggx", alpha=alpha)
    else:
        bsdf = {"type": "principled", "base_color": color_or_texture(rng),
                "metallic": float(rng.choice([0.0, rng.uniform(0, 1), 1.0])),
                "roughness": float(rng.uniform(0.05, 0.9)),
                "specular": float(rng.uniform(0.2, 0.8))}
    return bsdf


def two_sided(bsdf: dict) -> dict:
    """Open surfaces (rectangles, disks, cylinders) seen from behind: wrap non-transmissive BSDFs."""
    if bsdf["type"] in ("dielectric", "roughdielectric"):
        return bsdf
    return {"type": "twosided", "bsdf": bsdf}


def light_color(rng: np.random.Generator) -> np.ndarray:
    """An emission colour (3,) between warm and cool white, normalised to mean 1."""
    warm, cool = np.array([1.0, 0.78, 0.55]), np.array([0.75, 0.87, 1.0])
    t = rng.uniform()
    color = (1 - t) * warm + t * cool
    return color / color.mean()
