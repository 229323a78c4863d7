"""Mitsuba XML scenes (mcbench.render.xml_scenes): the contract, the wrapping, and the same pixels
as the same scene written as a dict."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from mcbench import BenchError
from mcbench.render.renderer import AOVS, render_buffers
from mcbench.render.variants import pick_variant
from mcbench.contracts.scene import SceneSpec, scene_spec
from mcbench.render.xml_scenes import XmlScene, film_resolution, scene_module, wrapped_xml

SPHERE_XML = """<?xml version="1.0"?>
<!-- a sphere under a constant sky -->
<scene version="3.0.0">
    <default name="w" value="20"/>
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm">
            <integer name="width" value="$w"/><integer name="height" value="14"/>
            <integer name="crop_width" value="5"/>
            <rfilter type="gaussian"/>
        </film>
        <sampler type="stratified"><integer name="sample_count" value="64"/></sampler>
    </sensor>
    <shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.5, 0.8"/></bsdf></shape>
    <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
</scene>
"""


def sphere_dict(width, height):
    import mitsuba as mi

    return {"type": "scene", "integrator": {"type": "path", "max_depth": 3},
            "sensor": {"type": "perspective", "fov": 45.0,
                       "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": width, "height": height}},
            "sphere": {"type": "sphere", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb",
                                                                                     "value": [0.2, 0.5, 0.8]}}},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}}


@pytest.fixture
def sphere_file(tmp_path):
    path = tmp_path / "sphere.xml"
    path.write_text(SPHERE_XML)
    return path


def test_an_xml_file_gets_the_scene_contract(sphere_file):
    module = scene_module(sphere_file)
    spec = scene_spec(module)
    assert spec.description == "a sphere under a constant sky" and spec.category == "xml"
    assert spec.resolution == (20, 14) == film_resolution(sphere_file)     # $w from its <default>
    assert spec.build(8, 6) == XmlScene(sphere_file.resolve(), 8, 6)


def test_the_wrapping_matches_the_dict_path(sphere_file):
    """The scene's integrator inside moment(aov(...)) under the names the renderer's channels use,
    the film resized with a box filter and no crop, an independent sampler of one sample."""
    text, integrator = wrapped_xml(XmlScene(sphere_file, 8, 6), aovs=AOVS)
    root = ET.fromstring(text)
    moment = root.find("integrator")
    assert moment.get("type") == "moment"
    aov = moment.find("integrator")
    assert (aov.get("type"), aov.get("name")) == ("aov", "nested")
    assert aov.find("string").attrib == {"name": "aovs", "value": AOVS}
    assert (aov.find("integrator").get("type"), aov.find("integrator").get("name")) == ("path", "integrator")
    assert integrator == {"type": "path", "max_depth": "3"}
    film = root.find("sensor/film")
    sizes = {e.get("name"): e.get("value") for e in film.findall("integer")}
    assert sizes == {"width": "8", "height": "6"}
    assert [e.get("type") for e in film.findall("rfilter")] == ["box"]
    assert [e.get("type") for e in root.findall("sensor/sampler")] == ["independent"]


def test_an_xml_scene_renders_the_same_pixels_as_the_same_dict_scene(sphere_file):
    """The same scene, once as XML and once as a dict, through render_buffers with the same seeds:
    the same buffers (independent truth: Mitsuba's dict loader)."""
    pick_variant("auto")
    dict_module = type("M", (), {"__name__": "scenes.sphere_dict",
                                 "SCENE": SceneSpec(description="a sphere", category="test", resolution=(20, 14),
                                                    build=sphere_dict)})
    from_xml, meta_xml = render_buffers(scene_module(sphere_file), 8, resolution=(12, 10))
    from_dict, meta_dict = render_buffers(dict_module, 8, resolution=(12, 10))
    assert from_xml.keys() == from_dict.keys()
    for name in from_xml:
        np.testing.assert_allclose(from_xml[name], from_dict[name], rtol=1e-6, atol=1e-7, err_msg=name)
    assert from_xml["color"].mean() > 0.1


@pytest.mark.parametrize("change, message", [
    (lambda t: t.replace('<integrator type="path"><integer name="max_depth" value="3"/></integrator>', ""),
     "its own top-level <integrator>"),
    (lambda t: t.replace("</scene>", '<sensor type="perspective"><film type="hdrfilm"/></sensor></scene>'),
     "exactly one <sensor>"),
    (lambda t: t.replace("</scene>", ""), "cannot read the XML scene"),
    (lambda t: t.replace('value="14"', 'value="tall"'), "film height 'tall' is not an integer"),
])
def test_bad_xml_scenes_name_the_file(sphere_file, change, message):
    sphere_file.write_text(change(SPHERE_XML))
    with pytest.raises(BenchError, match=message) as error:
        module = scene_module(sphere_file)
        render_buffers(module, 2, resolution=(4, 4))
    assert "sphere.xml" in str(error.value)
