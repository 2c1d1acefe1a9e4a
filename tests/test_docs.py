"""The docs build with warnings as errors (``make docs``); the gallery runs what it says."""

import ast
import re
import runpy
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
GENERATED = ("_build", "api", "gallery", "sg_execution_times.rst")  # by a build; git-ignored


def gallery_conf():
    path = sys.path[:]  # conf.py puts docs/ on sys.path, for gallery.py
    try:
        return runpy.run_path(str(DOCS / "conf.py"))["sphinx_gallery_conf"]
    finally:
        sys.path[:] = path


def test_gallery_runs_the_example_scripts_only():
    # bench.py (minutes) and codegen.py (a developer tool) are listed, never executed.
    pattern = re.compile(gallery_conf()["filename_pattern"])
    executed = {p.name for p in (ROOT / "scripts").glob("*.py") if pattern.search(str(p))}
    assert executed == {"simulate_nominal.py", "uncertain_study.py"}
    assert set(runpy.run_path(str(DOCS / "gallery.py"))["ARGV"]) == executed


@pytest.mark.parametrize("script", sorted(p.name for p in (ROOT / "scripts").glob("*.py")))
def test_script_docstring_has_a_gallery_title(script):
    # sphinx-gallery takes the page title from an underlined first line of the docstring.
    doc = ast.get_docstring(ast.parse((ROOT / "scripts" / script).read_text()))
    title, underline = doc.splitlines()[:2]
    assert underline == "=" * len(title)


@pytest.mark.slow  # about 2 min on 2 shared cores (imports every module, runs two scripts)
def test_docs_build_without_warnings(tmp_path):
    for mod in ("sphinx", "numpydoc", "sphinx_gallery", "myst_parser"):
        pytest.importorskip(mod, reason="the docs extra: pip install '.[docs]'")
    # A copy of what the build reads, so that it writes no generated page into this tree.
    src = tmp_path / "src"
    shutil.copytree(DOCS, src / "docs", ignore=lambda d, names: [
        n for n in names if Path(d) == DOCS and n in GENERATED])
    shutil.copytree(ROOT / "scripts", src / "scripts")
    shutil.copy(ROOT / "README.md", src / "README.md")
    html = tmp_path / "html"
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b",
                           "html", str(src / "docs"), str(html)],
                          capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr
    # One API page per module of the package (autosummary, recursive).
    modules = {".".join(p.relative_to(ROOT / "src").with_suffix("").parts).removesuffix(".__init__")
               for p in (ROOT / "src" / "rrr_pin").rglob("*.py")}
    pages = {p.stem for p in (html / "api").glob("rrr_pin*.html")}
    assert modules == pages
    # The executed scripts' figures are on their pages; the others are listed.
    for name in ("simulate_nominal", "uncertain_study"):
        assert (html / "_images" / f"sphx_glr_{name}_001.png").stat().st_size > 10_000
    for name in ("bench", "codegen"):
        assert (html / "gallery" / f"{name}.html").exists()
    assert "Quick start" in (html / "readme.html").read_text()
    # every page of the guide is built and reachable from its index (the glob toctree)
    index = (html / "guide" / "index.html").read_text()
    for page in (DOCS / "guide").glob("*.md"):
        assert (html / "guide" / f"{page.stem}.html").exists(), page.name
        assert page.stem == "index" or f'href="{page.stem}.html"' in index, page.name
    assert (html / "figures.html").exists()
