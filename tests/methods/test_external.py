"""``method: external`` (methods/external.py, mcbench/io/external_program.py): a program run on each
case through files. Its results against a box filter computed here; every failure named."""

from __future__ import annotations

import json
import shutil
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from mcbench import BenchError
from mcbench.io.exr import read_layers, write_layers
from mcbench.io.external_program import ExternalProgramError, check_command
from mcbench.pipeline.method_runs import run_methods
from methods import check_params, load_method

REPO = Path(__file__).resolve().parents[2]
BOX = REPO / "examples" / "box_denoiser" / "box_filter.py"
COMMAND = ["{python}", str(BOX), "--in", "{input_dir}", "--out", "{output_dir}", "--name", "{name}"]


def box_reference(image: np.ndarray, radius: int = 2) -> np.ndarray:
    """The clipped-window mean, pixel by pixel."""
    h, w, _ = image.shape
    out = np.zeros(image.shape)
    for y in range(h):
        for x in range(w):
            out[y, x] = image[max(0, y - radius):y + radius + 1, max(0, x - radius):x + radius + 1].mean(axis=(0, 1))
    return out


@pytest.fixture
def render(tmp_path, make_render_buffers):
    buffers = make_render_buffers(spp=8, half_std=0.1, seed=2, height=7, width=9)
    path = tmp_path / "render.exr"
    write_layers(path, buffers.layers, metadata={"spp": 8, "scene": "box", "resolution": "9x7"})
    return buffers, path


def run(render_path, tmp_path, params, name="mybox"):
    output, timing = tmp_path / f"{name}.exr", tmp_path / f"{name}.json"
    run_methods([{"name": name, "module": "external", "params": params, "input_paths": [], "exr": str(output),
                  "timing": str(timing)}], str(render_path), scene="box", spp=8)
    return read_layers(output), json.loads(timing.read_text())


def test_whole_case_program_gives_its_three_results(render, tmp_path):
    buffers, path = render
    layers, timing = run(path, tmp_path, {"command": COMMAND})
    for layer, source in (("color", "color"), ("color_a", "color_a"), ("color_b", "color_b")):
        np.testing.assert_allclose(layers[layer], box_reference(buffers.layers[source]), rtol=1e-6, atol=1e-7)
    assert timing["seconds"] > 0 and timing["module"] == "external"
    # the program's own wall time, recorded by the plugin (a Python start: well above a millisecond)
    assert timing["seconds"] == pytest.approx(load_method("external").program_seconds())


def test_per_image_program_is_called_once_per_image(render, tmp_path):
    """per_image: three calls, each with its image alone as color.exr (this program then writes
    NAME.exr from color.exr and fails on the missing colorA.exr: a wrapper that denoises only
    color.exr is used instead)."""
    buffers, path = render
    one = tmp_path / "one_image.py"
    one.write_text(textwrap.dedent(f"""
        import sys; sys.path.insert(0, {str(BOX.parent)!r})
        from pathlib import Path
        from box_filter import read_rgb, write_rgb, box_filter
        src, out, name = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
        write_rgb(out / (name + ".exr"), box_filter(read_rgb(src / "color.exr"), 2))
    """))
    layers, _ = run(path, tmp_path, {"command": ["{python}", str(one), "{input_dir}", "{output_dir}", "{name}"],
                                     "per_image": True})
    for layer in ("color", "color_a", "color_b"):
        np.testing.assert_allclose(layers[layer], box_reference(buffers.layers[layer]), rtol=1e-6, atol=1e-7)


def program(tmp_path, body: str) -> list[str]:
    script = tmp_path / "prog.py"
    script.write_text(textwrap.dedent(body))
    return ["{python}", str(script), "{input_dir}", "{output_dir}", "{name}"]


WRITE_ALL = """
    import sys, numpy as np, OpenEXR
    out, name = sys.argv[2], sys.argv[3]
    def save(path, image):
        with OpenEXR.File({{"type": OpenEXR.scanlineimage}}, {{"RGB": image.astype(np.float32)}}) as exr:
            exr.write(path)
    for suffix in ("", "A", "B"):
        save(f"{{out}}/{{name}}{{suffix}}.exr", {image})
"""


@pytest.mark.parametrize("body, message", [
    ("import sys\nprint('oops: no GPU found', file=sys.stderr)\nsys.exit(3)", r"exited with status 3.*oops: no GPU found"),
    ("import time\ntime.sleep(30)", r"timeout of 1 s"),
    ("pass", r"did not write a usable mybox.exr.*wrote nothing"),
    (WRITE_ALL.format(image="np.full((7, 9, 3), np.nan)"), r"NaN/Inf in 63 pixel"),
    (WRITE_ALL.format(image="np.zeros((5, 9, 3))"), r"is \(5, 9, 3\), the render is \(7, 9\)"),
])
def test_failures_name_the_command_the_case_and_stderr(render, tmp_path, body, message):
    _, path = render
    output = tmp_path / "mybox.exr"
    with pytest.raises(ExternalProgramError, match="(?s)" + message) as error:
        run(path, tmp_path, {"command": program(tmp_path, body), "timeout": 1.0})
    text = str(error.value)
    assert "prog.py" in text and "render.exr" in text          # the command and the case
    assert not output.exists()                                  # nothing half-written


def test_a_program_that_cannot_start_is_named(render, tmp_path):
    _, path = render
    with pytest.raises(ExternalProgramError, match="cannot start `/no/such/denoiser"):
        run(path, tmp_path, {"command": ["/no/such/denoiser", "{input_dir}"]})


@pytest.mark.parametrize("command, message", [
    ("./denoise --in x", "a list of str"),
    ([], "list of arguments"),
    (["./d", 3], "a list of str"),
    (["./d", "{input}"], r"unknown placeholder\(s\) \['input'\]"),
    (["./d", "{input_dir"], "not a valid template"),
])
def test_bad_commands_stop_at_parse_time_naming_the_key(command, message):
    with pytest.raises(BenchError, match=rf"denoisers\[3\]\.params\.command.*{message}|{message}"):
        check_params(load_method("external"), {"command": command}, config_key="denoisers[3].params")
    with pytest.raises(BenchError, match=r"timeout"):
        check_params(load_method("external"), {"command": COMMAND, "timeout": 0}, config_key="denoisers[3].params")
    assert check_command(COMMAND) == COMMAND


@pytest.mark.slow
@pytest.mark.extended
def test_the_example_ranks_an_external_denoiser_end_to_end(tmp_path):
    """examples/box_denoiser/config.yaml at the smoke scale: the program runs on every case (the
    Mitsuba XML scene scenes/xml_room.xml among them: rendered, referenced and ranked like the
    Python scenes), is ranked in the extra-methods tables beside the pool and combined with OIDN."""
    import yaml

    from tests.conftest import run_snakemake

    shutil.copytree(BOX.parent, tmp_path / "examples" / "box_denoiser")
    config = yaml.safe_load((BOX.parent / "config.yaml").read_text())
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(config))
    run_snakemake(tmp_path, timeout=1800)
    results = tmp_path / "results"
    for scene in config["scenes"]:
        for spp in config["spp"]:
            assert (results / "outputs" / scene / f"spp{spp}" / "box.exr").is_file()
            record = json.loads((results / "outputs" / scene / f"spp{spp}" / "box.json").read_text())
            assert record["seconds"] > 0
    assert "xml_room" in config["scenes"] and (results / "references" / "xml_room.exr").is_file()
    extras = (results / "tables" / "extras_relmse.md").read_text()
    assert "Box filter 5x5 (external example)" in extras and "Ensemble OIDN+Box (external)" in extras
    assert sys.executable  # the {python} of the example is this interpreter
