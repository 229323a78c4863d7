"""mcbench.io.weights (location, format, safe loading of learned weights) and the import structure
it enables: importing the learned methods does not import torch, core never imports the method
or scene plugins, and no module of mcbench imports one that imports it back."""

from __future__ import annotations

import os
import subprocess
import sys
import traceback
from pathlib import Path
from types import SimpleNamespace

import pytest

from mcbench import BenchError
from mcbench.io import weights
from mcbench.contracts.method import LearnedSpec, MethodSpec
ROOT = Path(__file__).resolve().parents[2]


def test_importing_learned_methods_does_not_import_torch():
    code = ("import sys, methods, mcbench.io.weights, mcbench.nn\n"
            "learned = [n for n in methods.available_methods() if mcbench.io.weights.is_learned_method(methods.load_method(n))]\n"
            "assert {'kpcn', 'wskpn', 'mcgan', 'optix_ae', 'deep_combiner', 'progressive'} <= set(learned), learned\n"
            "print(sorted(m for m in sys.modules if m == 'torch' or m.startswith('torch.')))\n")
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def test_location_is_the_folder_passed(tmp_path):
    assert weights.weights_folder(None) == weights.weights_folder("") == ROOT / "methods" / "weights" \
        == weights.COMMITTED_WEIGHTS
    assert weights.weights_folder(str(tmp_path)) == tmp_path
    assert weights.weights_path(tmp_path, "kpcn") == tmp_path / "kpcn.pt"
    assert weights.record_path(tmp_path, "kpcn") == tmp_path / "kpcn.json"


def test_learned_method_is_read_from_the_declaration():
    def run(buffers):
        return None

    def learned_run(buffers, *, weights_file):
        return None

    learned = SimpleNamespace(__name__="methods.toy", METHOD=MethodSpec(
        kind="denoiser", label="Toy", run=learned_run,
        learned=LearnedSpec(network={}, training={}, build_network=lambda: None)))
    plain = SimpleNamespace(__name__="methods.toy", METHOD=MethodSpec(kind="denoiser", label="Toy", run=run))
    assert weights.is_learned_method(learned) and not weights.is_learned_method(plain)
    assert weights.check_learned_method(learned) is learned
    with pytest.raises(BenchError, match=r"methods/toy\.py is not a learned method: its METHOD declares no learned="):
        weights.check_learned_method(plain)
    with pytest.raises(BenchError, match=r"methods/toy\.py: METHOD must be a mcbench\.contracts\.method\.MethodSpec"):
        weights.is_learned_method(SimpleNamespace(__name__="methods.toy", NETWORK={}, TRAINING={}))
    assert weights.method_name(plain) == "toy"


# ----------------------------------------------------------------------------- safe loading

class _RunsCode:
    """Pickles to a call of os.mkdir: a file that would run code when loaded unsafely."""

    def __init__(self, folder):
        self.folder = str(folder)

    def __reduce__(self):
        return os.mkdir, (self.folder,)


def _bad_files(folder: Path) -> dict[str, Path]:
    import torch

    files = {}
    files["hostile"] = folder / "hostile.pt"
    torch.save({"arch": {}, "state_dict": _RunsCode(folder / "pwned")}, files["hostile"])
    files["garbage"] = folder / "garbage.pt"
    files["garbage"].write_bytes(bytes(range(256)) * 3)
    files["empty"] = folder / "empty.pt"
    files["empty"].write_bytes(b"")
    files["truncated"] = folder / "truncated.pt"
    torch.save({"arch": {}, "state_dict": {"w": torch.ones(64)}}, folder / "whole.pt")
    whole = (folder / "whole.pt").read_bytes()
    files["truncated"].write_bytes(whole[: len(whole) // 2])
    files["a folder"] = folder / "folder.pt"
    files["a folder"].mkdir()
    return files


def _full_text(error: BaseException) -> str:
    return "".join(traceback.format_exception(error))


@pytest.mark.parametrize("kind", ["hostile", "garbage", "empty", "truncated", "a folder"])
def test_bad_files_raise_an_error_naming_the_file_without_unsafe_advice(tmp_path, kind):
    path = _bad_files(tmp_path)[kind]
    with pytest.raises(BenchError) as caught:
        weights.load_weights(path)
    text = _full_text(caught.value)
    assert str(path) in str(caught.value)
    assert "weights_only" not in text and "trusted source" not in text and "safe_globals" not in text
    assert not (tmp_path / "pwned").exists()            # the hostile file ran nothing


def test_hostile_file_error_says_what_was_refused(tmp_path):
    with pytest.raises(BenchError, match=r"hostile\.pt: cannot load weights \(UnpicklingError: .*mkdir"):
        weights.load_weights(_bad_files(tmp_path)["hostile"])


def test_loaded_blob_must_be_a_dict_with_the_format_keys(tmp_path):
    import torch

    torch.save([torch.ones(2)], tmp_path / "list.pt")
    with pytest.raises(BenchError, match=r"list\.pt: weights file holds a list"):
        weights.load_weights(tmp_path / "list.pt")
    torch.save({"arch": {"channels": 4}}, tmp_path / "partial.pt")
    with pytest.raises(BenchError, match=r"partial\.pt: weights file lacks the key\(s\) \['state_dict'\]"):
        weights.load_weights(tmp_path / "partial.pt")
    with pytest.raises(BenchError, match=r"missing\.pt: checkpoint file is missing"):
        weights.load_weights(tmp_path / "missing.pt", what="checkpoint")
    good = {"arch": {"channels": 4}, "state_dict": {"w": torch.arange(3.0)}}
    torch.save(good, tmp_path / "good.pt")
    blob = weights.load_weights(tmp_path / "good.pt")
    assert blob["arch"] == good["arch"] and torch.equal(blob["state_dict"]["w"], good["state_dict"]["w"])


def test_inference_refuses_bad_weights_naming_the_file(tmp_path):
    from mcbench.nn.inference import load_network
    import methods.kpcn as kpcn

    path = _bad_files(tmp_path)["hostile"]
    with pytest.raises(BenchError) as caught:
        load_network(kpcn.METHOD, path)
    assert str(path) in str(caught.value) and "weights_only" not in _full_text(caught.value)
    with pytest.raises(BenchError, match=r"kpcn\.pt: weights of 'kpcn' are missing; train them"):
        load_network(kpcn.METHOD, tmp_path / "kpcn.pt")


def test_reasons_drop_torch_advice_but_keep_the_cause():
    error = RuntimeError("Weights only load failed. Re-running `torch.load` with `weights_only` set to `False` "
                         "will likely succeed.\nWeightsUnpickler error: Unsupported global: GLOBAL os.system was "
                         "not an allowed global by default. Please use `torch.serialization.add_safe_globals"
                         "([system])` to allowlist this global if you trust this class/function.")
    assert weights.safe_failure_reason(error) == \
        "RuntimeError: Unsupported global: GLOBAL os.system was not an allowed global by default."
    assert weights.safe_failure_reason(EOFError()) == "EOFError"


def test_weights_trained_on_other_features_are_refused_naming_the_record(tmp_path):
    """A network's record names the feature convention of its training crops (``data.features``);
    a record without it (or no record) means first-hit features; every committed network was trained
    on the convention the schema's default ``features`` renders (the default study runs them)."""
    import json

    record = tmp_path / "kpcn.json"
    assert weights.trained_features(record) == "first_hit"                  # no record
    record.write_text(json.dumps({"data": {"spp_levels": [4, 16]}}))
    assert weights.trained_features(record) == "first_hit"
    weights.check_trained_features(record, "first_hit", name="kpcn")
    with pytest.raises(BenchError, match=r"kpcn\.json.*'first_hit'.*'tungsten'.*train_kpcn"):
        weights.check_trained_features(record, "tungsten", name="kpcn")
    record.write_text(json.dumps({"data": {"features": "tungsten"}}))
    weights.check_trained_features(record, "tungsten", name="kpcn")
    with pytest.raises(BenchError, match="trained on 'tungsten'"):
        weights.check_trained_features(record, "first_hit", name="kpcn")
    record.write_text("{not json")
    with pytest.raises(BenchError, match=r"kpcn\.json: cannot read the training record"):
        weights.trained_features(record)
    from mcbench.pipeline.config import resolve_config

    default = resolve_config({})["features"]
    for committed in sorted((ROOT / "methods" / "weights").glob("*.json")):
        assert weights.trained_features(committed) == default, committed.name
