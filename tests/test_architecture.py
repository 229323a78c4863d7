"""The project's import rules, checked statically (ast, no import is executed) on every module
of ``mcbench/``: imports anywhere in a file count (module level and inside functions, where
cycles hide), plus ``importlib.import_module("literal")``.

* no import cycle among the modules of ``mcbench/``;
* core never imports the plugins ``methods`` or ``scenes`` (only the step modules
  ``mcbench/pipeline/steps.py`` and ``mcbench/steps_*.py``, the rule bodies, may);
* no module uses another module's private (``_name``) function or constant.

A package's ``__init__`` is not counted as imported when one of its submodules is (Python runs
it, but re-exports in ``__init__`` would otherwise make every package a cycle).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CORE = ROOT / "mcbench"
PROJECT_PACKAGES = ("mcbench", "methods", "scenes")
PLUGINS = ("methods", "scenes")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def core_modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(CORE.rglob("*.py"))}


def project_modules() -> set[str]:
    return {module_name(p) for package in PROJECT_PACKAGES for p in (ROOT / package).rglob("*.py")}


def resolve_from(node: ast.ImportFrom, importer: str, is_package: bool) -> str:
    """Absolute module of ``from <module> import ...`` (relative levels resolved)."""
    if not node.level:
        return node.module or ""
    base = importer.split(".")
    base = base if is_package else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports_in(source: str, importer: str, is_package: bool,
               known: set[str]) -> list[tuple[str, int, dict[str, tuple[str, bool]]]]:
    """(imported module, line, {local name: (module or module.attribute, binds a module)}) for
    every import in ``source`` (the text of module ``importer``); ``from pkg import sub`` names
    the submodule when ``pkg.sub`` is a known module."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                local = alias.asname or alias.name.split(".")[0]
                target = alias.name if alias.asname else alias.name.split(".")[0]
                found.append((alias.name, node.lineno, {local: (target, True)}))
        elif isinstance(node, ast.ImportFrom):
            base = resolve_from(node, importer, is_package)
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                target = sub if sub in known else base
                found.append((target, node.lineno, {alias.asname or alias.name: (sub, sub in known)}))
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
              and node.func.attr == "import_module" and node.args
              and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            found.append((node.args[0].value, node.lineno, {}))
    return found


def imports_of(path: Path, known: set[str]):
    return imports_in(path.read_text(), module_name(path), path.name == "__init__.py", known)


def import_graph() -> dict[str, set[str]]:
    """Edges between core modules: importer -> imported (the nearest known module)."""
    modules = core_modules()
    known = set(modules)
    graph = {name: set() for name in modules}
    for name, path in modules.items():
        for target, _, _ in imports_of(path, known):
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name:
                graph[name].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_cycle_finder_finds_a_known_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_walk_sees_function_level_relative_and_importlib_imports():
    source = ("import numpy as np\nfrom . import buffers\nfrom .. import exr\n\n"
              "def f():\n    from mcbench.render.renderer import _load\n    import methods.ensemble\n"
              "    return importlib.import_module('scenes.cornell_box')\n")
    known = {"mcbench.nn.buffers", "mcbench.io.exr", "mcbench.render.renderer"}
    found = {(target, tuple(names.items())) for target, _, names in
             imports_in(source, "mcbench.nn.probe", False, known)}
    assert ("mcbench.nn.buffers", (("buffers", ("mcbench.nn.buffers", True)),)) in found
    assert ("mcbench.io.exr", (("exr", ("mcbench.io.exr", True)),)) in found
    assert ("mcbench.render.renderer", (("_load", ("mcbench.render.renderer._load", False)),)) in found
    assert ("methods.ensemble", (("methods", ("methods", True)),)) in found
    assert ("scenes.cornell_box", ()) in found


def test_no_import_cycle_in_core():
    found = cycles(import_graph())
    assert not found, f"import cycles in mcbench/: {found}"


def test_core_does_not_import_plugins():
    offending = []
    for name, path in core_modules().items():
        if name == "mcbench.pipeline.steps" or name.startswith("mcbench.steps_"):
            continue
        for target, line, _ in imports_of(path, project_modules()):
            if target.split(".")[0] in PLUGINS:
                offending.append(f"{path.relative_to(ROOT)}:{line} imports {target}")
    assert not offending, "core imports plugins:\n" + "\n".join(sorted(set(offending)))


def is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def private_uses_in(source: str, importer: str, where: str, known: set[str], *,
                    is_package: bool = False) -> list[str]:
    """Uses in ``source`` (module ``importer``, shown as ``where``) of a ``_private`` name of
    another project module: ``from m import _x``, ``m._x`` / ``pkg.m._x`` through a name bound
    to a project module by an import, and any import from a private module of another package."""
    package = importer if is_package else importer.rpartition(".")[0]
    modules, uses = {}, []
    for target, line, names in imports_in(source, importer, is_package, known):
        parts = target.split(".")
        hidden = [i for i, part in enumerate(parts) if is_private(part)]
        if (parts[0] in PROJECT_PACKAGES and hidden
                and ".".join(parts[:hidden[0]]) != package and target != importer):
            uses.append(f"{where}:{line} imports from private module {target}")
            continue
        for local, (full, binds_module) in names.items():
            head, _, attr = full.rpartition(".")
            if binds_module:
                modules[local] = full
            if not is_private(attr) or head.split(".")[0] not in PROJECT_PACKAGES:
                continue
            # a private function of another module, or a private module of another package
            if (not binds_module and head != importer) or (binds_module and head != package):
                uses.append(f"{where}:{line} imports {full}")
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and is_private(node.attr):
            chain, value = [], node.value  # e.g. pkg.module._name: chain ["module"]
            while isinstance(value, ast.Attribute):
                chain.append(value.attr)
                value = value.value
            if isinstance(value, ast.Name) and value.id in modules:
                owner = ".".join([modules[value.id]] + chain[::-1])
                if owner.split(".")[0] in PROJECT_PACKAGES and owner != importer:
                    uses.append(f"{where}:{node.lineno} uses {owner}.{node.attr}")
    return sorted(set(uses))


def private_uses(path: Path, known: set[str]) -> list[str]:
    return private_uses_in(path.read_text(), module_name(path), str(path.relative_to(ROOT)), known,
                           is_package=path.name == "__init__.py")


PRIVATE_PROBE = """\
import mcbench.render.renderer
from mcbench.render import renderer as r
from mcbench.io.exr import _open
from . import _helpers
from mcbench._helpers import fine
from mcbench.probe import _own
from scenes import _geometry
from scenes._curves import strands
x = r._load
y = mcbench.render.renderer._scene_cache
z = r.__name__
w = _helpers.public
v = np._private
"""


def test_private_finder_finds_known_patterns():
    known = {"mcbench.render.renderer", "mcbench.io.exr", "mcbench._helpers", "scenes._geometry", "scenes._curves"}
    uses = private_uses_in(PRIVATE_PROBE, "mcbench.probe", "probe.py", known)
    assert sorted(use.split(" ", 1)[1] for use in uses) == [
        "imports from private module scenes._curves", "imports from private module scenes._geometry",
        "imports mcbench.io.exr._open", "uses mcbench.render.renderer._load", "uses mcbench.render.renderer._scene_cache"]


def test_no_private_names_of_other_modules():
    """Core, methods and scenes alike: no module calls another's private names."""
    known = project_modules()
    paths = sorted(p for package in PROJECT_PACKAGES for p in (ROOT / package).rglob("*.py"))
    uses = [use for path in paths for use in private_uses(path, known)]
    assert not uses, "private names used across modules:\n" + "\n".join(uses)
