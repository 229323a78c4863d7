"""The project's import rules (``docs/architecture.md``), checked statically: every file is parsed
with ``ast``, no import is executed. Imports count wherever they are: module level, inside
functions (where cycles hide), relative imports, ``importlib.import_module("literal")`` and
``__import__("literal")``.

a. no import cycle among the modules of ``mcbench/``, ``methods/`` and ``scenes/`` together;
b. a module of layer L (``mcbench.<L>.*``, L in ``mcbench.LAYERS``) imports only from its own
   or lower layers; the top-level modules (``mcbench/__init__.py``, ``jit.py``, ``progress.py``)
   sit below every layer and import none; inside ``mcbench`` only
   ``mcbench.pipeline.registry`` imports the plugin packages ``methods`` and ``scenes``;
c. the plugins (``methods/``, ``scenes/``) never import ``mcbench.pipeline``;
d. no plugin file is over 600 lines;
e. ``workflow/scripts/*.py`` import from ``mcbench`` only ``mcbench.pipeline.*`` (and
   ``mcbench`` itself), and no plugin;
f. every module under ``mcbench/`` is in a layer package ``mcbench/<L>/`` or is an allowed
   top-level module (a new top-level module is added to :data:`TOP_LEVEL_MODULES` deliberately);
g. no module uses another module's private (``_name``) function, constant or module.

Every checker takes the root of a tree and returns its findings, so the tests at the end run them
on broken scratch copies of the tree and show that each kind of violation is reported. The
layers are read from the tree's own ``mcbench/__init__.py`` (``LAYERS``), again without importing.

A package's ``__init__`` is not counted as imported when one of its submodules is (Python runs
it, but re-exports in ``__init__`` would otherwise make every package a cycle).
"""

from __future__ import annotations

import ast
import functools
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "mcbench"
PLUGINS = ("methods", "scenes")
PROJECT_PACKAGES = (PACKAGE,) + PLUGINS
#: The modules of ``mcbench`` outside every layer (below all of them).
TOP_LEVEL_MODULES = ("mcbench", "mcbench.jit", "mcbench.progress")
#: The one core module that imports the plugins.
REGISTRY = "mcbench.pipeline.registry"
PIPELINE = "mcbench.pipeline"
MAX_PLUGIN_LINES = 600
SCRIPTS = Path("workflow") / "scripts"


# ---------------------------------------------------------------------------------------------
# Reading the tree


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def project_files(root: Path, packages: tuple[str, ...] = PROJECT_PACKAGES) -> dict[str, Path]:
    """Module name -> file of every ``.py`` file under ``root/<package>`` for each package."""
    return {module_name(p, root): p for package in packages
            for p in sorted((root / package).rglob("*.py")) if "__pycache__" not in p.parts}


def layers(root: Path) -> tuple[str, ...]:
    """``LAYERS`` of ``root/mcbench/__init__.py``, read from its source."""
    tree = ast.parse((root / PACKAGE / "__init__.py").read_text())
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, ast.AnnAssign) else []
        if any(isinstance(t, ast.Name) and t.id == "LAYERS" for t in targets):
            return tuple(ast.literal_eval(node.value))
    raise AssertionError(f"no LAYERS in {root / PACKAGE / '__init__.py'}")


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
    every import in ``source`` (the text of module ``importer``); ``from pkg import sub`` names
    the submodule when ``pkg.sub`` is a known module."""
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


def imports_of(path: Path, root: Path, known: set[str]):
    return imports_in(path.read_text(), module_name(path, root), path.name == "__init__.py", known)


def nearest_known(target: str, known: set[str]) -> str:
    """``target`` or its nearest enclosing known module ("" for a module outside the project)."""
    while target and target not in known:
        target = target.rpartition(".")[0]
    return target


def in_package(target: str, package: str) -> bool:
    return target == package or target.startswith(package + ".")


# ---------------------------------------------------------------------------------------------
# The checkers: each takes the root of a tree and returns its findings (empty: the rule holds)


def import_graph(root: Path) -> dict[str, set[str]]:
    """Edges among the modules of mcbench/, methods/ and scenes/: importer -> imported (the
    nearest known module)."""
    modules = project_files(root)
    known = set(modules)
    graph = {name: set() for name in modules}
    for name, path in modules.items():
        for target, _, _ in imports_of(path, root, known):
            target = nearest_known(target, known)
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


def import_cycles(root: Path) -> list[str]:
    """(a) Each import cycle of the tree, as its modules."""
    return ["cycle: " + ", ".join(component) for component in cycles(import_graph(root))]


def layer_of(module: str, layer_names: tuple[str, ...]) -> int | None:
    """Index of ``module``'s layer in ``layer_names``; -1 for the top-level modules of mcbench;
    None for a name in no layer."""
    parts = module.split(".")
    if parts[0] != PACKAGE:
        return None
    if len(parts) == 1 or ".".join(parts[:2]) in TOP_LEVEL_MODULES:
        return -1
    return layer_names.index(parts[1]) if parts[1] in layer_names else None


def layer_label(index: int, layer_names: tuple[str, ...]) -> str:
    return "mcbench top level" if index < 0 else f"layer {layer_names[index]}"


def layer_violations(root: Path) -> list[str]:
    """(b) Imports of a core module from a higher layer, from a name in no layer, or of a plugin
    (anywhere but the registry)."""
    layer_names = layers(root)
    known = set(project_files(root))
    found = []
    for name, path in project_files(root, (PACKAGE,)).items():
        own = layer_of(name, layer_names)
        if own is None:
            continue  # in no layer: unlayered_modules reports it
        for target, line, _ in imports_of(path, root, known):
            where = f"{relative(path, root)}:{line}: {name} ({layer_label(own, layer_names)})"
            top = target.split(".")[0]
            if top in PLUGINS:
                if name != REGISTRY:
                    found.append(f"{where} imports plugin {target} (only {REGISTRY} may)")
            elif top == PACKAGE:
                theirs = layer_of(target, layer_names)
                if theirs is None:
                    found.append(f"{where} imports {target}, which is in no layer")
                elif theirs > own:
                    found.append(f"{where} imports {target} ({layer_label(theirs, layer_names)})")
    return found


def plugin_violations(root: Path) -> list[str]:
    """(c) Imports of mcbench.pipeline by a plugin module."""
    known = set(project_files(root))
    return [f"{relative(path, root)}:{line}: plugin {name} imports {target}"
            for name, path in project_files(root, PLUGINS).items()
            for target, line, _ in imports_of(path, root, known) if in_package(target, PIPELINE)]


def long_plugin_files(root: Path, limit: int = MAX_PLUGIN_LINES) -> list[str]:
    """(d) Plugin files over ``limit`` lines."""
    found = []
    for path in project_files(root, PLUGINS).values():
        lines = len(path.read_text().splitlines())
        if lines > limit:
            found.append(f"{relative(path, root)}: {lines} lines (at most {limit} in a plugin file)")
    return found


def script_violations(root: Path) -> list[str]:
    """(e) Imports of workflow/scripts/*.py from mcbench outside mcbench.pipeline (mcbench itself
    allowed), or of a plugin."""
    known = set(project_files(root))
    found = []
    for path in sorted((root / SCRIPTS).glob("*.py")):
        for target, line, _ in imports_in(path.read_text(), f"scripts.{path.stem}", False, known):
            top = target.split(".")[0]
            if top in PLUGINS or (top == PACKAGE and target != PACKAGE and not in_package(target, PIPELINE)):
                found.append(f"{relative(path, root)}:{line}: imports {target} (scripts call {PIPELINE} only)")
    return found


def unlayered_modules(root: Path) -> list[str]:
    """(f) Modules of mcbench/ in no layer package and not allowed top-level modules; layers of
    LAYERS without a package."""
    layer_names = layers(root)
    found = [f"{PACKAGE}/{layer}/: layer {layer} of LAYERS has no package (no __init__.py)"
             for layer in layer_names if not (root / PACKAGE / layer / "__init__.py").is_file()]
    for name, path in project_files(root, (PACKAGE,)).items():
        parts = path.relative_to(root / PACKAGE).parts
        if name in TOP_LEVEL_MODULES or (len(parts) > 1 and parts[0] in layer_names):
            continue
        found.append(f"{relative(path, root)}: {name} is in no layer of LAYERS {layer_names} and "
                     f"not an allowed top-level module {TOP_LEVEL_MODULES}")
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
    """(g) Uses of other modules' private names, in mcbench/, methods/ and scenes/."""
    modules = project_files(root)
    known = set(modules)
    return [use for name, path in modules.items()
            for use in private_uses_in(path.read_text(), name, relative(path, root), known,
                                       is_package=path.name == "__init__.py")]


CHECKS = {"cycles": import_cycles, "layers": layer_violations, "plugins": plugin_violations,
          "length": long_plugin_files, "scripts": script_violations,
          "unlayered": unlayered_modules, "private": private_uses}


def findings(root: Path) -> dict[str, set[str]]:
    return {check: set(function(root)) for check, function in CHECKS.items()}


# ---------------------------------------------------------------------------------------------
# The rules on this repository


def test_no_import_cycle():
    found = import_cycles(ROOT)
    assert not found, "import cycles in mcbench/, methods/, scenes/:\n" + "\n".join(found)


def test_each_core_module_imports_its_own_or_lower_layers_only():
    found = layer_violations(ROOT)
    assert not found, "imports against the layers:\n" + "\n".join(found)


def test_plugins_never_import_the_pipeline():
    found = plugin_violations(ROOT)
    assert not found, "plugins importing mcbench.pipeline:\n" + "\n".join(found)


def test_no_plugin_file_over_the_limit():
    found = long_plugin_files(ROOT)
    assert not found, "plugin files to split (reusable parts move down into a layer):\n" + "\n".join(found)


def test_workflow_scripts_call_only_the_pipeline():
    assert sorted((ROOT / SCRIPTS).glob("*.py")), "no workflow scripts found"
    found = script_violations(ROOT)
    assert not found, "workflow scripts importing below mcbench.pipeline:\n" + "\n".join(found)


def test_every_core_module_is_in_a_layer():
    found = unlayered_modules(ROOT)
    assert not found, "modules outside the layers:\n" + "\n".join(found)


def test_no_private_names_of_other_modules():
    """Core, methods and scenes alike: no module calls another's private names."""
    found = private_uses(ROOT)
    assert not found, "private names used across modules:\n" + "\n".join(found)


# ---------------------------------------------------------------------------------------------
# The checkers themselves


def test_cycle_finder_finds_a_known_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


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


def test_layers_are_read_from_the_tree():
    names = layers(ROOT)
    assert names and len(set(names)) == len(names) and names[-1] == "pipeline"
    assert all(name.isidentifier() for name in names)
    assert layer_of("mcbench", names) == layer_of("mcbench.jit", names) == -1
    assert layer_of("mcbench.io.exr", names) == names.index("io")
    assert layer_of("mcbench.nowhere", names) is None and layer_of("numpy", names) is None


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
    """A two-layer package: LAYERS comes from the tree, and each rule fires on its own file."""
    write(tmp_path / "mcbench/__init__.py", 'LAYERS = ("low", "high")\n')
    write(tmp_path / "mcbench/jit.py", "def f():\n    from mcbench.low import a\n")
    write(tmp_path / "mcbench/low/__init__.py", "")
    write(tmp_path / "mcbench/low/a.py", "import numpy\nfrom mcbench import BenchError\n\n"
                                         "def f():\n    from ..high import b\n")
    write(tmp_path / "mcbench/high/__init__.py", "")
    write(tmp_path / "mcbench/high/b.py", "from mcbench.low import a\nimport methods.m\n")
    write(tmp_path / "mcbench/extra.py", "")
    write(tmp_path / "methods/__init__.py", "")
    write(tmp_path / "methods/m.py", "from mcbench.high import b\n" + "#\n" * MAX_PLUGIN_LINES)
    write(tmp_path / "scenes/__init__.py", "")
    write(tmp_path / "scenes/s.py", "import importlib\nimportlib.import_module('mcbench.pipeline.x')\n")
    write(tmp_path / "workflow/scripts/run.py", "from mcbench import BenchError\nfrom mcbench.low.a import f\n")

    # the function-level upward import a -> b closes a second loop through b -> a
    assert import_cycles(tmp_path) == ["cycle: mcbench.high.b, mcbench.low.a, methods.m"]
    assert layer_violations(tmp_path) == [
        "mcbench/high/b.py:2: mcbench.high.b (layer high) imports plugin methods.m (only mcbench.pipeline.registry may)",
        "mcbench/jit.py:2: mcbench.jit (mcbench top level) imports mcbench.low.a (layer low)",
        "mcbench/low/a.py:5: mcbench.low.a (layer low) imports mcbench.high.b (layer high)"]
    assert plugin_violations(tmp_path) == ["scenes/s.py:2: plugin scenes.s imports mcbench.pipeline.x"]
    assert long_plugin_files(tmp_path) == [f"methods/m.py: {MAX_PLUGIN_LINES + 1} lines (at most 600 in a plugin file)"]
    assert script_violations(tmp_path) == [
        "workflow/scripts/run.py:2: imports mcbench.low.a (scripts call mcbench.pipeline only)"]
    assert [f.split(":")[0] for f in unlayered_modules(tmp_path)] == ["mcbench/extra.py"]


def scratch_copy(dest: Path) -> Path:
    """The .py files of mcbench/, methods/, scenes/ and workflow/scripts/ copied under ``dest``."""
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


def append(path: Path, text: str) -> None:
    """Add ``text`` at the end of ``path`` (existing line numbers, hence findings, keep)."""
    path.write_text(path.read_text().rstrip("\n") + "\n" + text)


PROBE = "\n\ndef _architecture_probe():\n    {}\n"

# a function-level import in core closing a loop with a plugin that imports core
CYCLE = {"methods/jbf.py": PROBE.format("from mcbench.filters.bilateral import cross_bilateral_filter"),
         "mcbench/filters/bilateral.py": PROBE.format("import methods.jbf")}

# name: ({path: text appended, or None for a new module}, the check that must report it,
#        words of the finding it must add)
BREAKAGES = {
    "cycle between a plugin and core": (CYCLE, "cycles", ["mcbench.filters.bilateral", "methods.jbf"]),
    "core module importing a plugin": (
        CYCLE, "layers", ["mcbench/filters/bilateral.py", "imports plugin methods.jbf"]),
    "upward import inside a function": (
        {"mcbench/io/exr.py": PROBE.format("from mcbench.analysis.metrics import ALL_METRICS")},
        "layers", ["mcbench/io/exr.py", "(layer io) imports mcbench.analysis.metrics (layer analysis)"]),
    "upward relative import": (
        {"mcbench/render/seeds.py": PROBE.format("from ..nn import features")},
        "layers", ["mcbench/render/seeds.py", "(layer render) imports mcbench.nn.features (layer nn)"]),
    "top-level module importing a layer": (
        {"mcbench/progress.py": PROBE.format("from mcbench.io import tables")},
        "layers", ["mcbench/progress.py", "(mcbench top level) imports mcbench.io.tables (layer io)"]),
    "pipeline module other than the registry importing a plugin": (
        {"mcbench/pipeline/metrics.py": PROBE.format("import scenes")},
        "layers", ["mcbench/pipeline/metrics.py", "imports plugin scenes"]),
    "method importing the pipeline": (
        {"methods/oidn.py": PROBE.format("from mcbench.pipeline import registry")},
        "plugins", ["methods/oidn.py", "imports mcbench.pipeline.registry"]),
    "scene importing the pipeline through importlib": (
        {"scenes/cornell_box.py": PROBE.format("importlib.import_module('mcbench.pipeline.config')")},
        "plugins", ["scenes/cornell_box.py", "imports mcbench.pipeline.config"]),
    "over-long plugin": (
        {"scenes/cornell_box.py": "#\n" * (MAX_PLUGIN_LINES + 1)},
        "length", ["scenes/cornell_box.py", "lines (at most 600"]),
    "script importing below the pipeline": (
        {"workflow/scripts/figures.py": "from mcbench.analysis.figures import error_curves\n"},
        "scripts", ["workflow/scripts/figures.py", "imports mcbench.analysis.figures"]),
    "script importing a plugin": (
        {"workflow/scripts/run_method.py": "import methods\n"},
        "scripts", ["workflow/scripts/run_method.py", "imports methods"]),
    "new top-level module": (
        {"mcbench/helpers.py": None},
        "unlayered", ["mcbench/helpers.py", "mcbench.helpers is in no layer"]),
    "private name of another module": (
        {"methods/jbf.py": PROBE.format("from mcbench.io.exr import _private_helper")},
        "private", ["methods/jbf.py", "imports mcbench.io.exr._private_helper"]),
}


@pytest.mark.parametrize("breakage", sorted(BREAKAGES))
def test_a_broken_scratch_copy_fails_the_check(breakage, tmp_path):
    """Copy the tree, break it one way, and the matching check reports what the copy did not."""
    root = scratch_copy(tmp_path)
    before = findings(root)
    edits, check, words = BREAKAGES[breakage]
    for relative_path, text in edits.items():
        if text is None:
            write(root / relative_path, '"""A module added without a layer."""\n')
        else:
            append(root / relative_path, text)
    after = findings(root)
    new = sorted(after[check] - before[check])
    assert any(all(word in finding for word in words) for finding in new), (
        f"{check} missed the {breakage}; new findings: {new}")
