"""mcbench.weights (location, format, safe loading of learned weights) and the import structure
it enables: importing the learned methods does not import torch, core never imports the method
or scene plugins, and no module of mcbench imports one that imports it back."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import traceback
from pathlib import Path
from types import SimpleNamespace

import pytest

from mcbench import BenchError
from mcbench import weights

ROOT = Path(__file__).resolve().parents[1]


def test_importing_learned_methods_does_not_import_torch():
    code = ("import sys, methods.kpcn, methods.wskpn, methods.mcgan, methods.optix_ae, mcbench.weights, mcbench.nn\n"
            "import methods\n"
            "assert all(methods.load_method(n).NETWORK for n in ('kpcn', 'wskpn', 'mcgan', 'optix_ae'))\n"
            "print(sorted(m for m in sys.modules if m == 'torch' or m.startswith('torch.')))\n")
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def test_location_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv(weights.WEIGHTS_DIR_ENV, raising=False)
    assert weights.weights_dir() == ROOT / "methods" / "weights" == weights.COMMITTED_WEIGHTS
    monkeypatch.setenv(weights.WEIGHTS_DIR_ENV, str(tmp_path))
    assert weights.weights_path("kpcn") == tmp_path / "kpcn.pt"
    assert weights.record_path("kpcn") == tmp_path / "kpcn.json"


def test_learned_method_is_an_attribute_check():
    learned = SimpleNamespace(__name__="methods.toy", NETWORK={}, TRAINING={}, build_network=lambda: None)
    plain = SimpleNamespace(__name__="methods.toy", NETWORK={}, denoise=lambda buffers: None)
    assert weights.is_learned_method(learned) and not weights.is_learned_method(plain)
    assert weights.check_learned_method(learned) is learned
    with pytest.raises(BenchError, match=r"methods/toy\.py is not a learned method: it lacks TRAINING"):
        weights.check_learned_method(plain)
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
        load_network(kpcn, path)
    assert str(path) in str(caught.value) and "weights_only" not in _full_text(caught.value)
    with pytest.raises(BenchError, match=r"nothing\.pt: weights of 'kpcn' are missing; train them"):
        load_network(kpcn, tmp_path / "nothing.pt")


def test_reasons_drop_torch_advice_but_keep_the_cause():
    error = RuntimeError("Weights only load failed. Re-running `torch.load` with `weights_only` set to `False` "
                         "will likely succeed.\nWeightsUnpickler error: Unsupported global: GLOBAL os.system was "
                         "not an allowed global by default. Please use `torch.serialization.add_safe_globals"
                         "([system])` to allowlist this global if you trust this class/function.")
    assert weights.safe_failure_reason(error) == \
        "RuntimeError: Unsupported global: GLOBAL os.system was not an allowed global by default."
    assert weights.safe_failure_reason(EOFError()) == "EOFError"


# ----------------------------------------------------------------------------- import structure

def _imports(path: Path, package_root: Path) -> set[str]:
    """Every module a file imports, at any depth (function-level imports count), as dotted names."""
    tree = ast.parse(path.read_text(), filename=str(path))
    module = ".".join(path.relative_to(package_root).with_suffix("").parts)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    package = package.removesuffix(".__init__")
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{parent}.{base}" if base else parent
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return names


def _core_graph() -> dict[str, set[str]]:
    """{module of mcbench: the modules of mcbench it imports}; ``from a import b`` counts as
    importing ``a.b`` when that is a module, else ``a``."""
    files = {".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): p
             for p in (ROOT / "mcbench").rglob("*.py")}
    graph = {}
    for name, path in files.items():
        graph[name] = {m for m in _imports(path, ROOT) if m in files and m != name}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in graph[node]:
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_cycle_finder_finds_a_hidden_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle_in_mcbench():
    graph = _core_graph()
    assert {"mcbench.nn.train", "mcbench.nn.inference", "mcbench.weights"} <= set(graph)
    assert "mcbench.weights" in graph["mcbench.nn.inference"]
    assert _cycles(graph) == []


def test_core_never_imports_methods_or_scenes():
    offenders = {}
    for path in (ROOT / "mcbench").rglob("*.py"):
        if path.name == "steps.py" and path.parent.name == "mcbench":
            continue                              # the steps layer sits above the plugins
        bad = sorted(m for m in _imports(path, ROOT) if m.split(".")[0] in ("methods", "scenes"))
        if bad:
            offenders[str(path.relative_to(ROOT))] = bad
    assert offenders == {}
