"""One self-contained ``report.html``: tables, figures, the design summary and 3D scenes.

The page needs no server and no network: PNG (and JPEG, SVG) figures are inlined as base64
``data:`` URIs, tables are given as Markdown (rendered by markdown-it-py, raw HTML in it
escaped) or as HTML, and each :class:`rrr_pin.report.viewer.Scene` becomes an animated MeshCat
viewer (:func:`rrr_pin.report.viewer.scene_html`). The whole file is kept under a byte budget by
decimating the scenes' frames.
"""

from __future__ import annotations

import base64
import html
import math
import numbers
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..outputs import OutputNotWritable, check_writable
from .viewer import Scene, ViewerSizeError, scene_html

__all__ = ["write_report_html", "report_html", "REPORT_MAX_BYTES"]

#: Byte budget of a whole report [bytes] (the issue's bound for 10 s at 30 frames/s with
#: 11 arms).
REPORT_MAX_BYTES = 20_000_000

_MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg",
         ".svg": "image/svg+xml", ".gif": "image/gif"}

_STYLE = """
body {font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 0 auto;
      max-width: 1100px; padding: 1em 2em; color: #222; line-height: 1.45;}
h1 {font-size: 1.6em; border-bottom: 2px solid #ddd; padding-bottom: 0.2em;}
h2 {font-size: 1.3em; margin-top: 1.6em;}
table {border-collapse: collapse; margin: 0.6em 0; font-size: 0.92em;}
th, td {border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; vertical-align: top;}
th {background: #f2f2f4;}
td.num {text-align: right; font-variant-numeric: tabular-nums;}
figure {margin: 1em 0;}
figure img {max-width: 100%; border: 1px solid #eee;}
figcaption {font-size: 0.9em; color: #444; margin: 0.3em 0;}
code {background: #f4f4f6; padding: 0 0.2em;}
nav a {margin-right: 1em;}
"""


def _markdown(text: str, shift: int = 0) -> str:
    """Render Markdown, its headings ``shift`` levels down (``#`` becomes ``h{1 + shift}``)."""
    from markdown_it import MarkdownIt

    md = MarkdownIt("commonmark", {"html": False}).enable("table")
    md.disable("image")  # a Markdown image would be a file or network reference
    tokens = md.parse(text)
    for token in tokens:
        if token.type in ("heading_open", "heading_close"):
            token.tag = f"h{min(6, int(token.tag[1:]) + shift)}"
    return md.renderer.render(tokens, md.options, {})


def _table_html(content: str) -> str:
    """HTML of a table given as HTML (starts with ``<``) or as Markdown (headings under h3)."""
    return content if content.lstrip().startswith("<") else _markdown(content, shift=3)


def _figure_html(entry) -> str:
    """HTML of a figure given as a path or a ``(path, caption)`` pair (default: file name)."""
    path, caption = ((entry[0], entry[1]) if isinstance(entry, tuple) else (entry, None))
    path = Path(path)
    caption = path.name if caption is None else caption
    mime = _MIME.get(path.suffix.lower())
    if mime is None:
        raise ValueError(f"figure {str(path)!r}: expected one of {', '.join(sorted(_MIME))}, "
                         f"got {path.suffix!r}")
    if not path.is_file():
        raise FileNotFoundError(f"figure not found: {path}")
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (f'<figure><img alt="{html.escape(caption, quote=True)}" '
            f'src="data:{mime};base64,{data}"><figcaption>{html.escape(caption)}'
            f"</figcaption></figure>")


def _number(x) -> str:
    if isinstance(x, bool | np.bool_):
        return "yes" if x else "no"
    if isinstance(x, numbers.Integral):
        return str(int(x))
    x = float(x)
    if math.isnan(x):
        return "NaN"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.6g}"


#: Units by key suffix, the convention of the project's JSON (``duration_s``, ``rate_hz``);
#: longest suffixes first.
_SUFFIX_UNITS = (("_rad_s", "rad/s"), ("_n_m", "N m"), ("_hz", "Hz"), ("_db", "dB"),
                 ("_rad", "rad"), ("_s", "s"), ("_m", "m"))


def _unit(key, value, units: Mapping) -> str:
    """Return the unit of a key-value row: ``units[key]``, else its suffix's, else empty."""
    if isinstance(value, Mapping):
        return ""
    key = str(key)
    if key in units:
        return units[key]
    return next((u for suffix, u in _SUFFIX_UNITS if key.lower().endswith(suffix)), "")


def _value_html(value, units: Mapping | None = None) -> str:
    """Readable HTML of any JSON-like value: nested mappings as tables, numbers to 6 digits.

    A mapping is a table of key, value and unit (``units[key]``, else the key's suffix).
    """
    units = {} if units is None else units
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, Mapping):
        if not value:
            return "<i>(empty)</i>"
        rows = "".join(f"<tr><th>{html.escape(str(k))}</th><td>{_value_html(v, units)}</td>"
                       f"<td>{html.escape(_unit(k, v, units))}</td></tr>"
                       for k, v in value.items())
        return f"<table><tr><th>quantity</th><th>value</th><th>unit</th></tr>{rows}</table>"
    if isinstance(value, str):
        return html.escape(value)
    if value is None:
        return "-"
    if isinstance(value, numbers.Number | np.bool_):
        return _number(value)
    if isinstance(value, Sequence | set):
        items = list(value)
        if all(isinstance(v, numbers.Number | np.bool_) for v in items):
            shown = ", ".join(_number(v) for v in items[:24])
            more = f", ... ({len(items)} values)" if len(items) > 24 else ""
            return f"<code>[{shown}{more}]</code>"
        return "<ol>" + "".join(f"<li>{_value_html(v, units)}</li>" for v in items) + \
            "</ol>"
    return html.escape(str(value))


def _page(title: str, sections: list[tuple[str, str, str]]) -> str:
    nav = "".join(f'<a href="#{anchor}">{html.escape(name)}</a>'
                  for anchor, name, _ in sections)
    body = "".join(f'<section id="{anchor}"><h2>{html.escape(name)}</h2>{content}</section>'
                   for anchor, name, content in sections)
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head>\n<body>"
            f"<h1>{html.escape(title)}</h1><nav>{nav}</nav>{body}</body>\n</html>\n")


def report_html(*, title: str, tables: Sequence[tuple[str, str]] = (),
                figures: Sequence = (), design: Mapping | None = None,
                scenes: Sequence[Scene] = (), max_bytes: int = REPORT_MAX_BYTES,
                fps: float = 30.0, units: Mapping | None = None,
                design_title: str = "Design") -> str:
    """Build the report page as a string; see :func:`write_report_html`."""
    if isinstance(max_bytes, bool) or not (isinstance(max_bytes, numbers.Integral)
                                           and max_bytes > 0):
        raise ValueError(f"max_bytes must be an integer > 0, got {max_bytes!r}")
    if design is not None and not isinstance(design, Mapping):
        raise TypeError(f"design must be a dict or None, got {type(design).__name__}")
    sections = []
    if tables:
        parts = []
        for k, entry in enumerate(tables):
            if not (isinstance(entry, Sequence) and len(entry) == 2
                    and all(isinstance(e, str) for e in entry)):
                raise TypeError(f"tables[{k}] must be a (caption, markdown_or_html) pair of "
                                f"strings, got {entry!r:.80}")
            caption, content = entry
            parts.append(f"<h3>{html.escape(caption)}</h3>{_table_html(content)}")
        sections.append(("results", "Results", "".join(parts)))
    if design is not None:
        sections.append(("design", design_title, _value_html(design, units)))
    if figures:
        sections.append(("figures", "Figures", "".join(_figure_html(f) for f in figures)))
    scenes = list(scenes)
    if scenes:
        for k, scene in enumerate(scenes):
            if not isinstance(scene, Scene):
                raise TypeError(f"scenes[{k}] must be a rrr_pin.report.viewer.Scene, got "
                                f"{type(scene).__name__}")
        fixed = len(_page(title, sections + [("scenes", "3D animation", "")]).encode("utf-8"))
        room = max_bytes - fixed - 2000 * len(scenes)  # 2000: section and legend markup
        if room <= 0:
            raise ValueError(f"max_bytes={max_bytes} leaves no room for the scenes: the tables "
                             f"and figures alone take {fixed} bytes")
        per_scene = room // len(scenes)
        note = ("<p>Each scene: the nominal plant opaque, the uncertain plants as translucent "
                "ghosts. Open Controls &gt; Animations: play, pause, reset and a time slider; "
                "drag to orbit, right-drag to pan, scroll to zoom.</p>")
        sections.append(("scenes", "3D animation", note + "".join(
            _scene_or_note(scene, fps, per_scene) for scene in scenes)))
    return _page(title, sections)


def _scene_or_note(scene: Scene, fps: float, max_bytes: int) -> str:
    """Return the scene's fragment, or a paragraph saying why it is not drawn."""
    try:
        return scene_html(scene, fps=fps, max_bytes=max_bytes)
    except ViewerSizeError as exc:
        return (f"<p><b>{html.escape(scene.title)}</b>: not drawn, as even one arm exceeds "
                f"the page's size budget ({html.escape(str(exc))}).</p>")


def write_report_html(path, *, title: str, tables: Sequence[tuple[str, str]] = (),
                      figures: Sequence = (), design: Mapping | None = None,
                      scenes: Sequence[Scene] = (), max_bytes: int = REPORT_MAX_BYTES,
                      fps: float = 30.0, units: Mapping | None = None,
                      design_title: str = "Design") -> Path:
    """Write one self-contained HTML report.

    Parameters
    ----------
    path : path-like
        The file to write (e.g. ``results/report.html``); parent folders are created.
    title : str
        Page title.
    tables : sequence of (str, str)
        ``(caption, content)`` pairs, each caption an ``h3`` heading; ``content`` is Markdown
        (pipe tables, headings, lists; raw HTML in it is escaped; its headings are moved
        three levels down, ``#`` to ``h4``, so the page keeps one heading hierarchy) or, when
        it starts with ``<``, HTML inserted as is.
    figures : sequence of path-like or (path-like, str)
        Image files (PNG, JPEG, GIF, SVG), inlined as base64 ``data:`` URIs, each with its
        caption (default: the file name).
    design : dict, optional
        Design summary (e.g. gamma, K, margins): any JSON-like mapping, shown as nested
        tables of quantity, value (numbers to 6 significant digits) and unit.
    scenes : sequence of rrr_pin.report.viewer.Scene
        3D animations, e.g. one per controller; each is rendered with
        :func:`rrr_pin.report.viewer.scene_html`, the byte budget left by the rest of the page
        shared equally between them. A scene too large for its share draws its first tracks
        only, or none, and says so on the page: the page is always written.
    max_bytes : int, default :data:`REPORT_MAX_BYTES`
        Byte budget of the file [bytes]; the scenes' frames are decimated to fit.
    fps : float, default 30
        Frames per second of the animations before decimation [1/s].
    units : dict, optional
        Unit of each ``design`` key (``"-"``: dimensionless); a key not in it takes the unit
        of its suffix (``_s``, ``_hz``, ``_rad``, ``_rad_s``, ``_db``, ``_m``, ``_n_m``), else
        none.
    design_title : str, default "Design"
        Heading of the ``design`` section (e.g. "Settings").

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    FileNotFoundError
        A figure file is missing.
    OutputNotWritable (a ValueError)
        The file cannot be written.
    """
    text = report_html(title=title, tables=tables, figures=figures, design=design,
                       scenes=scenes, max_bytes=max_bytes, fps=fps, units=units,
                       design_title=design_title)
    path = Path(path)
    check_writable(path.parent)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except OSError as exc:  # a full disk: no half page, no temporary file left
        tmp.unlink(missing_ok=True)
        raise OutputNotWritable(f"cannot write {str(path)!r}: "
                                     f"{exc.strerror or exc}") from None
    return path
