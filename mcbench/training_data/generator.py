"""Seeded procedural training scenes: :func:`random_scene`.

:func:`random_scene` draws, from ``numpy.random.default_rng((SCENE_SALT, seed))``:

* a setting: a closed ``room`` (floor, four walls, ceiling; sometimes with the ceiling or one
  wall missing so that a sky gets in), a ``floor`` under an open sky, or objects floating in
  the ``open`` under an environment map;
* 2-7 objects: spheres, cubes, open cylinders, rectangles, disks, and NumPy meshes (torus,
  lathe vase, noise-displaced blob), each with a random material
  (:mod:`mcbench.training_data.materials`);
* 1-3 lights: area rectangles, sphere lights, point and spot lights, and (always when the sky
  is visible) an ``envmap`` made from a NumPy gradient sky with a Gaussian sun blob;
* a camera on a random orbit around the objects (distance, elevation, azimuth, fov), a thin
  lens with random aperture focused on one object in 30 % of the scenes;
* a ``path`` integrator with ``max_depth`` in 4..16.

Seeds from :data:`mcbench.render.seeds.FIBRE_SEED_BASE` on are fibre scenes: the same draw plus
clumps of thin fibres (:mod:`mcbench.training_data.fibres`).

Only the core building blocks :mod:`mcbench.render.geometry` and :mod:`mcbench.render.curves` are used, never
a test scene of ``scenes/``.
"""

from __future__ import annotations

import numpy as np

from mcbench import BenchError
from mcbench.render.geometry import (gradient_sky, lathe, mesh_from_arrays, perspective_sensor, quad,
                                     thinlens_sensor, torus)
from mcbench.render.seeds import MAX_TRAINING_SEED, is_fibre_seed
from mcbench.training_data.fibres import FIBRE_SALT, add_fibre_clumps
from mcbench.training_data.materials import (color_or_texture, light_color, random_material,
                                             two_sided)
from mcbench.render.variants import pick_variant

__all__ = ["SCENE_SALT", "random_scene"]

SCENE_SALT = 0x7A1D5CE7         # mixed into the scene RNG so scene streams are their own


def _rotation(rng: np.random.Generator):
    import mitsuba as mi

    axis = rng.normal(size=3)
    axis /= max(np.linalg.norm(axis), 1e-9)
    return mi.ScalarTransform4f().rotate([float(a) for a in axis], float(rng.uniform(0, 360)))


def _blob(rng: np.random.Generator, segments: int = 48, rows: int = 24):
    """Unit sphere (lathe) displaced radially by a smooth random field: flat-shaded arrays."""
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

    T = mi.ScalarTransform4f
    kind = str(rng.choice(["sphere", "sphere", "cube", "cylinder", "rectangle", "disk", "mesh"]))
    bsdf = random_material(rng)
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
        return {"type": "cylinder", "radius": radius, "bsdf": two_sided(bsdf),
                "to_world": T().translate(c) @ _rotation(rng) @ T().translate([0, 0, -length / 2])
                .scale([1, 1, length])}
    if kind in ("rectangle", "disk"):
        scale = [float(size * rng.uniform(0.6, 1.4)), float(size * rng.uniform(0.6, 1.4)), 1.0]
        return {"type": kind, "bsdf": two_sided(bsdf),
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
        bsdf = two_sided(bsdf)
    else:
        v, f, uv = _blob(rng)
        n = None
        scale = size / 1.35
    to_world = T().translate(c) @ _rotation(rng) @ T().scale(float(scale))
    return mesh_from_arrays(v, f, normals=n, uv=uv, bsdf=bsdf, name=f"mesh_{index}",
                            to_world=to_world)


def _room(rng: np.random.Generator, half: float, height: float, open_side: str | None) -> dict:
    """Inward-facing floor, walls and ceiling of a room (``open_side`` names one left out)."""
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
            bsdf = random_material(rng) if rng.random() < 0.3 else {
                "type": "diffuse", "reflectance": color_or_texture(rng, textured=0.8)}
        elif rng.random() < 0.25:
            bsdf = {"type": "diffuse", "reflectance": color_or_texture(rng, textured=0.7)}
        else:
            tint = wall_color * rng.uniform(0.8, 1.2, 3)
            bsdf = {"type": "diffuse", "reflectance": {"type": "rgb",
                                                       "value": [float(x) for x in np.clip(tint, 0.05, 0.9)]}}
        if bsdf["type"] in ("dielectric", "roughdielectric"):
            bsdf = {"type": "diffuse", "reflectance": color_or_texture(rng)}
        out[name] = quad(center, u, v, bsdf=bsdf)
    return out


def _envmap(rng: np.random.Generator) -> dict:
    import mitsuba as mi

    sun = rng.random() < 0.7
    sky = gradient_sky(height=64, zenith=rng.uniform(0.05, 0.5, 3) * [0.6, 0.8, 1.2],
                       horizon=rng.uniform(0.4, 1.0, 3), ground=rng.uniform(0.05, 0.35, 3),
                       sun_elevation_deg=float(rng.uniform(8, 75)) if sun else None,
                       sun_azimuth_deg=float(rng.uniform(0, 360)),
                       sun_radius_deg=float(rng.uniform(1.5, 5.0)),
                       sun_radiance=float(np.exp(rng.uniform(np.log(30), np.log(600)))) if sun else 0.0,
                       sun_color=light_color(rng))
    return {"type": "envmap", "bitmap": mi.Bitmap(sky), "scale": float(rng.uniform(0.5, 2.0)),
            "to_world": mi.ScalarTransform4f().rotate([0, 1, 0], float(rng.uniform(0, 360)))}


def _lights(rng: np.random.Generator, count: int, top: float, target) -> dict:
    """``count`` random local lights around the objects; ``top`` caps their height."""
    import mitsuba as mi

    out = {}
    for i in range(count):
        kind = str(rng.choice(["area", "area", "sphere", "point", "spot"]))
        azimuth = rng.uniform(0, 2 * np.pi)
        radius = rng.uniform(0.5, 3.0)
        y = float(min(top - 0.05, rng.uniform(1.8, 4.0)))
        position = np.array([radius * np.cos(azimuth), y, radius * np.sin(azimuth)])
        distance = float(np.linalg.norm(position - np.asarray(target)))
        color = light_color(rng) * float(np.exp(rng.uniform(np.log(0.4), np.log(2.5))))
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


def _ensure_variant() -> None:
    import mitsuba as mi

    if mi.variant() is None:
        pick_variant("auto")


def _place_objects(rng, setting: str, scene: dict) -> tuple[list, np.ndarray]:
    """Objects in a disc of radius ~1.6 around the origin, resting on y = 0 (or floating), added
    to ``scene``: ``(their centres, the camera's target)``."""
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
    return centers, target


def _orbit_camera(rng, target: np.ndarray) -> tuple[float, np.ndarray, float]:
    """A camera on an orbit around ``target``: ``(distance, origin, field of view)``."""
    distance = float(rng.uniform(3.0, 5.0))
    elevation = np.radians(rng.uniform(3, 45))
    azimuth = rng.uniform(0, 2 * np.pi)
    origin = target + distance * np.array([np.cos(elevation) * np.cos(azimuth), np.sin(elevation),
                                           np.cos(elevation) * np.sin(azimuth)])
    origin[1] = max(origin[1], 0.15)
    return distance, origin, float(rng.uniform(25, 60))


def _surroundings(rng, setting: str, origin: np.ndarray, target: np.ndarray, scene: dict) -> None:
    """The setting's room or floor, the lights and, where the sky is visible, the environment
    map, added to ``scene``."""
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
            bsdf = (random_material(rng) if rng.random() < 0.3 else
                    {"type": "diffuse", "reflectance": color_or_texture(rng, textured=0.7)})
            if bsdf["type"] in ("dielectric", "roughdielectric"):
                bsdf = {"type": "diffuse", "reflectance": color_or_texture(rng)}
            scene["floor"] = quad((0, 0, 0), (20, 0, 0), (0, 0, -20), bsdf=bsdf)
    local_lights = int(rng.integers(1, 4)) if not sky_visible else int(rng.integers(0, 3))
    scene.update(_lights(rng, local_lights, top, target))
    if sky_visible:
        scene["environment"] = _envmap(rng)


def random_scene(seed: int, width: int, height: int) -> dict:
    """A complete Mitsuba scene dict (integrator and ``perspective``/``thinlens`` sensor
    included, film ``width`` x ``height``) drawn from ``seed``; see the module docstring.
    Sets a Mitsuba variant (``pick_variant("auto")``) when none is set."""
    _ensure_variant()
    seed = int(seed)
    if not 0 <= seed <= MAX_TRAINING_SEED:
        raise BenchError(f"training seed {seed} out of range 0..{MAX_TRAINING_SEED}")
    rng = np.random.default_rng((SCENE_SALT, seed))
    setting = str(rng.choice(["room", "room", "floor", "open"]))
    scene: dict = {"type": "scene",
                   "integrator": {"type": "path", "max_depth": int(rng.integers(4, 17))}}
    centers, target = _place_objects(rng, setting, scene)
    distance, origin, fov = _orbit_camera(rng, target)
    _surroundings(rng, setting, origin, target, scene)
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
        add_fibre_clumps(np.random.default_rng((FIBRE_SALT, seed)), scene, target, distance, fov, centers)
    return scene
