"""Make the golden feature buffers of Tungsten's path tracer (the renderer of the ensemble paper).

Writes the Tungsten scene file of ``tests/data/golden/tungsten_features/scene.py`` (its ``QUADS``,
camera and bounce limit in Tungsten's scene format, :func:`tungsten_scene`), runs the built
``tungsten`` renderer on it (fixed seed, one thread, uniform random sampler, no adaptive sampling)
and stores its colour, albedo, normal and depth buffers and their per-pixel variances (Tungsten's
``sample_variance``: the variance of the pixel mean) as float32 arrays in ``tungsten_features.npz``,
with ``scene.json`` (the file Tungsten read), ``manifest.json`` (command, Tungsten commit, build
flags, spp, seed, seconds, SHA-256 of every file, machine) and ``README.md`` (provenance and the
build recipe, :data:`BUILD_RECIPE`), under ``--out`` (default ``tests/data/golden/tungsten_features``).

Run (after building ``tungsten``, see :data:`BUILD_RECIPE`)::

    . .venv/bin/activate
    python tools/golden/tungsten_features.py --tungsten <build>/tungsten

The Mitsuba side is not rendered here: ``tests/render/test_tungsten_features_golden.py`` renders
``scene.py``'s Mitsuba twin with :func:`mcbench.render.renderer.render_dict_buffers` (``features=
"tungsten"``) and compares. ``--check`` prints that comparison's summary (our render against the
stored golden) without writing anything.

Conventions of Tungsten 88ea020 this tool relies on (read from its source):

* pinhole camera (``src/core/cameras/PinholeCamera.cpp``): local direction
  ``(-1 + 2 (x + 0.5 + u) / W, H/W - 2 (y + 0.5 + v) / W, 1 / tan(fov / 2))`` with the box filter's
  ``u, v`` in [-0.5, 0.5]: ``fov`` spans x (horizontal, Mitsuba's ``fov_axis: "x"``), pixel row 0 at
  the top, column 0 at the camera's left (``Camera::fromJson`` negates the right axis of the
  ``position``/``look_at``/``up`` frame, whose x axis is ``up x forward``);
* output buffers (``src/core/cameras/OutputBuffer.hpp``): a pixel's value is the mean over the
  samples that *recorded* it (per-pixel count), ``<file>Variance.pfm`` is M2 / (n (n - 1)), the
  variance of that mean (0/0 = NaN where no sample recorded: stored as 0, like the mean); PFMs are
  written bottom row first (``ImageIO.cpp`` ``savePfm``) and read back top row first here;
* ``renderer.adaptive_sampling`` is on by default and would spend samples unevenly: switched off;
  ``stratified_sampler`` (Sobol) is switched off so that every sample is independent and the
  sample variances are honest variances of the mean.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from mcbench.io.tungsten_buffers import read_pfm  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from tungsten_nfor import TUNGSTEN_COMMIT, TUNGSTEN_REPO, machine, sha256  # noqa: E402  (the NFOR goldens' tool)

GOLDEN = ROOT / "tests" / "data" / "golden" / "tungsten_features"
SCENE_MODULE = GOLDEN / "scene.py"
NPZ_FILE = "tungsten_features.npz"
SCENE_FILE = "scene.json"
SPP = 1024
SEED = 7                  # Tungsten's --seed (its default is 0xBA5EBA11)
THREADS = 1
#: Tungsten buffer type -> (file stem, array name); the variance file is ``<stem>Variance.pfm``.
BUFFERS = {"color": ("color", "color"), "albedo": ("albedo", "albedo"),
           "normal": ("normal", "normal"), "depth": ("depth", "depth")}

BUILD_RECIPE = f"""\
Source: {TUNGSTEN_REPO} at commit {TUNGSTEN_COMMIT}. Only CMakeLists.txt, cmake/, src/ and
LICENSE.txt are needed (the `fetch` mirror lacks some large data blobs, so:
`git --git-dir=<mirror> archive {TUNGSTEN_COMMIT} -- CMakeLists.txt cmake src LICENSE.txt | tar -x -C tungsten`).
Build dependencies (Debian 12): `apt-get install cmake g++ make libeigen3-dev` (here cmake 3.25.1,
g++ 12.2.0, Eigen 3.4.0-4; Eigen only enables the `denoiser` target, not needed for `tungsten`).
OpenEXR was absent (outputs are PFM; CMake: "No OpenEXR detected"), libjpeg 62 was found
(irrelevant here), Qt5 absent (no editor).

    cd tungsten
    cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DTARGET_ARCHITECTURE=nehalem
    cmake --build build --target tungsten -j2

`CMAKE_BUILD_TYPE=Release` gives -O3 -DNDEBUG. `TARGET_ARCHITECTURE=nehalem` (-march=nehalem: SSE4.2,
no AVX, no FMA) because the bundled `cmake/OptimizeForArchitecture.cmake` does not recognise the
AMD EPYC (family 25 model 17, Zen 4) and stops with "The target machine does not support SSE3"; it also keeps the
floating-point code free of FMA contraction. The target builds Tungsten's `core`, `thirdparty`
and bundled `embree` static libraries and links `build/tungsten` (`tungsten -v`: version 0.2.2;
about 5 minutes on 2 shared cores; 205 compiler warnings, no errors).
"""


def load_scene_module(path: Path = SCENE_MODULE):
    """``scene.py`` of the golden folder as a module (it is data, not a package)."""
    spec = importlib.util.spec_from_file_location("tungsten_features_scene", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def tungsten_scene(scene, spp: int = SPP) -> dict:
    """Tungsten scene file (a JSON dict) of the scene module ``scene`` (``scene.py``)."""
    width, height = scene.RESOLUTION
    primitives = []
    for name, (_, _, _, kind, albedo, emission) in scene.QUADS.items():
        bsdf = {"type": {"diffuse": "lambert", "mirror": "mirror"}[kind], "albedo": list(albedo)}
        primitive = {"name": name, "type": "quad", "transform": scene.tungsten_matrix(name), "bsdf": bsdf}
        if emission is not None:
            primitive["emission"] = list(emission)
        primitives.append(primitive)
    outputs = [{"type": kind, "hdr_output_file": f"{stem}.pfm", "sample_variance": True,
                "two_buffer_variance": False} for kind, (stem, _) in BUFFERS.items()]
    return {
        "media": [],
        "bsdfs": [],
        "primitives": primitives,
        "camera": {
            "type": "pinhole",
            "resolution": [int(width), int(height)],
            "fov": float(scene.FOV_DEG),
            "reconstruction_filter": "box",
            "tonemap": "linear",
            "transform": {"position": list(scene.CAMERA_ORIGIN), "look_at": list(scene.CAMERA_TARGET),
                          "up": list(scene.CAMERA_UP)},
        },
        "integrator": {
            "type": "path_tracer",
            "min_bounces": 0,
            "max_bounces": int(scene.MAX_BOUNCES),
            "enable_consistency_checks": False,
            "enable_two_sided_shading": True,
            "enable_light_sampling": True,
            "enable_volume_light_sampling": True,
            "low_order_scattering": True,
            "include_surfaces": True,
        },
        "renderer": {
            "output_file": "",
            "hdr_output_file": "",
            "overwrite_output_files": True,
            "adaptive_sampling": False,
            "enable_resume_render": False,
            "stratified_sampler": False,
            "scene_bvh": True,
            "spp": int(spp),
            "spp_step": 16,
            "checkpoint_interval": "0",
            "timeout": "0",
            "output_buffers": outputs,
        },
    }


def _read(path: Path) -> np.ndarray:
    """A Tungsten PFM as float32, top row first, NaN (0/0 variance of an unrecorded pixel) -> 0."""
    image = np.asarray(read_pfm(path), dtype=np.float32)
    return np.nan_to_num(image, nan=0.0, posinf=0.0, neginf=0.0)


def run_tungsten(tungsten: Path, workdir: Path, spp: int, seed: int, threads: int) -> tuple[list[str], float, str]:
    """Run ``tungsten -t threads -s seed scene.json`` in ``workdir``; (command, seconds, log)."""
    command = [str(tungsten), "-t", str(threads), "-s", str(seed), "--spp", str(spp), SCENE_FILE]
    start = time.perf_counter()
    result = subprocess.run(command, cwd=workdir, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    missing = [stem for stem, _ in BUFFERS.values() if not (workdir / f"{stem}.pfm").exists()]
    if result.returncode != 0 or missing or "error" in result.stdout.lower():
        raise SystemExit(f"tungsten failed in {workdir} (exit {result.returncode}, missing {missing}):\n"
                         f"{result.stdout}\n{result.stderr}")
    return command, seconds, result.stdout


def collect(workdir: Path) -> dict[str, np.ndarray]:
    """The stored arrays: ``<q>`` and ``<q>_variance`` for q in color, albedo, normal ((H, W, 3))
    and depth ((H, W)), float32, top row first."""
    arrays = {}
    for stem, name in BUFFERS.values():
        arrays[name] = _read(workdir / f"{stem}.pfm")
        arrays[f"{name}_variance"] = _read(workdir / f"{stem}Variance.pfm")
    return arrays


def readme(manifest: dict) -> str:
    shapes = manifest["arrays"]
    rows = "\n".join(f"| `{name}` | {tuple(shape)} | {WHAT[name]} |" for name, shape in shapes.items())
    return f"""# Golden feature buffers of Tungsten's path tracer

Made by `tools/golden/tungsten_features.py` on {manifest['date']} ({manifest['machine']}), Python
{manifest['python']}. Command: `{manifest['command']}` (the binary's path and SHA-256 as run: `manifest.json`).
Used by `tests/render/test_tungsten_features_golden.py`, which renders the Mitsuba twin of the
same scene (`scene.py`, `build`) with our renderer's Tungsten feature convention
(`mcbench/render/path_features.py`) and compares.

## Tungsten

Repository {TUNGSTEN_REPO}, commit `{TUNGSTEN_COMMIT}` (the renderer of Bitterli et al.'s
NFOR data and of the ensemble-denoising paper; `src/core/integrators/path_tracer/PathTracer.cpp`
records the feature buffers). No Tungsten code is in this project; these files are its input and
outputs.

{BUILD_RECIPE}
Render: `{' '.join(manifest['tungsten_command'])}` in a scratch directory holding `scene.json`
({manifest['spp']} spp, seed {manifest['seed']}, {manifest['threads']} thread, {manifest['tungsten_seconds']:.2f} s).
The per-tile samplers are seeded from `--seed` only, so the output does not depend on the thread
count.

## The scene

`scene.py` describes it once for both renderers: a 45-degree perfect mirror (Tungsten `mirror`,
albedo 0.9) showing a red diffuse wall (its normal faces away from the scene: seen from its back
side, two-sided shading, so the recorded normal shows it is not flipped), a diffuse floor, a
quad area light (lambert, emission 6) and open background (no environment), pinhole camera, {manifest['resolution'][0]}x{manifest['resolution'][1]} pixels,
horizontal fov {manifest['fov_deg']} degrees, box pixel filter, `max_bounces` {manifest['max_bounces']}.
`scene.json` is the file Tungsten read, written by `tungsten_scene()` of the tool: every shape a
`quad` with the row-major `transform` of `scene.tungsten_matrix` (columns edge0, normal, edge1,
centre), BSDFs inline, `renderer.adaptive_sampling` false (Tungsten's default would spread the
samples unevenly), `stratified_sampler` false (independent uniform samples: honest variances),
`output_buffers` color, albedo, normal and depth with `sample_variance`.

Tungsten's conventions behind the scene file (source at the commit above): a `quad` is the unit
square [-0.5, 0.5]^2 of its local xz plane, `edge0 = T(1, 0, 0)`, `edge1 = T(0, 0, 1)`, normal
`normalize(edge1 x edge0)` (`Quad::prepareForRender`), shading normal = that normal unflipped
(`Quad::intersectionInfo`), emission one-sided (`Quad::evalDirect` is 0 on the back);
`max_bounces` N visits surface vertices 0 .. N-1 and samples lights only below N-1, so the
emitter is at most the N-th intersection: Mitsuba's `max_depth` N (`scene.py`, `MAX_BOUNCES`);
pinhole `fov` spans the image width, row 0 at the top, column 0 at the camera's left (the colour
images of both renderers agree without any flip: the test compares them).

## Files

`{NPZ_FILE}` (numpy, compressed): float32 arrays, row 0 at the top (as `read_pfm` returns
Tungsten's bottom-up PFMs):

| array | shape | what |
| --- | --- | --- |
{rows}

Tungsten's buffers average a pixel over the samples that *recorded* the quantity
(`OutputBuffer::addSample` counts per pixel): depth and albedo skip paths that leave the scene
before a non-specular vertex (albedo: no environment here; depth: except a camera ray that escapes,
which records 0), so a `*_variance` is M2 / (n (n - 1)) with that pixel's own n; a pixel where no
sample recorded has mean 0 and variance 0 (Tungsten writes 0/0 = NaN there; stored as 0). A
pixel with a single recorded sample has variance 0 as well.

`manifest.json`: commands, Tungsten commit, binary SHA-256, build flags, spp, seed, seconds, the
machine and the SHA-256 of every file here.
"""


WHAT = {
    "color": "radiance (Tungsten's `color` output buffer), mean over the pixel's samples",
    "color_variance": "variance of that mean (sample variance / n)",
    "albedo": ("albedo at the first non-specular vertex (BSDF albedo + emission of an emitter), "
               "mean over recording samples"),
    "albedo_variance": "variance of that mean",
    "normal": ("shading normal at the first non-specular vertex (world, not flipped); "
               "-d of the last ray for paths that leave"),
    "normal_variance": "variance of that mean",
    "depth": "summed hit distance to the first non-specular vertex; 0 for escaping camera rays",
    "depth_variance": "variance of that mean",
}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tungsten", default=os.environ.get("TUNGSTEN_RENDERER"),
                        help="Tungsten's built renderer (default $TUNGSTEN_RENDERER)")
    parser.add_argument("--out", type=Path, default=GOLDEN)
    parser.add_argument("--spp", type=int, default=SPP)
    parser.add_argument("--seed", type=int, default=SEED)
    parser.add_argument("--threads", type=int, default=THREADS)
    parser.add_argument("--build-flags", default="-DCMAKE_BUILD_TYPE=Release -DTARGET_ARCHITECTURE=nehalem",
                        help="CMake flags of the build, recorded in manifest.json")
    parser.add_argument("--readme-only", action="store_true",
                        help="only rewrite README.md from the existing manifest.json")
    parser.add_argument("--keep", type=Path, help="also copy Tungsten's raw PFM outputs here")
    args = parser.parse_args(argv)
    if args.readme_only:
        (args.out / "README.md").write_text(readme(json.loads((args.out / "manifest.json").read_text())))
        return
    if not args.tungsten or not Path(args.tungsten).is_file():
        parser.error(f"no tungsten binary: {args.tungsten!r} (give --tungsten or set TUNGSTEN_RENDERER)")
    tungsten = Path(args.tungsten).resolve()
    version = subprocess.run([str(tungsten), "-v"], capture_output=True, text=True).stdout.strip()

    scene = load_scene_module(args.out / "scene.py")
    description = tungsten_scene(scene, args.spp)
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="tungsten_features_") as tmp:
        workdir = Path(tmp)
        (workdir / SCENE_FILE).write_text(json.dumps(description, indent=1) + "\n")
        command, seconds, log = run_tungsten(tungsten, workdir, args.spp, args.seed, args.threads)
        arrays = collect(workdir)
        shutil.copyfile(workdir / SCENE_FILE, args.out / SCENE_FILE)
        if args.keep:
            args.keep.mkdir(parents=True, exist_ok=True)
            for path in workdir.iterdir():
                shutil.copyfile(path, args.keep / path.name)
    np.savez_compressed(args.out / NPZ_FILE, **arrays)
    print(f"tungsten: {args.spp} spp in {seconds:.2f} s; wrote {args.out / NPZ_FILE}", flush=True)

    manifest = {
        "tool": "tools/golden/tungsten_features.py",
        "command": "python tools/golden/tungsten_features.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": machine(), "python": platform.python_version(),
        "tungsten": {"repository": TUNGSTEN_REPO, "commit": TUNGSTEN_COMMIT, "binary": str(tungsten),
                     "binary_sha256": sha256(tungsten), "version": version, "build_flags": args.build_flags,
                     "build_target": "tungsten"},
        "tungsten_command": [Path(command[0]).name, *command[1:]],
        "tungsten_cwd": "scratch directory holding scene.json",
        "tungsten_seconds": round(seconds, 3), "tungsten_log": log.strip().splitlines(),
        "spp": args.spp, "seed": args.seed, "threads": args.threads,
        "resolution": list(scene.RESOLUTION), "fov_deg": scene.FOV_DEG, "max_bounces": scene.MAX_BOUNCES,
        "arrays": {name: list(a.shape) for name, a in arrays.items()},
        "sha256": {p.name: sha256(p) for p in sorted(args.out.iterdir())
                   if p.is_file() and p.name not in ("manifest.json", "README.md")},
    }
    (args.out / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
    (args.out / "README.md").write_text(readme(manifest))


if __name__ == "__main__":
    main()
