"""Friction everywhere the identification goes (issue 32, item 2): plant, draws, laws, export.

Synthetic only: the RRR with friction written into its URDF's ``<dynamics>``, short runs.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin import QuinticReference, exported_law, fl_controller, hinf_fl_controller, simulate
from rrr_pin import export as export_law
from rrr_pin.cli import main
from rrr_pin.cli.build import friction_spec
from rrr_pin.control.effects import EffectsError, PlantEffects
from rrr_pin.control.friction import JointFriction
from rrr_pin.control.laws import FLForm, FLFrictionForm
from rrr_pin.model.dynamics import robot_from_xml

#: Per joint: viscous [N m s/rad], Coulomb [N m] (the plants' and the laws').
FV, FC = (2.0, 1.5, 0.5), (1.0, 0.8, 0.3)
RATE = 1000.0


def _with_dynamics(urdf: str, fv, fc) -> str:
    """The URDF text with ``<dynamics damping friction>`` on each revolute joint, by hand."""
    root = ET.fromstring(urdf)
    joints = [j for j in root.findall("joint") if j.get("type") != "fixed"]
    for joint, v, c in zip(joints, fv, fc, strict=True):
        ET.SubElement(joint, "dynamics", damping=repr(v), friction=repr(c))
    return ET.tostring(root, encoding="unicode")


@pytest.fixture(scope="module")
def rubbing(rrr):
    """The RRR whose URDF carries FV, FC."""
    return robot_from_xml(_with_dynamics(rrr.urdf, FV, FC), name="rrr_friction")


def _ref(robot):
    q0 = np.clip(robot.neutral(), robot.lower, robot.upper)
    return QuinticReference(q0, q0 + 0.6, 0.3)


def test_joint_friction_torque_is_the_model_written_out():
    f = JointFriction(FV, FC, 0.02)
    qd = np.array([0.3, -0.01, 0.0])
    expected = np.array([2.0 * 0.3 + 1.0 * np.tanh(0.3 / 0.02),
                         1.5 * -0.01 + 0.8 * np.tanh(-0.01 / 0.02), 0.0])
    assert_allclose(f.torque(qd), expected, rtol=1e-15, atol=0)  # the same formula: round-off


@pytest.mark.parametrize("kwargs, match", [
    ({"viscous": (1.0, -0.1), "coulomb": (0.0, 0.0)}, r"viscous\[1\] = -0.1"),
    ({"viscous": (1.0,), "coulomb": (0.0, 0.0)}, "viscous has 1 values and coulomb 2"),
    ({"viscous": (1.0,), "coulomb": (float("nan"),)}, r"coulomb\[0\] = nan"),
    ({"viscous": (1.0,), "coulomb": (1.0,), "coulomb_velocity": 0.0}, "coulomb_velocity"),
], ids=["negative", "lengths", "nan", "veps"])
def test_joint_friction_refuses_by_name(kwargs, match):
    with pytest.raises(ValueError, match=match):
        JointFriction(**kwargs)


def test_the_urdf_friction_is_read_and_simulated(rrr, rubbing):
    """``viscous='urdf'`` takes each plant's own: the same run as the values given."""
    assert_allclose(np.concatenate(rubbing.joint_friction()), [*FV, *FC], rtol=0, atol=0)
    law, ref = fl_controller(rubbing), _ref(rubbing)
    a = simulate(rubbing, law, ref, 0.2, rate=RATE, engine="python",
                 effects=PlantEffects(viscous="urdf", coulomb="urdf"))
    b = simulate(rubbing, law, ref, 0.2, rate=RATE, engine="python",
                 effects=PlantEffects(viscous=FV, coulomb=FC))
    assert_allclose(a.q, b.q, rtol=0, atol=0)  # the same arrays reach the same loop
    assert a.info["effects"]["viscous_Nms"] == list(FV)
    with pytest.raises(EffectsError, match="both coefficients or neither"):
        PlantEffects(viscous="urdf", coulomb=1.0)


def test_the_urdf_friction_of_an_arm_without_any_is_refused(rrr):
    # issue 50's probe: --friction urdf on an arm whose URDF has no friction ran with none and
    # recorded "urdf", not the zeros; asking for the description's friction where it gives
    # none is refused, naming the arm and how to give the coefficients.
    assert not np.any(np.concatenate(rrr.joint_friction()))
    with pytest.raises(EffectsError, match=r"friction 'urdf': the serial arm 'rrr' has no joint "
                                           r"friction in its description .* viscous=V,coulomb=C"):
        simulate(rrr, fl_controller(rrr), _ref(rrr), 0.01, rate=RATE, engine="python",
                 effects=PlantEffects(viscous="urdf", coulomb="urdf"))


def test_compensation_adds_the_friction_torque(rubbing):
    """The law's torque with compensation minus without is Fv qd + Fc tanh(qd / v_eps)."""
    f = JointFriction(FV, FC)
    with_f, without = fl_controller(rubbing, friction=f), fl_controller(rubbing)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, qd, r, rd, rdd = (rng.uniform(-1.0, 1.0, 3) for _ in range(5))
        tau0 = without.torque(0.0, q, qd, r, rd, rdd, np.zeros(0))
        d = with_f.torque(0.0, q, qd, r, rd, rdd, np.zeros(0)) - tau0
        expected = np.array(FV) * qd + np.array(FC) * np.tanh(qd / 0.01)
        # a difference of two torques of size |tau0| (lam^2 = 1e4): round-off of that size
        assert_allclose(d, expected, rtol=0, atol=8 * np.finfo(float).eps * np.abs(tau0).max())
    assert with_f.describe()["friction_compensation"]["viscous_Nms_rad"] == list(FV)
    assert type(with_f.compiled_form()) is FLFrictionForm
    assert type(without.compiled_form()) is FLForm


def test_compensating_the_plants_friction_tracks_as_without_friction(rubbing):
    """FL (lam = 10 rad/s, where friction matters) on the plant with friction, compensated,
    tracks as FL on the same arm without friction: the compensation cancels it (up to the
    zero-order hold: the plant's friction acts between samples at the moving qd)."""
    ref = _ref(rubbing)

    def rms(effects, friction):
        tr = simulate(rubbing, fl_controller(rubbing, 10.0, friction=friction), ref, 0.5,
                      rate=RATE, effects=effects, engine="python")
        return float(np.sqrt(np.mean((tr.q - ref.sample(tr.t)[0]) ** 2)))

    fx = PlantEffects(viscous=FV, coulomb=FC)
    ideal = rms(PlantEffects(), None)
    # measured: 4.57e-4 (no friction), 2.38e-3 (friction), 4.59e-4 (friction, compensated)
    assert rms(fx, None) > 4.0 * ideal
    assert abs(rms(fx, JointFriction(FV, FC)) - ideal) < 0.01 * ideal


def test_engines_that_cannot_compensate_refuse_by_name(rubbing):
    law = fl_controller(rubbing, friction=JointFriction(FV, FC))
    ref = _ref(rubbing)
    with pytest.raises(ValueError, match="FLFrictionForm .* not implemented"):
        simulate(rubbing, law, ref, 0.05, rate=RATE, engine="compiled")
    with pytest.raises(ValueError, match="FLFrictionForm|not implemented|codegen"):
        simulate(rubbing, law, ref, 0.05, rate=RATE, engine="codegen")
    tr = simulate(rubbing, law, ref, 0.05, rate=RATE)  # auto: the engine that ran, recorded
    assert tr.info["engine"] == "python"


def test_friction_spec_spelling():
    assert friction_spec("urdf", 3) == {"viscous": "urdf", "coulomb": "urdf"}
    assert friction_spec("viscous=0.5/0.4/0.3,coulomb=1,smooth=0.02", 3) == {
        "viscous": (0.5, 0.4, 0.3), "coulomb": 1.0, "coulomb_velocity": 0.02}
    for bad, match in (("viscous=1/2", "2 values"), ("coulomb=-1", ">= 0"),
                       ("damping=1", "expects 'urdf'"), ("viscous=x", "not a number"),
                       ("smooth=0.1", "give viscous")):
        with pytest.raises(ValueError, match=match):
            friction_spec(bad, 3)


def _compile_shared(folder):
    """The folder's C sources (C99, no warning allowed) as a shared library, directly."""
    objs = []
    for f in ("controller.c", "dynamics.c", "codegen_rrr.c"):
        obj = folder / (f + ".o")
        subprocess.run(["cc", "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O2",
                        "-fPIC", "-c", str(folder / f), "-o", str(obj)], check=True)
        objs.append(str(obj))
    lib = folder / "libdirect.so"
    subprocess.run(["cc", "-shared", "-o", str(lib), *objs, "-lm"], check=True)
    return lib


def _assert_steps_equal(py_law, c_law, n, steps, seed):
    """The C law's steps against the Python law's at ``steps`` random states (seeded)."""
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        q, qd, r, rd, rdd = (rng.uniform(-2.0, 2.0, n) for _ in range(5))
        x = rng.standard_normal(py_law.nx)
        tau_py, x_py = py_law.step(0.0, q, qd, r, rd, rdd, x)
        tau_c, x_c = c_law.step(0.0, q, qd, r, rd, rdd, x)
        # the same operations in the same order; M and h by Pinocchio against the generated
        # C (or Pinocchio's C++): round-off, inside 1e-12 of each torque (test_export's bound)
        assert_allclose(tau_c, tau_py, rtol=1e-12, atol=0)
        assert_allclose(x_c, x_py, rtol=1e-12, atol=1e-12)


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
@pytest.mark.parametrize("name", ["fl", "hinf"])
def test_exported_law_compensates_as_python(name, rrr, tmp_path, design_for):
    """The C law with compensation against the Python law (1e-12), controller.json's record."""
    f = JointFriction(FV, FC, 0.05, source="test")
    law = (fl_controller(rrr, friction=f) if name == "fl" else
           hinf_fl_controller(rrr, design_for(3).K_reduced, friction=f))
    folder = tmp_path / name
    ex = export_law(law, rrr, RATE, folder)
    assert ex.form.kind == "fl_friction" and ex.dynamics == "generated"
    whole = json.loads((folder / "controller.json").read_text())
    rec = whole["law"]
    assert whole["model"]["parameters"]["friction_compensated"] is True
    assert rec["friction_compensation"]["viscous_Nms_rad"] == list(FV)
    assert rec["friction_compensation"]["coulomb_velocity_rad_s"] == 0.05
    c_law = exported_law(folder, _compile_shared(folder))
    _assert_steps_equal(ex.law, c_law, 3, 500, seed=11)
    without = export_law(fl_controller(rrr) if name == "fl" else
                         hinf_fl_controller(rrr, design_for(3).K_reduced), rrr, RATE,
                         tmp_path / f"{name}_plain")
    assert "FV" not in without.files["controller.c"] and "FV" in ex.files["controller.c"]


def test_cli_friction_options(tmp_path, capsys, rubbing):
    urdf = tmp_path / "rubbing.urdf"
    urdf.write_text(rubbing.urdf)
    base = ["reproduce", "--robot", str(urdf), "--samples", "1", "--no-certify",
            "--duration", "0.2", "--controllers", "fl", "--no-progress"]
    # refused up front, exit 2, no traceback
    for extra, match in ((["--friction", "viscous=1"], "give --rate"),
                         (["--rate", "1000", "--friction", "viscous=-1"], ">= 0"),
                         (["--rate", "1000", "--friction", "urdf", "--controllers", "pd",
                           "--compensate-friction"], "'pd' does not compensate friction")):
        assert main([*base, *extra, "--out", str(tmp_path / "bad")]) == 2
        err = capsys.readouterr().err
        assert match in err and "Traceback" not in err
    # the same options reach montecarlo's settings and laws (cli.build, shared): one run
    # records what it applied and what the laws compensate (reproduce's figures cost ~8 s)
    out = tmp_path / "ok"
    assert main(["montecarlo", "--robot", str(urdf), "--samples", "1", "--duration", "0.2",
                 "--controllers", "fl", "--jobs", "1", "--no-progress", "--friction", "urdf",
                 "--compensate-friction", "--out", str(out)]) == 0
    res = json.loads((out / "summary.json").read_text())
    text = json.dumps(res)
    assert '"friction_compensation"' in text and '"viscous_Nms_rad": [2.0, 1.5, 0.5]' in text
    assert '"viscous_Nms": "urdf"' in text


# --- plants drawn from an identification with friction carry their own -----------------------

@pytest.fixture(scope="module")
def friction_record(rrr, tmp_path_factory):
    """An identification with friction of the RRR (noisy synthetic log, 10 s at 50 Hz)."""
    from rrr_pin.model import identification as idn
    from rrr_pin.model.excitation import FourierTrajectory

    rng = np.random.default_rng(0)
    traj = FourierTrajectory(0.2, 0.4 * rng.standard_normal((3, 5)),
                             0.4 * rng.standard_normal((3, 5)), np.zeros(3), 2)
    t = np.arange(0.0, 10.0, 0.02)
    q, qd, qdd = traj.sample(t)
    tau = np.array([rrr.inverse_dynamics(*x) for x in zip(q, qd, qdd, strict=True)])
    tau += np.array(FV) * qd + np.array(FC) * np.sign(qd) + 0.1
    tau += 0.05 * rng.standard_normal(tau.shape)
    data = idn.Measurements(t, q, qd, qdd, tau, tuple(rrr.joint_names))
    folder = tmp_path_factory.mktemp("idf")
    idn.identify(rrr, data, held_out=0.0, friction=True).write(folder)
    return folder


def test_plants_drawn_carry_their_drawn_friction(friction_record, rrr):
    from rrr_pin.model.identification import IdentifiedUncertainty

    tol = IdentifiedUncertainty(str(friction_record / "identification.json"))
    rec = tol.record
    urdf = (friction_record / "identified.urdf").read_text()
    nominal = robot_from_xml(urdf, name="identified")
    fv0 = [rec["friction"][j]["viscous_Nms_rad"] for j in rrr.joint_names]
    # the identified URDF carries the estimate (its <dynamics>), read back by the plant
    assert_allclose(nominal.joint_friction()[0], fv0, rtol=1e-15)
    rng = np.random.default_rng(1)
    drawn = []
    for _ in range(20):
        text, info = tol.draw(urdf, rng)
        plant = robot_from_xml(text, name="drawn")
        fv, fc = plant.joint_friction()
        expect = info["friction"]
        assert_allclose(fv, [expect[j]["viscous_Nms_rad"] for j in rrr.joint_names], rtol=1e-15)
        assert_allclose(fc, [expect[j]["coulomb_Nm"] for j in rrr.joint_names], rtol=1e-15)
        assert np.all(fv >= 0) and np.all(fc >= 0)
        assert "friction_folded" in info["rejected"]
        drawn.append(fv)
    # the draws spread around the estimate by about its standard deviation (20 draws of a
    # chi-square-truncated normal: between 0.3 and 1.7 std per joint)
    std = np.array([rec["friction"][j]["std"]["viscous_Nms_rad"] for j in rrr.joint_names])
    spread = np.std(drawn, axis=0)
    assert np.all((spread > 0.3 * std) & (spread < 1.7 * std))


def test_montecarlo_on_drawn_plants_simulates_their_friction(friction_record, tmp_path, capsys):
    out = tmp_path / "mc"
    assert main(["montecarlo", "--robot", str(friction_record / "identified.urdf"),
                 "--uncertainty", str(friction_record / "identification.json"),
                 "--samples", "2", "--duration", "0.2", "--controllers", "fl",
                 "--friction", "urdf", "--compensate-friction", "--no-progress",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "folded back" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["summary"]["engines"]["fl"] == {"python": 2}  # compensation: Python only
    drawn = [json.loads(line) for line in (out / "samples.jsonl").read_text().splitlines()]
    assert all(d["parameters"]["identified"]["friction"] for d in drawn)


def test_projected_draws_are_consistent_and_record_the_move(friction_record, rrr):
    from rrr_pin.model import identification as idn
    from rrr_pin.model.identification import IdentifiedUncertainty

    path = str(friction_record / "identification.json")
    with pytest.raises(ValueError, match="draws must be one of reject, project"):
        IdentifiedUncertainty(path, draws="move")
    tol = IdentifiedUncertainty(path, draws="project")
    assert tol.to_dict()["draws"] == "project"
    urdf = (friction_record / "identified.urdf").read_text()
    # a base point no arm has (the first base parameter, a mass sum, made negative)
    theta = np.asarray(tol.record["base_consistent"], float).copy()
    theta[0] = -abs(theta[0])
    text, phi, moved = tol._project(urdf, theta, None)
    assert moved > 0.0
    for b in range(3):  # physically consistent after the move
        assert np.linalg.eigvalsh(idn.pseudo_inertia(phi[10 * b:10 * b + 10])).min() > 0.0
    text, info = tol.draw(urdf, np.random.default_rng(2))
    assert set(info["rejected"]) >= {"projected", "projected_mahalanobis", "friction_folded"}


def test_friction_too_stiff_for_the_substep_is_refused(rubbing):
    """Viscous friction on a light arm is a damper faster than RK4's step: refused up front,
    with the step that would hold it."""
    law = fl_controller(rubbing)
    with pytest.raises(EffectsError, match=r"too fast for the plant sub-step h = 0.001 s .*"
                                           r"lower dt below"):
        simulate(rubbing, law, _ref(rubbing), 0.01, rate=RATE,
                 effects=PlantEffects(viscous=1e5, coulomb=0.0))


def test_friction_spec_urdf_takes_a_smoothing_speed():
    assert friction_spec("urdf,smooth=0.05", 3) == {"viscous": "urdf", "coulomb": "urdf",
                                                    "coulomb_velocity": 0.05}
    with pytest.raises(ValueError, match="urdf takes smooth=S"):
        friction_spec("urdf,viscous=1", 3)


@pytest.mark.slow
def test_exported_compensation_on_pinocchio_dynamics_equals_python(ur5, tmp_path, design_for):
    """UR5 (the Pinocchio C++ dynamics of the export, a CMake build): H-inf + FL with friction
    compensation, 1000 random states, C against Python (the export tests' 1e-12)."""
    if shutil.which("cmake") is None:
        pytest.skip("no cmake")
    from rrr_pin.deploy.loaded import build

    f = JointFriction((0.3,) * 6, (0.5,) * 6, 0.05)
    ex = export_law(hinf_fl_controller(ur5, design_for(6).K_reduced, friction=f), ur5, RATE,
                    tmp_path / "ur5", dynamics="pinocchio")
    assert ex.dynamics == "pinocchio"
    c_law = exported_law(tmp_path / "ur5", build(tmp_path / "ur5"))
    _assert_steps_equal(ex.law, c_law, 6, 1000, seed=5)


def test_design_tunes_over_plants_drawn_from_the_identification(friction_record, tmp_path,
                                                                capsys):
    # issue 34: the plant set identified from data, as montecarlo's --uncertainty
    out = tmp_path / "d"
    assert main(["design", "--robot", str(friction_record / "identified.urdf"),
                 "--uncertainty", str(friction_record / "identification.json"),
                 "--samples", "2", "--structure", "gain", "--starts", "1", "--no-simulate",
                 "--require", "delay_margin=0.004", "--out", str(out)]) == 0
    data = json.loads((out / "design.json").read_text())
    assert data["plants"]["tolerances"]["uncertainty"] == "identified"
    assert data["plants"]["samples"] == 2 and data["requirements"][0]["verified"] > 0
