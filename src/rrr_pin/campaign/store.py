"""Append-only campaign store: finished samples reach the disk as they finish.

A campaign writes into one output directory ``out``:

``out/campaign.json``
    Manifest: ``{"format": "rrr-pin-campaign", "version": 2, "settings": {...},
    "settings_sha256": "...", "outputs": [...]}``. ``settings`` are the campaign's settings as
    given to :meth:`CampaignStore.open` (after a JSON round trip), ``settings_sha256`` their
    SHA-256 (of their JSON text with sorted keys); ``outputs`` lists the final files
    (relative names) a run has written through :meth:`CampaignStore.write_text` or
    :meth:`CampaignStore.wrote`.
``out/parts.jsonl``
    One JSON object per finished sample (a *row*, with an integer ``"index"``), appended in
    completion order, flushed and ``fsync``-ed after every chunk. Each line ends with the
    key ``"_sha256"``: the SHA-256 of ``settings_sha256``, a newline and the row's JSON text
    with sorted keys and no spaces. :meth:`CampaignStore.rows` returns the rows without it.
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
differ); it recomputes only the samples missing from ``parts.jsonl``. Every row is checked
against its checksum, on resume and when the rows are read for the final tables: a row edited
after it was written (even to another valid value) or copied from a campaign with other
settings is refused, naming the file and the line (:class:`ChecksumMismatch`). This detects
changes, not forgery: anyone can recompute a SHA-256. A store written by an older rrr-pin
(manifest version 1, rows without checksums) cannot be verified, so resuming it is refused;
``overwrite`` starts it afresh. Each sample is seeded by
its index alone, so the final tables of an interrupted and resumed campaign are byte-identical
to those of a run that was never interrupted. An existing non-empty output directory is
refused unless ``resume`` (continue it) or ``overwrite`` (start afresh) is given; with
``overwrite``, the previous run's manifest, rows and recorded outputs are deleted first, and
files the store does not know are left alone. A folder holding a run of another tool (the
manifest of :mod:`rrr_pin.outputs`, e.g. a ``rrr-pin reproduce`` study) is refused even with
``overwrite``, and a full disk while a final table is written leaves the rows and the
previous table whole (no temporary file) and names the file in its ``OSError``. Only files
written by this run are listed in :attr:`CampaignStore.written`, so a stale figure is never
reported as new.

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

import hashlib
import json
import logging
import os
import signal
import threading
from collections.abc import Iterable
from contextlib import contextmanager
from pathlib import Path

from .. import outputs
from ..outputs import (
    CAMPAIGN_FORMAT,
    CAMPAIGN_MANIFEST,
    CAMPAIGN_PARTS,
    check_writable,
    refuse_other_tool,
    writing,
)

try:  # POSIX advisory lock: one writer per output directory
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

__all__ = [
    "CampaignStore", "StoreError", "OutputNotEmpty", "SettingsMismatch", "StoreCorrupt",
    "ChecksumMismatch", "MANIFEST", "PARTS", "row_bytes", "check_room", "DiskTooSmall",
]

#: File names inside the output directory.
MANIFEST = CAMPAIGN_MANIFEST  # named once, in rrr_pin.outputs, which recognizes campaigns
PARTS = CAMPAIGN_PARTS
_FORMAT = CAMPAIGN_FORMAT
_VERSION = 2  # 2: rows carry a checksum (version 1 had none)
_CHECKSUM = "_sha256"  # key of a row's checksum in parts.jsonl

logger = logging.getLogger(__name__)


class StoreError(ValueError):
    """An output directory that cannot hold this campaign (base class)."""


class OutputNotEmpty(StoreError, outputs.OutputNotEmpty):
    """``out`` holds files and neither ``resume`` nor ``overwrite`` was given.

    Also a :class:`rrr_pin.outputs.OutputNotEmpty`, the refusal of every other command.
    """


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


class ChecksumMismatch(StoreCorrupt):
    """A row of ``parts.jsonl`` whose checksum does not match its content and settings.

    Attributes
    ----------
    path : Path
        The rows file.
    line : int
        Line number of the row in it (from 1).
    """

    def __init__(self, message: str, path: Path, line: int):
        super().__init__(message)
        self.path = path
        self.line = line


class DiskTooSmall(StoreError):
    """A campaign whose rows and tables cannot fit on the disk of its output folder."""


def row_bytes(laws: int, joints: int) -> int:
    """Bytes a sample takes on disk: its ``parts.jsonl`` row and its lines of the final tables.

    A fit of measured rows (RRR, 2 laws: 2.2 kB in ``parts.jsonl``; UR5, 3 laws: 3.7 kB),
    each then written again, about as large, into ``campaign.csv`` and ``samples.jsonl``.

    Parameters
    ----------
    laws, joints : int
        Laws of the campaign and joints of the plant.
    """
    return 2 * (600 + 150 * joints + 180 * laws * joints)


def check_room(out, samples: int, per_sample: int) -> None:
    """Refuse a campaign whose ``samples`` rows of ``per_sample`` bytes exceed the free disk.

    Parameters
    ----------
    out : path-like
        The output folder (or where it will be made).
    samples : int
        Rows the campaign writes (with the nominal plant's).
    per_sample : int
        Bytes per row (:func:`row_bytes`).

    Raises
    ------
    DiskTooSmall
        Naming the size needed and the free space.
    """
    import shutil

    where = Path(out).absolute()
    while not where.exists():
        where = where.parent
    free = shutil.disk_usage(where).free
    need = samples * per_sample
    if need > free:
        raise DiskTooSmall(f"--samples: {samples - 1} plants (+ the nominal) need about "
                           f"{_size(need)} on disk ({per_sample / 1e3:.3g} kB per plant: "
                           f"parts.jsonl and the tables), more than the {_size(free)} free "
                           f"at {str(where)!r}")


def _size(n: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n / 1e3:.3g} kB"


def _digest(settings: dict) -> str:
    """SHA-256 of the settings' JSON text with sorted keys (hex)."""
    text = json.dumps(settings, sort_keys=True, allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _checksum(row: dict, digest: str) -> str:
    """Checksum of a row (as read back from JSON) under settings of SHA-256 ``digest``."""
    text = json.dumps(row, sort_keys=True, allow_nan=True, separators=(",", ":"))
    return hashlib.sha256(f"{digest}\n{text}".encode()).hexdigest()


def _verified(line: bytes, n: int, path: Path, digest: str) -> dict:
    """Return the row of line ``n`` of ``path``, its checksum checked and removed.

    Raises ``ValueError`` (or ``KeyError``, ``TypeError``) for a line that is not a JSON row,
    and :class:`ChecksumMismatch` for a row without a checksum or with a wrong one.
    """
    row = json.loads(line)
    if not isinstance(row, dict):
        raise ValueError("not a JSON object")
    k = row.get("index")
    if _CHECKSUM not in row:
        raise ChecksumMismatch(f"{str(path)!r} line {n} (sample {k}) has no checksum, so it "
                               "cannot be verified; use --overwrite to start afresh", path, n)
    recorded = row.pop(_CHECKSUM)
    if recorded != _checksum(row, digest):
        raise ChecksumMismatch(
            f"{str(path)!r} line {n} (sample {k}) does not match its checksum: the row was "
            "changed after it was written, or comes from a campaign with other settings; "
            "restore it, or use --overwrite to start afresh", path, n)
    return row


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
    """Write ``data`` to ``path`` through a temporary file and a rename (never half a file).

    A failed write (a full disk) leaves the previous ``path`` and no temporary file, and its
    ``OSError`` names ``path``.
    """
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with writing(path), open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    _fsync_dir(path.parent)


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
        self._digest = _digest(settings)
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
        rrr_pin.outputs.OutputNotWritable
            ``out`` is a file, lies under a file, or cannot be created or written.
        rrr_pin.outputs.OutputInUse
            ``out`` holds a run of another tool (``rrr-pin reproduce``, ...), even with
            ``overwrite`` (see :mod:`rrr_pin.outputs`).
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
        refuse_other_tool(out, "montecarlo")  # a study's folder is not overwritten
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
        if resume and recorded is not None and recorded.get("version") != _VERSION:
            raise StoreCorrupt(
                f"cannot resume the campaign in {str(out)!r}: it was recorded by another "
                f"version of rrr-pin (store version {recorded.get('version')!r}, this one "
                f"writes {_VERSION}: rows with checksums), so its rows cannot be verified; "
                "use --overwrite to start afresh")
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
            done = _recover(parts_path, fh, _digest(settings)) if resume else set()
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
            An index already recorded, or repeated within ``rows``; a row holding the key
            ``"_sha256"`` (the store's checksum).
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
            if _CHECKSUM in row:
                raise ValueError(f"row {k}: the key {_CHECKSUM!r} is reserved for the "
                                 "store's checksum")
            try:
                canonical = json.loads(json.dumps(row, allow_nan=True))
            except (TypeError, ValueError) as exc:
                raise TypeError(f"row {k} is not JSON-able: {exc}") from exc
            canonical[_CHECKSUM] = _checksum(canonical, self._digest)
            lines.append(json.dumps(canonical, allow_nan=True) + "\n")
            seen.add(k)
        with _signals_deferred():  # written and recorded, or neither: never one without the other
            start = self._fh.tell()
            try:
                with writing(self.parts_path):  # a full disk names the file
                    self._fh.write("".join(lines).encode())
                    self._fh.flush()
                    os.fsync(self._fh.fileno())
            except OSError:  # e.g. disk full: leave no torn line between two good ones
                self._fh.truncate(start)
                raise
            self._done |= seen

    def rows(self) -> list[dict]:
        """Return every recorded row, sorted by ``index``, each checked against its checksum.

        Raises
        ------
        ChecksumMismatch
            A row changed since it was written (naming the file and the line).
        """
        if self._fh is not None:
            self._fh.flush()
        rows = []
        with open(self.parts_path, "rb") as fh:
            for n, line in enumerate(fh, 1):
                rows.append(_verified(line, n, self.parts_path, self._digest))
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
                "settings_sha256": _digest(settings), "outputs": outputs}
    _atomic_write(path, (json.dumps(manifest, indent=1, allow_nan=False) + "\n").encode())


def _remove_inside(out: Path, name: str) -> None:
    """Delete the file ``out/name`` if it exists (only plain files inside ``out``)."""
    path = out / name
    if ".." in Path(name).parts or Path(name).is_absolute():
        return
    if path.is_file() or path.is_symlink():
        path.unlink()


def _recover(parts_path: Path, fh, digest: str) -> set[int]:
    """Read the indices in ``parts.jsonl``, truncating a torn last line; return them.

    Every row is checked against its checksum (settings of SHA-256 ``digest``); a mismatch
    is refused even on the last line (a torn write never parses as a whole row).
    """
    fh.seek(0)
    data = fh.read()
    end = data.rfind(b"\n") + 1  # bytes after the last newline: a torn write
    lines = data[:end].split(b"\n")[:-1]
    done: set[int] = set()
    for i, line in enumerate(lines):
        try:
            row = _verified(line, i + 1, parts_path, digest)
            k = row["index"]
            if not isinstance(k, int) or isinstance(k, bool) or k in done:
                raise ValueError(f"bad or repeated index {k!r}")
        except ChecksumMismatch:
            raise
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
