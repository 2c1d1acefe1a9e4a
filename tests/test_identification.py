"""Identification: regressor, base parameters, estimation, consistency, excitation, refusals.

References are independent of the estimator: Pinocchio's RNEA for the regressor, an SVD rank
for the base count, the truth's standard parameters mapped by ``K`` for the estimates, the
parallel-axis theorem for the parameter order, the identified URDF's own M, V, G for the
predictions, closed-form derivatives of a sine for the Savitzky-Golay filter.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose
from scipy.stats import binom

from rrr_pin.cli import main
from rrr_pin.control.references import SplineReference
from rrr_pin.model import identification as idn
from rrr_pin.model.dh import paper_params
from rrr_pin.model.dynamics import load_robot, robot_from_xml
from rrr_pin.model.excitation import FourierTrajectory, design_excitation
from rrr_pin.model.uncertainty import sample_plant, sample_plants


def _truth(robot, radius=0.05, seed=7):
    """A hidden 'true' arm: the nominal's kinematics and changed bodies.

    Each body is first given links of ``radius`` [m] (the RRR's thin rods lie on the
    consistency boundary, real links do not: ``m radius^2 / 2`` more inertia on every axis
    about the centre of mass), then its mass distribution is deformed by a random affine map
    ``x -> A x + b`` (``A`` within 20 % of the identity, ``|b|`` ~ 2 cm) and its mass scaled
    by a factor in [0.8, 1.2]: ``J' = f T J T^T`` with ``T = [[A, b], [0, 1]]``, positive
    semi-definite as ``J`` is, so the truth is physical by construction.
    """
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
    return robot_from_xml(idn.urdf_with_parameters(robot.urdf, idn.body_links(robot), phi))


def _trajectory(n, seed=0, periods=2):
    rng = np.random.default_rng(seed)
    return FourierTrajectory(0.2, 0.4 * rng.standard_normal((n, 5)),
                             0.4 * rng.standard_normal((n, 5)), np.zeros(n), periods)


def _data(robot, truth, rate=200.0, noise=0.0, seed=0, traj=None):
    traj = traj or _trajectory(robot.nq)
    t = np.arange(0.0, traj.duration, 1.0 / rate)
    q, qd, qdd = traj.sample(t)
    tau = np.array([truth.inverse_dynamics(q[k], qd[k], qdd[k]) for k in range(len(t))])
    tau = tau + noise * np.random.default_rng(seed).standard_normal(tau.shape)
    return idn.Measurements(t, q, qd, qdd, tau, tuple(robot.joint_names))


def _write_csv(path, robot, data, columns=None):
    cols = {"t": data.t}
    for kind in ("q", "tau"):
        for j, name in enumerate(robot.joint_names):
            cols[f"{kind}_{name}"] = getattr(data, kind)[:, j]
    cols = columns(cols) if columns else cols
    rows = [",".join(cols)] + [",".join(repr(float(v)) for v in row)
                               for row in np.column_stack(list(cols.values()))]
    path.write_text("\n".join(rows) + "\n")
    return path


# --- regressor and base parameters ------------------------------------------------------------

def test_standard_parameter_order_is_pinocchios():
    """toDynamicParameters = [m, m c, I_O (xx, xy, yy, xz, yz, zz)], I_O by parallel axes."""
    I = pin.Inertia.Random()
    m, c, Ic = I.mass, I.lever, I.inertia
    IO = Ic + m * (c @ c * np.eye(3) - np.outer(c, c))
    expected = [m, *(m * c), IO[0, 0], IO[0, 1], IO[1, 1], IO[0, 2], IO[1, 2], IO[2, 2]]
    assert_allclose(I.toDynamicParameters(), expected, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("name", ["rrr", "ur5"])
def test_regressor_times_parameters_is_rnea(name, request):
    robot = request.getfixturevalue(name)
    q, qd, qdd = idn.random_states(robot, 4, 3)
    Y = idn.regressor(robot, q, qd, qdd)
    tau = np.concatenate([pin.rnea(robot.model, robot.data, *x) for x in zip(q, qd, qdd,
                                                                            strict=True)])
    # Two algorithms on the same model: agreement to round-off of ~100 N m torques.
    assert_allclose(Y @ idn.standard_parameters(robot), tau, rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize(("name", "count"), [("rrr", 15), ("ur5", 36)], ids=["rrr", "ur5"])
def test_base_count_against_svd_rank(name, count, request):
    """The QR count equals an SVD rank on other random states; the mapping is exact."""
    robot = request.getfixturevalue(name)
    base = idn.base_parameters(robot)
    assert base.p == count == idn.regressor_rank(robot, samples=40, seed=11)
    W = idn.regressor(robot, *idn.random_states(robot, 20, 5))
    phi = np.random.default_rng(2).standard_normal(W.shape[1])
    # W phi = W_b (K phi) for any phi: round-off only.
    assert_allclose(base.reduce(W) @ base(phi), W @ phi, rtol=1e-9,
                    atol=1e-9 * np.abs(W @ phi).max())
    assert len(set(base.names)) == base.p
    for name_, expr in zip(base.names, base.expressions, strict=True):
        assert expr.startswith(f"{name_} = ")


def test_rrr_base_parameter_names_say_what_combines(rrr):
    expressions = idn.base_parameters(rrr).expressions
    # Khalil's regrouping for the paper's 1 m links: m3 joins the first moment of link 2.
    assert "mx_R[link2] = mx[link2] + 1 m[link3]" in expressions


# --- estimation -------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["rrr", "ur5"])
def test_noise_free_data_recover_base_parameters(name, request):
    robot = request.getfixturevalue(name)
    truth = _truth(robot)
    base = idn.base_parameters(robot)
    data = _data(robot, truth, rate=50.0)
    W = base.reduce(idn.regressor(robot, data.q, data.qd, data.qdd))
    theta = idn.least_squares(base, W, data.tau.reshape(-1), robot.nq, "ols")[0]
    expected = base(idn.standard_parameters(truth))  # from the truth's standard parameters
    assert_allclose(theta, expected, rtol=1e-8, atol=1e-8 * np.abs(expected).max())


def _coverage(robot, seeds, samples_per_seed=300):
    truth, base = _truth(robot), idn.base_parameters(robot)
    expected = base(idn.standard_parameters(truth))
    traj = _trajectory(robot.nq)
    clean = _data(robot, truth, rate=samples_per_seed / traj.duration, traj=traj)
    W = base.reduce(idn.regressor(robot, clean.q, clean.qd, clean.qdd))
    noise = np.array([0.2, 0.5, 0.1])  # different per joint: WLS must weight them
    inside = []
    for seed in range(seeds):
        y = (clean.tau + noise * np.random.default_rng(seed).standard_normal(
            clean.tau.shape)).reshape(-1)
        theta, cov, *_ = idn.least_squares(base, W, y, robot.nq, "wls")
        inside.append(np.abs(theta - expected) <= 1.959964 * np.sqrt(np.diag(cov)))
    return np.array(inside)


def _band(trials, p=0.95, level=0.999):
    """Two-sided ``level`` acceptance band of a Binomial(trials, p) count."""
    return binom.ppf((1 - level) / 2, trials, p), binom.ppf(1 - (1 - level) / 2, trials, p)


def test_confidence_intervals_cover_the_truth_fast(rrr):
    """8 seeds x 15 parameters: the count inside the 95 % intervals in the 99.9 % band of
    Binomial(120, 0.95), [105, 120] (the 15 of one seed are correlated, so the band is
    optimistic in width; 99.9 % keeps the false alarm rare)."""
    inside = _coverage(rrr, 8)
    lo, hi = _band(inside.size)
    assert lo <= inside.sum() <= hi


@pytest.mark.slow
def test_confidence_intervals_cover_the_truth_50_seeds(rrr):
    """50 seeds: per parameter, the count in the 99.9 % band of Binomial(50, 0.95), [41, 50];
    pooled (750) in that of Binomial(750, 0.95), [691, 731] (measured: 716, per parameter
    46 to 50)."""
    inside = _coverage(rrr, 50)
    lo, hi = _band(50)
    assert np.all((inside.sum(axis=0) >= lo) & (inside.sum(axis=0) <= hi))
    lo, hi = _band(inside.size)
    assert lo <= inside.sum() <= hi


@pytest.fixture(scope="module")
def identified(rrr, tmp_path_factory):
    """A noisy RRR identification from a CSV (derivatives estimated), through the CLI."""
    folder = tmp_path_factory.mktemp("ident")
    truth = _truth(rrr)
    data = _data(rrr, truth, rate=500.0, noise=0.05, seed=3)
    csv = _write_csv(folder / "log.csv", rrr, data)
    # The truth has no friction and no armature: identified without them (issue 46 made
    # both the default).
    assert main(["identify", "--robot", "rrr", "--data", str(csv), "--no-friction",
                 "--no-armature", "--out", str(folder / "out")]) == 0
    return folder / "out", truth, data


def test_identified_urdf_is_consistent_and_predicts_to_the_noise_level(identified, rrr):
    out, truth, data = identified
    record = json.loads((out / "identification.json").read_text())
    robot = load_robot(str(out / "identified.urdf"))  # the project's URDF checks
    for inertia in list(robot.model.inertias)[1:]:  # every body: pseudo-inertia PSD
        J = idn.pseudo_inertia(inertia.toDynamicParameters())
        assert np.linalg.eigvalsh(J).min() > 0.0
    n_fit = record["held_out"]["first_sample"]
    q, qd, qdd = data.q[n_fit:], data.qd[n_fit:], data.qdd[n_fit:]
    pred = np.array([robot.M(a) @ c + robot.V(a, b) + robot.G(a)
                     for a, b, c in zip(q, qd, qdd, strict=True)])
    rms = np.sqrt(np.mean((data.tau[n_fit:] - pred) ** 2, axis=0))
    # ~950 held-out samples: the RMS of N(0, 0.05) noise is within 10 % of 0.05 (sd ~3 %);
    # the derivative filter and the fit add well under that.
    assert_allclose(rms, 0.05, rtol=0.1)
    for key in ("estimate", "std", "names", "condition_number", "residual_rms_Nm",
                "held_out"):
        assert key in record or key in record["base"]
    assert record["derivatives"]["filter"] == "savgol"


def test_savgol_derivatives_of_a_sine():
    t = np.arange(0.0, 2.0, 1e-3)
    q = np.sin(2 * np.pi * t)[:, None]
    qd, qdd, info = idn.estimate_derivatives(t, q, window=0.05)
    w = 2 * np.pi
    inner = slice(100, -100)  # away from the ends, where one polynomial serves the window
    # Degree-4 fit over 51 samples of a 1 Hz sine: truncation error ~ (w h)^4 / 5! ~ 1e-4.
    assert_allclose(qd[inner, 0], w * np.cos(w * t[inner]), atol=1e-3 * w)
    assert_allclose(qdd[inner, 0], -w * w * np.sin(w * t[inner]), atol=1e-2 * w * w)
    assert info["window_samples"] == 51


# --- excitation -------------------------------------------------------------------------------

def test_excitation_beats_random_and_stays_inside_limits(rrr):
    traj, info = design_excitation(rrr, points=25, maxiter=8)
    base = idn.base_parameters(rrr)
    t_grid = np.linspace(0.0, 1.0 / traj.frequency, 25, endpoint=False)
    W = base.reduce(idn.regressor(rrr, *traj.sample(t_grid)))
    assert_allclose(np.linalg.cond(W), info["cond"], rtol=1e-9)  # recomputed independently
    assert info["cond"] < info["cond_random"]
    t = np.linspace(0.0, traj.duration, 20001)
    q, qd, qdd = traj.sample(t)
    assert np.all((q >= rrr.lower) & (q <= rrr.upper))
    assert np.all(np.abs(qd) <= rrr.model.velocityLimit)
    assert np.all(np.abs(qdd) <= 10.0)
    for k in (0, -1):  # at rest at both ends
        assert_allclose(qd[k], 0.0, atol=1e-9)
        assert_allclose(qdd[k], 0.0, atol=1e-9)


def test_design_excitation_cli_writes_a_spline_reference(tmp_path, rrr):
    assert main(["identify", "--design-excitation", "--maxiter", "3", "--out",
                 str(tmp_path)]) == 0
    ref = SplineReference.from_csv(tmp_path / "excitation.csv", rrr)
    record = json.loads((tmp_path / "excitation.json").read_text())
    assert ref.duration == pytest.approx(record["trajectory"]["duration_s"])
    traj = record["trajectory"]
    fourier = FourierTrajectory(traj["frequency_hz"], np.array(traj["a_rad_s"]),
                                np.array(traj["b_rad_s"]), np.array(traj["q0_rad"]),
                                traj["periods"])
    t = np.linspace(0.0, ref.duration, 777)
    # A cubic spline through 100 Hz waypoints of a <= 1 Hz series: close to it.
    assert_allclose(ref.sample(t)[0], fourier.sample(t)[0], atol=1e-4)


# --- the identified uncertainty ---------------------------------------------------------------

def test_plants_from_the_identified_distribution(identified, rrr):
    out, _, _ = identified
    tol = idn.IdentifiedUncertainty(str(out / "identification.json"), confidence=0.95)
    nominal = load_robot(str(out / "identified.urdf"))
    tol.check_robot(nominal)
    plants = sample_plants(nominal.urdf, 2, 4, tol)
    record = tol.record
    mean, cov = np.array(record["base_consistent"]), np.array(record["cov"])
    base = tol.base
    limit = math.sqrt(__import__("scipy.stats").stats.chi2.ppf(0.95, base.p))
    for plant in plants:
        robot = robot_from_xml(plant.urdf)  # physically consistent: passes the checks
        theta = base(idn.standard_parameters(robot))  # read back from the plant's model
        d = theta - mean
        assert math.sqrt(d @ np.linalg.solve(cov, d)) <= limit * (1 + 1e-6)
        assert set(plant.parameters["identified"]["rejected"]) == {"outside_confidence",
                                                                   "inconsistent"}
    assert sample_plant(nominal.urdf, 4, 1, tol).urdf == plants[1].urdf


def test_identified_uncertainty_refuses_other_kinematics(identified, ur5):
    out, _, _ = identified
    tol = idn.IdentifiedUncertainty(str(out / "identification.json"))
    params = paper_params()
    longer = params.with_links([replace(params.links[0], d=1.05 * params.links[0].d),
                                *params.links[1:]])
    with pytest.raises(idn.IdentificationError, match="'joint2' of 'rrr' is not placed as in"):
        tol.check_robot(load_robot(longer))
    with pytest.raises(idn.IdentificationError, match="identified joints"):
        tol.check_robot(ur5)


# --- refusals ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def clean(rrr):
    return _data(rrr, _truth(rrr), rate=50.0)


@pytest.mark.parametrize(("edit", "match"), [
    (lambda c: {k: v for k, v in c.items() if not k.endswith("joint3")},
     r"missing columns \['q_joint3', 'tau_joint3'\].*has joints \['joint1', 'joint2', "
     r"'joint3'\]"),
    (lambda c: {**c, "q_joint4": c["q_joint1"], "tau_joint4": c["q_joint1"]},
     r"unexpected columns \['q_joint4', 'tau_joint4'\]"),
    (lambda c: {**c, "tau_joint2": np.where(np.arange(len(c["t"])) == 4, np.nan,
                                            c["tau_joint2"])},
     r"row 6, column 'tau_joint2': 'nan' is not finite"),
    (lambda c: {**c, "t": np.where(np.arange(len(c["t"])) == 9, 0.0, c["t"])},
     r"time must be strictly increasing; row 11 has t = 0.0 s"),
], ids=["missing-joint", "extra-joint", "nan", "time"])
def test_bad_csv_is_refused_by_name(edit, match, rrr, clean, tmp_path):
    path = _write_csv(tmp_path / "bad.csv", rrr, clean, edit)
    with pytest.raises(idn.IdentificationError, match=match):
        idn.read_measurements(path, rrr)


def test_urdf_not_matching_the_data_is_refused(rrr, ur5, clean, tmp_path):
    path = _write_csv(tmp_path / "rrr.csv", rrr, clean)
    with pytest.raises(idn.IdentificationError, match=r"missing columns \['q_shoulder_pan_joint"):
        idn.read_measurements(path, ur5)
    with pytest.raises(idn.IdentificationError, match="do not match the URDF 'ur5'"):
        idn.identify(ur5, clean)


def test_too_few_samples_is_refused(rrr, clean):
    few = idn.Measurements(*(x[:8] for x in (clean.t, clean.q, clean.qd, clean.qdd,
                                             clean.tau)), clean.joint_names)
    with pytest.raises(idn.IdentificationError, match="too few samples: 6 samples .* 18 "
                                                      "equations for 15 base parameters"):
        idn.identify(rrr, few)


def test_unexciting_trajectory_names_the_unidentifiable_parameters(rrr, clean):
    q = clean.q.copy()
    q[:, 1:] = 0.3  # joints 2 and 3 locked: their inertias never move
    qd, qdd = clean.qd.copy(), clean.qdd.copy()
    qd[:, 1:] = qdd[:, 1:] = 0.0
    tau = np.array([rrr.inverse_dynamics(*x) for x in zip(q, qd, qdd, strict=True)])
    data = idn.Measurements(clean.t, q, qd, qdd, tau, clean.joint_names)
    with pytest.raises(idn.IdentificationError,
                       match=r"not identifiable: .*Ixx_R\[link2\].*Izz\[link3\]"):
        idn.identify(rrr, data)


def test_infeasible_consistency_is_refused(rrr, clean):
    """Torques of the wrong sign: no arm with positive masses fits them."""
    noisy = clean.tau + 0.01 * np.random.default_rng(0).standard_normal(clean.tau.shape)
    data = idn.Measurements(clean.t, clean.q, clean.qd, clean.qdd, -noisy, clean.joint_names)
    with pytest.raises(idn.IdentificationError, match="infeasible consistency problem"):
        idn.identify(rrr, data)


def test_cli_identify_without_data_is_refused(capsys, tmp_path):
    assert main(["identify", "--out", str(tmp_path)]) == 2
    assert "--data FILE.csv is required" in capsys.readouterr().err


def test_cli_identify_refuses_a_log_of_another_arm(rrr, clean, tmp_path, capsys):
    path = _write_csv(tmp_path / "rrr.csv", rrr, clean)
    assert main(["identify", "--robot", "ur5", "--data", str(path), "--out",
                 str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "rrr-pin identify: error:" in err and "missing columns" in err
    assert "Traceback" not in err
    assert not (tmp_path / "out").exists()  # refused before the folder is claimed


def test_settings_record_the_identification(identified):
    from rrr_pin.campaign.montecarlo import CampaignSettings

    out, _, _ = identified
    tol = idn.IdentifiedUncertainty(str(out / "identification.json"), confidence=0.9)
    record = CampaignSettings(samples=1, tolerances=tol).to_dict()
    assert record["uncertainty"] == "identified" and record["confidence"] == 0.9
    assert record["identification_sha256"] == tol.sha256 and "tolerance_inertia" not in record


@pytest.mark.slow
def test_montecarlo_on_the_identified_set(identified, tmp_path, capsys):
    out, _, _ = identified
    assert main(["montecarlo", "--robot", str(out / "identified.urdf"), "--uncertainty",
                 str(out / "identification.json"), "--samples", "2", "--duration", "0.2",
                 "--jobs", "1", "--certify", "--no-progress", "--out", str(tmp_path)]) == 0
    assert "identified uncertainty: 2 plants drawn" in capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["settings"]["uncertainty"] == "identified"


@pytest.mark.parametrize("kinds", [("qd", "qdd"), ("qd",), ("qdd",)], ids=str)
def test_given_derivatives_are_kept(kinds, rrr, clean, tmp_path):
    def add(c):
        for kind in kinds:
            for j, name in enumerate(rrr.joint_names):
                c[f"{kind}_{name}"] = getattr(clean, kind)[:, j]
        return c

    data = idn.read_measurements(_write_csv(tmp_path / "d.csv", rrr, clean, add), rrr)
    for kind in kinds:  # read back as written (repr round-trips floats)
        assert_allclose(getattr(data, kind), getattr(clean, kind), rtol=0, atol=0)
    assert data.derived.get("estimated", []) == [k for k in ("qd", "qdd") if k not in kinds]


@pytest.mark.slow
def test_ur5_excitation_beats_random_and_stays_inside_limits(ur5):
    traj, info = design_excitation(ur5, points=30, maxiter=5)
    assert info["cond"] < info["cond_random"]
    q, qd, qdd = traj.sample(np.linspace(0.0, traj.duration, 20001))
    assert np.all((q >= ur5.lower) & (q <= ur5.upper))
    assert np.all(np.abs(qd) <= ur5.model.velocityLimit) and np.all(np.abs(qdd) <= 10.0)
