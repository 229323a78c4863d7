"""Render noisy buffers (full, A, B with variances and features) and reference chunks with Mitsuba 3.

How the numbers are made
------------------------
The scene's own integrator is wrapped as ``moment(aov(albedo, sh_normal, depth, <scene
integrator>))`` and the film gets a box reconstruction filter and an ``independent`` sampler.
With the box filter every sample lands in exactly one pixel with weight 1, so the film holds,
per pixel and channel, the sample mean ``m1`` and the mean of squared samples ``m2`` over the
``n`` samples of that render. Passes are accumulated in float64 as sums ``m1*n`` and ``m2*n``;
from pooled sums ``S1, S2`` over ``N`` samples

    mean = S1 / N,   variance of the mean = (S2 / N - mean^2) / (N - 1)

(the unbiased sample variance divided by ``N``). Tiny negative values from rounding are set to 0.
Noisy renders add RDFC's features (Rousselle et al. 2013): after each pass a *feature pass*
renders the same scene with the integrator ``moment(aov(position, mcbench_visibility))``
(:data:`FEATURE_AOVS`, :mod:`mcbench.render.visibility`) and the same spp and seed. The sensor
draws the same samples first, so the feature pass traces the colour pass's camera rays (same
pixel positions, lens and time samples); its moments give ``position`` and ``visibility`` and
their variances exactly as above. The colour pass itself is the one of renders made before the
features: adding channels to its film changes the order in which the film sums a pixel's samples
(1-ulp differences at more than 2 spp per pass), a separate pass leaves it bit-identical.
:func:`render_scene_sums` has no feature pass; a reference chunk has one (below).

Features (config key ``features``, :data:`FEATURE_CONVENTIONS`): with ``first_hit`` albedo, normal
and depth come from the colour pass's ``aov`` integrator (the camera ray's first surface) and
position and visibility from the feature pass above. With ``tungsten`` the feature pass is
``moment(mcbench_path_features)`` (:mod:`mcbench.render.path_features`): every feature recorded
at the first vertex whose sampled BSDF lobe is not a delta lobe, as the paper's renderer records
them, and averaged over the samples that recorded it (:func:`weighted_mean_variance`); the colour
pass is the same bit for bit in both conventions. A reference chunk's colour passes render the
scene's integrator in ``moment(aov(...))`` with no AOVs (the colour and its second moment), and it
records its features, in either convention, in one feature pass of :data:`REFERENCE_FEATURE_SPP`
samples (:func:`render_reference_chunk`).

Each buffer or chunk is split into passes of at most :data:`MAX_WAVEFRONT` samples
(:func:`passes_for`); every pass has its own 32-bit seed, laid out in :mod:`mcbench.render.seeds`
(which also maps a seed to the one handed to Mitsuba in scalar variants).

What is rendered
----------------
The renderer never looks up a scene by name (core does not import ``scenes/``): callers pass

* a scene *module* (its declaration ``SCENE``, a :class:`mcbench.contracts.scene.SceneSpec`:
  ``resolution``, ``build(width, height)``; see ``scenes/__init__.py``) to :func:`render_buffers`
  and :func:`render_reference_chunk`, which use the test render seeds of :func:`mcbench.render.seeds.render_seed`; or
* a Mitsuba scene *dict* (integrator and sensor included) with a caller-chosen ``key`` and
  seeds to :func:`render_dict_buffers` (noisy full/A/B buffers) or :func:`render_scene_sums`
  (float64 moment sums of one run of passes); the training data uses these.

Both paths wrap the scene the same way (:func:`load_scene_dict`) and share the moment sums and
buffer assembly (:func:`buffers_from_moment_sums`), so the same dict and seeds give the same
buffers bit for bit. Loaded scenes are cached per process by ``(key, width, height, variant)``
(a module's key is its module name, e.g. ``scenes.cornell_box``); :func:`forget_scene` drops a
key's entries.
"""

from __future__ import annotations

import time
from types import ModuleType
from typing import Callable

import numpy as np

from mcbench import BenchError
from mcbench.contracts.scene import scene_spec
from mcbench.io.buffers import ALL_LAYERS, BINS
from mcbench.progress import eta_seconds, progress_line
from mcbench.render.seeds import SCALAR_BLOCK_SIZE, mitsuba_seed, render_seed
from mcbench.render.variants import pick_variant, set_threads
from mcbench.render.visibility import AOV_NAME as VISIBILITY_AOV
from mcbench.render.visibility import register as register_visibility
from mcbench.render.xml_scenes import XmlScene, load_xml_scene

__all__ = ["RenderError", "MAX_WAVEFRONT", "passes_for", "load_scene_dict", "forget_scene",
           "render_scene_sums", "render_dict_buffers", "render_buffers", "render_reference_chunk",
           "merge_reference_chunks", "moments_to_mean_variance", "buffers_from_moment_sums",
           "buffers_from_bin_sums", "weighted_mean_variance", "check_features",
           "FEATURE_CONVENTIONS", "DEFAULT_FEATURES", "REFERENCE_FEATURE_SPP",
           "film_size"]

MAX_WAVEFRONT = 2 ** 22          # samples per mi.render call in vectorised variants (W*H*spp_pass)
AOVS = "albedo:albedo,nn:sh_normal,dd:depth"
#: The feature pass of a noisy render (module docstring): Mitsuba's position AOV and, nested in the same
#: ``aov`` integrator, the visibility integrator (:mod:`mcbench.render.visibility`) under this name.
FEATURE_AOVS = "pp:position"
VISIBILITY_CHILD = "visibility"
SENSOR_TYPES = ("perspective", "thinlens", "orthographic")

# Film channel names (Mitsuba 3.9 moment + aov integrators) of each quantity: m1 and m2.
CHANNELS = {
    "color": (("nested.integrator.R", "nested.integrator.G", "nested.integrator.B"),
              ("m2_nested.integrator.R", "m2_nested.integrator.G", "m2_nested.integrator.B")),
    "albedo": (("nested.albedo.R", "nested.albedo.G", "nested.albedo.B"),
               ("m2_nested.albedo.R", "m2_nested.albedo.G", "m2_nested.albedo.B")),
    "normal": (("nested.nn.X", "nested.nn.Y", "nested.nn.Z"),
               ("m2_nested.nn.X", "m2_nested.nn.Y", "m2_nested.nn.Z")),
    "depth": (("nested.dd.T",), ("m2_nested.dd.T",)),
}
# The same for the feature pass of a noisy render (RDFC's features, Rousselle et al. 2013).
FEATURE_CHANNELS = {
    "position": (("nested.pp.X", "nested.pp.Y", "nested.pp.Z"),
                 ("m2_nested.pp.X", "m2_nested.pp.Y", "m2_nested.pp.Z")),
    "visibility": ((f"nested.{VISIBILITY_CHILD}.{VISIBILITY_AOV}",),
                   (f"m2_nested.{VISIBILITY_CHILD}.{VISIBILITY_AOV}",)),
}
FEATURES = ("albedo", "normal", "depth")          # the features of a reference chunk
# The colour pass of a reference chunk, ``moment(aov(<scene integrator>))`` with no AOVs: the colour
# alone. (``moment(<scene integrator>)`` would not do: ``moment`` records a bare integrator's output
# as CIE XYZ, whose second moments do not give the RGB variance.)
COLOUR_CHANNELS = {"color": CHANNELS["color"]}
# A first-hit reference chunk's feature pass, ``moment(aov(albedo, sh_normal, depth))`` with no
# nested integrator: the first-hit features of :data:`CHANNELS`.
REFERENCE_FIRST_HIT_CHANNELS = {q: CHANNELS[q] for q in FEATURES}

#: Where a render's features are recorded (config key ``features``; module docstring, "Features"):
#: ``tungsten`` at the first non-specular vertex of the path, as the paper's renderer records them
#: (:mod:`mcbench.render.path_features`); ``first_hit`` at the camera ray's first surface (Mitsuba's
#: ``aov`` integrator in the colour pass, position and visibility from the first-hit feature pass).
FEATURE_CONVENTIONS = ("tungsten", "first_hit")
#: Samples of a Tungsten-convention reference chunk's feature pass (:func:`render_reference_chunk`).
REFERENCE_FEATURE_SPP = 256
#: The convention of a render that does not say (the learned methods' committed weights were
#: trained on these; :func:`render_buffers` and the config default).
DEFAULT_FEATURES = "first_hit"
# The path-feature pass's film channels (mcbench.render.path_features.AOVS): quantity -> m1, m2 names;
# ``q_count`` is the per-sample weight (1 where the sample recorded q) of a weighted quantity q.
_PATH_QUANTITIES = {"albedo": ("albedo", "RGB"), "albedo_count": ("albedo", "W"),
                    "normal": ("normal", "XYZ"), "depth": ("depth", "T"), "depth_count": ("depth", "W"),
                    "position": ("position", "XYZ"), "position_count": ("position", "W"),
                    "visibility": ("visibility", "V")}
PATH_FEATURE_CHANNELS = {
    quantity: (tuple(f"nested.{name}.{c}" for c in channels), tuple(f"m2_nested.{name}.{c}" for c in channels))
    for quantity, (name, channels) in _PATH_QUANTITIES.items()}

SeedOfPass = Callable[[int], int]            # pass index -> 32-bit seed
SeedOfBinPass = Callable[[int, int, int], int]   # (half 0 = A / 1 = B, bin 0/1, pass index) -> seed


class RenderError(BenchError):
    """Rendering failed or produced unusable numbers; the message names scene and spp."""


def passes_for(spp: int, width: int, height: int, variant: str) -> list[int]:
    """Samples per pixel of each pass for ``spp`` samples: one pass in scalar variants, else
    passes of ``max(1, MAX_WAVEFRONT // (W*H))`` spp (the last one takes the remainder)."""
    if spp < 1:
        raise ValueError(f"spp must be >= 1, got {spp}")
    if variant.startswith("scalar"):
        return [spp]
    per_pass = max(1, MAX_WAVEFRONT // (width * height))
    full, rest = divmod(spp, per_pass)
    return [per_pass] * full + ([rest] if rest else [])


# --------------------------------------------------------------------------- loading

_scene_cache: dict = {}


def film_size(desc: dict) -> tuple[int, int]:
    """``(width, height)`` in pixels of the film of a scene dict's sensor."""
    sensor = _sensor_key(desc, "scene dict")
    return int(desc[sensor]["film"]["width"]), int(desc[sensor]["film"]["height"])


def _sensor_key(desc: dict, label: str) -> str:
    try:
        return next(k for k, v in desc.items() if isinstance(v, dict) and v.get("type") in SENSOR_TYPES)
    except StopIteration:
        raise RenderError(f"scene '{label}': no {'/'.join(SENSOR_TYPES)} sensor in its dict") from None


def _wrapped(desc: dict, label: str, width: int, height: int, variant: str, *,
             aovs: bool = True) -> tuple[dict, dict]:
    """A copy of ``desc`` with the moment/aov integrator wrapper (``aovs=False``: an ``aov``
    integrator of no AOVs, the colour of a reference chunk), box filter and independent sampler
    (``desc`` itself is not changed), and the scene's own integrator dict."""
    desc = dict(desc)
    integrator = desc["integrator"]
    desc["integrator"] = {"type": "moment",
                          "nested": {"type": "aov", "aovs": AOVS if aovs else "", "integrator": integrator}}
    if variant.startswith("scalar"):
        desc["integrator"]["block_size"] = SCALAR_BLOCK_SIZE
    sensor_key = _sensor_key(desc, label)
    sensor = dict(desc[sensor_key])
    film = dict(sensor["film"])
    if (int(film["width"]), int(film["height"])) != (width, height):
        raise RenderError(f"scene '{label}': build({width}, {height}) made a "
                          f"{film['width']}x{film['height']} film")
    film["rfilter"] = {"type": "box"}
    for crop_key in ("crop_width", "crop_height", "crop_offset_x", "crop_offset_y"):
        film.pop(crop_key, None)
    sensor["film"] = film
    sensor["sampler"] = {"type": "independent", "sample_count": 1}
    desc[sensor_key] = sensor
    return desc, integrator


def _loaded(key: str, build: Callable[[], dict], label: str, width: int, height: int, variant: str, *,
            aovs: bool = True):
    """Cached ``(Mitsuba scene, scene integrator dict)``; ``build()`` runs only on a miss. ``aovs``:
    the colour pass's integrator records the first-hit features (:data:`CHANNELS`), else only the
    colour (:data:`COLOUR_CHANNELS`)."""
    import mitsuba as mi

    cache_key = (key, width, height, variant) + (() if aovs else ("colour",))
    if cache_key not in _scene_cache:
        desc = build()
        if isinstance(desc, XmlScene):        # a Mitsuba XML file (mcbench.render.xml_scenes)
            if (desc.width, desc.height) != (width, height):
                raise RenderError(f"scene '{label}': build({width}, {height}) made a {desc.width}x{desc.height} film")
            _scene_cache[cache_key] = load_xml_scene(
                desc, aovs=AOVS if aovs else "", block_size=SCALAR_BLOCK_SIZE if variant.startswith("scalar") else None)
            return _scene_cache[cache_key]
        desc, integrator = _wrapped(desc, label, width, height, variant, aovs=aovs)
        try:
            _scene_cache[cache_key] = (mi.load_dict(desc), integrator)
        except Exception as exc:
            raise RenderError(f"scene '{label}': Mitsuba cannot load it ({exc})") from exc
    return _scene_cache[cache_key]


def load_scene_dict(desc: dict, *, key: str, variant: str = "auto"):
    """The Mitsuba scene of scene dict ``desc`` wrapped for rendering (module docstring): the
    ``moment(aov(...))`` integrator, a box filter and an ``independent`` sampler, loaded once per
    process under ``key`` (which also names the scene in errors). ``desc`` is not changed.

    Returns ``(scene, integrator)``: the loaded ``mi.Scene`` and the scene's own integrator dict.
    """
    scene_object, integrator, *_ = _loaded_dict(desc, key, variant)
    return scene_object, integrator


def _loaded_dict(desc: dict, key: str, variant: str):
    """``(scene, integrator, variant, width, height)`` of a scene dict, the variant picked."""
    variant = pick_variant(variant)
    width, height = film_size(desc)
    return (*_loaded(key, lambda: desc, key, width, height, variant), variant, width, height)


def forget_scene(key: str) -> None:
    """Drop every cached Mitsuba scene loaded under ``key`` (all sizes and variants)."""
    for cache_key in [k for k in _scene_cache if k[0] == key]:
        del _scene_cache[cache_key]


# --------------------------------------------------------------------------- moment sums

def _channel_indices(scene_object, channels: dict = CHANNELS,
                     count: int | None = 31) -> dict[str, tuple[list[int], list[int]]]:
    """Indices of the m1 and m2 channels of each quantity of ``channels`` in the film developed
    last (the colour pass: :data:`CHANNELS`, 31 channels; a feature pass: :data:`FEATURE_CHANNELS`
    or :data:`PATH_FEATURE_CHANNELS`, any count), by name."""
    names = [field.name for field in scene_object.sensors()[0].film().bitmap().struct_()]
    if names[:3] != ["R", "G", "B"] or (count is not None and len(names) != count):
        raise RenderError(f"unexpected film channels {names}")
    try:
        return {q: ([names.index(c) for c in m1], [names.index(c) for c in m2])
                for q, (m1, m2) in channels.items()}
    except ValueError as exc:
        raise RenderError(f"film channel missing ({exc}); channels are {names}") from exc


def _render_pass(scene_object, spp: int, seed: int, integrator=None) -> np.ndarray:
    """One ``mi.render`` call (with the scene's integrator, or ``integrator``): the developed film
    as float64 (H, W, channels)."""
    import mitsuba as mi

    return np.asarray(mi.render(scene_object, spp=spp, seed=seed, integrator=integrator), dtype=np.float64)


_feature_integrators: dict = {}


def check_features(features: str, label: str = "features") -> str:
    """``features`` if it is one of :data:`FEATURE_CONVENTIONS`, else a ``ValueError`` naming ``label``."""
    if features not in FEATURE_CONVENTIONS:
        raise ValueError(f"config key '{label}': '{features}' is not a feature convention; "
                         f"use one of {', '.join(FEATURE_CONVENTIONS)}")
    return features


def _max_vertices(integrator) -> int:
    """The most surface vertices a Tungsten-convention feature path examines: the scene
    integrator's ``max_depth`` when it sets one (> 0), else Tungsten's default 64."""
    from mcbench.render.path_features import DEFAULT_MAX_VERTICES

    depth = integrator.get("max_depth", -1) if isinstance(integrator, dict) else -1
    return int(depth) if int(depth) > 0 else DEFAULT_MAX_VERTICES


def _feature_integrator(variant: str, features: str = "first_hit", max_vertices: int = 64, *,
                        reference: bool = False):
    """The integrator of the feature pass (module docstring), one per variant and convention:
    ``moment(aov(position, visibility))`` for ``first_hit`` (a ``reference`` chunk's:
    ``moment(aov(albedo, sh_normal, depth))``, the first-hit features its colour pass leaves out),
    ``moment(mcbench_path_features)`` for ``tungsten``; with the colour pass's block size in scalar
    variants (the same block size gives the same per-block seeds, hence the same camera rays)."""
    import mitsuba as mi

    reference = reference and features == "first_hit"
    key = (variant, features, max_vertices if features == "tungsten" else None, reference)
    if key not in _feature_integrators:
        if features == "tungsten":
            from mcbench.render.path_features import register as register_path_features

            desc = {"type": "moment", "nested": {"type": register_path_features(), "max_vertices": max_vertices}}
        elif reference:
            desc = {"type": "moment", "nested": {"type": "aov", "aovs": AOVS}}
        else:
            desc = {"type": "moment", "nested": {"type": "aov", "aovs": FEATURE_AOVS,
                                                 VISIBILITY_CHILD: {"type": register_visibility()}}}
        if variant.startswith("scalar"):
            desc["block_size"] = SCALAR_BLOCK_SIZE
        _feature_integrators[key] = mi.load_dict(desc)
    return _feature_integrators[key]


def _moment_sums(label: str, scene_object, spp: int, seed_of: SeedOfPass, variant: str,
                 width: int, height: int, label_spp: int,
                 progress: str | None = None, features: str | None = None,
                 max_vertices: int = 64, channels: dict = CHANNELS) -> tuple[dict[str, tuple], list[int]]:
    """Render ``spp`` samples in the passes of :func:`passes_for`, pass ``p`` seeded with
    ``seed_of(p)``; per quantity float64 sums (S1, S2), each (H, W, C), and the seeds used.
    ``features`` (a convention of :data:`FEATURE_CONVENTIONS`, or ``None`` for none): each pass is
    followed by its feature pass (same spp and seed): ``first_hit`` adds the quantities of
    :data:`FEATURE_CHANNELS`; ``tungsten`` those of :data:`PATH_FEATURE_CHANNELS`, which replace the
    colour pass's albedo, normal and depth (their ``*_count`` sums: the samples that recorded them).
    ``channels``: the quantities of the colour pass (:data:`CHANNELS`, or :data:`COLOUR_CHANNELS`
    for a scene loaded without the first-hit AOVs). With ``progress`` (a label), prints a :func:`mcbench.progress.progress_line` after each pass
    (passes done, elapsed time, ETA from the samples done so far)."""
    pass_spp = passes_for(spp, width, height, variant)
    seeds = [seed_of(p) for p in range(len(pass_spp))]
    sums = {}
    started = time.perf_counter()
    for done, (spp, seed) in enumerate(zip(pass_spp, seeds), start=1):
        image = _render_pass(scene_object, spp, mitsuba_seed(seed, variant, width, height))
        index = _channel_indices(scene_object, channels, 31 if channels is CHANNELS else None)
        color = image[..., index["color"][0]]
        if not np.all(np.isfinite(color)) or not np.all(np.isfinite(image[..., index["color"][1]])):
            bad = int((~np.isfinite(image)).any(axis=2).sum())
            raise RenderError(f"scene '{label}' at {label_spp} spp: Mitsuba produced NaN/Inf in "
                              f"{bad} pixel(s) (pass seed {seed}, variant {variant})")
        quantities = [(image, index)]
        if features is not None:
            feature_image, feature_index = _feature_pass(label, label_spp, scene_object, spp, seed, variant,
                                                         width, height, features, max_vertices)
            quantities = [(image, {q: v for q, v in index.items() if q not in feature_index}),
                          (feature_image, feature_index)]
        for pass_image, pass_index in quantities:
            for quantity, (m1, m2) in pass_index.items():
                s1, s2 = pass_image[..., m1] * spp, pass_image[..., m2] * spp
                if quantity in sums:
                    sums[quantity] = (sums[quantity][0] + s1, sums[quantity][1] + s2)
                else:
                    sums[quantity] = (s1, s2)
        if progress:
            elapsed = time.perf_counter() - started
            samples = sum(pass_spp[:done])
            print(progress_line(progress, f"pass {done}/{len(pass_spp)} ({samples}/{sum(pass_spp)} spp)",
                                elapsed, eta_seconds(elapsed, samples, sum(pass_spp))), flush=True)
    return sums, seeds


def _feature_pass(label: str, label_spp: int, scene_object, spp: int, seed: int, variant: str, width: int,
                  height: int, features: str, max_vertices: int, *, reference: bool = False) -> tuple[np.ndarray, dict]:
    """One feature pass (module docstring) of ``spp`` samples with pass seed ``seed``: the developed
    film (H, W, channels) and the indices of its quantities (:data:`FEATURE_CHANNELS` for
    ``first_hit``, :data:`PATH_FEATURE_CHANNELS` for ``tungsten``; a ``reference`` chunk's
    ``first_hit`` pass: :data:`REFERENCE_FIRST_HIT_CHANNELS`); NaN/Inf stops with a
    :class:`RenderError` naming ``label`` at ``label_spp``."""
    first_hit = FEATURE_CHANNELS if not reference else REFERENCE_FIRST_HIT_CHANNELS
    image = _render_pass(scene_object, spp, mitsuba_seed(seed, variant, width, height),
                         _feature_integrator(variant, features, max_vertices, reference=reference))
    index = _channel_indices(scene_object, first_hit if features == "first_hit" else PATH_FEATURE_CHANNELS,
                             None)
    if not np.all(np.isfinite(image)):
        bad = int((~np.isfinite(image)).any(axis=2).sum())
        raise RenderError(f"scene '{label}' at {label_spp} spp: the feature pass produced NaN/Inf in "
                          f"{bad} pixel(s) (pass seed {seed}, variant {variant})")
    return image, index


def render_scene_sums(desc: dict, spp: int, seed_of: SeedOfPass, *, key: str,
                      variant: str = "auto") -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], list[int]]:
    """Float64 moment sums of ``spp`` samples of scene dict ``desc`` (loaded with
    :func:`load_scene_dict` under ``key``), split into the passes of :func:`passes_for`, pass
    ``p`` seeded with ``seed_of(p)``.

    Returns ``(sums, seeds)``: ``sums[q] = (S1, S2)``, the sums of samples and squared samples
    over all passes, float64 (H, W, C) with C = 3 (``color``, ``albedo``, ``normal``) or 1
    (``depth``) -- :func:`moments_to_mean_variance` turns them into means and variances -- and
    the list of seeds used. Raises :class:`RenderError` on NaN/Inf from Mitsuba.
    """
    scene_object, _, variant, width, height = _loaded_dict(desc, key, variant)
    return _moment_sums(key, scene_object, int(spp), seed_of, variant, width, height, int(spp))


def _half_buffers(label: str, scene_object, spp: int, seed_of: SeedOfBinPass, variant: str,
                  width: int, height: int, features: str, max_vertices: int
                  ) -> tuple[dict[str, np.ndarray], list[int], list[int]]:
    """Layers of :data:`ALL_LAYERS` from half buffers A and B of ``spp/2`` samples each (plus
    :data:`mcbench.io.buffers.BIN_LAYERS` when ``spp`` is a multiple of 4: each half is then rendered as two bins of
    ``spp/4`` samples, bin ``j`` of half ``h`` seeded ``seed_of(h, j, p)``), and the seeds of A and
    of B; features of convention ``features`` (:data:`FEATURE_CONVENTIONS`)."""
    half_spp = spp // 2
    binned = half_spp % 2 == 0
    sums, seeds = {}, {0: [], 1: []}
    for half in (0, 1):
        for j in ((0, 1) if binned else (0,)):
            sums[2 * half + j], bin_seeds = _moment_sums(
                label, scene_object, half_spp // 2 if binned else half_spp,
                lambda p, half=half, j=j: seed_of(half, j, p), variant, width, height, spp,
                features=features, max_vertices=max_vertices)
            seeds[half] += bin_seeds
    clip = features == "first_hit"
    if binned:
        return (buffers_from_bin_sums([sums[k] for k in range(BINS)], half_spp // 2, clip_albedo=clip),
                seeds[0], seeds[1])
    return buffers_from_moment_sums(sums[0], sums[2], half_spp, clip_albedo=clip), seeds[0], seeds[1]


def render_dict_buffers(desc: dict, spp: int, seed_of: SeedOfHalfPass, *, key: str,
                        variant: str = "auto", features: str = DEFAULT_FEATURES
                        ) -> tuple[dict[str, np.ndarray], list[int]]:
    """Noisy buffers of scene dict ``desc`` with the conventions of :func:`render_buffers`.

    ``spp``: even total spp (``spp/2`` per half buffer); ``seed_of(half, bin, pass_index)`` gives
    the 32-bit seed of each pass of bin 0/1 of half 0 (A) and 1 (B) (bin 0 only when spp is not a
    multiple of 4); ``key`` names the scene in errors and in the scene cache
    (:func:`forget_scene`). Returns the float32 layers of :data:`ALL_LAYERS` and, for spp a
    multiple of 4, :data:`mcbench.io.buffers.BIN_LAYERS` (see :func:`buffers_from_bin_sums`), and the seeds used
    (A's, then B's). ``features``: where the features are recorded (:data:`FEATURE_CONVENTIONS`).
    """
    spp = _even_spp(spp, key)
    features = check_features(features)
    scene_object, integrator, variant, width, height = _loaded_dict(desc, key, variant)
    layers, seeds_a, seeds_b = _half_buffers(key, scene_object, spp, seed_of, variant, width, height,
                                             features, _max_vertices(integrator))
    return layers, seeds_a + seeds_b


def moments_to_mean_variance(s1: np.ndarray, s2: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel mean and variance of the mean from sums of ``n`` samples and squared samples.

    ``s1``, ``s2``: float64 arrays of any shape (e.g. (H, W, 3)); returns float64 arrays of the
    same shape: ``mean = s1/n`` and ``(s2/n - mean^2) / (n - 1)`` clamped at 0 (``n >= 2``).
    """
    if n < 2:
        raise ValueError(f"need at least 2 samples for a variance, got {n}")
    mean = s1 / n
    variance = (s2 / n - mean * mean) / (n - 1)
    return mean, np.maximum(variance, 0.0)


def _squeeze(array: np.ndarray) -> np.ndarray:
    return array[..., 0] if array.shape[-1] == 1 else array


def _mitsuba_version() -> str:
    import mitsuba as mi
    return mi.__version__


def _describe(integrator: dict) -> str:
    return ",".join(f"{k}={v}" for k, v in sorted(integrator.items()))


# --------------------------------------------------------------------------- test scenes

def _even_spp(spp, label: str) -> int:
    if not isinstance(spp, (int, np.integer)) or spp < 2 or spp % 2:
        raise BenchError(f"config key 'spp': scene '{label}' needs an even spp >= 2, got {spp}")
    return int(spp)


def _scene_name(module: ModuleType) -> str:
    return module.__name__.rpartition(".")[2]


def _size(module: ModuleType, resolution) -> tuple[int, int]:
    width, height = (resolution if resolution is not None else scene_spec(module).size)
    return int(width), int(height)


def _loaded_module(module: ModuleType, width: int, height: int, variant: str, *, aovs: bool = True):
    build = scene_spec(module).build
    return _loaded(module.__name__, lambda: build(width, height), _scene_name(module),
                   width, height, variant, aovs=aovs)


def render_buffers(scene_module: ModuleType, spp: int, *, resolution: tuple[int, int] | None = None,
                   variant: str = "auto", seed: int = 0, threads: int | None = None,
                   features: str = DEFAULT_FEATURES) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Render the two independent half buffers A and B (spp/2 samples each) of a test scene.

    ``scene_module``: the scene module (``scenes.load_scene(name)``; its name is the module's last
    component); ``resolution``: ``(width, height)``, default its declaration's ``resolution``;
    ``seed``: the config's global seed (:func:`mcbench.render.seeds.render_seed`).

    For spp a multiple of 4 each half is rendered as two sample bins of spp/4 (layers
    :data:`mcbench.io.buffers.BIN_LAYERS`; A = bins 0-1, B = bins 2-3). Returns float32 layers for
    every name in :data:`mcbench.io.buffers.ALL_LAYERS` (and the bins): ``color*``
    (H, W, 3) linear radiance, ``variance*`` (H, W, 3) variance of the mean, ``albedo*``,
    ``normal*``, ``position*`` (H, W, 3), ``depth*``, ``visibility*`` (H, W) and their
    ``*_variance`` layers (position and visibility from the feature pass); the full-image
    versions are ``(A + B) / 2`` and the variances from the pooled moments of all spp samples.
    ``features``: where albedo, normal, depth, position and visibility are recorded
    (:data:`FEATURE_CONVENTIONS`). Metadata (strings): scene, spp, variant, seed, seeds_a, seeds_b,
    mitsuba, seconds, resolution (``WxH``), integrator, passes, features.
    """
    module = scene_module
    name = _scene_name(module)
    spp = _even_spp(spp, name)
    features = check_features(features)
    width, height = _size(module, resolution)
    variant = pick_variant(variant)
    set_threads(threads)
    start = time.perf_counter()
    scene_object, integrator = _loaded_module(module, width, height, variant)
    layers, seeds_a, seeds_b = _half_buffers(
        name, scene_object, spp,
        lambda half, j, p: render_seed("noisy", spp=spp, half=half, bin=j, pass_index=p, base_seed=seed),
        variant, width, height, features, _max_vertices(integrator))
    seconds = time.perf_counter() - start
    metadata = {
        "scene": name, "spp": str(spp), "variant": variant, "seed": str(seed),
        "seeds_a": ",".join(map(str, seeds_a)), "seeds_b": ",".join(map(str, seeds_b)),
        "mitsuba": _mitsuba_version(), "seconds": f"{seconds:.3f}",
        "resolution": f"{width}x{height}", "integrator": _describe(integrator),
        "passes": str(len(seeds_a)), "features": features,
    }
    return layers, metadata


def render_reference_chunk(scene_module: ModuleType, spp: int, chunk: int, *,
                           resolution: tuple[int, int] | None = None, variant: str = "auto",
                           seed: int = 0, threads: int | None = None, features: str = DEFAULT_FEATURES
                           ) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Render chunk ``chunk`` (0-based) of a reference of the scene module ``scene_module``: ``spp``
    samples with seeds disjoint from every noisy render and every other chunk.

    The colour passes render ``moment(aov(<scene integrator>))`` with an empty AOV list, the colour
    alone: the scene's own estimator and sample stream, as in a noisy render's colour pass (the
    first-hit AOVs draw no random numbers), so a chunk's colour equals that of the wrapped pass up
    to the film's float32 accumulation order, and the AOVs, 4-10 % of a chunk's CPU
    (``docs/measurements.md``), are not computed for every sample.

    Layers (float32): ``color`` (H, W, 3) sample mean, ``color_m2`` (H, W, 3) mean of squared
    samples, ``albedo``, ``normal`` (H, W, 3) and ``depth`` (H, W) sample means from one feature
    pass of ``min(spp, REFERENCE_FEATURE_SPP)`` samples seeded as the chunk's first pass (``features``:
    ``first_hit``: ``moment(aov(albedo, sh_normal, depth))``; ``tungsten``: the path-feature pass,
    each the mean over the samples that recorded it): no step of the study reads a reference's
    features, they are kept for display and export, and a feature pass beside every colour pass
    would add its cost to the study's most expensive renders. Metadata (strings): scene, spp,
    chunk, variant, seed, seeds, mitsuba, seconds, resolution, integrator, features, feature_spp
    (the samples behind the features).
    """
    module = scene_module
    name = _scene_name(module)
    features = check_features(features)
    if not isinstance(spp, (int, np.integer)) or spp < 1:
        raise BenchError(f"config key 'reference.spp': scene '{name}' needs spp >= 1, got {spp}")
    spp, chunk = int(spp), int(chunk)
    width, height = _size(module, resolution)
    variant = pick_variant(variant)
    set_threads(threads)
    start = time.perf_counter()
    scene_object, integrator = _loaded_module(module, width, height, variant, aovs=False)
    seed_of = lambda p: render_seed("reference", chunk=chunk, pass_index=p, base_seed=seed)  # noqa: E731
    sums, seeds = _moment_sums(
        name, scene_object, spp, seed_of,
        variant, width, height, spp, progress=f"reference {name} chunk {chunk} ({width}x{height}, {variant})",
        channels=COLOUR_CHANNELS)
    layers = {"color": sums["color"][0] / spp, "color_m2": sums["color"][1] / spp}
    feature_spp = min(spp, REFERENCE_FEATURE_SPP)
    image, index = _feature_pass(name, spp, scene_object, feature_spp, seed_of(0), variant, width, height,
                                 features, _max_vertices(integrator), reference=True)
    sums = {quantity: (image[..., m1] * feature_spp, image[..., m2] * feature_spp)
            for quantity, (m1, m2) in index.items()}
    for quantity in FEATURES:
        count = sums[f"{quantity}_count"][0] if f"{quantity}_count" in sums else feature_spp
        layers[quantity] = _squeeze(weighted_mean_variance(*sums[quantity], count)[0])
    layers = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in layers.items()}
    metadata = {
        "scene": name, "spp": str(spp), "chunk": str(chunk), "variant": variant,
        "seed": str(seed), "seeds": ",".join(map(str, seeds)), "mitsuba": _mitsuba_version(),
        "seconds": f"{time.perf_counter() - start:.3f}", "resolution": f"{width}x{height}",
        "integrator": _describe(integrator), "features": features, "feature_spp": str(feature_spp),
    }
    return layers, metadata


def weighted_mean_variance(s1: np.ndarray, s2: np.ndarray, count) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance of the mean over the samples that recorded a value.

    ``s1``, ``s2``: float64 (H, W, C) sums of ``w f`` and ``w f^2`` over a pixel's samples, with
    weights ``w`` in {0, 1} (:mod:`mcbench.render.path_features`); ``count``: the sum of the
    weights, (H, W, 1) or a number (every sample recorded). Returns float64 arrays of ``s1``'s shape:
    ``mean = s1 / n`` and ``(s2 / n - mean^2) / (n - 1)`` clamped at 0 with ``n`` the count (Tungsten's
    per-pixel sample count, ``OutputBuffer::addSample``); 0 where no sample recorded (mean and
    variance) and a variance of 0 where only one did (no spread to estimate).
    """
    n = np.broadcast_to(np.asarray(count, dtype=np.float64), np.shape(s1))
    recorded = n > 0
    safe = np.where(recorded, n, 1.0)
    mean = np.where(recorded, s1 / safe, 0.0)
    spread = n > 1
    variance = np.where(spread, (s2 / safe - mean * mean) / np.where(spread, n - 1.0, 1.0), 0.0)
    return mean, np.maximum(variance, 0.0)


def _pooled(first: dict, second: dict) -> dict:
    return {q: (first[q][0] + second[q][0], first[q][1] + second[q][1]) for q in first}


def buffers_from_bin_sums(bin_sums: list[dict], bin_spp: int, *, clip_albedo: bool = True) -> dict[str, np.ndarray]:
    """Float32 layers of :data:`ALL_LAYERS` and :data:`mcbench.io.buffers.BIN_LAYERS` from the moment sums of four
    sample bins of ``bin_spp`` samples each (bins 0-1 make half buffer A, bins 2-3 make B).

    ``color_bin{j}`` is the bin's mean and ``variance_bin{j}`` the variance of that mean; with one
    sample per bin (4 spp) it is ``(b0 - b1)^2 / 2`` from the two bins of its half (unbiased for the
    variance of one sample, the same for both bins). Half buffers and the full image follow
    :func:`buffers_from_moment_sums` of the pooled sums, except that ``color_a`` is
    ``(color_bin0 + color_bin1) / 2`` and ``color_b`` ``(color_bin2 + color_bin3) / 2`` computed on
    the float32 bins, so the identities hold exactly for consumers that recompute them.
    ``clip_albedo``: as in :func:`buffers_from_moment_sums`.
    """
    if len(bin_sums) != BINS:
        raise ValueError(f"need {BINS} bins, got {len(bin_sums)}")
    bins = {}
    for j, sums in enumerate(bin_sums):
        s1, s2 = sums["color"]
        if bin_spp >= 2:
            mean, variance = moments_to_mean_variance(s1, s2, bin_spp)
        else:
            partner = bin_sums[j ^ 1]["color"][0]
            mean, variance = s1, 0.5 * (s1 - partner) ** 2
        bins[j] = (mean.astype(np.float32), variance.astype(np.float32))
    half_means = {"_a": (bins[0][0] + bins[1][0]) / np.float32(2), "_b": (bins[2][0] + bins[3][0]) / np.float32(2)}
    layers = buffers_from_moment_sums(_pooled(bin_sums[0], bin_sums[1]), _pooled(bin_sums[2], bin_sums[3]),
                                      2 * bin_spp, half_colors=half_means, clip_albedo=clip_albedo)
    for j, (mean, variance) in bins.items():
        layers[f"color_bin{j}"] = np.ascontiguousarray(mean)
        layers[f"variance_bin{j}"] = np.ascontiguousarray(variance)
    return layers


def buffers_from_moment_sums(sums_a: dict, sums_b: dict, half_spp: int, *,
                             half_colors: dict[str, np.ndarray] | None = None,
                             clip_albedo: bool = True) -> dict[str, np.ndarray]:
    """Float32 layers of :data:`ALL_LAYERS` from the per-half moment sums.

    ``sums_a[q]``/``sums_b[q]`` = (sum of m1·n, sum of m2·n) over the passes of one half buffer
    of ``half_spp`` samples, for every quantity q of :data:`CHANNELS` and those of
    :data:`FEATURE_CHANNELS` the sums hold (layers of quantities they lack are left out). Means and
    variances of the mean for A, B and the pooled full image (``2 * half_spp`` samples); a quantity
    with a ``{q}_count`` sum (the Tungsten convention's depth, albedo and position:
    :data:`PATH_FEATURE_CHANNELS`) is averaged over the samples that recorded it
    (:func:`weighted_mean_variance`). ``half_colors`` (``{"_a": ..., "_b": ...}``, float32
    (H, W, 3)) replaces the colour means of the halves (the bins' average,
    :func:`buffers_from_bin_sums`). ``clip_albedo``: clip the albedo means to [0, 1] (first-hit
    features: Mitsuba's AOV exceeds 1 on glossy conductors); the Tungsten convention clips each
    sample's reflectance instead and keeps the emission of emitters on top (as Tungsten).
    """
    sums = {"_a": sums_a, "_b": sums_b}
    layers = {}
    pooled = _pooled(sums["_a"], sums["_b"])
    quantities = [q for q in (*CHANNELS, *FEATURE_CHANNELS) if q in sums_a]
    for suffix, n, moments in (("_a", half_spp, sums["_a"]), ("_b", half_spp, sums["_b"]),
                               ("", 2 * half_spp, pooled)):
        for quantity in quantities:
            count = moments.get(f"{quantity}_count")
            if count is not None and n >= 2:
                mean, variance = weighted_mean_variance(*moments[quantity], count[0])
            elif n >= 2:
                mean, variance = moments_to_mean_variance(*moments[quantity], n)
            elif count is not None:   # one sample per half: its value where it recorded, as below
                mean = weighted_mean_variance(*moments[quantity], count[0])[0]
                other = "_b" if suffix == "_a" else "_a"
                partner = weighted_mean_variance(*sums[other][quantity], sums[other][f"{quantity}_count"][0])[0]
                variance = 0.5 * (mean - partner) ** 2
            else:  # spp = 2: one sample per half buffer, no within-buffer variance exists.
                # 0.5 * (a - b)^2 is an unbiased estimate of the variance of one sample,
                # i.e. of the mean of one sample; A and B both get it.
                mean = moments[quantity][0]
                diff = sums["_a"][quantity][0] - sums["_b"][quantity][0]
                variance = 0.5 * diff * diff
            name_var = ("variance" if quantity == "color" else quantity + "_variance") + suffix
            layers[quantity + suffix] = _squeeze(mean).astype(np.float32)
            layers[name_var] = _squeeze(variance).astype(np.float32)
    for suffix, color in (half_colors or {}).items():
        layers["color" + suffix] = np.asarray(color, dtype=np.float32)
    # The full image is by definition (A + B) / 2, computed on the float32 halves so that the
    # identity holds exactly for consumers that recompute it; a quantity averaged over the samples
    # that recorded it (a ``{q}_count`` sum) keeps the mean over the pooled recorded samples, as
    # Tungsten's output buffer gives it (a half that recorded nothing must not halve the other's).
    for quantity in quantities:
        if f"{quantity}_count" not in pooled:
            layers[quantity] = (layers[quantity + "_a"] + layers[quantity + "_b"]) / np.float32(2)
    # Mitsuba's albedo AOV can exceed 1 on glossy conductors (it evaluates the BSDF near the
    # specular peak); denoisers expect reflectance in [0, 1], so the means are clipped (the
    # albedo variances stay those of the raw samples).
    for suffix in ("", "_a", "_b") if clip_albedo else ():
        layers["albedo" + suffix] = np.clip(layers["albedo" + suffix], 0.0, 1.0)
    return {name: np.ascontiguousarray(layers[name], dtype=np.float32) for name in ALL_LAYERS if name in layers}


def merge_reference_chunks(chunks: list[tuple[dict, dict]]) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Merge reference chunks (``render_reference_chunk`` outputs, or the same read back from
    EXR with string metadata) into one reference, weighting each chunk by its spp, in float64.

    Output layers (float32): ``color`` (H, W, 3) mean of all samples, ``variance`` (H, W, 3)
    variance of that mean ``(M2 - mean^2) / (N - 1)`` with ``M2`` the pooled mean of squares and
    ``N`` the total spp (clamped at 0), ``albedo``, ``normal`` (H, W, 3), ``depth`` (H, W).
    Refuses chunks of different scene, resolution, variant, Mitsuba version or feature convention
    (metadata ``features``, ``first_hit`` where absent), and chunks sharing a seed (the same chunk
    twice).
    """
    if not chunks:
        raise BenchError("merge_reference_chunks: no chunks given")
    first = chunks[0][1]
    seen_seeds: dict[str, int] = {}
    for index, (layers, meta) in enumerate(chunks):
        # a chunk written before the key existed has first-hit features
        if str(meta.get("features", "first_hit")) != str(first.get("features", "first_hit")):
            raise BenchError(f"reference chunk {meta.get('chunk', index)} has features "
                             f"'{meta.get('features', 'first_hit')}' but chunk {first.get('chunk', 0)} has "
                             f"'{first.get('features', 'first_hit')}'; render the chunks under one convention")
        for key in ("scene", "resolution", "variant", "mitsuba"):
            if key in first and str(meta.get(key)) != str(first[key]):
                raise BenchError(f"reference chunk {meta.get('chunk', index)} has {key} "
                                 f"'{meta.get(key)}' but chunk {first.get('chunk', 0)} has "
                                 f"'{first[key]}'; all chunks of a reference must match")
        shape = layers["color"].shape
        if shape != chunks[0][0]["color"].shape:
            raise BenchError(f"reference chunk {meta.get('chunk', index)} is {shape[:2]}, chunk "
                             f"{first.get('chunk', 0)} is {chunks[0][0]['color'].shape[:2]}")
        for s in str(meta.get("seeds", "")).split(","):
            if s and s in seen_seeds:
                raise BenchError(f"reference chunks {seen_seeds[s]} and {meta.get('chunk', index)} "
                                 f"share seed {s} (the same chunk merged twice?)")
            if s:
                seen_seeds[s] = meta.get("chunk", index)
    weights = np.array([float(meta["spp"]) for _, meta in chunks])
    total = float(weights.sum())

    def pooled(name: str) -> np.ndarray:
        return sum(w * np.asarray(layers[name], dtype=np.float64)
                   for w, (layers, _) in zip(weights, chunks)) / total

    mean, m2 = pooled("color"), pooled("color_m2")
    variance = np.maximum(m2 - mean * mean, 0.0) / max(total - 1.0, 1.0)
    out = {"color": mean, "variance": variance}
    for quantity in FEATURES:
        out[quantity] = pooled(quantity)
    out = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in out.items()}
    metadata = {
        "scene": str(first.get("scene", "")), "spp": str(int(total)), "chunks": str(len(chunks)),
        "variant": str(first.get("variant", "")), "resolution": str(first.get("resolution", "")),
        "mitsuba": str(first.get("mitsuba", "")), "seed": str(first.get("seed", "")),
        "seeds": ",".join(str(meta.get("seeds", "")) for _, meta in chunks),
        "seconds": f"{sum(float(meta.get('seconds', 0.0)) for _, meta in chunks):.3f}",
        "features": str(first.get("features", "first_hit")),
    }
    return out, metadata
