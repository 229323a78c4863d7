"""The reference store's files: written and read back exactly; every damage, truncation or
foreign record refused naming the file; identities compared key by key."""

import json

import numpy as np
import pytest

from mcbench import BenchError

from mcbench.io.reference_store import (IDENTITY_KEYS, StoreError, identity_mismatches, read_store_record,
                                        read_stored_layers, store_paths, write_stored_reference)

WIDTH, HEIGHT = 24, 16


def _identity(**changes):
    identity = {"scene": "box", "scene_digest": "ab" * 32, "resolution": f"{WIDTH}x{HEIGHT}",
                "mitsuba": "3.9.1", "color_mode": "rgb"}
    identity.update(changes)
    return identity


def _layers(seed=0):
    rng = np.random.default_rng(seed)
    return {"color": rng.gamma(2.0, 0.5, (HEIGHT, WIDTH, 3)).astype(np.float32),
            "variance": rng.gamma(2.0, 1e-4, (HEIGHT, WIDTH, 3)).astype(np.float32)}


@pytest.fixture
def stored(tmp_path):
    layers = _layers()
    entry = write_stored_reference(tmp_path, "box", layers, identity=_identity(),
                                   provenance={"spp": 65536, "cpu": "test"})
    return tmp_path, entry, layers


def test_written_reference_reads_back_bit_for_bit(stored):
    store, entry, layers = stored
    read = read_stored_layers(read_store_record(store, "box", (WIDTH, HEIGHT)))
    for name in ("color", "variance"):
        np.testing.assert_array_equal(read[name], layers[name])
    assert entry.provenance == {"spp": 65536, "cpu": "test"}
    assert entry.exr_path == store_paths(store, "box", (WIDTH, HEIGHT))[0]


def test_no_record_means_no_stored_reference(tmp_path):
    assert read_store_record(tmp_path, "box", (WIDTH, HEIGHT)) is None


def test_identity_compared_key_by_key(stored):
    _, entry, _ = stored
    assert identity_mismatches(entry, _identity()) == []
    lines = identity_mismatches(entry, _identity(mitsuba="3.10.0", scene_digest="cd" * 32))
    assert len(lines) == 2 and lines[1].startswith("mitsuba: stored '3.9.1', this run '3.10.0'")


def test_a_flipped_byte_is_refused_naming_the_file(stored):
    store, entry, _ = stored
    data = bytearray(entry.exr_path.read_bytes())
    data[len(data) // 2] ^= 0x01
    entry.exr_path.write_bytes(bytes(data))
    with pytest.raises(StoreError, match=r"box\.exr.*SHA-256"):
        read_stored_layers(read_store_record(store, "box", (WIDTH, HEIGHT)))


def test_a_truncated_file_is_refused_naming_the_file(stored):
    store, entry, _ = stored
    entry.exr_path.write_bytes(entry.exr_path.read_bytes()[:-100])
    with pytest.raises(StoreError, match=r"box\.exr.*truncated"):
        read_stored_layers(read_store_record(store, "box", (WIDTH, HEIGHT)))


def test_a_missing_exr_is_refused_naming_it_and_its_record(stored):
    store, entry, _ = stored
    entry.exr_path.unlink()
    with pytest.raises(StoreError, match=r"box\.exr.*missing.*box\.json"):
        read_stored_layers(read_store_record(store, "box", (WIDTH, HEIGHT)))


def test_a_record_with_a_matching_digest_for_other_pixels_is_refused(stored, tmp_path_factory):
    """An EXR replaced by another valid stored reference (its own CRC intact) fails the record's
    SHA-256: the record and its file travel together."""
    store, entry, _ = stored
    other = tmp_path_factory.mktemp("other")
    replacement = write_stored_reference(other, "box", _layers(seed=1), identity=_identity(), provenance={})
    entry.exr_path.write_bytes(replacement.exr_path.read_bytes())
    with pytest.raises(StoreError, match="SHA-256|bytes"):
        read_stored_layers(read_store_record(store, "box", (WIDTH, HEIGHT)))


@pytest.mark.parametrize("edit, message", [
    (lambda record: "{not json", "unreadable record"),
    (lambda record: {**record, "format": 99}, "format 1"),
    (lambda record: {k: v for k, v in record.items() if k != "sha256"}, "lacks"),
    (lambda record: {**record, "identity": {k: v for k, v in record["identity"].items() if k != "mitsuba"}}, "lacks"),
    (lambda record: {**record, "identity": {**record["identity"], "scene": "other"}}, "expected scene 'box'"),
])
def test_a_malformed_record_is_refused_naming_it(stored, edit, message):
    store, entry, _ = stored
    record = json.loads(entry.record_path.read_text())
    edited = edit(record)
    entry.record_path.write_text(edited if isinstance(edited, str) else json.dumps(edited))
    with pytest.raises(StoreError, match=message) as error:
        read_store_record(store, "box", (WIDTH, HEIGHT))
    assert "box.json" in str(error.value)


@pytest.mark.parametrize("layers, message", [
    ({"color": np.full((HEIGHT, WIDTH, 3), np.nan, np.float32),
      "variance": np.zeros((HEIGHT, WIDTH, 3), np.float32)}, "NaN"),
    ({"color": np.ones((HEIGHT, WIDTH, 3), np.float32),
      "variance": -np.ones((HEIGHT, WIDTH, 3), np.float32)}, "negative"),
    ({"color": np.ones((HEIGHT, WIDTH, 3), np.float32)}, "no 'variance' layer"),
])
def test_bad_layers_are_never_stored(tmp_path, layers, message):
    with pytest.raises(BenchError, match=message):
        write_stored_reference(tmp_path, "box", layers, identity=_identity(), provenance={})
    assert not list(tmp_path.rglob("*.json"))


def test_identity_must_describe_what_is_stored(tmp_path):
    with pytest.raises(ValueError, match="resolution"):
        write_stored_reference(tmp_path, "box", _layers(), identity=_identity(resolution="8x8"), provenance={})
    with pytest.raises(ValueError, match="identity keys"):
        write_stored_reference(tmp_path, "box", _layers(), identity={"scene": "box"}, provenance={})
    assert set(IDENTITY_KEYS) == set(_identity())
