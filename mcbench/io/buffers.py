"""Render buffers shared by every method: the noisy full image, the two independent
half-sample buffers A and B, their per-pixel variances and the auxiliary features.

Conventions (all arrays float32, linear HDR radiance, row-major (H, W[, 3])):

* ``color = (color_a + color_b) / 2``; A and B hold spp/2 disjoint samples each.
* ``variance*`` is the per-pixel, per-channel variance *of the mean* (sample variance / n).
* ``albedo`` (H, W, 3) in [0, 1], ``normal`` (H, W, 3) shading normal in [-1, 1] (zero where
  no surface was hit), ``depth`` (H, W) distance along the camera ray (zero where no hit).
* ``position`` (H, W, 3) world-space position of the camera ray's first surface hit (Mitsuba's
  ``position`` AOV; zero where no surface was hit) and ``visibility`` (H, W) in [0, 1], the
  fraction of samples whose direct-light (emitter) sample at the first hit is unoccluded and
  contributes (RDFC's features, Rousselle et al. 2013; the authors' fbksd-package
  ``denoisers/RDFC/src/multifilm.cpp`` F:117-119 and F:123 ``R > 0``). The indicator is 0 on a
  miss and on purely specular or ``null`` surfaces, and geometric in media
  (:mod:`mcbench.render.visibility` says how each case is defined). Their ``*_variance`` layers
  are variances of the mean like the others. *Optional* (:data:`OPTIONAL_FEATURES`, not in
  :data:`REQUIRED_LAYERS`): every noisy Mitsuba render holds them; references, renders written
  before they existed and imported renders do not, and :class:`ImageBuffers` then has ``None``.
* Features come in full/A/B versions too, so a half-buffer denoise sees only its own samples
  (the dual-buffer estimate of the ensemble, Zheng et al. 2021 Eq. 10, assumes it).
* Sample bins (sample binning of Back et al. 2020 Sec. 4.4): renders whose spp is a multiple of 4
  also hold four quarter-sample bins ``color_bin{j}``/``variance_bin{j}`` (j = 0..3, spp/4
  disjoint samples each), bins 0-1 making half buffer A and bins 2-3 half buffer B:
  ``color_a = (color_bin0 + color_bin1) / 2``. So every image has two disjoint *sub-buffers* of
  its own samples (:data:`SUB_BUFFERS`): the full image has A and B, A has bins 0 and 1, B has
  bins 2 and 3, and a result computed for A from A's sub-buffers never sees B's samples. At
  4 spp a bin holds one sample; its variance is then ``(b0 - b1)^2 / 2`` from the two bins of its
  half (the unbiased one-sample variance, the same for both). Renders without bins (spp not a
  multiple of 4, files written before bins existed) load as before; only methods that need
  sub-buffers refuse them (:meth:`RenderBuffers.sub_images`).
* Renders imported from another renderer (:mod:`mcbench.io.render_folders`; header key
  ``imported_from``) hold only the layers their folder gives, e.g. no half buffers, variance or
  depth. Nothing stands in for a missing layer: an absent colour or variance is ``None`` in
  :class:`ImageBuffers`, and a single-image denoiser on a render without halves returns the full
  image only (``Denoised.a`` and ``.b`` are ``None``). The pipeline refuses, when the DAG is
  parsed, every method that reads a layer such a render lacks.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from mcbench import BenchError
from mcbench.io.exr import check_finite, check_resolution, read_layers, read_metadata

BUFFER_SUFFIXES = {"full": "", "a": "_a", "b": "_b"}
#: Index of each image of a case in seeds that run per image (e.g. SURE's perturbations).
IMAGE_INDEX = {"full": 0, "a": 1, "b": 2}
QUANTITIES = ("color", "variance", "albedo", "normal", "depth",
              "albedo_variance", "normal_variance", "depth_variance",
              "position", "visibility", "position_variance", "visibility_variance")
#: RDFC's features (module docstring): optional, renders made before them or elsewhere lack them.
OPTIONAL_FEATURES = ("position", "visibility")
# Layers every render must hold (full image, halves A and B, features); the rest are optional extras.
REQUIRED_LAYERS = ("color", "color_a", "color_b", "variance", "variance_a", "variance_b",
                   "albedo", "normal", "depth")
ALL_LAYERS = tuple(q + s for q in QUANTITIES for s in BUFFER_SUFFIXES.values())
BINS = 4
BIN_LAYERS = tuple(f"{q}_bin{j}" for q in ("color", "variance") for j in range(BINS))
# The two disjoint sample subsets of each image: layer suffixes of their colour and variance.
SUB_BUFFERS = {"full": ("_a", "_b"), "a": ("_bin0", "_bin1"), "b": ("_bin2", "_bin3")}
# Names under which a method's Denoised.extras holds its result on each image's sub-buffers (the
# kernel computed from all of the image's samples applied to each sub-buffer; Back et al. Sec. 5).
SUB_OUTPUTS = {"full": ("color_sub0", "color_sub1"), "a": ("color_a_sub0", "color_a_sub1"),
               "b": ("color_b_sub0", "color_b_sub1")}


@dataclass(frozen=True)
class ImageBuffers:
    """One noisy image (full, A or B) with its variance and features."""

    color: np.ndarray      # (H, W, 3)
    variance: np.ndarray | None   # (H, W, 3) variance of the mean; None: the render has none
    albedo: np.ndarray | None     # (H, W, 3)
    normal: np.ndarray | None     # (H, W, 3)
    depth: np.ndarray | None      # (H, W)
    spp: float             # samples behind this image
    position: np.ndarray | None = None    # (H, W, 3) world-space first hit; None: the render has none
    visibility: np.ndarray | None = None  # (H, W) in [0, 1]; None: the render has none

    @property
    def shape(self) -> tuple[int, int]:
        return self.color.shape[:2]


@dataclass(frozen=True)
class RenderBuffers:
    """All layers of one (scene, spp) render; ``layers`` maps layer name to array."""

    layers: dict
    spp: int
    source: str = "<memory>"

    def __getattr__(self, name):  # buffers.color_a, buffers.variance, ...
        layers = self.__dict__.get("layers", {})
        if name in layers:
            return layers[name]
        raise AttributeError(name)

    @property
    def shape(self) -> tuple[int, int]:
        return self.layers["color"].shape[:2]

    def image(self, which: str) -> ImageBuffers:
        """The full (``"full"``) or half (``"a"``/``"b"``) image with its own features.

        Half-buffer features fall back to the full-buffer ones when the render lacks them; colour
        and variance never do (a half's samples are its own). A quantity the render lacks is
        ``None`` (imported renders); an image without its colour raises :class:`mcbench.BenchError`.
        """
        suffix = BUFFER_SUFFIXES[which]
        if "color" + suffix not in self.layers:
            raise BenchError(f"{self.source}: the render has no image '{which}' (layer color{suffix})")

        def feature(q):
            return self.layers.get(q + suffix, self.layers.get(q))

        return ImageBuffers(color=self.layers["color" + suffix], variance=self.layers.get("variance" + suffix),
                            albedo=feature("albedo"), normal=feature("normal"), depth=feature("depth"),
                            spp=self.spp if which == "full" else self.spp / 2,
                            position=feature("position"), visibility=feature("visibility"))

    def has_halves(self) -> bool:
        """Whether the render holds the half buffers A and B (every Mitsuba render does; an
        imported one only when its folder gives them)."""
        return "color_a" in self.layers and "color_b" in self.layers

    def has_sub_buffers(self) -> bool:
        """Whether the render holds the four quarter-sample bins (spp a multiple of 4)."""
        return all(name in self.layers for name in BIN_LAYERS)

    def sub_images(self, which: str) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """The two disjoint sample subsets of image ``which`` (``"full"``, ``"a"``, ``"b"``; see
        :data:`SUB_BUFFERS`) as ``((color, variance), (color, variance))``, each (H, W, 3).

        Raises :class:`mcbench.BenchError` naming the file when the render has no bins.
        """
        suffixes = SUB_BUFFERS[which]
        missing = [q + s for s in suffixes for q in ("color", "variance") if q + s not in self.layers]
        if missing:
            raise BenchError(f"{self.source}: no sample bins {missing} (renders hold four quarter-sample "
                             f"bins only when spp is a multiple of 4; this one has {self.spp} spp)")
        return tuple((self.layers["color" + s], self.layers["variance" + s]) for s in suffixes)

    @classmethod
    def load(cls, path: str | Path, *, layers: tuple[str, ...] | None = None) -> "RenderBuffers":
        """Read a render EXR, refusing missing layers or NaN/Inf pixels (errors name the file).

        ``layers``: only these layers (plus ``color``, which gives the shape), e.g. a method's
        ``render_layers``; the rest are not kept (a render holds several times the layers most
        methods read). None: every layer, after checking :data:`REQUIRED_LAYERS` (an imported
        render, header key ``imported_from``: only ``color``; the pipeline checked its layers
        against its methods' when the DAG was parsed)."""
        path = Path(path)
        if layers is not None:
            wanted = list(dict.fromkeys(("color", *layers)))
            layers = read_layers(path, wanted)          # ExrError naming the file and the layer
            check_finite(path, layers)
            meta = read_metadata(path)
            check_resolution(path, layers["color"].shape, meta)
            return cls(layers=layers, spp=int(meta.get("spp", 0)), source=str(path))
        layers = read_layers(path)
        meta = read_metadata(path)
        required = ("color",) if meta.get("imported_from") else REQUIRED_LAYERS
        missing = [n for n in required if n not in layers]
        if missing:
            from mcbench.io.exr import ExrError
            raise ExrError(f"{path}: not a render file, missing layer(s) {missing}")
        check_finite(path, layers)
        check_resolution(path, layers["color"].shape, meta)
        spp = int(meta.get("spp", 0))
        return cls(layers=layers, spp=spp, source=str(path))


@dataclass(frozen=True)
class Denoised:
    """A method's output: denoised full image and the denoised half buffers A and B (``None``
    both, for a render without half buffers: an imported one, see the module docstring)."""

    full: np.ndarray  # (H, W, 3)
    a: np.ndarray | None
    b: np.ndarray | None
    extras: dict | None = None  # optional named layers (weight maps, selection maps, ...)

    source: str = "<memory>"

    def layers(self) -> dict[str, np.ndarray]:
        out = {"color": self.full, "color_a": self.a, "color_b": self.b}
        out = {name: image for name, image in out.items() if image is not None}
        out.update(self.extras or {})
        return out

    def image(self, which: str) -> np.ndarray:
        """The result on image ``which``: ``"full"``, ``"a"`` or ``"b"`` (BenchError naming the
        output when it has no half buffers)."""
        image = {"full": self.full, "a": self.a, "b": self.b}[which]
        if image is None:
            raise BenchError(f"{self.source}: no result on half buffer '{which}' (its render has no half buffers)")
        return image

    def sub_outputs(self, which: str) -> tuple[np.ndarray, np.ndarray]:
        """The method's result on the two sub-buffers of image ``which`` (:data:`SUB_OUTPUTS`),
        each (H, W, 3); raises :class:`mcbench.BenchError` naming the file when it has none."""
        names = SUB_OUTPUTS[which]
        extras = self.extras or {}
        missing = [n for n in names if n not in extras]
        if missing:
            raise BenchError(f"{self.source}: no sub-buffer results {missing} (only methods that expose a "
                             f"kernel, e.g. kpcn, write them, and only for renders with sample bins)")
        return extras[names[0]], extras[names[1]]

    @classmethod
    def load(cls, path: str | Path, *, extras: bool = False) -> "Denoised":
        """A method's output EXR: ``color``, ``color_a``, ``color_b`` and, with ``extras``, every
        other layer (sub-buffer results, weight maps) as :attr:`extras`. An output with neither
        half (a render without halves) loads with ``a`` and ``b`` None; one half alone is refused."""
        path = Path(path)
        from mcbench.io.exr import ExrError

        layers = read_layers(path)      # decodes every layer of the file either way
        halves = [n for n in ("color_a", "color_b") if n in layers]
        missing = [n for n in ("color", "color_a", "color_b") if n not in layers]
        if "color" in missing or len(halves) == 1:
            raise ExrError(f"{path}: not a method output, missing layer(s) {missing}")
        if not extras:
            layers = {n: layers[n] for n in ("color", *halves)}
        check_finite(path, layers)
        extras = {k: v for k, v in layers.items() if k not in ("color", "color_a", "color_b")}
        return cls(full=layers["color"], a=layers.get("color_a"), b=layers.get("color_b"), extras=extras or None,
                   source=str(path))


#: Prefix of a combiner's weight maps as its filter applied them, ``weights_filtered_{i}``, (H, W, 3)
#: per input i (its raw weights, ``weights_raw_{i}``, are in memory only).
FILTERED_WEIGHTS_PREFIX = "weights_filtered_"


def stored_layers(result: Denoised) -> dict[str, np.ndarray]:
    """The layers of method result ``result`` that its output EXR keeps: what a later step reads
    (so that a finished study stays small enough to move). The colour and the halves; of the extras, the sub-buffer
    results (:data:`SUB_OUTPUTS`: a multi-buffer combiner's inputs) and each
    ``weights_filtered_{i}`` as its mean over RGB, (H, W), the one thing the viewer shows of a
    weight map (:func:`mcbench.analysis.viewer_images.weight_map`). Left out, as no step reads them
    from a file (the oracle study and the tests take them from the result in memory): the raw
    weights ``weights_raw_{i}`` and every other extra (e.g. progressive denoising's α′ maps, NFOR's
    selection map)."""
    kept_extras = {name for names in SUB_OUTPUTS.values() for name in names}
    out = {}
    for name, layer in result.layers().items():
        if name.startswith(FILTERED_WEIGHTS_PREFIX):
            out[name] = np.asarray(layer, dtype=np.float64).mean(axis=2) if np.ndim(layer) == 3 else layer
        elif name in ("color", "color_a", "color_b") or name in kept_extras:
            out[name] = layer
    return out


def denoise_each_buffer(buffers: RenderBuffers,
                        denoise_image: Callable[[ImageBuffers], np.ndarray]) -> Denoised:
    """Run a single-image denoiser on the full buffer and on each half buffer.

    Each half buffer is denoised with its own features and variance only, keeping
    y^A independent of x^B as the dual-buffer estimate assumes (Zheng et al. Eq. 10). A render
    without half buffers (an imported one) gives the full image's result only.
    """
    if not buffers.has_halves():
        return Denoised(full=denoise_image(buffers.image("full")), a=None, b=None, source=buffers.source)
    return Denoised(full=denoise_image(buffers.image("full")),
                    a=denoise_image(buffers.image("a")),
                    b=denoise_image(buffers.image("b")))
