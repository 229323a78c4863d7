"""Scene registry: one module per scene, built from Python, or a Mitsuba 3 XML file.

A scene module ``scenes/<name>.py`` exports one declaration, ``SCENE``, a
:class:`mcbench.contracts.scene.SceneSpec`::

    SCENE = SceneSpec(description="...", category="diffuse", resolution=(128, 128), build=build)

* ``description``: one line saying what makes the scene hard for a denoiser;
* ``category``: e.g. ``"diffuse"``, ``"glossy/glass"``, ``"environment"``;
* ``resolution = (width, height)``: default image size in pixels;
* ``build(width, height) -> dict``: a complete Mitsuba scene dict, including its own
  integrator (``path``, or ``volpath`` when a medium needs it, with a ``max_depth`` chosen
  for the scene) and a sensor whose film has the requested size.

A misspelt field is refused naming the closest one, a value of the wrong type naming the field;
:func:`load_scene` names ``scenes/<name>.py`` in either error and when ``SCENE`` is missing.

The renderer (:mod:`mcbench.render.renderer`) replaces the film's reconstruction filter by a box
filter, replaces the sampler, and wraps the scene's integrator to get the sample moments and
the auxiliary features; it takes the module itself (the caller resolves a name with
:func:`load_scene`). ``build`` must be called after a Mitsuba variant has been set. Building
blocks (sensors, quads, boxes, meshes, textures, skies, curves) are core modules:
:mod:`mcbench.render.geometry` and :mod:`mcbench.render.curves`.

A Mitsuba 3 XML file ``scenes/<name>.xml`` (assets beside it) is a scene as well, with its own
``<integrator>``; :func:`mcbench.render.xml_scenes.scene_module` gives it a ``SCENE``
(``scenes/xml_room.xml`` is one, written for the project).

A YAML file ``scenes/<name>.yaml`` names a folder of renders made elsewhere (another renderer's
noisy images per spp and its reference, in the ensemble paper's layout or the OIDN toolkit's
naming): :func:`mcbench.io.render_folders.scene_module` gives it a ``SCENE`` with a
``render_folder`` and a ``build`` that refuses to render; the pipeline imports its files in place of
rendering and checks, when the DAG is parsed, that every configured method finds the layers it
reads.
"""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path
from types import ModuleType

from mcbench import BenchError
from mcbench.contracts.fields import SpecError
from mcbench.contracts.scene import SceneSpec, scene_spec
from mcbench.io.render_folders import scene_module as render_folder_scene
from mcbench.render.xml_scenes import scene_module

__all__ = ["SceneSpec", "scene_spec", "UnknownSceneError", "available_scenes", "load_scene"]

_FILE_SUFFIXES = (".xml", ".yaml")


class UnknownSceneError(BenchError):
    """A config names a scene that has no module in ``scenes/``."""


def available_scenes() -> list[str]:
    """Names of all scenes in this package, sorted: its modules, its Mitsuba XML files and its
    YAML files of renders."""
    modules = {info.name for info in pkgutil.iter_modules(__path__) if not info.name.startswith("_")}
    files = {path.stem for folder in __path__ for suffix in _FILE_SUFFIXES for path in Path(folder).glob(f"[!_]*{suffix}")}
    return sorted(modules | files)


def load_scene(name: str, config_key: str = "scenes") -> ModuleType:
    """Import ``scenes/<name>.py`` (or wrap ``scenes/<name>.xml``/``.yaml``) and check its
    declaration ``SCENE``; raise :class:`UnknownSceneError` naming ``config_key`` and the file."""
    available = available_scenes()
    if name not in available:
        raise UnknownSceneError(f"config key '{config_key}': unknown scene '{name}'; "
                                f"available scenes: {', '.join(available)}")
    kinds = [p for folder in map(Path, __path__)
             for p in (folder / f"{name}.py", *(folder / f"{name}{s}" for s in _FILE_SUFFIXES)) if p.is_file()]
    if len(kinds) > 1:
        raise UnknownSceneError(f"config key '{config_key}': scene '{name}' is {' and '.join(f'scenes/{p.name}' for p in kinds)}; "
                                f"keep one")
    if kinds and kinds[0].suffix == ".xml":
        return scene_module(kinds[0])
    if kinds and kinds[0].suffix == ".yaml":
        return render_folder_scene(kinds[0])
    try:
        module = importlib.import_module(f"{__name__}.{name}")
    except SpecError as exc:             # raised by the declaration while the module imports
        raise UnknownSceneError(f"config key '{config_key}': scenes/{name}.py: {exc}") from None
    try:
        scene_spec(module)
    except BenchError as exc:
        raise UnknownSceneError(f"config key '{config_key}': {exc}") from None
    return module
