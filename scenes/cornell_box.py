"""Diffuse Cornell box (Mitsuba's built-in ``mi.cornell_box()``): one ceiling area light."""

from __future__ import annotations

from mcbench.contracts.scene import SceneSpec


def build(width: int, height: int) -> dict:
    """Mitsuba scene dict of the Cornell box at ``width`` x ``height`` pixels; path tracer,
    ``max_depth`` 8 (diffuse light decays fast; deeper paths add little but noise)."""
    import mitsuba as mi

    scene = mi.cornell_box()
    scene["integrator"] = {"type": "path", "max_depth": 8}
    film = dict(scene["sensor"]["film"])
    film.update(width=int(width), height=int(height))
    scene["sensor"] = dict(scene["sensor"], film=film)
    return scene


SCENE = SceneSpec(
    description="diffuse interreflection: indirect light and colour bleeding from the red and "
                "green walls, soft shadows from a ceiling area light",
    category="diffuse", resolution=(128, 128), build=build)
