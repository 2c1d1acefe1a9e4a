"""Held-out torque prediction on a logged Franka Emika Panda: rigid, with friction, published.
===========================================================================================

Reads a log split into per-quantity text files (``time.txt``, ``positions.txt``,
``velocity.txt``, ``torques.txt``; one number per line, 7 per sample: the layout of Gaz et al.
2019's excitation logs, :func:`rrr_pin.model.identification.read_split_log`), identifies
example-robot-data's ``panda`` (fingers locked) on the first part of the log, rigid only and
with friction, and predicts the rest. Next to them, the published model of Gaz et al. 2019
(their retrieved inertial parameters, Tables VIII-IX of the supplementary material, and their
sigmoid friction) on the same window with the same filtering: accelerations from the same
Savitzky-Golay filter, the torques and every friction torque filtered alike.

Writes into ``--out``: ``panda_heldout.json`` (per-joint held-out RMS [N m] and R^2 of each
model, the link masses [kg] identified, published and example-robot-data's) and
``panda_heldout.png`` (measured and predicted torques on the held-out window, every joint).

Usage::

    python scripts/panda_heldout.py LOG_FOLDER --out results/panda

The log itself is not part of this repository.

References
----------
C. Gaz, M. Cognetti, A. Oliva, P. Robuffo Giordano, A. De Luca, "Dynamic Identification of
the Franka Emika Panda Robot With Retrieval of Feasible Parameters Using Penalty-Based
Optimization", IEEE RA-L 4(4), 2019; the numbers below from its supplementary material as
published in the repository marcocognetti/FrankaEmikaPandaDynModel.
"""

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

from rrr_pin.model import identification as idn
from rrr_pin.model.dynamics import load_robot, robot_from_xml
from rrr_pin.report.plotting import save_figure

#: Gaz et al. 2019: link masses [kg], links 1-7.
GAZ_MASS = np.array([4.970684, 0.646926, 3.228604, 3.587895, 1.225946, 1.666555, 0.735522])
#: Centres of mass [m] in each link's frame (Franka's modified DH frames, example-robot-data's
#: link frames), links 1-7.
GAZ_COM = np.array([[3.875e-03, 2.081e-03, 0.0], [-3.141e-03, -2.872e-02, 3.495e-03],
                    [2.7518e-02, 3.9252e-02, -6.6502e-02], [-5.317e-02, 1.04419e-01, 2.7454e-02],
                    [-1.1953e-02, 4.1065e-02, -3.8437e-02], [6.0149e-02, -1.4117e-02, -1.0517e-02],
                    [1.0517e-02, -4.252e-03, 6.1597e-02]])
#: Inertias about the centre of mass [kg m^2], link axes: Ixx, Ixy, Ixz, Iyy, Iyz, Izz.
GAZ_INERTIA = np.array([
    [7.0337e-01, -1.3900e-04, 6.7720e-03, 7.0661e-01, 1.9169e-02, 9.1170e-03],
    [7.9620e-03, -3.9250e-03, 1.0254e-02, 2.8110e-02, 7.0400e-04, 2.5995e-02],
    [3.7242e-02, -4.7610e-03, -1.1396e-02, 3.6155e-02, -1.2805e-02, 1.0830e-02],
    [2.5853e-02, 7.7960e-03, -1.3320e-03, 1.9552e-02, 8.6410e-03, 2.8323e-02],
    [3.5549e-02, -2.1170e-03, -4.0370e-03, 2.9474e-02, 2.2900e-04, 8.6270e-03],
    [1.9640e-03, 1.0900e-04, -1.1580e-03, 4.3540e-03, 3.4100e-04, 5.4330e-03],
    [1.2516e-02, -4.2800e-04, -1.1960e-03, 1.0027e-02, -7.4100e-04, 4.8150e-03]])
#: Sigmoid friction per joint: tau_f = phi1 / (1 + exp(-phi2 (qd + phi3))) - phi1 / (1 +
#: exp(-phi2 phi3)); rows phi1 [N m], phi2 [s/rad], phi3 [rad/s].
GAZ_FRICTION = np.array([[0.54615, 0.87224, 0.64068, 1.2794, 0.83904, 0.30301, 0.56489],
                         [5.1181, 9.0657, 10.136, 5.5903, 8.3469, 17.133, 10.336],
                         [0.039533, 0.025882, -0.04607, 0.036194, 0.026226, -0.021047,
                          0.0035526]])


def gaz_phi() -> np.ndarray:
    """Gaz et al.'s bodies as standard parameters (Pinocchio's order), shape (70,)."""
    out = []
    for m, c, (ixx, ixy, ixz, iyy, iyz, izz) in zip(GAZ_MASS, GAZ_COM, GAZ_INERTIA,
                                                     strict=True):
        Ic = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        I = Ic + m * (c @ c * np.eye(3) - np.outer(c, c))  # about the link frame's origin
        out += [m, *(m * c), I[0, 0], I[0, 1], I[1, 1], I[0, 2], I[1, 2], I[2, 2]]
    return np.array(out)


def gaz_friction(qd) -> np.ndarray:
    """Return the published sigmoid friction [N m] at ``qd`` [rad/s], shape (N, 7)."""
    p1, p2, p3 = GAZ_FRICTION
    return p1 / (1.0 + np.exp(-p2 * (qd + p3))) - p1 / (1.0 + np.exp(-p2 * p3))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("log", help="folder of the per-quantity log files")
    parser.add_argument("--out", default="results/panda", help="output folder")
    parser.add_argument("--held-out", type=float, default=0.3,
                        help="final fraction of the log predicted (0.3)")
    parser.add_argument("--mass-band", type=float, default=2.0,
                        help="every body's mass within [m0/F, F m0] of the URDF's (2)")
    parser.add_argument("--inertia-band", type=float, default=None,
                        help="every body's pseudo-inertia within [J0/F, F J0] of the URDF's "
                             "(default: none)")
    args = parser.parse_args(argv)
    robot = load_robot("panda")  # example-robot-data's, the fingers locked (logged)
    try:
        data = idn.read_split_log(args.log, robot)
    except idn.IdentificationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    tau_f = idn.filter_like(data, data.tau)
    fits, preds = {}, {}
    for name, friction in (("rigid", False), ("friction", True)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = idn.identify(robot, data, held_out=args.held_out, friction=friction,
                               refuse_inconsistent=False, mass_band=args.mass_band,
                               inertia_band=args.inertia_band)
        fits[name] = res
        arm = robot_from_xml(res.urdf, name=f"panda_{name}")  # its locks are written in
        preds[name] = idn.predict_torques(arm, data, res.summary["friction"])
        print(f"{name}: {len(caught)} warnings: " + " | ".join(
            str(w.message)[:160] for w in caught))
    held = fits["friction"].summary["held_out"]
    k0, k1 = held["first_sample"], held["last_sample"] + 1
    gaz = robot_from_xml(idn.urdf_with_parameters(robot.urdf, idn.body_links(robot), gaz_phi(),
                                                  moving=robot.joint_names),
                         name="panda_gaz2019", lock=dict(robot.locked) or None)
    preds["published"] = (idn.predict_torques(gaz, data)
                          + idn.filter_like(data, gaz_friction(data.qd)))
    sl = slice(k0, k1)
    table = {}
    for name, pred in preds.items():
        e = tau_f[sl] - pred[sl]
        table[name] = {"rms_Nm": np.sqrt(np.mean(e ** 2, axis=0)).tolist(),
                       "r2": idn.r_squared(tau_f[sl], pred[sl]).tolist()}
    masses = {"identified_friction": fits["friction"].phi[0::10].tolist(),
              "identified_rigid": fits["rigid"].phi[0::10].tolist(),
              "published_gaz2019": GAZ_MASS.tolist(),
              "example_robot_data": idn.standard_parameters(robot)[0::10].tolist()}
    record = {"log": str(args.log), "samples": data.N, "held_out_fraction": args.held_out,
              "window": [float(data.t[k0]), float(data.t[k1 - 1])],
              "derivatives": data.derived, "mass_band": args.mass_band,
              "inertia_band": args.inertia_band,
              "joints": robot.joint_names, "held_out": table, "masses_kg": masses,
              "friction_identified": fits["friction"].summary["friction"],
              "consistency": {k: fits[k].summary["consistency"] for k in fits}}
    (out / "panda_heldout.json").write_text(json.dumps(record, indent=1) + "\n")
    print(f"held-out {k1 - k0} samples, t = {data.t[k0]:.2f} .. {data.t[k1 - 1]:.2f} s")
    print("RMS [N m] per joint " + " ".join(f"{j + 1:>6}" for j in range(robot.nq))
          + "   R^2 joint 7")
    for name, row in table.items():
        print(f"{name:>19} " + " ".join(f"{v:6.3f}" for v in row["rms_Nm"])
              + f"   {row['r2'][-1]:.3f}")
    print("masses [kg]         " + " ".join(f"{j + 1:>6}" for j in range(robot.nq)))
    for name, row in masses.items():
        print(f"{name:>19} " + " ".join(f"{v:6.3f}" for v in row))
    fig = plot(data, tau_f, preds, table, sl, robot)
    print(f"wrote {save_figure(fig, out / 'panda_heldout.png')}")
    print(f"wrote {out / 'panda_heldout.json'}")


def plot(data, tau_f, preds, table, sl, robot):
    """Measured (filtered) and predicted torques on the held-out window, one row per joint."""
    import matplotlib.pyplot as plt

    n = robot.nq
    fig, axes = plt.subplots(n, 1, figsize=(11, 1.7 * n), sharex=True, layout="constrained")
    t = data.t[sl]
    style = {"rigid": ("C1", ":"), "friction": ("C0", "--"), "published": ("C3", "-.")}
    label = {"rigid": "identified, rigid only", "friction": "identified with friction",
             "published": "Gaz et al. 2019 (published)"}
    for j, ax in enumerate(axes):
        ax.plot(t, tau_f[sl, j], color="0.6", lw=2.2, label="measured (filtered)")
        for name, pred in preds.items():
            c, ls = style[name]
            ax.plot(t, pred[sl, j], color=c, ls=ls, lw=0.9, label=label[name])
        ax.set_ylabel(f"tau {j + 1} [N m]")
        ax.set_title(", ".join(f"{k} RMS {table[k]['rms_Nm'][j]:.3f} N m, R^2 "
                               f"{table[k]['r2'][j]:.3f}" for k in preds), fontsize=8)
    axes[-1].set_xlabel("time [s] (held-out window)")
    axes[0].legend(loc="lower left", bbox_to_anchor=(0.0, 1.25), ncol=4, fontsize=8)
    fig.suptitle("Franka Emika Panda, held-out torques: measured vs predicted")
    return fig


if __name__ == "__main__":
    main()
