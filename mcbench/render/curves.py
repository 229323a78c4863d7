"""Hair curves and triangle meshes built from NumPy arrays, for scene dicts (test and training scenes).

Curves: Mitsuba 3.9.1's ``linearcurve`` and ``bsplinecurve`` plugins can only be constructed
from a file (the ``filename`` property is mandatory; ``control_points`` exists only as a
``mi.traverse`` parameter of an already loaded shape). :func:`curve_shape` therefore writes the
NumPy control points to a text file in a fresh temporary directory, loads the shape with
``mi.load_dict`` (the plugin reads the whole file in its constructor) and deletes the directory
before returning the loaded ``mi.Shape``. The file is generated at build time, never shipped.

File format read by both plugins: one control point per line, ``x y z radius``; an empty line
ends a curve.

Meshes: :func:`mesh_shape` makes an ``mi.Mesh`` from vertex / face (and optional UV, normal)
arrays through ``mi.traverse``; no file is involved.

Both return Mitsuba objects that can be placed directly as values of a scene dict.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

__all__ = ["curve_shape", "bspline_polyline", "mesh_shape", "grid_mesh", "hair_bsdf"]


def curve_shape(strands, radius, kind: str = "linearcurve", bsdf: dict | None = None,
                to_world=None):
    """A loaded ``linearcurve`` / ``bsplinecurve`` shape from NumPy control points.

    ``strands``: list of (n_i, 3) arrays (one per curve, n_i >= 2; >= 4 for ``bsplinecurve``)
    or one (N, n, 3) array. ``radius``: scalar, or a list / array matching ``strands`` with one
    radius per control point ((n_i,) each). ``bsdf``: a BSDF dict (e.g. :func:`hair_bsdf`).
    """
    import mitsuba as mi

    if kind not in ("linearcurve", "bsplinecurve"):
        raise ValueError(f"kind must be 'linearcurve' or 'bsplinecurve', got {kind!r}")
    lines = []
    for index, points in enumerate(strands):
        points = np.asarray(points, dtype=np.float64)
        if np.isscalar(radius):
            radii = np.full(len(points), float(radius))
        else:
            radii = np.broadcast_to(np.asarray(radius[index], dtype=np.float64), (len(points),))
        block = np.column_stack([points, radii])
        lines.append("\n".join(" ".join(f"{v:.7g}" for v in row) for row in block))
    text = "\n\n".join(lines) + "\n"
    desc = {"type": kind}
    if bsdf is not None:
        desc["bsdf"] = bsdf
    if to_world is not None:
        desc["to_world"] = to_world
    with tempfile.TemporaryDirectory(prefix="mcbench_curves_") as folder:
        path = os.path.join(folder, "strands.txt")
        with open(path, "w") as handle:
            handle.write(text)
        desc["filename"] = path
        return mi.load_dict(desc)


def bspline_polyline(points, samples_per_span: int = 3) -> np.ndarray:
    """Points on the uniform cubic B-spline of control points ``points`` (..., n, 3), n >= 4:
    ``samples_per_span`` per span plus the end point, shape (..., (n-3)*samples_per_span+1, 3).

    Used to draw smooth strands with ``linearcurve``: in Mitsuba 3.9.1 (llvm_ad_rgb) a
    ``bsplinecurve`` of helical strands segfaulted for some sample seeds, linear segments did not.
    """
    p = np.asarray(points, dtype=np.float64)
    n = p.shape[-2]
    t = np.linspace(0.0, 1.0, samples_per_span, endpoint=False)
    basis = np.stack([(1 - t) ** 3, 3 * t ** 3 - 6 * t ** 2 + 4, -3 * t ** 3 + 3 * t ** 2 + 3 * t + 1,
                      t ** 3], axis=1) / 6.0                                   # (s, 4)
    spans = np.stack([p[..., i:i + 4, :] for i in range(n - 3)], axis=-3)      # (..., n-3, 4, 3)
    out = np.einsum("sk,...jkc->...jsc", basis, spans)
    out = out.reshape(*p.shape[:-2], (n - 3) * samples_per_span, 3)
    end = (p[..., -3, :] + 4 * p[..., -2, :] + p[..., -1, :]) / 6.0
    return np.concatenate([out, end[..., None, :]], axis=-2)


def mesh_shape(name: str, vertices, faces, *, uv=None, normals=None, bsdf: dict | None = None,
               emitter: dict | None = None, interior: dict | None = None):
    """An ``mi.Mesh`` from arrays: ``vertices`` (V, 3) float, ``faces`` (F, 3) int, optional
    ``uv`` (V, 2) and ``normals`` (V, 3) (without normals the mesh is flat shaded)."""
    import mitsuba as mi

    vertices = np.ascontiguousarray(vertices, dtype=np.float32)
    faces = np.ascontiguousarray(faces, dtype=np.uint32)
    props = mi.Properties()
    if bsdf is not None:
        props["bsdf"] = mi.load_dict(bsdf)
    if emitter is not None:
        props["emitter"] = mi.load_dict(emitter)
    if interior is not None:
        props["interior"] = mi.load_dict(interior)
    mesh = mi.Mesh(name, len(vertices), len(faces), props=props,
                   has_vertex_normals=normals is not None, has_vertex_texcoords=uv is not None)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(vertices.ravel())
    params["faces"] = mi.UInt32(faces.ravel())
    if uv is not None:
        params["vertex_texcoords"] = mi.Float(np.ascontiguousarray(uv, dtype=np.float32).ravel())
    if normals is not None:
        n = np.asarray(normals, dtype=np.float64)
        n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        params["vertex_normals"] = mi.Float(n.astype(np.float32).ravel())
    params.update()
    return mesh


def grid_mesh(heights, size_x: float, size_z: float):
    """Vertices, faces, UVs and smooth normals of a heightfield on the XZ plane.

    ``heights`` (nz, nx): y values on a regular grid spanning ``[-size_x/2, size_x/2]`` x
    ``[-size_z/2, size_z/2]``. Faces are wound so that normals point to +y.
    """
    heights = np.asarray(heights, dtype=np.float64)
    nz, nx = heights.shape
    x = np.linspace(-size_x / 2, size_x / 2, nx)
    z = np.linspace(-size_z / 2, size_z / 2, nz)
    xx, zz = np.meshgrid(x, z)
    vertices = np.stack([xx, heights, zz], axis=-1).reshape(-1, 3)
    uu, vv = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, nz))
    uv = np.stack([uu, vv], axis=-1).reshape(-1, 2)
    i = np.arange(nz - 1)[:, None] * nx + np.arange(nx - 1)[None, :]
    i = i.ravel()
    faces = np.concatenate([np.stack([i, i + nx, i + 1], axis=1),
                            np.stack([i + 1, i + nx, i + nx + 1], axis=1)])
    # Smooth normals from central differences of the height field.
    dhdx = np.gradient(heights, x, axis=1)
    dhdz = np.gradient(heights, z, axis=0)
    normals = np.stack([-dhdx, np.ones_like(heights), -dhdz], axis=-1).reshape(-1, 3)
    return vertices, faces, uv, normals


def hair_bsdf(eumelanin: float = 1.3, pheomelanin: float = 0.2, longitudinal: float = 0.3,
              azimuthal: float = 0.3) -> dict:
    """The ``hair`` BSDF (Chiang et al. 2016) with melanin concentrations and roughnesses."""
    return {"type": "hair", "eumelanin": eumelanin, "pheomelanin": pheomelanin,
            "longitudinal_roughness": longitudinal, "azimuthal_roughness": azimuthal}
