"""Identification end to end: from a hidden arm's logs to the study on the identified set.
=======================================================================================

1. A "true" RRR that the user does not see: the paper's thin rods given 5 cm of thickness,
   each body's mass distribution deformed by a random affine map and its mass scaled by up to
   20 % (physical by construction: ``J' = f T J T^T``).
2. An excitation designed on the nominal arm (``rrr_pin.model.excitation.design_excitation``),
   written as a spline reference CSV, tracked by the FL law on the true arm at 1 kHz with a
   1 ms actuator delay (``rrr_pin.control.effects.PlantEffects``). The log holds the torque
   that reaches the joints (the command one delay later, as a motor-current sensor measures
   it), with sensor noise (encoder 1e-4 rad, torque 0.2 N m), and no velocities or
   accelerations (the identification estimates them).
3. Identification from that CSV (``rrr_pin.model.identification``): base parameters, their
   95 % intervals, a physically consistent URDF.
4. The paper's study (``rrr-pin reproduce``) on plants drawn from the identified distribution.

With ``--friction``, the whole loop of a real arm: the hidden arm also has joint friction
(viscous and smooth Coulomb, per joint, ``FRICTION``), identified with the base parameters
(``identify --friction``); the study's plants are drawn with their friction, simulate it
(``--friction urdf``) and the laws compensate the identified friction
(``--compensate-friction``); the certificates are against the identified uncertainty; then
``rrr-pin export --compensate-friction`` writes the H-infinity + FL law with the compensation
as C (``export/``).

Writes into ``--out``: ``log.csv``, ``identify/`` (identified.urdf, identification.json),
``study/`` (the reproduce run), ``torque_prediction.png`` (held-out measured against predicted
torques) and ``estimates.png`` (estimates with 95 % intervals against the truth).

Usage::

    python scripts/identify_example.py --out results/identify_example
    python scripts/identify_example.py --quick --out /tmp/x      # seconds, to check it runs
"""

import argparse
import json
from pathlib import Path

import numpy as np

from rrr_pin.campaign.runner import make_laws
from rrr_pin.cli import main as cli
from rrr_pin.control.effects import PlantEffects
from rrr_pin.control.references import SplineReference
from rrr_pin.model import identification as idn
from rrr_pin.model.dynamics import load_robot, robot_from_xml
from rrr_pin.model.excitation import design_excitation
from rrr_pin.model.uncertainty import sample_plants
from rrr_pin.report.plotting import save_figure
from rrr_pin.sim.simulation import simulate

#: The hidden arm's friction with ``--friction``: viscous [N m s/rad] and Coulomb [N m] per
#: joint (smoothed as the plant effect does, tanh(qd / 0.01 rad/s)).
FRICTION = ((2.0, 1.5, 0.5), (1.0, 0.8, 0.3))


def hidden_truth(robot, seed=7, radius=0.05):
    """Make the arm the user does not see (see the module docstring, step 1)."""
    rng = np.random.default_rng(seed)
    phi = idn.standard_parameters(robot)
    for b in range(robot.nq):
        body = phi[10 * b:10 * b + 10].copy()
        body[[4, 6, 9]] += 0.5 * body[0] * radius**2
        T = np.eye(4)
        T[:3, :3] += rng.uniform(-0.2, 0.2, (3, 3))
        T[:3, 3] = rng.normal(0.0, 0.02, 3)
        J = rng.uniform(0.8, 1.2) * T @ idn.pseudo_inertia(body) @ T.T
        S = J[:3, :3]
        I = np.trace(S) * np.eye(3) - S
        phi[10 * b:10 * b + 10] = [J[3, 3], *J[:3, 3], I[0, 0], I[0, 1], I[1, 1], I[0, 2],
                                   I[1, 2], I[2, 2]]
    return robot_from_xml(idn.urdf_with_parameters(robot.urdf, idn.body_links(robot), phi),
                          name="hidden_truth")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("--out", default="results/identify_example", help="output folder")
    parser.add_argument("--samples", type=int, default=10, help="plants of the study (10)")
    parser.add_argument("--maxiter", type=int, default=60, help="excitation SLSQP steps (60)")
    parser.add_argument("--noise-tau", type=float, default=0.2, help="torque noise [N m]")
    parser.add_argument("--noise-q", type=float, default=1e-4, help="encoder noise [rad]")
    parser.add_argument("--friction", action="store_true",
                        help="the hidden arm has joint friction: identified, simulated, "
                             "compensated and exported (the whole loop)")
    parser.add_argument("--quick", action="store_true",
                        help="tiny settings, to check that it runs: a 2 s excitation after 3 "
                             "SLSQP steps, a 0.05 s derivative window, one plant drawn "
                             "instead of the study")
    args = parser.parse_args(argv)
    if args.quick:
        args.maxiter, args.samples = 3, 1
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    nominal = load_robot("rrr")
    truth = hidden_truth(nominal)
    quick = {"frequency": 0.5, "periods": 1, "points": 30} if args.quick else {"points": 50}
    traj, info = design_excitation(nominal, maxiter=args.maxiter, **quick)
    csv_ref = traj.write_csv(out / "excitation.csv", 100.0, nominal.joint_names)
    reference = SplineReference.from_csv(csv_ref, nominal)
    law = make_laws("fl", nominal)[0]
    delay = 1e-3
    friction = {"viscous": FRICTION[0], "coulomb": FRICTION[1]} if args.friction else {}
    run = simulate(truth, law, reference, traj.duration, rate=1000.0,
                   effects=PlantEffects(delay=delay, **friction))
    d = round(delay * 1000.0)  # the command of sample k reaches the joints at sample k + d
    rng = np.random.default_rng(1)
    t = run.t[d:]
    q = run.q[d:] + args.noise_q * rng.standard_normal(run.q[d:].shape)
    tau = run.tau[:-d] + args.noise_tau * rng.standard_normal(run.tau[:-d].shape)
    header = ",".join(["t"] + [f"{k}_{j}" for k in ("q", "tau") for j in nominal.joint_names])
    log = out / "log.csv"
    np.savetxt(log, np.column_stack([t, q, tau]), delimiter=",", header=header, comments="")
    print(f"excitation: cond {info['cond']:.3g} (random start {info['cond_random']:.3g}), "
          f"{traj.duration:g} s tracked on the hidden arm; log {log}")

    status = cli(["identify", "--robot", "rrr", "--data", str(log), "--out",
                  str(out / "identify"), "--overwrite"]
                 + (["--window", "0.05"] if args.quick else [])
                 + (["--keep-inconsistent"] if args.friction
                    else ["--no-friction", "--no-armature"]))
    if status:
        raise SystemExit(status)
    record = json.loads((out / "identify" / "identification.json").read_text())
    urdf = out / "identify" / "identified.urdf"
    # as on a real arm: the fit's Coulomb term is sign(qd) where the arm's is smooth, and the
    # log lags the command by the delay, so the estimate may lie just outside the consistent
    # set: kept (--keep-inconsistent) and its inconsistent draws projected onto it
    loop = (["--rate", "1000", "--friction", "urdf", "--compensate-friction",
             "--uncertainty-draws", "project"] if args.friction else [])
    if args.quick and not args.friction:  # one plant of the identified set, not the study
        tol = idn.IdentifiedUncertainty(str(out / "identify" / "identification.json"))
        plant = sample_plants(urdf.read_text(), 1, 0, tol)[0]
        print(f"drew plant 0: {plant.parameters['identified']['rejected']} draws rejected")
    elif args.quick:  # the loop, tiny: one plant, 0.2 s, certified
        status = cli(["montecarlo", "--robot", str(urdf), "--uncertainty",
                      str(out / "identify" / "identification.json"), "--samples", "1",
                      "--duration", "0.2", "--certify", "--controllers", "fl,hinf",
                      "--jobs", "1", "--out", str(out / "campaign"), "--overwrite",
                      "--no-progress", *loop])
    else:
        status = cli(["reproduce", "--robot", str(urdf), "--uncertainty",
                      str(out / "identify" / "identification.json"), "--samples",
                      str(args.samples), "--out", str(out / "study"), "--overwrite",
                      "--no-progress", *loop])
    if not status and args.friction:
        status = cli(["export", "--robot", str(urdf), "--law", "hinf", "--rate", "1000",
                      "--compensate-friction", "--out", str(out / "export"), "--overwrite"])
    if status:
        raise SystemExit(status)

    figures = [plot_torques(record, load_robot(str(urdf)), t, q, tau, nominal),
               plot_estimates(record, truth)]
    for fig, name in zip(figures, ("torque_prediction.png", "estimates.png"), strict=True):
        print(f"wrote {save_figure(fig, out / name)}")


def plot_torques(record, identified, t, q, tau, nominal):
    """Held-out part: measured torque against the identified URDF's prediction, per joint."""
    import matplotlib.pyplot as plt

    from rrr_pin.model.identification import estimate_derivatives

    qd, qdd, _ = estimate_derivatives(t, q, record["derivatives"]["window_s"])
    k0, k1 = record["held_out"]["first_sample"], record["held_out"]["last_sample"] + 1
    t, tau = t[:k1], tau[:k1]  # the samples the identification predicted (filter ends out)
    pred = np.array([identified.inverse_dynamics(q[k], qd[k], qdd[k]) for k in
                     range(k0, k1)])
    if record.get("friction"):  # the identified friction model, as identify fits it
        f = np.array([[v[k] for k in ("viscous_Nms_rad", "coulomb_Nm", "offset_Nm")]
                      for v in record["friction"].values()])
        pred = pred + (idn.friction_regressor(qd[k0:k1]) @ f.reshape(-1)).reshape(pred.shape)
    fig, axes = plt.subplots(nominal.nq, 2, figsize=(11, 2.2 * nominal.nq), sharex=True,
                             layout="constrained")
    for j, (ax, ax_e) in enumerate(axes):
        ax.plot(t[k0:], tau[k0:, j], color="0.55", lw=2.0, label="measured")
        ax.plot(t[k0:], pred[:, j], color="C0", lw=0.9, ls="--", label="identified URDF")
        ax.set_ylabel(f"tau {j + 1} [N m]")
        ax_e.plot(t[k0:], tau[k0:, j] - pred[:, j], color="C3", lw=0.5,
                  label="measured - predicted")
        rms = record["held_out"]["rms_error_urdf_Nm"][nominal.joint_names[j]]
        ax_e.set_ylabel(f"error {j + 1} [N m]")
        ax_e.set_title(f"{nominal.joint_names[j]}: error RMS {rms:.3g} N m", fontsize=9)
    for ax in axes[-1]:
        ax.set_xlabel("time [s] (held-out samples)")
    axes[0, 0].legend(loc="lower left", bbox_to_anchor=(0.0, 1.02), ncol=2, fontsize=8)
    axes[0, 1].legend(loc="lower right", bbox_to_anchor=(1.0, 1.12), fontsize=8)
    fig.suptitle("Held-out torques: measured vs predicted by the identified URDF")
    return fig


def plot_estimates(record, truth):
    """Each base parameter: estimate with its 95 % interval, and the truth; then in sigmas."""
    import matplotlib.pyplot as plt

    base = idn.BaseParameters.from_dict(record["base"])
    theta, std = np.array(record["estimate"]), np.array(record["std"])
    true = base(idn.standard_parameters(truth))
    x = np.arange(base.p)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 7), sharex=True, layout="constrained")
    ax1.errorbar(x, theta, yerr=1.96 * std, fmt="o", color="C0", ms=4, capsize=3,
                 label="estimate, 95 % interval")
    ax1.plot(x, true, "x", color="C3", ms=7, label="truth (hidden arm)")
    ax1.set_ylabel("value [SI: kg, kg m, kg m^2]")
    ax1.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    z = (theta - true) / std
    ax2.axhspan(-1.96, 1.96, color="C0", alpha=0.15, label="95 % interval")
    ax2.plot(x, z, "o", color="C0", ms=4, label="(estimate - truth) / std")
    ax2.axhline(0.0, color="k", lw=0.6)
    ax2.set_ylabel("estimate - truth [std]")
    ax2.set_xticks(x, base.names, rotation=60, ha="right", fontsize=8)
    ax2.set_xlabel("base parameter")
    ax2.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    inside = int(np.sum(np.abs(z) <= 1.96))
    fig.suptitle(f"Base parameters: {inside} of {base.p} truths inside their 95 % interval")
    return fig


if __name__ == "__main__":
    main()
