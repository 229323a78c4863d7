"""Building blocks of Python-built Mitsuba scene dicts (no files anywhere).

Core, not a scene: the test scenes (``scenes/*.py``) and the procedural training scenes
(:mod:`mcbench.training_data`) both build on these. Call them only after a Mitsuba variant is
set (e.g. inside a scene's ``build``):

* :func:`rgb` -- ``{"type": "rgb", "value": [...]}``;
* :func:`diffuse` -- a diffuse BSDF dict of an RGB colour or a texture dict;
* :func:`bitmap_texture` -- a ``bitmap`` texture dict from a NumPy array (linear values);
* :func:`mesh_from_arrays` -- a ``mi.Mesh`` from vertex/face (and optional normal/uv) arrays,
  usable directly as a value in a scene dict;
* :func:`lathe` -- vertices/faces/uv of a surface of revolution (vases, lamp shades, teapot
  bodies), to feed :func:`mesh_from_arrays`;
* :func:`gradient_sky` -- a lat-long HDR sky array (horizon-to-zenith gradient, ground, optional
  Gaussian sun) for ``{"type": "envmap", "bitmap": mi.Bitmap(array)}``;
* :func:`perspective_sensor` -- a pinhole camera dict with an ``hdrfilm``;
* :func:`thinlens_sensor` -- like :func:`perspective_sensor`, with a thin lens;
* :func:`quad` -- a ``rectangle`` dict from a centre and two half-edge vectors;
* :func:`box` -- a ``cube`` dict from a centre, half sizes and a rotation about +Y;
* :func:`torus` -- vertices/faces/normals/uv of a torus about +Y (handles, rings).

All arrays are NumPy; everything is deterministic given its arguments.
"""

from __future__ import annotations

import numpy as np

__all__ = ["rgb", "diffuse", "bitmap_texture", "mesh_from_arrays", "lathe", "gradient_sky",
           "perspective_sensor", "thinlens_sensor", "quad", "box", "torus"]


def rgb(*value) -> dict:
    """``rgb(0.5)`` or ``rgb(0.2, 0.3, 0.4)`` or ``rgb([0.2, 0.3, 0.4])`` -> an ``rgb`` dict."""
    if len(value) == 1:
        value = value[0]
    values = np.broadcast_to(np.asarray(value, dtype=float), (3,))
    return {"type": "rgb", "value": [float(v) for v in values]}


def diffuse(color) -> dict:
    """Diffuse BSDF dict; ``color`` is a scalar, an RGB triple or a texture dict."""
    reflectance = color if isinstance(color, dict) else rgb(color)
    return {"type": "diffuse", "reflectance": reflectance}


def bitmap_texture(array, filter_type: str = "bilinear", wrap_mode: str = "repeat",
                   raw: bool = False, to_uv=None) -> dict:
    """``bitmap`` texture dict from an (H, W), (H, W, 1) or (H, W, 3) array of linear values.

    Row 0 of the array is the top of the image (v = 0 in Mitsuba's convention, which flips v:
    uv (0, 0) is the array's first row). ``filter_type`` is ``"bilinear"`` or ``"nearest"``;
    ``raw=True`` for data that is not a colour (normal maps); ``to_uv`` a
    ``mi.ScalarTransform4f`` (e.g. ``scale([8, 8, 1])`` to tile the texture 8 times).
    """
    import mitsuba as mi

    data = np.ascontiguousarray(array, dtype=np.float32)
    if data.ndim == 3 and data.shape[2] == 1:
        data = data[..., 0]
    texture = {"type": "bitmap", "bitmap": mi.Bitmap(data), "filter_type": filter_type,
               "wrap_mode": wrap_mode, "raw": bool(raw)}
    if to_uv is not None:
        texture["to_uv"] = to_uv
    return texture


def mesh_from_arrays(vertices, faces, normals=None, uv=None, bsdf: dict | None = None,
                     emitter: dict | None = None, name: str = "mesh", to_world=None):
    """A triangle ``mi.Mesh`` (put it straight into a scene dict) from NumPy arrays.

    ``vertices`` (V, 3) float positions, ``faces`` (F, 3) integer vertex indices
    (counter-clockwise seen from the front), optional ``normals`` (V, 3) per-vertex shading
    normals and ``uv`` (V, 2) texture coordinates; ``bsdf`` / ``emitter`` are Mitsuba dicts;
    ``to_world`` an optional ``mi.ScalarTransform4f`` applied to positions and normals here.
    Without normals the mesh is flat-shaded (face normals).
    """
    import drjit as dr
    import mitsuba as mi

    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    n = None if normals is None else np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"mesh '{name}': face indices out of range 0..{len(v) - 1}")
    if to_world is not None:
        matrix = np.array(to_world.matrix, dtype=np.float64).reshape(4, 4)
        v = v @ matrix[:3, :3].T + matrix[:3, 3]
        if n is not None:
            n = n @ np.linalg.inv(matrix[:3, :3])      # inverse transpose, row vectors
    if n is not None:
        n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    props = mi.Properties()
    if bsdf is not None:
        props["bsdf"] = mi.load_dict(bsdf)
    if emitter is not None:
        props["emitter"] = mi.load_dict(emitter)
    mesh = mi.Mesh(name, len(v), len(f), props=props, has_vertex_normals=n is not None,
                   has_vertex_texcoords=uv is not None)
    params = mi.traverse(mesh)
    params["vertex_positions"] = dr.ravel(mi.Point3f(*[v[:, i].astype(np.float32) for i in range(3)]))
    params["faces"] = mi.UInt32(f.astype(np.uint32).ravel())
    if n is not None:
        params["vertex_normals"] = dr.ravel(mi.Normal3f(*[n[:, i].astype(np.float32)
                                                         for i in range(3)]))
    if uv is not None:
        t = np.asarray(uv, dtype=np.float32).reshape(-1, 2)
        params["vertex_texcoords"] = dr.ravel(mi.Point2f(t[:, 0], t[:, 1]))
    params.update()
    return mesh


def lathe(radius, height, segments: int = 32, cap_bottom: bool = True, cap_top: bool = False):
    """Surface of revolution about +Y: ``(vertices, faces, normals, uv)`` arrays.

    ``radius`` and ``height`` are equal-length 1-D profiles (bottom to top, radius >= 0);
    ``segments`` steps around the axis. Smooth per-vertex normals come from the profile
    tangent. Caps are flat discs at the first/last profile point.
    """
    r = np.asarray(radius, dtype=np.float64)
    y = np.asarray(height, dtype=np.float64)
    rows = len(r)
    phi = np.linspace(0.0, 2 * np.pi, segments + 1)          # seam duplicated for the uv
    cos, sin = np.cos(phi)[None, :], np.sin(phi)[None, :]
    vertices = np.stack([r[:, None] * cos, np.broadcast_to(y[:, None], (rows, segments + 1)),
                         r[:, None] * sin], axis=-1).reshape(-1, 3)
    dr_ = np.gradient(r)
    dy = np.gradient(y)
    # Outward normal of the profile curve (r(t), y(t)) is (dy, -dr) in the (radial, y) plane.
    nr, ny = dy, -dr_
    length = np.maximum(np.hypot(nr, ny), 1e-12)
    nr, ny = nr / length, ny / length
    normals = np.stack([nr[:, None] * cos, np.broadcast_to(ny[:, None], (rows, segments + 1)),
                        nr[:, None] * sin], axis=-1).reshape(-1, 3)
    uv = np.stack(np.meshgrid(phi / (2 * np.pi), np.linspace(0, 1, rows)), axis=-1).reshape(-1, 2)
    faces = []
    width = segments + 1
    for i in range(rows - 1):
        for j in range(segments):
            a, b = i * width + j, i * width + j + 1
            c, d = a + width, b + width
            faces += [(a, c, b), (b, c, d)]          # counter-clockwise seen from outside
    vertices, normals, uv = list(vertices), list(normals), list(uv)
    for cap, index, sign in ((cap_bottom, 0, -1.0), (cap_top, rows - 1, 1.0)):
        if not cap or r[index] <= 0:
            continue
        center = len(vertices)
        vertices.append((0.0, y[index], 0.0))
        normals.append((0.0, sign, 0.0))
        uv.append((0.5, 0.5))
        ring = []
        for j in range(segments):
            ring.append(len(vertices))
            vertices.append((r[index] * np.cos(phi[j]), y[index], r[index] * np.sin(phi[j])))
            normals.append((0.0, sign, 0.0))
            uv.append((0.5 + 0.5 * np.cos(phi[j]), 0.5 + 0.5 * np.sin(phi[j])))
        for j in range(segments):
            a, b = ring[j], ring[(j + 1) % segments]
            faces.append((center, a, b) if sign > 0 else (center, b, a))
    return (np.array(vertices), np.array(faces, dtype=np.int64), np.array(normals),
            np.array(uv))


def gradient_sky(height: int = 64, zenith=(0.2, 0.35, 0.85), horizon=(1.0, 0.95, 0.9),
                 ground=(0.22, 0.18, 0.14), sun_elevation_deg: float | None = None,
                 sun_azimuth_deg: float = 0.0, sun_radius_deg: float = 2.5,
                 sun_radiance: float = 0.0, sun_color=(1.0, 0.92, 0.8)) -> np.ndarray:
    """Lat-long HDR sky, float32 (height, 2*height, 3), linear radiance, for Mitsuba's
    ``envmap`` (row 0 = zenith = +Y, last row = nadir).

    Above the horizon ``horizon`` blends to ``zenith`` (with sqrt(sin(elevation))); below it a
    constant ``ground``. With ``sun_elevation_deg`` set and ``sun_radiance`` > 0, a Gaussian
    sun blob (sigma ``sun_radius_deg``) is added at that elevation and at azimuth
    ``sun_azimuth_deg`` (0 deg = +X, 90 deg = +Z, in the envmap's own frame).
    """
    width = 2 * height
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    elevation = (0.5 - v) * np.pi
    up = np.clip(np.sin(elevation), 0.0, 1.0)[:, None] ** 0.5
    sky = (1 - up[..., None]) * np.asarray(horizon) + up[..., None] * np.asarray(zenith)
    env = np.where((elevation > 0)[:, None, None], sky, np.asarray(ground)) * np.ones((1, width, 1))
    if sun_elevation_deg is not None and sun_radiance > 0:
        theta = elevation[:, None]
        phi = 2 * np.pi * u[None, :]
        direction = np.stack(np.broadcast_arrays(np.cos(theta) * np.cos(phi), np.sin(theta),
                                                 np.cos(theta) * np.sin(phi)), axis=-1)
        st, sp = np.radians(sun_elevation_deg), np.radians(sun_azimuth_deg)
        sun = np.array([np.cos(st) * np.cos(sp), np.sin(st), np.cos(st) * np.sin(sp)])
        angle = np.arccos(np.clip(direction @ sun, -1.0, 1.0))
        blob = np.exp(-0.5 * (angle / np.radians(sun_radius_deg)) ** 2)
        env = env + sun_radiance * blob[..., None] * np.asarray(sun_color)
    return np.ascontiguousarray(env, dtype=np.float32)


def perspective_sensor(width: int, height: int, origin, target, up=(0, 1, 0),
                       fov: float = 40.0) -> dict:
    """A pinhole camera dict looking from ``origin`` to ``target`` (world units), ``fov`` in
    degrees along the smaller image axis, with an ``hdrfilm`` of ``width`` x ``height`` pixels."""
    import mitsuba as mi

    return {
        "type": "perspective",
        "fov": fov,
        "fov_axis": "smaller",
        "to_world": mi.ScalarTransform4f().look_at(origin=list(origin), target=list(target),
                                                   up=list(up)),
        "sampler": {"type": "independent", "sample_count": 16},
        "film": {"type": "hdrfilm", "width": int(width), "height": int(height),
                 "pixel_format": "rgb", "component_format": "float32",
                 "rfilter": {"type": "gaussian"}},
    }


def thinlens_sensor(width: int, height: int, origin, target, up=(0, 1, 0), fov: float = 40.0,
                    aperture_radius: float = 0.05, focus_distance: float | None = None) -> dict:
    """A ``thinlens`` camera dict (depth of field) with an ``hdrfilm`` of ``width`` x ``height``;
    ``focus_distance`` defaults to the distance from ``origin`` to ``target``."""
    sensor = perspective_sensor(width, height, origin, target, up=up, fov=fov)
    if focus_distance is None:
        focus_distance = float(np.linalg.norm(np.subtract(target, origin)))
    sensor.update(type="thinlens", aperture_radius=float(aperture_radius),
                  focus_distance=float(focus_distance))
    return sensor


def quad(center, u, v, bsdf: dict | None = None, emitter: dict | None = None) -> dict:
    """A ``rectangle`` dict spanning ``center +- u +- v`` (``u``, ``v`` orthogonal half-edge
    vectors, world units). Its front face (the side a diffuse BSDF shades and an area emitter
    lights) points along ``u x v``."""
    import mitsuba as mi

    u, v, c = (np.asarray(x, dtype=np.float64) for x in (u, v, center))
    n = np.cross(u, v)
    n = n / np.linalg.norm(n)
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = u, v, n, c
    shape = {"type": "rectangle", "to_world": mi.ScalarTransform4f(matrix.tolist())}
    if bsdf is not None:
        shape["bsdf"] = bsdf
    if emitter is not None:
        shape["emitter"] = emitter
    return shape


def box(center, half_size, bsdf: dict | None = None, rotate_y_deg: float = 0.0) -> dict:
    """A ``cube`` dict centred at ``center`` with half extents ``half_size`` (scalar or 3),
    rotated by ``rotate_y_deg`` degrees about the vertical axis."""
    import mitsuba as mi

    half = np.broadcast_to(np.asarray(half_size, dtype=float), (3,))
    to_world = (mi.ScalarTransform4f().translate([float(x) for x in center])
                .rotate([0, 1, 0], float(rotate_y_deg)).scale([float(x) for x in half]))
    shape = {"type": "cube", "to_world": to_world}
    if bsdf is not None:
        shape["bsdf"] = bsdf
    return shape


def torus(major: float, minor: float, segments: int = 32, ring_segments: int = 12,
          arc: float = 2 * np.pi):
    """Torus about +Y centred at the origin: ``(vertices, faces, normals, uv)`` arrays.

    ``major`` is the ring radius, ``minor`` the tube radius; ``arc`` < 2 pi gives an open
    partial ring (e.g. pi for a handle), starting at +X and turning towards +Z.
    """
    closed = np.isclose(arc, 2 * np.pi)
    count = segments if closed else segments + 1
    phi = np.arange(count) * arc / segments
    theta = np.arange(ring_segments) * 2 * np.pi / ring_segments
    P, Th = np.meshgrid(phi, theta, indexing="ij")
    normals = np.stack([np.cos(Th) * np.cos(P), np.sin(Th), np.cos(Th) * np.sin(P)], axis=-1)
    centers = np.stack([major * np.cos(P), np.zeros_like(P), major * np.sin(P)], axis=-1)
    vertices = (centers + minor * normals).reshape(-1, 3)
    faces = []
    for i in range(segments):
        i2 = (i + 1) % count
        for j in range(ring_segments):
            j2 = (j + 1) % ring_segments
            a, b = i * ring_segments + j, i * ring_segments + j2
            c, d = i2 * ring_segments + j, i2 * ring_segments + j2
            faces += [(a, b, c), (b, d, c)]
    uv = np.stack([P / arc, Th / (2 * np.pi)], axis=-1).reshape(-1, 2)
    return vertices, np.array(faces, dtype=np.int64), normals.reshape(-1, 3), uv
