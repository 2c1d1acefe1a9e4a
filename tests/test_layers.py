"""The layer contract of the package, checked on its source by AST (imports inside functions too).

Layers, lowest first: validation -> outputs -> model -> robust -> control -> sim -> deploy ->
campaign -> report -> cli. A module may import its own layer and the layers below it, never one
above; no two modules import each other, directly or through others; no module takes a
``_private`` name from a module outside its own subpackage; the study and the Monte Carlo
campaign are siblings (neither imports the other). ``rrr_pin/__init__.py`` is the package's
face: it names every layer's public objects and is exempt.

One house for every kind of plant: no module outside ``rrr_pin/model/`` names a mechanism (a
string holding ``"fivebar"``, ``"delta"``, ... of the registry, or an import of a kind's module
or of a name it defines, ``FiveBarParams``, ``delta_fk``) or switches on the plant's kind
(``isinstance(p, ClosedChain)``, ``type(p) is Robot``, ``is_closed_chain...``); and nowhere in
the package is a capability sniffed with ``hasattr(..., "constraints")``.

Run ``python -m pytest tests/test_layers.py`` after moving code; the second half of this file
shows the checkers failing on trees with an upward import, a cycle, a private import, a named
mechanism, a kind switch and a sniffed capability.
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


# --- one house: no layer above model/ knows which kind of plant it has -------------------------

#: Calls and names that switch on the kind of plant: ``isinstance(p, ClosedChain)``,
#: ``type(p) is Robot``, ``is_closed_chain_source(p)``. A kind's capabilities are declared
#: (``plant.capabilities``, ``plant.require``), never sniffed.
KIND_CLASSES = ("ClosedChain", "Robot")


def mechanism_kinds() -> dict[str, Path]:
    """Every registered mechanism by name, with the file of its module (the registry's)."""
    import inspect

    from rrr_pin.model.mechanisms import MECHANISMS

    return {name: Path(inspect.getfile(type(m))) for name, m in MECHANISMS.items()}


def _top_level_names(path: Path) -> set[str]:
    """Names a module defines at its top level (functions, classes, assignments)."""
    names = set()
    for node in ast.parse(path.read_text(), str(path)).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            for target in node.targets if isinstance(node, ast.Assign) else [node.target]:
                names |= {n.id for n in ast.walk(target) if isinstance(n, ast.Name)}
    return names


def _docstrings(tree: ast.AST) -> set[int]:
    """``id`` of every docstring node (module, class, function): prose, not code."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                    and isinstance(body[0].value.value, str):
                out.add(id(body[0].value))
    return out


def _names_a_kind_class(node: ast.AST) -> str | None:
    """The kind class (``ClosedChain``, ``Robot``) an expression names, if any."""
    for n in ast.walk(node):
        name = n.id if isinstance(n, ast.Name) else n.attr if isinstance(n, ast.Attribute) \
            else None
        if name in KIND_CLASSES:
            return name
    return None


def kind_violations(root: Path, kinds: dict[str, Path]) -> list[str]:
    """Where a module outside ``model/`` names a mechanism or switches on the plant's kind.

    ``kinds`` maps each mechanism's name to its module's file (:func:`mechanism_kinds`). A
    module breaks the rule with a string (not a docstring) holding a mechanism's name as a
    word, an import of a kind's module or of a name it defines (``FiveBarParams``,
    ``delta_fk``, ...), an ``isinstance``/``issubclass``/``type(...) is`` test against
    ``ClosedChain`` or ``Robot``, or a name starting with ``is_closed_chain``. Anywhere in the
    package: ``hasattr(..., "constraints")``.
    """
    import re

    pkg = root.name
    word = re.compile(r"\b(" + "|".join(map(re.escape, kinds)) + r")\b")
    kind_modules = {f"{pkg}.model.mechanisms.{Path(p).stem}" for p in kinds.values()}
    specific = set().union(*(_top_level_names(Path(p)) for p in kinds.values())) if kinds \
        else set()
    problems = []
    for path in sorted(root.rglob("*.py")):
        mod = module_name(root, path)
        tree = ast.parse(path.read_text(), str(path))
        above_model = mod.split(".")[1:2] != ["model"]
        prose = _docstrings(tree)
        for node in ast.walk(tree):
            where = f"{mod}:{getattr(node, 'lineno', '?')}"
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                    and node.func.id == "hasattr" and len(node.args) == 2 \
                    and isinstance(node.args[1], ast.Constant) \
                    and node.args[1].value == "constraints":
                problems.append(f"capability sniffed: {where} hasattr(..., 'constraints')")
            if not above_model:
                continue
            if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                    and id(node) not in prose and word.search(node.value):
                problems.append(f"mechanism named: {where} "
                                f"{word.search(node.value).group(1)!r} in a string")
            elif isinstance(node, ast.ImportFrom):
                here = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
                base = here[:len(here) - node.level + 1] if node.level else []
                target = ".".join(base + ([node.module] if node.module else []))
                for a in node.names:
                    if target in kind_modules or f"{target}.{a.name}" in kind_modules or (
                            target.startswith(f"{pkg}.model.mechanisms")
                            and a.name in specific):
                        problems.append(f"mechanism named: {where} imports {a.name} from "
                                        f"{target}")
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name in kind_modules:
                        problems.append(f"mechanism named: {where} imports {a.name}")
            elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                    and node.func.id in ("isinstance", "issubclass") and len(node.args) == 2 \
                    and _names_a_kind_class(node.args[1]):
                problems.append(f"kind switch: {where} {node.func.id}(..., "
                                f"{_names_a_kind_class(node.args[1])})")
            elif isinstance(node, ast.Compare) and isinstance(node.left, ast.Call) \
                    and isinstance(node.left.func, ast.Name) and node.left.func.id == "type" \
                    and any(_names_a_kind_class(c) for c in node.comparators):
                problems.append(f"kind switch: {where} type(...) compared with "
                                f"{next(filter(None, map(_names_a_kind_class, node.comparators)))}")
            name = node.id if isinstance(node, ast.Name) else node.attr \
                if isinstance(node, ast.Attribute) else node.name \
                if isinstance(node, ast.alias) else None
            if name and name.split(".")[-1].startswith("is_closed_chain"):
                problems.append(f"kind switch: {where} {name.split('.')[-1]}")
    return problems


@pytest.fixture(scope="module")
def package_kind_violations():
    """:func:`kind_violations` of the package (one scan for both rules)."""
    return kind_violations(SRC, mechanism_kinds())


def test_no_layer_above_the_model_names_a_mechanism_or_switches_on_the_kind(
        package_kind_violations):
    assert [p for p in package_kind_violations if not p.startswith("capability sniffed")] == []


def test_no_capability_is_sniffed(package_kind_violations):
    assert [p for p in package_kind_violations if p.startswith("capability sniffed")] == []


def _kinds_of(root: Path) -> dict[str, Path]:
    return {p.stem: p for p in (root / "model" / "mechanisms").glob("*.py")
            if p.stem not in ("__init__", "base")}


_FIVEBAR = 'class FiveBarParams:\n    name = "fivebar"\n\n\ndef fivebar_fk(p, q):\n    return q\n'


def test_kind_checker_passes_a_clean_tree(tmp_path):
    root = _tree(tmp_path, {
        "model/mechanisms/fivebar.py": _FIVEBAR,
        "model/closed_chain.py": "def load(p):\n    return isinstance(p, ClosedChain)\n",
        "sim/a.py": '"""Runs any plant (the fivebar too)."""\n\n\ndef f(plant):\n'
                    '    plant.require("frames", "circle")\n',
        "campaign/b.py": "from ..model.mechanisms import MECHANISMS, mechanism_of\n"})
    assert kind_violations(root, _kinds_of(root)) == []


@pytest.mark.parametrize("files, expected", [
    ({"sim/a.py": 'def f(plant):\n    return plant.name == "fivebar"\n'},
     "mechanism named: rrr_pin.sim.a:2 'fivebar' in a string"),
    ({"report/a.py": 'HELP = "a mechanism (delta, ...)"\n'},
     "mechanism named: rrr_pin.report.a:1 'delta' in a string"),
    ({"campaign/a.py": "from ..model.mechanisms import FiveBarParams\n"},
     "mechanism named: rrr_pin.campaign.a:1 imports FiveBarParams from "
     "rrr_pin.model.mechanisms"),
    ({"report/a.py": "def f():\n    from rrr_pin.model.mechanisms.fivebar import fivebar_fk\n"},
     "mechanism named: rrr_pin.report.a:2 imports fivebar_fk from "
     "rrr_pin.model.mechanisms.fivebar"),
    ({"sim/a.py": "def f(p):\n    return isinstance(p, (int, closed_chain.ClosedChain))\n"},
     "kind switch: rrr_pin.sim.a:2 isinstance(..., ClosedChain)"),
    ({"cli/a.py": "def f(p):\n    return type(p) is Robot\n"},
     "kind switch: rrr_pin.cli.a:2 type(...) compared with Robot"),
    ({"control/a.py": "def f(p):\n    return is_closed_chain_source(p)\n"},
     "kind switch: rrr_pin.control.a:2 is_closed_chain_source"),
    ({"model/a.py": 'def f(p):\n    return hasattr(p, "constraints")\n'},
     "capability sniffed: rrr_pin.model.a:2 hasattr(..., 'constraints')"),
], ids=["string", "help-text", "params", "kind-module", "isinstance", "type-is",
        "is-closed-chain", "hasattr"])
def test_kind_checker_catches(tmp_path, files, expected):
    root = _tree(tmp_path, {"model/mechanisms/fivebar.py": _FIVEBAR,
                            "model/mechanisms/delta.py": "class DeltaParams:\n    pass\n",
                            **files})
    assert expected in kind_violations(root, _kinds_of(root))
