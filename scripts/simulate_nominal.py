"""One plant, both controllers: the paper's Fig. 5 from the Python API.

Loads the paper's RRR arm (or any URDF / example-robot-data arm), designs the H-infinity
controller of section 4, simulates FL alone (lam = 100 rad/s) and H-infinity + FL
(lam = 45 rad/s) on the exact model, prints the per-joint figures and writes a PNG of torques
and tracking errors.

    python scripts/simulate_nominal.py --out nominal.png
    python scripts/simulate_nominal.py --robot ur5 --duration 2 --rate 1000
"""

import argparse

import rrr_pin
from rrr_pin.controllers import fl_controller, hinf_fl_controller
from rrr_pin.loopshaping import design
from rrr_pin.plotting import plot_runs
from rrr_pin.simulate import metrics, simulate
from rrr_pin.study import default_reference


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="rrr", help="'rrr', an example-robot-data name or a "
                                                       "URDF path (default rrr)")
    parser.add_argument("--duration", type=float, default=4.0, help="simulated time [s]")
    parser.add_argument("--rate", type=float, default=None,
                        help="sampled controllers at this rate [Hz] (default continuous)")
    parser.add_argument("--out", default="nominal.png", help="PNG to write")
    args = parser.parse_args(argv)

    robot = rrr_pin.load_robot(args.robot)
    K = design(n=robot.nq).K_reduced  # eq. (18), negative feedback on e = r - q
    reference = default_reference(robot)
    runs = {"fl": simulate(robot, fl_controller(robot), reference, args.duration,
                           rate=args.rate),
            "hinf": simulate(robot, hinf_fl_controller(robot, K), reference, args.duration,
                             rate=args.rate)}
    for traj in runs.values():
        m = metrics(traj)
        print(f"{traj.controller:8s} max |e| per joint [rad]: "
              + " ".join(f"{v:.3g}" for v in m["max_error"])
              + "   RMS torque [N m]: " + " ".join(f"{v:.4g}" for v in m["rms_torque"]))
    print(f"wrote {plot_runs(runs, robot.joint_names, args.out, title=f'{robot.name}: nominal')}")


if __name__ == "__main__":
    main()
