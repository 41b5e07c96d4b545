"""The import graph of the ``postproc`` package has no cycles.

The graph is read from the source with :mod:`ast`, so an import made inside a function
counts as much as one at the top of a module: a function-level import hides a cycle
from Python, not from the structure. Two graphs are checked: between modules, and
between the top-level parts of the package (``postproc.engine``, ``postproc.gcode``,
...; a module directly under ``postproc`` is a part of its own).

A module loaded by name from a registry (``"postproc.cli.correct:correct"`` in the
command table, ``"postproc.engine.static:StaticEngine"`` in the engine registry) counts
as imported by the module holding that string: loading it lazily keeps ``--help`` fast,
it does not take it out of the structure.

Run as a script to print the graph's figures and any cycle::

    python tests/test_structure.py
"""

from __future__ import annotations

import ast
import functools
import re
import sys
from collections.abc import Iterable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "postproc"
#: a "module:attribute" string naming a module of the package (a registry entry)
BY_NAME = re.compile(rf"^({PACKAGE}(?:\.\w+)+):\w+$")


def module_names(root: Path = ROOT) -> dict[str, Path]:
    """Every module of the package: dotted name -> file (a package is its ``__init__``)."""
    names = {}
    for path in sorted((root / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        if is_package:
            parts.pop()
        names[".".join(parts)] = path
    return names


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The longest prefix of ``name`` that is a module of the package, if any."""
    parts = name.split(".")
    while parts:
        candidate = ".".join(parts)
        if candidate in modules:
            return candidate
        parts.pop()
    return None


def imports_of(module: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package's modules that ``module`` imports, at any depth of its code."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                target = _resolve(alias.name, modules)
                if target:
                    found.add(target)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")
                drop = node.level - 1 if is_package else node.level
                base = base[: len(base) - drop] if drop else base
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ""
            for alias in node.names:
                target = _resolve(f"{prefix}.{alias.name}", modules)
                if target is None:
                    target = _resolve(prefix, modules)
                if target:
                    found.add(target)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            m = BY_NAME.match(node.value)
            target = _resolve(m.group(1), modules) if m else None
            if target:
                found.add(target)
    found.discard(module)
    return found


@functools.cache
def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """module -> the package's modules it imports (read once per run; do not modify)."""
    modules = module_names(root)
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def part_of(module: str) -> str:
    """The top-level part of the package a module belongs to (``postproc.engine``...)."""
    return ".".join(module.split(".")[:2])


def part_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """The graph between top-level parts: an edge where any module of one imports the other."""
    parts: dict[str, set[str]] = {}
    for module, targets in graph.items():
        source = part_of(module)
        edges = parts.setdefault(source, set())
        edges.update(part_of(t) for t in targets if part_of(t) != source)
    return parts


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for succ in sorted(graph.get(node, ())):
            if succ not in index:
                visit(succ)
                low[node] = min(low[node], low[succ])
            elif succ in on_stack:
                low[node] = min(low[node], index[succ])
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
    return sorted(found)


def _describe(graph: dict[str, set[str]], components: Iterable[list[str]]) -> str:
    lines = []
    for component in components:
        members = set(component)
        lines.append("cycle: " + ", ".join(component))
        for source in component:
            for target in sorted(graph[source] & members):
                lines.append(f"  {source} -> {target}")
    return "\n".join(lines)


def test_graph_reads_function_level_imports_and_registries():
    graph = import_graph()
    # an edge made inside a function body, and one made by a registry string
    assert "postproc.engine.registry" in graph["postproc.diagnose.models"]
    assert "postproc.engine.parametric" in graph["postproc.engine.registry"]
    assert "postproc.cli.correct" in graph["postproc.cli"]
    assert len(graph) > 50


def test_no_module_cycles():
    graph = import_graph()
    components = cycles(graph)
    assert not components, "import cycles between modules:\n" + _describe(graph, components)


def test_no_part_cycles():
    parts = part_graph(import_graph())
    components = cycles(parts)
    assert not components, "import cycles between parts of the package:\n" + _describe(
        parts, components
    )


def test_cycle_finder_on_a_hand_made_graph():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"d"}, "f": {"f"}}
    assert cycles(graph) == [["a", "b", "c"]]


def main() -> int:
    graph = import_graph()
    parts = part_graph(graph)
    edges = sum(len(t) for t in graph.values())
    part_edges = sum(len(t) for t in parts.values())
    module_cycles = cycles(graph)
    part_cycles = cycles(parts)
    lines = [f"modules {len(graph)}, edges {edges}, cycles {len(module_cycles)}",
             f"parts {len(parts)}, edges {part_edges}, cycles {len(part_cycles)}"]
    if module_cycles:
        lines.append(_describe(graph, module_cycles))
    if part_cycles:
        lines.append(_describe(parts, part_cycles))
    sys.stdout.write("\n".join(lines) + "\n")
    return 1 if module_cycles or part_cycles else 0


if __name__ == "__main__":
    sys.exit(main())


# the private names of the standard library a module may call (documented there)
STDLIB_PRIVATE = frozenset({"os._exit"})


def private_names(tree: ast.Module) -> set[str]:
    """The private names (one leading underscore) a module defines: functions, classes,
    their methods and class attributes, attributes assigned on any object, and names
    bound at any level."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update(a.asname or a.name for a in node.names)
        elif (isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__slots__"
                                                   for t in node.targets)):
            names.update(c.value for c in ast.walk(node.value)
                         if isinstance(c, ast.Constant) and isinstance(c.value, str))
    return {n for n in names if n.startswith("_") and not n.startswith("__")}


def foreign_private_uses(root: Path = ROOT) -> list[str]:
    """``module:line X._name`` for each read of a private name (one leading underscore)
    on anything but ``self`` or ``cls`` that the module itself does not define: a module
    reaching into another's internals."""
    found = []
    for name, path in module_names(root).items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        own = private_names(tree)
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Attribute) and node.attr.startswith("_")
                    and not node.attr.startswith("__")):
                continue
            if isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"):
                continue
            text = f"{ast.unparse(node.value)}.{node.attr}"
            if node.attr not in own and text not in STDLIB_PRIVATE:
                found.append(f"{name}:{node.lineno} {text}")
    return sorted(found)


def test_no_module_reaches_into_another_modules_private_names():
    """What a module uses of another is that module's public API: the run writer, the
    fit, the expansion and the solvers call the interpreter, the writer, the Sinumerik
    reader and the engine through public names."""
    assert foreign_private_uses() == []


def test_foreign_private_uses_are_found(tmp_path):
    pkg = tmp_path / PACKAGE
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("class A:\n    def _own(self):\n        return self._x\n")
    (pkg / "b.py").write_text("from postproc import a\n\ndef f(o):\n    return o._own() + a.A()._x\n")
    (pkg / "c.py").write_text("class C:\n    __slots__ = ('_z',)\n    _y = 1\n\ndef g(o):\n    return o._y + o._z\n")
    (pkg / "d.py").write_text('"""About o._y and o._w."""\n\ndef h(o):\n    return o._w\n')
    assert foreign_private_uses(tmp_path) == ["postproc.b:4 a.A()._x", "postproc.b:4 o._own", "postproc.d:4 o._w"]
