"""Numba compilation with an on-disk cache that is robust to how a module was imported.

``@cached_njit(**options)`` is ``numba.njit(cache=True, **options)`` with two differences:

* The cache lives outside the source tree: ``$NUMBA_CACHE_DIR`` if the user set it, else
  ``$XDG_CACHE_HOME/mcbench/numba`` (``~/.cache/mcbench/numba`` without ``XDG_CACHE_HOME``).
  Numba's own default is ``__pycache__`` next to the source, which dirties a checkout.
* Only a module imported under its canonical name (``methods.ensemble`` for
  ``methods/ensemble.py``, derived from the package folders around the file) caches. Numba keys
  cache entries by source file and function, not by module name, and records the module by name
  (``<dynamic>`` when the module is not in ``sys.modules``); a compilation cached while the
  file is loaded under another name (``importlib.util.spec_from_file_location``, a notebook, a
  plugin loader, pytest's ``--import-mode=importlib``) would be loaded by every later normal
  import, which would then die with ``ModuleNotFoundError: No module named '<dynamic>'``. So such
  loads compile without a cache.

Numba reads ``NUMBA_CACHE_DIR`` from the environment (it re-reads the environment before each
compilation), so this module sets the variable (only if unset) and reloads numba's config;
subprocesses inherit the same folder.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numba

CACHE_DIR_ENV = "NUMBA_CACHE_DIR"


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/mcbench/numba``, or ``~/.cache/mcbench/numba`` when XDG_CACHE_HOME is unset."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "mcbench" / "numba"


def use_cache_dir() -> Path:
    """Point numba's cache at ``$NUMBA_CACHE_DIR`` (set to :func:`default_cache_dir` if unset); returns it."""
    if not os.environ.get(CACHE_DIR_ENV):
        os.environ[CACHE_DIR_ENV] = str(default_cache_dir())
    numba.config.reload_config()
    return Path(os.environ[CACHE_DIR_ENV])


def canonical_module_name(source_file: str | Path) -> str:
    """The dotted name a normal import gives ``source_file``: its stem below every enclosing folder
    that is a package (has ``__init__.py``), e.g. ``methods/ensemble.py`` -> ``methods.ensemble``."""
    path = Path(source_file).resolve()
    parts = [path.stem]
    folder = path.parent
    while (folder / "__init__.py").is_file():
        parts.append(folder.name)
        folder = folder.parent
    return ".".join(reversed(parts))


def is_canonically_imported(module_name: str, source_file: str | Path) -> bool:
    """Whether ``module_name`` is the canonical name of ``source_file`` and ``sys.modules`` holds
    that module loaded from that file (true while a normal import runs the module's body)."""
    module = sys.modules.get(module_name)
    module_file = getattr(module, "__file__", None)
    return (module_name == canonical_module_name(source_file) and module_file is not None
            and Path(module_file).resolve() == Path(source_file).resolve())


def cached_njit(**options):
    """Decorator: ``numba.njit(cache=..., **options)`` caching in :func:`use_cache_dir` when the
    decorated function's module is canonically imported, compiling without a cache otherwise."""
    if "cache" in options:
        raise TypeError("cached_njit decides cache itself; pass the other njit options only")

    def decorate(function):
        cache = is_canonically_imported(function.__module__, function.__code__.co_filename)
        return numba.njit(cache=cache, **options)(function)

    return decorate


use_cache_dir()
