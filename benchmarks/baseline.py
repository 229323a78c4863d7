"""The implementation of a method at an earlier commit, loaded beside the current one for a
same-run baseline in the benchmarks (no copy of the old code in the tree).

``load_baseline("methods/nfor.py", "9ec8741")`` reads the file as it was at that commit
(``git show``), makes its ``mcbench.filters.nlmeans`` import use :func:`mcbench.filters.nlmeans.nl_means_filter_reference`
(the NumPy NL-means that module had at that commit, kept unchanged), and executes it as a
module named ``baseline_<stem>``. Numba compiles such a module without a cache (see
``mcbench.jit``), so call it once on a small input before timing.
"""

from __future__ import annotations

import subprocess
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE_COMMIT = "9ec8741"   # NFOR and RDFC with the NumPy NL-means, without the numba kernels
OLD_IMPORT = "from mcbench.filters.nlmeans import nl_means_filter\n"
NEW_IMPORT = "from mcbench.filters.nlmeans import nl_means_filter_reference as nl_means_filter\n"


def load_baseline(path: str, commit: str = BASELINE_COMMIT, *, patches: dict | None = None,
                  suffix: str = "") -> types.ModuleType:
    """The module at ``path`` (relative to the repository root) as of ``commit``; ``patches``
    maps exact source snippets to their replacements (each must occur)."""
    source = subprocess.run(["git", "show", f"{commit}:{path}"], cwd=ROOT, check=True,
                            capture_output=True, text=True).stdout
    for old, new in {OLD_IMPORT: NEW_IMPORT, **(patches or {})}.items():
        if old not in source:
            raise ValueError(f"{path} at {commit} does not contain {old!r}")
        source = source.replace(old, new)
    module = types.ModuleType(f"baseline_{Path(path).stem}{suffix}")
    module.__file__ = str(ROOT / path)
    exec(compile(source, f"{commit}:{path}", "exec"), module.__dict__)
    return module


def relmse(image, reference) -> float:
    """mean((x - r)^2 / (r^2 + 1e-2)) over pixels and channels (the study's relMSE)."""
    import numpy as np

    x = np.asarray(image, np.float64)
    r = np.asarray(reference, np.float64)
    return float(np.mean((x - r) ** 2 / (r ** 2 + 1e-2)))


def time_denoisers(denoisers: dict, buffers, repeats: int = 1) -> dict:
    """{name: (best wall s, best CPU s, Denoised)} for every ``name: denoise`` in ``denoisers``
    (CPU time = this process's, all threads; the machines here are shared, so it is the
    steadier figure at one thread)."""
    import time

    results = {}
    for name, denoise in denoisers.items():
        best_wall, best_cpu, out = float("inf"), float("inf"), None
        for _ in range(max(int(repeats), 1)):
            wall, cpu = time.perf_counter(), time.process_time()
            out = denoise(buffers)
            best_wall = min(best_wall, time.perf_counter() - wall)
            best_cpu = min(best_cpu, time.process_time() - cpu)
        results[name] = (best_wall, best_cpu, out)
    return results


def print_comparison(size: int, results: dict, *, new: str = "new", old: str = "baseline") -> None:
    """One line per size: wall and CPU seconds of both, the speed-ups, relMSE of new against
    old for the full, A and B outputs, and the relMSE against every further entry."""
    import os
    import numpy as np

    wall_n, cpu_n, out_n = results[new]
    line = f"{size:>4}^2 threads={os.environ.get('NUMBA_NUM_THREADS', 'all')} {new}: wall {wall_n:7.2f} s cpu {cpu_n:7.2f} s"
    if old in results:
        wall_o, cpu_o, out_o = results[old]
        errors = " ".join(f"{k}={relmse(getattr(out_n, k), getattr(out_o, k)):.2e}" for k in ("full", "a", "b"))
        line += (f" | {old}: wall {wall_o:7.2f} s cpu {cpu_o:7.2f} s | speed-up wall {wall_o / wall_n:5.2f}x "
                 f"cpu {cpu_o / cpu_n:5.2f}x | relMSE new vs {old}: {errors}")
    for other, (_, _, out_x) in results.items():
        if other not in (new, old):
            errors = " ".join(f"{k}={relmse(getattr(out_n, k), getattr(out_x, k)):.2e}" for k in ("full", "a", "b"))
            line += f" | relMSE new vs {other}: {errors}"
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(line + f" | load {load:.1f}", flush=True)
    assert all(np.isfinite(getattr(out_n, k)).all() for k in ("full", "a", "b"))
