r"""The exported controller in a real-time loop against a simulated arm: :func:`hil`.

Two processes share one memory mapping (``hil_harness.c``, built with CMake against the exported
folder by ``add_subdirectory``): the **controller** wakes on absolute deadlines ``t0 + k T``
(``clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)``, ``T = 1 / rate``), reads the arm's state,
calls ``ctrl_step`` and writes the torque; SCHED_FIFO (priority 80) and ``mlockall`` are asked
for and recorded as granted or not. The **arm** is the export's nominal model (its
``dynamics.h``), advanced one law period ``Ts`` per cycle by classical RK4 with the torque held,
as :mod:`rrr_pin.sim.python_engine` integrates. A torque written after the next tick is a
**missed deadline**: the arm holds the previous torque for that period, as a drive does.

The same harness also runs the loop **offline** (one process, no clock): the same arithmetic,
so with no missed deadline the real-time closed loop equals it bit for bit, and
``max_error_vs_offline_rad`` measures what the misses cost. The offline loop is run a second
time with the real-time run's missed deadlines replayed (the arm holding the previous torque on
those cycles): it must then equal the real-time loop bit for bit (``max_error_vs_replay_rad``),
which checks the exchange through shared memory whatever the misses. ``tests/test_hil.py`` pins the
offline loop to :func:`rrr_pin.simulate` (Python engine) on the same reference.

Figures (``hil.json``, exactly the keys of issue 35): ``cycles``, ``missed``, ``latency_us``
(tick to torque written: wake-up latency + waiting for the state + ``ctrl_step``; percentiles
``p50``, ``p99``, ``p999`` (99.9 %), ``p9999`` (99.99 %) and ``max``), ``jitter_us`` (the
largest deviation of a wake-to-wake interval from ``T``) and ``max_error_vs_offline_rad``.
``hil_run.json`` records the conditions: the clock rate, the law's rate, SCHED_FIFO and
mlockall granted or not, the load average, ``ctrl_step`` alone, the wake-up latency, the cycles
whose state was late, the tracking error of both loops.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..outputs import OutputDir, writing
from ..validation import FieldError, check_count, check_rate
from .writer import read_record

__all__ = ["HilResult", "hil", "check_export", "build_cache", "MAX_CYCLES", "HARNESS"]

#: Largest ``cycles``: the harness keeps every cycle's state, torque and timing in memory
#: (``(2 n + 4) x 8`` bytes a cycle; 20 million cycles of a 7-joint arm: 2.9 GB).
MAX_CYCLES = 20_000_000

#: The harness's C source, beside this module.
HARNESS = Path(__file__).resolve().parent / "hil_harness.c"

_PERCENTILES = {"p50": 50.0, "p99": 99.0, "p999": 99.9, "p9999": 99.99}


@dataclass(frozen=True)
class HilResult:
    """What :func:`hil` measured.

    Attributes
    ----------
    summary : dict
        The content of ``hil.json``.
    run : dict
        The content of ``hil_run.json`` (the conditions and the secondary figures).
    q_hil, q_offline, q_replay : ndarray, shape (cycles, n)
        The arm's joint angles [rad] at each tick: real-time, offline, and offline with the
        real-time run's missed deadlines replayed (equal to ``q_hil`` bit for bit). A loop that
        diverged stops there: ``q_hil`` and ``q_replay`` at the real-time run's divergence,
        ``q_offline`` at its own (the offline loop holds no torque).
    """

    summary: dict
    run: dict
    q_hil: np.ndarray
    q_offline: np.ndarray
    q_replay: np.ndarray


def _robot(record: dict, folder: Path):
    """Return the arm the export was made for, fingerprint checked.

    The model the export embeds (``model.txt``, Pinocchio's text serialization: a URDF path,
    an identified arm, any model); an export written before it carried one, by its recorded
    name.
    """
    from ..model.dynamics import Robot, load_robot
    from ..sim.codegen import fingerprint

    name = record["model"]["name"]
    embedded = folder / "model.txt"
    if embedded.is_file():
        import pinocchio as pin

        model = pin.Model()
        try:
            model.loadFromString(embedded.read_text(encoding="ascii"))
        except (RuntimeError, ValueError, UnicodeDecodeError) as exc:
            raise ValueError(f"{embedded} is not a Pinocchio model ({exc}): export again"
                             ) from None
        if fingerprint(model) != record["model"]["fingerprint"]:
            raise ValueError(f"{embedded}: the model's fingerprint {fingerprint(model)[:12]}... "
                             f"is not controller.json's {record['model']['fingerprint'][:12]}...; "
                             f"the folder's files come from different exports: export again")
        return Robot(model, model.createData(), name, f"{embedded} (rrr-pin export)", "")
    try:
        robot = load_robot(name)
    except (ValueError, FileNotFoundError) as exc:
        raise ValueError(f"the export's model {name!r} cannot be loaded by name ({exc}); hil "
                         f"simulates the arm the export was made for") from None
    if fingerprint(robot.model) != record["model"]["fingerprint"]:
        raise ValueError(f"load_robot({name!r}) is not the model the export was made for "
                         f"(fingerprints differ): export again, or run hil on that model")
    return robot


#: controller.h's defines and the controller.json keys they must equal.
_DEFINES = {"CTRL_NQ": ("nq", int), "CTRL_RATE_HZ": ("rate_hz", float),
            "CTRL_LAW_NAME": ("law.name", str),
            "CTRL_MODEL_FINGERPRINT": ("model.fingerprint", str),
            "CTRL_COMMAND": ("command.name", str)}


def check_export(folder) -> dict:
    """Check an export's files against each other before a cycle runs; return its record.

    ``controller.h`` (what the code is compiled with: joints, rate, law, model fingerprint,
    torque convention) against ``controller.json`` (what ``hil`` reads); the embedded model's
    fingerprint is checked when it is loaded. An export without a torque convention (written
    before it existed) is ``full``.

    Raises
    ------
    FileNotFoundError
        No ``controller.json`` or ``controller.h``: not an export.
    ValueError
        A value of one file that the other contradicts, named with both values.
    """
    import re

    folder = Path(folder)
    record = read_record(folder)
    header = folder / "controller.h"
    if not header.is_file():
        raise FileNotFoundError(f"{folder} holds no controller.h: not a folder written by "
                                f"rrr-pin export")
    text = header.read_text(encoding="ascii", errors="replace")
    for define, (key, kind) in _DEFINES.items():
        hit = re.search(rf"^#define {define} (.+)$", text, re.M)
        value = record
        for part in key.split("."):
            value = value.get(part) if isinstance(value, dict) else None
        if define == "CTRL_COMMAND" and value is None and hit is None:
            continue  # an export from before the torque conventions: full
        if hit is None or value is None:
            raise ValueError(f"{folder}: controller.h has no {define} or controller.json no "
                             f"{key}: not a complete export; export again")
        raw = hit.group(1).strip()
        compiled = kind(raw.strip('"')) if kind is not float else float(raw)
        if compiled != kind(value):
            raise ValueError(f"{folder}: controller.json says {key} = {value!r}, the code "
                             f"(controller.h {define}) is compiled for {compiled!r}; the files "
                             f"come from different exports or were edited: export again")
    return record


def build_cache(fingerprint: str, dynamics: str) -> Path:
    """Return the folder where ``hil`` keeps the harness build of one model.

    ``$RRR_PIN_CACHE/hil/<fingerprint[:16]>-<dynamics>`` (default ``~/.cache/rrr-pin``, as
    :func:`rrr_pin.sim.dyncache.cache_dir`): the export's sources are copied there, each file
    rewritten only when its text differs, so that CMake recompiles only what changed; the
    model's dynamics (the largest file, ``dyn_model.c`` or ``dynamics.cpp``) are compiled once
    per model and reused by every later ``hil`` of it, whatever the law.
    """
    from ..sim.dyncache import cache_dir

    return cache_dir().parent / "hil" / f"{fingerprint[:16]}-{dynamics}"


def _put(path: Path, data: bytes) -> None:
    """Write ``data`` unless ``path`` holds it already (its time stamp then unchanged)."""
    if not path.is_file() or path.read_bytes() != data:
        path.write_bytes(data)


def _build(folder: Path, work: Path, dynamics: str, fingerprint: str) -> Path:
    """Build ``hil_harness.c`` against ``folder`` in the model's cache; copy it to ``work``."""
    import fcntl

    cmake = shutil.which("cmake")
    if cmake is None:
        raise FileNotFoundError("cmake is not on PATH (install CMake >= 3.21 and a C compiler)")
    pinocchio = dynamics == "pinocchio"
    root = build_cache(fingerprint, dynamics)
    export, src, build = root / "export", root / "harness", root / "build"
    for d in (export, src):
        d.mkdir(parents=True, exist_ok=True)
    with open(root / "lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one build of a model at a time
        for f in folder.iterdir():
            if f.is_file() and f.name != "design.json":
                _put(export / f.name, f.read_bytes())
        _put(src / "hil_harness.c", HARNESS.read_bytes())
        langs = "C CXX" if pinocchio else "C"
        link = ("set_target_properties(rrr_pin_hil PROPERTIES LINKER_LANGUAGE CXX)\n"
                if pinocchio else "")
        _put(src / "CMakeLists.txt", (
            "cmake_minimum_required(VERSION 3.21)\n"
            f"project(rrr_pin_hil LANGUAGES {langs})\n"
            f"add_subdirectory(\"{export.resolve().as_posix()}\" ctrl)\n"
            "add_executable(rrr_pin_hil hil_harness.c)\n"
            "set_target_properties(rrr_pin_hil PROPERTIES C_STANDARD 11 C_EXTENSIONS ON)\n"
            "target_compile_options(rrr_pin_hil PRIVATE -Wall -Wextra -Werror)\n"
            "target_link_libraries(rrr_pin_hil PRIVATE rrr_pin_ctrl)\n" + link).encode())
        configure = [cmake, "-S", str(src), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release",
                     f"-DRRR_PIN_PYTHON={sys.executable}"]
        steps = [[cmake, "--build", str(build), "--target", "rrr_pin_hil"]]
        if not (build / "CMakeCache.txt").is_file():
            steps.insert(0, configure)
        for cmd in steps:
            done = subprocess.run(cmd, capture_output=True, text=True, check=False)
            if done.returncode:
                shutil.rmtree(build, ignore_errors=True)  # a failed tree is not kept
                raise RuntimeError(f"{' '.join(cmd)} failed ({done.returncode}):\n"
                                   f"{done.stdout[-3000:]}{done.stderr[-3000:]}")
        exe = work / "rrr_pin_hil"
        shutil.copy2(build / "rrr_pin_hil", exe)
    return exe


def _run(exe: Path, mode: str, settings: Path, out: Path, n: int, cycles: int,
         holds: Path | None = None):
    """Run the harness; return (q, tau, timing or None, header dict, wall seconds)."""
    start = time.perf_counter()
    extra = [str(holds)] if holds is not None else []
    # the harness ends with this process however it ends (PR_SET_PDEATHSIG on this pid)
    env = {**os.environ, "RRR_PIN_HIL_PARENT": str(os.getpid())}
    done = subprocess.run([str(exe), mode, str(settings), str(out), *extra],
                          capture_output=True, text=True, check=False, env=env)
    wall = time.perf_counter() - start
    if done.returncode:
        raise RuntimeError(f"the {mode} harness failed ({done.returncode}): "
                           f"{done.stderr.strip() or done.stdout.strip()}")
    words = done.stdout.split()
    header = {words[i]: int(words[i + 1]) for i in range(0, len(words) - 1, 2)}
    raw = out.read_bytes()
    size = n * cycles * 8
    q = np.frombuffer(raw[:size], dtype=float).reshape(cycles, n)
    tau = np.frombuffer(raw[size:2 * size], dtype=float).reshape(cycles, n)
    timing = None
    if mode == "hil":
        timing = np.frombuffer(raw[2 * size:], dtype=[("wake", "<i8"), ("done", "<i8"),
                                                       ("step", "<i8"), ("late", "<i4"),
                                                       ("pad", "<i4")])
    return q, tau, timing, header, wall


def _percentiles(ns: np.ndarray) -> dict:
    us = ns.astype(float) / 1e3
    out = {k: float(np.percentile(us, p)) for k, p in _PERCENTILES.items()}
    out["max"] = float(us.max())
    return out


def _loadavg() -> list[float] | None:
    try:
        return [float(v) for v in Path("/proc/loadavg").read_text().split()[:3]]
    except OSError:
        return None


def hil(folder, cycles: int, out, *, rate: float | None = None, effects=None,
        overwrite: bool = False) -> HilResult:
    """Run an exported controller in real time against its nominal arm; write ``hil.json``.

    Parameters
    ----------
    folder : path-like
        A folder written by :func:`rrr_pin.export` (built here again, with the harness).
    cycles : int
        Control periods to run, 1 to :data:`MAX_CYCLES`.
    out : path-like
        Output folder, claimed as :mod:`rrr_pin.outputs` says: ``hil.json`` and
        ``hil_run.json``.
    rate : float, optional
        The harness's clock [Hz]; default the law's own rate (``rate_hz`` of
        ``controller.json``). The arm always advances one law period ``Ts`` a cycle: a faster
        clock runs the same closed loop faster than real time (recorded in ``hil_run.json``).
    effects : PlantEffects, optional
        The simulated arm's effects (:class:`rrr_pin.control.effects.PlantEffects`), realized
        as the engines do with one RK4 step per law period: ``delay`` (a whole number of law
        periods), ``bandwidth`` (first-order actuator), ``viscous``/``coulomb`` friction. The
        others (torque limit, noise, encoder, flexible joints) are refused by name. A loop that
        diverges (the engines' test) stops there: ``hil.json`` ``"status": "diverged"`` and
        ``"diverged_at_s"``.
    overwrite : bool, default False
        Replace a previous ``hil`` run in ``out``.

    Returns
    -------
    HilResult

    Raises
    ------
    FileNotFoundError
        Not an exported folder; no ``cmake``.
    ValueError
        ``cycles`` or ``rate`` out of range; a clock period shorter than one offline cycle of
        the law and the arm (the loop could meet no deadline: refused before the real-time run,
        naming both figures); a model that cannot be loaded by its recorded name.
    RuntimeError
        The build or the harness failed.
    """
    from ..control.effects import PlantEffects
    from ..sim.trajectory import VELOCITY_LIMIT

    folder = Path(folder)
    cycles = check_count("cycles", cycles, 1, MAX_CYCLES)
    record = check_export(folder)
    law_rate = float(record["rate_hz"])
    rate = law_rate if rate is None else check_rate("rate", rate)
    robot = _robot(record, folder)
    effects = PlantEffects() if effects is None else effects
    if not isinstance(effects, PlantEffects):
        raise TypeError(f"effects must be a PlantEffects, got {type(effects).__name__}")
    fx = effects.resolve(robot, 1, 1.0 / law_rate, cycles)
    unsupported = [name for name, on in (
        ("torque_limit", fx.limit is not None), ("noise_q", fx.noise_q is not None),
        ("noise_qd", fx.noise_qd is not None), ("encoder_counts", bool(fx.quantum)),
        ("stiffness", fx.Kf is not None)) if on]
    if unsupported:
        raise FieldError(unsupported[0], f"{{name}}: hil's simulated arm realizes the delay, "
                                         f"the actuator bandwidth and friction only; drop "
                                         f"{', '.join(unsupported)}")
    d = fx.delay_steps
    fv = fx.Fv if fx.Fv is not None else np.zeros(robot.nq)
    fc = fx.Fc if fx.Fc is not None else np.zeros(robot.nq)
    from ..control.references import default_reference

    ref = default_reference(robot)
    r0, rd0, _ = ref(0.0)
    n = int(record["nq"])
    lines = [f"{cycles} {round(1e9 / rate)} {1.0 / law_rate!r} {d} {VELOCITY_LIMIT!r} "
             f"{float(fx.wa or 0.0)!r} {float(fx.veps)!r}"]
    for j in range(n):
        lines.append(" ".join(repr(float(v)) for v in (ref.home[j], ref.amp[j], ref.freq[j],
                                                       ref.phase[j], r0[j], rd0[j],
                                                       robot.lower[j], robot.upper[j], fv[j],
                                                       fc[j])))
    settings = {"folder": str(folder), "cycles": cycles, "rate": rate, "law_rate": law_rate,
                "effects": effects.to_dict()}
    with OutputDir.claim(out, "hil", overwrite=overwrite, settings=settings,
                         option="out") as claimed, \
            tempfile.TemporaryDirectory(prefix="rrr-pin-hil-") as tmp:
        work = Path(tmp)
        exe = _build(folder, work, record["model"]["dynamics"], record["model"]["fingerprint"])
        (work / "settings.txt").write_text("\n".join(lines) + "\n")
        q_off, tau_off, _, off_header, wall_off = _run(exe, "offline", work / "settings.txt",
                                                       work / "offline.bin", n, cycles)
        per_cycle = wall_off / cycles
        if per_cycle > 1.0 / rate:
            raise FieldError("rate", f"{{name}} = {rate:g} Hz: one cycle of the law and the "
                                     f"simulated arm took {per_cycle * 1e6:.1f} us offline, "
                                     f"longer than the period {1e6 / rate:.1f} us; no deadline "
                                     f"could be met: give a slower rate")
        load_before = _loadavg()
        q_hil, tau_hil, timing, header, wall_hil = _run(exe, "hil", work / "settings.txt",
                                                        work / "hil.bin", n, cycles)
        load_after = _loadavg()
        # the same offline loop with the torques the arm held replayed: equal bit for bit
        missed = timing["done"] > round(1e9 / rate)
        (work / "holds.bin").write_bytes(missed.astype(np.uint8).tobytes())
        q_rep, _, _, rep_header, _ = _run(exe, "offline", work / "settings.txt",
                                          work / "replay.bin", n, cycles, work / "holds.bin")
        if rep_header["missed"] != header["missed"]:
            raise RuntimeError(f"the harness counted {header['missed']} missed deadlines, its "
                               f"timing {rep_header['missed']}")
        if rep_header["diverged"] != header["diverged"]:
            raise RuntimeError(f"the real-time loop diverged at cycle {header['diverged']}, "
                               f"its replay at {rep_header['diverged']}")
        summary = _summary(cycles, header, timing, rate, q_hil, q_off, law_rate)
        ran = cycles if header["diverged"] < 0 else header["diverged"] + 1
        # the offline loop keeps its own length: a real-time run that diverged on held torques
        # (missed deadlines) does not cut the loop that had none
        ran_off = cycles if off_header["diverged"] < 0 else off_header["diverged"] + 1
        both = min(ran, ran_off)
        q_hil, q_off, q_rep = q_hil[:ran], q_off[:ran_off], q_rep[:ran]
        tau_hil, tau_off = tau_hil[:ran], tau_off[:ran_off]
        r = ref.sample(np.arange(ran) / law_rate)[0]
        r_off = ref.sample(np.arange(ran_off) / law_rate)[0]
        run = {
            "folder": str(folder), "law": record["law"]["name"], "model": robot.name,
            "law_rate_hz": law_rate, "clock_rate_hz": rate,
            "real_time_factor": rate / law_rate,
            "sched_fifo": bool(header.get("sched_fifo")), "mlockall": bool(header.get("mlockall")),
            "plant_sched_fifo": bool(header.get("plant_sched_fifo")),
            "plant_mlockall": bool(header.get("plant_mlockall")),
            "loadavg_before": load_before, "loadavg_after": load_after, "cpus": os.cpu_count(),
            "wall_s": wall_hil, "offline_wall_s": wall_off,
            "step_us": _percentiles(timing["step"]), "wake_us": _percentiles(timing["wake"]),
            "state_late": int(timing["late"].sum()),
            "torque_max_diff_vs_offline_Nm": float(np.max(np.abs(tau_hil[:both]
                                                                 - tau_off[:both]))),
            "max_error_vs_replay_rad": float(np.max(np.abs(q_hil - q_rep))),
            "max_tracking_error_rad": {"hil": float(np.max(np.abs(q_hil - r))),
                                       "offline": float(np.max(np.abs(q_off - r_off)))},
            "reference": ref.to_dict(),
            "plant": "the export's nominal model (dynamics.h), RK4 of Ts per cycle, torque "
                     "held; a torque written after the next tick is not applied (the "
                     "previous one is held); the drive adds what the torque convention "
                     "removes (ctrl_removed_torque)",
            "delay_s": d / law_rate, "delay_periods": d, "effects": fx.info,
            "command": (record.get("command") or {"name": "full"})["name"],
            "offline_diverged_at_s": (None if off_header["diverged"] < 0
                                      else (off_header["diverged"] + 1) / law_rate),
            "offline": "the same harness and arithmetic in one process, no clock",
        }
        for name, data in (("hil.json", summary), ("hil_run.json", run)):
            path = claimed.path / name
            with writing(path):
                path.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
    return HilResult(summary, run, q_hil.copy(), q_off.copy(), q_rep.copy())


def _summary(cycles, header, timing, rate, q_hil, q_off, law_rate) -> dict:
    """``hil.json``: ``cycles``, ``missed``, ``latency_us``, ``jitter_us``, the error, status.

    A loop that diverged at cycle ``k`` ran ``k + 1`` cycles: the figures are theirs, and
    ``diverged_at_s`` is the end of that cycle's period, ``(k + 1) Ts`` (as the engines date a
    sampled run's divergence); None when the loop held.
    """
    k = int(header["diverged"])
    ran = cycles if k < 0 else k + 1
    wake = timing["wake"][:ran].astype(float)
    jitter = float(np.max(np.abs(np.diff(wake)))) / 1e3 if ran > 1 else 0.0
    err = np.abs(q_hil[:ran] - q_off[:ran])
    return {"cycles": cycles, "missed": int(header["missed"]),
            "latency_us": _percentiles(timing["done"][:ran]), "jitter_us": jitter,
            "max_error_vs_offline_rad": float(np.max(err)) if np.isfinite(err).all()
            else float("inf"),
            "status": "completed" if k < 0 else "diverged",
            "diverged_at_s": None if k < 0 else ran / law_rate}
