"""The paper's uncertain study (Fig. 6) from the Python API, for any built-in laws.
================================================================================

Draws seeded uncertain plants (20 % on masses and moments, 5 % on lengths), runs the laws on
the nominal arm and on each plant (:func:`rrr_pin.campaign.study.run_study`), prints the headline
ratios against the baseline law and writes the figure of every plant's torques and errors.

Usage::

    python scripts/uncertain_study.py --samples 10 --out uncertain.png
    python scripts/uncertain_study.py --controllers fl,hinf,pd --rate 1000 --jobs 2
"""

import argparse
import json

import rrr_pin
from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.campaign.study import StudyConfig, run_study, summarize
from rrr_pin.report.plotting import plot_study_uncertain, save_figure


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("--robot", default="rrr", help="arm name or URDF path (default rrr)")
    parser.add_argument("--controllers", default="fl,hinf",
                        help="built-in laws, comma-separated: fl, hinf, pd (default fl,hinf)")
    parser.add_argument("--baseline", default="fl", help="law the others are compared with (fl)")
    parser.add_argument("--samples", type=int, default=10, help="uncertain plants (10)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the plants (0)")
    parser.add_argument("--duration", type=float, default=4.0, help="simulated time [s] (4)")
    parser.add_argument("--rate", type=float, default=None,
                        help="sampled laws at this rate [Hz] (default continuous time)")
    parser.add_argument("--jobs", type=int, default=None, help="worker processes (default 2)")
    parser.add_argument("--out", default="uncertain.png", help="PNG to write")
    args = parser.parse_args(argv)

    robot = rrr_pin.load_robot(args.robot)
    laws = make_laws(args.controllers, robot)
    config = StudyConfig(run=RunSettings(duration=args.duration, rate=args.rate),
                         samples=args.samples, seed=args.seed, baseline=args.baseline,
                         jobs=args.jobs)
    result = run_study(robot, laws, config=config)
    print(json.dumps(summarize(result), indent=1))
    print(f"wrote {save_figure(plot_study_uncertain(result), args.out)}")


if __name__ == "__main__":
    main()
