"""Mitsuba 3 XML scene files as test scenes.

A scene of the harness is normally a Python module whose ``build(width, height)`` returns a
Mitsuba scene dict (``scenes/__init__.py``). A Mitsuba 3 XML file ``scenes/<name>.xml`` (its
assets beside it, paths relative to it) is a scene too: :func:`scene_module` gives it the same
declaration, a :class:`mcbench.contracts.scene.SceneSpec` -- ``description`` (the file's first
comment line, or its name), ``category`` ("xml"), ``resolution`` (its film's size) and
``build(width, height)``, which returns an :class:`XmlScene` instead of a dict. The renderer
(:mod:`mcbench.render.renderer`) wraps an XML scene as it wraps a dict (:func:`wrapped_xml`): the
scene's own ``<integrator>`` goes inside ``moment(aov(...))`` (sample moments and the albedo,
normal and depth features), the film gets the requested size and a box filter (crop windows
removed), the sensor an ``independent`` sampler; then Mitsuba loads the text with the file's
folder on its search path. The file must hold one ``<sensor>`` with a
``<film>`` and its own top-level ``<integrator>``; ``$name`` parameters keep their ``<default>``s.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from mcbench import BenchError
from mcbench.contracts.scene import SceneSpec

__all__ = ["XmlScene", "scene_module", "film_resolution", "wrapped_xml", "load_xml_scene"]


@dataclass(frozen=True)
class XmlScene:
    """An XML scene file to be rendered at ``width`` x ``height`` pixels."""
    path: Path
    width: int
    height: int


def _parse(path: Path) -> ET.Element:
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise BenchError(f"{path}: cannot read the XML scene ({exc})") from None
    if root.tag != "scene":
        raise BenchError(f"{path}: not a Mitsuba scene file (its root element is <{root.tag}>, not <scene>)")
    return root


def _film(root: ET.Element, path: Path) -> ET.Element:
    sensors = root.findall("sensor")
    if len(sensors) != 1 or sensors[0].find("film") is None:
        raise BenchError(f"{path}: an XML scene needs exactly one <sensor> with a <film>, found {len(sensors)} sensor(s)")
    return sensors[0].find("film")


def _integer(parent: ET.Element, name: str) -> ET.Element | None:
    return next((e for e in parent.findall("integer") if e.get("name") == name), None)


def film_resolution(path: str | Path) -> tuple[int, int]:
    """``(width, height)`` of the scene's film (Mitsuba's default 768 x 576 where unset); a value
    given as a ``$parameter`` takes the parameter's ``<default>``."""
    path = Path(path)
    root = _parse(path)
    film = _film(root, path)
    defaults = {d.get("name"): d.get("value") for d in root.findall("default")}
    size = []
    for name, default in (("width", 768), ("height", 576)):
        element = _integer(film, name)
        value = default if element is None else element.get("value", "")
        if isinstance(value, str) and value.startswith("$"):
            value = defaults.get(value[1:], "")
        try:
            size.append(int(value))
        except ValueError:
            raise BenchError(f"{path}: film {name} {value!r} is not an integer") from None
    return size[0], size[1]


def _description(path: Path) -> str:
    text = path.read_text(errors="replace")
    start = text.find("<!--")
    if start >= 0:
        comment = text[start + 4:text.find("-->", start)].strip()
        if comment:
            return comment.splitlines()[0].strip()
    return f"Mitsuba XML scene {path.name}"


def scene_module(path: str | Path) -> ModuleType:
    """A scene module for the XML file ``path``: its ``SCENE`` (:class:`SceneSpec`) describes it
    (the first comment), sizes it (its film) and builds an :class:`XmlScene` of it."""
    path = Path(path).resolve()
    module = ModuleType(f"scenes.{path.stem}", f"Mitsuba XML scene {path}")
    module.__file__ = str(path)        # the scene's file (its digest, mcbench.pipeline.reference_sources)
    module.SCENE = SceneSpec(description=_description(path), category="xml", resolution=film_resolution(path),
                             build=lambda width, height: XmlScene(path, int(width), int(height)))
    return module


def wrapped_xml(scene: XmlScene, *, aovs: str, block_size: int | None = None) -> tuple[str, dict]:
    """The scene's XML text wrapped for rendering (the module docstring) and a description of its
    own integrator (``{"type": ..., <name>: <value>}`` of its direct properties)."""
    root = _parse(scene.path)
    integrators = root.findall("integrator")
    if len(integrators) != 1:
        raise BenchError(f"{scene.path}: an XML scene needs its own top-level <integrator> (found {len(integrators)})")
    own = integrators[0]
    description = {"type": own.get("type", "?"), **{e.get("name"): e.get("value") for e in own
                                                     if e.get("name") and e.get("value") is not None}}
    index = list(root).index(own)
    root.remove(own)
    moment = ET.Element("integrator", {"type": "moment"})
    if block_size is not None:
        ET.SubElement(moment, "integer", {"name": "block_size", "value": str(block_size)})
    aov = ET.SubElement(moment, "integrator", {"type": "aov", "name": "nested"})
    ET.SubElement(aov, "string", {"name": "aovs", "value": aovs})
    own.set("name", "integrator")
    aov.append(own)
    root.insert(index, moment)
    film = _film(root, scene.path)
    sensor = root.find("sensor")
    for element in list(film):
        if element.tag == "rfilter" or (element.tag == "integer" and element.get("name") in
                                        ("width", "height", "crop_width", "crop_height", "crop_offset_x",
                                         "crop_offset_y")):
            film.remove(element)
    ET.SubElement(film, "integer", {"name": "width", "value": str(scene.width)})
    ET.SubElement(film, "integer", {"name": "height", "value": str(scene.height)})
    ET.SubElement(film, "rfilter", {"type": "box"})
    for element in sensor.findall("sampler"):
        sensor.remove(element)
    sampler = ET.SubElement(sensor, "sampler", {"type": "independent"})
    ET.SubElement(sampler, "integer", {"name": "sample_count", "value": "1"})
    return ET.tostring(root, encoding="unicode"), description


def load_xml_scene(scene: XmlScene, *, aovs: str, block_size: int | None = None):
    """``(mi.Scene, integrator description)`` of the wrapped scene, loaded with the file's folder
    on Mitsuba's search path (relative asset paths resolve against it)."""
    import mitsuba as mi

    text, description = wrapped_xml(scene, aovs=aovs, block_size=block_size)
    resolver = mi.file_resolver()
    folder = str(scene.path.parent)
    if folder not in [str(entry) for entry in resolver]:
        resolver.prepend(folder)
    try:
        return mi.load_string(text), description
    except Exception as exc:
        raise BenchError(f"{scene.path}: Mitsuba cannot load the XML scene ({exc})") from exc
