"""Golden intermediates of Tungsten's NFOR ``denoiser``: its first-pass regressions, MSE maps,
selection map and selected half-buffer results on the stored golden cases.

Tungsten's binary writes only the final (second-pass) image. ``tungsten_nfor_intermediates.patch``
(next to this file) is a minimal patch of ``src/denoiser/denoiser.cpp`` at the commit of
``tools/golden/tungsten_nfor.py`` that only adds ``Pixmap::save`` calls (9 lines); it changes no
computation. Build the patched ``denoiser`` exactly as :data:`tungsten_nfor.BUILD_RECIPE` says,
after::

    cd tungsten && patch -p1 < <mcbench>/tools/golden/tungsten_nfor_intermediates.patch

then run (it re-reads the stored cases of ``tests/data/golden/tungsten_nfor/``, renders nothing)::

    . .venv/bin/activate
    python tools/golden/tungsten_nfor_intermediates.py --denoiser <patched build>/denoiser

Per case it copies the case folder to a temporary directory, runs ``denoiser scene.json
out.pfm`` there (the patch writes ``nfor_*.pfm`` into the working directory), checks that the
final output is bit-identical to the stored ``tungsten_nfor.pfm`` (so the patched program is the
program of the goldens), and stores the intermediates, float32, in
``tests/data/golden/tungsten_nfor/intermediates.npz`` under ``"<case>/<name>"`` (names:
:data:`FILES`, the keys of ``methods.nfor.denoise(..., intermediates=True)``). Rewrites the
section of the folder's README.md between ``tungsten_nfor.MARK_BEGIN`` and ``MARK_END``, and
``intermediates.json`` (command, date, machine, SHA-256 of the binary, the patch and the npz).
"""

from __future__ import annotations

import argparse
import datetime
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from mcbench.io.tungsten_buffers import SCENE_FILE, read_pfm  # noqa: E402
from tungsten_nfor import (MARK_BEGIN, MARK_END, OUTPUT_FILE, TUNGSTEN_COMMIT, TUNGSTEN_REPO,  # noqa: E402
                           machine, sha256)

GOLDEN = ROOT / "tests" / "data" / "golden" / "tungsten_nfor"
PATCH = Path(__file__).resolve().parent / "tungsten_nfor_intermediates.patch"
NPZ = "intermediates.npz"
#: Tungsten's file (written by the patch) -> our name, and what it is (D = src/denoiser/denoiser.cpp
#: after the patch is not cited; lines are of the unpatched file).
FILES = {
    "nfor_filteredA_k0.5.pfm": ("filtered_a_k0.5", "pass-1 regression of half A at k = 0.5 (`filteredColorA`, D:63)"),
    "nfor_filteredB_k0.5.pfm": ("filtered_b_k0.5", "pass-1 regression of half B at k = 0.5 (`filteredColorB`, D:65)"),
    "nfor_filteredA_k1.0.pfm": ("filtered_a_k1.0", "the same at k = 1.0"),
    "nfor_filteredB_k1.0.pfm": ("filtered_b_k1.0", "the same at k = 1.0"),
    "nfor_mse_k0.5.pfm": ("mse_k0.5", "filtered MSE estimate at k = 0.5 (`mses[0]`, D:69-81)"),
    "nfor_mse_k1.0.pfm": ("mse_k1.0", "filtered MSE estimate at k = 1.0 (`mses[1]`)"),
    "nfor_selection.pfm": ("selection", "filtered selection map (`selection`, D:88-94)"),
    "nfor_resultA.pfm": ("result_a", "selected half A, r^A (`resultA`, D:97-102; ours: `Denoised.a`)"),
    "nfor_resultB.pfm": ("result_b", "selected half B, r^B (`resultB`; ours: `Denoised.b`)"),
}


def run_case(denoiser: Path, case: Path) -> tuple[dict[str, np.ndarray], float]:
    """Run the patched denoiser on a copy of ``case``; returns ({our name: (H, W, 3) float32}, seconds)."""
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp) / case.name
        shutil.copytree(case, work, ignore=shutil.ignore_patterns(OUTPUT_FILE))
        start = time.perf_counter()
        result = subprocess.run([str(denoiser), SCENE_FILE, "out.pfm"], cwd=work, capture_output=True, text=True)
        seconds = time.perf_counter() - start
        if result.returncode != 0:
            raise SystemExit(f"denoiser failed on {case.name} (exit {result.returncode}):\n{result.stderr}")
        if (work / "out.pfm").read_bytes() != (case / OUTPUT_FILE).read_bytes():
            raise SystemExit(f"{case.name}: the patched denoiser's output differs from the stored {OUTPUT_FILE}; "
                             "was it built from the same commit and recipe?")
        missing = [f for f in FILES if not (work / f).exists()]
        if missing:
            raise SystemExit(f"{case.name}: the denoiser wrote no {missing}; is the patch applied?")
        return {name: read_pfm(work / f).astype(np.float32) for f, (name, _) in FILES.items()}, seconds


def readme_section(meta: dict) -> str:
    rows = "\n".join(f"| `{name}` | `{f}` | {what} |" for f, (name, what) in FILES.items())
    return f"""{MARK_BEGIN}
## Intermediates (`{NPZ}`)

Made by `tools/golden/tungsten_nfor_intermediates.py` on {meta['date']} ({meta['machine']}).
Command: `{meta['command']}`, where the binary is Tungsten's `denoiser` at commit
`{TUNGSTEN_COMMIT}`, built with the recipe above after applying
`tools/golden/tungsten_nfor_intermediates.patch` (`patch -p1` in the source tree; SHA-256
`{meta['patch_sha256']}`). The patch only adds `Pixmap::save` calls to `src/denoiser/denoiser.cpp`
that write the intermediates below into the working directory; on every case the patched binary's
final output was checked to be bit-identical to the stored `{OUTPUT_FILE}`.
{('Build as run: ' + meta['build']) if meta.get('build') else ''}

`{NPZ}` (numpy, compressed, {meta['npz_bytes'] // 1024} KiB) holds per case folder `<case>` the arrays
`<case>/<name>`, each (H, W, 3) float32, top row first (as `read_pfm` returns them):

| name | Tungsten's file | what |
| --- | --- | --- |
{rows}

Used by `tests/methods/test_nfor_golden_intermediates.py` against
`methods.nfor.denoise(buffers, intermediates=True)`. `intermediates.json` holds the command, the
binary's and the patch's SHA-256 and the seconds per case.
{MARK_END}
"""


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--denoiser", required=True, help="Tungsten's denoiser built with the patch applied")
    parser.add_argument("--golden", type=Path, default=GOLDEN)
    parser.add_argument("--build-note", default="",
                        help="how the patched binary was built, as run (for the README)")
    args = parser.parse_args(argv)
    denoiser = Path(args.denoiser).resolve()
    cases = sorted(p for p in args.golden.iterdir() if (p / OUTPUT_FILE).exists())
    arrays, seconds = {}, {}
    for case in cases:
        images, seconds[case.name] = run_case(denoiser, case)
        arrays.update({f"{case.name}/{name}": image for name, image in images.items()})
        print(f"{case.name}: {len(images)} intermediates, {seconds[case.name]:.2f} s", flush=True)
    np.savez_compressed(args.golden / NPZ, **arrays)
    meta = {"tool": "tools/golden/tungsten_nfor_intermediates.py", "repository": TUNGSTEN_REPO,
            "commit": TUNGSTEN_COMMIT, "denoiser": str(denoiser), "denoiser_sha256": sha256(denoiser),
            "patch": "tools/golden/tungsten_nfor_intermediates.patch", "patch_sha256": sha256(PATCH),
            "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": machine(),
            "command": "python tools/golden/tungsten_nfor_intermediates.py --denoiser <patched build>/denoiser",
            "build": args.build_note, "seconds": {k: round(v, 3) for k, v in seconds.items()},
            "npz_bytes": (args.golden / NPZ).stat().st_size, "npz_sha256": sha256(args.golden / NPZ)}
    (args.golden / "intermediates.json").write_text(json.dumps(meta, indent=2) + "\n")
    readme = (args.golden / "README.md").read_text()
    if MARK_BEGIN in readme:
        readme = readme[:readme.index(MARK_BEGIN)] + readme[readme.index(MARK_END) + len(MARK_END) + 1:]
    (args.golden / "README.md").write_text(readme.rstrip("\n") + "\n\n" + readme_section(meta))


if __name__ == "__main__":
    main()
