"""Every 32-bit Mitsuba seed the harness uses: test renders, reference chunks, training renders.

Every ``mi.render`` call gets its own 32-bit seed. Two bit layouts share the 32 bits; their
top three bits (31..29, the *base seed*) tell them apart.

Test renders and reference chunks (:func:`render_seed`)::

    bit 31..29  base_seed   global seed from the config (key ``seed``), 0..6
    bit 28      kind        0 = noisy render, 1 = reference chunk
    bit 27..16  field       noisy: (spp_code << 1) | half    reference: chunk (0..4095)
    bit 15      bin         noisy: sample bin within the half (0 or 1; 0 for unbinned renders)
    bit 14..0   pass        pass index within one bin / buffer / chunk (0..32767)

``spp_code`` (:func:`spp_code`) is ``spp/2 - 1`` for spp <= 2048 (any even spp) and
``1023 + spp/2048`` for larger multiples of 2048 up to 2**21; ``half`` is 0 for buffer A and 1
for buffer B.

Training renders of the procedural scenes (:func:`training_render_seed`)::

    bit 31..29  7 = TRAINING_BASE_SEED (reserved: no config may use it)
    bit 28..13  training scene seed, 0..65535
    bit 12      0 = noisy render, 1 = target
    bit 11..0   noisy:  bit 11..8 log2(spp) (spp a power of two, 2..32768), bit 7 half
                        (0 = A, 1 = B), bit 6 bin within the half, bit 5..0 pass (0..63)
                target: pass (0..4095)

Oracle renders of the ground-truth statistics study (:func:`oracle_render_seed`, Zheng et
al. 2021 Sec. 5.2.7: one scene rendered many times at one spp)::

    bit 31..29  base_seed   global seed from the config (key ``seed``), 0..6
    bit 28      1           (shared with reference chunks)
    bit 27..16  field       (repetition << 2) | (half << 1) | bin; repetition 0..1023
    bit 15      1           oracle marker: every reference chunk seed has 0 here
    bit 14..0   pass        pass index within one bin / buffer (0..32767)

The repetition, half and bin sit above bit 15, so scalar variants (one pass per bin, seed
``>> 15`` an odd index, a reference chunk's is even) keep disjoint pixel-seed ranges too.
:func:`decode_seed` does not know this slot (it reads an oracle seed as a reference chunk);
:func:`decode_oracle_seed` decodes it and :func:`is_oracle_seed` tells it apart. The seed holds
neither scene nor spp (like a test render's, which holds no scene): two oracle studies of
different spp reuse the same streams, never a test, reference or training render's.

Renders of progressive denoising's consistency curve (:func:`progressive_curve_seed`: one scene
at every level of ``progressive_curve.spp``) sit in a hole of the training layout: base 7 with
bits 12..8 all zero, which no training seed has (its bit 12..8 hold the target flag or log2(spp)
>= 1); the config seed, half, bin and the level index fill the bits below. Its docstring gives
the layout and why it is disjoint from every other kind, scalar pixel ranges included.

Why no two renders share a seed
-------------------------------
Within each layout every field has its own bits and every field value decodes back
(:func:`decode_seed`, :func:`decode_training_seed`), so each layout is injective. Across the
layouts, the base seed of a test render is 0..6 (:func:`render_seed` refuses 7, and the config
schema caps ``seed`` at 6) while every training seed has base 7: the two images are disjoint
intervals ``[b * 2**29, (b + 1) * 2**29)`` of the 32-bit range. Oracle seeds have base 0..6 and
bits 28 and 15 both set, which no test render has (a noisy render has bit 28 = 0, a reference
chunk bit 15 = 0: :func:`render_seed` refuses ``bin`` for references). Training scene seeds are split
into two families: object scenes below :data:`FIBRE_SEED_BASE` (32768) and fibre scenes from it
on (:func:`training_seeds`).

In the LLVM/CUDA variants Mitsuba seeds lane ``i`` of the wavefront with ``TEA(seed, i)``, a
bijection of the pair, so distinct seeds give distinct random streams.

Scalar variants
---------------
The scalar variant seeds pixel by pixel with ``seed * W * H + block_id * B^2 + i`` (B = block
size :data:`SCALAR_BLOCK_SIZE`, i = pixel in the block), which would wrap around 2**32 and
collide for seeds like the harness's. There each bin/buffer/chunk is rendered in one pass (pass 0), with
the Mitsuba seed ``(seed >> 15) * m`` where ``m = ceil(blocks * B^2 / (W*H))``
(:func:`scalar_seed_stride`); renders are refused unless ``((seed >> 15) + 1) * m * W * H <=
2**32``, so the pixel seed ranges of two different renders are disjoint integer intervals
(:func:`mitsuba_seed`). (Since sample bins took bit 15, scalar references fit up to about
2**32 / 2**14 = 262144 pixels, i.e. 512x512, at base seed 0; use llvm_ad_rgb beyond.) These helpers live here, not with the renderer, because they are the
scalar-variant consequence of the render seed layout. Training renders refuse scalar variants
(their layout cannot keep the pixel ranges disjoint).

Pure integer arithmetic: no NumPy, no Mitsuba.
"""

from __future__ import annotations

import math

from mcbench import BenchError

__all__ = ["MAX_BASE_SEED", "TRAINING_BASE_SEED", "MAX_TRAINING_SEED", "FIBRE_SEED_BASE",
           "SCALAR_BLOCK_SIZE", "spp_code", "render_seed", "decode_seed", "training_render_seed",
           "decode_training_seed", "is_fibre_seed", "training_seeds", "scalar_seed_stride",
           "mitsuba_seed", "MAX_ORACLE_REPETITIONS", "oracle_render_seed", "decode_oracle_seed",
           "is_oracle_seed"]

TRAINING_BASE_SEED = 7          # bits 31..29 of every training render seed, reserved
MAX_BASE_SEED = TRAINING_BASE_SEED - 1   # largest config ``seed`` (test renders: 0..6)
MAX_TRAINING_SEED = (1 << 16) - 1
FIBRE_SEED_BASE = 1 << 15       # training scene seeds >= this are fibre scenes
SCALAR_BLOCK_SIZE = 16          # explicit block size in scalar variants (seed ranges depend on it)

MAX_ORACLE_REPETITIONS = 1 << 10   # repetitions of one oracle study (10 bits of the field)
_ORACLE_MARK = (1 << 28) | (1 << 15)

SPP_SMALL = 2048                # every even spp up to this has its own code
SPP_STEP = 2048                 # above it, multiples of this up to SPP_STEP * 1024


# --------------------------------------------------------------------------- test renders


def _check_base_seed(base_seed: int) -> None:
    """BenchError naming config key ``seed`` unless ``base_seed`` is in 0..MAX_BASE_SEED."""
    if not 0 <= base_seed <= MAX_BASE_SEED:
        raise BenchError(f"config key 'seed': must be in 0..{MAX_BASE_SEED} "
                         f"({TRAINING_BASE_SEED} is reserved for training renders), got {base_seed}")


def _check_index(value: int, limit: int, message: str) -> None:
    """BenchError ``message`` unless 0 <= ``value`` < ``limit``."""
    if not 0 <= value < limit:
        raise BenchError(message)


def _check_half_and_bin(half, bin) -> None:
    """ValueError unless ``half`` is 0 (A) or 1 (B) and ``bin`` is 0 or 1."""
    if half not in (0, 1):
        raise ValueError(f"half must be 0 (A) or 1 (B), got {half!r}")
    if bin not in (0, 1):
        raise ValueError(f"bin must be 0 or 1, got {bin!r}")

def spp_code(spp: int) -> int:
    """11-bit code of a noisy spp level: ``spp/2 - 1`` for even spp <= 2048, else
    ``1023 + spp/2048`` for multiples of 2048 up to 2**21 (codes 1025..2047)."""
    spp = int(spp)
    if spp >= 2 and spp % 2 == 0 and spp <= SPP_SMALL:
        return spp // 2 - 1
    if spp > SPP_SMALL and spp % SPP_STEP == 0 and spp // SPP_STEP <= 1024:
        return 1023 + spp // SPP_STEP
    raise BenchError(f"config key 'spp': {spp} spp has no seed code; use an even spp <= 2048 or a "
                     f"multiple of 2048 up to {SPP_STEP * 1024}")


def render_seed(kind: str, spp: int | None = None, half: int | None = None, chunk: int | None = None,
                pass_index: int = 0, base_seed: int = 0, bin: int = 0) -> int:
    """32-bit Mitsuba seed of one test render pass (layout in the module docstring).

    ``kind`` is ``"noisy"`` (needs ``spp`` = total spp of the full image, ``half`` 0 = A,
    1 = B, and ``bin`` 0/1, the sample bin within the half) or ``"reference"`` (needs
    ``chunk``). ``base_seed`` is the config's ``seed``, 0..:data:`MAX_BASE_SEED` (7 is reserved
    for training renders). Distinct arguments give distinct seeds.
    """
    base_seed, pass_index = int(base_seed), int(pass_index)
    _check_base_seed(base_seed)
    if not 0 <= pass_index < 1 << 15:
        raise BenchError(f"pass index {pass_index} out of range 0..32767 (too many passes; "
                         f"lower the spp or the resolution)")
    if bin not in (0, 1) or (bin and kind != "noisy"):
        raise ValueError(f"bin must be 0 or 1 (noisy renders only), got {bin!r}")
    pass_index |= int(bin) << 15
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
    """Inverse of :func:`render_seed`: the fields a seed was made from (a training seed decodes
    with ``base_seed`` 7 and meaningless other fields; see :func:`decode_training_seed`)."""
    base, kind_bit, field, pass_index = seed >> 29, (seed >> 28) & 1, (seed >> 16) & 0xFFF, seed & 0x7FFF
    out = {"base_seed": base, "kind": "reference" if kind_bit else "noisy", "pass_index": pass_index}
    if kind_bit:
        out["chunk"] = field
    else:
        code, out["half"], out["bin"] = field >> 1, field & 1, (seed >> 15) & 1
        out["spp"] = 2 * (code + 1) if code < 1024 else SPP_STEP * (code - 1023)
    return out


# --------------------------------------------------------------------------- training renders

def training_render_seed(scene_seed: int, kind: str, spp: int | None = None,
                         half: int | None = None, pass_index: int = 0, bin: int = 0) -> int:
    """32-bit Mitsuba seed of one training render pass (layout in the module docstring).

    ``kind`` is ``"noisy"`` (needs ``spp``, a power of two 2..32768, ``half`` 0/1 and ``bin``
    0/1, the sample bin within the half) or ``"target"``. Raises :class:`BenchError` for fields
    out of range.
    """
    scene_seed, pass_index = int(scene_seed), int(pass_index)
    if not 0 <= scene_seed <= MAX_TRAINING_SEED:
        raise BenchError(f"training seed {scene_seed} out of range 0..{MAX_TRAINING_SEED}")
    if kind == "noisy":
        spp = int(spp)
        if spp < 2 or spp & (spp - 1) or spp > 1 << 15:
            raise BenchError(f"training spp levels must be powers of two 2..32768, got {spp}")
        _check_half_and_bin(half, bin)
        if not 0 <= pass_index < 1 << 6:
            raise BenchError(f"noisy pass index {pass_index} out of range 0..63 (lower the spp "
                             f"or the resolution)")
        low = ((spp.bit_length() - 1) << 8) | (half << 7) | (int(bin) << 6) | pass_index
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
                   bin=(seed >> 6) & 1, pass_index=seed & 0x3F)
    return out


def is_fibre_seed(seed: int) -> bool:
    """Whether training scene ``seed`` belongs to the fibre family (seed >= 32768)."""
    return int(seed) >= FIBRE_SEED_BASE


def training_seeds(settings: dict) -> list[int]:
    """Scene seeds of a config's ``training`` section: ``first_seed .. first_seed + count - 1``
    (object family, must stay below :data:`FIBRE_SEED_BASE`) then ``fibre_count`` fibre scenes
    from :data:`FIBRE_SEED_BASE` on. All three keys are required (their defaults live in the
    config schema). Raises :class:`BenchError` naming the key."""
    missing = [key for key in ("first_seed", "count", "fibre_count") if key not in settings]
    if missing:
        raise BenchError(f"training: missing {', '.join('training.' + k for k in missing)}")
    first, count = int(settings["first_seed"]), int(settings["count"])
    fibres = int(settings["fibre_count"])
    if first < 0 or count < 1 or first + count > FIBRE_SEED_BASE:
        raise BenchError(f"training.first_seed + training.count must stay within 0..{FIBRE_SEED_BASE} "
                         f"(fibre scenes start there), got {first} + {count}")
    if not 0 <= fibres <= MAX_TRAINING_SEED + 1 - FIBRE_SEED_BASE:
        raise BenchError(f"training.fibre_count must be 0..{MAX_TRAINING_SEED + 1 - FIBRE_SEED_BASE}, "
                         f"got {fibres}")
    return list(range(first, first + count)) + list(range(FIBRE_SEED_BASE, FIBRE_SEED_BASE + fibres))


# --------------------------------------------------------------------------- oracle renders

def oracle_render_seed(repetition: int, half: int, *, bin: int = 0, pass_index: int = 0,
                       base_seed: int = 0) -> int:
    """32-bit Mitsuba seed of one pass of an oracle render (layout in the module docstring).

    ``repetition``: 0..:data:`MAX_ORACLE_REPETITIONS` - 1 (config key ``oracle.repetitions``
    plus the held-out one); ``half`` 0 = A, 1 = B; ``bin`` 0/1, the sample bin within the
    half; ``pass_index`` 0..32767; ``base_seed`` the config's ``seed`` (0..6). Distinct
    arguments give distinct seeds, none equal to a :func:`render_seed` or
    :func:`training_render_seed` value.
    """
    repetition, base_seed, pass_index = int(repetition), int(base_seed), int(pass_index)
    _check_base_seed(base_seed)
    _check_index(repetition, MAX_ORACLE_REPETITIONS, f"config key 'oracle.repetitions': repetition {repetition} "
                 f"out of range 0..{MAX_ORACLE_REPETITIONS - 1} (the held-out one included)")
    _check_half_and_bin(half, bin)
    _check_index(pass_index, 1 << 15, f"oracle pass index {pass_index} out of range 0..32767 (lower "
                 f"oracle.spp or the resolution)")
    field = (repetition << 2) | (half << 1) | int(bin)
    return (base_seed << 29) | _ORACLE_MARK | (field << 16) | pass_index


def is_oracle_seed(seed: int) -> bool:
    """Whether ``seed`` lies in the oracle slot (bits 28 and 15 set, base seed 0..6)."""
    seed = int(seed)
    return seed >> 29 <= MAX_BASE_SEED and seed & _ORACLE_MARK == _ORACLE_MARK


def decode_oracle_seed(seed: int) -> dict:
    """Inverse of :func:`oracle_render_seed`: ``base_seed``, ``repetition``, ``half``, ``bin``,
    ``pass_index``. Raises ValueError for a seed outside the oracle slot."""
    seed = int(seed)
    if not is_oracle_seed(seed):
        raise ValueError(f"seed {seed} is not an oracle render seed")
    field = (seed >> 16) & 0xFFF
    return {"base_seed": seed >> 29, "repetition": field >> 2, "half": (field >> 1) & 1,
            "bin": field & 1, "pass_index": seed & 0x7FFF}


# --------------------------------------------------------------------------- scalar variants

def scalar_seed_stride(width: int, height: int, block_size: int = SCALAR_BLOCK_SIZE) -> int:
    """Smallest ``m`` with ``m * W * H >=`` the pixel-seed range ``blocks * B^2`` that one
    scalar-variant render uses (Mitsuba adds ``block_id * B^2 + i`` to ``seed * W * H``)."""
    blocks = math.ceil(width / block_size) * math.ceil(height / block_size)
    return math.ceil(blocks * block_size ** 2 / (width * height))


def mitsuba_seed(seed: int, variant: str, width: int, height: int) -> int:
    """The seed handed to ``mi.render``: ``seed`` itself in vectorised variants; in scalar
    variants ``(seed >> 15) * m`` (see module docstring), refusing a wrap-around of 2**32."""
    if not variant.startswith("scalar"):
        return seed
    if seed & 0x7FFF:
        raise ValueError("scalar variants render each bin/buffer in one pass (pass index 0)")
    index, stride = seed >> 15, scalar_seed_stride(width, height)
    if (index + 1) * stride * width * height > 1 << 32:
        raise BenchError(f"config key 'variant': scalar_rgb cannot give disjoint seeds at "
                         f"{width}x{height} with this seed/spp/chunk (pixel seeds would wrap "
                         f"around 2**32); use llvm_ad_rgb, a lower 'seed' or a smaller resolution")
    return index * stride


# --------------------------------------------------------------------------- progressive-curve renders

MAX_PROGRESSIVE_CURVE_LEVELS = 1 << 9     # spp levels of one consistency curve (9 bits)
MAX_PROGRESSIVE_CURVE_PASSES = 1 << 10    # passes per bin of one level's render (10 bits)
_CURVE_ZERO_BITS = 0x1F00                 # bits 12..8: 0 here, never 0 in a training seed


def progressive_curve_seed(level_index: int, half: int, *, bin: int = 0, pass_index: int = 0,
                           base_seed: int = 0) -> int:
    """32-bit Mitsuba seed of one pass of a render of progressive denoising's consistency curve
    (:mod:`mcbench.pipeline.progressive_study`: one scene rendered at many spp levels, level ``i`` of the
    sorted levels seeded with ``level_index`` i)::

        bit 31..29  7 (the training renders' base seed: the slot is a hole of their layout)
        bit 28..26  base_seed   global seed from the config (key ``seed``), 0..6
        bit 25      half        0 = A, 1 = B
        bit 24      bin         sample bin within the half (0 or 1)
        bit 23..15  level index 0..511
        bit 14..13  pass index bits 9..8
        bit 12..8   0
        bit 7..0    pass index bits 7..0   (pass index 0..1023 in all)

    Why there: with base seed 0..6 every seed value (and every scalar pixel-seed index
    ``seed >> 15``) is a test render's, a reference chunk's or an oracle render's, except the
    four indices of the one unused spp code (1024) -- too few for a curve's levels. A training
    seed (base 7) has bit 12 set (target) or bits 11..8 = log2(spp) >= 1 (noisy, spp >= 2), so
    bits 12..8 are never all 0 there: every seed of this slot differs from every training seed
    and, having base 7, from every test, reference and oracle seed. In scalar variants (pass 0,
    ``seed >> 15`` = ``(7 << 14) | (base_seed << 11) | (half << 10) | (bin << 9) | level``) the
    pixel-seed indices are distinct per (base seed, level, half, bin) and above every test,
    reference and oracle index (those have base <= 6); training renders refuse scalar variants,
    so no scalar pixel range of theirs exists. The large index limits scalar curves to about
    33,000 pixels per render (e.g. 128 x 128; :func:`mitsuba_seed` refuses more, naming
    ``variant``); llvm_ad_rgb has no such limit. Like an oracle seed it holds neither scene nor
    spp: two curves with the same levels reuse the same streams, never another kind's.
    """
    level_index, base_seed, pass_index = int(level_index), int(base_seed), int(pass_index)
    _check_base_seed(base_seed)
    _check_index(level_index, MAX_PROGRESSIVE_CURVE_LEVELS, f"config key 'progressive_curve.spp': level "
                 f"{level_index} out of range 0..{MAX_PROGRESSIVE_CURVE_LEVELS - 1} (too many spp levels)")
    _check_half_and_bin(half, bin)
    _check_index(pass_index, MAX_PROGRESSIVE_CURVE_PASSES, f"config key 'progressive_curve.spp': pass index "
                 f"{pass_index} out of range 0..{MAX_PROGRESSIVE_CURVE_PASSES - 1} (lower the top spp level or "
                 f"the resolution)")
    return ((TRAINING_BASE_SEED << 29) | (base_seed << 26) | (half << 25) | (int(bin) << 24)
            | (level_index << 15) | ((pass_index >> 8) << 13) | (pass_index & 0xFF))


def is_progressive_curve_seed(seed: int) -> bool:
    """Whether ``seed`` lies in the progressive-curve slot (base 7, bits 12..8 all 0, config seed
    0..6 in bits 28..26)."""
    seed = int(seed)
    return seed >> 29 == TRAINING_BASE_SEED and not seed & _CURVE_ZERO_BITS and (seed >> 26) & 7 <= MAX_BASE_SEED


__all__ += ["MAX_PROGRESSIVE_CURVE_LEVELS", "MAX_PROGRESSIVE_CURVE_PASSES", "progressive_curve_seed",
            "is_progressive_curve_seed"]
