"""Speed and memory of the ensemble combiner (Zheng et al. 2021, Sec. 4).
A script, not a timed test:

    python benchmarks/bench_ensemble.py [--quick] [--keep DIR] [--baseline COMMIT | --no-baseline]

Every figure is one whole process (``benchmarks/ensemble_job.py``: Python start, imports, EXR
reads of the render and the N inputs, solve + weight filter + blend, EXR write), as the DAG runs
an ensemble job, with its wall time, CPU seconds (user + system: what a loaded machine inflates
least) and peak RSS (``os.wait4`` of the child). Printed:

1. 1024^2, N = 2, 4, 8, ``solver=iterative`` and ``exact``: wall, peak RSS and the phases, beside
   the authors' C++ program run on the same case in the same minute with ``--cpp PATH`` (else
   :data:`CPP_REFERENCE`, the program's whole-process figures at 1024^2 on an idle 2-core machine
   of the project's kind: 9.0 / 13.0 / 20.4 s, 274 / 395 / 635 MiB) as ratios (target: wall
   <= 0.25x, RSS <= 1.2x). Three jobs per line, one after the other: ``rows`` (the job reading
   the render and the inputs by rows, as ``run_methods`` reads for a batch of ``reads_rows``
   methods), ``eager`` (every layer read whole, as ``run_methods`` reads for any other batch)
   and ``base`` (the whole job as of ``--baseline``, default :data:`BASELINE_COMMIT`, the
   whole-image combine without bands or row reads: its files extracted from
   git (``git archive``) into the temporary folder and run from there, so it loads its own numba
   cache; ``baseline.load_baseline`` loads one module into this process, which would compile
   its kernels in the job and count the compiler's memory); then the ratios rows / base of
   wall, CPU and RSS from the same minute, and the largest relMSE between the rows job's output
   layers (images and weight maps) and the baseline's (0 when equal);
2. the fitted exponent b of combine time ~ pixels^b (256^2 ... 2048^2, N = 4) and ~ N^b
   (N = 2 ... 8 at 1024^2), both solvers (1.0 = linear);
3. numba against NumPy in the same run: the weight filter (Eq. 32-34) of
   ``mcbench.combine.weight_filter.filter_weights`` against a vectorised NumPy implementation of the same
   equations (one shifted-image pass per window offset, float64) at 256^2, N = 4, and the
   relMSE between their blends;
4. the machine load (``os.getloadavg``) before and after (and the 1-minute load after each job
   of 1.).

Synthetic inputs (:func:`synthetic_parts`; linear radiance, float32 EXRs written once per size
and N into a temporary folder): a smooth truth mu (H, W, 3); noisy halves x^h = mu + sqrt(mu) 0.3 eps with 0.1 %
fireflies; base outputs y_i^h = mu + bias_i + 0.02 eps (bias_i a smooth per-denoiser field), the
full result with 0.015 eps; albedo mu / max mu, normals piecewise constant.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from mcbench.io.exr import write_layers  # noqa: E402

CPP_REFERENCE = {2: (9.0, 274.0), 4: (13.0, 395.0), 8: (20.4, 635.0)}  # N: (wall s, peak MiB)
BASELINE_COMMIT = "cedab75"   # the whole-image combine, without bands or row reads
WALL_TARGET, RSS_TARGET = 0.25, 1.2


def truth_and_features(size: int):
    """mu (H, W, 3) float64, albedo and normal (H, W, 3) of the synthetic case."""
    yy, xx = np.mgrid[0:size, 0:size] / size
    mu = np.stack([0.6 + 0.5 * np.sin(6 * xx) * np.cos(4 * yy),
                   0.4 + 0.3 * np.cos(5 * (xx + yy)),
                   0.3 + 0.25 * np.sin(9 * xx * yy)], -1) * 2.0
    mu = np.maximum(mu, 0.01)
    albedo = np.clip(mu / mu.max(), 0, 1)
    normal = np.zeros((size, size, 3))
    normal[..., 2] = 1.0
    normal[:, size // 2:] = [0.0, 1.0, 0.0]
    return mu, albedo, normal


def synthetic_parts(size: int, n: int, seed: int = 0):
    """The synthetic case piece by piece (float64), so that a large one need not be held whole:
    yields ``(mu, albedo, normal)``, then ``(x^A, x^B)``, then for each base output i the dict
    ``{"full", "a", "b"}`` of its (H, W, 3) results."""
    rng = np.random.default_rng(seed)
    mu, albedo, normal = truth_and_features(size)
    yield mu, albedo, normal
    halves = []
    for _ in range(2):
        x = mu + np.sqrt(mu) * 0.3 * rng.standard_normal(mu.shape)
        fire = rng.random(mu.shape[:2]) < 1e-3
        x[fire] += rng.uniform(10, 100, (int(fire.sum()), 1))
        halves.append(x)
    yield tuple(halves)
    yy, xx = np.mgrid[0:size, 0:size] / size
    for i in range(n):
        fx, fy, ph = rng.uniform(1, 6), rng.uniform(1, 6), rng.uniform(0, 6.3)
        bias = (0.05 * (i + 1) / n) * np.sin(fx * xx + ph)[..., None] * np.cos(fy * yy)[..., None]
        bias = bias * rng.uniform(0.5, 1.5, 3)
        yield {key: mu + bias + sd * rng.standard_normal(mu.shape)
               for key, sd in (("full", 0.015), ("a", 0.02), ("b", 0.02))}


def synthetic(size: int, n: int, seed: int = 0):
    """The whole synthetic case in memory: color_a, color_b (H, W, 3), y_full, y_a, y_b
    (N, H, W, 3), albedo, normal (float64)."""
    parts = synthetic_parts(size, n, seed)
    _, albedo, normal = next(parts)
    xa, xb = next(parts)
    bases = list(parts)
    return (xa, xb, *(np.stack([b[key] for b in bases]) for key in ("full", "a", "b")), albedo,
            normal)


def write_case(folder: Path, size: int, n: int, seed: int = 0):
    """The synthetic render and n base outputs as float32 EXRs in ``folder`` (reused when
    present); returns (render path, input paths)."""
    folder.mkdir(parents=True, exist_ok=True)
    render = folder / "render.exr"
    inputs = [folder / f"base{i}.exr" for i in range(n)]
    if render.exists() and all(p.exists() for p in inputs):
        return render, inputs
    parts = synthetic_parts(size, n, seed)
    mu, albedo, normal = next(parts)
    xa, xb = next(parts)
    variance = 0.09 * mu
    write_layers(render, {"color": 0.5 * (xa + xb), "color_a": xa, "color_b": xb,
                          "variance": 0.5 * variance, "variance_a": variance,
                          "variance_b": variance, "albedo": albedo, "normal": normal,
                          "depth": np.ones(mu.shape[:2])}, metadata={"spp": 8})
    for path, base in zip(inputs, parts):
        write_layers(path, {"color": base["full"], "color_a": base["a"], "color_b": base["b"]})
    return render, inputs


def baseline_tree(commit: str, folder: Path) -> Path:
    """``methods/``, ``mcbench/`` and ``benchmarks/ensemble_job.py`` as of ``commit``, extracted
    into ``folder/<commit>`` (``git archive``); returns that job script."""
    root = folder / f"baseline_{commit}"
    script = root / "benchmarks" / "ensemble_job.py"
    if not script.exists():
        root.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", "archive", commit, "methods", "mcbench",
                                  "benchmarks/ensemble_job.py"], cwd=HERE.parent, check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(root)], input=archive, check=True)
    return script


def output_relmse(path: Path, reference: Path) -> float:
    """The largest relMSE (as the study's: mean (x - r)^2 / (r^2 + 1e-2)) over the layers of
    two EXRs with the same layers."""
    from mcbench.io.exr import read_layers

    a, b = read_layers(path), read_layers(reference)
    if sorted(a) != sorted(b):
        raise ValueError(f"{path} and {reference} hold different layers")
    return max(float(np.mean((a[k].astype(np.float64) - b[k]) ** 2 / (b[k].astype(np.float64) ** 2
                                                                      + 1e-2))) for k in a)


def run_job(render: Path, inputs: list[Path], output: Path, *, script: Path | None = None,
            eager: bool = False, **params) -> dict:
    """One ``ensemble_job.py`` process (``script``: another tree's, e.g. :func:`baseline_tree`;
    ``eager``: read every layer whole): its phases plus wall seconds, CPU seconds, peak RSS
    (MiB) and the 1-minute load average after it."""
    command = [sys.executable, str(script or HERE / "ensemble_job.py"), str(render), str(output),
               *map(str, inputs)]
    if eager:
        command.append("--eager")
    if params:
        command += ["--param", *(f"{k}={v}" for k, v in params.items())]
    start = time.perf_counter()
    child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - start
    stdout, stderr = child.stdout.read(), child.stderr.read()
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode:
        raise RuntimeError(f"{' '.join(command)} failed:\n{stderr[-3000:]}")
    phases = json.loads(stdout.strip().splitlines()[-1])
    return dict(phases, wall_s=wall, cpu_s=usage.ru_utime + usage.ru_stime,
                rss_mib=usage.ru_maxrss / 1024.0, load=os.getloadavg()[0])


def run_cpp(program: str, render: Path, inputs: list[Path], folder: Path, *, solver: str = "brute") -> dict:
    """The authors' program (``--cpp``) on the same case: its inputs written once in its layout
    (:func:`mcbench.io.case_folders.write_case`, not timed), then one process ``-m d0,d1,... -s
    solver -q`` with its wall seconds, CPU seconds and peak RSS (MiB) from ``os.wait4``, as
    :func:`run_job` measures ours, and the 1-minute load after it."""
    from mcbench.io.buffers import Denoised
    from mcbench.io.case_folders import write_case as write_authors_case
    from mcbench.io.exr import read_layers

    names = [f"d{i}" for i in range(len(inputs))]
    if not (folder / "colorA.exr").exists():
        layers = read_layers(render, ["color_a", "color_b", "albedo", "normal"])
        outputs = {}
        for name, path in zip(names, inputs):
            images = read_layers(path, ["color", "color_a", "color_b"])
            outputs[name] = Denoised(images["color"], images["color_a"], images["color_b"])
        write_authors_case(folder, layers, outputs, extra_files=False)
    command = [program, "-i", str(folder), "-o", str(folder / "out"), "-m", ",".join(names), "-s", solver, "-q"]
    start = time.perf_counter()
    child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                             env=dict(os.environ, OPENCV_IO_ENABLE_OPENEXR="1"))
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status):
        raise RuntimeError(f"{' '.join(command)} failed:\n{child.stderr.read()[-3000:]}")
    return dict(wall_s=wall, cpu_s=usage.ru_utime + usage.ru_stime, rss_mib=usage.ru_maxrss / 1024.0,
                load=os.getloadavg()[0])


def fitted_exponent(xs, ys) -> float:
    """Least-squares slope of log y against log x."""
    return float(np.polyfit(np.log(xs), np.log(ys), 1)[0])


def numpy_weight_filter(weights, y_full, y_a, y_b, albedo, normal, *, radius=7, sigma_spatial=3.0,
                        sigma_color=2.0, sigma_albedo=0.25, sigma_normal=0.15):
    """Eq. 32-34 in vectorised NumPy (float64), the baseline for the numba filter: for each window
    offset the kernel of every pixel at once on zero-padded shifted images (out-of-image
    neighbours get kappa 0); the colour distance of Eq. 33 (zero-variance
    guard as :mod:`mcbench.filters.bilateral`) summed over the channels (Eq. 33, the paper's filter
    alone, ``weight_filter.PAPER_FILTER``). weights, y_*: (N, H, W, C); returns (N, H, W, C)."""
    z = np.einsum("nhwc,nhwc->hwc", weights, y_full)
    var = 0.5 * (np.einsum("nhwc,nhwc->hwc", weights, y_a) - np.einsum("nhwc,nhwc->hwc", weights, y_b)) ** 2
    n, h, w, c = weights.shape
    r = radius

    def pad(a):
        return np.pad(a, [(0, 0)] * (a.ndim - 3) + [(r, r), (r, r), (0, 0)])

    zp, vp, ap, np_ = pad(z), pad(var), pad(albedo), pad(normal)
    inside = pad(np.ones((h, w, 1)))
    wp = pad(weights)
    acc = np.zeros_like(weights)
    total = np.zeros((h, w, 1))
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            window = (slice(r + dy, r + dy + h), slice(r + dx, r + dx + w))
            num = (z - zp[window]) ** 2
            den = var + vp[window]
            safe = den > 1e-20
            term = np.where(safe, num / np.where(safe, den, 1.0), np.where(num == 0, 0.0, np.inf))
            e = ((dy * dy + dx * dx) / (2 * sigma_spatial ** 2)
                 + term.sum(axis=2, keepdims=True) / (2 * sigma_color ** 2)
                 + ((albedo - ap[window]) ** 2).sum(2, keepdims=True) / (2 * sigma_albedo ** 2)
                 + ((normal - np_[window]) ** 2).sum(2, keepdims=True) / (2 * sigma_normal ** 2))
            kappa = np.exp(-e) * inside[window]
            acc += kappa[None] * wp[(slice(None), *window)]
            total += kappa
    return acc / total[None]


def filter_against_numpy(size: int = 256, n: int = 4, repeats: int = 2):
    """Seconds of the numba weight filter and of the NumPy baseline on one case, and the relMSE
    between the blends of their filtered weights."""
    from mcbench.combine.ensemble_weights import solve_weights
    from mcbench.combine.weight_filter import filter_weights
    from timing import timed

    rng = np.random.default_rng(1)
    mu, albedo, normal = truth_and_features(size)
    xa, xb = (mu + np.sqrt(mu) * 0.3 * rng.standard_normal(mu.shape) for _ in range(2))
    y = {k: np.stack([mu + 0.05 * (i + 1) / n + 0.02 * rng.standard_normal(mu.shape) for i in range(n)])
         for k in ("full", "a", "b")}
    raw = solve_weights(xa, xb, y["a"], y["b"], solver="exact")
    filter_weights(raw[:, :16, :16], y["full"][:, :16, :16], y["a"][:, :16, :16],
                   y["b"][:, :16, :16], albedo[:16, :16], normal[:16, :16])   # compile
    t_numba, fast = timed(lambda: filter_weights(raw, y["full"], y["a"], y["b"], albedo, normal), repeats)
    t_numpy, slow = timed(lambda: numpy_weight_filter(raw, y["full"], y["a"], y["b"], albedo, normal), 1)
    blend_fast = np.einsum("nhwc,nhwc->hwc", fast, y["full"])
    blend_slow = np.einsum("nhwc,nhwc->hwc", slow, y["full"])
    relmse = float(np.mean((blend_fast - blend_slow) ** 2 / (blend_slow ** 2 + 1e-2)))
    return t_numba, t_numpy, relmse


def _arguments(argv) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (a smoke run of the script)")
    ap.add_argument("--keep", type=Path, help="folder for the synthetic EXRs (kept between runs)")
    ap.add_argument("--baseline", default=BASELINE_COMMIT,
                    help=f"commit whose job runs beside the current one in 1. (default {BASELINE_COMMIT})")
    ap.add_argument("--no-baseline", action="store_true", help="skip the baseline and eager jobs")
    ap.add_argument("--cpp", default=os.environ.get("MCBENCH_ENSEMBLE_CPP"),
                    help="the authors' built EnsembleDenoising (tests/data/golden/ensemble_cpp/README.md): "
                         "run beside each job of 1. on the same case, in the same minute (default "
                         "$MCBENCH_ENSEMBLE_CPP; without it the C++ figures are CPP_REFERENCE's)")
    return ap.parse_args(argv)


def _whole_process(args, root: Path, main_size: int, ns: list[int], case, job, base_script) -> None:
    """Section 1: each job as a whole process at ``main_size``^2 (beside the baseline's, the
    eager job's and the C++ program's when given)."""
    cpp_source = (f"measured beside each job: {args.cpp}, solver brute" if args.cpp
                  else "CPP_REFERENCE: 1024^2, an idle 2-core machine, not this run")
    print(f"\n1. whole process at {main_size}^2 (C++ {cpp_source}; target "
          f"wall <= {WALL_TARGET}x, RSS <= {RSS_TARGET}x)")
    print(f"{'N':>2} {'solver':>9} {'job':>5} {'wall_s':>7} {'cpu_s':>6} {'import':>7} {'read':>6} "
          f"{'jit':>5} {'combine':>8} {'write':>6} {'RSS_MiB':>8} {'C++_s':>6} {'x_C++':>6} "
          f"{'C++MiB':>7} {'xRSS':>5} {'load':>5}")
    worst = 0.0
    for n in ns:
        for solver in ("iterative", "exact"):
            render, inputs = case(main_size, n)
            if args.cpp:
                cpp = run_cpp(args.cpp, render, inputs, root / f"cpp_s{main_size}_n{n}")
                cpp_s, cpp_mib = cpp["wall_s"], cpp["rss_mib"]
                print(f"{n:>2} {'C++':>9} {'brute':>5} {cpp['wall_s']:7.2f} {cpp['cpu_s']:6.2f} "
                      f"{'':>7} {'':>6} {'':>5} {'':>8} {'':>6} {cpp['rss_mib']:8.0f} {'':>6} {'':>6} "
                      f"{'':>7} {'':>5} {cpp['load']:5.2f}", flush=True)
            else:
                cpp_s, cpp_mib = CPP_REFERENCE[n]
            runs = {"rows": job(main_size, n, solver)}
            if base_script:
                runs["eager"] = run_job(render, inputs, root / "eager.exr", eager=True,
                                        solver=solver)
                runs["base"] = run_job(render, inputs, root / "base.exr", script=base_script,
                                       solver=solver)
                worst = max(worst, output_relmse(root / "out.exr", root / "base.exr"))
                runs["eager"]["relmse"] = output_relmse(root / "eager.exr", root / "out.exr")
            for kind, r in runs.items():
                print(f"{n:>2} {solver:>9} {kind:>5} {r['wall_s']:7.2f} {r['cpu_s']:6.2f} "
                      f"{r['import_s']:7.2f} {r['read_s']:6.2f} {r['jit_s']:5.2f} "
                      f"{r['combine_s']:8.2f} {r['write_s']:6.2f} {r['rss_mib']:8.0f} {cpp_s:6.1f} "
                      f"{r['wall_s'] / cpp_s:6.2f} {cpp_mib:7.0f} {r['rss_mib'] / cpp_mib:5.2f} "
                      f"{r['load']:5.2f}", flush=True)
            if base_script:
                new, old = runs["rows"], runs["base"]
                print(f"{'':>18} rows / base: wall {new['wall_s'] / old['wall_s']:.2f}x, cpu "
                      f"{new['cpu_s'] / old['cpu_s']:.2f}x, RSS {new['rss_mib'] / old['rss_mib']:.2f}x"
                      f"; eager output vs rows relMSE {runs['eager']['relmse']:.1e}", flush=True)
    if base_script:
        print(f"   largest relMSE of any output layer (blends, raw and filtered weight maps) of the "
              f"rows job against the baseline {args.baseline}: {worst:.1e}")


def _scaling(job, sizes: list[int], main_size: int, n_sweep: list[int]) -> None:
    """Section 2: the combine phase's time against the pixels and against N, with the fitted
    exponents."""
    print("\n2. scaling of the combine phase (after the numba cache is loaded; fitted exponent b of "
          "time ~ x^b)")
    for solver in ("iterative", "exact"):
        times = [job(s, 4, solver)["combine_s"] for s in sizes]
        print(f"   {solver:>9} vs pixels {[f'{s}^2' for s in sizes]}: "
              f"{' '.join(f'{t:.2f}s' for t in times)} -> b = "
              f"{fitted_exponent([s * s for s in sizes], times):.2f}", flush=True)
        times = [job(main_size, n, solver)["combine_s"] for n in n_sweep]
        print(f"   {solver:>9} vs N {n_sweep} at {main_size}^2: {' '.join(f'{t:.2f}s' for t in times)} "
              f"-> b = {fitted_exponent(n_sweep, times):.2f}", flush=True)


def main(argv=None):
    args = _arguments(argv)
    sys.path.insert(0, str(HERE))
    main_size = 256 if args.quick else 1024
    sizes = [128, 256] if args.quick else [256, 512, 1024, 2048]
    load_before = os.getloadavg()
    folder_ctx = tempfile.TemporaryDirectory(prefix="bench_ensemble_") if args.keep is None else None
    root = Path(folder_ctx.name) if folder_ctx else args.keep
    print(f"machine: {os.cpu_count()} CPUs, load average {load_before[0]:.2f} {load_before[1]:.2f} "
          f"{load_before[2]:.2f}; numba threads {os.environ.get('NUMBA_NUM_THREADS', 'default')}",
          flush=True)

    def case(size, n):
        return write_case(root / f"s{size}_n{n}", size, n)

    base_script = None if args.no_baseline else baseline_tree(args.baseline, root)
    # warm the numba caches once (compilation is not part of a job's cost)
    render, inputs = case(64, 2)
    for solver in ("iterative", "exact"):
        run_job(render, inputs, root / "warm.exr", solver=solver)
        if base_script:
            run_job(render, inputs, root / "warm.exr", script=base_script, solver=solver)

    results = {}

    def job(size, n, solver):
        key = (size, n, solver)
        if key not in results:
            render, inputs = case(size, n)
            results[key] = run_job(render, inputs, root / "out.exr", solver=solver)
        return results[key]

    _whole_process(args, root, main_size, [2, 4, 8], case, job, base_script)
    _scaling(job, sizes, main_size, [2, 3, 4, 6, 8])
    t_numba, t_numpy, relmse = filter_against_numpy(128 if args.quick else 256)
    print(f"\n3. weight filter, numba {t_numba:.3f} s vs NumPy baseline {t_numpy:.3f} s "
          f"({t_numpy / t_numba:.1f}x faster); blend relMSE between them {relmse:.1e}")
    load_after = os.getloadavg()
    print(f"\n4. load average after: {load_after[0]:.2f} {load_after[1]:.2f} {load_after[2]:.2f}")
    if folder_ctx:
        folder_ctx.cleanup()


if __name__ == "__main__":
    main()
