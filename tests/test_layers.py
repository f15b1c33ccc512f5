"""The package's layering, read from the source: no import cycle between files, ``render/`` reaches
the method packages only through its registry strings, no private name imported across packages.

Imports inside functions count: a cycle hidden in a function body is still a cycle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
METHOD_PACKAGES = {"ltc", "multiscale", "leadr", "colormap", "glints"}
#: Packages above render/ (they may import anything; render/ must not import them).
TOP_PACKAGES = {"viewer", "report", "studies", "cli"}


def _modules() -> dict[str, tuple[Path, str]]:
    mods = {}
    for path in SRC.rglob("*.py"):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
            pkg = ".".join(parts)
        else:
            pkg = ".".join(parts[:-1])
        mods[".".join(parts)] = (path, pkg)
    return mods


MODULES = _modules()


def _resolve(name: str) -> str | None:
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _imports(module: str) -> list[tuple[str, str | None, int]]:
    """(imported module, imported name or None, line) of every prefilter import in ``module``."""
    path, pkg = MODULES[module]
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [(t, None, node.lineno) for a in node.names if (t := _resolve(a.name))
                    and t.startswith("prefilter")]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            if not source.startswith("prefilter"):
                continue
            for alias in node.names:
                full = f"{source}.{alias.name}"
                if full in MODULES:
                    out.append((full, None, node.lineno))
                elif (t := _resolve(source)) is not None:
                    out.append((t, alias.name, node.lineno))
    return out


def _package(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def test_no_import_cycle_between_files():
    graph = {m: {t for t, _, _ in _imports(m) if t != m} for m in MODULES}
    # A package's __init__ re-exporting its modules is not a cycle between files of the package.
    for m in graph:
        graph[m] = {t for t in graph[m] if not (m.startswith(t + ".") and MODULES[t][0].name ==
                                                "__init__.py")}
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles between files: {cycles}"


def test_render_reaches_methods_only_through_the_registry():
    arrows = [(m, t, line) for m in MODULES if _package(m) == "render"
              for t, _, line in _imports(m)
              if _package(t) in METHOD_PACKAGES | TOP_PACKAGES]
    assert not arrows, f"render/ imports method or top-level packages: {arrows}"


def test_no_private_name_imported_across_packages():
    private = []
    for m in MODULES:
        for t, name, line in _imports(m):
            if _package(t) == _package(m):
                continue
            hidden = [s for s in t.split(".")[1:] if s.startswith("_") and s != "__init__"]
            if hidden or (name or "").startswith("_"):
                private.append((m, t, name, line))
    assert not private, f"private names imported across packages: {private}"


@pytest.mark.parametrize("module", ["prefilter.render.methods"])
def test_the_registry_names_modules_it_does_not_import(module):
    assert not [t for t, _, _ in _imports(module) if _package(t) in METHOD_PACKAGES]
