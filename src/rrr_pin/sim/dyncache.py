r"""Generated dynamics at first use: any serial structure, compiled once into a user cache.

The extension compiles in the generated dynamics of a few structures (:data:`rrr_pin.sim.batched.
GENERATED`). For any other structure of revolute joints about x, y or z (an xArm7, a z1, a
user's URDF), :func:`load` runs the generator (:func:`rrr_pin.sim.dyngen.generate`), compiles
its C with the compiler and flags that built the extension's own generated dynamics
(``EXTENSION.c_compiler()``, ``EXTENSION.c_flags()``: the same code, the same rounding), caches
the shared object per structure and registers its functions with the batched loop
(``EXTENSION.batch_register``). A later process finds the entry and only loads it.

The cache: ``$RRR_PIN_CACHE`` if set, else ``$XDG_CACHE_HOME/rrr-pin`` (``~/.cache/rrr-pin``),
folder ``dyn/<key>`` per entry, ``key`` a hash of the structure, :data:`GENERATOR_VERSION` (a
hash of the generator's source), the compiler and its flags: an entry of another generator
version is never reused (it lives under another key; a folder whose ``entry.json`` names another
version or structure is rebuilt). Each entry holds ``dyn.c``, ``dyn_common.h``, ``dyn.so`` and
``entry.json`` (structure, version, compiler, flags, build time [s]), written last, so a build
that stopped halfway is rebuilt.

Nothing here is silent: a structure that cannot be built or loaded (no compiler, a compiler that
fails, a cache folder that cannot be written, a corrupted entry) raises :class:`CacheError`
naming it, and :mod:`rrr_pin.sim.batched` then leaves the run to the compiled engine, with the
reason in ``Trajectory.info["engine_note"]``.
"""

from __future__ import annotations

import ctypes
import hashlib
import inspect
import json
import logging
import os
import subprocess
import threading
import time
from pathlib import Path

from . import dyngen
from .extension import EXTENSION

__all__ = ["GENERATOR_VERSION", "CacheError", "cache_dir", "generatable", "load", "failure",
           "entry", "COMPILER"]

logger = logging.getLogger(__name__)

#: The C compiler to use; None: the one that built the extension (``EXTENSION.c_compiler()``).
COMPILER: str | None = None

_HEADER = Path(__file__).resolve().parents[1] / "_ext" / "generated" / "dyn_common.h"


def _version() -> str:
    text = inspect.getsource(dyngen)
    try:
        text += _HEADER.read_text()
    except OSError:  # no header installed: _build names it
        pass
    return hashlib.sha256(text.encode()).hexdigest()[:16]


#: The generator's version: a hash of :mod:`rrr_pin.sim.dyngen`'s source (whose ``VERSION``
#: counts its releases) and of the header the generated C includes, so any change to either
#: makes new cache entries.
GENERATOR_VERSION = _version()
_FUNCTIONS = ("pre", "crba", "nle", "gravity", "fd", "id")

# structure -> registered name, or the CacheError of its first attempt (this process).
_LOADED: dict = {}
_LOCK = threading.Lock()
# Shared objects kept loaded for the life of the process (their functions are registered).
_LIBS: list = []


class CacheError(RuntimeError):
    """A structure's dynamics cannot be generated, built or loaded; the message says why."""


def cache_dir() -> Path:
    """Return the cache folder of generated dynamics (see the module docstring)."""
    root = os.environ.get("RRR_PIN_CACHE")
    if not root:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"),
                                                                ".cache")
        root = os.path.join(base, "rrr-pin")
    return Path(root) / "dyn"


def generatable(model) -> bool:
    """Whether the generator handles ``model``'s joints (revolute about x, y or z, nq = nv)."""
    kinds = [model.joints[i].shortname() for i in range(1, model.njoints)]
    return (bool(kinds) and model.nq == model.nv == len(kinds)
            and all(k in dyngen.JOINT_AXES for k in kinds))


def failure(structure: str) -> str | None:
    """Why ``structure``'s dynamics could not be had in this process (None: no failure)."""
    hit = _LOADED.get(structure)
    return str(hit) if isinstance(hit, CacheError) else None


def _compiler() -> tuple[str, list[str]]:
    cc = COMPILER if COMPILER is not None else EXTENSION.c_compiler()
    return cc, EXTENSION.c_flags().split()


def load(model, *, source: str = "a model") -> str:
    """Return the registered name of the generated dynamics of ``model``'s structure.

    Builds them into the cache at first use (seconds), loads them from it afterwards; once per
    process and structure (a failure is remembered too).

    Parameters
    ----------
    model : pinocchio.Model
        Of a :func:`generatable` structure; only its structure enters the code.
    source : str
        Where the model came from, for the generated file's header.

    Raises
    ------
    CacheError
        No compiler, a compiler that fails, a cache folder that cannot be written, a corrupted
        or foreign entry that cannot be loaded: named, with the file or command.
    ValueError
        A structure the generator does not handle.
    """
    st = dyngen.structure(model)
    with _LOCK:  # one build per structure, also when a campaign's threads meet it at once
        hit = _LOADED.get(st)
        if isinstance(hit, CacheError):
            raise hit
        if hit is not None:
            return hit
        try:
            name = _load(model, st, source)
        except CacheError as exc:
            _LOADED[st] = exc
            logger.warning("%s", exc)
            raise
        _LOADED[st] = name
        return name


def _load(model, st: str, source: str) -> str:
    if not generatable(model):
        raise ValueError(f"cannot generate dynamics for the structure {st!r}: only revolute "
                         f"joints about x, y or z")
    cc, flags = _compiler()
    folder, name = entry(st)
    meta_path, so = folder / "entry.json", folder / "dyn.so"
    meta = _read_meta(meta_path)
    if meta is not None and (meta.get("generator_version") != GENERATOR_VERSION
                             or meta.get("structure") != st or meta.get("name") != name):
        logger.info("cache entry %s is of generator %s (structure %r), not %s: rebuilt",
                    folder, meta.get("generator_version"), meta.get("structure"),
                    GENERATOR_VERSION)
        meta = None
    if meta is None or not so.is_file():
        meta = _build(model, st, name, folder, cc, flags, source)
    return _register(so, name, st, model.nq, folder)


def entry(structure: str) -> tuple[Path, str]:
    """Return the cache folder of ``structure``'s entry and the C name of its functions.

    The folder's key hashes the structure, :data:`GENERATOR_VERSION`, the compiler and its
    flags; the name is unique per folder, so two caches never register the same name.
    """
    cc, flags = _compiler()
    key = hashlib.sha256("|".join([structure, GENERATOR_VERSION, cc, *flags]).encode())
    folder = cache_dir() / key.hexdigest()[:20]
    return folder, "dyn_" + hashlib.sha256(str(folder).encode()).hexdigest()[:12]


def _read_meta(path: Path) -> dict | None:
    try:
        meta = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return meta if isinstance(meta, dict) else None


def _build(model, st, name, folder: Path, cc, flags, source) -> dict:
    try:
        header = _HEADER.read_text()
    except OSError as exc:
        raise CacheError(f"the generated dynamics' header {str(_HEADER)!r} is not installed "
                         f"with rrr_pin ({exc}); reinstall the package") from None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "entry.json").unlink(missing_ok=True)
        # Without the forward dynamics not chosen: 60-90 % more compile time, never run.
        (folder / "dyn.c").write_text(dyngen.generate(name, model, source=source, other=False))
        (folder / "dyn_common.h").write_text(header)
    except OSError as exc:
        raise CacheError(f"the generated-dynamics cache folder {str(folder)!r} cannot be "
                         f"written ({exc}); set RRR_PIN_CACHE to a writable folder") from None
    tmp = folder / f"dyn.so.{os.getpid()}.tmp"
    libs = ["-lmvec"] if "-DRRR_DYN_LIBMVEC=1" in flags else []  # as the extension links
    cmd = [cc, *flags, "-fPIC", "-shared", "-I", str(folder), str(folder / "dyn.c"), "-o",
           str(tmp), *libs, "-lm"]
    t0 = time.perf_counter()
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    except (OSError, subprocess.SubprocessError) as exc:
        raise CacheError(f"no C compiler to build the generated dynamics of {st!r}: "
                         f"{' '.join(cmd[:1])!r} cannot run ({exc})") from None
    if done.returncode != 0:
        tail = (done.stderr or done.stdout or "").strip().splitlines()[-3:]
        raise CacheError(f"the C compiler {cc!r} failed (exit {done.returncode}) on the "
                         f"generated dynamics of {st!r} in {str(folder)!r}: "
                         f"{' | '.join(tail) or 'no message'}")
    build_s = time.perf_counter() - t0
    counts = dyngen.operation_counts(model)
    meta = {"structure": st, "name": name, "generator_version": GENERATOR_VERSION,
            "compiler": cc, "flags": flags, "build_s": build_s, "nq": model.nq,
            "fd_algorithm": dyngen.fd_algorithm(counts),
            "operations": {k: v["total"] for k, v in counts.items()}}
    try:
        os.replace(tmp, folder / "dyn.so")
        (folder / "entry.json").write_text(json.dumps(meta, indent=1))
    except OSError as exc:
        raise CacheError(f"the generated-dynamics cache folder {str(folder)!r} cannot be "
                         f"written ({exc}); set RRR_PIN_CACHE to a writable folder") from None
    logger.info("generated dynamics of %r built in %.1f s into %s", st, build_s, folder)
    return meta


def _register(so: Path, name: str, st: str, nq: int, folder: Path) -> str:
    if name in EXTENSION.batch_loaded():  # registered by this process already
        return name
    try:
        lib = ctypes.CDLL(str(so))
        found, algorithm = (ctypes.string_at(ctypes.addressof(
            ctypes.c_char.in_dll(lib, f"{name}_dyn_{key}"))).decode()
            for key in ("structure", "fd"))
        counts = (ctypes.c_int.in_dll(lib, f"{name}_dyn_nq").value,
                  ctypes.c_int.in_dll(lib, f"{name}_dyn_np").value)
        nd = ctypes.c_int.in_dll(lib, f"{name}_dyn_nd").value
        addresses = [ctypes.cast(getattr(lib, f"{name}_{fn}"), ctypes.c_void_p).value
                     for fn in _FUNCTIONS]
    except (OSError, ValueError, AttributeError) as exc:
        raise CacheError(f"the generated-dynamics cache entry {str(folder)!r} is corrupted "
                         f"({exc}); delete the folder to rebuild it") from None
    npar = 3 + dyngen.PER_JOINT * nq
    if found != st or counts != (nq, npar):
        raise CacheError(f"the generated-dynamics cache entry {str(folder)!r} is foreign: it "
                         f"holds the structure {found!r} ({counts[0]} joints), not {st!r}; "
                         f"delete the folder to rebuild it")
    if algorithm not in dyngen.FD_ALGORITHMS or nd < 1:
        raise CacheError(f"the generated-dynamics cache entry {str(folder)!r} is corrupted "
                         f"(forward dynamics {algorithm!r}, {nd} derived entries); delete the "
                         f"folder to rebuild it")
    # fd_other: the chosen algorithm again (an entry holds one; see dyngen.generate).
    EXTENSION.batch_register(name, st, algorithm, nq, npar, nd, *addresses[:5], addresses[4],
                             addresses[5])
    _LIBS.append(lib)
    return name
