"""Benchmark: dynamics calls, closed-loop rollouts against the C++ floor, Monte Carlo throughput.

Everything is measured in one run on this machine and printed (never asserted):

1. per call from Python: M, V, G through Pinocchio (``Robot`` methods and bare ``pin`` calls)
   against the paper's closed form (``rrr_pin.closed_form``);
2. one closed-loop rollout, 10 s of the nominal RRR at 1 kHz (zero-order hold, RK4 plant, one
   sub-step), both controllers, for every rollout path: wall time (median of ``--repeat`` runs)
   and microseconds per control step;
3. the floor: the same Pinocchio calls a step needs (1 CRBA + 1 NLE on the nominal model,
   4 ABA on the plant) timed in a plain C++ loop, and the ratio of each path to it;
4. Monte Carlo throughput (plant-rollouts per second) with 1 and 2 worker processes.

    python scripts/bench.py            # table
    python scripts/bench.py --json     # one JSON object
"""

import argparse
import json
import os
import platform
import statistics
import time
import timeit

import numpy as np
import pinocchio as pin

import rrr_pin
from rrr_pin import closed_form
from rrr_pin.compiled import compile_robot, floor_ms, rollout_compiled
from rrr_pin.montecarlo import run_campaign


def per_call_us(fn, number):
    """Median over 5 repeats of the time of one call [us]."""
    times = timeit.repeat(fn, number=number, repeat=5)
    return 1e6 * statistics.median(times) / number


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
    return (f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"pin {pin.__version__}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--duration", type=float, default=10.0, help="rollout length [s] (10)")
    parser.add_argument("--rate", type=float, default=1000.0, help="control rate [Hz] (1000)")
    parser.add_argument("--repeat", type=int, default=5, help="runs per rollout timing (5)")
    parser.add_argument("--calls", type=int, default=2000, help="calls per per-call timing")
    parser.add_argument("--mc-samples", type=int, default=40,
                        help="plants per Monte Carlo throughput timing (40)")
    args = parser.parse_args(argv)

    robot = rrr_pin.load_robot("rrr")
    params = rrr_pin.paper_params()
    model, data = robot.model, robot.data
    rng = np.random.default_rng(0)
    q, qd = rng.uniform(-np.pi, np.pi, 3), rng.uniform(-5, 5, 3)

    calls = {
        "M": {"pinocchio_robot": lambda: robot.M(q),
              "pinocchio_bare": lambda: pin.crba(model, data, q),
              "closed_form": lambda: closed_form.M(params, q)},
        "V": {"pinocchio_robot": lambda: robot.V(q, qd),
              "pinocchio_bare": lambda: pin.nonLinearEffects(model, data, q, qd),
              "closed_form": lambda: closed_form.V(params, q, qd)},
        "G": {"pinocchio_robot": lambda: robot.G(q),
              "pinocchio_bare": lambda: pin.computeGeneralizedGravity(model, data, q),
              "closed_form": lambda: closed_form.G(params, q)},
    }
    per_call = {k: {path: per_call_us(fn, args.calls) for path, fn in v.items()}
                for k, v in calls.items()}

    K = rrr_pin.design().K_reduced
    ref = rrr_pin.default_reference(robot)
    controllers = {"fl": rrr_pin.fl_controller(robot),
                   "hinf": rrr_pin.hinf_fl_controller(robot, K)}
    n_steps = int(round(args.duration * args.rate))
    Ts = 1.0 / args.rate
    compiled = compile_robot(robot)

    def prepared(ctrl):
        mats = ctrl.discretize(args.rate)
        return lambda: rollout_compiled(compiled, compiled, ctrl.lam, mats, ref.home, ref.amp,
                                        ref.omega, ref.phase, Ts, 1, n_steps)

    paths = {
        "python": lambda c: (lambda: rrr_pin.simulate(robot, c, ref, args.duration,
                                                      rate=args.rate, engine="python")),
        "compiled": lambda c: (lambda: rrr_pin.simulate(robot, c, ref, args.duration,
                                                        rate=args.rate, engine="compiled")),
        "compiled_prepared": prepared,
    }
    rollout = {}
    for path, make in paths.items():
        rollout[path] = {}
        repeat = max(1, args.repeat // 2) if path == "python" else args.repeat
        for key, ctrl in controllers.items():
            fn = make(ctrl)
            fn()  # warm-up
            times = []
            for _ in range(repeat):
                t0 = time.perf_counter()
                fn()
                times.append(1e3 * (time.perf_counter() - t0))
            rollout[path][key] = statistics.median(times)
    floor = floor_ms(robot, robot, n_steps, substeps=1, repeat=args.repeat)

    mc = {}
    for jobs in (1, 2):
        t0 = time.perf_counter()
        run_campaign(robot, K, samples=args.mc_samples, duration=args.duration,
                     rate=args.rate, jobs=jobs, engine="auto")
        mc[jobs] = 2 * args.mc_samples / (time.perf_counter() - t0)

    result = {
        "machine": machine(),
        "per_call_us": per_call,
        "rollout_ms": {path: v["hinf"] for path, v in rollout.items()},
        "rollout_ms_fl": {path: v["fl"] for path, v in rollout.items()},
        "floor_ms": floor,
        "ratio_to_floor": {path: v["hinf"] / floor for path, v in rollout.items()},
        "us_per_step": {path: 1e3 * v["hinf"] / n_steps for path, v in rollout.items()},
        "montecarlo_rollouts_per_s": {str(j): r for j, r in mc.items()},
        "settings": {"duration_s": args.duration, "rate_hz": args.rate, "substeps": 1,
                     "repeat": args.repeat, "mc_samples": args.mc_samples},
    }
    if args.json:
        print(json.dumps(result))
        return
    print(f"machine: {result['machine']}")
    print("\nper call from Python [us]        Pinocchio (Robot)  Pinocchio (bare)  closed form")
    for k, v in per_call.items():
        print(f"  {k:30}{v['pinocchio_robot']:17.2f}{v['pinocchio_bare']:18.2f}"
              f"{v['closed_form']:13.2f}")
    print(f"\nrollout: nominal RRR, {args.duration:g} s at {args.rate:g} Hz, RK4 plant "
          f"(median of {args.repeat})")
    print(f"  {'path':20}{'FL [ms]':>10}{'Hinf+FL [ms]':>14}{'us/step':>10}{'x floor':>9}")
    for path, v in rollout.items():
        print(f"  {path:20}{v['fl']:10.1f}{v['hinf']:14.1f}"
              f"{result['us_per_step'][path]:10.2f}{result['ratio_to_floor'][path]:9.2f}")
    print(f"  {'C++ floor':20}{'':10}{floor:14.1f}{1e3 * floor / n_steps:10.2f}{1.0:9.2f}")
    print(f"\nMonte Carlo ({args.mc_samples} plants x 2 controllers x {args.duration:g} s): "
          + ", ".join(f"{r:.1f} rollouts/s with {j} job{'s' if j > 1 else ''}"
                      for j, r in mc.items()))


if __name__ == "__main__":
    main()
