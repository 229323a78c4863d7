"""Scene registry: one module per scene, built from Python, or a Mitsuba 3 XML file.

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

A Mitsuba 3 XML file ``scenes/<name>.xml`` (assets beside it) is a scene as well, with its own
``<integrator>``; :func:`mcbench.render.xml_scenes.scene_module` gives it the contract above
(``scenes/xml_room.xml`` is one, written for the project).
"""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path
from types import ModuleType

from mcbench import BenchError
from mcbench.render.xml_scenes import scene_module

__all__ = ["UnknownSceneError", "available_scenes", "load_scene"]

_REQUIRED_ATTRIBUTES = ("DESCRIPTION", "CATEGORY", "RESOLUTION", "build")


class UnknownSceneError(BenchError):
    """A config names a scene that has no module in ``scenes/``."""


def available_scenes() -> list[str]:
    """Names of all scenes in this package, sorted: its modules and its Mitsuba XML files."""
    modules = {info.name for info in pkgutil.iter_modules(__path__) if not info.name.startswith("_")}
    files = {path.stem for path in Path(__path__[0]).glob("[!_]*.xml")}
    return sorted(modules | files)


def load_scene(name: str, config_key: str = "scenes") -> ModuleType:
    """Import ``scenes/<name>.py``; raise :class:`UnknownSceneError` naming ``config_key``."""
    available = available_scenes()
    if name not in available:
        raise UnknownSceneError(f"config key '{config_key}': unknown scene '{name}'; "
                                f"available scenes: {', '.join(available)}")
    xml_file = Path(__path__[0]) / f"{name}.xml"
    if xml_file.is_file():
        if (Path(__path__[0]) / f"{name}.py").is_file():
            raise UnknownSceneError(f"config key '{config_key}': scene '{name}' is both scenes/{name}.py and "
                                    f"scenes/{name}.xml; keep one")
        return scene_module(xml_file)
    module = importlib.import_module(f"{__name__}.{name}")
    missing = [a for a in _REQUIRED_ATTRIBUTES if not hasattr(module, a)]
    if missing:
        raise UnknownSceneError(f"config key '{config_key}': scene module scenes/{name}.py "
                                f"lacks {', '.join(missing)}")
    return module
