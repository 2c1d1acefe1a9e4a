"""Serial arms from MJCF (rrr_pin.model.dynamics.arm_from_mjcf) and the MuJoCo engine.

Every model is written here (no file of ../shared is read). MuJoCo is the independent
reference: its mj_fullM and qfrc_bias for the loaded arm, and its own RK4 for the engine; the
MuJoCo tests skip by name without the extra (pip install 'rrr-pin[mujoco]').
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.control.catalog import make_law
from rrr_pin.control.effects import PlantEffects
from rrr_pin.control.references import default_reference
from rrr_pin.model.dynamics import MjcfArm, arm_from_mjcf, load_robot
from rrr_pin.model.robots import RobotModelError
from rrr_pin.sim.simulation import simulate

#: A 3-joint arm with a slide "finger" (to lock), rotor inertia, damping and friction loss;
#: joint axes and inertias chosen off the principal axes so every term of M and h is exercised.
ARM = """<mujoco model="arm3">
  <compiler angle="radian"/>
  <default><joint armature="{arm}" damping="{damp}" frictionloss="{fric}"/></default>
  <worldbody>
    <body name="l1" pos="0 0 0.3">
      <joint name="j1" axis="0 0 1"/>
      <inertial pos="0.05 0.01 0.1" mass="3.0" fullinertia="0.05 0.04 0.03 0.002 0.001 0.003"/>
      <body name="l2" pos="0 0.05 0.2" quat="0.7071068 0.7071068 0 0">
        <joint name="j2" axis="0 0 1" armature="{arm2}"/>
        <inertial pos="0.2 0 0.02" mass="2.0" diaginertia="0.01 0.04 0.045"/>
        <body name="l3" pos="0.4 0 0">
          <joint name="j3" axis="0 0.6 0.8"/>
          <inertial pos="0.15 0.01 0" mass="1.0" diaginertia="0.004 0.01 0.012"/>
          <body name="finger" pos="0.3 0 0">
            <joint name="finger" type="slide" axis="1 0 0" range="0 0.04"/>
            <inertial pos="0 0 0" mass="0.05" diaginertia="1e-5 1e-5 1e-5"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  {extra}
</mujoco>
"""

LOCK = {"finger": 0.0}


def write_arm(tmp_path, name="arm.xml", *, arm=0.1, arm2=0.2, damp=0.5, fric=0.3, extra=""):
    """Write the test arm with these joint coefficients [kg m^2, N m s/rad, N m]."""
    path = tmp_path / name
    path.write_text(ARM.format(arm=arm, arm2=arm2, damp=damp, fric=fric, extra=extra))
    return path


@pytest.fixture
def arm_file(tmp_path):
    return write_arm(tmp_path)


def test_mjcf_arm_loads_its_joint_coefficients(arm_file):
    robot = load_robot(arm_file, lock=LOCK)
    assert isinstance(robot, MjcfArm)
    assert robot.joint_names == ["j1", "j2", "j3"]
    # Exact: the numbers written in the file, read back (no arithmetic on the way).
    assert_allclose(robot.model.armature, [0.1, 0.2, 0.1], rtol=0, atol=0)
    Fv, Fc = robot.joint_friction()
    assert_allclose(Fv, [0.5, 0.5, 0.5], rtol=0, atol=0)
    assert_allclose(Fc, [0.3, 0.3, 0.3], rtol=0, atol=0)
    assert robot.joint_sources == {"armature": "mjcf", "damping": "mjcf", "friction": "mjcf"}


def test_mjcf_arm_matches_mujoco(arm_file):
    mujoco = pytest.importorskip("mujoco", reason="MuJoCo not installed: "
                                 "pip install 'rrr-pin[mujoco]'")
    robot = arm_from_mjcf(arm_file)  # the file's gravity: MuJoCo's default, 9.81
    m = mujoco.MjModel.from_xml_path(str(arm_file))
    d = mujoco.MjData(m)
    rng = np.random.default_rng(44)
    for _ in range(5):
        q = rng.uniform(-1.0, 1.0, robot.nq)
        q[3] = rng.uniform(0.0, 0.04)
        qd = rng.uniform(-2.0, 2.0, robot.nq)
        d.qpos[:], d.qvel[:] = q, qd
        mujoco.mj_forward(m, d)
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        Mp, h = robot.terms(q, qd)
        # Two rigid-body algorithms on the same numbers: equal to round-off (1e-10 absolute on
        # entries of order 0.1-1 kg m^2 and 1-30 N m).
        assert_allclose(Mp, M, rtol=0, atol=1e-10)
        assert_allclose(h, d.qfrc_bias, rtol=0, atol=1e-10)


@pytest.mark.parametrize("extra, match", [
    ('<worldbody><body name="b"><freejoint name="float"/>'
     '<inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/></body></worldbody>', "free"),
    ('<tendon><fixed name="t"><joint joint="j1" coef="1"/><joint joint="j2" coef="1"/>'
     '</fixed></tendon>', "tendon 't'.*'j1'"),
    ('<equality><joint name="e" joint1="j2" joint2="j3"/></equality>', "equality joint 'e'"),
    ('<actuator><position name="servo" joint="j1" kp="100"/></actuator>', "'servo'.*position"),
    ('<actuator><motor name="m" joint="j2" gear="50"/></actuator>', "gear='50'"),
], ids=["free-joint", "tendon", "equality", "position-actuator", "gear"])
def test_mjcf_arm_refuses_what_it_cannot_honour(tmp_path, extra, match):
    path = write_arm(tmp_path, extra=extra)
    with pytest.raises(RobotModelError, match=match):
        load_robot(path, lock=LOCK)


def test_mjcf_arm_accepts_a_motor_and_couplings_of_locked_joints(tmp_path):
    extra = ('<actuator><motor name="m1" joint="j1"/><position name="grip" joint="finger"/>'
             '</actuator>')
    assert load_robot(write_arm(tmp_path, extra=extra), lock=LOCK).nq == 3


def test_closed_chain_is_not_an_arm(tmp_path):
    extra = '<equality><connect name="c" body1="l3" body2="world" anchor="0 0 0"/></equality>'
    with pytest.raises(RobotModelError, match="closed chain"):
        arm_from_mjcf(write_arm(tmp_path, extra=extra), lock=LOCK)


def test_mjcf_arm_negative_coefficient_refused(tmp_path):
    with pytest.raises(RobotModelError, match="negative joint damping"):
        load_robot(write_arm(tmp_path, damp=-0.1), lock=LOCK)


@pytest.fixture
def rigid_run(tmp_path):
    """A rigid arm (no armature, damping or friction), its FL law and a reference."""
    robot = load_robot(write_arm(tmp_path, arm=0, arm2=0, damp=0, fric=0), lock=LOCK)
    return robot, make_law("fl", robot), default_reference(robot, amp=0.4, freq=0.5)


def _rms(traj):
    return float(np.sqrt(np.mean((traj.q - traj.r) ** 2)))


def test_mjcf_arm_run_records_the_friction_it_applied(arm_file):
    robot = load_robot(arm_file, lock=LOCK)
    traj = simulate(robot, make_law("fl", robot), default_reference(robot, amp=0.3), 0.05,
                    rate=1000.0, engine="python")
    rec = traj.info["plant_friction"]
    assert rec["applied"] and rec["source"] == "mjcf"
    assert_allclose(traj.info["effects"]["viscous_Nms"], [0.5] * 3, rtol=0, atol=0)
    assert "MJCF" in traj.info["effects"]["friction_source"]
    # a friction the run names replaces the file's, and says so
    traj = simulate(robot, make_law("fl", robot), default_reference(robot, amp=0.3), 0.05,
                    rate=1000.0, engine="python", effects=PlantEffects(viscous=0.1))
    assert not traj.info["plant_friction"]["applied"]
    assert "replaced" in traj.info["plant_friction"]["note"]
    # a continuous-time law cannot have effects: not applied, and it says so
    with pytest.warns(UserWarning, match="not applied"):
        traj = simulate(robot, make_law("fl", robot), default_reference(robot, amp=0.3), 0.02,
                        engine="python")
    assert traj.info["plant_friction"]["applied"] is False


def test_mujoco_engine_refused_without_mujoco(rigid_run, monkeypatch):
    from rrr_pin.sim import mujoco_engine

    robot, law, ref = rigid_run
    monkeypatch.setattr(mujoco_engine, "_mujoco", lambda: None)
    with pytest.raises(ImportError, match=r"pip install 'rrr-pin\[mujoco\]'"):
        simulate(robot, law, ref, 0.01, rate=1000.0, engine="mujoco")


def test_mujoco_engine_equals_python_on_a_rigid_arm(rigid_run):
    pytest.importorskip("mujoco", reason="MuJoCo not installed: pip install 'rrr-pin[mujoco]'")
    robot, law, ref = rigid_run
    # The run: 4 s at 1 kHz (about 0.3 s per engine on this 3-joint arm).
    a = simulate(robot, law, ref, 4.0, rate=1000.0, engine="python")
    b = simulate(robot, law, ref, 4.0, rate=1000.0, engine="mujoco")
    assert b.info["engine"] == "mujoco" and b.info["mujoco"]["integrator"] == "RK4"
    # The same RK4 at the same 1 ms step on two implementations of the same dynamics: they
    # differ by round-off carried through the loop (the bound, 1e-9 rad).
    assert_allclose(b.q, a.q, rtol=0, atol=1e-9)


def test_mujoco_engine_with_armature_damping_and_effects(arm_file, paper):
    pytest.importorskip("mujoco", reason="MuJoCo not installed: pip install 'rrr-pin[mujoco]'")
    robot = load_robot(arm_file, lock=LOCK)
    law = make_law("hinf", robot, K=paper.K_reduced)  # the paper's 3-joint design, shared
    ref = default_reference(robot, amp=0.4, freq=0.5)
    fx = PlantEffects(delay=2e-3, actuator_bandwidth=300.0, torque_limit=60.0, noise_q=1e-4, seed=3)
    a = simulate(robot, law, ref, 0.5, rate=500.0, dt=1e-3, engine="python", effects=fx)
    b = simulate(robot, law, ref, 0.5, rate=500.0, dt=1e-3, engine="mujoco", effects=fx)
    assert b.info["plant_friction"]["applied"]
    # Armature, damping (MuJoCo's joint damping), the tanh Coulomb friction (a passive
    # callback), the actuator as a MuJoCo filter: all integrated by the same RK4, so the two
    # agree far inside the integrator's own error (RK4 at 1 ms on this arm: ~1e-8 rad).
    assert_allclose(b.q, a.q, rtol=0, atol=1e-8)
    assert abs(_rms(b) - _rms(a)) <= 1e-6 * _rms(a)


# --- a law's model and the plant (rrr_pin.model.joint_map) -----------------------------------

def test_match_joints_by_order_and_by_map(arm_file, rrr):
    from rrr_pin.model.joint_map import match_joints

    model, plant = rrr, load_robot(arm_file, lock=LOCK)
    by_order = match_joints(model, plant)
    assert by_order.by == "order"
    assert by_order.pairs == (("joint1", "j1"), ("joint2", "j2"), ("joint3", "j3"))
    by_map = match_joints(model, plant, {"joint1": "j1", "joint2": "j2", "joint3": "j3"})
    assert by_map.by == "map" and by_map.pairs == by_order.pairs


@pytest.mark.parametrize("mapping, match", [
    ({"joint1": "j2", "joint2": "j1", "joint3": "j3"}, "reorders"),
    ({"joint1": "j1", "joint2": "j2", "joint3": "nope"}, "unknown joint 'nope'"),
    ({"joint1": "j1", "joint2": "j2"}, "'joint3' is not mapped"),
], ids=["reorder", "unknown", "missing"])
def test_match_joints_refuses_a_bad_map(arm_file, rrr, mapping, match):
    from rrr_pin.model.joint_map import JointMapError, match_joints

    with pytest.raises(JointMapError, match=match):
        match_joints(rrr, load_robot(arm_file, lock=LOCK), mapping)


def test_match_joints_refuses_other_counts_and_kinds(arm_file, rrr, fivebar):
    from rrr_pin.model.joint_map import JointMapError, match_joints

    with pytest.raises(JointMapError, match="4 .*lock the extra joints"):
        match_joints(rrr, load_robot(arm_file))
    with pytest.raises(JointMapError, match="closed chain"):
        match_joints(fivebar, load_robot("rrr", lock={"joint3": 0.0}))


def test_mujoco_engine_writes_the_arm_when_a_joint_is_locked_away_from_zero(tmp_path):
    pytest.importorskip("mujoco", reason="MuJoCo not installed: pip install 'rrr-pin[mujoco]'")
    robot = load_robot(write_arm(tmp_path, arm=0, arm2=0, damp=0, fric=0),
                       lock={"finger": 0.02})
    law, ref = make_law("fl", robot), default_reference(robot, amp=0.4, freq=0.5)
    a = simulate(robot, law, ref, 0.2, rate=1000.0, engine="python")
    b = simulate(robot, law, ref, 0.2, rate=1000.0, engine="mujoco")
    assert b.info["mujoco"]["model"].startswith("written from the Pinocchio model")
    # The same RK4 on the same arm, its body written from Pinocchio's reduced model: round-off.
    assert_allclose(b.q, a.q, rtol=0, atol=1e-9)


def test_cli_refuses_a_joint_map_that_reorders(arm_file, tmp_path, capsys):
    from rrr_pin import cli

    argv = ["stress", "--robot", "rrr", "--plant", str(arm_file), "--plant-lock", "finger=0",
            "--joint-map", "joint1=j2,joint2=j1,joint3=j3", "--effect", "delay",
            "--out", str(tmp_path / "out"), "--no-progress"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "reorders the joints" in err and "Traceback" not in err
