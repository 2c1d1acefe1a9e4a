"""Any built-in laws on the nominal arm: the paper's Fig. 5 from the Python API.
=============================================================================

Loads the paper's RRR arm (or any URDF / example-robot-data arm), builds the laws by name
(``fl``: FL alone, lam = 100 rad/s; ``hinf``: H-infinity + FL with the section-4 design,
lam = 45 rad/s; ``pd``: PD + gravity compensation), runs them on the exact model through the
runner (:func:`rrr_pin.campaign.runner.run_laws`), prints the per-joint figures and writes a PNG of
torques and tracking errors.

Usage::

    python scripts/simulate_nominal.py --out nominal.png
    python scripts/simulate_nominal.py --robot ur5 --controllers fl,hinf,pd --rate 1000
"""

import argparse

import rrr_pin
from rrr_pin.campaign.runner import RunSettings, make_laws, run_laws
from rrr_pin.control.references import default_reference
from rrr_pin.report.plotting import plot_runs, save_figure
from rrr_pin.sim.trajectory import SimulationDiverged, metrics


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("--robot", default="rrr", help="'rrr', an example-robot-data name or a "
                                                       "URDF path (default rrr)")
    parser.add_argument("--controllers", default="fl,hinf",
                        help="built-in laws, comma-separated: fl, hinf, pd (default fl,hinf)")
    parser.add_argument("--duration", type=float, default=4.0, help="simulated time [s] (4)")
    parser.add_argument("--rate", type=float, default=None,
                        help="sampled laws at this rate [Hz] (default continuous time)")
    parser.add_argument("--out", default="nominal.png", help="PNG to write")
    args = parser.parse_args(argv)

    robot = rrr_pin.load_robot(args.robot)
    laws = make_laws(args.controllers, robot)
    settings = RunSettings(duration=args.duration, rate=args.rate)
    runs = run_laws(robot, laws, default_reference(robot), settings)
    for law in laws:
        traj = runs[law.name]
        if isinstance(traj, SimulationDiverged):
            print(f"{law.name:8s} diverged: {traj}")
            continue
        m = metrics(traj)
        print(f"{law.name:8s} max |e| per joint [rad]: "
              + " ".join(f"{v:.3g}" for v in m["max_error"])
              + "   RMS torque [N m]: " + " ".join(f"{v:.4g}" for v in m["rms_torque"])
              + f"   ({traj.info['engine']} engine)")
    ok = {k: v for k, v in runs.items() if not isinstance(v, SimulationDiverged)}
    labels = {law.name: law.label or law.name for law in laws}
    path = save_figure(plot_runs(ok, robot.joint_names, title=f"{robot.name}: nominal",
                                 labels=labels), args.out)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
