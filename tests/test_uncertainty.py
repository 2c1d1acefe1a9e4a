"""Uncertain plants (rrr_pin.model.uncertainty): seeded draws of arms and of mechanisms."""

from dataclasses import asdict, dataclass, replace

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin.campaign.montecarlo import CampaignSettings
from rrr_pin.model.dh import ArmParams, forward_kinematics, paper_params
from rrr_pin.model.dynamics import load_robot, robot_from_xml
from rrr_pin.model.mechanisms import FiveBarParams
from rrr_pin.model.uncertainty import (
    MechanismUncertainty,
    Tolerances,
    perturb_inertia,
    perturb_link,
    perturb_links,
    perturb_urdf,
    sample_mechanism,
    sample_plants,
)


def test_same_seed_same_plants():
    a = sample_plants(paper_params(), 3, seed=7)
    b = sample_plants(paper_params(), 3, seed=7)
    c = sample_plants(paper_params(), 3, seed=8)
    assert [s.urdf for s in a] == [s.urdf for s in b]
    assert all(x.urdf != y.urdf for x, y in zip(a, c, strict=True))
    assert [s.seed for s in a] == [[7, 0], [7, 1], [7, 2]]
    # A single plant regenerates alone from its seed.
    rng = np.random.default_rng([7, 2])
    assert rng.uniform() == np.random.default_rng(a[2].seed).uniform()


def test_first_draws_are_platform_independent():
    # PCG64 with a fixed seed is specified bit for bit; this pins the sampling scheme:
    # a change to the order of draws in perturb_params shows up here.
    p = ArmParams.from_dict(sample_plants(paper_params(), 1, seed=0)[0].parameters["params"])
    f_m = np.random.default_rng([0, 0]).uniform(0.8, 1.2)
    assert_allclose(p.links[0].mass, 20.0 * f_m, rtol=1e-15)


def test_factors_within_tolerances_and_physical():
    nominal = paper_params()
    for s in sample_plants(nominal, 50, seed=1):
        p = ArmParams.from_dict(s.parameters["params"])  # validates every link
        assert np.all(np.abs(p.m / nominal.m - 1) <= 0.2)
        assert np.all(np.abs(p.l / nominal.l - 1) <= 0.05)
        assert_allclose(p.lg / p.l, nominal.lg / nominal.l, rtol=1e-12)  # lg scales with l
        nz = nominal.J > 0
        assert np.all(np.abs(p.J[nz] / nominal.J[nz] - 1) <= 0.2 + 1e-12)
        assert np.all(p.J[~nz] == 0)  # a thin rod stays a thin rod


def test_perturb_inertia_property():
    rng = np.random.default_rng(3)
    for _ in range(200):
        R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        s = rng.uniform(0, 1, 3)  # second moments of a random body
        I = np.trace(np.diag(s)) * np.eye(3) - R @ np.diag(s) @ R.T
        f = rng.uniform(0.8, 1.2, 3)
        J = np.linalg.eigvalsh(perturb_inertia(I, f))
        J0 = np.linalg.eigvalsh(I)
        assert J.min() >= -1e-12
        assert J.max() <= J.sum() - J.max() + 1e-12  # triangle inequality
        assert np.all(np.abs(J / J0 - 1) <= 0.2 + 1e-9)


def test_links_drawn_together_are_the_links_drawn_one_by_one():
    # perturb_links (the drawn arms' route) scales the inertias as one stack; it must give the
    # numbers of perturb_link (the URDF text route) bit for bit, draws and all.
    rng = np.random.default_rng(5)
    nominals = []
    for _ in range(9):
        R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        s = rng.uniform(0, 1, 3)
        nominals.append((rng.uniform(0.1, 10.0), np.trace(np.diag(s)) * np.eye(3)
                         - R @ np.diag(s) @ R.T, rng.normal(size=3)))
    tol = Tolerances(inertia=0.3, length=0.1)
    together = perturb_links(nominals, np.random.default_rng(11), tol)
    one = np.random.default_rng(11)
    for (mass, I, com), got in zip(nominals, together, strict=True):
        want = perturb_link(mass, I, com, one, tol)
        assert got[0] == want[0] and got[3] == want[3]
        assert got[1].tobytes() == want[1].tobytes() and got[2].tobytes() == want[2].tobytes()


def test_written_urdf_loads_back_as_the_sampled_plant(tmp_path):
    s = sample_plants(paper_params(), 1, seed=4)[0]
    params = ArmParams.from_dict(s.parameters["params"])
    robot = load_robot(s.write(tmp_path))
    assert robot.name == "plant_000"
    assert_allclose([robot.model.inertias[i].mass for i in (1, 2, 3)], params.m, rtol=1e-15)
    q = np.array([0.2, -0.4, 0.9])
    # Lengths: Pinocchio's tip placement of the loaded file equals DH FK of the sampled params.
    assert_allclose(robot.frame_placement(q, "ee"), forward_kinematics(params, q)[-1],
                    atol=1e-12)


def test_perturb_urdf_ur5(tmp_path, ur5):
    nominal = ur5
    text, factors = perturb_urdf(nominal.urdf, np.random.default_rng(0), Tolerances())
    path = tmp_path / "ur5_pert.urdf"
    path.write_text(text)
    plant = load_robot(path)
    for i in range(1, nominal.model.njoints):
        ratio = plant.model.inertias[i].mass / nominal.model.inertias[i].mass
        assert 0.8 <= ratio <= 1.2
        I = plant.model.inertias[i].inertia
        assert np.linalg.eigvalsh(I).min() >= -1e-12
    # Geometry moved by at most 5 % per joint origin, so the tip moves but stays close.
    q = np.zeros(6)
    pin.framesForwardKinematics(nominal.model, nominal.data, q)
    assert all(0.95 <= f <= 1.05 for f in factors["joints"].values())


@pytest.mark.parametrize("source", ["rrr", "ur5"], ids=["dh-plant", "urdf-plant"])
def test_a_plant_checked_where_made_loads_trusted_as_checked(source):
    # robot_from_xml(check=False) skips only the URDF validator: the model is the same, bit
    # for bit, as the checked load (and as what the study would simulate).
    nominal = load_robot(source)
    plant = sample_plants(paper_params() if source == "rrr" else nominal.urdf, 1, seed=3)[0]
    checked = robot_from_xml(plant.urdf, gravity=nominal.gravity)
    trusted = robot_from_xml(plant.urdf, gravity=nominal.gravity, check=False)
    q = np.linspace(-0.5, 0.7, nominal.nq)
    qd = np.linspace(0.3, -0.2, nominal.nq)
    assert np.array_equal(trusted.M(q), checked.M(q))
    assert np.array_equal(trusted.V(q, qd), checked.V(q, qd))
    assert np.array_equal(trusted.G(q), checked.G(q))
    assert np.array_equal(trusted.lower, checked.lower)
    assert np.array_equal(trusted.upper, checked.upper)
    assert trusted.joint_names == checked.joint_names


@pytest.mark.parametrize("kwargs,message", [
    ({"count": -1}, "count must be an integer >= 0, got -1"),
    ({"count": 1, "seed": -2}, "seed must be an integer >= 0, got -2"),
    ({"count": True}, "count must be an integer >= 0, got True"),
    ({"count": 1.5}, r"count must be an integer >= 0, got 1\.5"),
], ids=["count", "seed", "count-bool", "count-fraction"])
def test_bad_sampling_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        sample_plants(paper_params(), **kwargs)


@pytest.mark.parametrize("kwargs,message", [
    ({"inertia": 1.5}, r"inertia tolerance must be in \[0, 1\), got 1\.5"),
    ({"length": -0.1}, r"length tolerance must be in \[0, 1\), got -0\.1"),
    ({"inertia": "0.1"}, r"inertia tolerance must be a number, got '0\.1' \(str\)"),
    ({"length": float("nan")}, "length tolerance must be finite, got nan"),
], ids=["inertia-above-1", "negative-length", "string", "nan"])
def test_bad_tolerance(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Tolerances(**kwargs)


@dataclass(frozen=True)
class MassesOnly(MechanismUncertainty):
    """A user's uncertainty set of a 5-bar: its two masses only."""

    inertia: float = 0.1

    def draw(self, params, rng):
        f = rng.uniform(1 - self.inertia, 1 + self.inertia, size=2)
        return replace(params, m1=params.m1 * f[0], m2=params.m2 * f[1]), {"f": f.tolist()}

    def to_dict(self):
        return {"inertia": self.inertia}


def test_a_users_mechanism_uncertainty_set_draws_the_plants(fivebar, rrr):
    plant, drawn = fivebar.perturbed(np.random.default_rng([3, 5]), MassesOnly())
    f = np.random.default_rng([3, 5]).uniform(0.9, 1.1, size=2)  # the seed rule, recomputed
    P = plant.params
    assert drawn["factors"] == {"f": f.tolist()}
    # the drawn set is recorded whole (the plant may carry another name)
    assert {**drawn["params"], "name": P.name} == asdict(P)
    assert (P.m1, P.m2) == (0.5 * f[0], 0.3 * f[1])
    assert (P.d, P.l1, P.l2) == (0.12, 0.23, 0.23)
    # sample_mechanism draws sample k of seed s alone, by the same rule
    params, factors = sample_mechanism(FiveBarParams(), 3, 5, MassesOnly())
    assert factors == drawn["factors"] and (params.m1, params.m2) == (P.m1, P.m2)
    # recorded whole in a campaign's settings
    record = CampaignSettings(samples=1, tolerances=MassesOnly()).to_dict()
    assert record["uncertainty"] == "MassesOnly" and record["inertia"] == 0.1
    # a mechanism's set does not perturb a URDF: an arm refuses it by name
    with pytest.raises(TypeError, match="MassesOnly does not perturb a serial arm"):
        rrr.perturbed(np.random.default_rng(0), MassesOnly())
