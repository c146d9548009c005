"""The packages' imports form no cycle, and pyrhonn never imports hil.

A static walk of the source (ast), not an import: every ``import`` and
``from ... import`` statement of every module under pyrhonn/ and hil/ counts,
at module level and inside functions and methods alike (a function-level
import that closes a cycle is still a cycle, only a later one). Imports under
``if TYPE_CHECKING:`` are left out: they never run. ``from . import name``
is an edge to the submodule ``name`` when there is one, else to the package
when its ``__init__`` binds ``name``; else ``name`` is a compiled submodule
(the cffi extensions), which imports nothing of ours, and no edge.
"""
from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("pyrhonn", "hil")


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules(root: Path, packages: tuple[str, ...]) -> dict[str, Path]:
    return {module_name(p, root): p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))}


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _statements(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement in ``tree`` that can run (not under ``if TYPE_CHECKING:``)."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append(node)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


@functools.cache
def bound_names(path: Path) -> set[str]:
    """The names a module binds at its top level (assignments, defs, classes, imports)."""
    names: set[str] = set()
    for node in ast.parse(path.read_text(), str(path)).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update(n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name))
    return names


def imports(name: str, path: Path, known: dict[str, Path]) -> dict[str, int]:
    """The known modules ``name`` imports, each with the line of its first import."""
    is_package = path.name == "__init__.py"
    out: dict[str, int] = {}
    for node in _statements(ast.parse(path.read_text(), str(path))):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        else:
            if node.level:
                base = name.split(".")
                base = base[:len(base) - node.level + (1 if is_package else 0)]
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ""
            for alias in node.names:
                sub = f"{prefix}.{alias.name}"
                if sub in known or prefix not in known or alias.name == "*" or \
                        alias.name in bound_names(known[prefix]):
                    targets.append(sub if sub in known else prefix)
        for target in targets:
            while target and target not in known:  # ``import a.b.c`` of a package a.b: the deepest known module
                target = target.rpartition(".")[0]
            if target and target != name:
                out.setdefault(target, node.lineno)
    return out


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, {})))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
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
    return found


def import_graph(root: Path, packages: tuple[str, ...]) -> dict[str, dict[str, int]]:
    known = modules(root, packages)
    return {name: imports(name, path, known) for name, path in known.items()}


def describe(graph: dict[str, dict[str, int]], component: list[str]) -> str:
    members = set(component)
    return "; ".join(f"{a} imports {b} (line {line})" for a in component
                     for b, line in sorted(graph[a].items()) if b in members)


@pytest.fixture(scope="module")
def graph() -> dict[str, dict[str, int]]:
    return import_graph(ROOT, PACKAGES)


def test_pyrhonn_and_hil_have_no_import_cycle(graph: dict[str, dict[str, int]]) -> None:
    assert len(graph) > 40 and "pyrhonn.identifier" in graph and "hil.rig" in graph
    found = cycles(graph)
    assert not found, "import cycles: " + " | ".join(describe(graph, c) for c in found)


def test_pyrhonn_never_imports_hil(graph: dict[str, dict[str, int]]) -> None:
    wrong = {a: sorted(b for b in targets if b.split(".")[0] == "hil")
             for a, targets in graph.items() if a.split(".")[0] == "pyrhonn"}
    assert not {a: b for a, b in wrong.items() if b}


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)


def test_the_walk_finds_a_cycle_closed_inside_a_function(tmp_path: Path) -> None:
    _write(tmp_path, {"pkg/__init__.py": "", "pkg/a.py": "from .b import f\n",
                      "pkg/b.py": "def f():\n    from . import a\n", "pkg/c.py": "import pkg.a\n"})
    graph = import_graph(tmp_path, ("pkg",))
    assert graph["pkg.b"] == {"pkg.a": 2} and graph["pkg.c"] == {"pkg.a": 1}
    assert cycles(graph) == [["pkg.a", "pkg.b"]]


def test_the_walk_skips_type_checking_imports_and_resolves_parent_packages(tmp_path: Path) -> None:
    _write(tmp_path, {"pkg/__init__.py": "from .a import x\n",
                      "pkg/a.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .b import y\nx = 1\n",
                      "pkg/b.py": "from .a import x\ny = 2\n",
                      "pkg/sub/__init__.py": "from .. import a\n", "pkg/sub/d.py": "from .. import x\n",
                      "pkg/e.py": "from . import _compiled\n"})
    graph = import_graph(tmp_path, ("pkg",))
    assert graph["pkg.a"] == {} and graph["pkg.sub"] == {"pkg.a": 1} and graph["pkg.sub.d"] == {"pkg": 1}
    assert graph["pkg.e"] == {}
    assert cycles(graph) == []


@pytest.mark.parametrize("text", ["import pkg.b\n", "from pkg import b\n", "from . import b\n"])
def test_the_walk_sees_every_spelling_of_an_import(tmp_path: Path, text: str) -> None:
    _write(tmp_path, {"pkg/__init__.py": "", "pkg/a.py": text, "pkg/b.py": "from .a import *\n"})
    assert cycles(import_graph(tmp_path, ("pkg",))) == [["pkg.a", "pkg.b"]]
