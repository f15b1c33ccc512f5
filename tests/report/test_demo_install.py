"""`make demo` installs what the demo needs and no more: the package's base dependencies, without
the `test` and `fit` extras (torch); `make test` adds both extras. Read from the Makefile and
pyproject.toml, and from the imports of the package's source (function-level imports included)."""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

try:
    import tomllib
except ImportError:  # Python 3.10
    tomllib = None

import pytest

REPO = Path(__file__).resolve().parents[2]
SRC = REPO / "src"
#: Import name -> distribution, where they differ (llvmlite is numba's own dependency).
DISTRIBUTION = {"PIL": "pillow", "flip_evaluator": "flip-evaluator", "llvmlite": "numba",
                "distributed": "dask"}
#: Third-party modules only the `fit` extra provides, and the one file that imports each.
FIT_ONLY = {"torch": "prefilter.ltc.aniso.fit"}


def _targets(makefile: str) -> dict[str, tuple[list[str], list[str]]]:
    """target -> (prerequisites, recipe lines), variables left unexpanded."""
    out, current = {}, None
    for line in makefile.splitlines():
        if line.startswith("\t") and current is not None:
            out[current][1].append(line.strip())
            continue
        m = re.match(r"^([^\s:=#]+)\s*:(?!=)\s*(.*)$", line)
        current = None
        if m and not m.group(1).startswith("."):
            current = m.group(1)
            out[current] = (m.group(2).split(), [])
    return out


def _base_dependencies() -> set[str]:
    if tomllib is None:
        pytest.skip("tomllib needs Python >= 3.11")
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    return {re.split(r"[<>=!~\[ ;]", d, 1)[0].lower() for d in project["dependencies"]}


def _installs(targets, name) -> str:
    """Every recipe line that ``name`` runs through its stamp prerequisites, as one string."""
    prereqs, recipe = targets[name]
    lines = list(recipe)
    for p in prereqs:
        if p in targets:
            lines.append(_installs(targets, p))
    return "\n".join(lines)


def test_make_demo_installs_no_extras_and_make_test_adds_them():
    targets = _targets((REPO / "Makefile").read_text())
    demo = _installs(targets, "demo")
    assert "pip install -q -e ." in demo
    assert "torch" not in demo and "[" not in demo, demo
    test = _installs(targets, "test")
    assert "pip install -q torch==2.13.0" in test and "-e '.[test,fit]'" in test
    stamps = [p for p in targets["test"][0] if p in targets]
    assert any(p in targets and "$(DEMO_STAMP)" in targets[p][0] for p in stamps)


def _module_files() -> dict[str, Path]:
    mods = {}
    for path in SRC.rglob("*.py"):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


def _imports(path: Path, package: str) -> set[str]:
    """Absolute names of every module imported anywhere in ``path``."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1]
                                + ([node.module] if node.module else []))
            out.add(base)
            out |= {f"{base}.{a.name}" for a in node.names}
    return out


def _graph():
    mods = _module_files()
    graph = {}
    for name, path in mods.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        graph[name] = _imports(path, package)
    return mods, graph


def _third_party(name: str) -> str | None:
    top = name.split(".")[0]
    if not top or top == "prefilter" or top in sys.stdlib_module_names or top == "tomllib":
        return None
    return top


def test_every_third_party_import_is_a_base_dependency():
    base = _base_dependencies()
    _, graph = _graph()
    used = {t: m for m, imps in graph.items() for i in imps if (t := _third_party(i))}
    missing = {t: m for t, m in used.items()
               if t not in FIT_ONLY and DISTRIBUTION.get(t, t).lower() not in base}
    assert not missing, f"imported but not in [project] dependencies: {missing}"
    for t, module in FIT_ONLY.items():
        users = {m for m, imps in graph.items() if any(_third_party(i) == t for i in imps)}
        assert users == {module}, users


def test_the_demo_never_reaches_the_fit_extra():
    """No chain of imports from the demo (or the CLI's top level) leads to torch."""
    mods, graph = _graph()
    seen, todo = set(), ["prefilter.report.demo", "prefilter.cli", "prefilter.examples.commands"]
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        parents = [m.rsplit(".", k)[0] for k in range(1, m.count("."))]  # run their __init__
        for i in list(graph[m]) + parents:
            while i and i not in mods:
                i = i.rpartition(".")[0]
            if i:
                todo.append(i)
    assert not seen & set(FIT_ONLY.values()), sorted(seen & set(FIT_ONLY.values()))
