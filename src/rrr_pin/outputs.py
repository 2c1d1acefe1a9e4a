"""Output folders: one run of one tool per folder, claimed before any work, written in full.

Every command that writes a folder of results (``rrr-pin reproduce``, ``stress``,
``design --out``, and any later one such as ``export``) claims it with :meth:`OutputDir.claim`
before it computes anything. The rule:

* the folder must be writable: not a file, creatable, and a probe file can be made in it
  (:func:`check_writable`), so ``--out /proc/x`` or ``--out some_file`` is refused at once;
* an empty (or new) folder is claimed as is;
* a folder holding a previous run of the *same* tool and part (its manifest says so) is
  refused unless ``overwrite``; with ``overwrite``, exactly the files that manifest lists are
  removed (then the folders they leave empty), and nothing else;
* runs of the same tool with other *parts* share a folder: ``rrr-pin stress --effect delay``
  and ``--effect actuator`` both write ``results/stress`` (part = the effect), each with its
  own manifest and files; neither counts or touches the other's;
* a folder holding a run of *another* tool (another tool's manifest, or a Monte Carlo
  campaign's ``campaign.json``, see :mod:`rrr_pin.campaign.store`) is refused even with
  ``overwrite``: its files would sit beside the new ones, or be lost;
* a folder holding files no manifest lists is refused unless ``overwrite``; with
  ``overwrite`` they are kept, untouched, and never listed as this run's;
* a sub-folder that holds a run of its own (``results/montecarlo`` inside ``results``) is a
  separate run: it does not make the folder non-empty and is never touched.

The manifest ``out/rrr-pin-run.json`` (``out/rrr-pin-run-<part>.json`` for a part)::

    {"format": "rrr-pin-run", "version": 1, "tool": "reproduce", "part": null,
     "settings": {...},
     "complete": true, "finished": true, "outputs": ["fig2.png", "plants/rrr_0.urdf", ...],
     "kept": ["notes.txt"]}

It is written when the folder is claimed (``complete`` false, no outputs) and rewritten by
:meth:`OutputDir.close` with every file created or changed since the claim (``complete``
true). ``finished`` says whether the command ended without an error (false: refused or
failed after writing the files listed, which are then partial). ``kept`` lists the files that
were there before the claim. If a run dies before
:meth:`OutputDir.close` (killed, power lost), its manifest stays incomplete, and the next
``overwrite`` removes every file not in ``kept`` nor listed by another run: the dead run's,
which it never listed.

:func:`writing` names the file in an ``OSError`` raised while it is written (a full disk,
``ENOSPC``, raises inside Pillow's or json's ``write`` with no file name).

Layer: base, beside :mod:`rrr_pin.validation`; imports nothing of rrr_pin, so every layer
(the campaign store, the report writers, the CLI) can use it.

Examples
--------
>>> run = OutputDir.claim("results", "reproduce", overwrite=False,
...                       settings={"samples": 10})           # doctest: +SKIP
>>> figure.savefig(run.path / "fig2.png")                     # doctest: +SKIP
>>> run.close()   # the manifest now lists fig2.png            # doctest: +SKIP
"""

from __future__ import annotations

import json
import os
import re
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

__all__ = ["OutputError", "OutputNotWritable", "OutputNotEmpty", "OutputInUse", "OutputDir",
           "RecordedRun", "check_writable", "recorded_runs", "refuse_other_tool", "writing",
           "manifest_name", "MANIFEST", "CAMPAIGN_MANIFEST", "CAMPAIGN_PARTS",
           "CAMPAIGN_FORMAT"]

#: The manifest a claimed folder holds (a part's: ``rrr-pin-run-<part>.json``).
MANIFEST = "rrr-pin-run.json"
#: The Monte Carlo store's manifest (:data:`rrr_pin.campaign.store.MANIFEST`) and its format.
CAMPAIGN_MANIFEST = "campaign.json"
CAMPAIGN_FORMAT = "rrr-pin-campaign"
CAMPAIGN_PARTS = "parts.jsonl"  # a campaign's rows (rrr_pin.campaign.store)
_FORMAT = "rrr-pin-run"
_VERSION = 1
_SHOWN = 3  # files named in a refusal


class OutputError(ValueError):
    """An output folder that cannot take this run (base class)."""


class OutputNotWritable(OutputError):
    """An output folder that is a file, lies under one, or cannot be created or written."""


class OutputNotEmpty(OutputError):
    """A folder holding files, claimed without ``overwrite``."""


class OutputInUse(OutputError):
    """A folder holding another tool's run (refused even with ``overwrite``).

    Attributes
    ----------
    tool : str
        The tool whose run the folder holds (``"montecarlo"``).
    """

    def __init__(self, message: str, tool: str):
        super().__init__(message)
        self.tool = tool


def check_writable(out, option: str = "--out") -> Path:
    """Make sure files can be written into the folder ``out``, before any work is done.

    Creates the folder (and its parents) if needed, then creates and removes a probe file in
    it, so a path that is a file or lies under one, a missing permission and a read-only file
    system are all caught. The one writability check of the package.

    Parameters
    ----------
    out : path-like
        The output folder.
    option : str, default "--out"
        How the caller names ``out`` (the command-line option), for the message.

    Returns
    -------
    Path
        ``out``, resolved.

    Raises
    ------
    OutputNotWritable (a ValueError)
        Naming the option, the folder and the reason.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputNotWritable(f"{option}: output directory {str(out)!r} exists and is not a "
                                f"folder (it is an existing file); choose another {option}")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputNotWritable(f"{option}: cannot create output directory {str(out)!r}, so it "
                                f"is not writable: {exc.strerror or exc}; choose another "
                                f"{option}") from exc
    try:
        with tempfile.NamedTemporaryFile(dir=out, prefix=".rrr-pin-probe-"):
            pass
    except OSError as exc:
        raise OutputNotWritable(f"{option}: output directory {str(out)!r} is not writable: "
                                f"{exc.strerror or exc}; choose another {option}") from exc
    return out.resolve()


@contextmanager
def writing(path):
    """Name ``path`` in an ``OSError`` raised inside the block (a full disk, a lost mount).

    A write that fails half-way (``ENOSPC`` in ``fh.write``) raises an ``OSError`` without a
    file name; this re-raises it as ``OSError(errno, strerror, path)``.
    """
    try:
        yield
    except OSError as exc:
        if exc.filename is not None:
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc


@dataclass(frozen=True)
class RecordedRun:
    """A run that a folder's manifest records.

    Attributes
    ----------
    tool : str
        The tool that wrote it (``"reproduce"``, ``"montecarlo"``).
    part : str or None
        Which of that tool's runs sharing a folder (``"delay"`` for ``stress --effect delay``).
    listed : tuple of str
        The files it lists (relative names), its manifest first.
    complete : bool
        Whether ``listed`` is every file it wrote (false: the run died before saying).
    kept : tuple of str
        Files that were in the folder before that run (never its own).
    """

    tool: str
    part: str | None
    listed: tuple[str, ...]
    complete: bool = True
    kept: tuple[str, ...] = ()


def manifest_name(part: str | None = None) -> str:
    """Return the manifest's file name for a run's ``part`` (:data:`MANIFEST` without one)."""
    return MANIFEST if part is None else f"rrr-pin-run-{part}.json"


_MANIFEST_RE = re.compile(r"^rrr-pin-run(-[A-Za-z0-9_.]+)?\.json$")


def recorded_runs(folder) -> list[RecordedRun]:
    """Return the runs whose manifests the folder ``folder`` holds (sorted by manifest name).

    A Monte Carlo campaign (``campaign.json`` of :mod:`rrr_pin.campaign.store`) is a run of
    ``"montecarlo"`` listing its manifest, its rows and its recorded outputs.

    Raises
    ------
    OutputError
        A manifest that cannot be read.
    """
    folder = Path(folder)
    runs = []
    for manifest in sorted(p for p in folder.iterdir() if _MANIFEST_RE.match(p.name)):
        try:
            data = json.loads(manifest.read_text())
            if data.get("format") != _FORMAT or not isinstance(data.get("tool"), str):
                raise ValueError(f"not an {_FORMAT} manifest")
        except (ValueError, AttributeError, OSError) as exc:
            raise OutputError(f"{str(manifest)!r} is not a readable rrr-pin manifest ({exc}); "
                              "remove it, or choose another --out") from exc
        runs.append(RecordedRun(data["tool"], data.get("part"),
                                (manifest.name, *data.get("outputs", [])),
                                bool(data.get("complete")), tuple(data.get("kept", []))))
    campaign = folder / CAMPAIGN_MANIFEST
    if campaign.is_file():
        try:
            data = json.loads(campaign.read_text())
        except (ValueError, OSError):
            data = None
        if isinstance(data, dict) and data.get("format") == CAMPAIGN_FORMAT:
            runs.append(RecordedRun("montecarlo", None, (CAMPAIGN_MANIFEST, CAMPAIGN_PARTS,
                                                         *data.get("outputs", []))))
    return runs


def _holds_run(folder: Path) -> bool:
    """Whether ``folder`` holds a run's manifest (a separate run, when nested)."""
    return (folder / CAMPAIGN_MANIFEST).is_file() or any(
        _MANIFEST_RE.match(p.name) for p in folder.iterdir())


def _entries(folder: Path, owned: set[str]) -> list[str]:
    """Top-level entries of ``folder`` (``name/`` for a folder) but nested runs and ``owned``."""
    out = []
    for p in sorted(folder.iterdir()):
        if p.name.startswith(".rrr-pin-probe-") or (p.is_dir() and _holds_run(p)):
            continue
        if p.is_dir():
            inside = [q.relative_to(folder).as_posix() for q in p.rglob("*") if not q.is_dir()]
            if inside and all(n in owned for n in inside):
                continue
        elif p.name in owned:
            continue
        out.append(p.name + ("/" if p.is_dir() else ""))
    return out


def _shown(entries: list[str]) -> str:
    return ", ".join(entries[:_SHOWN]) + (", ..." if len(entries) > _SHOWN else "")


def refuse_other_tool(out, tool: str, option: str = "--out") -> list[RecordedRun]:
    """Refuse the folder ``out`` if it holds a run of a tool other than ``tool``.

    Returns
    -------
    list of RecordedRun
        The runs of ``tool`` recorded there (any part).

    Raises
    ------
    OutputInUse
        Naming the folder, the other tool, a few of its files and the way out.
    """
    out = Path(out)
    runs = recorded_runs(out)
    for run in runs:
        if run.tool != tool:
            raise OutputInUse(
                f"{option} {str(out)!r} holds a run of `rrr-pin {run.tool}` "
                f"({_shown(_entries(out, set()))}); `rrr-pin {tool}` does not write beside it, "
                f"even with --overwrite: choose another {option} (or remove that run first)",
                run.tool)
    return runs


def _files(out: Path) -> dict[str, tuple[int, int, int]]:
    """Map every file under ``out`` (relative posix name) to its inode, mtime and size.

    Nested runs and probe files are left out.
    """
    found = {}
    for root, dirs, names in os.walk(out):
        here = Path(root)
        dirs[:] = sorted(d for d in dirs if not _holds_run(here / d))
        for name in names:
            if name.startswith(".rrr-pin-probe-"):
                continue
            p = here / name
            try:
                st = p.lstat()
            except OSError:  # removed meanwhile
                continue
            found[p.relative_to(out).as_posix()] = (st.st_ino, st.st_mtime_ns, st.st_size)
    return found


def _safe_name(name) -> bool:
    return isinstance(name, str) and ".." not in Path(name).parts and not Path(name).is_absolute()


def _write_json(path: Path, data: dict) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename (never half a file)."""
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with writing(path), open(tmp, "w") as fh:
            fh.write(json.dumps(data, indent=1) + "\n")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _remove(out: Path, names) -> list[str]:
    """Delete the files ``out/name`` (plain files only), then the folders left empty."""
    removed = []
    for name in sorted(set(names)):
        p = out / name
        if _safe_name(name) and (p.is_file() or p.is_symlink()):
            p.unlink()
            removed.append(name)
    for name in sorted({str(Path(n).parent) for n in removed}, key=len, reverse=True):
        for d in [out / name, *(out / name).parents]:
            if d == out or out not in d.parents:
                break
            try:
                d.rmdir()  # only if empty
            except OSError:
                break
    return removed


class OutputDir:
    """An output folder claimed by one run of one tool; see the module docstring for the rule.

    Create with :meth:`claim` before any computation; write files under :attr:`path`; call
    :meth:`close` at the end (also after an error: it records what was written), or use it as
    a context manager.

    Attributes
    ----------
    path : Path
        The folder (as given, not resolved).
    tool : str
        The tool that claimed it (``"reproduce"``).
    part : str or None
        Which of the tool's runs sharing the folder this is.
    manifest : Path
        This run's manifest.
    settings : dict
        The run's settings, recorded in the manifest (after a JSON round trip).
    removed : list of str
        Files of the previous run removed by ``overwrite`` (relative names).
    """

    def __init__(self, path: Path, tool: str, part: str | None, settings: dict,
                 before: dict, removed: list, created: bool = False):
        self.path = path
        self.tool = tool
        self.part = part
        self.manifest = path / manifest_name(part)
        self.settings = settings
        self.removed = removed
        self._before = before
        self._created = created
        self._owned: set[str] = set()
        self._closed = False

    @classmethod
    def claim(cls, out, tool: str, *, part: str | None = None, overwrite: bool = False,
              settings: dict | None = None, option: str = "--out") -> OutputDir:
        """Claim the folder ``out`` for a run of ``tool``, before any work is done.

        Parameters
        ----------
        out : path-like
            The output folder, created if missing.
        tool : str
            The tool's name, recorded in the manifest (``"reproduce"``, ``"export"``).
        part : str, optional
            For a tool whose runs share a folder, each writing its own files: which run this
            is (letters, digits, ``_`` and ``.``; ``stress`` uses the effect's name).
        overwrite : bool, default False
            Replace a previous run of ``tool`` (and ``part``) in ``out``: remove exactly the
            files its manifest lists. Files no manifest lists are kept. A run of another tool
            is refused all the same.
        settings : dict, optional
            JSON-able settings of the run, recorded in the manifest (non-JSON values are
            written as their ``repr``).
        option : str, default "--out"
            How the caller names ``out``, for the messages.

        Returns
        -------
        OutputDir

        Raises
        ------
        OutputNotWritable
            ``out`` is a file, lies under one, or cannot be created or written.
        OutputInUse
            ``out`` holds a run of another tool.
        OutputNotEmpty
            ``out`` holds files (but other parts' runs) and ``overwrite`` is not given.
        OutputError
            ``out`` holds a damaged manifest.
        """
        if part is not None and not re.fullmatch(r"[A-Za-z0-9_.]+", part):
            raise ValueError(f"part must be letters, digits, '_' or '.', got {part!r}")
        path = Path(out)
        created = not path.exists()
        check_writable(path, option)
        runs = refuse_other_tool(path, tool, option)
        mine = [r for r in runs if r.part == part]
        owned = {n for r in runs if r.part != part for n in r.listed}  # other parts' files
        entries = _entries(path, owned)
        if entries and not overwrite:
            if mine:
                what = f"a previous run of `rrr-pin {tool}`"
                way = (f"pass --overwrite to replace it (only the files its manifest "
                       f"{manifest_name(part)} lists are removed; other files are kept)")
            else:
                what = "files no rrr-pin run recorded"
                way = "pass --overwrite to write beside them (they are kept, untouched)"
            raise OutputNotEmpty(
                f"{option} {str(path)!r} is not empty: it holds {what} ({len(entries)} "
                f"entries: {_shown(entries)}); choose an empty {option}, or {way}")
        listed = []
        for run in mine:
            listed += run.listed
            if not run.complete:  # a run that died before listing its files
                kept = set(run.kept) | owned
                listed += [n for n in _files(path) if n not in kept]
        removed = _remove(path, listed)
        settings = json.loads(json.dumps(settings or {}, default=repr))
        before = _files(path)
        self = cls(path, tool, part, settings, before, removed, created)
        self._owned = owned
        self._write_manifest([], complete=False)
        return self

    def outputs(self) -> list[str]:
        """Return the files created or changed under :attr:`path` since the claim (sorted)."""
        return sorted(n for n, st in _files(self.path).items()
                      if self._before.get(n) != st and n not in self._owned
                      and not _MANIFEST_RE.match(n))

    def close(self, finished: bool = True) -> list[str]:
        """Record the files this run wrote in the manifest and mark it complete.

        ``finished`` (recorded as such) is false for a command that ended on an error.

        A run that wrote nothing (refused on a bad input after the claim) leaves no trace: its
        manifest is removed, and the folder too if the claim created it and it is empty.

        Returns
        -------
        list of str
            Those files (relative names), sorted. Calling again does nothing more.
        """
        written = self.outputs()
        if self._closed:
            return written
        self._closed = True
        if written:
            self._write_manifest(written, complete=True, finished=finished)
            return written
        self.manifest.unlink(missing_ok=True)
        if self._created and not any(self.path.iterdir()):
            self.path.rmdir()
        return written

    def _write_manifest(self, outputs: list[str], complete: bool,
                        finished: bool = False) -> None:
        kept = sorted(n for n in self._before if n != self.manifest.name)
        _write_json(self.manifest, {
            "format": _FORMAT, "version": _VERSION, "tool": self.tool, "part": self.part,
            "settings": self.settings, "complete": complete, "finished": finished,
            "outputs": outputs, "kept": kept})

    def __enter__(self) -> OutputDir:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
