"""The ``mcbench_path_features`` integrator: features at the first non-specular vertex, as Tungsten records them.

The ensemble paper's bases were run on renders of Tungsten (Bitterli's renderer: the paper's
scenes, NFOR and KPCN's training data), whose path tracer writes its feature buffers at the first
vertex of the path that is *not specular* (tunabrain/tungsten at 88ea020,
``src/core/integrators/path_tracer/PathTracer.cpp`` L78-96: ``!wasSpecular || terminate``, and
L133-140 for paths that leave the scene); fbksd's RDFC driver asks for the same (its ``_NS``
features, "first non-specular"), and OIDN's documentation for its albedo and normal through mirrors
and glass. This integrator gives Mitsuba 3 those features as AOVs of one sampling integrator that
the renderer runs as the *feature pass* of a render (:mod:`mcbench.render.renderer`,
``features: tungsten``): a second ``mi.render`` with the colour pass's spp and seed, so it starts
from the colour pass's camera rays (same pixel positions, lens and time samples) and the colour
pass stays bit-identical.

Per camera sample, the path is followed from the camera ray, vertex ``k = 0, 1, ...``:

* at a surface vertex the BSDF is sampled once (``bsdf.sample``, one ``next_1d`` and one
  ``next_2d``). A *null* event (Mitsuba's ``null`` BSDF and the transparent part of ``mask``:
  Tungsten's forward/transparency event, ``TraceBase.cpp`` L529-534) leaves ``was_specular`` as
  it was; otherwise ``was_specular`` = the sampled lobe is a delta lobe (``DeltaReflection`` or
  ``DeltaTransmission``; Tungsten: ``event.sampledLobe.hasSpecular()``, L556). So a smooth
  plastic records at the vertex when its diffuse lobe is sampled and follows the coat's mirror
  reflection otherwise, per sample, as Tungsten does. ``terminate`` is a failed BSDF sample
  (zero pdf or weight; Tungsten's ``handleSurface`` returning false).
* the vertex is *recorded* when ``not was_specular or terminate``, with

  - ``depth``: the summed hit distance ``sum_k t_k`` of the path's segments so far (Tungsten's
    ``hitDistance``), in scene units;
  - ``normal``: the world-space shading normal of the vertex (``si.sh_frame.n``, Tungsten's
    ``info.Ns``; not flipped towards the ray);
  - ``albedo``: the BSDF's diffuse reflectance ``bsdf.eval_diffuse_reflectance`` clipped to
    [0, 1] per sample, plus the emitted radiance ``Le(x, -d)`` of an emissive surface (Tungsten:
    ``bsdf->albedo()`` plus ``evalDirect`` of an emissive primitive);
  - ``position``: the vertex ``si.p`` (RDFC's world position, fbksd's ``WORLD_X_NS``);
  - ``visibility``: RDFC's direct-light indicator at the vertex
    (:func:`mcbench.render.visibility.direct_light_visible`).

* a path that leaves the scene (or reaches ``max_vertices`` specular vertices, Tungsten's
  ``maxBounces``) before it records (L133-140) records ``normal = -d`` of its last ray, ``depth
  = 0`` only when the camera ray itself escapes (``bounce == 0``), the environment's radiance as
  albedo only where the scene has an environment emitter (Tungsten: an infinite primitive), no
  position, and visibility 0.

Averaging: Tungsten's output buffers average a pixel over the samples that *recorded* a value
(``OutputBuffer::addSample`` counts per pixel). So depth, albedo and position come with a per-sample
weight ``w`` in {0, 1} (AOVs ``*.W``) and the value is written as ``w * f``: the renderer turns the
moment sums into ``mean = sum(w f) / sum(w)`` and its variance over the recorded samples
(:func:`mcbench.render.renderer.weighted_mean_variance`); a pixel where no sample recorded gets 0.
Normal and visibility are recorded by every sample.

Departures (each for a reason given here):

* participating media are not sampled: the feature path goes straight through a medium to the next
  surface (a medium's ``null`` boundary is a null event). Tungsten samples a free-flight distance
  and, after a scattering in the medium, records at the next non-specular *surface* vertex (media
  events themselves record nothing, ``wasSpecular`` false after them); in thin media that is the
  surface behind, in dense ones a random surface after a scattering. Keeping the features a
  function of the surfaces along the ray keeps them the same kind of quantity as in every other
  scene (and as our first-hit features in media).
* no Russian roulette on the feature path (Tungsten's roulette after 2 bounces can end a path of
  throughput < 0.1 before it records; a chain of delta lobes rarely has that throughput).
* Mitsuba's ``eval_diffuse_reflectance`` stands for Tungsten's albedo texture: the reflectance of
  diffuse and plastic-like BSDFs, ``pi * f(n, n)`` for others (clipped to 1; Tungsten: the
  conductor's albedo texture, 1 unless set).
* a failed BSDF sample at a delta vertex records that vertex (Tungsten: the same, ``terminate``).

Random numbers: after the sensor's samples, per vertex one ``next_1d`` and one ``next_2d`` (the
BSDF sample) and, at the recorded vertex, one ``next_2d`` (the emitter sample of the visibility).
Deterministic for a seed like the rest of the render. Works in scalar and JIT variants.
"""

from __future__ import annotations

# Module-level imports: ``dr.syntax`` compiles ``sample`` again in this module's namespace, so the
# names it uses must be globals (the renderer imports this module only when a feature pass runs).
import drjit as dr
import mitsuba as mi

from mcbench.render.variants import register_integrator_once
from mcbench.render.visibility import direct_light_visible

__all__ = ["PLUGIN", "AOVS", "WEIGHTED", "DEFAULT_MAX_VERTICES", "register"]

PLUGIN = "mcbench_path_features"
#: AOV names in order (one channel each); quantity ``q`` with a ``q.W`` weight is written as ``w * f``.
AOVS = ("albedo.R", "albedo.G", "albedo.B", "albedo.W",
        "normal.X", "normal.Y", "normal.Z",
        "depth.T", "depth.W",
        "position.X", "position.Y", "position.Z", "position.W",
        "visibility.V")
#: Quantities averaged over the samples that recorded them (module docstring).
WEIGHTED = ("albedo", "depth", "position")
#: Vertices examined when the scene's integrator has no ``max_depth`` (Tungsten's default maxBounces).
DEFAULT_MAX_VERTICES = 64

def register() -> str:
    """Register the :data:`PLUGIN` integrator for Mitsuba's current variant (once per variant; call
    after the variant is set) and return the plugin name. Property ``max_vertices`` (int, default
    :data:`DEFAULT_MAX_VERTICES`): the most surface vertices a feature path examines."""
    return register_integrator_once(PLUGIN, _integrator_class)


def _emitted(scene, si, mask):
    """Radiance emitted at ``si`` towards ``si.wi`` (an environment's radiance on a miss), 0 without
    an emitter. Scalar variants return ``None`` for a missing emitter, hence the branch."""
    emitter = si.emitter(scene)
    if dr.is_jit_v(mi.Float):
        return mi.unpolarized_spectrum(emitter.eval(si, mask))
    if emitter is None or not mask:
        return mi.Color3f(0.0)
    return mi.unpolarized_spectrum(emitter.eval(si))


def _reflectance(bsdf, si, mask):
    """The BSDF's diffuse reflectance at ``si`` clipped to [0, 1] (module docstring)."""
    value = mi.unpolarized_spectrum(bsdf.eval_diffuse_reflectance(si, mask))
    return dr.clip(mi.Color3f(value), 0.0, 1.0)


def _not(mask):
    """Logical not of a mask in JIT (``~``) and scalar (a Python ``bool``: ``~True`` is ``-2``) variants."""
    return ~mask if dr.is_jit_v(mi.Float) else not mask


def _integrator_class():
    """The integrator class for the current variant (``mi.SamplingIntegrator`` is per variant)."""
    class PathFeatureIntegrator(mi.SamplingIntegrator):
        """Features at the first non-specular vertex (module docstring); AOVs :data:`AOVS`."""

        def __init__(self, props):
            super().__init__(props)
            self.max_vertices = int(props.get("max_vertices", DEFAULT_MAX_VERTICES))
            if self.max_vertices < 1:
                raise ValueError(f"{PLUGIN}: max_vertices must be >= 1, got {self.max_vertices}")

        @dr.syntax
        def sample(self, scene, sampler, ray, medium=None, active=True):
            """``(0, True, aovs)`` for one camera ray: the values of :data:`AOVS` (module docstring)."""
            ray = mi.Ray3f(ray)
            si = scene.ray_intersect(ray, mi.Bool(active))
            has_environment = scene.environment() is not None
            escaped = mi.Bool(active) & _not(si.is_valid())
            # A camera ray that escapes: normal -d, depth 0 (recorded), environment as albedo.
            normal = dr.select(escaped, -ray.d, mi.Vector3f(0.0))
            depth_weight = dr.select(escaped, mi.Float(1.0), mi.Float(0.0))
            albedo = mi.Color3f(0.0)
            albedo_weight = mi.Float(0.0)
            if has_environment:
                albedo = dr.select(escaped, _emitted(scene, si, escaped), albedo)
                albedo_weight = dr.select(escaped, mi.Float(1.0), albedo_weight)
            depth = mi.Float(0.0)
            position = mi.Point3f(0.0)
            position_weight = mi.Float(0.0)
            visibility = mi.Float(0.0)
            distance = mi.Float(0.0)
            was_specular = mi.Bool(True)
            vertices = mi.UInt32(0)
            searching = mi.Bool(active) & si.is_valid()

            while searching:
                distance = dr.select(searching, distance + si.t, distance)
                bsdf = si.bsdf(ray)
                bs, weight = bsdf.sample(mi.BSDFContext(), si, sampler.next_1d(searching),
                                         sampler.next_2d(searching), searching)
                failed = (bs.pdf <= 0.0) | (dr.max(mi.unpolarized_spectrum(weight)) <= 0.0)
                null = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
                delta = (mi.has_flag(bs.sampled_type, mi.BSDFFlags.DeltaReflection)
                         | mi.has_flag(bs.sampled_type, mi.BSDFFlags.DeltaTransmission))
                was_specular = dr.select(searching & _not(null) & _not(failed), delta, was_specular)
                record = searching & (_not(was_specular) | failed)

                emission = _emitted(scene, si, record)
                albedo = dr.select(record, _reflectance(bsdf, si, record) + emission, albedo)
                albedo_weight = dr.select(record, mi.Float(1.0), albedo_weight)
                normal = dr.select(record, si.sh_frame.n, normal)
                depth = dr.select(record, distance, depth)
                depth_weight = dr.select(record, mi.Float(1.0), depth_weight)
                position = dr.select(record, si.p, position)
                position_weight = dr.select(record, mi.Float(1.0), position_weight)
                visible = direct_light_visible(scene, bsdf, si, sampler.next_2d(record), record)
                visibility = dr.select(visible, mi.Float(1.0), visibility)

                searching = searching & _not(record)
                vertices += 1
                ray = dr.select(searching, si.spawn_ray(si.to_world(bs.wo)), ray)
                # Tungsten's maxBounces: the path ends unrecorded (normal -d of its last ray).
                ended = searching & (vertices >= self.max_vertices)
                normal = dr.select(ended, -ray.d, normal)
                searching = searching & _not(ended)
                si = scene.ray_intersect(ray, searching)
                left = searching & _not(si.is_valid())
                normal = dr.select(left, -ray.d, normal)
                if has_environment:
                    albedo = dr.select(left, _emitted(scene, si, left), albedo)
                    albedo_weight = dr.select(left, mi.Float(1.0), albedo_weight)
                searching = searching & si.is_valid()

            aovs = [albedo[0] * albedo_weight, albedo[1] * albedo_weight, albedo[2] * albedo_weight,
                    albedo_weight, normal[0], normal[1], normal[2], depth * depth_weight, depth_weight,
                    position[0] * position_weight, position[1] * position_weight,
                    position[2] * position_weight, position_weight, visibility]
            return mi.Spectrum(0.0), mi.Bool(True), aovs

        def aov_names(self):
            return list(AOVS)

        def to_string(self):
            return f"{PLUGIN}[max_vertices={self.max_vertices}]"

    return PathFeatureIntegrator
