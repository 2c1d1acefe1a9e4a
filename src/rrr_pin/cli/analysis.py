"""``rrr-pin margins`` and ``robstab``: linear analysis at a frozen configuration, any plant."""

from __future__ import annotations

from .build import frozen_configuration, load_plant
from .common import as_options, claim_out, join
from .options import add_overwrite, add_plant_arguments

__all__ = ["add", "run_margins", "run_robstab"]


def add(sub) -> None:
    """Declare ``margins`` and ``robstab``."""
    p = sub.add_parser(
        "margins", help="gain, phase, delay and disk margins of each law's loop at the torque "
                        "input, linearized at a frozen configuration")
    add_plant_arguments(p)
    p.add_argument("--controllers", default="fl,hinf,pd", metavar="NAMES",
                   help="comma-separated built-in controllers (fl,hinf,pd)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="write margins.png (singular values, Bode phase, Nyquist) into DIR")
    add_overwrite(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run_margins)

    p = sub.add_parser(
        "robstab", help="real-parametric robust stability (mu) of the feedback-linearized "
                        "loop at a frozen configuration, inertial parameters uncertain")
    add_plant_arguments(p)
    p.add_argument("--controllers", default="fl,hinf", metavar="NAMES",
                   help="comma-separated feedback-linearizing controllers (fl,hinf)")
    p.add_argument("--tol", type=float, default=0.2,
                   help="relative tolerance of the masses and principal second moments that "
                        "the margin is counted in (0.2, the paper's 20 %%)")
    p.add_argument("--samples", type=int, default=0,
                   help="also scale this many vertices of the parameter box on perturbed "
                        "Pinocchio models until the loop is unstable (0: no check)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run_robstab)


def run_margins(args) -> int:
    """Linearize each law's loop at the frozen configuration; print (or write) its margins."""
    from ..campaign.runner import make_laws
    from ..control.analysis import loop_at_input, loop_margins
    from ..report.jsondata import dumps

    if args.out is not None:
        claim_out(args, "margins")
    robot = load_plant(args)
    q = frozen_configuration(args, robot)
    out = {"robot": robot.name, "q_rad": [float(v) for v in q], "laws": {}}
    loops = {}
    with as_options():
        laws = make_laws(args.controllers, robot)
        for law in laws:
            loops[law.name] = loop_at_input(law, robot, q)
            m = loop_margins(loops[law.name])
            out["laws"][law.name] = {
                "gain_margin_lower": m.gain_lower.tolist(),
                "gain_margin_upper": m.gain_upper.tolist(), "phase_margin_deg": m.phase.tolist(),
                "crossover_rad_s": m.crossover.tolist(), "delay_margin_s": m.delay.tolist(),
                "disk_margin": m.disk, "disk_gain_margin": m.disk_gain,
                "disk_gain_margin_db": m.disk_gain_db,
                "disk_phase_margin_deg": m.disk_phase}
    if args.out is not None:
        from ..report.margins import save_margins_figure

        qs = ", ".join(f"{float(v):.4g}" for v in q)
        out["figure"] = str(save_margins_figure(
            loops, args.out, title=f"{robot.name}: {', '.join(loops)} loops at the torque input, "
                                   f"frozen at q = [{qs}] rad"))
    if args.json:
        print(dumps(out))
        return 0
    print(f"{robot.name} at q = {[round(float(v), 4) for v in q]} rad, loop broken at the "
          f"torque input (loop at a time, per joint):")
    for name, m in out["laws"].items():
        print(f"  {name}: phase margin {join(m['phase_margin_deg'], '.1f')} deg at "
              f"{join(m['crossover_rad_s'], '.1f')} rad/s; delay margin "
              f"{join([1e3 * d for d in m['delay_margin_s']], '.2f')} ms; gain margins: "
              f"{_gain_range(m['gain_margin_lower'], m['gain_margin_upper'])}; disk margin "
              f"{m['disk_margin']:.3f} "
              f"(gain x{m['disk_gain_margin']:.3g} = {m['disk_gain_margin_db']:.3g} dB, "
              f"phase {m['disk_phase_margin_deg']:.1f} "
              f"deg, all joints at once)")
    if "figure" in out:
        print(f"wrote {out['figure']}")
    return 0


def run_robstab(args) -> int:
    """Compute each law's real-parametric robust stability margin at the configuration."""
    from ..campaign.runner import make_laws
    from ..control.analysis import parametric_margin, sampled_margin
    from ..report.jsondata import dumps
    from ..validation import check_count

    robot = load_plant(args)
    q = frozen_configuration(args, robot)
    out = {"robot": robot.name, "q_rad": [float(v) for v in q], "tol": args.tol, "laws": {}}
    with as_options():
        samples = check_count("samples", args.samples)
        for law in make_laws(args.controllers, robot):
            try:
                loop, r = parametric_margin(law, q, args.tol)
            except TypeError as exc:  # pd: no feedback-linearizing loop
                raise ValueError(f"--controllers {law.name}: {exc}") from None
            rec = {"margin_lower": r.margin_lower, "margin_upper": r.margin_upper,
                   "critical_frequency_rad_s": r.critical_frequency,
                   "parameters": loop.names, "dropped": loop.dropped}
            if samples:
                rec["sampled_margin"] = sampled_margin(law, loop, samples)[0]
            out["laws"][law.name] = rec
    if args.json:
        print(dumps(out))
        return 0
    print(f"{robot.name} at q = {[round(float(v), 4) for v in q]} rad: inertial parameters "
          f"uncertain, margin in units of +-{100 * args.tol:g} %")
    for name, m in out["laws"].items():
        line = (f"  {name}: stable for all errors up to {m['margin_lower']:.3f} x "
                f"{100 * args.tol:g} %; a {m['margin_upper']:.3f} x error destabilizes it "
                f"(at {m['critical_frequency_rad_s']:.3g} rad/s); {len(m['parameters'])} "
                f"parameters")
        if "sampled_margin" in m:
            line += f"; sampled vertices: unstable from {m['sampled_margin']:.3f} x"
        print(line)
    return 0


def _gain_range(lower, upper) -> str:
    """Per joint, the loop-gain factors the loop stays stable within: ``x0.046 to inf``."""
    def one(lo, hi):
        return (f"x{lo:.3g}" if lo > 0 else "0") + " to " + (f"x{hi:.3g}" if hi < float("inf")
                                                                else "inf")
    return "/".join(one(lo, hi) for lo, hi in zip(lower, upper, strict=True)) + \
        " (lower to upper, per joint)"
