"""Make the golden outputs of Tungsten's NFOR ``denoiser`` on small renders of this project.

For every scene and spp level: render the buffers (:func:`mcbench.render.renderer.render_buffers`,
fixed resolution and seed), write a Tungsten case folder (:func:`mcbench.io.tungsten_buffers.write_case`:
``scene.json`` and float32 PFMs), run the built ``denoiser`` on it (working directory = the case
folder, ``denoiser scene.json tungsten_nfor.pfm``) and keep its output. Per scene also a reference
image (the ``color`` of a high-spp render with another seed). Writes, under ``--out``
(default ``tests/data/golden/tungsten_nfor``):

* ``<scene>_spp<N>/``: the case (inputs exactly as Tungsten read them) and ``tungsten_nfor.pfm``;
* ``<scene>_reference.pfm``;
* ``manifest.json``: per case the render metadata, the command, the denoiser's seconds, SHA-256 of
  every file; tool, machine and date;
* ``README.md``: provenance and the build recipe (:data:`BUILD_RECIPE`).

Run (after building the denoiser, see :data:`BUILD_RECIPE`)::

    . .venv/bin/activate
    python tools/golden/tungsten_nfor.py --denoiser <build>/denoiser

The renders use one thread and fixed seeds; Mitsuba's output can still differ across Mitsuba
versions and CPUs, which is why the inputs are stored with the outputs (the tests read the stored
inputs, never re-render).
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from mcbench.io.tungsten_buffers import SCENE_FILE, write_case, write_pfm  # noqa: E402

TUNGSTEN_REPO = "https://github.com/tunabrain/tungsten"
TUNGSTEN_COMMIT = "88ea02044dbaf20472a8173b6752460b50c096d8"
OUTPUT_FILE = "tungsten_nfor.pfm"
DEFAULT_SCENES = ("cornell_box", "envmap_objects", "fine_textures")
DEFAULT_SPP = (8, 64)
RESOLUTION = 32            # a multiple of Tungsten's 32-px tiles (docs/fidelity_nfor.md, "Suspected problems")
SEED = 3                   # base seed of the noisy renders (0..6 allowed, mcbench.render.seeds)
REFERENCE_SEED = 5         # base seed of the reference renders
REFERENCE_SPP = 4096

#: Markers of the README section that ``tools/golden/tungsten_nfor_intermediates.py`` writes;
#: :func:`write_readme` keeps that section when it rewrites the README.
MARK_BEGIN = "<!-- intermediates: written by tools/golden/tungsten_nfor_intermediates.py -->"
MARK_END = "<!-- end of intermediates -->"

BUILD_RECIPE = f"""\
Source: {TUNGSTEN_REPO} at commit {TUNGSTEN_COMMIT}. Only CMakeLists.txt, cmake/, src/ and
LICENSE.txt are needed (a full checkout also works; here the `fetch` mirror lacked some large
data blobs, so: `git --git-dir=<mirror> archive {TUNGSTEN_COMMIT} -- CMakeLists.txt cmake src
LICENSE.txt > tungsten.tar && tar -xf tungsten.tar -C tungsten`).
Build dependencies (Debian 12): `apt-get install cmake g++ make libeigen3-dev` (here cmake 3.25.1,
g++ 12.2.0, Eigen 3.4.0-4; the `denoiser` target exists only when CMake finds Eigen3). OpenEXR is
not needed (cases and outputs are PFM) and was absent; libjpeg was found (irrelevant here).

    cd tungsten
    cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DTARGET_ARCHITECTURE=nehalem
    cmake --build build --target denoiser -j2

`CMAKE_BUILD_TYPE=Release` gives -O3 -DNDEBUG (Tungsten's CMakeLists.txt sets no optimisation
of its own). `TARGET_ARCHITECTURE=nehalem` (-march=nehalem: SSE4.2, no AVX, no FMA) is needed
because the bundled `cmake/OptimizeForArchitecture.cmake` does not recognise this AMD EPYC
(Zen 3) and then stops with "The target machine does not support SSE3"; it also keeps the
floating-point code free of FMA contraction, so other x86-64 machines should reproduce the
outputs bit for bit. The target builds Tungsten's `core`, `thirdparty` and bundled `embree`
static libraries that `denoiser` links (CMakeLists.txt:147-156), nothing else (about 8 minutes
on 2 cores). The binary is `build/denoiser` (`denoiser -v`: version 0.2.2).
"""


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def machine() -> str:
    cpu = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{platform.system()} {platform.release()} {platform.machine()}, {cpu}, {os.cpu_count()} CPUs"


def run_denoiser(denoiser: Path, case: Path) -> tuple[list[str], float]:
    """Run ``denoiser scene.json tungsten_nfor.pfm`` in ``case``; returns (command, seconds)."""
    command = [str(denoiser), SCENE_FILE, OUTPUT_FILE]
    start = time.perf_counter()
    result = subprocess.run(command, cwd=case, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if result.returncode != 0 or not (case / OUTPUT_FILE).exists():
        raise SystemExit(f"denoiser failed in {case} (exit {result.returncode}):\n{result.stdout}\n{result.stderr}")
    return command, seconds


def write_readme(path: Path, text: str) -> None:
    """Write ``text`` to ``path``, keeping an existing intermediates section (:data:`MARK_BEGIN`)."""
    old = path.read_text() if path.exists() else ""
    if MARK_BEGIN in old and MARK_END in old:
        section = old[old.index(MARK_BEGIN):old.index(MARK_END) + len(MARK_END)]
        text = text.rstrip("\n") + "\n\n" + section + "\n"
    path.write_text(text)


def readme(manifest: dict) -> str:
    cases = "\n".join(f"| `{name}/` | {c['scene']} | {c['spp']} | {c['seed']} | {c['denoiser_seconds']:.2f} |"
                      for name, c in manifest["cases"].items())
    derived = sorted({d for c in manifest["cases"].values() for d in c["derived"]})
    return f"""# Golden outputs of Tungsten's NFOR denoiser

Made by `tools/golden/tungsten_nfor.py` on {manifest['date']} ({manifest['machine']}), Python
{manifest['python']}, Mitsuba {manifest['mitsuba']} (variant `{manifest['variant']}`).
Command: `python tools/golden/tungsten_nfor.py --denoiser <build>/denoiser` (the build's path as run: `manifest.json`).
Used by `tests/methods/test_nfor_golden.py`; `tools/golden/tungsten_nfor_departures.py` measures our
NFOR's departures against these files and `tools/golden/tungsten_nfor_float32.py` the float32
rounding noise that bounds the agreement (`docs/fidelity_nfor.md`, section "Golden comparison").

## Tungsten

Repository {TUNGSTEN_REPO}, commit `{TUNGSTEN_COMMIT}` (`src/denoiser/`, the NFOR authors' public
re-implementation of Bitterli et al. 2016). No Tungsten code is in this project; these files are
its inputs and outputs.

{BUILD_RECIPE}
Per case the denoiser ran as `denoiser scene.json {OUTPUT_FILE}` with the case folder as working
directory (it has no options; every constant is hard-coded; it used max(CPUs - 1, 1) threads).

## Files

Each case folder `<scene>_spp<N>/` ({manifest['resolution']}x{manifest['resolution']} pixels, noisy
render with base seed {SEED}, one render thread):

| file | what |
| --- | --- |
| `scene.json` | Tungsten scene file: only `renderer.output_buffers` color, normal, albedo, depth, each with `sample_variance` and `two_buffer_variance` |
| `color.pfm`, `colorA.pfm`, `colorB.pfm` | our layers `color` (= (A + B) / 2), `color_a`, `color_b`, (H, W, 3) float32 radiance |
| `colorVariance.pfm` | our `variance`: per-pixel, per-channel variance of the full-buffer mean (sample variance / n), as Tungsten's renderer writes it |
| `normal*.pfm`, `albedo*.pfm` | likewise `normal`, `normal_a`, `normal_b`, `normal_variance` and the `albedo` ones |
| `depth*.pfm` | likewise for `depth`, one channel (`Pf`) |
| `colorVarianceOfA.pfm`, `colorVarianceOfB.pfm` | our `variance_a`, `variance_b` (not read by Tungsten; lets our default estimator run on a case) |
| `{OUTPUT_FILE}` | Tungsten's output (the second-pass regression), (H, W, 3) float32 |

PFMs are little-endian float32, rows stored bottom to top (`mcbench/io/tungsten_buffers.py`).
Feature variances derived as (A - B)^2 / 4 because the render lacked them: {derived or 'none'}.
`<scene>_reference.pfm`: the `color` of a {REFERENCE_SPP}-spp render of the scene (base seed
{REFERENCE_SEED}), for errors against the truth. `manifest.json` holds per case the render metadata,
the denoiser's seconds and the SHA-256 of every file.

| case | scene | spp | seed | denoiser seconds |
| --- | --- | --- | --- | --- |
{cases}
"""


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--denoiser", default=os.environ.get("TUNGSTEN_DENOISER"),
                        help="Tungsten's built denoiser (default $TUNGSTEN_DENOISER)")
    parser.add_argument("--out", type=Path, default=ROOT / "tests" / "data" / "golden" / "tungsten_nfor")
    parser.add_argument("--scenes", nargs="+", default=list(DEFAULT_SCENES))
    parser.add_argument("--spp", nargs="+", type=int, default=list(DEFAULT_SPP))
    parser.add_argument("--resolution", type=int, default=RESOLUTION)
    parser.add_argument("--reference-spp", type=int, default=REFERENCE_SPP)
    parser.add_argument("--variant", default="auto")
    parser.add_argument("--readme-only", action="store_true",
                        help="only rewrite README.md from the existing manifest.json (no render, no denoiser)")
    args = parser.parse_args(argv)
    if args.readme_only:
        write_readme(args.out / "README.md", readme(json.loads((args.out / "manifest.json").read_text())))
        return
    if not args.denoiser or not Path(args.denoiser).is_file():
        parser.error(f"no denoiser binary: {args.denoiser!r} (give --denoiser or set TUNGSTEN_DENOISER)")
    denoiser = Path(args.denoiser).resolve()

    import scenes
    from mcbench.render.renderer import render_buffers

    args.out.mkdir(parents=True, exist_ok=True)
    size = (args.resolution, args.resolution)
    manifest = {"tool": "tools/golden/tungsten_nfor.py", "tungsten": {"repository": TUNGSTEN_REPO,
                "commit": TUNGSTEN_COMMIT, "denoiser": str(denoiser), "denoiser_sha256": sha256(denoiser)},
                "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
                "machine": machine(), "python": platform.python_version(),
                "command": "python tools/golden/tungsten_nfor.py " + " ".join(argv if argv is not None else sys.argv[1:]),
                "resolution": args.resolution, "seed": SEED, "reference_seed": REFERENCE_SEED,
                "reference_spp": args.reference_spp, "cases": {}, "references": {}}
    for scene in args.scenes:
        module = scenes.load_scene(scene)
        for spp in args.spp:
            layers, meta = render_buffers(module, spp, resolution=size, variant=args.variant, seed=SEED, threads=1)
            manifest["mitsuba"], manifest["variant"] = meta["mitsuba"], meta["variant"]
            case = args.out / f"{scene}_spp{spp}"
            _, _, derived = write_case(case, layers)
            command, seconds = run_denoiser(denoiser, case)
            manifest["cases"][case.name] = {
                "scene": scene, "spp": spp, "seed": SEED, "render": meta, "derived": derived,
                "command": command, "cwd": case.name, "denoiser_seconds": round(seconds, 3),
                "sha256": {p.name: sha256(p) for p in sorted(case.iterdir())}}
            print(f"{case.name}: rendered in {meta['seconds']} s, denoised in {seconds:.2f} s", flush=True)
        ref_layers, ref_meta = render_buffers(module, args.reference_spp, resolution=size, variant=args.variant,
                                              seed=REFERENCE_SEED, threads=1)
        ref = args.out / f"{scene}_reference.pfm"
        write_pfm(ref, ref_layers["color"])
        manifest["references"][ref.name] = {"scene": scene, "spp": args.reference_spp, "seed": REFERENCE_SEED,
                                            "render_seconds": ref_meta["seconds"], "sha256": sha256(ref)}
        print(f"{ref.name}: rendered in {ref_meta['seconds']} s", flush=True)
    (args.out / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
    write_readme(args.out / "README.md", readme(manifest))


if __name__ == "__main__":
    main()
