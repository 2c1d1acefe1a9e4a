"""Benchmark: every figure of issue 13, each with its ratio and goal, measured side by side.
=========================================================================================

Everything is measured in one run on this machine (named in the output) and printed, never
asserted:

- section 1: per call from Python: ``Robot.M/V/G`` (checked and ``check=False``) against the bare
  ``pin`` calls they make, and the paper's closed form (``rrr_pin.model.closed_form``);
- section 2: the compiled engine: a 10 s rollout of the nominal RRR for every built-in law (FL,
  H-inf + FL, PD + gravity), sampled at 1 kHz (zero-order hold, RK4 plant) and continuous (RK4, law
  at every stage, dt = 1 ms), with every reference kind (sine, quintic, spline, task-space line),
  against the C++ floor (``rrr_pin.sim.compiled.floor_ms``: the same Pinocchio calls in a bare C++
  loop);
- section 2b/2c: engine ``"codegen"`` (parameter-input generated dynamics,
  :mod:`rrr_pin.sim.batched`) on the nominal RRR, and per-plant rollouts of uncertain RRR, UR5 and
  Panda plants on the compiled engine, the generated dynamics and 16 plants per batched call, with
  their floors;
- section 3: the Python engine (``simulate(..., engine="python")``) against a hand-written loop that
  calls ``pin`` directly (:func:`handwritten_fl_rollout`, the yardstick): 10 s, 1 kHz, ZOH FL;
- section 4: a Monte Carlo campaign (N plants x 2 laws, 10 s, 2 worker processes; batched under
  ``engine="auto"``) against its bounds ``2 N x floor / 2 cores`` (generic and batched floors), and
  the throughput with 1 worker;
- section 4b: a closed chain (issue 22): a 10 s, 1 kHz FL run of the 5-bar on the Python and the
  compiled engines, against the ``pin.constraintDynamics`` calls the Python engine makes, alone
  (4 per RK4 step), and the compiled engine's exact-KKT calls alone in C++;
- section 4c (issue 33): the campaign (N plants x (FL, H-inf + FL)) against the batched engine's
  own floor, the C++ loop alone on the same plants (the time inside ``batch_rollout``), in one
  process, with ``jobs=2`` and with ``threads=2``, its CPU share outside that loop, on the RRR
  and the Panda (``--panda-samples``), and the xArm7 and the z1 at first use in an empty cache
  (the one-time build time; not under ``--quick``);
- section 4d (issue 44): the MuJoCo engine (``engine="mujoco"``, the plant stepped by MuJoCo,
  the laws in Python) on a campaign of N uncertain RRR plants x (FL, H-inf + FL), next to the
  same campaign on the batched engine (``engine="auto"``), each in a fresh process (its peak
  RSS), one job; with the load average, and the time scaled to 1000 plants
  (``--mujoco-samples``; skipped without MuJoCo);
- section 5: start-up: ``rrr-pin --help`` and ``python -c "import rrr_pin"`` in fresh processes;
- section 6: ``rrr_pin.robust.loopshaping.loopsyn`` on a coupled 3 x 3 plant
  (:func:`loopsyn_3x3_s`);
- section 7: the mu upper bound (``rrr_pin.robust.mu.mussv``) on the frozen FL loop of the RRR with
  its inertial parameters real-uncertain (``rrr_pin.control.analysis.parametric_loop``), per
  frequency, against issue 21's goal of 0.5 s;
- section 8: identification of the UR5 from 10 s of 1 kHz data, the consistency SDP included;
- section 9: with ``--export`` (CMake builds, minutes): one ``ctrl_step`` of the exported H-inf + FL
  law (:func:`rrr_pin.export`) for the RRR (generated dynamics) and UR5 (Pinocchio C++), against the
  same Pinocchio calls alone (``ctrl_dyn_crba`` + ``ctrl_dyn_nle`` of a Pinocchio export of the same
  arm: CRBA and NLE, M's triangle mirrored, nle copied out), in a C loop; and ``ctrl_step_dt`` at
  periods off the nominal one (K discretized at each call).
- section 10 (issue 34): ``rrr_pin.tune`` of the RRR's order-2 K and lam against five requirements
  over 20 plants (grid search), and one evaluation with the grid screened
  (``rrr_pin.control.grid_bounds``) against LAPACK at every grid point, at the same points.

Usage::

    python scripts/bench.py                  # table
    python scripts/bench.py --json           # one JSON object
    python scripts/bench.py --campaign-samples 1000   # the campaign of issue 13's table
    python scripts/bench.py --quick          # seconds, to check that it runs
    python scripts/bench.py --sections 2,2b,2c,4b   # the engines' sections alone
    python scripts/bench.py --sections 4c --campaign-samples 1000 --panda-samples 1000
    python scripts/bench.py --sections 4d --mujoco-samples 10   # the MuJoCo engine's campaign
    python scripts/bench.py --export         # also section 9 (builds three exports)
"""

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import time
import timeit
from pathlib import Path

import control
import numpy as np
import pinocchio as pin

import rrr_pin
from rrr_pin.campaign.montecarlo import CampaignSettings, run_campaign
from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.control.references import (
    LinePath,
    QuinticReference,
    SplineReference,
    default_reference,
    task_space_reference,
)
from rrr_pin.model import closed_form
from rrr_pin.model.dynamics import robot_from_xml
from rrr_pin.model.robots import nominal_params
from rrr_pin.model.uncertainty import sample_plant
from rrr_pin.sim.batched import GENERATED
from rrr_pin.sim.batched import floor_ms as batch_floor_ms
from rrr_pin.sim.compiled import floor_ms
from rrr_pin.sim.simulation import simulate, simulate_batch

#: Issue 13's goals: (largest ratio, what it is a ratio of). Start-up goals are in seconds.
GOALS = {
    "compiled": 1.2,  # compiled rollout / C++ floor
    "campaign": 1.1,  # campaign wall time / (2 N floor / 2 cores)
    "batched_rrr": 20.0,  # compiled / batched per-plant rollout, RRR (issue 23): at least
    "batched_ur5": 5.0,  # the same for UR5: at least
    "campaign_batched": 1.2,  # campaign wall time / (2 N batched floor / 2 cores)
    "campaign_1000_s": 5.0,  # 1000-plant RRR campaign, 2 laws, 2 jobs [s]: under
    "campaign_floor": 1.2,  # campaign wall time / (its own C++ loop time / 2 cores) (issue 33)
    "campaign_1000_2cores_s": 4.0,  # 1000-plant RRR campaign on 2 cores [s] (issue 33)
    "campaign_panda_1000_s": 15.0,  # the same on the Panda [s] (issue 33)
    "python": 1.5,  # Python engine / hand-written loop
    "robot_call": 2.0,  # Robot.M/V/G / bare pin call
    "cli_help_s": 0.3,
    "import_s": 0.6,
    "loopsyn_3x3_s": 5.0,  # issue 21
    "export_rrr_us": 2.0,  # exported ctrl_step of the RRR, generated dynamics [us]
    "export_ur5": 1.5,  # exported ctrl_step of UR5 / its Pinocchio calls alone
}

#: Section 6: a C loop timing ctrl_step and the dynamics calls alone of an exported folder.
EXPORT_BENCH_C = r"""
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "controller.h"
#include "dynamics.h"
#define NS 64
static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}
/* argv[1] calls per round; prints the fastest round of ctrl_step, of the dynamics calls
 * alone and of ctrl_step_dt at periods inside +-10 % (never the nominal one: K discretized at
 * each) [us per call], the rounds interleaved so that a shared machine's load falls on all */
int main(int argc, char **argv)
{
    long calls = argc > 1 ? atol(argv[1]) : 100000, k;
    static double q[NS][CTRL_NQ], qd[NS][CTRL_NQ], r[NS][CTRL_NQ], tau[CTRL_NQ];
    static double M[CTRL_NQ * CTRL_NQ], h[CTRL_NQ];
    double sink = 0.0, t0, best[3] = {1e9, 1e9, 1e9};
    unsigned s = 12345u;
    ctrl_state st;
    int i, j, rep, mode;
    for (i = 0; i < NS; ++i) {
        for (j = 0; j < CTRL_NQ; ++j) {
            s = 1664525u * s + 1013904223u;
            q[i][j] = (s / 4294967296.0 - 0.5) * 3.0;
            s = 1664525u * s + 1013904223u;
            qd[i][j] = (s / 4294967296.0 - 0.5) * 2.0;
            r[i][j] = q[i][j] + 0.01;
        }
    }
    ctrl_reset(&st);
    for (rep = 0; rep < 10; ++rep) {
        for (mode = 0; mode < 3; ++mode) {
            t0 = now();
            for (k = 0; k < calls; ++k) {
                i = (int)(k % NS);
                if (mode == 0) {
                    ctrl_step(&st, q[i], qd[i], r[i], qd[i], qd[i], tau);
                    sink += tau[0];
                } else if (mode == 2) {
                    ctrl_step_dt(&st, q[i], qd[i], r[i], qd[i], qd[i], tau,
                                 CTRL_PERIOD * (0.9 + 0.2 * (double)(k % 7) / 7.0));
                    sink += tau[0];
                } else {
                    ctrl_dyn_crba(q[i], M);
                    ctrl_dyn_nle(q[i], qd[i], h);
                    sink += M[0] + h[0];
                }
            }
            t0 = (now() - t0) / calls;
            if (t0 < best[mode]) best[mode] = t0;
        }
    }
    printf("%.6f %.6f %.6f %g\n", 1e6 * best[0], 1e6 * best[1], 1e6 * best[2], sink);
    return 0;
}
"""


def export_step_us(calls: int, out: Path) -> dict:
    """Section 6: one exported ctrl_step [us] against the same Pinocchio calls alone.

    Builds (CMake, Release) the H-inf + FL export of the RRR with generated dynamics, of the
    RRR with Pinocchio dynamics and of UR5, links :data:`EXPORT_BENCH_C` to each shared
    library, and takes the fastest of 10 interleaved rounds of ``calls`` calls of each, cycling
    over 64 states. A folder already built with its bench program (a previous run) is reused.
    """
    from rrr_pin.deploy.loaded import build

    def timed(folder: Path) -> tuple:
        lib = build(folder).parent
        exe = folder / "bench_ctrl"
        (folder / "bench_ctrl.c").write_text(EXPORT_BENCH_C)
        subprocess.run(["cc", "-O2", "-std=c99", "-D_POSIX_C_SOURCE=199309L", f"-I{folder}",
                        str(folder / "bench_ctrl.c"), f"-L{lib}", "-lrrr_pin_ctrl_shared",
                        f"-Wl,-rpath,{lib}", "-o", str(exe)], check=True)
        done = subprocess.run([str(exe), str(calls)], check=True, capture_output=True,
                              text=True)
        return tuple(float(v) for v in done.stdout.split()[:3])

    rows = {}
    for arm, dynamics in (("rrr", "generated"), ("rrr", "pinocchio"), ("ur5", "pinocchio")):
        robot = rrr_pin.load_robot(arm)
        folder = out / f"{arm}_{dynamics}"
        if not (folder / "build" / "bench_ctrl").exists():  # a previous run's build is reused
            rrr_pin.export("hinf", robot, 1000.0, folder, dynamics=dynamics, overwrite=True)
        step_us, calls_us, step_dt_us = timed(folder)
        rows[f"{arm}_{dynamics}"] = {"ctrl_step_us": step_us, "dynamics_calls_us": calls_us,
                                     "ctrl_step_dt_us": step_dt_us}
    return {"rrr_ctrl_step_us": rows["rrr_generated"]["ctrl_step_us"],
            "rrr_ctrl_step_dt_us": rows["rrr_generated"]["ctrl_step_dt_us"],
            "ur5_ctrl_step_dt_us": rows["ur5_pinocchio"]["ctrl_step_dt_us"],
            "rrr_pinocchio_calls_us": rows["rrr_pinocchio"]["dynamics_calls_us"],
            "ur5_ctrl_step_us": rows["ur5_pinocchio"]["ctrl_step_us"],
            "ur5_pinocchio_calls_us": rows["ur5_pinocchio"]["dynamics_calls_us"],
            "ur5_ratio": (rows["ur5_pinocchio"]["ctrl_step_us"]
                          / rows["ur5_pinocchio"]["dynamics_calls_us"]),
            "rows": rows, "calls": calls, "load_avg_1min": os.getloadavg()[0]}

# The paper's H-infinity controller, eq. (18) (as rrr_pin.design().K_reduced reproduces it).
K18 = control.tf([47.40, 47.40 * (134.75 + 12.17), 47.40 * 134.75 * 12.17],
                 [1.0, 513.37 + 0.19, 513.37 * 0.19])


def per_call_us(fn, number):
    """Fastest of 5 repeats of the time of one call [us] (the least disturbed, as timeit says)."""
    times = timeit.repeat(fn, number=number, repeat=5)
    return 1e6 * min(times) / number


def side_by_side_ms(fns: dict, repeat: int) -> dict:
    """Fastest wall time [ms] of each callable over ``repeat`` interleaved rounds.

    One warm-up call each, then ``repeat`` rounds that call every function once in turn, so
    that the load of a shared machine falls on all of them alike; the fastest run of each is
    the least disturbed one (as :func:`rrr_pin.sim.compiled.floor_ms` takes it). A callable whose
    name starts with ``"floor"`` returns its own time [ms] (the C++ timer).
    """
    for fn in fns.values():
        fn()
    best = dict.fromkeys(fns, float("inf"))
    for _ in range(repeat):
        for key, fn in fns.items():
            t0 = time.perf_counter()
            out = fn()
            ms = out if key.startswith("floor") else 1e3 * (time.perf_counter() - t0)
            best[key] = min(best[key], ms)
    return best


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    return (f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"pin {pin.__version__}, numpy {np.__version__}; load average {load} at start")


def handwritten_fl_rollout(plant, nominal, lam, R, RD, RDD, Ts, n_steps):
    """Run the yardstick: 10 s of ZOH FL written directly on ``pin``, as a user would.

    Per control period ``Ts``: ``tau = Mhat (rdd + 2 lam (rd - qd) + lam^2 (r - q)) + nle_hat``
    (eq. 20 with feed-forward), then one classical RK4 step of the plant's ABA with ``tau`` held.
    No validation and no divergence test. Returns the positions, shape (n_steps + 1, n) [rad].
    """
    pm, pd, nm, nd = plant.model, plant.data, nominal.model, nominal.data
    crba, nle, aba = pin.crba, pin.nonLinearEffects, pin.aba
    h, h2, h6 = Ts, 0.5 * Ts, Ts / 6.0
    q, qd = R[0].copy(), RD[0].copy()
    Q = np.empty((n_steps + 1, plant.nq))
    Q[0] = q
    for k in range(n_steps):
        taubar = RDD[k] + 2.0 * lam * (RD[k] - qd) + lam * lam * (R[k] - q)
        tau = crba(nm, nd, q) @ taubar + nle(nm, nd, q, qd)
        a1 = aba(pm, pd, q, qd, tau)
        v2 = qd + h2 * a1
        a2 = aba(pm, pd, q + h2 * qd, v2, tau)
        v3 = qd + h2 * a2
        a3 = aba(pm, pd, q + h2 * v2, v3, tau)
        v4 = qd + h * a3
        a4 = aba(pm, pd, q + h * v3, v4, tau)
        q = q + h6 * (qd + 2.0 * (v2 + v3) + v4)
        qd = qd + h6 * (a1 + 2.0 * (a2 + a3) + a4)
        Q[k + 1] = q
    return Q


def closed_chain_ms(duration, rate, repeat):
    """Issue 22: a closed-loop FL run of the 5-bar on both engines, against its KKT calls alone.

    The run: ``simulate`` of the FL law on the reduced model, 1 sub-step per period, on the
    Python engine and on the compiled one (:mod:`rrr_pin.sim.compiled`). The floors: the
    ``4 x steps`` ``pin.constraintDynamics`` calls the Python engine's RK4 plant makes, in a
    bare Python loop, and as many exact-KKT accelerations of the compiled engine in a bare C++
    loop. The Python engine runs twice (a warm-up and one timed run: 15 s each), the others
    ``repeat`` times, interleaved.
    """
    from rrr_pin.control.laws import fl_controller
    from rrr_pin.control.references import SineReference
    from rrr_pin.model.closed_chain import load_closed_chain
    from rrr_pin.sim.compiled import acceleration_ms

    plant, nominal = load_closed_chain("fivebar"), load_closed_chain("fivebar")
    ref = SineReference(home=plant.neutral(), amp=0.05, freq=0.5, phase=0.0)
    law = fl_controller(nominal)
    q, qd = plant.home, plant.velocity(plant.home, np.array([0.1, -0.1]))
    tau = np.array([0.1, 0.1])
    u = plant.actuation(tau)
    calls = 4 * int(round(duration * rate))

    def calls_alone():
        for _ in range(calls):
            plant.constrained_acceleration(q, qd, u)

    fast = side_by_side_ms(
        {"compiled": lambda: simulate(plant, law, ref, duration, rate=rate, engine="compiled"),
         "calls": calls_alone,
         "floor_kkt": lambda: acceleration_ms(plant, q, qd, tau, calls, repeat=1)}, repeat)
    slow = side_by_side_ms(
        {"python": lambda: simulate(plant, law, ref, duration, rate=rate, engine="python")}, 1)
    traj = {e: simulate(plant, law, ref, duration, rate=rate, engine=e)
            for e in ("python", "compiled")} if duration <= 1.0 else None
    return {"closed_chain_rollout_ms": slow["python"],
            "closed_chain_compiled_ms": fast["compiled"],
            "constraint_dynamics_floor_ms": fast["calls"],
            "closed_chain_kkt_floor_ms": fast["floor_kkt"],
            "closed_chain_goal_ms": 300.0 * duration / 10.0, "closed_chain_engine": "compiled",
            "closed_chain_engines_max_diff_rad": (
                float(np.abs(traj["python"].q - traj["compiled"].q).max()) if traj else None)}


def references(robot, duration):
    """One reference of each kind for the RRR, inside its limits, over ``duration`` [s]."""
    move = min(2.0, duration)
    q_start = np.array([0.3, -0.6, 1.0])
    pin.framesForwardKinematics(robot.model, robot.data, q_start)
    p0 = robot.data.oMf[robot.model.getFrameId("ee")].translation.copy()
    times = np.linspace(0.0, duration, 6)
    waypoints = 0.5 * np.sin(np.outer(times, [1.0, 1.7, 2.3]) + [0.0, 1.0, 2.0])
    return {
        "sine": default_reference(robot),
        "quintic": QuinticReference(start=[0.2, -0.5, 0.8], goal=[0.9, 0.3, -0.2],
                                    move_time=move),
        "spline": SplineReference(times=times, waypoints=waypoints),
        "line": task_space_reference(robot, "ee", LinePath(p0, p0 + [-0.3, 0.2, 0.25]),
                                     move_time=move, q_start=q_start),
    }


def subprocess_s(cmd, repeat):
    """Median wall time [s] of a fresh process running ``cmd``."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def batch_row(arm, args, n_steps):
    """Section 2c for one arm: per-plant rollout times and floors [ms], side by side."""
    source, lock = GENERATED[arm]
    nominal = rrr_pin.load_robot(source, lock=dict(lock))
    law = make_laws("hinf" if arm == "rrr" else "fl", nominal,
                    K=K18 if arm == "rrr" else None)[0]
    ref = default_reference(nominal)
    src = nominal_params(nominal) or nominal.urdf
    plants = [robot_from_xml(sample_plant(src, 0, k).urdf, gravity=nominal.gravity,
                             lock=dict(lock), name=f"sample{k}", check=False) for k in range(16)]
    kind = law.compiled_form().kind
    go = {"rate": args.rate}
    ms = side_by_side_ms({
        "compiled": lambda: simulate(plants[0], law, ref, args.duration, engine="compiled", **go),
        "codegen": lambda: simulate(plants[0], law, ref, args.duration, engine="codegen", **go),
        "batched": lambda: simulate_batch(plants, law, ref, args.duration, batch=16, **go),
        "floor": lambda: floor_ms(plants[0], nominal, n_steps, repeat=1, kind=kind),
        "floor_codegen": lambda: batch_floor_ms(plants[0], nominal, n_steps, repeat=1,
                                                kind=kind),
        "floor_batched": lambda: batch_floor_ms(plants[0], nominal, n_steps, repeat=1,
                                                kind=kind, batch=16),
    }, args.repeat)
    ms["batched"] /= 16  # per plant
    a = simulate(plants[1], law, ref, args.duration, engine="compiled", **go)
    b = simulate_batch(plants, law, ref, args.duration, batch=16, **go)[1]
    return {"robot": arm, "law": law.name, **{f"{k}_ms": v for k, v in ms.items()},
            "compiled_vs_batched": ms["compiled"] / ms["batched"],
            "compiled_vs_codegen": ms["compiled"] / ms["codegen"],
            "max_diff_rad": float(np.abs(a.q - b.q).max())}


def loop_on_cores(robot, laws, settings, threads: int) -> float:
    """Wall time [s] of the batched C++ loops alone on ``threads`` threads, the campaign's plants.

    The plants of the campaign (the nominal and samples ``0 .. N-1``, the same seeded draws)
    are drawn and their runs prepared first, untimed; then each law's batches run on
    ``threads`` threads (the GIL released) and only the calls into C++ are timed: what no
    campaign on these cores can beat, with whatever the cores lose running together (a
    shared cache, the clock) included, unlike ``floor / threads``.
    """
    from rrr_pin.campaign.runner import run_laws_batch
    from rrr_pin.control.references import study_reference
    from rrr_pin.sim import batched

    plants = [robot] + [robot.perturbed(np.random.default_rng([settings.seed, k]),
                                        settings.tolerances)[0]
                        for k in range(settings.samples)]
    spent = [0.0]
    original = batched._map

    def timed(fn, items, n):
        t0 = time.perf_counter()
        out = list(original(fn, items, n))
        spent[0] += time.perf_counter() - t0
        return out

    batched._map = timed
    try:
        run_laws_batch(plants, laws, study_reference(robot, settings.run.duration), settings.run,
                       batch=16, threads=threads, figures=True)
    finally:
        batched._map = original
    return spent[0]


def _engine_campaign(engine, samples, duration, rate) -> dict:
    """One campaign of ``samples`` RRR plants x (FL, H-inf + FL) on ``engine``, in this process."""
    import resource

    robot = rrr_pin.load_robot("rrr")
    laws = make_laws("fl,hinf", robot)
    settings = CampaignSettings(samples=samples, seed=0, baseline="fl",
                                run=RunSettings(duration=duration, rate=rate, engine=engine))
    load = [os.getloadavg()[0]]
    t0 = time.perf_counter()
    rows = run_campaign(robot, laws, settings, jobs=1).rows
    seconds = time.perf_counter() - t0
    load.append(os.getloadavg()[0])
    return {"s": seconds, "load_avg": load,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "engines": sorted({v for r in rows for k, v in r.items() if k.endswith("_engine")})}


def mujoco_campaign(samples, duration, rate, fresh: bool = True) -> dict:
    """Section 4d (issue 44): the MuJoCo engine's campaign next to the batched engine's.

    Each campaign runs in a fresh process (``spawn``), so each peak RSS is its own; with
    ``fresh=False`` (``--quick``) both run in this process (the peak RSS is then this one's).
    """
    import concurrent.futures
    import importlib.util
    import multiprocessing

    if importlib.util.find_spec("mujoco") is None:
        return {"samples": samples, "skipped": "MuJoCo not installed (pip install "
                                               "'rrr-pin[mujoco]')"}
    engines = {}
    for engine in ("auto", "mujoco"):
        if not fresh:
            engines[engine] = _engine_campaign(engine, samples, duration, rate)
            continue
        with concurrent.futures.ProcessPoolExecutor(
                1, mp_context=multiprocessing.get_context("spawn")) as pool:
            engines[engine] = pool.submit(_engine_campaign, engine, samples, duration,
                                          rate).result()
    return {"samples": samples, "engines": engines, "fresh_processes": fresh,
            "ratio": engines["mujoco"]["s"] / engines["auto"]["s"]}


def campaign_at_floor(robot, names, samples, duration, rate) -> dict:
    """Section 4c (issue 33): a campaign against the batched engine's own C++ loop on its plants.

    The floor is the wall time spent inside the batched C++ rollouts (``batch_rollout``, or
    ``batch_figures``, the loop that reduces each run to its row's figures as it goes; the GIL
    released) during a one-process, one-thread campaign on the same plants: the loop alone,
    without drawing plants, preparing runs or making rows. The campaign then runs with 2
    processes (``jobs=2``) and with 1 process of 2 threads (``threads=2``); each ratio is its
    wall time over ``floor / 2 cores``.
    """
    from rrr_pin.sim.extension import EXTENSION

    laws = make_laws(names, robot)
    settings = CampaignSettings(samples=samples, seed=0, baseline=laws[0].name,
                                run=RunSettings(duration=duration, rate=rate))
    inner = {"s": 0.0, "cpu": 0.0}
    # the loop with its trajectories, or reduced to the row's figures in C++ (a campaign's)
    originals = {key: getattr(EXTENSION, key) for key in ("batch_rollout", "batch_figures")}

    def timer(original):
        def timed(*a, **k):
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                return original(*a, **k)
            finally:
                inner["s"] += time.perf_counter() - t0
                inner["cpu"] += time.thread_time() - c0
        return timed

    def wall(**kw):
        t0 = time.perf_counter()
        rows = run_campaign(robot, laws, settings, **kw).rows
        return time.perf_counter() - t0, rows

    load = [os.getloadavg()[0]]
    for key, original in originals.items():
        setattr(EXTENSION, key, timer(original))
    c0 = time.process_time()
    try:
        one_s, rows1 = wall(jobs=1, threads=1)
    finally:
        for key, original in originals.items():
            setattr(EXTENSION, key, original)
    one_cpu = time.process_time() - c0
    floor_s = inner["s"]
    t0 = os.times()
    jobs2_s, rows2 = wall(jobs=2, threads=1)
    t1 = os.times()
    # CPU of the 2-process campaign: this process and its (finished, waited-for) workers
    jobs2_cpu = sum(getattr(t1, k) - getattr(t0, k) for k in ("user", "system", "children_user",
                                                              "children_system"))
    threads2_s, rows3 = wall(jobs=1, threads=2)
    floor2_s = loop_on_cores(robot, laws, settings, 2)
    load.append(os.getloadavg()[0])
    engines = sorted({r.get(f"{law.name}_engine", "-") for r in rows1 for law in laws})
    from rrr_pin.sim import dyngen

    ops = dyngen.operation_counts(robot.model)  # the generated code's arithmetic per call
    dynamics = {"fd_algorithm": dyngen.fd_algorithm(ops),
                "operations": {k: v["total"] for k, v in ops.items()},
                "featherstone_aba": dyngen.featherstone_aba_operations(robot.model.nq)}
    return {"robot": robot.name, "samples": samples, "floor_1core_s": floor_s,
            "dynamics": dynamics,
            "one_process_s": one_s, "jobs2_s": jobs2_s, "threads2_s": threads2_s,
            "ratio_jobs2": jobs2_s / (floor_s / 2), "ratio_threads2": threads2_s / (floor_s / 2),
            "ratio_one_process": one_s / floor_s, "rows_identical": rows1 == rows2 == rows3,
            "floor_2cores_s": floor2_s, "ratio_jobs2_2cores": jobs2_s / floor2_s,
            "ratio_threads2_2cores": threads2_s / floor2_s,
            "floor_cpu_s": inner["cpu"], "one_process_cpu_s": one_cpu,
            "ratio_one_process_cpu": one_cpu / inner["cpu"],
            "jobs2_cpu_s": jobs2_cpu, "ratio_jobs2_cpu": jobs2_cpu / inner["cpu"],
            "engines": engines, "load_avg": load}


def verdict(ratio, goal):
    return f"goal <= {goal:g}: {'met' if ratio <= goal else 'NOT MET'}"


def loopsyn_3x3_s(repeat: int = 1) -> float:
    """Fastest of ``repeat`` wall times [s] of ``loopsyn(G, 10/s)``, ``G = fl_plant(45, 3) M``.

    ``M`` couples the joints (a constant 3 x 3 matrix), so the synthesis is truly MIMO.
    """
    from rrr_pin.robust.loopshaping import fl_plant, loopsyn

    M = np.array([[1.0, 0.3, 0.1], [0.2, 1.0, 0.4], [0.1, -0.2, 1.0]])
    G = control.ss(fl_plant(45.0, 3) * control.ss(np.zeros((0, 0)), np.zeros((0, 3)),
                                                  np.zeros((3, 0)), M))
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        loopsyn(G, control.tf(10.0, [1.0, 0.0]))
        best = min(best, time.perf_counter() - t0)
    return best


#: The sections, in order (``--sections``); 9 only with ``--export``.
SECTIONS = ("1", "2", "2b", "2c", "3", "4", "4b", "4c", "4d", "5", "6", "7", "8", "10", "11")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--sections", default=",".join(SECTIONS),
                        help=f"comma-separated sections to run, of {', '.join(SECTIONS)} "
                             f"(default: all); e.g. 2,2b,2c,4b for the engines alone")
    parser.add_argument("--duration", type=float, default=10.0, help="rollout length [s] (10)")
    parser.add_argument("--rate", type=float, default=1000.0, help="control rate [Hz] (1000)")
    parser.add_argument("--repeat", type=int, default=5, help="runs per rollout timing (5)")
    parser.add_argument("--calls", type=int, default=20000, help="calls per per-call timing")
    parser.add_argument("--campaign-samples", type=int, default=100,
                        help="plants of the 2-job campaign (100; issue 13's table: 1000)")
    parser.add_argument("--panda-samples", type=int, default=100,
                        help="Panda plants of section 4c (100; 0 skips; issue 33: 1000)")
    parser.add_argument("--mujoco-samples", type=int, default=10,
                        help="RRR plants of section 4d, the MuJoCo engine's campaign (10; "
                             "scaled to 1000)")
    parser.add_argument("--mc-samples", type=int, default=20,
                        help="plants of the 1-job throughput run (20)")
    parser.add_argument("--startup-repeat", type=int, default=5,
                        help="runs of each start-up timing (5)")
    parser.add_argument("--design-arms", action="store_true",
                        help="section 11: also design --robot panda and ur5 with the defaults "
                             "(minutes each)")
    parser.add_argument("--mc-100k", action="store_true",
                        help="section 11: also montecarlo --samples 100000 on the RRR "
                             "(minutes)")
    parser.add_argument("--scale-samples", type=int, default=1000,
                        help="section 11: plants of the montecarlo command against the "
                             "in-process campaign (1000)")
    parser.add_argument("--quick", action="store_true",
                        help="tiny settings (0.05 s rollouts, 2 plants), to check that it runs")
    parser.add_argument("--export", metavar="DIR", nargs="?", const="bench_export",
                        default=None,
                        help="also section 9, the exported ctrl_step (three CMake builds in DIR, "
                             "bench_export/, minutes)")
    args = parser.parse_args(argv)
    sections = [x.strip() for x in args.sections.split(",") if x.strip()]
    unknown = [x for x in sections if x not in SECTIONS]
    if unknown:
        parser.error(f"--sections: unknown {', '.join(unknown)} (known: {', '.join(SECTIONS)})")
    args.sections = set(sections)
    if args.quick:
        args.duration, args.repeat, args.calls = 0.05, 1, 20
        args.campaign_samples, args.mc_samples, args.startup_repeat = 2, 2, 1
        args.mujoco_samples = 1
        args.panda_samples = 0  # section 4c on the RRR alone, no first-use build
    run = args.sections.__contains__

    robot = rrr_pin.load_robot("rrr")
    params = rrr_pin.paper_params()
    model, data = robot.model, robot.data
    rng = np.random.default_rng(0)
    q, qd = rng.uniform(-np.pi, np.pi, 3), rng.uniform(-5, 5, 3)
    result = {"machine": machine()}
    peaks = SectionPeaks(result, run)   # each section's own peak resident memory

    # 1. Per call. The bare calls are the ones the Robot methods make (V: RNEA with zero
    # acceleration on the zero-gravity copy of the model).
    if run("1"):
        (m0, d0), zero = robot._without_gravity(), np.zeros(robot.nq)
        calls = {
            "M": {"robot": lambda: robot.M(q),
                  "robot_unchecked": lambda: robot.M(q, check=False),
                  "bare": lambda: pin.crba(model, data, q),
                  "closed_form": lambda: closed_form.M(params, q)},
            "V": {"robot": lambda: robot.V(q, qd),
                  "robot_unchecked": lambda: robot.V(q, qd, check=False),
                  "bare": lambda: pin.rnea(m0, d0, q, qd, zero),
                  "closed_form": lambda: closed_form.V(params, q, qd)},
            "G": {"robot": lambda: robot.G(q),
                  "robot_unchecked": lambda: robot.G(q, check=False),
                  "bare": lambda: pin.computeGeneralizedGravity(model, data, q),
                  "closed_form": lambda: closed_form.G(params, q)},
        }
        per_call = {k: {path: per_call_us(fn, args.calls) for path, fn in v.items()}
                    for k, v in calls.items()}
        result.update({"per_call_us": per_call,
                       "robot_call_us": {k: v["robot"] for k, v in per_call.items()},
                       "robot_call_unchecked_us": {k: v["robot_unchecked"]
                                                   for k, v in per_call.items()},
                       "bare_call_us": {k: v["bare"] for k, v in per_call.items()}})

    # 2. Compiled rollouts against the floor, every law x time x reference.
    laws = dict(zip(("fl", "hinf", "pd"), make_laws("fl,hinf,pd", robot, K=K18), strict=True))
    refs = references(robot, args.duration)
    n_steps = int(round(args.duration * args.rate))
    n_rk4 = int(round(args.duration / 1e-3))
    floors = {}
    peaks.mark("1")
    if run("2"):
        compiled_rows = []
        for name, law in laws.items():
            kind = law.compiled_form().kind
            for timing, rate in (("sampled", args.rate), ("continuous", None)):
                steps = n_steps if rate else n_rk4
                for ref_name, ref in refs.items():
                    ms = side_by_side_ms({
                        "compiled": lambda law=law, ref=ref, rate=rate: simulate(
                            robot, law, ref, args.duration, rate=rate, engine="compiled"),
                        "floor": lambda kind=kind, rate=rate, steps=steps: floor_ms(
                            robot, robot, steps, repeat=1, kind=kind, sampled=rate is not None),
                    }, args.repeat)
                    key = kind, timing
                    floors[key] = min(floors.get(key, float("inf")), ms["floor"])
                    compiled_rows.append({"law": name, "time": timing, "reference": ref_name,
                                          "compiled_ms": ms["compiled"],
                                          "floor_ms": ms["floor"],
                                          "ratio": ms["compiled"] / ms["floor"]})
        hinf_sampled = {r["reference"]: r for r in compiled_rows
                        if r["law"] == "hinf" and r["time"] == "sampled"}["sine"]
        fl_sampled = {r["reference"]: r for r in compiled_rows
                      if r["law"] == "fl" and r["time"] == "sampled"}["sine"]
        floor = floors["fl", "sampled"]
        result.update({"compiled_vs_floor": compiled_rows,
                       "floor_ms": floor,
                       "floors_ms": {f"{k}_{t}": v for (k, t), v in floors.items()},
                       "compiled_rollout_ms": {"hinf": hinf_sampled["compiled_ms"],
                                               "fl": fl_sampled["compiled_ms"]}})

    # 2b. Engine "codegen" (issues 13, 23): the same loop on the parameter-input generated
    # dynamics (rrr_pin.sim.batched, one plant per call), against the compiled engine and both
    # floors in the same interleaved rounds; sine reference.
    peaks.mark("2")
    if run("2b"):
        codegen_rows = []
        for name, law in laws.items():
            kind = law.compiled_form().kind
            for timing, rate in (("sampled", args.rate), ("continuous", None)):
                steps = n_steps if rate else n_rk4
                ms = side_by_side_ms({
                    f"{eng}": lambda law=law, rate=rate, eng=eng: simulate(
                        robot, law, refs["sine"], args.duration, rate=rate, engine=eng)
                    for eng in ("compiled", "codegen")} | {
                    "floor": lambda kind=kind, rate=rate, steps=steps: floor_ms(
                        robot, robot, steps, repeat=1, kind=kind, sampled=rate is not None),
                    "floor_codegen": lambda kind=kind, rate=rate, steps=steps: batch_floor_ms(
                        robot, robot, steps, repeat=1, kind=kind, sampled=rate is not None),
                }, args.repeat)
                codegen_rows.append({"law": name, "time": timing, "reference": "sine",
                                     "codegen_ms": ms["codegen"], "compiled_ms": ms["compiled"],
                                     "floor_ms": ms["floor"],
                                     "floor_codegen_ms": ms["floor_codegen"],
                                     "speedup": ms["compiled"] / ms["codegen"],
                                     "speedup_vs_floor": ms["floor"] / ms["codegen"]})
        result.update({"codegen_rollout_ms": next(r["codegen_ms"] for r in codegen_rows
                                                  if r["law"] == "hinf"
                                                  and r["time"] == "sampled"),
                       "codegen_vs_compiled": codegen_rows})

    # 2c. Batched rollouts (issue 23): per-plant time of an uncertain-plant rollout (sampled
    # at the rate, sine reference; H-inf + FL on the RRR, FL on UR5 and Panda) on the compiled
    # engine, on the generated dynamics one plant per call, and 16 plants per call; each with
    # its dynamics-call floor; same interleaved rounds.
    peaks.mark("2b")
    if run("2c") or run("4"):
        result["batched_vs_compiled"] = [batch_row(arm, args, n_steps)
                                         for arm in (("rrr", "ur5", "panda") if run("2c")
                                                     else ("rrr",))]

    # 3. Python engine against the hand-written loop (FL, ZOH, sine), and H-inf for the record.
    peaks.mark("2c")
    if run("3"):
        sine = refs["sine"]
        Ts = 1.0 / args.rate
        grid = Ts * np.arange(n_steps + 1)
        R, RD, RDD = (np.ascontiguousarray(a) for a in sine.sample(grid))
        lam = laws["fl"].lam
        fns = {"handwritten": lambda: handwritten_fl_rollout(robot, robot, lam, R, RD, RDD, Ts,
                                                             n_steps)}
        fns.update({name: lambda law=law: simulate(robot, law, sine, args.duration,
                                                   rate=args.rate, engine="python")
                    for name, law in laws.items()})
        python_ms = side_by_side_ms(fns, args.repeat)
        handwritten_ms = python_ms.pop("handwritten")
        same = np.max(np.abs(
            handwritten_fl_rollout(robot, robot, lam, R, RD, RDD, Ts, n_steps)
            - simulate(robot, laws["fl"], sine, args.duration, rate=args.rate,
                       engine="python").q))
        result.update({"python_rollout_ms": python_ms["fl"],
                       "python_rollout_ms_by_law": python_ms,
                       "handwritten_python_ms": handwritten_ms,
                       "handwritten_max_diff_rad": float(same)})
    if run("2") and run("3"):
        rollout = {"python": result["python_rollout_ms_by_law"]["hinf"],
                   "compiled": result["compiled_rollout_ms"]["hinf"]}
        result.update({
            "rollout_ms": rollout,
            "rollout_ms_fl": {"python": result["python_rollout_ms"],
                              "compiled": result["compiled_rollout_ms"]["fl"]},
            "ratio_to_floor": {path: v / result["floor_ms"] for path, v in rollout.items()},
            "us_per_step": {path: 1e3 * v / n_steps for path, v in rollout.items()}})

    # 4. Campaign: N plants x (FL, H-inf), 10 s at 1 kHz, 2 workers; bound from the floor.
    two = [laws["fl"], laws["hinf"]]

    def campaign(samples, jobs):
        settings = CampaignSettings(samples=samples, seed=0, baseline="fl",
                                    run=RunSettings(duration=args.duration, rate=args.rate))
        t0 = time.perf_counter()
        run_campaign(robot, two, settings, jobs=jobs)
        return time.perf_counter() - t0

    peaks.mark("3")
    if run("4b"):
        result.update(closed_chain_ms(args.duration, args.rate, args.repeat))

    peaks.mark("4b")
    if run("4"):
        floor = result.get("floor_ms") or floor_ms(robot, robot, n_steps, kind="fl",
                                                   repeat=args.repeat)
        result["floor_ms"] = floor
        load_before = os.getloadavg()[0]
        campaign_s = campaign(args.campaign_samples, 2)
        campaign_load = [load_before, os.getloadavg()[0]]
        # The batched bound: the same count of rollouts at the batched floor per plant (RRR).
        one_job_s = campaign(args.mc_samples, 1)
        result.update({
            "campaign_s": campaign_s,
            "campaign_bound_s": 2 * args.campaign_samples * 1e-3 * floor / 2,
            "campaign_batched_bound_s": (2 * args.campaign_samples * 1e-3
                                         * result["batched_vs_compiled"][0]["floor_batched_ms"]
                                         / 2),
            "campaign_load_avg": campaign_load,
            "montecarlo_rollouts_per_s": {"1": 2 * args.mc_samples / one_job_s,
                                          "2": 2 * args.campaign_samples / campaign_s}})

    peaks.mark("4")
    # 4c. Campaigns against the batched engine's own floor (issue 33): RRR, Panda, and arms
    # whose structure is not compiled in (generated, built and cached at first use, timed in
    # an empty cache).
    if run("4c"):
        import tempfile

        from rrr_pin.sim import dyncache, dyngen
        from rrr_pin.sim.batched import generated_structure

        panda = rrr_pin.load_robot("panda", lock=dict(GENERATED["panda"][1]))
        result["campaign_at_floor"] = [
            campaign_at_floor(arm, "fl,hinf", count, args.duration, args.rate)
            for arm, count in ((robot, args.campaign_samples),
                               (panda, args.panda_samples)) if count]
        first = []
        with tempfile.TemporaryDirectory() as cache:
            names = () if args.quick else ("xarm7", "z1")  # a build takes ~20 s: not quick
            os.environ["RRR_PIN_CACHE"] = cache
            for name in names:
                arm = rrr_pin.load_robot(name)
                t0 = time.perf_counter()
                dyn = generated_structure(arm.model)
                build_s = time.perf_counter() - t0
                row = {"robot": name, "structure": dyngen.structure(arm.model),
                       "generated": dyn, "build_s": build_s,
                       "note": dyncache.failure(dyngen.structure(arm.model))}
                if args.panda_samples:
                    row.update(campaign_at_floor(arm, "fl,hinf", args.panda_samples,
                                                 args.duration, args.rate))
                first.append(row)
            del os.environ["RRR_PIN_CACHE"]
        result["first_use"] = first

    peaks.mark("4c")
    # 4d. The MuJoCo engine's campaign next to the batched engine's (issue 44).
    if run("4d"):
        result["mujoco_campaign"] = mujoco_campaign(args.mujoco_samples, args.duration,
                                                    args.rate, fresh=not args.quick)
    peaks.mark("4d")

    # 5. Start-up in fresh processes.
    if run("5"):
        exe = shutil.which("rrr-pin", path=str(Path(sys.executable).parent)) or "rrr-pin"
        result.update({
            "cli_help_s": subprocess_s([exe, "--help"], args.startup_repeat),
            "import_s": subprocess_s([sys.executable, "-c", "import rrr_pin"],
                                     args.startup_repeat),
            "python_startup_s": subprocess_s([sys.executable, "-c", "pass"],
                                             args.startup_repeat)})

    peaks.mark("5")
    # 6. loopsyn on a 3 x 3 plant (issue 21).
    if run("6"):
        result["loopsyn_3x3_s"] = loopsyn_3x3_s(1 if args.quick else 3)
    peaks.mark("6")
    result["goals"] = GOALS
    result["settings"] = {"duration_s": args.duration, "rate_hz": args.rate, "substeps": 1,
                          "continuous_dt_s": 1e-3, "repeat": args.repeat, "calls": args.calls,
                          "campaign_samples": args.campaign_samples, "campaign_jobs": 2,
                          "mc_samples": args.mc_samples, "startup_repeat": args.startup_repeat,
                          "sections": [x for x in SECTIONS if run(x)]}
    if run("8"):
        result["identification"] = identification_bench(5.0 if args.quick else 10.0)
    peaks.mark("8")
    if run("7"):
        result["mu"] = mu_upper_s(1 if args.quick else 10)
    peaks.mark("7")
    if run("10"):
        result["tuning"] = tuning_bench(1 if args.quick else 19, 1 if args.quick else 4,
                                        30 if args.quick else None)
    peaks.mark("10")
    if run("11"):
        result["scale"] = scale_bench(args)
    peaks.mark("11")
    if args.export is not None:
        result["export"] = export_step_us(200 if args.quick else 200000, Path(args.export))
    if args.json:
        print(json.dumps(result))
        return
    report(result, args)
    if "8" in args.sections:
        report_identification(result["identification"])
    if "10" in args.sections:
        report_tuning(result["tuning"])
    if "11" in args.sections:
        report_scale(result["scale"])
    report_peaks(result)


def report(res, args):
    """Print the table of every figure, ratio and goal."""
    print(f"machine: {res['machine']}")
    if "1" in args.sections:
        print(f"\n1. per call from Python [us] (fastest of 5 x {args.calls})")
        print(f"  {'':4}{'Robot':>9}{'check=False':>13}{'bare pin':>10}{'closed form':>13}"
              f"{'Robot/bare':>12}{'unchecked/bare':>16}   goal")
        for k, v in res["per_call_us"].items():
            r1, r2 = v["robot"] / v["bare"], v["robot_unchecked"] / v["bare"]
            print(f"  {k:4}{v['robot']:9.2f}{v['robot_unchecked']:13.2f}{v['bare']:10.2f}"
                  f"{v['closed_form']:13.2f}{r1:12.2f}{r2:16.2f}   "
                  f"{verdict(r1, GOALS['robot_call'])}")
    if "2" in args.sections:
        print(f"\n2. compiled engine, nominal RRR, {args.duration:g} s; sampled at "
              f"{args.rate:g} Hz (RK4 plant, ZOH) or continuous (RK4, dt = 1 ms, law at every "
              f"stage); fastest of {args.repeat} rounds, each with the floor")
        print(f"  {'law':6}{'time':12}{'reference':10}{'compiled [ms]':>14}{'floor [ms]':>12}"
              f"{'ratio':>8}   goal")
        for r in res["compiled_vs_floor"]:
            print(f"  {r['law']:6}{r['time']:12}{r['reference']:10}{r['compiled_ms']:14.1f}"
                  f"{r['floor_ms']:12.1f}{r['ratio']:8.2f}   "
                  f"{verdict(r['ratio'], GOALS['compiled'])}")
    if "2b" in args.sections:
        print("\n2b. engine='codegen' (parameter-input generated dynamics), nominal RRR, sine, "
              "same rounds as the compiled engine and both floors")
        print(f"  {'law':6}{'time':12}{'codegen [ms]':>13}{'compiled [ms]':>14}{'floor [ms]':>12}"
              f"{'cg floor [ms]':>14}{'compiled/cg':>12}{'floor/cg':>10}")
        for r in res["codegen_vs_compiled"]:
            print(f"  {r['law']:6}{r['time']:12}{r['codegen_ms']:13.2f}{r['compiled_ms']:14.1f}"
                  f"{r['floor_ms']:12.1f}{r['floor_codegen_ms']:14.2f}{r['speedup']:12.2f}"
                  f"{r['speedup_vs_floor']:10.2f}")
    if "2c" in args.sections:
        print(f"\n2c. batched rollouts (issue 23): per plant, an uncertain plant, "
              f"{args.duration:g} s at {args.rate:g} Hz, sine-like default reference; 16 plants "
              f"per batched call; same rounds")
        print(f"  {'robot':6}{'law':6}{'compiled':>10}{'codegen':>9}{'batched':>9}{'floor':>8}"
              f"{'cg floor':>9}{'b floor':>9}{'compiled/batched':>18}{'max |dq|':>10}   goal")
        goals = {"rrr": GOALS["batched_rrr"], "ur5": GOALS["batched_ur5"]}
        for r in res["batched_vs_compiled"]:
            g = goals.get(r["robot"])
            mark = (f">= {g:g}: {'met' if r['compiled_vs_batched'] >= g else 'NOT MET'}" if g
                    else "-")
            print(f"  {r['robot']:6}{r['law']:6}{r['compiled_ms']:10.1f}{r['codegen_ms']:9.2f}"
                  f"{r['batched_ms']:9.2f}{r['floor_ms']:8.1f}{r['floor_codegen_ms']:9.2f}"
                  f"{r['floor_batched_ms']:9.2f}{r['compiled_vs_batched']:18.2f}"
                  f"{r['max_diff_rad']:10.1e}   {mark}")
        print("  [ms]; codegen: generated dynamics, one plant per call; floors: the bare dynamics "
              "calls (generic Pinocchio, generated, generated 16 at a time)")
    if "3" in args.sections:
        hw = res["handwritten_python_ms"]
        print(f"\n3. Python engine, {args.duration:g} s at {args.rate:g} Hz ZOH, sine (fastest of "
              f"{args.repeat} interleaved rounds)")
        print(f"  hand-written FL loop on pin (yardstick): {hw:8.1f} ms  (same q as the engine to "
              f"{res['handwritten_max_diff_rad']:.1e} rad)")
        for name, ms in res["python_rollout_ms_by_law"].items():
            mark = f"   {verdict(ms / hw, GOALS['python'])}" if name == "fl" else ""
            print(f"  simulate(engine='python'), {name:5}:     {ms:8.1f} ms  {ms / hw:5.2f} x the "
                  f"yardstick{mark}")
    if "4" in args.sections:
        c, b = res["campaign_s"], res["campaign_bound_s"]
        print(f"\n4. campaign: {args.campaign_samples} plants x 2 laws (FL, H-inf), "
              f"{args.duration:g} s at {args.rate:g} Hz, 2 jobs")
        print(f"  measured {c:8.2f} s; bound 2 x {args.campaign_samples} x "
              f"{res['floor_ms']:.1f} ms / 2 cores = {b:.2f} s; ratio {c / b:.2f}   "
              f"{verdict(c / b, GOALS['campaign'])}")
        bb = res["campaign_batched_bound_s"]
        goal_s = (f"; 1000 plants under {GOALS['campaign_1000_s']:g} s: "
                  f"{'met' if c < GOALS['campaign_1000_s'] else 'NOT MET'}"
                  if args.campaign_samples == 1000 else "")
        print(f"  batched bound 2 x {args.campaign_samples} x "
              f"{res['batched_vs_compiled'][0]['floor_batched_ms']:.2f} ms / 2 cores = {bb:.2f} s; "
              f"ratio {c / bb:.2f}   {verdict(c / bb, GOALS['campaign_batched'])}{goal_s}")
        print("  1-minute load average {:.2f} before the campaign, {:.2f} after (2 cores)".format(
            *res["campaign_load_avg"]))
        print("  throughput: " + ", ".join(
            f"{r:.1f} rollouts/s with {j} job{'s' if j != '1' else ''}"
            for j, r in res["montecarlo_rollouts_per_s"].items()))
    if "4c" in args.sections:
        print(f"\n4c. campaigns at the batched engine's floor (issue 33): N plants x (FL, "
              f"H-inf + FL), {args.duration:g} s at {args.rate:g} Hz; floor = the batched C++ "
              f"loop alone on the same plants (1 core)")
        print(f"  {'robot':7}{'N':>6}{'floor':>9}{'1 proc':>9}{'jobs 2':>9}{'threads 2':>11}"
              f"{'jobs2/(floor/2)':>17}{'thr2/(floor/2)':>16}  rows equal  load")
        for r in res["campaign_at_floor"]:
            print(f"  {r['robot']:7}{r['samples']:6d}{r['floor_1core_s']:9.2f}"
                  f"{r['one_process_s']:9.2f}{r['jobs2_s']:9.2f}{r['threads2_s']:11.2f}"
                  f"{r['ratio_jobs2']:17.2f}{r['ratio_threads2']:16.2f}  "
                  f"{str(r['rows_identical']):10}  {r['load_avg'][0]:.1f} -> "
                  f"{r['load_avg'][1]:.1f}")
            best = min(r["jobs2_s"], r["threads2_s"])
            goal = (GOALS["campaign_1000_2cores_s"] if r["robot"] == "rrr"
                    else GOALS["campaign_panda_1000_s"])
            ratio = min(r["ratio_jobs2"], r["ratio_threads2"])
            scaled = best * 1000 / r["samples"]
            print(f"    CPU time of the 1-process campaign {r['one_process_cpu_s']:.2f} s over its "
                  f"C++ loop's {r['floor_cpu_s']:.2f} s: {r['ratio_one_process_cpu']:.3f} "
                  f"(the Python share, independent of the load); CPU time of the 2-process "
                  f"campaign {r['jobs2_cpu_s']:.2f} s: {r['ratio_jobs2_cpu']:.3f}")
            print(f"    the C++ loop alone on 2 threads: {r['floor_2cores_s']:.2f} s (floor / 2 = "
                  f"{r['floor_1core_s'] / 2:.2f} s); jobs 2 over it {r['ratio_jobs2_2cores']:.2f}, "
                  f"threads 2 over it {r['ratio_threads2_2cores']:.2f}")
            print(f"    [s]; best on 2 cores {best:.2f} s ({scaled:.1f} s per 1000 plants, goal "
                  f"{goal:g} s: {'met' if scaled <= goal else 'NOT MET'}); ratio to the floor "
                  f"{ratio:.2f} ({verdict(ratio, GOALS['campaign_floor'])}); engines "
                  f"{', '.join(r['engines'])}")
            d = r["dynamics"]
            print(f"    generated forward dynamics by {d['fd_algorithm']}: "
                  f"{d['operations'][d['fd_algorithm']]} operations per plant and call "
                  f"(ldlt {d['operations']['ldlt']}, aba {d['operations']['aba']}; "
                  f"Featherstone's ABA {d['featherstone_aba']}); "
                  f"{d['operations']['pre']} once per plant")
        for r in res["first_use"]:
            print(f"  {r['robot']} ({r['structure']}): generated dynamics {r['generated']}, "
                  f"{r['build_s']:.1f} s to have them at first use (an empty cache)"
                  + (f"; NOT generated: {r['note']}" if r["note"] else ""))
            if "floor_1core_s" in r:
                print(f"    {r['samples']} plants x (FL, H-inf + FL): floor "
                      f"{r['floor_1core_s']:.2f} s, 1 process {r['one_process_s']:.2f} s, "
                      f"jobs 2 {r['jobs2_s']:.2f} s, "
                      f"threads 2 {r['threads2_s']:.2f} s, engines {', '.join(r['engines'])}")
    if "4d" in args.sections:
        r = res["mujoco_campaign"]
        print(f"\n4d. the MuJoCo engine (issue 44): {r['samples']} uncertain RRR plants x (FL, "
              f"H-inf + FL), {args.duration:g} s at {args.rate:g} Hz, 1 job, "
              + ("each engine in a fresh process" if r.get("fresh_processes", True)
                 else "both in this process"))
        if r.get("skipped"):
            print(f"  skipped: {r['skipped']}")
        else:
            for name, e in r["engines"].items():
                print(f"  {name:8} {e['s']:9.2f} s ({e['s'] * 1000 / r['samples']:9.1f} s per "
                      f"1000 plants)  peak RSS {e['peak_rss_mb']:7.1f} MB  engines "
                      f"{', '.join(e['engines'])}  load {e['load_avg'][0]:.1f} -> "
                      f"{e['load_avg'][1]:.1f}")
            print(f"  mujoco / batched: {r['ratio']:.1f} x; the MuJoCo engine checks, the batched "
                  f"one runs campaigns")
    if "4b" in args.sections:
        cp, cf = res["closed_chain_rollout_ms"], res["constraint_dynamics_floor_ms"]
        cc, ck = res["closed_chain_compiled_ms"], res["closed_chain_kkt_floor_ms"]
        goal = res["closed_chain_goal_ms"]
        print(f"\n4b. closed chain (issue 22): 5-bar FL, {args.duration:g} s at {args.rate:g} Hz "
              f"({4 * round(args.duration * args.rate)} plant accelerations)")
        print(f"  python engine   {cp:9.1f} ms ({cp / cf:5.1f} x its constraintDynamics calls "
              f"alone, {cf:.1f} ms)")
        print(f"  compiled engine {cc:9.1f} ms ({cc / cf:5.3f} x the constraintDynamics calls; "
              f"{cp / cc:.0f} x faster than Python; its exact-KKT calls alone in C++ {ck:.1f} ms)")
        print(f"  goal < {goal:g} ms on the fastest engine: {'met' if cc < goal else 'NOT MET'}")
    if "5" in args.sections:
        print(f"\n5. start-up, fresh processes (median of {args.startup_repeat}; bare `python -c "
              f"pass` takes {res['python_startup_s']:.3f} s)")
        for key, what in (("cli_help_s", "rrr-pin --help"), ("import_s", "import rrr_pin")):
            v, goal = res[key], GOALS[key]
            print(f"  {what:16}{v:8.3f} s   goal < {goal:g} s: {'met' if v < goal else 'NOT MET'}")
    if "6" in args.sections:
        v, goal = res["loopsyn_3x3_s"], GOALS["loopsyn_3x3_s"]
        print(f"\n6. loopsyn(G, 10/s), G coupled 3 x 3 (6 states): {v:.3f} s   goal < {goal:g} s: "
              f"{'met' if v < goal else 'NOT MET'}")

    if "7" in args.sections:
        m = res["mu"]
        print(f"\n7. mu upper bound (D,G LMI, Clarabel) on the frozen FL loop, "
              f"{m['parameters']} real parameters, M of size {m['size']}: "
              f"{m['s_per_frequency']:.3f} s per frequency (mean of {m['frequencies']}; with the "
              f"lower bound {m['both_s_per_frequency']:.3f} s)   "
              f"goal < 0.5 s: {'met' if m['s_per_frequency'] < 0.5 else 'NOT MET'}")

    if "export" in res:
        e = res["export"]
        print(f"\n9. exported H-inf + FL, one ctrl_step in a C loop [us] (fastest of 10 x "
              f"{e['calls']}, interleaved; load average {e['load_avg_1min']:.1f})")
        g = GOALS["export_rrr_us"]
        print(f"  RRR, generated dynamics: {e['rrr_ctrl_step_us']:8.3f} us (its Pinocchio calls "
              f"alone: {e['rrr_pinocchio_calls_us']:.3f} us)   goal < {g:g} us: "
              f"{'met' if e['rrr_ctrl_step_us'] < g else 'NOT MET'}")
        print(f"  UR5, Pinocchio C++:      {e['ur5_ctrl_step_us']:8.3f} us, its Pinocchio calls "
              f"alone {e['ur5_pinocchio_calls_us']:.3f} us; ratio {e['ur5_ratio']:.2f}   "
              f"{verdict(e['ur5_ratio'], GOALS['export_ur5'])}")
        if "rrr_ctrl_step_dt_us" in e:
            print(f"  ctrl_step_dt off the nominal period (K discretized each call): RRR "
                  f"{e['rrr_ctrl_step_dt_us']:.3f} us, UR5 {e['ur5_ctrl_step_dt_us']:.3f} us")


def identification_bench(duration: float) -> dict:
    """Issue 18: identify UR5 from ``duration`` s of 1 kHz data (CSV read, derivatives by
    Savitzky-Golay, regressor, WLS, consistency SDP, URDF written and loaded, held-out
    prediction); goal < 10 s for 10 s of data. The cvxpy import is timed apart.
    """
    import tempfile

    t0 = time.perf_counter()
    import cvxpy  # noqa: F401  (imported once per process, timed apart)

    import_s = time.perf_counter() - t0
    from rrr_pin.model import identification as idn
    from rrr_pin.model.excitation import FourierTrajectory

    robot = rrr_pin.load_robot("ur5")
    rng = np.random.default_rng(0)
    n = robot.nq
    traj = FourierTrajectory(0.2, 0.3 * rng.standard_normal((n, 5)),
                             0.3 * rng.standard_normal((n, 5)), np.zeros(n), 2)
    t = np.arange(0.0, duration, 1e-3)
    q, qd, qdd = traj.sample(t)
    tau = np.array([robot.inverse_dynamics(*x, check=False) for x in zip(q, qd, qdd, strict=True)])
    tau += 0.1 * rng.standard_normal(tau.shape)
    header = ",".join(["t"] + [f"{k}_{j}" for k in ("q", "tau") for j in robot.joint_names])
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "ur5.csv"
        np.savetxt(path, np.column_stack([t, q, tau]), delimiter=",", header=header,
                   comments="")
        start = time.perf_counter()
        data = idn.read_measurements(path, robot)
        result = idn.identify(robot, data)
        result.write(folder)
        elapsed = time.perf_counter() - start
    return {"robot": "ur5", "data_s": duration, "rate_hz": 1000.0, "samples": len(t),
            "identify_s": elapsed, "cvxpy_import_s": import_s, "goal_s": 10.0,
            "base_count": result.summary["base_count"],
            "condition_number": result.summary["condition_number"]}


def report_identification(r: dict) -> None:
    """Print the identification figure (issue 18)."""
    print(f"\n8. identification, {r['robot']}: {r['data_s']:g} s of {r['rate_hz']:g} Hz data "
          f"({r['samples']} samples, {r['base_count']} base parameters), CSV to URDF with the "
          f"consistency SDP: {r['identify_s']:.2f} s   goal < {r['goal_s']:g} s: "
          f"{'met' if r['identify_s'] < r['goal_s'] else 'NOT MET'} (cvxpy import "
          f"{r['cvxpy_import_s']:.2f} s apart)")


def mu_upper_s(count: int) -> dict:
    """Time ``mussv`` per frequency on the frozen FL loop of the RRR: both bounds, and the
    upper bound alone (``lower=False``: its bisection then starts from 0, the worst case).
    """
    from rrr_pin.control.analysis import parametric_loop
    from rrr_pin.control.laws import fl_controller
    from rrr_pin.robust.mu import mussv

    loop = parametric_loop(fl_controller(rrr_pin.load_robot("rrr")), [0.3, 0.6, -0.9])
    w = np.logspace(0, 4, count)
    t0 = time.perf_counter()
    mussv(loop.M, loop.blocks, w, lower=False)
    t1 = time.perf_counter()
    mussv(loop.M, loop.blocks, w)
    t2 = time.perf_counter()
    return {"s_per_frequency": (t1 - t0) / count, "both_s_per_frequency": (t2 - t1) / count,
            "frequencies": count, "parameters": len(loop.names),
            "size": int(loop.M.ninputs)}



class SectionPeaks:
    """Each section's own peak resident memory [MB] into ``result["peak_rss_mb"]``.

    Linux's high-water mark ``VmHWM`` (``/proc/self/status``) is read when a section ends,
    then reset (``5`` into ``/proc/self/clear_refs``) for the next one; elsewhere
    ``getrusage``'s peak, which only grows (then a section's figure is the largest so far).
    Subprocesses' peaks are measured apart (:func:`run_child`).
    """

    def __init__(self, result: dict, run):
        self.result, self.run = result, run
        result["peak_rss_mb"] = {}
        self._reset()

    @staticmethod
    def _reset() -> None:
        try:
            Path("/proc/self/clear_refs").write_text("5")
        except OSError:
            pass

    @staticmethod
    def now_mb() -> float:
        """Return the peak resident memory since the last reset [MB]."""
        try:
            for line in Path("/proc/self/status").read_text().splitlines():
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
        except OSError:
            pass
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    def mark(self, name: str) -> None:
        """End section ``name`` (if it ran): record its peak, start the next one's."""
        if self.run(name):
            self.result["peak_rss_mb"][name] = self.now_mb()
        self._reset()


def report_peaks(res: dict) -> None:
    """Print each section's peak resident memory."""
    peaks = res.get("peak_rss_mb") or {}
    if peaks:
        print("\npeak resident memory of this process per section [MB]: " +
              ", ".join(f"{k}: {v:.0f}" for k, v in peaks.items()))


def run_child(argv: list[str], limit_bytes: int | None = None) -> dict:
    """Run ``argv`` and return its wall time [s], exit status and peak resident memory [MB].

    ``os.wait4`` gives this child's own resource usage (its ``ru_maxrss``, with the
    descendants it waited for, e.g. worker processes). ``limit_bytes`` caps its address space
    (``RLIMIT_AS``) so that a run that would grow without bound fails instead.
    """
    import resource

    def limit():
        if limit_bytes:
            resource.setrlimit(resource.RLIMIT_AS, (limit_bytes, limit_bytes))

    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            preexec_fn=limit)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace").strip().splitlines()
    return {"argv": argv[2:], "wall_s": wall, "status": proc.returncode,
            "peak_rss_mb": usage.ru_maxrss / 1024.0, "load": os.getloadavg()[0],
            "error": err[-1] if proc.returncode and err else None}


#: Issue 48's goals: (largest value, unit).
SCALE_GOALS = {"design_arm_s": 120.0, "design_arm_mb": 1024.0, "moonshot_s": 40.0,
               "moonshot_mb": 500.0, "montecarlo_cli_ratio": 1.3, "mc_100k_ratio": 1.1,
               "mc_100k_mb": 2048.0}


def scale_bench(args) -> dict:
    """Issue 48: designs and campaigns at scale, each in a fresh process (time and memory).

    * ``rrr-pin design`` of the RRR's moonshot (four requirements, lam tuned), and with
      ``--design-arms`` of the Panda and the UR5 with the defaults, each under a 6 GB address
      space limit;
    * ``rrr-pin montecarlo --samples N --jobs 2 --no-figures`` (RRR) against
      :func:`rrr_pin.campaign.montecarlo.run_campaign` of the same plants in this process
      (``jobs=2``);
    * with ``--mc-100k``, ``montecarlo --samples 100000`` against 100 times the 1000-plant one.
    """
    import tempfile

    from rrr_pin.campaign.montecarlo import CampaignSettings, run_campaign

    cli = [sys.executable, "-m", "rrr_pin.cli"]
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        reduced = ["--samples", "2", "--starts", "1"] if args.quick else []
        moon = ["design", "--robot", "rrr", "--require", "delay_margin=0.006", "--require",
                "error_ratio=10", "--require", "actuator_bandwidth=300,delay=0.002",
                "--tune-lam", "--no-progress", "--out", f"{tmp}/moon", *reduced]
        out["moonshot"] = run_child(cli + moon, 6_000_000_000)
        if args.design_arms:
            for arm in ("panda", "ur5"):
                out[f"design_{arm}"] = run_child(
                    cli + ["design", "--robot", arm, "--no-progress", "--out",
                           f"{tmp}/{arm}", *reduced], 6_000_000_000)
        n = 2 if args.quick else args.scale_samples
        mc = ["montecarlo", "--samples", str(n), "--jobs", "2", "--no-figures",
              "--no-progress"]
        out["montecarlo_cli"] = run_child(cli + mc + ["--out", f"{tmp}/mc"])
        robot = rrr_pin.load_robot("rrr")
        laws = make_laws("fl,hinf", robot)
        t0 = time.perf_counter()
        run_campaign(robot, laws, CampaignSettings(samples=n, run=RunSettings(duration=10.0)),
                     jobs=2)
        out["montecarlo_in_process_s"] = time.perf_counter() - t0
        out["montecarlo_samples"] = n
        if args.mc_100k:
            out["mc_100k"] = run_child(cli + ["montecarlo", "--samples", "100000", "--jobs",
                                              "2", "--no-figures", "--no-progress", "--out",
                                              f"{tmp}/mc100k"], 6_000_000_000)
    out["goals"] = SCALE_GOALS
    return out


def report_scale(r: dict) -> None:
    """Print issue 48's figures: time and peak memory of each command, with the load."""
    g = r["goals"]
    print("\n11. at scale (issue 48), each command in a fresh process "
          "[wall s, peak resident MB, 1-min load average at its end]")
    rows = [("moonshot", "design rrr moonshot", g["moonshot_s"], g["moonshot_mb"])]
    rows += [(k, f"design {k[7:]} (defaults)", g["design_arm_s"], g["design_arm_mb"])
             for k in ("design_panda", "design_ur5") if k in r]
    for key, label, gs, gm in rows:
        x = r[key]
        ok = x["status"] == 0 and x["wall_s"] <= gs and x["peak_rss_mb"] <= gm
        print(f"  {label:34}{x['wall_s']:9.1f} s{x['peak_rss_mb']:9.0f} MB  load "
              f"{x['load']:5.2f}   goal <= {gs:g} s, {gm:g} MB: "
              f"{'met' if ok else 'NOT MET'}{'' if x['status'] == 0 else ' ' + str(x['error'])}")
    x, n = r["montecarlo_cli"], r["montecarlo_samples"]
    ratio = x["wall_s"] / r["montecarlo_in_process_s"]
    print(f"  montecarlo --samples {n} --jobs 2: {x['wall_s']:.2f} s ({x['peak_rss_mb']:.0f} "
          f"MB, load {x['load']:.2f}) / in-process campaign {r['montecarlo_in_process_s']:.2f}"
          f" s = {ratio:.2f}   {verdict(ratio, g['montecarlo_cli_ratio'])}")
    if "mc_100k" in r:
        x = r["mc_100k"]
        ratio = x["wall_s"] / (100 * r["montecarlo_cli"]["wall_s"] * 1000 / n)
        ok = ratio <= g["mc_100k_ratio"] and x["peak_rss_mb"] <= g["mc_100k_mb"]
        print(f"  montecarlo --samples 100000: {x['wall_s']:.1f} s, {x['peak_rss_mb']:.0f} MB "
              f"(load {x['load']:.2f}); / 100 x the 1000-plant command = {ratio:.2f}   goal <= "
              f"{g['mc_100k_ratio']:g}, {g['mc_100k_mb']:g} MB: {'met' if ok else 'NOT MET'}")


def tuning_bench(samples: int, starts: int, maxfev: int | None = None) -> dict:
    """Time ``rrr_pin.tune`` (issue 34): the RRR's order-2 law with ``lam``, five requirements,
    the nominal and ``samples`` uncertain plants, ``starts`` starts, grid search only (the
    exact verification and its simulations timed apart).
    """
    from rrr_pin import load_robot, tune
    from rrr_pin.campaign.requirements import (
        ActuatorBandwidth,
        Bandwidth,
        DelayMargin,
        DiskMargin,
        ErrorRatio,
    )
    from rrr_pin.control.structures import FixedOrder

    robot = load_robot("rrr")
    reqs = [DelayMargin(0.006), DiskMargin(0.5), ActuatorBandwidth(300.0, delay=0.002),
            Bandwidth(20.0), ErrorRatio(10.0)]
    t0 = time.perf_counter()
    res = tune(robot, FixedOrder(lam=None, order=2), reqs, plants=samples, starts=starts,
               maxfev=maxfev, verify=False)
    search = time.perf_counter() - t0
    evals = sum(s["evaluations"] for s in res.starts)
    out = {"plants": samples + 1, "starts": starts, "requirements": len(reqs),
           "search_s": search, "evaluations": evals, "per_evaluation_ms": 1e3 * search / evals,
           "objective": res.objective, "goal_s": 60.0}
    return {**out, **screen_bench(robot, reqs, samples, 5 if samples < 5 else 40)}


def screen_bench(robot, reqs, samples: int, points: int) -> dict:
    """Time the tuner's evaluation screened against LAPACK at every grid point.

    The grid screened (``rrr_pin.control.grid_bounds``) against the path before it, at the
    same seeded points of the order-2 structure: ms per evaluation of each and the largest
    relative difference of the values.
    """
    import numpy as np

    from rrr_pin import Tolerances
    from rrr_pin.campaign.tuning import _context, _Eval
    from rrr_pin.control.references import default_reference
    from rrr_pin.control.structures import FixedOrder

    st = FixedOrder(lam=None, order=2)
    plants = [robot] + [robot.perturbed(np.random.default_rng([0, k]), Tolerances())[0]
                        for k in range(samples)]
    ctx = _context(robot, plants, default_reference(robot), 1000.0, {}, 4.0)
    b = np.log(np.array(st.bounds()))
    rng = np.random.default_rng(3)
    xs = [st.split(np.exp(rng.uniform(b[:, 0], b[:, 1]))) for _ in range(points)]
    times, vals = {}, {}
    for screen in (False, True):
        ctx.screen = screen
        t0 = time.perf_counter()
        vals[screen] = np.array([[r.estimate(ctx, ev) for r in reqs]
                                 for ev in (_Eval(ctx, lam, K) for lam, K in xs)])
        times[screen] = 1e3 * (time.perf_counter() - t0) / points
    a, c = vals[False], vals[True]
    same = np.isfinite(a) & np.isfinite(c)
    rel = float(np.max(np.abs(a[same] - c[same]) / np.maximum(np.abs(a[same]), 1e-300)))
    return {"lapack_everywhere_ms": times[False], "screened_ms": times[True],
            "screen_points": points, "screen_max_rel_diff": rel,
            "screen_same_infinities": bool(np.array_equal(~np.isfinite(a), ~np.isfinite(c)))}


def report_tuning(r: dict) -> None:
    """Print the tuning figure (issue 34)."""
    print(f"\n10. tuning, RRR order-2 K + lam, {r['requirements']} requirements, {r['plants']} "
          f"plants, {r['starts']} starts: {r['search_s']:.1f} s ({r['evaluations']} "
          f"evaluations, {r['per_evaluation_ms']:.1f} ms each; worst normalized "
          f"{r['objective']:.3g})   goal < {r['goal_s']:g} s: "
          f"{'met' if r['search_s'] < r['goal_s'] else 'NOT MET'}")
    print(f"    one evaluation at {r['screen_points']} seeded points: LAPACK at every grid point "
          f"{r['lapack_everywhere_ms']:.1f} ms -> screened {r['screened_ms']:.1f} ms "
          f"(x{r['lapack_everywhere_ms'] / r['screened_ms']:.1f}); values differ by at most "
          f"{r['screen_max_rel_diff']:.1e} relative"
          f"{'' if r['screen_same_infinities'] else ' (NOT the same infinite values)'}")


if __name__ == "__main__":
    main()

