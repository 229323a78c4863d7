"""The scene plugin contract: :class:`SceneSpec`, what every ``scenes/<name>.py`` exports as its
module-level ``SCENE`` (and what :mod:`mcbench.render.xml_scenes` and
:mod:`mcbench.io.render_folders` build for a Mitsuba XML file or a folder of renders).

Constructing one checks the names (a misspelt field is refused with the closest known name) and
every value against its annotation. The registry (``scenes/__init__.py``) reads ``SCENE`` through
:func:`scene_spec`; the renderer and the pipeline read a scene's fields from it, never off the module.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType
from typing import Callable, Optional, Union

from mcbench import BenchError
from mcbench.contracts.fields import SpecError, checked, declaration

__all__ = ["SPEC_ATTRIBUTE", "SceneSpec", "SpecError", "scene_spec"]

#: The module-level name of a scene's declaration.
SPEC_ATTRIBUTE = "SCENE"


@checked
@dataclass(frozen=True, kw_only=True, eq=False)
class SceneSpec:
    """What a scene module declares (``SCENE = SceneSpec(...)``); fields, keyword-only:

    * ``description`` -- one line saying what makes the scene hard for a denoiser.
    * ``category`` -- e.g. ``"diffuse"``, ``"glossy/glass"``, ``"environment"``.
    * ``resolution`` -- the default image size ``(width, height)`` in pixels, or a function
      returning it (a folder of renders reads it from its first image when asked; :attr:`size`).
    * ``build`` -- ``build(width, height)``: a complete Mitsuba scene dict with its own integrator
      and a sensor whose film has the requested size (called after a Mitsuba variant is set), or
      what the renderer loads in its place (an XML scene's file).
    * ``render_folder`` -- a folder of renders made elsewhere
      (:class:`mcbench.io.render_folders.RenderFolder`), imported in place of rendering; None for
      a scene Mitsuba renders.
    """

    description: str
    category: str
    resolution: Union[tuple[int, ...], Callable]
    build: Callable
    render_folder: Optional[object] = None

    def __post_init__(self) -> None:
        if not self.description or len(self.description.splitlines()) != 1:
            raise SpecError(f"SceneSpec field 'description' must be one non-empty line, got {self.description!r}")
        if not self.category:
            raise SpecError("SceneSpec field 'category' must not be empty")
        if not callable(self.resolution) and (len(self.resolution) != 2 or min(self.resolution) < 1):
            raise SpecError(f"SceneSpec field 'resolution' must be (width, height), got {self.resolution!r}")

    @property
    def size(self) -> tuple[int, int]:
        """The default ``(width, height)``: ``resolution``, or what its function returns."""
        width, height = self.resolution() if callable(self.resolution) else self.resolution
        return int(width), int(height)


def scene_spec(module: ModuleType) -> SceneSpec:
    """The declaration ``SCENE`` of scene module ``module``; a :class:`BenchError` naming
    ``scenes/<name>.py`` when it has none or something else under that name."""
    return declaration(module, SPEC_ATTRIBUTE, SceneSpec, "scenes")
