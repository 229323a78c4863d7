"""Scene registry: one module per scene, built entirely from Python (no scene files).

A scene module ``scenes/<name>.py`` exposes

* ``DESCRIPTION``: one line saying what makes the scene hard for a denoiser;
* ``CATEGORY``: e.g. ``"diffuse"``, ``"glossy/glass"``, ``"environment"``;
* ``RESOLUTION = (width, height)``: default image size in pixels;
* ``build(width, height) -> dict``: a complete Mitsuba scene dict, including its own
  integrator (``path``, or ``volpath`` when a medium needs it, with a ``max_depth`` chosen
  for the scene) and a sensor whose film has the requested size.

The renderer (:mod:`mcbench.render.renderer`) replaces the film's reconstruction filter by a box
filter, replaces the sampler, and wraps the scene's integrator to get the sample moments and
the auxiliary features; it takes the module itself (the caller resolves a name with
:func:`load_scene`). ``build`` must be called after a Mitsuba variant has been set. Building
blocks (sensors, quads, boxes, meshes, textures, skies, curves) are core modules:
:mod:`mcbench.render.geometry` and :mod:`mcbench.render.curves`.
"""

from __future__ import annotations

import importlib
import pkgutil
from types import ModuleType

from mcbench import BenchError

__all__ = ["UnknownSceneError", "available_scenes", "load_scene"]

_REQUIRED_ATTRIBUTES = ("DESCRIPTION", "CATEGORY", "RESOLUTION", "build")


class UnknownSceneError(BenchError):
    """A config names a scene that has no module in ``scenes/``."""


def available_scenes() -> list[str]:
    """Names of all scene modules in this package, sorted."""
    return sorted(info.name for info in pkgutil.iter_modules(__path__)
                  if not info.name.startswith("_"))


def load_scene(name: str, config_key: str = "scenes") -> ModuleType:
    """Import ``scenes/<name>.py``; raise :class:`UnknownSceneError` naming ``config_key``."""
    available = available_scenes()
    if name not in available:
        raise UnknownSceneError(f"config key '{config_key}': unknown scene '{name}'; "
                                f"available scenes: {', '.join(available)}")
    module = importlib.import_module(f"{__name__}.{name}")
    missing = [a for a in _REQUIRED_ATTRIBUTES if not hasattr(module, a)]
    if missing:
        raise UnknownSceneError(f"config key '{config_key}': scene module scenes/{name}.py "
                                f"lacks {', '.join(missing)}")
    return module
