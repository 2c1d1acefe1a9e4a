"""The corrected closed form of the paper's eq. (2)-(7) against Pinocchio, and its errata."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin import paper_params
from rrr_pin.cli import main
from rrr_pin.model import closed_form as cf
from rrr_pin.model.dh import ArmParams, DHLink
from rrr_pin.model.dynamics import load_robot
from rrr_pin.model.urdf import write_urdf

N_STATES = 200
QD_MAX = 5.0  # rad/s


def _second_moments(J):
    """Principal second moments (a, b, c) with Jx = b + c, Jy = a + c, Jz = a + b."""
    Jx, Jy, Jz = J
    return np.array([Jy + Jz - Jx, Jx + Jz - Jy, Jx + Jy - Jz]) / 2.0


def _moments(abc):
    a, b, c = abc
    return (b + c, a + c, a + b)


def perturbed_params(seed: int) -> ArmParams:
    """Paper parameters with masses and moments within +-20 %, lengths within +-5 %.

    Moments are perturbed through the principal second moments, which keeps them physically
    valid (non-negative, triangle inequality) by construction. The paper's thin rods have zero
    second moments (e.g. Jx2 = 0), which stay zero.
    """
    p = paper_params()
    rng = np.random.default_rng(seed)
    links = []
    for k, link in enumerate(p.links):
        s = rng.uniform(0.95, 1.05)
        length = link.length * s
        lg = min(link.lg * s * rng.uniform(0.95, 1.05), length)
        geometry = {"d": length} if k == 0 else {"a": length}
        links.append(replace(link, **geometry, lg=lg, mass=link.mass * rng.uniform(0.8, 1.2),
                             J=_moments(_second_moments(link.J) * rng.uniform(0.8, 1.2, 3))))
    return replace(p, links=tuple(links), g=p.g * rng.uniform(0.99, 1.01))


def generic_moments_params(seed: int) -> ArmParams:
    """Perturbed parameters whose links all have three distinct non-zero principal moments.

    Goes beyond +-20 % on purpose: with the paper's Jx2 = Jx3 = 0, the Jx terms of D11, D112,
    D113, D211 and D311 are never exercised.
    """
    p = perturbed_params(seed)
    rng = np.random.default_rng(seed + 1000)
    links = tuple(replace(link, J=_moments(rng.uniform(0.05, 0.6, 3))) for link in p.links)
    return replace(p, links=links)


PARAM_SETS = {
    "paper": paper_params(),
    "perturbed-1": perturbed_params(1),
    "perturbed-2": perturbed_params(2),
    "perturbed-3": perturbed_params(3),
    "generic-moments-4": generic_moments_params(4),
    "generic-moments-5": generic_moments_params(5),
}


def _states(seed: int, n: int = N_STATES):
    rng = np.random.default_rng(seed)
    return rng.uniform(-math.pi, math.pi, (n, 3)), rng.uniform(-QD_MAX, QD_MAX, (n, 3))


@pytest.fixture(scope="module", params=list(PARAM_SETS.values()), ids=list(PARAM_SETS))
def arm(request):
    params = request.param
    return params, load_robot(params, gravity=params.g)


def test_perturbed_sets_are_perturbed_and_valid():
    nominal = paper_params()
    for name, params in PARAM_SETS.items():
        if name.startswith("perturbed"):
            assert_allclose(params.m, nominal.m, rtol=0.2)
            assert_allclose(params.l, nominal.l, rtol=0.05)
            assert_allclose(params.J, nominal.J, rtol=0.2)
            assert not np.allclose(params.m, nominal.m)
        # DHLink validates the moments (triangle inequality) and lg in [0, l] on construction.
        assert all(isinstance(link, DHLink) for link in params.links)


def test_M_V_G_match_pinocchio(arm):
    params, robot = arm
    qs, qds = _states(11)
    closed = {"M": [], "V": [], "G": []}
    pinocchio = {"M": [], "V": [], "G": []}
    for q, qd in zip(qs, qds, strict=True):
        closed["M"].append(cf.M(params, q))
        closed["V"].append(cf.V(params, q, qd))
        closed["G"].append(cf.G(params, q))
        pinocchio["M"].append(robot.M(q))
        pinocchio["V"].append(robot.V(q, qd))
        pinocchio["G"].append(robot.G(q))
    for key in closed:
        ref = np.array(pinocchio[key])
        # Entries that vanish exactly (M12, M13, G1) come out of Pinocchio as round-off of the
        # size eps * (largest entry) ~ 1e-14 for entries up to ~500 (N m or kg m^2); an atol of
        # 1e-12 times the largest entry covers that 100-fold and is 1000x tighter than
        # rtol * (largest entry).
        atol = 1e-12 * np.abs(ref).max()
        assert_allclose(np.array(closed[key]), ref, rtol=1e-9, atol=atol, err_msg=key)


def test_each_coefficient_matches_pinocchio(arm):
    """Coefficient by coefficient: D_ijk from Pinocchio's V by polarization."""
    params, robot = arm
    qs, _ = _states(12, 50)
    for q in qs:
        closed, ref = cf.coefficients(params, q), cf.robot_coefficients(robot, q)
        assert set(closed) == set(cf.COEFFICIENT_NAMES) == set(ref)
        for name in cf.COEFFICIENT_NAMES:
            # Round-off of polarization: three V evaluations of size up to ~30 N m at unit
            # speeds, eps * 30 ~ 1e-14; 1e-11 leaves a 1000x margin.
            assert_allclose(closed[name], ref[name], rtol=1e-9, atol=1e-11, err_msg=name)


def test_christoffel_identity_of_closed_form():
    """D_ijk = 1/2 (dD_ij/dq_k + dD_ik/dq_j - dD_jk/dq_i), with dM/dq by central differences.

    Checks the printed-and-corrected V coefficients against the M coefficients of the same
    closed form, independently of Pinocchio.
    """
    params = PARAM_SETS["generic-moments-4"]
    h = 1e-6  # rad
    for q in _states(13, 30)[0]:
        dM = [(cf.M(params, q + h * e) - cf.M(params, q - h * e)) / (2.0 * h) for e in np.eye(3)]
        D = cf.coefficients(params, q)
        for i in range(3):
            for j in range(3):
                for k in range(j, 3):
                    c = 0.5 * (dM[k][i, j] + dM[j][i, k] - dM[i][j, k])
                    # Central differences, h = 1e-6: truncation h^2/6 |M'''| ~ 1e-11, round-off
                    # eps |M| / h ~ 2e-16 * 30 / 1e-6 ~ 6e-9; atol 1e-7 covers both.
                    assert_allclose(D[f"D{i + 1}{j + 1}{k + 1}"], c, atol=1e-7)


# Errata of eq. (7), as recorded in docs/errata.md.
ERRATA = ("D2", "D3", "D11", "D112", "D211", "D223")


@pytest.mark.parametrize("params", [PARAM_SETS["paper"], PARAM_SETS["generic-moments-4"]],
                         ids=["paper", "generic-moments-4"])
def test_printed_eq7_errata_are_real_and_complete(params):
    """The printed coefficients listed in ERRATA disagree with Pinocchio; all others agree."""
    robot = load_robot(params, gravity=params.g)
    worst = dict.fromkeys(cf.COEFFICIENT_NAMES, 0.0)
    for q in _states(14, 100)[0]:
        printed, ref = cf.printed_coefficients(params, q), cf.robot_coefficients(robot, q)
        for name in worst:
            worst[name] = max(worst[name], abs(printed[name] - ref[name]))
    wrong = {name for name, diff in worst.items() if diff > 1e-9}
    assert wrong == set(ERRATA)
    # Each erratum is far from round-off: at least 0.1 (kg m^2 or N m) on 100 random states
    # (the smallest, D11's cos^2(q2 + q2), is ~0.4 for the paper's Jy3 = 0.4167).
    assert min(worst[name] for name in ERRATA) > 0.1


@pytest.mark.parametrize(
    ("index", "field", "value", "match"),
    [
        (0, "alpha", 0.0, r"links\[0\]\.alpha must be"),
        (0, "a", 0.1, r"links\[0\]\.a must be 0"),
        (1, "d", 0.2, r"links\[1\]\.d must be 0"),
        (2, "alpha", math.pi / 2, r"links\[2\]\.alpha must be 0"),
        (1, "theta_offset", 0.3, r"links\[1\]\.theta_offset must be 0"),
        (0, "d", -1.0, r"links\[0\]\.d = l1 > 0"),
        (2, "a", -1.0, r"links\[2\]\.a = l3 > 0"),
    ],
    ids=["alpha1", "a1", "d2", "alpha3", "offset2", "negative-d1", "negative-a3"],
)
def test_structure_mismatch_raises(index, field, value, match):
    p = paper_params()
    links = list(p.links)
    links[index] = replace(links[index], **{field: value})
    params = p.with_links(links)
    with pytest.raises(ValueError, match=match):
        cf.coefficients(params, np.zeros(3))


def test_wrong_number_of_links_and_bad_state_raise():
    p = paper_params()
    with pytest.raises(ValueError, match="3-link RRR arm, got 2 links"):
        cf.M(p.with_links(p.links[:2]), np.zeros(3))
    with pytest.raises(ValueError, match=r"Expected q of shape \(3,\), got \(2,\)"):
        cf.G(p, np.zeros(2))
    with pytest.raises(ValueError, match=r"Expected qd of shape \(3,\), got \(4,\)"):
        cf.V(p, np.zeros(3), np.zeros(4))
    with pytest.raises(ValueError, match="q must be finite"):
        cf.M(p, [0.0, np.nan, 0.0])


def test_compare_with_pinocchio(ur5):
    params = PARAM_SETS["perturbed-1"]
    same = cf.compare_with_pinocchio(load_robot(params, gravity=params.g), params, 50, seed=3)
    other = cf.compare_with_pinocchio(load_robot(paper_params()), params, 50, seed=3)
    for key in ("M", "V", "G"):
        assert same[key]["rel"] < 1e-13  # measured ~4e-16: round-off only
        assert other[key]["rel"] > 1e-3  # masses differ by up to 20 %
        assert same[key]["scale"] > 1.0
    with pytest.raises(ValueError, match="3 joints"):
        cf.compare_with_pinocchio(ur5, params)
    robot = load_robot(params)
    with pytest.raises(ValueError, match="samples must be an integer in \\[1, 1000000\\], got 0"):
        cf.compare_with_pinocchio(robot, params, samples=0)
    with pytest.raises(ValueError, match="samples must be an integer in \\[1, 1000000\\], got 2.5"):
        cf.compare_with_pinocchio(robot, params, samples=2.5)
    with pytest.raises(ValueError, match="seed must be an integer >= 0, got -1"):
        cf.compare_with_pinocchio(robot, params, seed=-1)
    with pytest.raises(ValueError, match=r"qd_max must be a finite number >= 0 \[rad/s\], got nan"):
        cf.compare_with_pinocchio(robot, params, qd_max=float("nan"))


# --- CLI: rrr-pin check-dynamics ---------------------------------------------------------------

def test_cli_check_dynamics_paper(capsys):
    assert main(["check-dynamics", "--samples", "30", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    assert "30 random states, seed 1" in out
    for key in ("M", "V", "G"):
        assert any(line.startswith(key) and line.endswith("ok") for line in out.splitlines())
    assert "OK: all relative differences <= rtol = 1e-09" in out


def test_cli_check_dynamics_params_file_and_matching_urdf(tmp_path, capsys):
    params = PARAM_SETS["generic-moments-5"]
    params.save(tmp_path / "arm.json")
    write_urdf(tmp_path / "arm.urdf", params)
    for extra in ([], ["--urdf", str(tmp_path / "arm.urdf")]):
        argv = ["check-dynamics", "--params", str(tmp_path / "arm.json"), "--samples", "20"]
        assert main(argv + extra) == 0
        assert "OK" in capsys.readouterr().out


def test_cli_check_dynamics_urdf_disagrees(tmp_path, capsys):
    write_urdf(tmp_path / "other.urdf", PARAM_SETS["perturbed-2"])
    assert main(["check-dynamics", "--urdf", str(tmp_path / "other.urdf"),
                 "--samples", "20"]) == 1
    out = capsys.readouterr().out
    assert "FAIL: M, V, G differ by more than rtol = 1e-09" in out


def test_cli_check_dynamics_tolerance_option(tmp_path, capsys):
    # perturbed-2 differs from the paper by < 20 % in every parameter, so relative differences
    # stay well below 1: a loose --rtol accepts the mismatching URDF.
    write_urdf(tmp_path / "other.urdf", PARAM_SETS["perturbed-2"])
    assert main(["check-dynamics", "--urdf", str(tmp_path / "other.urdf"), "--samples", "20",
                 "--rtol", "0.9"]) == 0
    assert "OK: all relative differences <= rtol = 0.9" in capsys.readouterr().out


def test_cli_check_dynamics_missing_file(tmp_path, capsys):
    assert main(["check-dynamics", "--params", str(tmp_path / "none.json")]) == 2
    assert "parameter file not found" in capsys.readouterr().err
