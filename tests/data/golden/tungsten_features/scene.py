"""Mitsuba 3 twin of ``tungsten_scene.json``: the scene behind the Tungsten feature goldens.

A 45-degree perfect mirror showing a red diffuse wall, a diffuse floor, a tilted quad area
light and open background (no environment), seen by a pinhole camera. Every shape is a quad;
``QUADS`` holds each one in Tungsten's terms (centre, ``edge0``, ``edge1``: Tungsten's ``quad``
is the unit square [-0.5, 0.5]^2 of its local xz plane, its points ``centre + s*edge0 + t*edge1``
for s, t in [-0.5, 0.5], its normal ``normalize(edge1 x edge0)``; README.md). Mitsuba's
``rectangle`` is [-1, 1]^2 in local z = 0 with normal +z, so the same quad is the ``to_world``
whose columns are ``edge1/2``, ``edge0/2``, the unit normal and the centre (local x, y, z, and
origin): the same point set, the same normal, a proper (right-handed) affine map.
"""

from __future__ import annotations

DESCRIPTION = ("Tungsten feature-buffer golden scene: 45-degree mirror showing a red diffuse "
               "wall, diffuse floor, quad area light, open background")
CATEGORY = "test"
RESOLUTION = (48, 48)

# Pinhole camera, y up. FOV_DEG is the horizontal field of view in degrees, for both renderers
# (Tungsten: PinholeCamera ``fov``, planeDist = 1/tan(fov/2) against x in [-1, 1]).
CAMERA_ORIGIN = (0.0, 1.6, 5.5)
CAMERA_TARGET = (0.0, 0.9, 0.0)
CAMERA_UP = (0.0, 1.0, 0.0)
FOV_DEG = 50.0

# Tungsten path_tracer max_bounces = Mitsuba max_depth (both 8). Tungsten (PathTracer.cpp, TraceBase.cpp
# handleSurface) visits surface vertices bounce = 0 .. max_bounces - 1, samples lights only where
# bounce < max_bounces - 1 and counts a hit emitter at any visited vertex: the emitter is at most the
# max_bounces-th intersection, as with Mitsuba's max_depth (1: directly visible emitters only; Tungsten
# max_bounces 1 likewise). The feature path examines the same max_bounces vertices (our max_vertices
# is the scene's max_depth, mcbench.render.renderer._max_vertices).
MAX_BOUNCES = 8

RED = (0.8, 0.05, 0.05)
FLOOR_ALBEDO = (0.5, 0.5, 0.5)
MIRROR_ALBEDO = (0.9, 0.9, 0.9)
LIGHT_ALBEDO = (0.5, 0.5, 0.5)  # the light quad's own (diffuse) BSDF
LIGHT_EMISSION = (6.0, 6.0, 6.0)

_S = 0.5 ** 0.5

# name: (centre, edge0, edge1, bsdf kind, albedo, emission or None)
QUADS = {
    # 5 x 5 floor at y = 0, normal +y (z x x = +y)
    "floor": ((0.0, 0.0, -0.5), (5.0, 0.0, 0.0), (0.0, 0.0, 5.0), "diffuse", FLOOR_ALBEDO, None),
    # red wall at x = -1.8, 4 deep (z in [-2.5, 1.5]) and 2 high, normal -x (z x y = -x): it faces
    # away from the scene, so the camera and the mirror see its back side (lit: two-sided shading);
    # the recorded normal must be the unflipped -x (Tungsten's info.Ns, Mitsuba's sh_frame.n)
    "wall": ((-1.8, 1.0, -0.5), (0.0, 2.0, 0.0), (0.0, 0.0, 4.0), "diffuse", RED, None),
    # 1.4 wide, 2 high (y in [0.2, 2.2]) vertical mirror turned 45 degrees about y, normal
    # (-1, 0, 1)/sqrt(2): camera rays (mostly -z) leave it towards -x, onto the red wall (its
    # top part reflects the open background above the wall)
    "mirror": ((1.0, 1.2, -0.5), (0.0, 2.0, 0.0), (1.4 * _S, 0.0, 1.4 * _S), "mirror",
               MIRROR_ALBEDO, None),
    # 1.2 x 1.2 light, normal (0, -0.8, 0.6): edge0 = 1.2*(-1,0,0), edge1 = 1.2*(0,0.6,0.8)
    "light": ((0.0, 2.6, -0.8), (-1.2, 0.0, 0.0), (0.0, 1.2 * 0.6, 1.2 * 0.8), "diffuse",
              LIGHT_ALBEDO, LIGHT_EMISSION),
}


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def quad_normal(name: str) -> tuple:
    """Unit normal of quad ``name``, Tungsten's ``normalize(edge1 x edge0)``."""
    _, e0, e1 = QUADS[name][:3]
    n = _cross(e1, e0)
    length = sum(c * c for c in n) ** 0.5
    return tuple(c / length for c in n)


def tungsten_matrix(name: str) -> list:
    """Row-major 4x4 ``transform`` of Tungsten's quad ``name`` (columns edge0, normal, edge1,
    centre: Quad::prepareForRender takes edge0 = T(1,0,0), edge1 = T(0,0,1))."""
    c, e0, e1 = QUADS[name][:3]
    n = quad_normal(name)
    return [e0[0], n[0], e1[0], c[0],
            e0[1], n[1], e1[1], c[1],
            e0[2], n[2], e1[2], c[2],
            0.0, 0.0, 0.0, 1.0]


def mitsuba_matrix(name: str) -> list:
    """Row-major 4x4 ``to_world`` of Mitsuba's rectangle for quad ``name`` (columns edge1/2,
    edge0/2, normal, centre)."""
    c, e0, e1 = QUADS[name][:3]
    n = quad_normal(name)
    return [[e1[0] / 2, e0[0] / 2, n[0], c[0]],
            [e1[1] / 2, e0[1] / 2, n[1], c[1]],
            [e1[2] / 2, e0[2] / 2, n[2], c[2]],
            [0.0, 0.0, 0.0, 1.0]]


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict at ``width`` x ``height`` pixels (the goldens are 48 x 48): path
    tracer with ``max_depth`` 8 (= Tungsten's max_bounces 8, see ``MAX_BOUNCES``), box
    pixel filter (Tungsten's ``reconstruction_filter`` "box"), every BSDF two-sided (Tungsten's
    default ``enable_two_sided_shading``), one-sided emission (as Tungsten's quad)."""
    import mitsuba as mi

    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": MAX_BOUNCES},
        "sensor": {
            "type": "perspective",
            "fov": FOV_DEG,
            "fov_axis": "x",
            "near_clip": 1e-3,
            "far_clip": 1e4,
            "to_world": mi.ScalarTransform4f().look_at(origin=list(CAMERA_ORIGIN),
                                                       target=list(CAMERA_TARGET),
                                                       up=list(CAMERA_UP)),
            "sampler": {"type": "independent", "sample_count": 16},
            "film": {"type": "hdrfilm", "width": int(width), "height": int(height),
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        },
    }
    for name, (_, _, _, kind, albedo, emission) in QUADS.items():
        if kind == "mirror":
            inner = {"type": "conductor", "material": "none",
                     "specular_reflectance": {"type": "rgb", "value": list(albedo)}}
        else:
            inner = {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(albedo)}}
        shape = {"type": "rectangle",
                 "to_world": mi.ScalarTransform4f(mitsuba_matrix(name)),
                 "bsdf": {"type": "twosided", "bsdf": inner}}
        if emission is not None:
            shape["emitter"] = {"type": "area",
                                "radiance": {"type": "rgb", "value": list(emission)}}
        scene[name] = shape
    return scene
