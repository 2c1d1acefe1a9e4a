"""``rrr-pin identify``: base inertial parameters from measured torques, or an excitation."""

from __future__ import annotations

import argparse
import json
import math

from .build import load_plant
from .common import as_options, claim_out, not_a_folder
from .options import add_overwrite

__all__ = ["add", "run_identify"]

#: Upper bound of the waypoints written to excitation.csv.
MAX_CSV_SAMPLES = 10_000_000

#: What identification needs of a plant, and why (the refusal's reason).
_WHY = ("the base-parameter regressor is that of a serial tree with a torque at every joint "
        "(a mechanism is driven at its actuated joints only: its passive joints' torques are "
        "the loop forces)")


def add(sub) -> None:
    """Declare ``identify``."""
    p = sub.add_parser(
        "identify", help="identify the arm's base inertial parameters from measured torques",
        description="Reads --data (CSV: t, q_<joint>, optionally qd_<joint> and qdd_<joint>, "
                    "tau_<joint>, SI units), estimates the base inertial parameters of --robot "
                    "with their covariance, makes them physically consistent (SDP) and writes "
                    "DIR/identified.urdf and DIR/identification.json. With "
                    "--design-excitation, writes instead an optimised Fourier excitation, "
                    "DIR/excitation.csv (for --reference spline --csv) and excitation.json.")
    p.add_argument("--robot", default=None, metavar="NAME|PATH",
                   help="arm whose kinematics are trusted and whose inertials are the prior: "
                        "'rrr' (default), an example-robot-data name or a URDF path")
    p.add_argument("--lock", action="append", metavar="JOINT=VALUE",
                   help="lock a joint at a position [rad or m] (repeatable), e.g. the Panda's "
                        "fingers: --lock panda_finger_joint1=0 --lock panda_finger_joint2=0")
    p.add_argument("--data", metavar="FILE.csv|DIR", nargs="+", default=None,
                   help="measurements (required unless --design-excitation): a CSV, or a "
                        "folder of per-quantity text files (time.txt, positions.txt, "
                        "velocity.txt, torques.txt: one number per line, nq per sample, as "
                        "Gaz et al.'s Panda logs); several runs: several, each filtered on "
                        "its own, fitted together")
    p.add_argument("--friction", action=argparse.BooleanOptionalAction, default=None,
                   help="identify each joint's viscous and Coulomb friction and torque offset "
                        "with the base parameters (written into identification.json and the "
                        "URDF's <dynamics damping friction>); on by default")
    p.add_argument("--armature", action=argparse.BooleanOptionalAction, default=None,
                   help="identify each joint's armature (reflected rotor inertia, added to "
                        "M(q)'s diagonal; in identification.json, not the URDF); a joint whose "
                        "estimate is below 0 is said and left out; on by default")
    p.add_argument("--covariance", choices=("calibrated", "noise"), default=None,
                   help="'calibrated' (default): Newey-West covariance scaled by a block "
                        "jackknife, which includes the model error; 'noise': white noise "
                        "around a correct model")
    p.add_argument("--folds", default=None, metavar="K|period|runs",
                   help="cross-validate: K contiguous segments, one fold per period of a "
                        "periodic excitation, or one per run; reported per fold, with the "
                        "coverage of --level prediction intervals")
    p.add_argument("--level", type=float, default=0.95, metavar="P",
                   help="level of the prediction intervals, in (0, 1) (0.95): of --folds, "
                        "and of tau_<joint>_lo/_hi written by --model")
    p.add_argument("--mass-band", type=float, default=None, metavar="F",
                   help="plausibility bound of the consistent arm: every body's mass within "
                        "[m0/F, F m0] of --robot's (default: pseudo-inertia positive definite "
                        "only)")
    p.add_argument("--inertia-band", type=float, default=None, metavar="F",
                   help="plausibility bound of the consistent arm: every body's pseudo-inertia "
                        "(mass, first and second moments) between J0/F and F J0 of --robot's, "
                        "in every direction (default: none)")
    p.add_argument("--keep-inconsistent", action="store_true",
                   help="keep the nearest consistent arm, with a warning, when it lies outside "
                        "the estimate's 99.9%% region of the covariance; refused by default")
    p.add_argument("--model", metavar="DIR", default=None,
                   help="predict only: the torques of --data with the model identified in DIR "
                        "(its identified.urdf, friction and armature), with --level prediction "
                        "intervals (tau_<joint>_lo, tau_<joint>_hi); writes "
                        "--out/prediction.csv and prediction.json, fits nothing")
    p.add_argument("--method", choices=("wls", "ols"), default="wls",
                   help="weighted (per-joint noise, default) or ordinary least squares")
    p.add_argument("--held-out", type=float, default=0.2, metavar="FRACTION",
                   help="final fraction of the samples left out of the fit and predicted (0.2)")
    p.add_argument("--window", type=float, default=None, metavar="S",
                   help="Savitzky-Golay window [s] for derivatives missing from the data "
                        "(default max(0.2 s, 11 samples))")
    g = p.add_argument_group("excitation")
    g.add_argument("--design-excitation", action="store_true",
                   help="design an excitation trajectory instead of identifying")
    g.add_argument("--harmonics", type=int, default=5, help="Fourier harmonics per joint (5)")
    g.add_argument("--frequency", type=float, default=0.2, metavar="HZ",
                   help="base frequency [Hz] (0.2: a 5 s period)")
    g.add_argument("--periods", type=int, default=2, help="periods in the trajectory (2)")
    g.add_argument("--max-acceleration", type=float, default=10.0, metavar="RAD_S2",
                   help="acceleration limit of every joint [rad/s^2] (10)")
    g.add_argument("--maxiter", type=int, default=60, help="SLSQP iterations (60)")
    g.add_argument("--seed", type=int, default=0, help="seed of the starting point (0)")
    g.add_argument("--csv-rate", type=float, default=100.0, metavar="HZ",
                   help="waypoints per second in excitation.csv (100)")
    p.add_argument("--out", default="results/identify", metavar="DIR",
                   help="output folder (results/identify)")
    add_overwrite(p)
    p.set_defaults(func=run_identify)


def run_identify(args) -> int:
    """Identify from ``--data``, or design an excitation; write and print the result."""
    from ..model.plant import URDF
    from ..outputs import writing

    if not (math.isfinite(args.level) and 0.0 < args.level < 1.0):
        raise ValueError(f"--level must be in (0, 1) (the prediction intervals' coverage), "
                         f"got {args.level!r}")
    if args.data is not None:
        from pathlib import Path

        seen = {}
        for path in args.data:
            key = Path(path).resolve()
            if key in seen:
                raise ValueError(f"--data: {path!r} is given twice (as {seen[key]!r}): the same "
                                 f"log fitted twice would halve its variance; give each run "
                                 f"once")
            seen[key] = path
    if args.model is not None:
        return _predict(args)
    if args.design_excitation:
        given = [opt for opt, v in (("--friction/--no-friction", args.friction),
                                    ("--armature/--no-armature", args.armature),
                                    ("--covariance", args.covariance), ("--folds", args.folds),
                                    ("--mass-band", args.mass_band),
                                    ("--inertia-band", args.inertia_band)) if v is not None]
        if given or args.keep_inconsistent:
            raise ValueError("--design-excitation designs the motion to log and fits nothing: "
                             + ", ".join(given + (["--keep-inconsistent"]
                                                  if args.keep_inconsistent else []))
                             + " would not act; leave them out")
    args.robot = "rrr" if args.robot is None else args.robot
    args.friction = True if args.friction is None else args.friction
    args.armature = True if args.armature is None else args.armature
    args.covariance = "calibrated" if args.covariance is None else args.covariance
    not_a_folder(robot=args.robot)
    folds = _folds(args.folds)
    from ..model.excitation import MAX_HARMONICS

    for name, lo in (("harmonics", 2), ("periods", 1), ("maxiter", 1)):
        hi = MAX_HARMONICS if name == "harmonics" else None
        v = getattr(args, name)
        if v < lo or (hi is not None and v > hi):
            raise ValueError(f"--{name} must be an integer >= {lo}"
                             + (f" and <= {hi}" if hi else "") + f", got {v!r}")
    for name in ("mass_band", "inertia_band"):
        v = getattr(args, name)
        if v is not None and not (math.isfinite(v) and v > 1.0):
            raise ValueError(f"--{name.replace('_', '-')} must be a finite factor > 1, got "
                             f"{v!r}")
    for name in ("frequency", "csv_rate", "max_acceleration"):
        v = getattr(args, name)
        if not (math.isfinite(v) and v > 0.0):
            raise ValueError(f"--{name.replace('_', '-')} must be a finite number > 0, got {v!r}")
    if args.design_excitation:
        samples = args.periods / args.frequency * args.csv_rate
        if samples > MAX_CSV_SAMPLES:
            raise ValueError(f"--periods {args.periods} / --frequency {args.frequency:g} Hz at "
                             f"--csv-rate {args.csv_rate:g} Hz make {samples:.3g} waypoints, "
                             f"above {MAX_CSV_SAMPLES:.0e}: lower --csv-rate or raise "
                             f"--frequency")
    if args.design_excitation and args.data is not None:
        raise ValueError("--data is not read by --design-excitation (it designs the "
                         "motion to log); give one or the other")
    if not args.design_excitation and args.data is None:
        raise ValueError("--data FILE.csv is required (or --design-excitation)")
    robot = load_plant(args, armature=False)  # --armature: the column to identify
    robot.require(URDF, f"rrr-pin identify --robot {args.robot} ({_WHY})")
    if args.design_excitation:
        from ..model.excitation import design_excitation

        with as_options():
            traj, info = design_excitation(
                robot, harmonics=args.harmonics, frequency=args.frequency,
                max_acceleration=args.max_acceleration, periods=args.periods,
                seed=args.seed, maxiter=args.maxiter)
        out = claim_out(args, "identify")
        csv_path = traj.write_csv(out / "excitation.csv", args.csv_rate, robot.joint_names)
        path = out / "excitation.json"
        with writing(path):
            path.write_text(json.dumps({"robot": robot.name, **info,
                                        "trajectory": traj.to_dict()}, indent=1) + "\n")
        print(f"{robot.name}: Fourier excitation, {info['harmonics']} harmonics at "
              f"{info['frequency_hz']:g} Hz, {traj.duration:g} s; condition number of the "
              f"base regressor {info['cond']:.4g} (random start {info['cond_random']:.4g})")
        print(f"wrote {csv_path} and {path}; run it with --reference spline --csv {csv_path} "
              f"--duration {traj.duration:g}")
        return 0
    import warnings

    from ..model.identification import cross_validate, identify

    with as_options(), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        data = [_read(path, robot, args.window) for path in args.data]
        result = identify(robot, data, method=args.method, held_out=args.held_out,
                          friction=args.friction, armature=args.armature,
                          covariance=args.covariance, mass_band=args.mass_band,
                          inertia_band=args.inertia_band,
                          refuse_inconsistent=not args.keep_inconsistent)
        cv = None if folds is None else cross_validate(
            robot, data, folds, method=args.method, friction=args.friction,
            armature=args.armature, level=args.level)
    for w in caught:  # the model-error and consistency warnings, said once, without a path
        print(f"warning: {w.message}")
    if cv is not None:
        result.summary["cross_validation"] = cv
    out = claim_out(args, "identify")
    written = result.write(out)
    s = result.summary
    extra = f" and {3 * robot.nq} friction" if s["friction"] else ""
    print(f"{robot.name}: {s['base_count']} base{extra} parameters from {s['samples_fit']} samples "
          f"({s['method']}), condition number {s['condition_number']:.4g}")
    print("residual RMS [N m]: " + ", ".join(f"{k} {v:.4g}"
                                             for k, v in s["residual_rms_Nm"].items()))
    if s["friction"]:
        print("friction (viscous [N m s/rad], Coulomb [N m], offset [N m]): " + ", ".join(
            f"{k} {v['viscous_Nms_rad']:.3g}/{v['coulomb_Nm']:.3g}/{v['offset_Nm']:.3g}"
            for k, v in s["friction"].items()))
    if s["held_out"] is not None:
        print(f"held-out {s['held_out']['samples']} samples, identified URDF's torque error "
              "RMS [N m]: " + ", ".join(f"{k} {v:.4g}" for k, v in
                                       s["held_out"]["rms_error_urdf_Nm"].items()))
    if s.get("armature"):
        print("armature [kg m^2]: " + ", ".join(
            f"{k} " + ("absorbed into " + "/".join(v["absorbed_into"]) if "absorbed_into" in v
                       else "not detected (estimate < 0)" if "not_detected" in v
                       else f"{v['value_kg_m2']:.3g} +- {v['std']:.2g}")
            for k, v in s["armature"].items()))
    c = s["consistency"]
    w = c["written"]
    print("physically consistent: " + ("the estimate itself" if c["feasible_at_estimate"]
                                       else "the nearest consistent arm") +
          f", {w['mahalanobis']:.3g} standard deviations of the {args.covariance} covariance "
          f"from the estimate ({w['mahalanobis_noise']:.3g} of the noise-only one), RMS torque "
          f"change {w['rms_Nm_all']:.3g} N m")
    if cv is not None:
        print(f"cross-validation ({cv['kind']}" + (f", period {cv['period_s']:.4g} s"
                                                    if cv["period_s"] else "")
              + f"), {cv['level']:.0%} prediction intervals:")
        for f in cv["folds"]:
            print(f"  fold {f['fold']} (run {f['run']}, samples {f['first_sample']}.."
                  f"{f['last_sample']}" + (", repeats the training motion" if
                                            f["repeats_training"] else "") + "): RMS [N m] "
                  + " ".join(f"{v:.3g}" for v in f["rms_Nm"].values()) + "; covered "
                  + " ".join(f"{v:.0%}" for v in f["coverage"].values()))
        print("  all folds: RMS [N m] " + " ".join(f"{v:.3g}" for v in cv["rms_Nm"].values())
              + "; covered " + " ".join(f"{v:.1%}" for v in cv["coverage"].values()))
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


def _predict(args) -> int:
    """``--model DIR``: predict ``--data``'s torques with DIR's identified model; fit nothing."""
    from pathlib import Path

    import numpy as np

    from ..model.dynamics import robot_from_xml
    from ..model.identification import IdentificationError, predict_torques
    from ..outputs import writing

    if args.data is None or len(args.data) != 1:
        raise ValueError("--model DIR predicts one --data FILE.csv: give one file")
    given = [opt for opt, on in (
        ("--robot", args.robot is not None), ("--lock", bool(args.lock)),
        ("--design-excitation", args.design_excitation),
        ("--mass-band", args.mass_band is not None),
        ("--inertia-band", args.inertia_band is not None),
        ("--keep-inconsistent", args.keep_inconsistent), ("--folds", args.folds is not None),
        ("--method", args.method != "wls"), ("--held-out", args.held_out != 0.2),
        ("--friction/--no-friction", args.friction is not None),
        ("--armature/--no-armature", args.armature is not None),
        ("--covariance", args.covariance is not None)) if on]
    if given:
        raise ValueError(f"--model DIR predicts with DIR's identified arm, fitting nothing: "
                         f"{', '.join(given)} would not act; leave "
                         + ("it" if len(given) == 1 else "them") + " out")
    folder = Path(args.model)
    rec_path = folder / "identification.json"
    try:
        rec = json.loads(rec_path.read_text())
        urdf = (folder / rec["urdf"]).read_text()
    except (OSError, ValueError, KeyError) as exc:
        raise IdentificationError(f"--model {args.model!r}: cannot read its "
                                  f"identification.json and identified URDF: {exc}") from None
    import xml.etree.ElementTree as ET

    moving = {j.get("name") for j in ET.fromstring(urdf).findall("joint")
              if j.get("type") != "fixed"}
    lock = {k: v for k, v in (rec.get("locked") or {}).items() if k in moving}  # older records
    robot = robot_from_xml(urdf, name=f"{rec.get('robot', 'arm')}_identified",
                           gravity=rec["gravity_m_s2"], label=f"--model {args.model}",
                           **({"lock": lock} if lock else {}))
    arm = rec.get("armature") or {}
    if arm:  # a URDF carries no armature: set on the loaded model from the record
        from ..model.identification import with_armature

        with_armature(robot, [max(arm[j]["value_kg_m2"], 0.0) for j in robot.joint_names])
    with as_options():
        data = _read(args.data[0], robot, args.window)
    pred = predict_torques(robot, data, rec.get("friction"))
    half = _half_width(rec, robot, data, args.level)
    from ..model.identification import filter_like, r_squared

    tau = filter_like(data, data.tau)
    e = tau - pred
    rms = np.sqrt(np.mean(e ** 2, axis=0))
    r2 = r_squared(tau, pred)
    out = claim_out(args, "identify")
    csv_path, js = out / "prediction.csv", out / "prediction.json"
    header = "t," + ",".join(f"tau_{j}" for j in robot.joint_names)
    columns = [data.t, pred]
    if half is not None:
        header += "," + ",".join(f"tau_{j}_lo,tau_{j}_hi" for j in robot.joint_names)
        columns += [np.column_stack([x for j in range(robot.nq)
                                     for x in (pred[:, j] - half[:, j], pred[:, j] + half[:, j])])]
    with writing(csv_path):
        np.savetxt(csv_path, np.column_stack(columns), delimiter=",", header=header,
                   comments="", fmt="%.10g")
    summary = {"model": str(folder), "data": data.source, "samples": data.N,
               "derivatives": data.derived or None,
               "torque_filter": "savgol (as q)" if data.derived else None,
               "residual_rms_Nm": dict(zip(robot.joint_names, rms.tolist(), strict=True)),
               "r2": dict(zip(robot.joint_names, r2.tolist(), strict=True)),
               "interval_level": None if half is None else args.level,
               "interval_coverage": None if half is None else dict(zip(
                   robot.joint_names, (np.abs(e) <= half).mean(axis=0).tolist(), strict=True)),
               "interval": None if half is None else (
                   "tau_<joint>_lo/_hi: prediction +- z sqrt(s_j^2 + y C y^T), s_j the "
                   "leave-one-block-out residual level, C the Newey-West covariance "
                   "(identification.json's cov_all / jackknife_c2)")}
    with writing(js):
        js.write_text(json.dumps(summary, indent=1) + "\n")
    print(f"predicted {data.N} samples of {data.source} with {folder}")
    print("residual RMS [N m]: " + ", ".join(f"{k} {v:.4g}" for k, v in
                                             summary["residual_rms_Nm"].items()))
    print("R^2: " + ", ".join(f"{k} {v:.4f}" for k, v in summary["r2"].items()))
    if half is not None:
        print(f"{args.level:.0%} prediction intervals cover: " + ", ".join(
            f"{k} {v:.1%}" for k, v in summary["interval_coverage"].items()))
    print(f"wrote {csv_path} and {js}")
    return 0


def _half_width(rec, robot, data, level):
    """Half-widths [N m] (shape (N, nq)) of the prediction intervals of a calibrated record."""
    import numpy as np

    from ..model.identification import (
        BaseParameters,
        armature_regressor,
        filter_like,
        friction_regressor,
        prediction_interval,
        regressor,
    )

    s = rec.get("prediction_noise_std_Nm")
    if not s or rec.get("cov_all") is None:
        return None  # a record without the calibration (older, or --covariance noise)
    n = robot.nq
    W = BaseParameters.from_dict(rec["base"]).reduce(regressor(robot, data.q, data.qd,
                                                               data.qdd))
    if rec.get("friction"):
        Yf = friction_regressor(data.qd).reshape(data.N, n * 3 * n)
        W = np.hstack([W, filter_like(data, Yf).reshape(-1, 3 * n)])
    kept = rec.get("armature_columns") or []
    if kept:
        W = np.hstack([W, armature_regressor(data.qdd)[:, kept]])
    cov = np.asarray(rec["cov_all"], float) / max(rec.get("jackknife_c2", 1.0), 1.0)
    _, half = prediction_interval(W, np.zeros(W.shape[1]), cov,
                                  np.array([s[j] for j in robot.joint_names]), n, level)
    return half


def _folds(text):
    """``--folds``: None, an integer >= 2, 'period' or 'runs'."""
    if text is None or text in ("period", "runs"):
        return text
    try:
        k = int(text)
    except ValueError:
        k = 0
    if k < 2:
        raise ValueError(f"--folds must be an integer >= 2, 'period' or 'runs', got {text!r}")
    return k


def _read(path, robot, window):
    """Read a run of ``--data``: a CSV, or a folder of per-quantity text files (a split log)."""
    from pathlib import Path

    from ..model.identification import read_measurements, read_split_log

    if Path(path).is_dir():
        return read_split_log(path, robot, window=window)
    return read_measurements(path, robot, window=window)
