"""The ``mcbench_visibility`` integrator: a per-sample direct-light visibility indicator.

RDFC (Rousselle et al. 2013) guides its filters with a *visibility* feature: per sample, 1 when
the direct-light sample at the first hit contributes, else 0 (the authors' code,
fbksd/fbksd-package ``denoisers/RDFC/src/multifilm.cpp`` F:123: ``R > 0`` for the sample's direct
light ``R``), averaged over a pixel's samples. This module gives Mitsuba 3 that indicator as an
AOV of a small sampling integrator that the renderer nests, with Mitsuba's ``position`` AOV, in the
``aov`` integrator of its *feature pass* (:mod:`mcbench.render.renderer`): a second ``mi.render``
of the same scene with the colour pass's spp and seed, so it traces the same camera rays.

Per camera ray (one sample) the indicator ``v`` in {0, 1} is

    v = 1  iff  the ray hits a surface  and  ds.pdf > 0  and  f_R(wi, wo) * W_R > 0

with ``(ds, W) = scene.sample_emitter_direction(si, u, test_visibility=True)`` one emitter
sample (one emitter picked by the scene's emitter sampling, then a point/direction on it; ``W`` is
``Le * G / pdf``, zero when the shadow ray is blocked) and ``f = bsdf.eval`` the first hit's BSDF
(cosine included) for that direction. So ``v`` is 1 exactly when the red channel of the
one-sample direct-light estimate ``R = f * W`` is positive, as the authors test it (fbksd-package
``denoisers/RDFC/src/multifilm.cpp:123``, ``R[0] > 0``; a test of any channel is the commented-out
line 122): a surface lit only in green and blue records 0, as theirs. Cases:

* miss (the ray leaves the scene, an environment map seen directly included): ``v = 0`` (the
  authors: a miss has ``R = 0``);
* a hit on an emitter surface: treated like any other surface (its own emission is not a direct
  light *sample*; its BSDF and the emitter sample decide);
* purely specular surfaces (mirror, glass, ``null`` medium boundaries): ``bsdf.eval`` is 0 for
  delta lobes, so ``v = 0``, as ``R = 0`` for light sampling in the authors' renderer;
* point and spot lights (delta positions), environment maps (the shadow ray to infinity) and area
  lights go through the same ``sample_emitter_direction``;
* participating media: the first hit is the first *surface* along the camera ray, the same one
  Mitsuba's ``aov`` integrator uses for depth and position (media between are ignored), and the
  shadow test is Mitsuba's ``ray_test`` -- geometric: any surface (a medium's ``null`` boundary
  too) blocks, media transmittance does not. Departure: the authors' renderer (pbrt-v2 based)
  does not render media with RDFC's features; we keep the indicator geometric so that it stays
  a 0/1 Bernoulli per sample.
* depth of field: the camera ray is the thin-lens ray the sensor generated; nothing changes.

Random numbers: the integrator draws one ``next_2d`` (the emitter sample) after the sensor's
samples; deterministic for a seed like the rest of the render. It runs in its own pass, so the
colour pass -- colour, albedo, normal, depth -- is bit-identical to a render without it
(``tests/render/test_features.py``). Returns zero radiance (its RGBA channels are unused) and the
indicator as its one AOV, :data:`AOV_NAME`. In scalar variants Mitsuba calls it from Python once
per sample (Mitsuba warns about the speed once); a miss returns early there (no BSDF to call).
"""

from __future__ import annotations

__all__ = ["PLUGIN", "AOV_NAME", "register", "direct_light_visible"]

PLUGIN = "mcbench_visibility"
AOV_NAME = "v"

def register() -> str:
    """Register the :data:`PLUGIN` integrator for Mitsuba's current variant (once per variant;
    call after the variant is set) and return the plugin name."""
    from mcbench.render.variants import register_integrator_once

    return register_integrator_once(PLUGIN, _integrator_class)


def direct_light_visible(scene, bsdf, si, sample, active):
    """RDFC's indicator at surface interaction ``si`` (module docstring): ``True`` where the one-sample
    direct-light estimate ``R = f(wi, wo) * W`` of emitter sample ``sample`` (a ``Point2f``) is
    positive in the red channel (the authors' test, module docstring), for the lanes of ``active``
    whose ``si`` is a hit (else ``False``).
    ``bsdf`` is ``si``'s BSDF. Shared by this module's integrator (the first hit) and
    :mod:`mcbench.render.path_features` (the first non-specular vertex)."""
    import drjit as dr
    import mitsuba as mi

    hit = mi.Bool(active) & si.is_valid()
    if not dr.is_jit_v(mi.Float) and not hit:
        return False
    ds, weight = scene.sample_emitter_direction(si, sample, True, hit)
    value = mi.unpolarized_spectrum(bsdf.eval(mi.BSDFContext(), si, si.to_local(ds.d), hit) * weight)
    positive = value[0] > 0
    return hit & (ds.pdf > 0) & positive


def _integrator_class():
    """The integrator class for the current variant (``mi.SamplingIntegrator`` is per variant)."""
    import drjit as dr
    import mitsuba as mi

    class VisibilityIntegrator(mi.SamplingIntegrator):
        """One emitter sample at the camera ray's first surface hit; AOV ``v`` in {0, 1}."""

        def __init__(self, props):
            super().__init__(props)

        def sample(self, scene, sampler, ray, medium=None, active=True):
            """``(0, True, [v])`` for one camera ray (module docstring: v = 1 iff R = f W > 0)."""
            si = scene.ray_intersect(mi.Ray3f(ray), active)
            hit = mi.Bool(active) & si.is_valid()
            sample = sampler.next_2d(hit)
            if not dr.is_jit_v(mi.Float) and not hit:     # scalar: a miss has no BSDF to call
                return mi.Spectrum(0.0), mi.Bool(True), [mi.Float(0.0)]
            visible = direct_light_visible(scene, si.bsdf(ray), si, sample, hit)
            return mi.Spectrum(0.0), mi.Bool(True), [dr.select(visible, mi.Float(1.0), mi.Float(0.0))]

        def aov_names(self):
            return [AOV_NAME]

        def to_string(self):
            return f"{PLUGIN}[]"

    return VisibilityIntegrator
