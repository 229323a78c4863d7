"""Numba's on-disk cache (mcbench.jit): robust to how a module is imported and kept out of the
source tree. Each test works on a fresh copy of the project's code, with the cache folders of
that copy only, in subprocesses (numba's cache is per process and per file)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# A solver call that compiles (and caches) the ensemble's numba kernels (mcbench.combine.simplex_solvers.iterative:
# 20 problems of 2 denoisers, 3 channels sharing the weights).
SOLVE = """
import numpy as np
rng = np.random.default_rng(0)
xa, xb = rng.uniform(0, 1, (2, 20, 3))
ya, yb = rng.uniform(0, 1, (2, 20, 2, 3))
weights, _ = ensemble.iterative_weights(ya, yb, xa, xb, ensemble.seed_state(1), 1024, 1e-9, 0, 0)
assert np.all(np.isfinite(weights)), weights
print("solved", weights.shape)
"""
BY_PATH = """
import importlib.util
spec = importlib.util.spec_from_file_location("ensemble_loaded_by_path",
                                              "mcbench/combine/simplex_solvers/iterative.py")
ensemble = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ensemble)
"""
NORMAL = "import mcbench.combine.simplex_solvers.iterative as ensemble\n"


@pytest.fixture
def project_copy(tmp_path):
    """(copy of mcbench/ and methods/ without weights or caches, environment for its subprocesses)."""
    copy = tmp_path / "project"
    ignore = shutil.ignore_patterns("__pycache__", "weights", "*.nbi", "*.nbc")
    for package in ("mcbench", "methods"):
        shutil.copytree(ROOT / package, copy / package, ignore=ignore)
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    env.update(XDG_CACHE_HOME=str(tmp_path / "xdg"), PYTHONDONTWRITEBYTECODE="1", NUMBA_NUM_THREADS="1")
    return copy, env


def run_python(code: str, cwd: Path, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def numba_cache_files(folder: Path) -> list[Path]:
    return sorted(p for pattern in ("*.nbi", "*.nbc") for p in folder.rglob(pattern))


def test_loading_a_module_by_path_does_not_break_its_normal_import(project_copy):
    """Load the solvers' module by file path and solve, then a normal
    `import mcbench.combine.simplex_solvers.iterative` solves too, reading what the first cached
    (a cache entry recorded under the module name '<dynamic>' must not break the normal import)."""
    copy, env = project_copy
    first = run_python(BY_PATH + SOLVE, copy, env)
    assert first.returncode == 0, first.stderr
    for attempt in range(2):         # the second normal import reads what the first cached
        normal = run_python(NORMAL + SOLVE, copy, env)
        assert normal.returncode == 0, f"normal import #{attempt + 1} failed:\n{normal.stderr[-3000:]}"
        assert "solved" in normal.stdout


def test_numba_cache_stays_out_of_the_source_tree(project_copy, tmp_path):
    copy, env = project_copy
    result = run_python(NORMAL + SOLVE + """
import mcbench.jit, os
print("cache", os.environ["NUMBA_CACHE_DIR"])
""", copy, env)
    assert result.returncode == 0, result.stderr
    assert numba_cache_files(copy) == []
    expected = tmp_path / "xdg" / "mcbench" / "numba"
    assert f"cache {expected}" in result.stdout
    assert numba_cache_files(expected), "the canonical import should have cached its compilations"
    # a user's NUMBA_CACHE_DIR wins
    chosen = tmp_path / "chosen"
    result = run_python(NORMAL + SOLVE, copy, {**env, "NUMBA_CACHE_DIR": str(chosen)})
    assert result.returncode == 0, result.stderr
    assert numba_cache_files(chosen) and numba_cache_files(copy) == []


def test_only_the_canonical_import_of_a_file_caches(tmp_path, monkeypatch):
    from types import ModuleType

    from mcbench.jit import canonical_module_name, is_canonically_imported

    ensemble_file = ROOT / "methods" / "ensemble.py"
    assert canonical_module_name(ensemble_file) == "methods.ensemble"
    assert canonical_module_name(ROOT / "mcbench" / "filters" / "bilateral.py") == "mcbench.filters.bilateral"
    assert canonical_module_name(tmp_path / "loose.py") == "loose"            # no package around it
    import methods.ensemble

    assert is_canonically_imported("methods.ensemble", ensemble_file)
    # the same file under another name (a plugin loader, pytest's importlib mode), registered or not
    stranger = ModuleType("ensemble_by_path")
    stranger.__file__ = str(ensemble_file)
    monkeypatch.setitem(sys.modules, "ensemble_by_path", stranger)
    assert not is_canonically_imported("ensemble_by_path", ensemble_file)
    assert not is_canonically_imported("not_loaded_anywhere", ensemble_file)
    # the canonical name bound to another file
    impostor = ModuleType("methods.ensemble")
    impostor.__file__ = str(tmp_path / "ensemble.py")
    monkeypatch.setitem(sys.modules, "methods.ensemble", impostor)
    assert not is_canonically_imported("methods.ensemble", ensemble_file)
