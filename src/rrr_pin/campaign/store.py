"""Append-only campaign store: finished samples reach the disk as they finish.

A campaign writes into one output directory ``out``:

``out/campaign.json``
    Manifest: ``{"format": "rrr-pin-campaign", "version": 1, "settings": {...},
    "outputs": [...]}``. ``settings`` are the campaign's settings as given to
    :meth:`CampaignStore.open` (after a JSON round trip); ``outputs`` lists the final files
    (relative names) a run has written through :meth:`CampaignStore.write_text` or
    :meth:`CampaignStore.wrote`.
``out/parts.jsonl``
    One JSON object per finished sample (a *row*, with an integer ``"index"``), appended in
    completion order, flushed and ``fsync``-ed after every chunk.
final tables (``campaign.csv``, ``summary.json``, figures, ...)
    Written by the caller from :meth:`CampaignStore.rows` (sorted by index), so they depend only
    on the set of finished rows, never on the order they finished in or on interruptions.

Behaviour on faults
-------------------
Every finished chunk of samples is appended to ``parts.jsonl`` and forced to disk before the
next one is recorded, so Ctrl-C, SIGTERM, a killed worker, a dead cluster or a full disk loses
at most the chunks that were still running. A process killed in the middle of a write leaves at
most one torn last line; the next ``--resume`` ignores it and truncates it away. Resuming needs
the same settings as the interrupted run (a difference is refused, naming the settings that
differ); it recomputes only the samples missing from ``parts.jsonl``. Each sample is seeded by
its index alone, so the final tables of an interrupted and resumed campaign are byte-identical
to those of a run that was never interrupted. An existing non-empty output directory is
refused unless ``resume`` (continue it) or ``overwrite`` (start afresh) is given; with
``overwrite``, the previous run's manifest, rows and recorded outputs are deleted first, and
files the store does not know are left alone. Only files written by this run are listed in
:attr:`CampaignStore.written`, so a stale figure is never reported as new.

Examples
--------
>>> store = CampaignStore.open(out, settings=settings, resume=args.resume,
...                            overwrite=args.overwrite)          # doctest: +SKIP
>>> todo = [k for k in range(samples) if k not in store.done()]  # doctest: +SKIP
>>> for _, rows in run_tasks(fn, chunks(todo), jobs=2):           # doctest: +SKIP
...     store.append(rows)
>>> store.write_text("summary.json", summarize(store.rows()))     # doctest: +SKIP
"""

from __future__ import annotations

import json
import logging
import os
import signal
import tempfile
import threading
from collections.abc import Iterable
from contextlib import contextmanager
from pathlib import Path

try:  # POSIX advisory lock: one writer per output directory
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

__all__ = [
    "CampaignStore", "StoreError", "OutputNotWritable", "OutputNotEmpty", "SettingsMismatch",
    "StoreCorrupt", "MANIFEST", "PARTS", "check_writable",
]

#: File names inside the output directory.
MANIFEST = "campaign.json"
PARTS = "parts.jsonl"
_FORMAT = "rrr-pin-campaign"
_VERSION = 1

logger = logging.getLogger(__name__)


class StoreError(ValueError):
    """An output directory that cannot hold this campaign (base class)."""


class OutputNotWritable(StoreError):
    """An output folder that is a file, lies under one, or cannot be created or written.

    Raised by :func:`check_writable`, for campaigns and reports alike.
    """


class OutputNotEmpty(StoreError):
    """``out`` holds files and neither ``resume`` nor ``overwrite`` was given."""


class SettingsMismatch(StoreError):
    """``resume`` with settings that differ from the recorded ones.

    Attributes
    ----------
    keys : list of str
        Dotted paths of the settings that differ (``"reference.amp"``), sorted.
    """

    def __init__(self, message: str, keys: list[str]):
        super().__init__(message)
        self.keys = keys


class StoreCorrupt(StoreError):
    """A recorded file that cannot be read (not a torn last line: real damage)."""


def _canonical(value):
    """Return ``value`` after a JSON round trip (tuples become lists, keys strings)."""
    return json.loads(json.dumps(value, allow_nan=True))


def _diff_keys(old, new, prefix: str = "") -> list[str]:
    """Dotted paths where two JSON-like values differ (a key missing on one side differs)."""
    if isinstance(old, dict) and isinstance(new, dict):
        keys = []
        for k in sorted(set(old) | set(new)):
            path = f"{prefix}.{k}" if prefix else str(k)
            if k not in old or k not in new:
                keys.append(path)
            else:
                keys += _diff_keys(old[k], new[k], path)
        return keys
    # NaN != NaN: compare the JSON texts, which spell NaN the same way
    same = json.dumps(old, allow_nan=True) == json.dumps(new, allow_nan=True)
    return [] if same else [prefix or "<settings>"]


def _at(settings: dict, key: str) -> str:
    """Short text of the value at dotted path ``key`` (``"missing"`` if absent)."""
    value = settings
    for part in key.split("."):
        if not isinstance(value, dict) or part not in value:
            return "missing"
        value = value[part]
    text = json.dumps(value, allow_nan=True)
    return text if len(text) <= 60 else text[:57] + "..."


def _fsync_dir(path: Path) -> None:
    """Make a file creation or rename in ``path`` durable (no-op where unsupported)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def _atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename (never half a file)."""
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def check_writable(out) -> Path:
    """Make sure files can be written into the folder ``out``, before any work is done.

    Creates the folder (and its parents) if needed, then creates and removes a probe file in
    it, so a path that is a file or lies under one, a missing permission and a read-only file
    system are all caught. The one writability check of the package (the campaign store and
    :func:`rrr_pin.campaign.store.check_writable` both use it).

    Parameters
    ----------
    out : path-like
        The output folder.

    Returns
    -------
    Path
        ``out``, resolved.

    Raises
    ------
    OutputNotWritable (a ValueError)
        Naming the folder and the reason.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputNotWritable(f"output directory {str(out)!r} exists and is not a folder "
                                "(it is an existing file); choose another --out")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputNotWritable(f"cannot create output directory {str(out)!r}, so it is not "
                                f"writable: {exc.strerror or exc}") from exc
    try:
        with tempfile.NamedTemporaryFile(dir=out, prefix=".rrr-pin-probe-"):
            pass
    except OSError as exc:
        raise OutputNotWritable(f"output directory {str(out)!r} is not writable: "
                                f"{exc.strerror or exc}") from exc
    return out.resolve()


@contextmanager
def _signals_deferred():
    """Hold SIGINT and SIGTERM until the block ends, then deliver them to the handlers in force.

    A signal that lands while rows are being written (during ``fsync``, say) would otherwise
    raise ``KeyboardInterrupt`` between the write and its bookkeeping: rows on disk that the
    store does not count. Only the main thread has signal handlers; elsewhere it does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending = []
    held = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.signal(s, lambda signum, frame: pending.append(signum)) for s in held}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
        if pending:
            signal.raise_signal(pending[0])


class CampaignStore:
    """An output directory holding one campaign's rows, appended as they finish.

    Create with :meth:`open`; see the module docstring for the layout on disk and the
    behaviour on faults. Use as a context manager, or call :meth:`close`, to release the file
    and its lock.

    Attributes
    ----------
    out : Path
        The output directory.
    settings : dict
        The campaign settings (after a JSON round trip).
    resumed : int
        Rows found on disk when the store was opened (0 unless ``resume``).
    written : list of Path
        Final outputs written by *this* run, in order (the manifest and ``parts.jsonl`` are
        not listed: see :attr:`parts_path`, :attr:`manifest_path`).
    """

    def __init__(self, out: Path, settings: dict, outputs: list[str], done: set[int],
                 fh):
        self.out = out
        self.settings = settings
        self._outputs = outputs
        self._done = done
        self._fh = fh
        self.resumed = len(done)
        self.written: list[Path] = []

    # --- opening ----------------------------------------------------------------------------

    @classmethod
    def open(cls, out: str | os.PathLike, *, settings: dict, resume: bool = False,
             overwrite: bool = False, outputs: Iterable[str] = ()) -> CampaignStore:
        """Open ``out`` for a campaign with ``settings``; call before any work starts.

        Parameters
        ----------
        out : str or path-like
            Output directory, created if missing.
        settings : dict
            JSON-able campaign settings. Everything that changes a row must be in it (seed,
            tolerances, reference, rates, controllers, ...): a resume is only allowed with
            equal settings.
        resume : bool, default False
            Continue the campaign recorded in ``out``: the settings must equal the recorded
            ones, :meth:`done` returns the finished sample indices, and the previous run's
            final outputs are deleted (they are rebuilt from the rows at the end). On an
            empty or missing ``out`` a resume simply starts the campaign.
        overwrite : bool, default False
            Start afresh in a non-empty ``out``: the previous run's manifest, rows and recorded
            outputs, and the files named in ``outputs``, are deleted first. Files the store
            does not know are left in place (and never reported as written).
        outputs : iterable of str
            Names (relative to ``out``) of the final files the caller may write, deleted on
            ``overwrite`` and ``resume`` even if no manifest records them (e.g. a directory
            written by an older version).

        Returns
        -------
        CampaignStore

        Raises
        ------
        OutputNotWritable
            ``out`` is a file, lies under a file, or cannot be created or written.
        OutputNotEmpty
            ``out`` holds files and neither ``resume`` nor ``overwrite`` is given, or ``resume``
            is given but ``out`` holds no campaign (no ``campaign.json``).
        SettingsMismatch
            ``resume`` with settings that differ from the recorded ones.
        StoreCorrupt
            A recorded file is damaged beyond a torn last line, or ``out`` is in use by
            another running campaign.
        ValueError
            Both ``resume`` and ``overwrite``; settings not a JSON-able dict.
        """
        if resume and overwrite:
            raise ValueError("resume and overwrite are exclusive: resume continues the "
                             "campaign in the output directory, overwrite starts it afresh")
        if not isinstance(settings, dict):
            raise TypeError(f"settings must be a dict, got {type(settings).__name__}")
        try:
            settings = _canonical(settings)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"settings must be JSON-able: {exc}") from exc
        out = Path(out)
        check_writable(out)
        manifest_path, parts_path = out / MANIFEST, out / PARTS
        entries = [p.name for p in out.iterdir()]
        recorded = None
        if manifest_path.exists() and not overwrite:
            try:
                recorded = json.loads(manifest_path.read_text())
                if recorded.get("format") != _FORMAT or "settings" not in recorded:
                    raise ValueError("not a campaign manifest")
            except (ValueError, AttributeError) as exc:
                raise StoreCorrupt(f"{str(manifest_path)!r} is not a readable campaign "
                                   f"manifest ({exc}); use --overwrite to start afresh"
                                   ) from exc
        if entries and not (resume or overwrite):
            raise OutputNotEmpty(f"output directory {str(out)!r} is not empty "
                                 f"({len(entries)} entries, e.g. {sorted(entries)[0]!r}); "
                                 "pass --resume to continue the campaign recorded there or "
                                 "--overwrite to start afresh")
        if resume and entries and recorded is None:
            raise OutputNotEmpty(f"cannot resume: output directory {str(out)!r} is not empty "
                                 f"but holds no campaign ({MANIFEST} missing); use "
                                 "--overwrite to start afresh there")
        if resume and recorded is not None:
            keys = _diff_keys(recorded["settings"], settings)
            if keys:
                what = "; ".join(f"{k} (recorded {_at(recorded['settings'], k)}, given "
                                 f"{_at(settings, k)})" for k in keys)
                raise SettingsMismatch(
                    f"cannot resume the campaign in {str(out)!r}: settings differ from the "
                    f"recorded ones in {', '.join(keys)}: {what}; rerun with the same "
                    "settings, or use --overwrite to start afresh", keys)
        previous = list(recorded.get("outputs", [])) if recorded else []
        stale = set(previous) | set(outputs)
        if overwrite:
            stale |= {MANIFEST, PARTS}
        fh = None
        try:
            fh = open(parts_path, "a+b")
            if fcntl is not None:
                try:
                    fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
                except OSError as exc:
                    raise StoreCorrupt(f"output directory {str(out)!r} is in use by another "
                                       "running campaign") from exc
            for name in sorted(stale - {PARTS}):
                _remove_inside(out, name)
            if overwrite:
                fh.truncate(0)
            done = _recover(parts_path, fh) if resume else set()
            if resume:
                logger.info("store %s: resuming, %d samples already on disk", out, len(done))
            elif overwrite:
                logger.info("store %s: previous campaign deleted (overwrite)", out)
            if not resume and not overwrite:
                fh.truncate(0)
            fh.seek(0, os.SEEK_END)
            _write_manifest(manifest_path, settings, [])
        except BaseException:
            if fh is not None:
                fh.close()
            raise
        return cls(out, settings, [], done, fh)

    # --- rows -------------------------------------------------------------------------------

    @property
    def parts_path(self) -> Path:
        """Path of the append-only rows file ``parts.jsonl``."""
        return self.out / PARTS

    @property
    def manifest_path(self) -> Path:
        """Path of the manifest ``campaign.json``."""
        return self.out / MANIFEST

    def done(self) -> set[int]:
        """Return the indices of the rows on disk (recorded before and in this run)."""
        return set(self._done)

    def append(self, rows: list[dict]) -> None:
        """Append ``rows`` (one finished chunk) and force them to disk.

        Parameters
        ----------
        rows : list of dict
            JSON-able rows, each with an integer ``"index"`` not yet recorded. Tuples come
            back from :meth:`rows` as lists; keys keep their order.

        Raises
        ------
        TypeError
            A row that is not a dict, an ``index`` that is not an int, a value that is not
            JSON-able (e.g. ``numpy.int64``).
        ValueError
            An index already recorded, or repeated within ``rows``.
        """
        if self._fh is None:
            raise ValueError(f"campaign store {str(self.out)!r} is closed")
        lines, seen = [], set()
        for row in rows:
            if not isinstance(row, dict):
                raise TypeError(f"a row must be a dict, got {type(row).__name__}")
            k = row.get("index")
            if not isinstance(k, int) or isinstance(k, bool):
                raise TypeError(f"row['index'] must be an int, got {k!r}")
            if k in self._done or k in seen:
                raise ValueError(f"row index {k} is already recorded in "
                                 f"{str(self.parts_path)!r}")
            try:
                lines.append(json.dumps(row, allow_nan=True) + "\n")
            except (TypeError, ValueError) as exc:
                raise TypeError(f"row {k} is not JSON-able: {exc}") from exc
            seen.add(k)
        with _signals_deferred():  # written and recorded, or neither: never one without the other
            start = self._fh.tell()
            try:
                self._fh.write("".join(lines).encode())
                self._fh.flush()
                os.fsync(self._fh.fileno())
            except OSError:  # e.g. disk full: leave no torn line between two good ones
                self._fh.truncate(start)
                raise
            self._done |= seen

    def rows(self) -> list[dict]:
        """Return every recorded row, sorted by ``index``."""
        if self._fh is not None:
            self._fh.flush()
        rows = []
        with open(self.parts_path, "rb") as fh:
            for line in fh:
                rows.append(json.loads(line))
        rows.sort(key=lambda r: r["index"])
        return rows

    # --- final outputs ----------------------------------------------------------------------

    def write_text(self, name: str, text: str) -> Path:
        """Write the final output ``out/name`` atomically and record it as written.

        Parameters
        ----------
        name : str
            Path relative to ``out`` (``"campaign.csv"``); parent folders are created.
        text : str
            Content, written as UTF-8.

        Returns
        -------
        Path
        """
        path = self._inside(name)
        path.parent.mkdir(parents=True, exist_ok=True)
        _atomic_write(path, text.encode("utf-8"))
        return self.wrote(name)

    def wrote(self, name: str) -> Path:
        """Record that the caller wrote ``out/name`` itself (e.g. a figure); returns its path."""
        path = self._inside(name)
        if not path.is_file():
            raise FileNotFoundError(f"{str(path)!r} was reported as written but does not exist")
        rel = path.relative_to(self.out).as_posix()
        if rel not in self._outputs:
            self._outputs.append(rel)
            _write_manifest(self.manifest_path, self.settings, self._outputs)
        if path not in self.written:
            self.written.append(path)
        return path

    def _inside(self, name: str) -> Path:
        path = (self.out / name)
        if ".." in Path(name).parts or Path(name).is_absolute() or name in (MANIFEST, PARTS):
            raise ValueError(f"output name {name!r} must be a new file inside {str(self.out)!r}")
        return path

    # --- closing ----------------------------------------------------------------------------

    def close(self) -> None:
        """Release ``parts.jsonl`` and its lock (rows already appended are on disk)."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> CampaignStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _write_manifest(path: Path, settings: dict, outputs: list[str]) -> None:
    """Write the manifest ``campaign.json`` atomically (layout: module docstring)."""
    manifest = {"format": _FORMAT, "version": _VERSION, "settings": settings,
                "outputs": outputs}
    _atomic_write(path, (json.dumps(manifest, indent=1) + "\n").encode())


def _remove_inside(out: Path, name: str) -> None:
    """Delete the file ``out/name`` if it exists (only plain files inside ``out``)."""
    path = out / name
    if ".." in Path(name).parts or Path(name).is_absolute():
        return
    if path.is_file() or path.is_symlink():
        path.unlink()


def _recover(parts_path: Path, fh) -> set[int]:
    """Read the indices in ``parts.jsonl``, truncating a torn last line; return them."""
    fh.seek(0)
    data = fh.read()
    end = data.rfind(b"\n") + 1  # bytes after the last newline: a torn write
    lines = data[:end].split(b"\n")[:-1]
    done: set[int] = set()
    for i, line in enumerate(lines):
        try:
            row = json.loads(line)
            k = row["index"]
            if not isinstance(k, int) or isinstance(k, bool) or k in done:
                raise ValueError(f"bad or repeated index {k!r}")
        except (ValueError, TypeError, KeyError) as exc:
            if i == len(lines) - 1:  # a damaged last line is a torn write too
                end -= len(line) + 1
                break
            raise StoreCorrupt(f"{str(parts_path)!r} line {i + 1} is damaged ({exc}); "
                               "use --overwrite to start afresh") from exc
        done.add(k)
    if end != len(data):
        fh.truncate(end)
        fh.flush()
        os.fsync(fh.fileno())
    fh.seek(0, os.SEEK_END)
    return done
