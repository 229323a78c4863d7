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

Seeds (see :func:`render_seed`)
-------------------------------
Every ``mi.render`` call gets its own 32-bit seed, laid out as bit fields::

    bit 31..29  base_seed   global seed from the config, 0..7
    bit 28      kind        0 = noisy render, 1 = reference chunk
    bit 27..16  field       noisy: (spp_code << 1) | half    reference: chunk (0..4095)
    bit 15..0   pass        pass index within one buffer / chunk (0..65535)

``spp_code`` is ``spp/2 - 1`` for spp <= 2048 (any even spp) and ``1023 + spp/2048`` for
larger multiples of 2048 up to 2**21; ``half`` is 0 for buffer A and 1 for buffer B. The map
from (base_seed, kind, spp, half, chunk, pass) to the seed is injective (each field has its own
bits and every field value decodes back, see :func:`decode_seed`), so no two renders ever share
a seed. In the LLVM variants Mitsuba seeds lane ``i`` of the wavefront with
``TEA(seed, i)``, a bijection of the pair, so distinct seeds give distinct random streams.

The scalar variant seeds pixel by pixel with ``seed * W * H + block_id * B^2 + i`` (B = block
size, i = pixel in the block), which would wrap around 2**32 and collide for seeds like ours.
There each buffer/chunk is rendered in one pass (pass 0; no wavefront limit on the CPU), with
the Mitsuba seed ``(seed >> 16) * m`` where ``m = ceil(blocks * B^2 / (W*H))``; renders are
refused unless ``((seed >> 16) + 1) * m * W * H <= 2**32``, so the pixel seed ranges of two
different renders are disjoint integer intervals (see :func:`mitsuba_seed`).
"""

from __future__ import annotations

import glob
import math
import os
import re
import sys
import time

import numpy as np

from mcbench import BenchError
from mcbench.buffers import ALL_LAYERS

__all__ = ["RenderError", "pick_variant", "render_seed", "decode_seed", "mitsuba_seed",
           "passes_for", "render_buffers", "render_reference_chunk", "merge_reference_chunks",
           "moments_to_mean_variance", "buffers_from_moment_sums", "MAX_WAVEFRONT"]

MAX_WAVEFRONT = 2 ** 22          # samples per mi.render call in vectorised variants (W*H*spp_pass)
MIN_LLVM_MAJOR = 19              # older libLLVM versions crash Dr.Jit 1.5 on this machine
SCALAR_BLOCK_SIZE = 16           # explicit block size in scalar variants (seed ranges depend on it)
AOVS = "albedo:albedo,nn:sh_normal,dd:depth"
LLVM_SEARCH_PATTERNS = ("/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/llvm-*/lib/libLLVM*.so*",
                        "/usr/lib64/libLLVM*.so*", "/usr/local/lib/libLLVM*.so*",
                        "/usr/lib/libLLVM*.so*", "/opt/homebrew/opt/llvm/lib/libLLVM*.dylib")

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
FEATURES = ("albedo", "normal", "depth")


class RenderError(BenchError):
    """Rendering failed or produced unusable numbers; the message names scene and spp."""


# --------------------------------------------------------------------------- variants

_active_variant: str | None = None


def _llvm_major(path: str) -> int | None:
    """LLVM major version from a library file name (``libLLVM.so.19.1``, ``libLLVM-19.so``)."""
    match = re.search(r"libLLVM(?:\.so\.|-|\.)(\d+)", os.path.basename(path))
    return int(match.group(1)) if match else None


def find_libllvm() -> tuple[str | None, str]:
    """Path of a usable libLLVM (major >= 19) and a one-line reason when there is none.

    ``DRJIT_LIBLLVM_PATH`` is used when it names an existing file whose version is >= 19 or
    cannot be told from its name; otherwise the newest libLLVM >= 19 in the usual folders.
    """
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    reason = "no libLLVM >= %d found" % MIN_LLVM_MAJOR
    if env:
        major = _llvm_major(env)
        if os.path.isfile(env) and (major is None or major >= MIN_LLVM_MAJOR):
            return env, ""
        reason = (f"DRJIT_LIBLLVM_PATH={env} is " +
                  ("missing" if not os.path.isfile(env) else f"LLVM {major} (< {MIN_LLVM_MAJOR})"))
    found = [(major, path) for pattern in LLVM_SEARCH_PATTERNS for path in glob.glob(pattern)
             if (major := _llvm_major(path)) is not None and major >= MIN_LLVM_MAJOR
             and os.path.isfile(path)]
    if found:
        return max(found)[1], ""
    return None, reason


def pick_variant(requested: str = "auto") -> str:
    """Set the Mitsuba variant once per process and return its name.

    ``"auto"`` gives ``cuda_ad_rgb`` when Dr.Jit finds a CUDA GPU (cluster/GPU runs of the
    paper-scale config), else ``llvm_ad_rgb`` when a libLLVM >= 19 is usable (``DRJIT_LIBLLVM_PATH`` is
    then set to it), else ``scalar_rgb`` with one line on stderr saying why. An explicit
    variant is honoured; a variant Mitsuba lacks raises :class:`BenchError` naming the config
    key ``variant``. Asking for a different variant after one was set raises too.
    """
    global _active_variant
    import mitsuba as mi

    if _active_variant is not None:
        if requested in ("auto", _active_variant):
            return _active_variant
        raise BenchError(f"config key 'variant': this process already renders with "
                         f"'{_active_variant}' and cannot switch to '{requested}'")
    if requested == "auto" and _cuda_usable():
        variant = "cuda_ad_rgb"
    elif requested == "auto":
        library, reason = find_libllvm()
        variant = "scalar_rgb"
        if library is not None:
            os.environ["DRJIT_LIBLLVM_PATH"] = library
            import drjit as dr
            if "llvm_ad_rgb" in mi.variants() and dr.has_backend(dr.JitBackend.LLVM):
                variant = "llvm_ad_rgb"
            else:
                reason = f"Dr.Jit cannot use the LLVM backend with {library}"
        if variant == "scalar_rgb":
            print(f"mcbench.render: using scalar_rgb (3-4x slower): {reason}", file=sys.stderr)
    else:
        variant = requested
        if variant not in mi.variants():
            raise BenchError(f"config key 'variant': Mitsuba {mi.__version__} has no variant "
                             f"'{variant}'; available: {', '.join(mi.variants())}")
        if variant.startswith("llvm_"):
            library, reason = find_libllvm()
            if library is None:
                raise BenchError(f"config key 'variant': '{variant}' needs libLLVM >= "
                                 f"{MIN_LLVM_MAJOR} ({reason}); use 'auto' or 'scalar_rgb'")
            os.environ["DRJIT_LIBLLVM_PATH"] = library
    mi.set_variant(variant)
    _active_variant = variant
    return variant


def _cuda_usable() -> bool:
    """True when Mitsuba has ``cuda_ad_rgb`` and Dr.Jit can initialise its CUDA backend."""
    import drjit as dr
    import mitsuba as mi

    try:
        return "cuda_ad_rgb" in mi.variants() and bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # no driver, no device: fall through to the CPU variants
        return False


def set_threads(threads: int | None) -> None:
    """Set the Dr.Jit thread pool size (used by both scalar and LLVM variants) when given."""
    if threads is not None:
        import drjit as dr
        if int(threads) < 1:
            raise BenchError(f"config key 'render_threads': must be >= 1, got {threads}")
        dr.set_thread_count(int(threads))


# --------------------------------------------------------------------------- seeds

_SPP_SMALL = 2048        # every even spp up to this has its own code
_SPP_STEP = 2048         # above it, multiples of this up to _SPP_STEP * 1024


def spp_code(spp: int) -> int:
    """11-bit code of a noisy spp level: ``spp/2 - 1`` for even spp <= 2048, else
    ``1023 + spp/2048`` for multiples of 2048 up to 2**21 (codes 1025..2047)."""
    spp = int(spp)
    if spp >= 2 and spp % 2 == 0 and spp <= _SPP_SMALL:
        return spp // 2 - 1
    if spp > _SPP_SMALL and spp % _SPP_STEP == 0 and spp // _SPP_STEP <= 1024:
        return 1023 + spp // _SPP_STEP
    raise BenchError(f"config key 'spp': {spp} spp has no seed code; use an even spp <= 2048 or a "
                     f"multiple of 2048 up to {_SPP_STEP * 1024}")


def render_seed(kind: str, spp: int | None = None, half: int | None = None, chunk: int | None = None,
                pass_index: int = 0, base_seed: int = 0) -> int:
    """32-bit Mitsuba seed of one render pass (layout in the module docstring).

    ``kind`` is ``"noisy"`` (needs ``spp`` = total spp of the full image and ``half`` 0 = A,
    1 = B) or ``"reference"`` (needs ``chunk``). Distinct arguments give distinct seeds.
    """
    base_seed, pass_index = int(base_seed), int(pass_index)
    if not 0 <= base_seed <= 7:
        raise BenchError(f"config key 'seed': must be in 0..7, got {base_seed}")
    if not 0 <= pass_index < 1 << 16:
        raise BenchError(f"pass index {pass_index} out of range 0..65535 (too many passes; "
                         f"lower the spp or the resolution)")
    if kind == "noisy":
        if half not in (0, 1):
            raise ValueError(f"half must be 0 (A) or 1 (B), got {half!r}")
        field, kind_bit = (spp_code(spp) << 1) | half, 0
    elif kind == "reference":
        if chunk is None or not 0 <= int(chunk) < 1 << 12:
            raise BenchError(f"config key 'reference.chunks': chunk {chunk} out of range 0..4095")
        field, kind_bit = int(chunk), 1
    else:
        raise ValueError(f"kind must be 'noisy' or 'reference', got {kind!r}")
    return (base_seed << 29) | (kind_bit << 28) | (field << 16) | pass_index


def decode_seed(seed: int) -> dict:
    """Inverse of :func:`render_seed`: the fields a seed was made from."""
    base, kind_bit, field, pass_index = seed >> 29, (seed >> 28) & 1, (seed >> 16) & 0xFFF, seed & 0xFFFF
    out = {"base_seed": base, "kind": "reference" if kind_bit else "noisy", "pass_index": pass_index}
    if kind_bit:
        out["chunk"] = field
    else:
        code, out["half"] = field >> 1, field & 1
        out["spp"] = 2 * (code + 1) if code < 1024 else _SPP_STEP * (code - 1023)
    return out


def scalar_seed_stride(width: int, height: int, block_size: int = SCALAR_BLOCK_SIZE) -> int:
    """Smallest ``m`` with ``m * W * H >=`` the pixel-seed range ``blocks * B^2`` that one
    scalar-variant render uses (Mitsuba adds ``block_id * B^2 + i`` to ``seed * W * H``)."""
    blocks = math.ceil(width / block_size) * math.ceil(height / block_size)
    return math.ceil(blocks * block_size ** 2 / (width * height))


def mitsuba_seed(seed: int, variant: str, width: int, height: int) -> int:
    """The seed handed to ``mi.render``: ``seed`` itself in vectorised variants; in scalar
    variants ``(seed >> 16) * m`` (see module docstring), refusing a wrap-around of 2**32."""
    if not variant.startswith("scalar"):
        return seed
    if seed & 0xFFFF:
        raise ValueError("scalar variants render each buffer in one pass (pass index 0)")
    index, stride = seed >> 16, scalar_seed_stride(width, height)
    if (index + 1) * stride * width * height > 1 << 32:
        raise BenchError(f"config key 'variant': scalar_rgb cannot give disjoint seeds at "
                         f"{width}x{height} with this seed/spp/chunk (pixel seeds would wrap "
                         f"around 2**32); use llvm_ad_rgb, a lower 'seed' or a smaller resolution")
    return index * stride


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


# --------------------------------------------------------------------------- rendering

_scene_cache: dict = {}


def _resolve(scene: str, resolution) -> tuple:
    from scenes import load_scene

    module = load_scene(scene)
    width, height = (resolution if resolution is not None else module.RESOLUTION)
    return module, int(width), int(height)


def _load(scene: str, module, width: int, height: int, variant: str):
    """The Mitsuba scene object with the moment/aov wrapper, box filter and independent sampler
    (cached per process)."""
    import mitsuba as mi

    key = (scene, width, height, variant)
    if key not in _scene_cache:
        desc = module.build(width, height)
        integrator = desc["integrator"]
        desc["integrator"] = {"type": "moment",
                              "nested": {"type": "aov", "aovs": AOVS, "integrator": integrator}}
        if variant.startswith("scalar"):
            desc["integrator"]["block_size"] = SCALAR_BLOCK_SIZE
        sensor_key = next(k for k, v in desc.items() if isinstance(v, dict)
                          and v.get("type") in ("perspective", "thinlens", "orthographic"))
        sensor = dict(desc[sensor_key])
        film = dict(sensor["film"])
        if (int(film["width"]), int(film["height"])) != (width, height):
            raise RenderError(f"scene '{scene}': build({width}, {height}) made a "
                              f"{film['width']}x{film['height']} film")
        film["rfilter"] = {"type": "box"}
        for crop_key in ("crop_width", "crop_height", "crop_offset_x", "crop_offset_y"):
            film.pop(crop_key, None)
        sensor["film"] = film
        sensor["sampler"] = {"type": "independent", "sample_count": 1}
        desc[sensor_key] = sensor
        try:
            _scene_cache[key] = (mi.load_dict(desc), integrator)
        except Exception as exc:
            raise RenderError(f"scene '{scene}': Mitsuba cannot load it ({exc})") from exc
    return _scene_cache[key]


def _channel_indices(scene_object) -> dict[str, tuple[list[int], list[int]]]:
    """Indices of the m1 and m2 channels of each quantity in the developed film, by name."""
    names = [field.name for field in scene_object.sensors()[0].film().bitmap().struct_()]
    if names[:3] != ["R", "G", "B"] or len(names) != 31:
        raise RenderError(f"unexpected film channels {names}")
    try:
        return {q: ([names.index(c) for c in m1], [names.index(c) for c in m2])
                for q, (m1, m2) in CHANNELS.items()}
    except ValueError as exc:
        raise RenderError(f"film channel missing ({exc}); channels are {names}") from exc


def _render_pass(scene_object, spp: int, seed: int) -> np.ndarray:
    """One ``mi.render`` call: the developed film as float64 (H, W, 31)."""
    import mitsuba as mi

    return np.asarray(mi.render(scene_object, spp=spp, seed=seed), dtype=np.float64)


def _render_sums(scene: str, scene_object, pass_spp: list[int], seeds: list[int],
                 variant: str, width: int, height: int, total_spp: int) -> dict[str, tuple]:
    """Render the passes and return, per quantity, float64 sums (S1, S2) of samples and squared
    samples, each (H, W, C) with C = 3 (color, albedo, normal) or 1 (depth)."""
    sums = {}
    for spp, seed in zip(pass_spp, seeds):
        image = _render_pass(scene_object, spp, mitsuba_seed(seed, variant, width, height))
        index = _channel_indices(scene_object)
        color = image[..., index["color"][0]]
        if not np.all(np.isfinite(color)) or not np.all(np.isfinite(image[..., index["color"][1]])):
            bad = int((~np.isfinite(image)).any(axis=2).sum())
            raise RenderError(f"scene '{scene}' at {total_spp} spp: Mitsuba produced NaN/Inf in "
                              f"{bad} pixel(s) (pass seed {seed}, variant {variant})")
        for quantity, (m1, m2) in index.items():
            s1, s2 = image[..., m1] * spp, image[..., m2] * spp
            if quantity in sums:
                sums[quantity] = (sums[quantity][0] + s1, sums[quantity][1] + s2)
            else:
                sums[quantity] = (s1, s2)
    return sums


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


def render_buffers(scene: str, spp: int, *, resolution: tuple[int, int] | None = None,
                   variant: str = "auto", seed: int = 0, threads: int | None = None
                   ) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Render the two independent half buffers A and B (spp/2 samples each) of ``scene``.

    Returns float32 layers for every name in :data:`mcbench.buffers.ALL_LAYERS`: ``color*``
    (H, W, 3) linear radiance, ``variance*`` (H, W, 3) variance of the mean, ``albedo*``,
    ``normal*`` (H, W, 3), ``depth*`` (H, W) and their ``*_variance`` layers; the full-image
    versions are ``(A + B) / 2`` and the variances from the pooled moments of all spp samples.
    Metadata (strings): scene, spp, variant, seed, seeds_a, seeds_b, mitsuba, seconds,
    resolution (``WxH``), integrator, passes.
    """
    if not isinstance(spp, (int, np.integer)) or spp < 2 or spp % 2:
        raise BenchError(f"config key 'spp': scene '{scene}' needs an even spp >= 2, got {spp}")
    spp = int(spp)
    module, width, height = _resolve(scene, resolution)
    variant = pick_variant(variant)
    set_threads(threads)
    start = time.perf_counter()
    scene_object, integrator = _load(scene, module, width, height, variant)
    half_spp = spp // 2
    pass_spp = passes_for(half_spp, width, height, variant)
    seeds, sums = {}, {}
    for half, suffix in ((0, "_a"), (1, "_b")):
        seeds[suffix] = [render_seed("noisy", spp=spp, half=half, pass_index=p, base_seed=seed)
                         for p in range(len(pass_spp))]
        sums[suffix] = _render_sums(scene, scene_object, pass_spp, seeds[suffix], variant,
                                    width, height, spp)
    layers = buffers_from_moment_sums(sums["_a"], sums["_b"], half_spp)
    seconds = time.perf_counter() - start
    metadata = {
        "scene": scene, "spp": str(spp), "variant": variant, "seed": str(seed),
        "seeds_a": ",".join(map(str, seeds["_a"])), "seeds_b": ",".join(map(str, seeds["_b"])),
        "mitsuba": _mitsuba_version(), "seconds": f"{seconds:.3f}",
        "resolution": f"{width}x{height}", "integrator": _describe(integrator),
        "passes": str(len(pass_spp)),
    }
    return layers, metadata


def buffers_from_moment_sums(sums_a: dict, sums_b: dict, half_spp: int) -> dict[str, np.ndarray]:
    """Float32 layers of :data:`ALL_LAYERS` from the per-half moment sums.

    ``sums_a[q]``/``sums_b[q]`` = (sum of m1·n, sum of m2·n) over the passes of one half buffer
    of ``half_spp`` samples, for every quantity q of :data:`CHANNELS`. Means and variances of the
    mean for A, B and the pooled full image (``2 * half_spp`` samples).
    """
    sums = {"_a": sums_a, "_b": sums_b}
    layers = {}
    pooled = {q: (sums["_a"][q][0] + sums["_b"][q][0], sums["_a"][q][1] + sums["_b"][q][1])
              for q in CHANNELS}
    for suffix, n, moments in (("_a", half_spp, sums["_a"]), ("_b", half_spp, sums["_b"]),
                               ("", 2 * half_spp, pooled)):
        for quantity in CHANNELS:
            if n >= 2:
                mean, variance = moments_to_mean_variance(*moments[quantity], n)
            else:  # spp = 2: one sample per half buffer, no within-buffer variance exists.
                # 0.5 * (a - b)^2 is an unbiased estimate of the variance of one sample,
                # i.e. of the mean of one sample; A and B both get it.
                mean = moments[quantity][0]
                diff = sums["_a"][quantity][0] - sums["_b"][quantity][0]
                variance = 0.5 * diff * diff
            name_var = ("variance" if quantity == "color" else quantity + "_variance") + suffix
            layers[quantity + suffix] = _squeeze(mean).astype(np.float32)
            layers[name_var] = _squeeze(variance).astype(np.float32)
    # The full image is by definition (A + B) / 2, computed on the float32 halves so that the
    # identity holds exactly for consumers that recompute it.
    for quantity in CHANNELS:
        layers[quantity] = (layers[quantity + "_a"] + layers[quantity + "_b"]) / np.float32(2)
    # Mitsuba's albedo AOV can exceed 1 on glossy conductors (it evaluates the BSDF near the
    # specular peak); denoisers expect reflectance in [0, 1], so the means are clipped (the
    # albedo variances stay those of the raw samples).
    for suffix in ("", "_a", "_b"):
        layers["albedo" + suffix] = np.clip(layers["albedo" + suffix], 0.0, 1.0)
    return {name: np.ascontiguousarray(layers[name], dtype=np.float32) for name in ALL_LAYERS}


def _describe(integrator: dict) -> str:
    return ",".join(f"{k}={v}" for k, v in sorted(integrator.items()))


def render_reference_chunk(scene: str, spp: int, chunk: int, *, resolution: tuple[int, int] | None = None,
                           variant: str = "auto", seed: int = 0, threads: int | None = None
                           ) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Render chunk ``chunk`` (0-based) of a reference: ``spp`` samples with seeds disjoint from
    every noisy render and every other chunk.

    Layers (float32): ``color`` (H, W, 3) sample mean, ``color_m2`` (H, W, 3) mean of squared
    samples, ``albedo``, ``normal`` (H, W, 3) and ``depth`` (H, W) sample means. Metadata
    (strings): scene, spp, chunk, variant, seed, seeds, mitsuba, seconds, resolution, integrator.
    """
    if not isinstance(spp, (int, np.integer)) or spp < 1:
        raise BenchError(f"config key 'reference.spp': scene '{scene}' needs spp >= 1, got {spp}")
    spp, chunk = int(spp), int(chunk)
    module, width, height = _resolve(scene, resolution)
    variant = pick_variant(variant)
    set_threads(threads)
    start = time.perf_counter()
    scene_object, integrator = _load(scene, module, width, height, variant)
    pass_spp = passes_for(spp, width, height, variant)
    seeds = [render_seed("reference", chunk=chunk, pass_index=p, base_seed=seed)
             for p in range(len(pass_spp))]
    sums = _render_sums(scene, scene_object, pass_spp, seeds, variant, width, height, spp)
    layers = {"color": sums["color"][0] / spp, "color_m2": sums["color"][1] / spp}
    for quantity in FEATURES:
        layers[quantity] = _squeeze(sums[quantity][0] / spp)
    layers = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in layers.items()}
    metadata = {
        "scene": scene, "spp": str(spp), "chunk": str(chunk), "variant": variant,
        "seed": str(seed), "seeds": ",".join(map(str, seeds)), "mitsuba": _mitsuba_version(),
        "seconds": f"{time.perf_counter() - start:.3f}", "resolution": f"{width}x{height}",
        "integrator": _describe(integrator),
    }
    return layers, metadata


def merge_reference_chunks(chunks: list[tuple[dict, dict]]) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Merge reference chunks (``render_reference_chunk`` outputs, or the same read back from
    EXR with string metadata) into one reference, weighting each chunk by its spp, in float64.

    Output layers (float32): ``color`` (H, W, 3) mean of all samples, ``variance`` (H, W, 3)
    variance of that mean ``(M2 - mean^2) / (N - 1)`` with ``M2`` the pooled mean of squares and
    ``N`` the total spp (clamped at 0), ``albedo``, ``normal`` (H, W, 3), ``depth`` (H, W).
    Refuses chunks of different scene, resolution, variant or Mitsuba version, and chunks
    sharing a seed (the same chunk twice).
    """
    if not chunks:
        raise BenchError("merge_reference_chunks: no chunks given")
    first = chunks[0][1]
    seen_seeds: dict[str, int] = {}
    for index, (layers, meta) in enumerate(chunks):
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
    }
    return out, metadata
