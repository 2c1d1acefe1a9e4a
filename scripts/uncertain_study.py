"""The paper's uncertain study (Fig. 6) from the Python API.

Draws seeded uncertain plants (20 % on masses and moments, 5 % on lengths), writes them as
URDF, runs FL alone and H-infinity + FL on each, prints the headline ratios and writes the
figure of every plant's torques and errors.

    python scripts/uncertain_study.py --samples 10 --out uncertain.png
"""

import argparse
import json

import rrr_pin
from rrr_pin.loopshaping import design
from rrr_pin.plotting import plot_study_uncertain
from rrr_pin.study import StudyConfig, run_study


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="rrr", help="arm name or URDF path (default rrr)")
    parser.add_argument("--samples", type=int, default=10, help="uncertain plants (10)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the plants (0)")
    parser.add_argument("--duration", type=float, default=4.0, help="simulated time [s]")
    parser.add_argument("--jobs", type=int, default=None, help="worker processes")
    parser.add_argument("--out", default="uncertain.png", help="PNG to write")
    args = parser.parse_args(argv)

    robot = rrr_pin.load_robot(args.robot)
    K = design(n=robot.nq).K_reduced
    config = StudyConfig(duration=args.duration, samples=args.samples, seed=args.seed,
                         jobs=args.jobs)
    result = run_study(robot, K, config=config)
    print(json.dumps(result.to_json()["summary"], indent=1))
    print(f"wrote {plot_study_uncertain(result, args.out)}")


if __name__ == "__main__":
    main()
