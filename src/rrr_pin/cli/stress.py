"""``rrr-pin stress``: where each controller breaks under an unmodeled effect, on any plant."""

from __future__ import annotations

import time

from .build import load_model_and_plant, plant_friction_record
from .common import as_options, claim_out, option
from .options import add_design_argument, add_force_argument, add_overwrite, add_plant_arguments

__all__ = ["add", "run_stress", "parse_with"]


def add(sub) -> None:
    """Declare ``stress``."""
    from ..control.catalog import DEFAULT_BUDGET, EFFECT_FIELDS, EFFECTS
    from ..sim.engines import ENGINE_CHOICES

    p = sub.add_parser(
        "stress", help="where each controller breaks under an unmodeled effect",
        description="For each --controllers law and the --effect, the breaking point of the "
                    "nonlinear closed loop (bisection on the effect's size: the run diverges "
                    "or its RMS tracking error exceeds --budget), the linear prediction of the "
                    "design's digital loop, and what the robust-stability barrier of eq. "
                    "(12)-(13) guarantees, on the plant's study reference. Writes "
                    "stress_<effect>.png (and .json) into --out.")
    add_plant_arguments(p, plant=True)
    p.add_argument("--controllers", default="fl,hinf,pd", metavar="NAMES",
                   help="comma-separated built-in controllers (fl,hinf,pd)")
    p.add_argument("--effect", required=True, metavar="NAME",
                   help="; ".join(f"{k}: {v.what} [{v.unit}]" for k, v in EFFECTS.items())
                        + " (also named by the PlantEffects field and option it sizes: "
                        + ", ".join(f"{f} = {k}" for f, k in EFFECT_FIELDS.items()) + ")")
    p.add_argument("--with", dest="fixed", action="append", default=[], metavar="EFFECT=SIZE",
                   help="hold another effect at a size in every run, e.g. actuator=300 "
                        "(repeatable or comma-separated); predictions include it")
    p.add_argument("--budget", type=float, default=DEFAULT_BUDGET,
                   help=f"RMS tracking error [rad] above which a run is broken "
                        f"({DEFAULT_BUDGET:g})")
    p.add_argument("--duration", type=float, default=2.0,
                   help="shortest simulated time per run [s] (2; slow loops run longer)")
    p.add_argument("--rate", type=float, default=1000.0, metavar="HZ",
                   help="sampling rate of the controllers [Hz] (1000)")
    p.add_argument("--dt", type=float, default=None,
                   help="plant RK4 sub-step [s], which must divide 1/rate; also the grid the "
                        "delay is searched on (default: the largest such step up to 1e-4)")
    p.add_argument("--engine", choices=ENGINE_CHOICES, default=ENGINE_CHOICES[0],
                   help="simulation engine (auto: the first that runs each run exactly)")
    add_force_argument(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--out", default="results/stress", metavar="DIR",
                   help="folder for the figure and the JSON (results/stress)")
    add_overwrite(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-figures", action="store_true",
                   help="no stress_<effect>.png (matplotlib not imported); the JSON is the "
                        "same but for its figure (null)")
    add_design_argument(p)
    p.set_defaults(func=run_stress)


def parse_with(items, effect: str) -> dict:
    """``["actuator=300", "delay=0.001,..."]`` -> ``{"actuator": 300.0, ...}`` (``--with``)."""
    from ..campaign.stress import check_fixed
    from ..validation import FieldError

    fixed = {}
    for item in (part.strip() for text in items for part in text.split(",")):
        name, sep, size = item.partition("=")
        try:
            value = float(size)
        except ValueError:
            value = None
        if not sep or value is None or name.strip() in fixed:
            raise FieldError("--with", f"{{name}} expects EFFECT=SIZE, each effect once (e.g. "
                                       f"actuator=300), got {item!r}")
        fixed[name.strip()] = value
    try:
        return check_fixed(fixed, effect)
    except FieldError as exc:
        raise exc.relabelled(lambda _: "--with") from None


def run_stress(args) -> int:
    """Search each law's breaking point, write the figure and JSON, print the table."""
    from tqdm import tqdm

    from ..campaign.runner import RunSettings, make_laws
    from ..campaign.stress import StressSettings, stress
    from ..control.catalog import EFFECTS, effect_name
    from ..control.specs import ReferenceSpec
    from ..report.jsondata import dumps
    from ..report.stress import stress_lines, write_stress
    from ..sim.simulation import largest_substep
    from ..validation import check_rate
    from .common import floats

    args.effect = effect_name(args.effect)  # --effect torque_limit is --effect torque
    if args.effect not in EFFECTS:
        raise ValueError(f"--effect {args.effect!r} is unknown; known effects: "
                         f"{', '.join(EFFECTS)}")
    rate = check_rate("--rate", args.rate)
    fixed = parse_with(args.fixed, args.effect)
    with as_options():
        dt = args.dt if args.dt is not None else largest_substep(rate, 1e-4)
        settings = StressSettings(run=RunSettings(duration=args.duration, dt=dt,
                                                  rate=rate, engine=args.engine,
                                                  force=args.force),
                                  budget=args.budget)
    stem = args.effect + "".join(f"_with_{k}{v:g}" for k, v in fixed.items())
    claim_out(args, "stress", part=stem)  # one folder holds every effect's run
    model, plant, match = load_model_and_plant(args)
    home = floats(args.home, "--home")
    if home is not None and plant.task_path(args.duration) is not None:
        # stress has no --reference: the specification's hint to give one does not apply
        raise ValueError(f"--home centres the sinusoid of a serial arm's study reference; the "
                         f"study reference of {plant.name!r} is its task path, which --home "
                         f"does not move (stress runs the study reference only)")
    reference = ReferenceSpec(kind="study", home=None if home is None else tuple(home)).build(
        plant, args.duration, label=option)
    from .build import design_record, tuned_from_args

    names = [n.strip() for n in args.controllers.split(",")]
    tuned = tuned_from_args(args, model, names)
    with as_options():
        laws = make_laws([n for n in names if n != "tuned"], model) \
            if set(names) - {"tuned"} else []
    if tuned is not None:
        laws.insert(names.index("tuned"), tuned)
    start = time.perf_counter()
    bar = tqdm(total=len(laws), unit="law", desc=f"{plant.name}: stress {args.effect}",
               disable=args.no_progress)
    result = stress(plant, laws, reference, args.effect, settings, fixed=fixed,
                    progress=lambda done, total: bar.update(done - bar.n))
    bar.close()
    result["elapsed_s"] = time.perf_counter() - start
    result["robot"] = plant.name
    if match is not None:
        result["joint_match"] = match.to_dict()
    friction = plant_friction_record(plant, settings.run)
    if friction is not None:
        result["plant_friction"] = friction
    result["stem"] = stem
    if design_record(args) is not None:
        result["design"] = design_record(args)
    fig = write_stress(result, args.out, figure=not args.no_figures)
    if args.json:
        print(dumps(result))
        return 0
    if friction is not None:
        print(f"{plant.name}: its own damping and friction loss ({friction['source']}): "
              f"{friction['note']}")
    print("\n".join(stress_lines(result) + [f"wrote {fig}"]))
    return 0
