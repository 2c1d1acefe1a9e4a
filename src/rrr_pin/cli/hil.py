"""``rrr-pin hil``: an exported controller at its rate against a simulated arm, measured."""

from __future__ import annotations

from .options import add_overwrite

__all__ = ["add", "run_hil"]


def add(sub) -> None:
    """Declare ``hil``."""
    p = sub.add_parser(
        "hil", help="run an exported controller in real time against a simulated arm",
        description="Builds EXPORT_DIR (written by rrr-pin export) with a harness and runs "
                    "its controller in its own process on absolute deadlines "
                    "(clock_nanosleep; SCHED_FIFO and mlockall when permitted) against the "
                    "export's nominal arm in another process, through shared memory. Writes "
                    "DIR/hil.json (cycles, missed, latency_us p50/p99/p999/p9999/max, "
                    "jitter_us, max_error_vs_offline_rad) and DIR/hil_run.json (conditions).")
    p.add_argument("folder", metavar="EXPORT_DIR", help="a folder written by rrr-pin export")
    p.add_argument("--cycles", type=float, default=10000, metavar="N",
                   help="control periods to run (default 10000; 1e6 is about 17 min at 1 kHz)")
    p.add_argument("--rate", type=float, default=None, metavar="HZ",
                   help="the harness clock [Hz] (default: the law's rate; the arm always "
                        "advances one law period per cycle, so a faster clock runs the same "
                        "loop faster than real time)")
    p.add_argument("--delay", type=float, default=0.0, metavar="S",
                   help="plant effect: transport delay between the torque written and the "
                        "joints [s], a whole number of law periods (default 0); a loop that "
                        "diverges ends with status 'diverged' and its time in hil.json (exit 0)")
    p.add_argument("--actuator-bandwidth", type=float, default=None, metavar="RAD_S",
                   help="plant effect: first-order actuator wa/(s + wa), wa [rad/s]")
    p.add_argument("--friction", metavar="viscous=V,coulomb=C[,smooth=S]", default=None,
                   help="plant effect: joint friction Fv qd + Fc tanh(qd / S) opposing the "
                        "motion, as montecarlo spells it (one value or one per joint separated "
                        "by '/')")
    p.add_argument("--out", default="hil", metavar="DIR", help="output folder (hil/)")
    add_overwrite(p)
    p.set_defaults(func=run_hil)


def run_hil(args) -> int:
    """Run the loop and print its figures."""
    from ..control.effects import PlantEffects
    from ..deploy.hil import hil
    from ..deploy.writer import read_record
    from .build import friction_spec
    from .common import as_options

    n = int(read_record(args.folder)["nq"])
    with as_options():
        effects = PlantEffects(delay=args.delay, actuator_bandwidth=args.actuator_bandwidth,
                               **friction_spec(args.friction, n))
        res = hil(args.folder, args.cycles, args.out, rate=args.rate, effects=effects,
                  overwrite=args.overwrite)
    s, r = res.summary, res.run
    lat = s["latency_us"]
    print(f"{r['model']}: {r['law']} at {r['clock_rate_hz']:g} Hz ({s['cycles']} cycles, law "
          f"rate {r['law_rate_hz']:g} Hz), SCHED_FIFO {'yes' if r['sched_fifo'] else 'no'}, "
          f"mlockall {'yes' if r['mlockall'] else 'no'}, load average {r['loadavg_before']}")
    print(f"latency [us] (tick -> torque written): p50 {lat['p50']:.1f}, p99 {lat['p99']:.1f}, "
          f"p99.9 {lat['p999']:.1f}, p99.99 {lat['p9999']:.1f}, max {lat['max']:.1f}")
    print(f"ctrl_step alone [us]: p50 {r['step_us']['p50']:.2f}, max {r['step_us']['max']:.1f}; "
          f"period jitter {s['jitter_us']:.1f} us; missed deadlines {s['missed']}")
    print(f"max |q_hil - q_offline| {s['max_error_vs_offline_rad']:.3g} rad; max tracking "
          f"error {r['max_tracking_error_rad']['hil']:.3g} rad (offline "
          f"{r['max_tracking_error_rad']['offline']:.3g} rad)")
    if s["status"] == "diverged":
        print(f"the loop DIVERGED at t = {s['diverged_at_s']:.6g} s (offline: "
              f"{r['offline_diverged_at_s']} s)")
    print(f"wrote {args.out}/hil.json, {args.out}/hil_run.json")
    return 0
