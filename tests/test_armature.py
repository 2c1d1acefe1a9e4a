"""Armature (reflected rotor inertia), damping and friction as plant parameters (issue 44).

Checked against independent computations: Pinocchio's CRBA of the armature-free model plus
``diag(armature)``, MuJoCo's ``mj_fullM`` on an MJCF this file writes, the Python engine for
every other engine of the registry and every built-in law of the catalog, and the closed form
``(M + diag(armature))^-1`` for the linearization's input matrix.
"""

import pickle
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from rrr_pin.cli import main
from rrr_pin.control.catalog import LAWS, make_law
from rrr_pin.control.effects import PlantEffects
from rrr_pin.control.references import SineReference
from rrr_pin.model.dynamics import load_robot, robot_from_xml
from rrr_pin.model.uncertainty import Tolerances, ToleranceVertices
from rrr_pin.sim.engines import ENGINES
from rrr_pin.sim.simulation import simulate

#: Per-joint armature of the RRR in these tests [kg m^2]: of the order of its links' own
#: inertia about the joints (1.7 kg m^2 for link 1), as a geared arm's rotors are.
ARMATURE = np.array([0.3, 0.5, 0.2])


@pytest.fixture(scope="module")
def rrr_armature():
    """The paper's RRR with :data:`ARMATURE`."""
    return load_robot("rrr", armature=ARMATURE)


def _states(n, count=5, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-np.pi, np.pi, size=(count, n)), rng.normal(size=(count, n))


# --- M(q) with armature against two independent computations ------------------------------

@pytest.mark.parametrize("name", ["rrr", "ur5"])
def test_mass_matrix_is_crba_plus_diag_armature(name, rrr, ur5):
    free = {"rrr": rrr, "ur5": ur5}[name]
    armature = np.linspace(0.05, 0.4, free.nq)
    arm = free.with_joint_dynamics(armature=armature)
    data = free.model.createData()
    for q, qd in zip(*_states(free.nq), strict=True):
        M0 = pin.crba(free.model, data, q)
        M0 = np.triu(M0) + np.triu(M0, 1).T
        # Both are the same CRBA sums, the armature added once to the diagonal: round-off of
        # entries up to ~30 kg m^2, 1e-12 is 300 ulp of them.
        assert_allclose(arm.M(q), M0 + np.diag(armature), rtol=0.0, atol=1e-12)
        M, h = arm.terms(q, qd)
        assert_allclose(M, M0 + np.diag(armature), rtol=0.0, atol=1e-12)
        # h does not see the armature (qdd = 0); the inverse dynamics adds armature * qdd.
        assert_allclose(h, pin.nonLinearEffects(free.model, data, q, qd), rtol=0.0, atol=1e-12)
        qdd = np.cos(q)
        assert_allclose(arm.inverse_dynamics(q, qd, qdd),
                        pin.rnea(free.model, data, q, qd, qdd) + armature * qdd,
                        rtol=0.0, atol=1e-10)  # torques up to ~1e3 N m on the RRR
        assert_allclose(arm.V(q, qd), free.V(q, qd), rtol=0.0, atol=1e-12)


#: A 3-joint arm with general inertias and skewed axes, as URDF and as MJCF (the same numbers:
#: body position = joint origin, joint at the body's origin, inertial at its centre of mass).
_LINKS = [  # joint origin [m], axis, mass [kg], com [m], diagonal inertia [kg m^2]
    ((0.0, 0.0, 0.1), (0, 0, 1), 3.0, (0.02, 0.01, 0.15), (0.05, 0.04, 0.02)),
    ((0.0, 0.05, 0.3), (0, 1, 0), 2.0, (0.2, 0.0, 0.01), (0.01, 0.06, 0.05)),
    ((0.4, 0.0, 0.0), (0.6, 0.8, 0), 1.0, (0.1, 0.02, 0.0), (0.004, 0.01, 0.012)),
]
_ARMATURE3 = (0.2, 0.15, 0.05)


def _urdf3() -> str:
    parts = ['<robot name="arm3"><link name="base"/>']
    parent = "base"
    for i, (xyz, axis, m, com, I) in enumerate(_LINKS, start=1):
        parts.append(
            f'<joint name="j{i}" type="revolute"><parent link="{parent}"/>'
            f'<child link="l{i}"/><origin xyz="{" ".join(map(str, xyz))}"/>'
            f'<axis xyz="{" ".join(map(str, axis))}"/>'
            f'<limit lower="-3" upper="3" effort="100" velocity="10"/></joint>'
            f'<link name="l{i}"><inertial><origin xyz="{" ".join(map(str, com))}"/>'
            f'<mass value="{m}"/><inertia ixx="{I[0]}" ixy="0" ixz="0" iyy="{I[1]}" iyz="0" '
            f'izz="{I[2]}"/></inertial></link>')
        parent = f"l{i}"
    return "".join(parts) + "</robot>"


def _mjcf3() -> str:
    body = ""
    for i, (xyz, axis, m, com, I) in reversed(list(enumerate(_LINKS, start=1))):
        body = (f'<body name="l{i}" pos="{" ".join(map(str, xyz))}">'
                f'<joint name="j{i}" type="hinge" axis="{" ".join(map(str, axis))}" '
                f'armature="{_ARMATURE3[i - 1]}"/>'
                f'<inertial pos="{" ".join(map(str, com))}" mass="{m}" '
                f'diaginertia="{" ".join(map(str, I))}"/>{body}</body>')
    return f'<mujoco model="arm3"><worldbody>{body}</worldbody></mujoco>'


def test_mass_matrix_equals_mujoco_full_m():
    mujoco = pytest.importorskip("mujoco")
    m = mujoco.MjModel.from_xml_string(_mjcf3())
    d = mujoco.MjData(m)
    arm = robot_from_xml(_urdf3()).with_joint_dynamics(armature=_ARMATURE3)
    assert_array_equal(m.dof_armature, _ARMATURE3)
    M = np.zeros((m.nv, m.nv))
    for q, _ in zip(*_states(3, seed=1), strict=True):
        d.qpos[:] = q
        mujoco.mj_forward(m, d)
        mujoco.mj_fullM(m, d, M)  # MuJoCo 4: (model, data, dst)
        # Two algorithms (Pinocchio's CRBA in joint frames, MuJoCo's composite inertias in the
        # world frame) on entries of ~0.5 kg m^2: round-off ~1e-16, 1e-12 far above it.
        assert_allclose(arm.M(q), M, rtol=0.0, atol=1e-12)


# --- every engine of the registry equals the Python engine, with armature and friction ------

DURATION = 0.1  # [s]: 100 control periods at 1 kHz; the reference moves by ~0.1 rad
RATE = 1000.0
# Engine agreement as tests/test_engines.py states it (issue 9's 1e-9 rad; tau up to ~1e3 N m
# carries the state's round-off times lam^2 M: 1e-7 N m).
ATOL_Q, ATOL_TAU = 1e-9, 1e-7


def _law(name, nominal, paper, twodof):
    """The catalog's law ``name`` on ``nominal``, from the session's designs (no new synthesis).

    The paper's K for the laws that take one; the 2-DOF law's design (which does not depend on
    the arm's inertias) moved onto ``nominal``.
    """
    if name == "hinf2dof":
        return replace(twodof, nominal=nominal)
    return make_law(name, nominal, K=paper.K_reduced)


def _runs(nominal, laws, home):
    """Per (engine, law): the run's trajectory, or the reason the engine refused it.

    ``laws``: the catalog's built-ins on ``nominal`` (which has an armature), by name; the
    plant is an uncertain arm drawn around it (armature drawn too); a viscous and Coulomb
    friction effect acts on the joints.
    """
    plant, _ = nominal.perturbed(np.random.default_rng(3), Tolerances(armature=0.3))
    ref = SineReference(home=home, amp=0.1, freq=2.0, phase=0.3)
    effects = PlantEffects(viscous=0.4, coulomb=0.8)
    out = {}
    for law_name, law in laws.items():
        for engine in ENGINES:
            try:
                out[engine, law_name] = simulate(plant, law, ref, DURATION, rate=RATE,
                                                 q0=ref(0.0)[0] + 0.01, engine=engine,
                                                 effects=effects)
            except ValueError as exc:  # an engine that does not run this law exactly
                out[engine, law_name] = str(exc)
    return plant, out


@pytest.fixture(scope="module")
def armature_runs(rrr_armature, paper, twodof):
    """:func:`_runs` on the RRR with :data:`ARMATURE`, every law of the catalog."""
    laws = {name: _law(name, rrr_armature, paper, twodof) for name in LAWS}
    return _runs(rrr_armature, laws, [0.2, -0.4, 0.6])


@pytest.mark.parametrize("engine", [e for e in ENGINES if e != "python"])
def test_every_engine_equals_python_with_armature_and_friction(armature_runs, engine):
    _check_engine(*armature_runs, engine)


@pytest.mark.slow  # about 10 s: the designs of every law for 6 joints and 6-joint Python runs
@pytest.mark.parametrize("engine", [e for e in ENGINES if e != "python"])
def test_every_engine_equals_python_with_armature_on_the_ur5(ur5, engine):
    nominal = ur5.with_joint_dynamics(armature=[0.4, 0.4, 0.3, 0.1, 0.1, 0.05])
    laws = {name: make_law(name, nominal) for name in LAWS}
    _check_engine(*_runs(nominal, laws, [0.0, -1.2, 1.0, -0.5, 0.3, 0.2]), engine)


def _check_engine(plant, runs, engine):
    assert np.all(np.asarray(plant.model.armature) > 0.0)
    ran = []
    for law_name in LAWS:
        py, other = runs["python", law_name], runs[engine, law_name]
        assert not isinstance(py, str), py  # the reference runs every law
        if isinstance(other, str):
            assert engine in other or "cannot" in other or "not" in other, other
            continue
        ran.append(law_name)
        assert other.info["engine"] == engine
        assert_allclose(other.q, py.q, rtol=0.0, atol=ATOL_Q, err_msg=law_name)
        assert_allclose(other.qd, py.qd, rtol=0.0, atol=ATOL_Q, err_msg=law_name)
        assert_allclose(other.tau, py.tau, rtol=0.0, atol=ATOL_TAU, err_msg=law_name)
        assert np.abs(py.error).max() > 1e-4  # the loop acts: not two idle runs
    # the paper's laws run on every compiled engine (the point of the check)
    assert {"fl", "hinf"} <= set(ran), runs


def test_armature_changes_the_run(rrr, rrr_armature):
    """The armature reaches the plant: the same law on the arm without it runs differently."""
    ref = SineReference(home=[0.2, -0.4, 0.6], amp=0.1, freq=2.0, phase=0.3)
    law = make_law("fl", rrr)
    a = simulate(rrr, law, ref, DURATION, rate=RATE, engine="compiled")
    b = simulate(rrr_armature, law, ref, DURATION, rate=RATE, engine="compiled")
    assert np.abs(a.q - b.q).max() > 1e-6


# --- linearization against the closed form and finite differences ----------------------------

def test_linearization_with_armature(rrr, rrr_armature):
    q = np.array([0.3, -0.7, 1.1])
    tau = np.array([5.0, -20.0, 8.0])
    dq, dv, B = rrr_armature.linearization(q, tau)
    data = rrr.model.createData()
    Ma = pin.crba(rrr.model, data, q)
    Ma = np.triu(Ma) + np.triu(Ma, 1).T + np.diag(ARMATURE)
    # closed form of the input matrix: (M + diag(armature))^-1; a 3x3 inverse, round-off
    assert_allclose(B, np.linalg.inv(Ma), rtol=0.0, atol=1e-12)

    def qdd(x):  # forward dynamics at rest from the armature-free model's M and G
        M = pin.crba(rrr.model, data, x)
        M = np.triu(M) + np.triu(M, 1).T + np.diag(ARMATURE)
        return np.linalg.solve(M, tau - pin.computeGeneralizedGravity(rrr.model, data, x))

    h = 1e-6
    fd = np.array([(qdd(q + h * e) - qdd(q - h * e)) / (2 * h) for e in np.eye(3)]).T
    # central differences, O(h^2) ~ 1e-12 truncation plus ~1e-10 round-off (eps |qdd| / h)
    assert_allclose(dq, fd, rtol=0.0, atol=1e-7)
    assert_allclose(dv, 0.0, atol=1e-12)  # at qd = 0 the velocity terms vanish


# --- drawn plants ---------------------------------------------------------------------------

@pytest.mark.parametrize("tol_class", [Tolerances, ToleranceVertices])
def test_drawn_armature_within_its_band_and_reproducible(rrr_armature, tol_class):
    tol = tol_class(armature=0.25, damping=0.1, friction=0.1)
    a = [np.array(rrr_armature.perturbed(np.random.default_rng([7, k]), tol)[0].model.armature)
         for k in range(6)]
    again = rrr_armature.perturbed(np.random.default_rng([7, 2]), tol)[0]
    assert_array_equal(again.model.armature, a[2])  # the same (seed, sample), the same plant
    lo, hi = ARMATURE * 0.75, ARMATURE * 1.25
    for x in a:
        # the factor's band, up to the product's one rounding
        assert np.all(x >= lo * (1 - 1e-15)) and np.all(x <= hi * (1 + 1e-15))
    if tol_class is Tolerances:
        assert len({tuple(x) for x in a}) == len(a)  # every sample its own draw
    else:  # corners: every factor at 1 - tol or 1 + tol
        f = np.array(a) / ARMATURE
        assert_allclose(np.minimum(abs(f - 0.75), abs(f - 1.25)), 0.0, atol=1e-15)


def test_a_zero_joint_tolerance_leaves_the_plants_as_they_were(rrr_armature):
    """The joint draws come after the inertial ones and only when asked: same links."""
    rng = [np.random.default_rng([0, 4]) for _ in range(2)]
    p0, par0 = rrr_armature.perturbed(rng[0], Tolerances())
    p1, par1 = rrr_armature.perturbed(rng[1], Tolerances(armature=0.3))
    assert par0["params"] == par1["params"]
    assert_array_equal(p0.model.armature, ARMATURE)  # carried from the nominal
    assert "factors" not in par0["joint_dynamics"]
    assert par1["joint_dynamics"]["source"]["armature"] == "cli"
    assert_allclose(par1["joint_dynamics"]["armature_kg_m2"],
                    ARMATURE * par1["joint_dynamics"]["factors"]["armature"], rtol=1e-15)


def test_damping_and_friction_drawn_relative_to_the_urdf(ur5):
    """Damping and friction of the URDF drawn per plant; a zero nominal stays zero."""
    arm = ur5.with_joint_dynamics(damping=0.5, source="cli")
    p, par = arm.perturbed(np.random.default_rng(1), Tolerances(damping=0.2, friction=0.2))
    f = np.asarray(par["joint_dynamics"]["factors"]["damping"])
    assert_allclose(p.model.damping, 0.5 * f, rtol=1e-15)
    assert np.all((f >= 0.8) & (f <= 1.2))
    assert_array_equal(p.model.friction, arm.model.friction * 0.0)  # zero nominal: zero
    assert_allclose(p.joint_friction()[0], p.model.damping)


def test_joint_dynamics_recorded_and_pickled(rrr_armature):
    rec = rrr_armature.joint_dynamics()
    assert rec["armature_kg_m2"] == ARMATURE.tolist()
    assert rec["source"] == {"armature": "cli", "damping": "none", "friction": "none"}
    assert rrr_armature.fingerprint()["joint_dynamics"] == rec
    back = pickle.loads(pickle.dumps(rrr_armature))  # how a campaign sends its nominal
    assert back.joint_dynamics() == rec
    assert "joint_dynamics" not in load_robot("rrr").fingerprint()  # old resumes still match


def test_locked_arm_takes_one_armature_per_moving_joint():
    lock = {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0}
    arm = load_robot("panda", lock=lock, armature=0.1)
    assert_array_equal(arm.model.armature, np.full(7, 0.1))
    assert arm.joint_dynamics()["source"]["damping"] == "urdf"  # the Panda URDF's 0.003
    with pytest.raises(ValueError, match=r"armature has 9 values, the arm has 7 joints"):
        load_robot("panda", lock=lock, armature=[0.1] * 9)


# --- bad input ------------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, match", [
    ({"armature": -0.1}, r"armature of joint 'joint1' must be a finite number >= 0 \[kg m\^2\]"),
    ({"armature": [0.1, np.nan, 0.1]}, r"armature of joint 'joint2' must be a finite"),
    ({"armature": [0.1, 0.2]}, r"armature has 2 values, the arm has 3 joints"),
    ({"damping": [0.1, 0.1, -1.0]}, r"damping of joint 'joint3' must be .* \[N m s/rad\]"),
    ({"friction": np.inf}, r"friction of joint 'joint1' must be a finite .* \[N m\]"),
    ({"armature": "heavy"}, r"armature must be a number or one number per joint"),
], ids=["negative", "nan", "count", "damping", "friction", "text"])
def test_bad_joint_values_are_refused_by_name(rrr, kwargs, match):
    with pytest.raises(ValueError, match=match):
        rrr.with_joint_dynamics(**kwargs)


@pytest.mark.parametrize("field", ["armature", "damping", "friction"])
@pytest.mark.parametrize("value", [-0.1, 1.0, float("nan")])
def test_bad_tolerances_are_refused_by_name(field, value):
    with pytest.raises(ValueError, match=f"{field} tolerance"):
        Tolerances(**{field: value})


def test_closed_chains_refuse_armature_and_joint_tolerances(fivebar):
    with pytest.raises(ValueError, match="closed chain's armature is its MJCF's"):
        load_robot("fivebar", armature=0.1)
    with pytest.raises(ValueError, match="tolerance armature: drawn for serial arms only"):
        fivebar.perturbed(np.random.default_rng(0), Tolerances(armature=0.1))


@pytest.mark.parametrize("argv, match", [
    (["margins", "--armature", "-0.1"], "--armature of joint 'joint1' must be a finite number"),
    (["margins", "--armature", "0.1/0.2"], "--armature has 2 values, the arm has 3 joints"),
    (["margins", "--armature", "a/b"], "--armature expects a number"),
    (["montecarlo", "--samples", "1", "--tolerance-armature", "1.5"],
     "--tolerance-armature: armature tolerance must be in"),
    (["design", "--armature", "0.1"], "--armature applies to an arm's design"),
], ids=["negative", "count", "text", "tolerance", "design-without-robot"])
def test_cli_refuses_bad_armature(argv, match, capsys, tmp_path):
    code = main(argv + (["--out", str(tmp_path / "o")] if argv[0] == "montecarlo" else []))
    err = capsys.readouterr().err
    assert code == 2
    assert match in err and "Traceback" not in err and err.count("\n") == 1


# --- campaigns: every row records its plant's coefficients, and resumes stay exact ------------

def test_campaign_records_joint_dynamics_and_resumes(rrr_armature, tmp_path):
    import json
    import shutil

    from rrr_pin.campaign import montecarlo as mc
    from rrr_pin.campaign.runner import RunSettings, make_laws
    from rrr_pin.campaign.store import StoreError
    from rrr_pin.control.references import study_reference
    from rrr_pin.report.campaign import write_campaign

    settings = mc.CampaignSettings(samples=3, tolerances=Tolerances(armature=0.3),
                                   run=RunSettings(duration=0.05, rate=1000.0))
    laws = make_laws("fl", rrr_armature)
    reference = study_reference(rrr_armature, settings.run.duration)
    ref = tmp_path / "ref"
    with mc.open_store(ref, rrr_armature, laws, settings, reference) as store:
        whole = mc.run_campaign(rrr_armature, laws, settings, jobs=1, chunk=1, store=store)
    for row in whole.rows:  # each row's record is its plant's, redrawn alone from its seed
        plant, _ = rrr_armature.perturbed(np.random.default_rng(row["seed"]),
                                          settings.tolerances)
        assert row["parameters"]["joint_dynamics"] == json.loads(json.dumps(
            {**plant.joint_dynamics(),
             "factors": row["parameters"]["joint_dynamics"]["factors"]}))
        assert_allclose(plant.model.armature,
                        ARMATURE * row["parameters"]["joint_dynamics"]["factors"]["armature"],
                        rtol=1e-15)
    write_campaign(whole, tmp_path / "out")
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["joint_dynamics"] == rrr_armature.joint_dynamics()
    assert summary["settings"]["tolerance_armature"] == 0.3
    # a killed run resumes to the same rows; another armature or tolerance is refused
    cut = tmp_path / "cut"
    shutil.copytree(ref, cut)
    lines = (cut / "parts.jsonl").read_text().splitlines(keepends=True)
    (cut / "parts.jsonl").write_text("".join(lines[:2]))
    with mc.open_store(cut, rrr_armature, laws, settings, reference, resume=True) as store:
        resumed = mc.run_campaign(rrr_armature, laws, settings, jobs=1, chunk=1, store=store)
    assert resumed.rows == whole.rows
    other = rrr_armature.with_joint_dynamics(armature=0.1)
    with pytest.raises(StoreError):
        mc.open_store(cut, other, make_laws("fl", other), settings, reference, resume=True)
    with pytest.raises(StoreError):
        mc.open_store(cut, rrr_armature, laws,
                      replace(settings, tolerances=Tolerances(armature=0.2)), reference,
                      resume=True)
