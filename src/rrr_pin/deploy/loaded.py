"""Run an exported folder's compiled library from Python: :func:`build`, :func:`exported_law`.

:func:`build` runs the folder's ``CMakeLists.txt`` (CMake and a C/C++ compiler on ``PATH``;
the Pinocchio CMake package of the installed ``pin`` wheel, found by ``python -m cmeel
cmake``). :func:`exported_law` loads the shared library it made (``ctypes``) as a
:class:`~rrr_pin.control.laws.SampledLaw`, so :func:`rrr_pin.simulate` runs the C code in
the loop, against the plant it is given (nominal or uncertain), on the Python engine.
"""

from __future__ import annotations

import ctypes
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from ..control.laws import SampledLaw
from .writer import read_record

__all__ = ["ExportedLaw", "exported_law", "build", "library_name"]

_DOUBLES = ctypes.POINTER(ctypes.c_double)


def library_name() -> str:
    """File name of the shared library CMake makes (``librrr_pin_ctrl_shared.so`` on Linux)."""
    if sys.platform == "darwin":
        return "librrr_pin_ctrl_shared.dylib"
    if sys.platform == "win32":
        return "rrr_pin_ctrl_shared.dll"
    return "librrr_pin_ctrl_shared.so"


def build(folder, build_dir=None, *, timeout: float = 1800.0) -> Path:
    """Configure and build the exported ``folder`` with CMake (Release); return the shared library.

    Parameters
    ----------
    folder : path-like
        A folder written by :func:`rrr_pin.export`.
    build_dir : path-like, optional
        Build tree (default ``folder/build``).
    timeout : float, default 1800
        Seconds allowed to each CMake step.

    Returns
    -------
    Path
        The shared library ``rrr_pin_ctrl_shared`` (:func:`library_name`); the commands and
        their output are in ``build_dir/build.log``.

    Raises
    ------
    FileNotFoundError
        No ``cmake`` on ``PATH``, or ``folder`` holds no ``CMakeLists.txt``.
    RuntimeError
        A CMake step failed (its output is in the message).
    """
    folder = Path(folder)
    if not (folder / "CMakeLists.txt").is_file():
        raise FileNotFoundError(f"{folder} holds no CMakeLists.txt: not an exported folder")
    cmake = shutil.which("cmake")
    if cmake is None:
        raise FileNotFoundError("cmake is not on PATH (install CMake >= 3.16 and a C compiler)")
    build_dir = Path(build_dir) if build_dir is not None else folder / "build"
    prefix = subprocess.run([sys.executable, "-m", "cmeel", "cmake"], capture_output=True,
                            text=True, check=False).stdout.strip()
    configure = [cmake, "-S", str(folder), "-B", str(build_dir), "-DCMAKE_BUILD_TYPE=Release"]
    if prefix:
        configure.append(f"-DCMAKE_PREFIX_PATH={prefix.replace(':', ';')}")
    log = []
    for cmd in (configure, [cmake, "--build", str(build_dir)]):
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
        log += [f"$ {' '.join(cmd)}", done.stdout, done.stderr]
        if done.returncode:
            raise RuntimeError(f"{' '.join(cmd)} failed ({done.returncode}):\n"
                               f"{done.stdout[-4000:]}{done.stderr[-4000:]}")
    (build_dir / "build.log").write_text("\n".join(log))
    return build_dir / library_name()


class ExportedLaw(SampledLaw):
    """The compiled ``ctrl_step`` of an exported folder, as a sampled law.

    Its state ``x`` is the C ``ctrl_state``'s (``CTRL_NX`` doubles): :meth:`step` copies it in,
    calls ``ctrl_step`` and returns the torque and the advanced state, so the simulator holds
    the state as for any law. An input ``ctrl_step`` refuses (NaN or inf) gives a NaN torque,
    which stops a simulation with its own reason.

    Attributes
    ----------
    folder : Path
        The exported folder.
    library : Path
        The shared library loaded.
    record : dict
        ``controller.json``.
    name, label, n, nx, rate
        As recorded (:class:`~rrr_pin.control.laws.SampledLaw`).
    """

    def __init__(self, folder, library=None):
        self.folder = Path(folder)
        self.record = record = read_record(self.folder)
        self.library = (Path(library) if library is not None
                        else self.folder / "build" / library_name())
        if not self.library.is_file():
            raise FileNotFoundError(f"{self.library} does not exist: build the folder first, "
                                    f"rrr_pin.deploy.loaded.build({str(self.folder)!r}) or cmake "
                                    f"-S {self.folder} -B {self.folder / 'build'} && cmake "
                                    f"--build {self.folder / 'build'}")
        self._lib = ctypes.CDLL(str(self.library.resolve()))
        self._step = self._lib.ctrl_step
        self._step.restype = ctypes.c_int
        self._step.argtypes = [_DOUBLES] * 7
        self.name = record["law"]["name"]
        self.label = f"{record['law']['label']} (exported C)"
        self.n, self.nx, self.rate = int(record["nq"]), int(record["nx"]), float(record["rate_hz"])
        self._size = max(self.nx, 1)
        self._step_dt = None  # ctrl_step_dt, bound at its first use
        # ctrl_reset: the initial state, and Pinocchio's workspace for this thread
        s = np.zeros(self._size)
        self._lib.ctrl_reset.argtypes = [_DOUBLES]
        self._lib.ctrl_reset(s.ctypes.data_as(_DOUBLES))
        self._x0 = s[:self.nx].copy()

    def initial_state(self) -> np.ndarray:
        """Return ``ctrl_reset``'s state, shape (nx,)."""
        return self._x0.copy()

    def step(self, t, q, qd, r, rd, rdd, x):
        """One ``ctrl_step``: ``(tau, x_next)``, tau [N m] shape (n,), x_next shape (nx,)."""
        s = np.zeros(self._size)
        s[:self.nx] = x
        tau = np.empty(self.n)
        args = [np.ascontiguousarray(v, dtype=float) for v in (q, qd, r, rd, rdd)]
        rc = self._step(s.ctypes.data_as(_DOUBLES), *(a.ctypes.data_as(_DOUBLES) for a in args),
                        tau.ctypes.data_as(_DOUBLES))
        if rc == 1:  # CTRL_EINPUT: nothing computed
            tau[:] = np.nan
        return tau, s[:self.nx].copy()

    def step_dt(self, q, qd, r, rd, rdd, x, dt: float):
        """One ``ctrl_step_dt`` over a period of ``dt`` [s]: ``(tau, x_next, rc)``.

        ``rc`` is its return code (0 ``CTRL_OK``, 3 ``CTRL_EPERIOD``: nothing written, ``tau``
        NaN and ``x_next`` the state given).
        """
        if self._step_dt is None:
            self._step_dt = self._lib.ctrl_step_dt
            self._step_dt.restype = ctypes.c_int
            self._step_dt.argtypes = [_DOUBLES] * 7 + [ctypes.c_double]
        s = np.zeros(self._size)
        s[:self.nx] = x
        tau = np.full(self.n, np.nan)
        args = [np.ascontiguousarray(v, dtype=float) for v in (q, qd, r, rd, rdd)]
        rc = self._step_dt(s.ctypes.data_as(_DOUBLES), *(a.ctypes.data_as(_DOUBLES) for a in args),
                           tau.ctypes.data_as(_DOUBLES), float(dt))
        return tau, s[:self.nx].copy(), int(rc)

    def __reduce__(self):
        return (ExportedLaw, (self.folder, self.library))

    def describe(self) -> dict:
        """Return the recorded law, with the folder and the library run."""
        return {**super().describe(), "exported": str(self.folder),
                "library": str(self.library), "model": self.record["model"]}


def exported_law(folder, library=None) -> ExportedLaw:
    """Load an exported folder's built library as a :class:`~rrr_pin.control.laws.SampledLaw`.

    Parameters
    ----------
    folder : path-like
        A folder written by :func:`rrr_pin.export` and built (:func:`build`, or CMake).
    library : path-like, optional
        The shared library (default ``folder/build/`` :func:`library_name`).

    Returns
    -------
    ExportedLaw

    Raises
    ------
    FileNotFoundError
        No ``controller.json``, or the library is not built (the message gives the commands).
    """
    return ExportedLaw(folder, library)
