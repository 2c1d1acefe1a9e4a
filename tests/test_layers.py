"""The layer contract of the package, checked on its source by AST (imports inside functions too).

Layers, lowest first: validation -> outputs -> model -> robust -> control -> sim -> deploy ->
campaign -> report -> cli. A module may import its own layer and the layers below it, never one
above; no two modules import each other, directly or through others; no module takes a
``_private`` name from a module outside its own subpackage; the study and the Monte Carlo
campaign are siblings (neither imports the other). ``rrr_pin/__init__.py`` is the package's
face: it names every layer's public objects and is exempt.

Run ``python -m pytest tests/test_layers.py`` after moving code; the second half of this file
shows the checker failing on a tree with an upward import, a cycle and a private import.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "rrr_pin"

LAYERS = ("validation", "outputs", "model", "robust", "control", "sim", "deploy", "campaign",
          "report", "cli")

#: Pairs of modules that must not import each other (either way).
INDEPENDENT = (("rrr_pin.campaign.study", "rrr_pin.campaign.montecarlo"),)


def module_name(root: Path, path: Path) -> str:
    rel = path.relative_to(root.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(root: Path) -> dict[str, list[tuple[str, str | None]]]:
    """Map each module of the package to the ``(module, name)`` pairs it imports.

    ``from a.b import c`` gives ``("a.b.c", None)`` if ``a/b/c.py`` exists (a submodule), else
    ``("a.b", "c")``. Relative imports are resolved; imports in function bodies count.
    """
    pkg = root.name
    modules = {module_name(root, p): p for p in root.rglob("*.py")}
    out = {}
    for mod, path in modules.items():
        is_pkg = path.name == "__init__.py"
        here = mod.split(".") if is_pkg else mod.split(".")[:-1]
        found = []
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found += [(a.name, None) for a in node.names if a.name.split(".")[0] == pkg]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here[:len(here) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                if target.split(".")[0] != pkg:
                    continue
                for a in node.names:
                    sub = f"{target}.{a.name}"
                    if sub in modules or (root.parent / sub.replace(".", "/")).is_dir():
                        found.append((sub, None))
                    else:
                        found.append((target, a.name))
        out[mod] = found
    return out


def layer_of(mod: str) -> int | None:
    parts = mod.split(".")
    if len(parts) == 1:
        return None  # the package's __init__: exempt
    head = parts[1]
    return LAYERS.index(head) if head in LAYERS else None


def violations(root: Path) -> list[str]:
    """Every breach of the contract in the package at ``root``, as sentences."""
    graph = imports_of(root)
    known = set(graph)
    problems = []
    for mod, targets in graph.items():
        lo = layer_of(mod)
        for target, name in targets:
            if target not in known and target.rsplit(".", 1)[0] in known:
                target = target.rsplit(".", 1)[0]  # an extension module: its package's layer
            hi = layer_of(target)
            if lo is not None and hi is not None and hi > lo:
                problems.append(f"upward import: {mod} ({LAYERS[lo]}) imports {target} "
                                f"({LAYERS[hi]})")
            if name and name.startswith("_") and not name.startswith("__"):
                if target.split(".")[:2] != mod.split(".")[:2]:
                    problems.append(f"private import: {mod} takes {name} from {target}")
    edges = {m: {t for t, _ in ts if t in known and t != m} for m, ts in graph.items()}
    for m in edges:  # an edge to a package means its __init__
        edges[m] = {t for t in edges[m] if t in graph}
    problems += [f"import cycle: {' -> '.join(c)}" for c in _cycles(edges)]
    for a, b in INDEPENDENT:
        for x, y in ((a, b), (b, a)):
            if any(t == y for t, _ in graph.get(x, ())):
                problems.append(f"independence: {x} imports {y}")
    return problems


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """One cycle per strongly connected component with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp) + [sorted(comp)[0]])

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_package_keeps_its_layers():
    assert violations(SRC) == []


def test_every_module_is_in_a_layer():
    names = [m for m in imports_of(SRC) if m != "rrr_pin"]
    assert [m for m in names if layer_of(m) is None] == []


@pytest.mark.parametrize("sub", LAYERS[1:-1])
def test_each_layer_says_what_it_holds(sub):
    # the subpackage's docstring names every module in it, and what the layer may import
    doc = importlib.import_module(f"rrr_pin.{sub}").__doc__
    modules = sorted(p.stem for p in (SRC / sub).glob("*.py") if p.stem != "__init__")
    assert [m for m in modules if f"rrr_pin.{sub}.{m}" not in doc] == []
    assert "Layer:" in doc


# --- the checker itself, on a small tree --------------------------------------------------------

def _tree(tmp_path, files: dict[str, str]) -> Path:
    root = tmp_path / "rrr_pin"
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    for d in [root, *[p for p in root.rglob("*") if p.is_dir()]]:
        (d / "__init__.py").touch()
    return root


def test_checker_passes_a_clean_tree(tmp_path):
    root = _tree(tmp_path, {"model/a.py": "X = 1\n",
                            "sim/b.py": "from ..model.a import X\n",
                            "cli.py": "def f():\n    from .sim import b\n"})
    assert violations(root) == []


@pytest.mark.parametrize("files, expected", [
    ({"model/a.py": "def f():\n    from ..sim.b import Y\n", "sim/b.py": "Y = 1\n"},
     "upward import: rrr_pin.model.a (model) imports rrr_pin.sim.b (sim)"),
    ({"sim/a.py": "from . import b\n", "sim/b.py": "def f():\n    from .a import g\n"},
     "import cycle: rrr_pin.sim.a -> rrr_pin.sim.b -> rrr_pin.sim.a"),
    ({"model/a.py": "_h = 1\n", "sim/b.py": "from ..model.a import _h\n"},
     "private import: rrr_pin.sim.b takes _h from rrr_pin.model.a"),
    ({"campaign/study.py": "X = 1\n", "campaign/montecarlo.py": "from .study import X\n"},
     "independence: rrr_pin.campaign.montecarlo imports rrr_pin.campaign.study"),
], ids=["upward", "cycle", "private", "siblings"])
def test_checker_catches(tmp_path, files, expected):
    assert expected in violations(_tree(tmp_path, files))
