"""The import rules of docs/architecture.md, checked on the source: the four packages, the layers inside
them, and no import cycle between any two modules (imports inside functions count)."""
import ast
import functools
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("design", "analysis", "drivers", "labapp")
FORBIDDEN = {
    "design": ["labapp", "drivers", "analysis", "PySide6", "pyqtgraph"],
    "analysis": ["labapp", "drivers", "design", "PySide6", "pyqtgraph"],
    "drivers": ["labapp", "design", "analysis", "PySide6", "pyqtgraph"],
}
#: sub-package -> the sub-packages of the same package it must not import (docs/architecture.md, "Layers")
LAYERS = {
    "labapp.records": ["labapp.acquisition", "labapp.jobs", "labapp.scaleout", "labapp.figures", "labapp.cli",
                       "labapp.gui"],
    "labapp.figures": ["labapp.acquisition", "labapp.jobs", "labapp.scaleout", "labapp.cli", "labapp.gui"],
    "labapp.acquisition": ["labapp.jobs", "labapp.scaleout", "labapp.figures", "labapp.cli", "labapp.gui"],
    "labapp.jobs": ["labapp.scaleout", "labapp.cli", "labapp.gui"],
    "labapp.scaleout": ["labapp.acquisition", "labapp.cli", "labapp.gui"],
    "labapp.gui": ["labapp.cli"],
    "design.forward": ["design.geometry", "design.fabrication", "design.inverse", "design.montecarlo", "design.files"],
    "design.geometry": ["design.forward", "design.fabrication", "design.inverse", "design.montecarlo", "design.files"],
    "design.fabrication": ["design.inverse", "design.montecarlo", "design.files"],
    "design.inverse": ["design.montecarlo", "design.files"],
    "design.montecarlo": ["design.fabrication", "design.inverse", "design.files"],
}


def _modules() -> dict[str, Path]:
    """Dotted module name -> source file, for every module of the four packages."""
    modules = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join(parts)] = path
    return modules


@functools.cache
def import_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports anywhere in its source (module level or inside functions); parsed
    once per test process (to be read only)."""
    modules = _modules()

    def owner(name: str) -> str | None:          # the module a dotted name lives in
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [owner(alias.name) for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[:len(package.split(".")) - (node.level - 1)]
                    base = ".".join(up + ([base] if base else []))
                targets = [owner(f"{base}.{alias.name}") for alias in node.names]
            else:
                continue
            graph[name].update(t for t in targets if t and t != name)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
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


def test_no_module_imports_itself_through_others():
    assert cycles(import_graph()) == []


def test_the_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


@pytest.mark.parametrize("layer", sorted(LAYERS))
def test_a_layer_imports_only_the_layers_below_it(layer):
    graph = import_graph()
    offenders = [f"{name} imports {target}" for name, targets in graph.items()
                 if name == layer or name.startswith(layer + ".")
                 for target in sorted(targets)
                 for banned in LAYERS[layer] if target == banned or target.startswith(banned + ".")]
    assert not offenders, offenders


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_imports_only_what_it_may(package):
    pattern = re.compile(r"^\s*(?:from|import)\s+(\w+)", re.MULTILINE)
    offenders = []
    for path in (ROOT / package).rglob("*.py"):
        for name in pattern.findall(path.read_text()):
            if name in FORBIDDEN[package]:
                offenders.append(f"{path.relative_to(ROOT)} imports {name}")
    assert not offenders, offenders


def test_qt_only_in_gui():
    pattern = re.compile(r"^\s*(?:from|import)\s+(PySide6|pyqtgraph)", re.MULTILINE)
    offenders = [str(p.relative_to(ROOT)) for p in (ROOT / "labapp").rglob("*.py")
                 if "gui" not in p.relative_to(ROOT).parts and pattern.search(p.read_text())]
    assert not offenders, offenders
