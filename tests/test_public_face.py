"""Every ``rrr_pin`` name the README, the docs, the scripts and the docstrings use resolves.

Extracted from the text: dotted names ``rrr_pin.a.b`` (a module path, then attributes), and
``from rrr_pin... import x, y`` lines (each imported name must exist). The package's lazy
top-level names (``rrr_pin.X``) are checked the same way, so a name the README advertises and
the package lacks fails here.
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

import rrr_pin

ROOT = Path(__file__).resolve().parents[1]
TEXTS = sorted([ROOT / "README.md", *ROOT.glob("docs/*.md"), *ROOT.glob("docs/guide/*.md"),
                *ROOT.glob("scripts/*.py"),
                *(ROOT / "src" / "rrr_pin").rglob("*.py")])

DOTTED = re.compile(r"(?<![\w.])rrr_pin(?:\.[A-Za-z_]\w*)+")
FROM = re.compile(r"^\s*from (rrr_pin(?:\.\w+)*) import \(?([\w, \n]+?)\)?\s*$", re.M)


def resolve(dotted: str) -> bool:
    """Import the longest module prefix of ``dotted``, then follow the rest as attributes."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        try:
            for attr in parts[k:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return False
        return True
    return False


def _names():
    out = set()
    for path in TEXTS:
        text = path.read_text()
        rel = path.relative_to(ROOT).as_posix()
        for m in DOTTED.finditer(text):
            name = m.group(0).rstrip(".")
            if name.endswith((".py", ".so")) or "rrr_pin._ext" in name:
                continue  # file names, not Python names
            out.add((rel, name))
        for m in FROM.finditer(text):
            for item in m.group(2).replace("\n", " ").split(","):
                item = item.strip().split(" as ")[0].strip()
                if item:
                    out.add((rel, f"{m.group(1)}.{item}"))
    return sorted(out)


NAMES = _names()


def test_texts_name_many_things():
    # the extraction itself works: the README and the guide name dozens of rrr_pin objects
    assert sum(1 for rel, _ in NAMES if rel == "README.md") > 5
    assert sum(1 for rel, _ in NAMES if rel.startswith("docs/guide/")) > 20


@pytest.mark.parametrize("where, name", NAMES, ids=[f"{w}:{n}" for w, n in NAMES])
def test_name_resolves(where, name):
    assert resolve(name), f"{where} names {name}, which does not resolve"


def test_all_lists_only_real_names():
    missing = [n for n in rrr_pin.__all__ if not hasattr(rrr_pin, n)]
    assert missing == []


def test_version_is_the_package_version():
    from importlib.metadata import version

    assert rrr_pin.__version__ == version("rrr-pin")


def _defined_and_all(path: Path):
    import ast

    defined, listed = set(), []
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            defined.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                for name in ([t] if isinstance(t, ast.Name) else getattr(t, "elts", [])):
                    if isinstance(name, ast.Name):
                        defined.add(name.id)
                        if name.id == "__all__":
                            listed = [e.value for e in node.value.elts]
    return defined, listed


MODULES = sorted(p for p in (ROOT / "src" / "rrr_pin").rglob("*.py") if p.name != "__init__.py")


@pytest.mark.parametrize("path", MODULES, ids=[p.relative_to(ROOT).as_posix() for p in MODULES])
def test_no_module_reexports_a_siblings_names(path):
    # a module's __all__ names only what it defines; a name's home is the module defining it
    defined, listed = _defined_and_all(path)
    assert [n for n in listed if n not in defined] == []


def test_dir_lists_only_the_public_names():
    # issue 50: dir(rrr_pin) showed the module's own imports (annotations, importlib)
    assert dir(rrr_pin) == sorted(rrr_pin.__all__)
    assert not {"annotations", "importlib"} & set(dir(rrr_pin))
    assert all(not n.startswith("_") for n in dir(rrr_pin) if n != "__version__")


def test_design_files_and_tuned_laws_at_the_top_level(tmp_path, rrr):
    # issue 50: a tuned law is rrr_pin.tuned_law(rrr_pin.load_design(path), robot)
    import json

    from rrr_pin.campaign.design_file import DESIGN_FORMAT

    path = tmp_path / "design.json"
    path.write_text(json.dumps({"format": DESIGN_FORMAT, "robot": rrr.name,
                                "joints": list(rrr.joint_names), "lam_rad_s": 30.0,
                                "K": None}))
    law = rrr_pin.tuned_law(rrr_pin.load_design(path), rrr)
    assert law.name == "tuned" and law.lam == 30.0
    with pytest.raises(ValueError, match="not an rrr-pin design"):
        path.write_text('{"format": "other"}')
        rrr_pin.load_design(path)


def test_campaign_summary_is_a_method():
    # Campaign.summary() is campaign_summary(campaign); a hand-made campaign of three plants
    from rrr_pin.campaign.montecarlo import campaign_summary

    rows = [{"index": k, "seed": [0, k], "status": "ok", "parameters": {}, "fl_rms_error": e,
             "fl_max_error": e, "fl_rms_torque": 1.0} for k, e in enumerate([1.0, 3.0, 2.0])]
    camp = rrr_pin.Campaign(robot="rrr", joint_names=["j1"], laws=[{"name": "fl", "label": "FL"}],
                            rows=rows, settings={"baseline": "fl"})
    assert camp.summary() == campaign_summary(camp)
    # the median and the worst of 1, 3, 2 by hand
    assert camp.summary()["fl_rms_error"]["median"] == 2.0
    assert camp.summary()["fl_rms_error"]["worst"] == 3.0
