"""EXR I/O round trips, bad-input errors that name the file or key, and the render buffers' views."""

import numpy as np
import pytest

from mcbench.io.buffers import REQUIRED_LAYERS, RenderBuffers
from mcbench.io.exr import ExrError, NonFiniteError, read_layers, read_metadata, write_layers


@pytest.fixture
def render_layers(make_render_buffers):
    """A fresh dict of all layers of a small synthetic render (6 x 7 pixels)."""
    layers = dict(make_render_buffers(height=6, width=7).layers)
    assert set(REQUIRED_LAYERS) <= set(layers)
    return layers


@pytest.mark.parametrize("compression", ["none", "zip", "zstd"])
def test_round_trip_preserves_layers_and_metadata(tmp_path, render_layers, compression):
    path = tmp_path / "r.exr"
    layers = render_layers
    write_layers(path, layers, metadata={"spp": 16, "scene": "box"}, compression=compression)
    back = read_layers(path)
    assert set(back) == set(layers)
    for name in layers:
        np.testing.assert_array_equal(back[name], layers[name])
    assert read_metadata(path) == {"spp": "16", "scene": "box"}
    assert RenderBuffers.load(path).spp == 16
    assert not list(tmp_path.glob(".*tmp*")), "atomic write left a temporary file"


def test_missing_file_names_the_path(tmp_path):
    with pytest.raises(ExrError, match="nope.exr.*missing"):
        read_layers(tmp_path / "nope.exr")


@pytest.mark.parametrize("compression", ["none", "zip", "zstd"])
def test_corrupt_file_names_the_path(tmp_path, render_layers, compression):
    path = tmp_path / "corrupt.exr"
    write_layers(path, render_layers, compression=compression)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 3])  # truncated mid-file
    with pytest.raises(ExrError, match="corrupt.exr"):
        RenderBuffers.load(path)
    path.write_bytes(b"not an exr at all")
    with pytest.raises(ExrError, match="corrupt.exr"):
        read_layers(path)


def test_nan_render_is_refused_with_count(tmp_path, render_layers):
    layers = render_layers
    layers["color_b"][0, 0, 1] = np.nan
    layers["color_b"][2, 3, :] = np.inf
    path = tmp_path / "nan.exr"
    write_layers(path, layers)
    with pytest.raises(NonFiniteError, match=r"nan.exr.*color_b.*2 pixel"):
        RenderBuffers.load(path)


def test_missing_layer_is_named(tmp_path, render_layers):
    layers = render_layers
    del layers["variance_a"]
    path = tmp_path / "partial.exr"
    write_layers(path, layers)
    with pytest.raises(ExrError, match="partial.exr.*variance_a"):
        RenderBuffers.load(path)


def test_mismatched_layer_shapes_are_refused(tmp_path):
    with pytest.raises(ValueError, match="bad.exr.*'b'"):
        write_layers(tmp_path / "bad.exr", {"a": np.zeros((4, 4, 3)), "b": np.zeros((4, 5, 3))})


def test_half_buffer_view_uses_its_own_features(render_layers):
    layers = render_layers
    layers["albedo_a"] = np.full_like(layers["albedo"], 0.25)
    del layers["albedo_b"]
    buffers = RenderBuffers(layers=layers, spp=8)
    a = buffers.image("a")
    assert np.all(a.albedo == 0.25) and a.spp == 4
    np.testing.assert_array_equal(a.color, layers["color_a"])
    np.testing.assert_array_equal(buffers.image("b").albedo, layers["albedo"])  # falls back to full


@pytest.mark.parametrize("compression", ["none", "zip", "zstd"])
def test_layer_rows_read_what_read_layers_reads(tmp_path, render_layers, compression):
    """mcbench.io.exr.layer_rows: every layer (3-channel and the 1-channel depth), indexed by rows,
    single rows (negative too), rows and columns, or whole, equals read_layers bit for bit; the
    layers of one file share reads, and a block handed out is the caller's own (writing to it
    changes no later read)."""
    from mcbench.io.exr import layer_rows

    path = tmp_path / "render.exr"
    write_layers(path, render_layers, metadata={"spp": 4}, compression=compression)
    whole = read_layers(path)
    lazy = layer_rows(path)
    assert sorted(lazy) == sorted(whole)
    for name, layer in lazy.items():
        expected = whole[name]
        assert layer.shape == expected.shape and layer.dtype == np.float32 and len(layer) == 6
        assert np.array_equal(np.asarray(layer), expected)
        for key in (slice(0, 6), slice(2, 5), slice(4, 99), slice(-2, None), slice(3, 3), 0, -1,
                    (slice(1, 4), slice(2, 6)), (2, slice(0, 3)), slice(0, 6, 2)):
            assert np.array_equal(layer[key], expected[key]), (name, key)
    color, color_a = lazy["color"], lazy["color_a"]
    block = color[1:4]
    color_a[1:4][:] = -1.0                    # handed out from the shared read: the caller's
    assert np.array_equal(color_a[1:4], whole["color_a"][1:4])
    block[:] = 0.0
    assert np.array_equal(color[1:4], whole["color"][1:4])
    assert read_metadata(path) == {"spp": "4"}
    with pytest.raises(IndexError):
        color[6]
    with pytest.raises(ExrError, match="missing layer"):
        layer_rows(path, ["color", "nope"])
    with pytest.raises(ExrError, match="missing"):
        layer_rows(tmp_path / "absent.exr")
