"""The project's import rules, numbered as in ``docs/architecture.md`` ("Import rules").

Rules 1-5 are import-linter contracts in ``pyproject.toml`` (``[tool.importlinter]``); this file
runs ``lint-imports`` on the repository, and on scratch copies broken one way each. import-linter's
graph (grimp) holds every import statement of a module: at module level, inside functions and
classes, relative ones, under ``if TYPE_CHECKING:``. It does not see ``importlib.import_module``
or ``__import__`` calls, hence rule 6.

1. every module of ``mcbench`` is in a layer; no layer imports a higher one, directly or not; the
   layers of one level are independent;
2. each layer is imported only by the packages declared to use it (the graph as it is);
3. only ``mcbench.pipeline.registry`` imports the plugins (``methods``, ``scenes``, ``metrics``); they never
   import ``mcbench.pipeline``, even indirectly, nor each other;
4. no import cycle between the modules (or subpackages) of one package, nor (checked here:
   the contract compares a package's children only) through a package's ``__init__``;
5. torch only in ``nn``, ``pipeline``, ``methods``; Mitsuba only in ``render``, ``training_data``,
   ``scenes``.

Rules 6-9 and the second half of rule 4 are what import-linter cannot express, checked here by
parsing files with ``ast`` (no import is executed):

6. no ``importlib.import_module("m")`` or ``__import__("m")`` of a project module ``m`` (an import
   statement instead, which the contracts see);
7. no plugin file over 600 lines;
8. no module uses another module's private (``_name``) function, constant or module;
9. ``workflow/scripts/*.py`` import from ``mcbench`` only ``mcbench.pipeline.*`` (and ``mcbench``
   itself), and no plugin.

Rule 2's declaration is also compared with the code and the documentation: every declared use is
an import the code makes (the declaration permits nothing more than the graph has), and the table
of ``docs/architecture.md`` is the same graph.
"""

from __future__ import annotations

import ast
import functools
import os
import re
import shutil
import subprocess
import sys
import tomllib
from collections import deque
from pathlib import Path

import grimp
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "mcbench"
PLUGINS = ("methods", "scenes", "metrics")
PROJECT_PACKAGES = (PACKAGE,) + PLUGINS
PIPELINE = "mcbench.pipeline"
MAX_PLUGIN_LINES = 600
SCRIPTS = Path("workflow") / "scripts"
DOC = Path("docs") / "architecture.md"
#: The heading of the declared graph's table in ``docs/architecture.md``.
GRAPH_HEADING = "## The declared graph"


# ---------------------------------------------------------------------------------------------
# Rules 1-5: the contracts, and lint-imports


def import_linter_config(root: Path = ROOT) -> dict:
    """``[tool.importlinter]`` of ``root/pyproject.toml``."""
    with open(root / "pyproject.toml", "rb") as file:
        return tomllib.load(file)["tool"]["importlinter"]


def contracts_of_type(kind: str) -> list[dict]:
    return [c for c in import_linter_config()["contracts"] if c["type"] == kind]


def lint_imports_command() -> str:
    """The ``lint-imports`` of this interpreter's environment (the ``test`` extra installs it)."""
    command = Path(sys.executable).with_name("lint-imports")
    if command.is_file():
        return str(command)
    found = shutil.which("lint-imports")
    if not found:
        pytest.fail("lint-imports not found: pip install -e '.[test]' (import-linter)")
    return found


def lint(root: Path) -> tuple[set[str], str]:
    """Run ``lint-imports`` on the tree at ``root`` (its own ``pyproject.toml``, its own packages
    first on the path): the ids of the broken contracts, and the output."""
    environment = {**os.environ, "PYTHONPATH": str(root), "COLUMNS": "300", "NO_COLOR": "1"}
    result = subprocess.run([lint_imports_command(), "--no-cache", "--no-logo"], cwd=root, env=environment,
                            capture_output=True, text=True, timeout=600)
    output = result.stdout + result.stderr
    status = {}
    for contract in import_linter_config(root)["contracts"]:
        match = re.search(rf"^{re.escape(contract['name'])} (KEPT|BROKEN)", output, re.MULTILINE)
        assert match, f"lint-imports did not report contract {contract['id']} ({contract['name']}):\n{output}"
        status[contract["id"]] = match.group(1)
    broken = {contract_id for contract_id, state in status.items() if state == "BROKEN"}
    assert result.returncode == (1 if broken else 0), f"lint-imports exit status {result.returncode}:\n{output}"
    return broken, output


def unit_of(module: str) -> str:
    """The package of the declared graph that ``module`` belongs to: its layer for a module of a
    layer (``mcbench.nn.crops`` -> ``nn``), its plugin package (``methods.kpcn`` -> ``methods``),
    ``mcbench`` for the package's top-level modules, else its top-level name (a third party)."""
    parts = module.split(".")
    if parts[0] == PACKAGE and len(parts) > 1 and (ROOT / PACKAGE / parts[1] / "__init__.py").is_file():
        return parts[1]
    return parts[0]


def declared_uses() -> dict[str, set[str]]:
    """Rules 2 and 3 as a graph: package -> the packages it is declared to use (import directly),
    read from the ``protected`` contracts of the project's own packages."""
    roots = set(import_linter_config()["root_packages"])
    uses = {}
    for contract in contracts_of_type("protected"):
        for protected in contract["protected_modules"]:
            if protected.split(".")[0] not in roots:
                continue  # a third party (rule 5)
            uses.setdefault(unit_of(protected), set())
            for importer in contract["allowed_importers"]:
                uses.setdefault(unit_of(importer), set()).add(unit_of(protected))
    return uses


def measured_uses() -> dict[str, set[str]]:
    """The graph of this repository's imports, as grimp reads it for import-linter: package ->
    the declared packages it imports directly (module level or inside functions)."""
    declared = declared_uses()
    graph = grimp.build_graph(*import_linter_config()["root_packages"], cache_dir=None)
    assert graph.modules == set(project_files(ROOT)), "grimp read another tree than this repository's"
    uses = {name: set() for name in declared}
    for module in graph.modules:
        for imported in graph.find_modules_directly_imported_by(module):
            user, used = unit_of(module), unit_of(imported)
            if user != used and used in declared:
                uses.setdefault(user, set()).add(used)
    return uses


def documented_graph() -> dict[str, tuple[set[str], set[str]]]:
    """The table under ``GRAPH_HEADING`` in ``docs/architecture.md``: package -> (the packages it
    uses, the packages that use it), each a cell of backquoted names."""
    text = (ROOT / DOC).read_text()
    assert GRAPH_HEADING in text, f"{DOC}: no section {GRAPH_HEADING!r}"
    section = text.split(GRAPH_HEADING, 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")] if line.startswith("| `") else []
        if cells:
            names = [set(re.findall(r"`([\w.]+)`", cell)) for cell in cells[:3]]
            assert len(names[0]) == 1, f"{DOC}: a row of the graph names one package first: {line}"
            rows[names[0].pop()] = (names[1], names[2])
    return rows


def test_the_import_contracts_hold():
    """Rules 1-5: ``lint-imports`` on this repository keeps every contract."""
    broken, output = lint(ROOT)
    assert not broken, f"broken import contracts {sorted(broken)} (pyproject.toml, [tool.importlinter]):\n{output}"


def test_the_declared_graph_is_the_graph_of_the_code():
    """Rule 2 declares the graph as it is: each declared use is made by some import, and every
    import between packages is declared (lint-imports checks that direction too)."""
    declared, measured = declared_uses(), measured_uses()
    unused = sorted(f"{user} -> {used}" for user, uses in declared.items() for used in uses - measured.get(user, set()))
    undeclared = sorted(f"{user} -> {used}" for user, uses in measured.items() for used in uses - declared.get(user, set()))
    assert not unused, ("declared uses no module makes (drop them from the contracts in pyproject.toml "
                        f"and from {DOC}): {unused}")
    assert not undeclared, f"imports between packages the contracts do not declare: {undeclared}"


def test_every_layer_but_the_shared_bottom_declares_its_users():
    """A layer of rule 1 without a rule-2 contract could be imported by anyone: every layer that
    is a package has one; the single-file modules of the lowest level (``jit``, ``progress``)
    are the ones every package may use (its package, ``contracts``, declares its users too)."""
    (contract,) = contracts_of_type("layers")
    levels = [re.split(r"\s*[|:]\s*", level.strip("() ")) for level in contract["layers"]]
    shared = {name for name in levels[-1] if (ROOT / PACKAGE / f"{name}.py").is_file()}
    layers = {name for level in levels for name in level} - shared
    declared = {name for name in declared_uses() if name not in PLUGINS}
    assert layers == declared, f"layers {sorted(layers)} but rule-2 contracts for {sorted(declared)}"
    assert all((ROOT / PACKAGE / name / "__init__.py").is_file() for name in layers)
    assert shared and all(name in shared or name in layers for name in levels[-1])


def test_the_documented_graph_is_the_declared_one():
    declared = declared_uses()
    used_by = {name: {user for user, uses in declared.items() if name in uses} for name in declared}
    expected = {name: (uses, used_by[name]) for name, uses in declared.items()}
    assert documented_graph() == expected, f"{DOC}, {GRAPH_HEADING}: the table is not the graph of pyproject.toml"


def test_the_documentation_lists_every_pipeline_module():
    """``docs/architecture.md`` has one line per module of ``mcbench/pipeline/`` (``- `name` — ...``)."""
    listed = re.findall(r"^- `(\w+)` — ", (ROOT / DOC).read_text(), re.MULTILINE)
    modules = sorted(p.stem for p in (ROOT / PIPELINE.replace(".", "/")).glob("*.py") if p.stem != "__init__")
    assert sorted(listed) == modules, f"{DOC}: pipeline modules listed {sorted(listed)}, in the package {modules}"


#: Functions that hold class definitions made on first use (so that importing the module imports
#: no torch or Mitsuba): their length is their classes'.
CLASS_FACTORIES = {"methods/wskpn.py:network_classes", "methods/mcgan.py:network_classes",
                   "mcbench/render/path_features.py:_integrator_class"}
MAX_FUNCTION_LINES = 60


def long_functions(root: Path = ROOT) -> list[str]:
    """Functions of ``mcbench``, ``methods``, ``scenes`` and ``metrics`` with more than
    :data:`MAX_FUNCTION_LINES` lines besides their docstring, numba kernels (a decorator naming
    ``jit``) and Dr.Jit-traced functions (``dr.syntax``) aside."""
    found = []
    for package in ("mcbench", "methods", "scenes", "metrics"):
        for path in sorted((root / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    continue
                if any("jit" in ast.unparse(d) or "dr.syntax" in ast.unparse(d) for d in node.decorator_list):
                    continue
                body = node.body
                docstring = (body[0].end_lineno - body[0].lineno + 1 if body and isinstance(body[0], ast.Expr)
                             and isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str)
                             else 0)
                lines = node.end_lineno - node.lineno + 1 - docstring
                name = f"{relative(path, root)}:{node.name}"
                if lines > MAX_FUNCTION_LINES and name not in CLASS_FACTORIES:
                    found.append(f"{name}: {lines} lines besides its docstring")
    return found


def test_no_function_is_over_sixty_lines():
    """Small functions: none over :data:`MAX_FUNCTION_LINES` lines of code, but numba kernels and
    the class factories of :data:`CLASS_FACTORIES`."""
    assert long_functions() == []


#: Names two modules of mcbench may share (none).
SHARED_MODULE_NAMES: set[str] = set()


def test_no_two_modules_share_a_name():
    """No two modules or packages of ``mcbench`` have the same name, whatever their layers (one
    name per concept, ``docs/architecture.md``), but those of :data:`SHARED_MODULE_NAMES`."""
    found: dict[str, list[str]] = {}
    for path in sorted((ROOT / "mcbench").rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        name = path.parent.name if path.stem == "__init__" else path.stem
        if path.stem == "__init__" and path.parent == ROOT / "mcbench":
            continue
        found.setdefault(name, []).append(relative(path, ROOT))
    shared = {name: paths for name, paths in found.items() if len(paths) > 1 and name not in SHARED_MODULE_NAMES}
    assert not shared, f"modules of the same name: {shared}"


# ---------------------------------------------------------------------------------------------
# Rule 4 through a package's __init__, and rules 6-9: reading the tree with ast


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def project_files(root: Path, packages: tuple[str, ...] = PROJECT_PACKAGES) -> dict[str, Path]:
    """Module name -> file of every ``.py`` file under ``root/<package>`` for each package."""
    return {module_name(p, root): p for package in packages
            for p in sorted((root / package).rglob("*.py")) if "__pycache__" not in p.parts}


def relative(path: Path, root: Path) -> str:
    return path.relative_to(root).as_posix()


def resolve_from(node: ast.ImportFrom, importer: str, is_package: bool) -> str:
    """Absolute module of ``from <module> import ...`` (relative levels resolved)."""
    if not node.level:
        return node.module or ""
    base = importer.split(".")
    base = base if is_package else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def is_literal_import_call(node: ast.AST) -> bool:
    """``importlib.import_module("x")``, ``import_module("x")`` or ``__import__("x")``."""
    if not (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)):
        return False
    func = node.func
    name = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""
    return name in ("import_module", "__import__")


@functools.cache
def parsed(source: str) -> tuple[list[ast.AST], list[ast.Attribute]]:
    """The import statements and literal import calls of ``source``, and its attribute nodes
    (cached by text: the scratch-copy tests parse the same files many times)."""
    nodes, attributes = [], []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Import, ast.ImportFrom)) or is_literal_import_call(node):
            nodes.append(node)
        elif isinstance(node, ast.Attribute):
            attributes.append(node)
    return nodes, attributes


def imports_in(source: str, importer: str, is_package: bool,
               known: set[str]) -> list[tuple[str, int, dict[str, tuple[str, bool]]]]:
    """(imported module, line, {local name: (module or module.attribute, binds a module)}) for
    every import in ``source`` (the text of module ``importer``), wherever it is; ``from pkg
    import sub`` names the submodule when ``pkg.sub`` is a known module."""
    found = []
    for node in parsed(source)[0]:
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
        elif is_literal_import_call(node):
            found.append((node.args[0].value, node.lineno, {}))
    return sorted(found, key=lambda item: item[1])


def in_package(target: str, package: str) -> bool:
    return target == package or target.startswith(package + ".")


def nearest_known(target: str, known: set[str]) -> str:
    """``target`` or its nearest enclosing known module ("" for a module outside the project)."""
    while target and target not in known:
        target = target.rpartition(".")[0]
    return target


def import_graph(root: Path) -> dict[str, set[str]]:
    """Edges among the modules of mcbench/, methods/ and scenes/: importer -> the nearest
    project module of each import (module level or inside functions)."""
    modules = project_files(root)
    known = set(modules)
    return {name: {nearest_known(target, known)
                   for target, _, _ in imports_in(path.read_text(), name, path.name == "__init__.py", known)}
            - {"", name} for name, path in modules.items()}


def cycle_through(graph: dict[str, set[str]], start: str) -> list[str] | None:
    """A shortest import chain from ``start`` back to ``start`` (breadth first), or None."""
    parents, queue = {}, deque()
    for module in sorted(graph[start]):
        parents[module] = start
        queue.append(module)
    while queue:
        module = queue.popleft()
        if module == start:
            chain, node = [start], parents[start]
            while node != start:
                chain.append(node)
                node = parents[node]
            return [start] + chain[::-1]
        for imported in sorted(graph.get(module, ())):
            if imported not in parents:
                parents[imported] = module
                queue.append(imported)
    return None


# The checkers: each takes the root of a tree and returns its findings (empty: the rule holds)


def package_cycles(root: Path) -> list[str]:
    """(4) Import cycles through a package's own module (its ``__init__``), which import-linter's
    ``acyclic_siblings`` leaves out: it compares the children of a package, not the package with
    its children (e.g. ``methods`` importing ``methods.jbf``, which imports ``methods``)."""
    graph = import_graph(root)
    packages = [name for name, path in project_files(root).items() if path.name == "__init__.py"]
    return [f"cycle through package {package}: " + " -> ".join(chain) for package in sorted(packages)
            if (chain := cycle_through(graph, package))]



def import_calls(root: Path) -> list[str]:
    """(6) ``importlib.import_module`` / ``__import__`` calls naming a project module, which
    import-linter's graph leaves out."""
    return [f"{relative(path, root)}:{node.lineno}: imports {node.args[0].value} by a call "
            "(an import statement, which the contracts see)"
            for path in project_files(root).values() for node in parsed(path.read_text())[0]
            if is_literal_import_call(node) and node.args[0].value.split(".")[0] in PROJECT_PACKAGES]


def long_plugin_files(root: Path, limit: int = MAX_PLUGIN_LINES) -> list[str]:
    """(7) Plugin files over ``limit`` lines."""
    found = []
    for path in project_files(root, PLUGINS).values():
        lines = len(path.read_text().splitlines())
        if lines > limit:
            found.append(f"{relative(path, root)}: {lines} lines (at most {limit} in a plugin file)")
    return found


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
    for node in parsed(source)[1]:
        if is_private(node.attr):
            chain, value = [], node.value  # e.g. pkg.module._name: chain ["module"]
            while isinstance(value, ast.Attribute):
                chain.append(value.attr)
                value = value.value
            if isinstance(value, ast.Name) and value.id in modules:
                owner = ".".join([modules[value.id]] + chain[::-1])
                if owner.split(".")[0] in PROJECT_PACKAGES and owner != importer:
                    uses.append(f"{where}:{node.lineno} uses {owner}.{node.attr}")
    return sorted(set(uses))


def private_uses(root: Path) -> list[str]:
    """(8) Uses of other modules' private names, in mcbench/, methods/ and scenes/."""
    modules = project_files(root)
    known = set(modules)
    return [use for name, path in modules.items()
            for use in private_uses_in(path.read_text(), name, relative(path, root), known,
                                       is_package=path.name == "__init__.py")]


def script_violations(root: Path) -> list[str]:
    """(9) Imports of workflow/scripts/*.py from mcbench outside mcbench.pipeline (mcbench itself
    allowed), or of a plugin."""
    known = set(project_files(root))
    found = []
    for path in sorted((root / SCRIPTS).glob("*.py")):
        for target, line, _ in imports_in(path.read_text(), f"scripts.{path.stem}", False, known):
            top = target.split(".")[0]
            if top in PLUGINS or (top == PACKAGE and target != PACKAGE and not in_package(target, PIPELINE)):
                found.append(f"{relative(path, root)}:{line}: imports {target} (scripts call {PIPELINE} only)")
    return found


#: rule -> (its checker, what the checker's findings are)
CHECKS = {4: (package_cycles, "import cycles through a package's __init__"),
          6: (import_calls, "project modules imported by importlib/__import__ calls"),
          7: (long_plugin_files, "plugin files to split (reusable parts move down into a layer)"),
          8: (private_uses, "private names used across modules (core, methods and scenes alike)"),
          9: (script_violations, "workflow scripts importing below mcbench.pipeline")}


def findings(root: Path) -> dict[int, set[str]]:
    return {rule: set(check(root)) for rule, (check, _) in CHECKS.items()}


@pytest.mark.parametrize("rule", sorted(CHECKS))
def test_the_rule_holds(rule):
    check, what = CHECKS[rule]
    found = check(ROOT)
    assert not found, f"rule {rule}, {what}:\n" + "\n".join(found)


def test_the_workflow_scripts_are_found():
    """Rule 9 reads ``workflow/scripts/*.py``: an empty glob would make it hold trivially."""
    assert sorted((ROOT / SCRIPTS).glob("*.py")), f"no workflow scripts in {SCRIPTS}"


# ---------------------------------------------------------------------------------------------
# The checkers themselves


def test_the_walk_sees_function_level_relative_and_importlib_imports():
    source = ("import numpy as np\nfrom . import buffers\nfrom ..io import exr\n\n"
              "def f():\n    from mcbench.render.renderer import _load\n    import methods.ensemble\n"
              "    __import__('scenes.furball')\n"
              "    return importlib.import_module('scenes.cornell_box')\n")
    known = {"mcbench.nn.buffers", "mcbench.io.exr", "mcbench.render.renderer"}
    found = {(target, tuple(names.items())) for target, _, names in
             imports_in(source, "mcbench.nn.probe", False, known)}
    assert ("mcbench.nn.buffers", (("buffers", ("mcbench.nn.buffers", True)),)) in found
    assert ("mcbench.io.exr", (("exr", ("mcbench.io.exr", True)),)) in found
    assert ("mcbench.render.renderer", (("_load", ("mcbench.render.renderer._load", False)),)) in found
    assert ("methods.ensemble", (("methods", ("methods", True)),)) in found
    assert ("scenes.cornell_box", ()) in found
    assert ("scenes.furball", ()) in found


def test_cycle_through_finds_the_shortest_loop_back():
    graph = {"p": {"p.a", "q"}, "p.a": {"p.b"}, "p.b": {"p"}, "q": {"p"}, "r": set()}
    assert cycle_through(graph, "p") == ["p", "q", "p"]
    assert cycle_through(graph, "p.a") == ["p.a", "p.b", "p", "p.a"]
    assert cycle_through(graph, "r") is None and cycle_through({"s": {"t"}, "t": set()}, "s") is None


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


def write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_checkers_on_a_minimal_synthetic_tree(tmp_path):
    """Each of rules 4 (through a package) and 6-9 fires on its own file of a small tree."""
    write(tmp_path / "mcbench/__init__.py", "")
    write(tmp_path / "mcbench/pipeline/__init__.py", "from mcbench.pipeline import step\n")
    write(tmp_path / "mcbench/pipeline/step.py", "def f():\n    import mcbench.pipeline\n")
    write(tmp_path / "mcbench/low/__init__.py", "def _hidden():\n    pass\n")
    write(tmp_path / "mcbench/low/a.py", "import numpy\nfrom mcbench import BenchError\n")
    write(tmp_path / "methods/__init__.py", "")
    write(tmp_path / "methods/m.py", "from mcbench.low import _hidden\n" + "#\n" * MAX_PLUGIN_LINES)
    write(tmp_path / "scenes/__init__.py", "")
    write(tmp_path / "scenes/s.py", "import importlib\nimportlib.import_module('mcbench.pipeline.x')\n"
                                    "__import__('numpy')\n")
    write(tmp_path / "workflow/scripts/run.py", "from mcbench import BenchError\nfrom mcbench.low.a import f\n"
                                                "from mcbench.pipeline import rendering\n")

    assert package_cycles(tmp_path) == [
        "cycle through package mcbench.pipeline: mcbench.pipeline -> mcbench.pipeline.step -> mcbench.pipeline"]
    assert import_calls(tmp_path) == ["scenes/s.py:2: imports mcbench.pipeline.x by a call "
                                      "(an import statement, which the contracts see)"]
    assert long_plugin_files(tmp_path) == [f"methods/m.py: {MAX_PLUGIN_LINES + 1} lines (at most 600 in a plugin file)"]
    assert private_uses(tmp_path) == ["methods/m.py:1 imports mcbench.low._hidden"]
    assert script_violations(tmp_path) == [
        "workflow/scripts/run.py:2: imports mcbench.low.a (scripts call mcbench.pipeline only)"]


# ---------------------------------------------------------------------------------------------
# Every rule, on a scratch copy of the tree broken one way


def copy_tree(dest: Path) -> Path:
    """``pyproject.toml`` and the .py files of mcbench/, methods/, scenes/ and workflow/scripts/
    copied under ``dest``."""
    shutil.copyfile(ROOT / "pyproject.toml", dest / "pyproject.toml")
    for tree in PROJECT_PACKAGES + (str(SCRIPTS),):
        for path in sorted((ROOT / tree).rglob("*.py")):
            if "__pycache__" in path.parts:
                continue
            target = dest / path.relative_to(ROOT)
            target.parent.mkdir(parents=True, exist_ok=True)
            try:
                shutil.copyfile(path, target)
            except FileNotFoundError:  # removed while copying (someone is editing the tree)
                continue
    return dest


@pytest.fixture(scope="module")
def clean_copy(tmp_path_factory):
    """A copy of the tree that keeps every contract, and its findings of rules 6-9."""
    root = copy_tree(tmp_path_factory.mktemp("clean"))
    broken, output = lint(root)
    assert not broken, f"the unbroken copy already breaks {sorted(broken)}:\n{output}"
    return root, findings(root)


def append(path: Path, text: str) -> None:
    """Add ``text`` at the end of ``path`` (existing line numbers, hence findings, keep)."""
    path.write_text(path.read_text().rstrip("\n") + "\n" + text)


PROBE = "\n\ndef _architecture_probe():\n    {}\n"

# name: ({path: text appended, or None for a new module}, the contract id or rule 6-9 that must
#        report it, words of its report)
BREAKAGES = {
    "upward import inside a function": (
        {"mcbench/io/exr.py": PROBE.format("from mcbench.analysis.metrics import tonemap")},
        "1-layers", ["mcbench.io.exr -> mcbench.analysis.metrics"]),
    "upward relative import": (
        {"mcbench/render/seeds.py": PROBE.format("from ..nn import features")},
        "1-layers", ["mcbench.render.seeds -> mcbench.nn.features"]),
    "top-level module importing a layer": (
        {"mcbench/progress.py": PROBE.format("from mcbench.io import tables")},
        "1-layers", ["mcbench.progress -> mcbench.io.tables"]),
    "new top-level module": (
        {"mcbench/helpers.py": None}, "1-layers", ["not listed as layers", "mcbench.helpers"]),
    "import between the independent layers of one level": (
        {"mcbench/analysis/error_speed_figures.py": PROBE.format("from mcbench.training_data import fingerprints")},
        "1-layers", ["mcbench.analysis.error_speed_figures -> mcbench.training_data.fingerprints"]),
    "a lower layer the layer does not use (analysis -> nn)": (
        {"mcbench/analysis/metrics.py": PROBE.format("from mcbench.nn import losses")},
        "2-nn", ["mcbench.analysis.metrics -> mcbench.nn.losses"]),
    "a layer a plugin does not use (scenes -> combine)": (
        {"scenes/cornell_box.py": PROBE.format("from mcbench.combine import selection")},
        "2-combine", ["scenes.cornell_box -> mcbench.combine.selection"]),
    "a lower layer the layer does not use (analysis -> filters)": (
        {"mcbench/analysis/pool.py": PROBE.format("from mcbench.filters import sure")},
        "2-filters", ["mcbench.analysis.pool -> mcbench.filters.sure"]),
    "a lower layer the layer does not use (combine -> io)": (
        {"mcbench/combine/blending.py": PROBE.format("from mcbench.io import tables")},
        "2-io", ["mcbench.combine.blending -> mcbench.io.tables"]),
    "a layer a plugin does not use (methods -> render)": (
        {"methods/oidn.py": PROBE.format("from mcbench.render import seeds")},
        "2-render", ["methods.oidn -> mcbench.render.seeds"]),
    "a layer a plugin does not use (methods -> training_data)": (
        {"methods/oidn.py": PROBE.format("from mcbench.training_data import generator")},
        "2-training_data", ["methods.oidn -> mcbench.training_data.generator"]),
    "a layer that does not read the plugins' contracts (combine -> contracts)": (
        {"mcbench/combine/blending.py": PROBE.format("from mcbench.contracts import method")},
        "2-contracts", ["mcbench.combine.blending -> mcbench.contracts.method"]),
    "a layer a plugin does not use (scenes -> analysis)": (
        {"scenes/cornell_box.py": PROBE.format("from mcbench.analysis import metrics")},
        "2-analysis", ["scenes.cornell_box -> mcbench.analysis.metrics"]),
    "a layer that does not read the plugins' contracts (filters -> contracts)": (
        {"mcbench/filters/bilateral.py": PROBE.format("from mcbench.contracts import metric")},
        "2-contracts", ["mcbench.filters.bilateral -> mcbench.contracts.metric"]),
    "the package's __init__ importing the pipeline": (
        {"mcbench/__init__.py": PROBE.format("from mcbench.pipeline import config")},
        "2-pipeline", ["mcbench -> mcbench.pipeline.config"]),
    "core module importing a plugin": (
        {"mcbench/filters/bilateral.py": PROBE.format("import methods.jbf")},
        "3-plugins-registry", ["mcbench.filters.bilateral -> methods.jbf"]),
    "pipeline module other than the registry importing a plugin": (
        {"mcbench/pipeline/evaluation.py": PROBE.format("import scenes")},
        "3-plugins-registry", ["mcbench.pipeline.evaluation -> scenes"]),
    "method importing the pipeline": (
        {"methods/oidn.py": PROBE.format("from mcbench.pipeline import registry")},
        "3-plugins-below-pipeline", ["methods.oidn -> mcbench.pipeline.registry"]),
    "metric importing a method": (
        {"metrics/relmse.py": PROBE.format("import methods.jbf")},
        "3-plugins-independent", ["metrics.relmse -> methods.jbf"]),
    "method importing a scene": (
        {"methods/jbf.py": PROBE.format("import scenes.cornell_box")},
        "3-plugins-independent", ["methods.jbf -> scenes.cornell_box"]),
    "cycle inside a layer, through function-level imports": (
        {"mcbench/filters/sure.py": PROBE.format("from mcbench.filters import smoothing"),
         "mcbench/filters/smoothing.py": PROBE.format("from mcbench.filters import sure")},
        "4-acyclic", ["No cycles are allowed in mcbench.filters"]),
    "cycle through a package's __init__": (
        {"methods/__init__.py": PROBE.format("import methods.jbf")},
        4, ["cycle through package methods: methods -> methods.jbf -> methods"]),
    "torch below nn": (
        {"mcbench/analysis/metrics.py": PROBE.format("import torch")},
        "5-torch", ["mcbench.analysis.metrics -> torch"]),
    "Mitsuba in nn": (
        {"mcbench/nn/features.py": PROBE.format("import mitsuba as mi")},
        "5-mitsuba", ["mcbench.nn.features -> mitsuba"]),
    "scene importing the pipeline through importlib": (
        {"scenes/cornell_box.py": PROBE.format("importlib.import_module('mcbench.pipeline.config')")},
        6, ["scenes/cornell_box.py", "imports mcbench.pipeline.config by a call"]),
    "over-long plugin": (
        {"scenes/cornell_box.py": "#\n" * (MAX_PLUGIN_LINES + 1)},
        7, ["scenes/cornell_box.py", "lines (at most 600"]),
    "private name of another module": (
        {"methods/jbf.py": PROBE.format("from mcbench.io.exr import _private_helper")},
        8, ["methods/jbf.py", "imports mcbench.io.exr._private_helper"]),
    "script importing below the pipeline": (
        {"workflow/scripts/error_curves.py": "from mcbench.analysis.error_speed_figures import error_curves\n"},
        9, ["workflow/scripts/error_curves.py", "imports mcbench.analysis.error_speed_figures"]),
    "script importing a plugin": (
        {"workflow/scripts/gather_timings.py": "import methods\n"},
        9, ["workflow/scripts/gather_timings.py", "imports methods"]),
}


def test_every_contract_and_rule_has_a_breakage():
    ids = {contract["id"] for contract in import_linter_config()["contracts"]}
    assert {check for _, check, _ in BREAKAGES.values()} == ids | set(CHECKS)


@pytest.mark.parametrize("breakage", sorted(BREAKAGES))
def test_a_broken_scratch_copy_fails_the_check(breakage, clean_copy, tmp_path):
    """Copy the tree, break it one way, and the matching contract or check reports it."""
    clean, before = clean_copy
    root = tmp_path / "tree"
    shutil.copytree(clean, root)
    edits, check, words = BREAKAGES[breakage]
    for relative_path, text in edits.items():
        if text is None:
            write(root / relative_path, '"""A module added without a layer."""\n')
        else:
            append(root / relative_path, text)
    if isinstance(check, int):
        new = sorted(findings(root)[check] - before[check])
        assert any(all(word in finding for word in words) for finding in new), (
            f"rule {check} missed the {breakage}; new findings: {new}")
    else:
        broken, output = lint(root)
        assert check in broken, f"contract {check} kept despite the {breakage}:\n{output}"
        report = output.split(next(c["name"] for c in import_linter_config()["contracts"] if c["id"] == check))[-1]
        assert all(word in report for word in words), f"contract {check}'s report lacks {words}:\n{output}"
