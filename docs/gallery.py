"""Settings of the sphinx-gallery run (docs/conf.py names these functions by qualified name).

The scripts write their figure with ``savefig`` and close it, so the matplotlib scraper finds
nothing; :func:`png_scraper` shows the PNG that ``--out`` named instead.
"""

import shutil
from pathlib import Path

#: Arguments of each executed script in the gallery: the scripts' own defaults, except fewer
#: uncertain plants and one worker process, so the whole gallery runs in seconds.
ARGV = {
    "simulate_nominal.py": ["--controllers", "fl,hinf,pd"],
    "uncertain_study.py": ["--samples", "4", "--jobs", "1"],
}


def _out(target_file: str) -> Path:
    """Where the script writes its PNG: beside its copy in the gallery's output folder."""
    target = Path(target_file)
    return target.with_name(f"{target.stem}_out.png")


def reset_argv(gallery_conf, script_vars):
    """Command-line arguments of one gallery script (sphinx-gallery's ``reset_argv``)."""
    name = Path(script_vars["src_file"]).name
    return [*ARGV.get(name, []), "--out", str(_out(script_vars["target_file"]))]


def png_scraper(block, block_vars, gallery_conf):
    """Show the PNG the script wrote through ``--out`` (a sphinx-gallery image scraper)."""
    from sphinx_gallery.scrapers import figure_rst

    src = _out(block_vars["target_file"])
    if not src.exists():
        return ""
    dest = Path(next(block_vars["image_path_iterator"]))
    shutil.move(src, dest)
    return figure_rst([str(dest)], gallery_conf["src_dir"])


class ExamplesFirst:
    """Gallery order (``within_subsection_order``): the executed scripts, then the others."""

    def __init__(self, src_dir):
        self.src_dir = src_dir

    def __call__(self, filename):
        """Sort key of one script's file name: ARGV's order, then by name."""
        names = list(ARGV)
        return (names.index(filename), "") if filename in ARGV else (len(names), filename)
