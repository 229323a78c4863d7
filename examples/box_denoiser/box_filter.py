"""A tiny external denoiser for mcbench's ``method: external`` (examples/box_denoiser/README.md):
a 5 x 5 box filter of the noisy colour, written as a stand-alone program (NumPy and the OpenEXR
bindings only, no mcbench), as a denoiser in another language would be.

    python box_filter.py --in INPUT_DIR --out OUTPUT_DIR --name NAME [--radius 2]

Reads ``color.exr``, ``colorA.exr``, ``colorB.exr`` (float32 R, G, B) from INPUT_DIR and writes
``NAME.exr``, ``NAMEA.exr``, ``NAMEB.exr`` into OUTPUT_DIR; exits 2 with a message on stderr
when an input is missing.
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import OpenEXR


def read_rgb(path: Path) -> np.ndarray:
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        channels = exr.channels()
        return np.stack([channels[c].pixels for c in "RGB"], axis=-1).astype(np.float32)


def write_rgb(path: Path, image: np.ndarray) -> None:
    header = {"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": np.ascontiguousarray(image, dtype=np.float32)}) as exr:
        exr.write(str(path))


def box_filter(image: np.ndarray, radius: int) -> np.ndarray:
    """Mean over the (2 radius + 1)^2 window, clipped at the borders (float64 sums)."""
    padded = np.pad(image.astype(np.float64), ((radius, radius), (radius, radius), (0, 0)))
    ones = np.pad(np.ones(image.shape[:2]), radius)
    total, count = np.zeros(image.shape), np.zeros(image.shape[:2])
    for dy in range(2 * radius + 1):
        for dx in range(2 * radius + 1):
            total += padded[dy:dy + image.shape[0], dx:dx + image.shape[1]]
            count += ones[dy:dy + image.shape[0], dx:dx + image.shape[1]]
    return total / count[..., None]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--in", dest="input_dir", type=Path, required=True)
    ap.add_argument("--out", dest="output_dir", type=Path, required=True)
    ap.add_argument("--name", required=True)
    ap.add_argument("--radius", type=int, default=2)
    args = ap.parse_args()
    for stem, suffix in (("color", ""), ("colorA", "A"), ("colorB", "B")):
        source = args.input_dir / f"{stem}.exr"
        if not source.is_file():
            print(f"box_filter: no {source}", file=sys.stderr)
            return 2
        write_rgb(args.output_dir / f"{args.name}{suffix}.exr", box_filter(read_rgb(source), args.radius))
    return 0


if __name__ == "__main__":
    sys.exit(main())
