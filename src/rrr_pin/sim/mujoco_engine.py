r"""The MuJoCo engine: the plant stepped by MuJoCo, the project's laws at their rate.

An independent check of the Python engine: MuJoCo (``pip install 'rrr-pin[mujoco]'``)
integrates the arm from its own compiled model, with its own rigid-body algorithms, while the
law, the reference and the plant effects are the run's, through the same steps the Python
engine takes (:class:`rrr_pin.control.effects.Resolved`: ``measure``, ``saturate``,
``applied``). Registered as ``"mujoco"`` in :mod:`rrr_pin.sim.engines`; never chosen by
``"auto"``.

The model MuJoCo steps (:func:`mujoco_model`):

* an arm read from MJCF (:class:`rrr_pin.model.dynamics.MjcfArm`): its own file, compiled by
  MuJoCo, with its locked joints removed (each locked at its reference position 0; another
  lock value is written as below) and everything that is not the arm's rigid body taken out:
  geoms, meshes, actuators, tendons, equalities, sensors, keyframes; checked against the plant
  as Pinocchio reads it (``M`` and ``h`` to :data:`FILE_RTOL`), else written as below, the
  reason recorded (``Trajectory.info["mujoco"]["model"]``);
* any other serial arm (a URDF, example-robot-data, the paper's RRR): an MJCF written from the
  arm's Pinocchio model, one body per joint with its placement, mass, centre of mass and
  inertia, and the joint's axis and armature.

Then contacts, joint limits, equality constraints, MuJoCo's own friction loss and fluid forces
are switched off (the engines' divergence test watches the limits), gravity is the plant's,
armature is the plant's (``model.armature``), and the integrator is MuJoCo's classical RK4
with ``timestep`` the run's plant sub-step ``h``: the same scheme as the Python engine, so the
two are pinned to each other (``tests/test_mujoco_engine.py``).

The plant effects, as the Python engine applies them:

* sensor noise and quantization, saturation and the transport delay: Python, per control
  period and per sub-step, with the ``Resolved`` steps (the delayed command is the actuator's
  ``ctrl`` over each sub-step);
* the first-order actuator ``wa/(s + wa)``: a MuJoCo ``filter`` actuator (``act' = (ctrl -
  act) / tau``, ``tau = 1/wa``, gain 1), its state integrated by MuJoCo's RK4 with the arm;
  without it a ``motor`` of gear 1;
* viscous friction ``Fv qd``: MuJoCo's joint ``damping`` (a passive force at every RK4
  stage); smooth Coulomb friction ``Fc tanh(qd / v_eps)``: a passive-force callback
  (``mjcb_passive``) at every stage. MuJoCo's own ``frictionloss`` (a dry-friction
  constraint) is not used, so that both engines model the same friction;
* flexible joints: refused by name (no MuJoCo counterpart here).

Continuous-time laws (evaluated at every RK4 stage) and closed chains are refused by name.
"""

from __future__ import annotations

import numpy as np

from ..control.laws import check_step_output
from .trajectory import (
    Run,
    Trajectory,
    diverged_joint,
    divergence,
    first_bad_torque,
    law_divergence,
    make_trajectory,
)

__all__ = ["why_not", "run", "mujoco_model", "INSTALL", "FILE_RTOL", "MujocoMissing"]

#: How to install the optional dependency (in every refusal that lacks it).
INSTALL = "pip install 'rrr-pin[mujoco]'"


#: Smallest principal moment of a written body, relative to its largest (MuJoCo refuses 0).
_MOMENT_FLOOR = 1e-12


class MujocoMissing(ImportError, ValueError):
    """``engine="mujoco"`` without MuJoCo installed (named, with :data:`INSTALL`)."""


def _mujoco():
    try:
        import mujoco
    except ImportError:
        return None
    return mujoco


def why_not(run: Run, form) -> str | Exception | None:
    """Return None when MuJoCo can run ``run`` exactly, else why not (or the exception to raise).

    Refused: MuJoCo not installed (an exception naming the install line), a closed chain, a
    continuous-time law, flexible joints.
    """
    if _mujoco() is None:
        return MujocoMissing(f"engine 'mujoco' needs MuJoCo, which is not installed: {INSTALL}")
    plant = run.plant
    if plant.loop_closures or plant.actuated_index is not None:
        return (f"the MuJoCo engine steps serial arms only, and {plant.describe_kind()} "
                f"{plant.name!r} closes kinematic loops")
    if not run.sampled:
        return (f"the MuJoCo engine holds the torque over each step, and law "
                f"{run.law.name!r} is continuous-time: give rate= (a sampled law)")
    fx = run.effects
    if fx is not None and fx.flex is not None:
        return "the MuJoCo engine does not model flexible joints (stiffness)"
    return None


def _axis(joint) -> tuple[str, np.ndarray]:
    """Return ``("hinge" | "slide", axis)`` of a Pinocchio revolute or prismatic joint."""
    kind = joint.shortname()
    jtype = "hinge" if kind.startswith("JointModelR") else "slide"
    if kind.endswith("Unaligned"):
        return jtype, np.asarray(joint.extract().axis, dtype=float)
    return jtype, np.eye(3)["XYZ".index(kind[-1])]


def _written(mujoco, plant):
    """Return an MjSpec of ``plant``'s Pinocchio model: one body per joint (module docstring)."""
    import pinocchio as pin

    model = plant.model
    spec = mujoco.MjSpec()
    bodies = {0: spec.worldbody}
    for i in range(1, model.njoints):
        placement, inertia = model.jointPlacements[i], model.inertias[i]
        body = bodies[model.parents[i]].add_body(
            name=f"body_{model.names[i]}", pos=placement.translation,
            quat=pin.Quaternion(placement.rotation).coeffs()[[3, 0, 1, 2]])
        body.mass = inertia.mass
        body.ipos = inertia.lever
        # Principal axes: MuJoCo refuses a zero principal moment (a thin rod, a point mass);
        # such a moment is raised to _MOMENT_FLOOR times the largest (an M changed by 1e-12
        # relative at most).
        moments, axes = np.linalg.eigh(inertia.inertia)
        if np.linalg.det(axes) < 0:
            axes[:, 0] = -axes[:, 0]
        body.inertia = np.maximum(moments, _MOMENT_FLOOR * max(moments.max(), 1e-300))
        body.iquat = pin.Quaternion(axes).coeffs()[[3, 0, 1, 2]]
        body.explicitinertial = True
        jtype, axis = _axis(model.joints[i])
        body.add_joint(name=model.names[i], axis=axis,
                       type=getattr(mujoco.mjtJoint, f"mjJNT_{jtype.upper()}"))
        bodies[i] = body
    return spec


def _from_file(mujoco, plant):
    """Return an MjSpec of an MJCF arm's own file, reduced to its rigid bodies and moving joints.

    Its locked joints (locked at 0, their reference position) are removed.
    """
    spec = mujoco.MjSpec.from_string(plant.mjcf)
    for kind in ("actuators", "tendons", "equalities", "sensors", "keys", "pairs", "excludes",
                 "geoms", "sites", "cameras", "lights", "meshes", "textures", "materials",
                 "hfields", "skins"):
        for element in list(getattr(spec, kind)):
            spec.delete(element)
    for joint in list(spec.joints):
        if joint.name in plant.locked:
            spec.delete(joint)
    return spec


def mujoco_model(plant, h: float, *, viscous=None, bandwidth: float = 0.0) -> tuple:
    """Compile the MuJoCo model of a serial arm for a run with plant sub-step ``h`` [s].

    An MJCF arm is compiled from its own file, then checked against the plant as Pinocchio
    reads it: ``M`` and the bias torques at two seeded states must agree to
    :data:`FILE_RTOL` (relative). A file MuJoCo reads otherwise (e.g. inertias it computes from
    geoms, which are removed) or cannot compile alone (an ``<include>``) is replaced by the
    model written from the Pinocchio model, and the reason is returned.

    Parameters
    ----------
    plant : Robot
        A serial arm (module docstring).
    h : float
        MuJoCo's timestep [s] (the run's RK4 sub-step).
    viscous : ndarray, shape (nq,), optional
        Joint damping [N m s/rad] (the run's viscous friction); default 0.
    bandwidth : float, default 0
        First-order actuator bandwidth ``wa`` [rad/s]; 0: ideal (a motor of gear 1).

    Returns
    -------
    model : mujoco.MjModel
        ``nv == plant.nq``, its dofs in the plant's joint order, one actuator per joint.
    source : str
        Which model: ``"the MJCF file"`` or ``"written from the Pinocchio model"`` (with why).

    Raises
    ------
    ValueError
        MuJoCo's compiler refused the written model, or its joints are not the plant's.
    """
    mujoco = _mujoco()
    if mujoco is None:
        raise MujocoMissing(f"the MuJoCo engine needs MuJoCo: {INSTALL}")
    why = None
    if plant.source_text()[1] == ".xml":
        if any(v != 0.0 for v in plant.locked.values()):
            why = "a joint is locked away from 0"
        else:
            try:
                m = _compile(mujoco, plant, _from_file(mujoco, plant), h, viscous, bandwidth)
                gap = _gap(mujoco, plant, m)
                if gap <= FILE_RTOL:
                    return m, "the MJCF file"
                why = (f"MuJoCo reads the file otherwise than Pinocchio (M and h differ by "
                       f"{gap:.2g} relative)")
            except ValueError as exc:
                why = f"MuJoCo could not compile the file alone ({exc})"
    m = _compile(mujoco, plant, _written(mujoco, plant), h, viscous, bandwidth)
    return m, "written from the Pinocchio model" + (f": {why}" if why else "")


#: Largest relative difference of ``M`` and the bias torques between an MJCF file as MuJoCo
#: compiles it and the plant as Pinocchio reads it, for the engine to step the file itself.
FILE_RTOL = 1e-9


def _gap(mujoco, plant, m) -> float:
    """Return the largest relative difference of (M, h) of MuJoCo's ``m`` and the plant's."""
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(2):
        q = np.clip(rng.uniform(-1.0, 1.0, plant.nq), plant.lower, plant.upper)
        qd = rng.uniform(-1.0, 1.0, plant.nq)
        d.qpos[:], d.qvel[:] = q, qd
        mujoco.mj_forward(m, d)
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        Mp, hp = plant.terms(q, qd)
        scale = 1.0 + max(np.abs(Mp).max(), np.abs(hp).max())
        worst = max(worst, np.abs(M - Mp).max() / scale,
                    np.abs(d.qfrc_bias - hp).max() / scale)
    return float(worst)


def _compile(mujoco, plant, spec, h, viscous, bandwidth):
    """Set the run's options, joints and actuators on ``spec`` and compile it."""
    names = plant.joint_names
    opt = spec.option
    opt.timestep = h
    opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    opt.gravity = [0.0, 0.0, -plant.gravity]
    opt.density = opt.viscosity = 0.0
    opt.wind = [0.0, 0.0, 0.0]
    bits = mujoco.mjtDisableBit
    opt.disableflags |= (bits.mjDSBL_CONTACT | bits.mjDSBL_LIMIT | bits.mjDSBL_EQUALITY
                         | bits.mjDSBL_FRICTIONLOSS | bits.mjDSBL_SPRING)
    damping = np.zeros(plant.nq) if viscous is None else np.asarray(viscous, dtype=float)
    joints = {j.name: j for j in spec.joints}
    missing = [n for n in names if n not in joints]
    if missing:
        raise ValueError(f"MuJoCo's model of {plant.name!r} has no joint {missing[0]!r}")
    for j, name in enumerate(names):
        joint = joints[name]
        joint.armature = float(plant.model.armature[j])
        joint.damping = [float(damping[j]), 0.0, 0.0]  # MuJoCo >= 4: a polynomial
        joint.stiffness = [0.0, 0.0, 0.0]
        joint.frictionloss = 0.0
        joint.limited = mujoco.mjtLimited.mjLIMITED_FALSE
        act = spec.add_actuator(name=f"tau_{name}", target=name,
                                trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.gear = [1.0, 0, 0, 0, 0, 0]
        act.gainprm = [1.0] + [0.0] * 9
        act.biastype = mujoco.mjtBias.mjBIAS_NONE
        act.ctrllimited = act.forcelimited = mujoco.mjtLimited.mjLIMITED_FALSE
        if bandwidth:
            act.dyntype = mujoco.mjtDyn.mjDYN_FILTER
            act.dynprm = [1.0 / bandwidth] + [0.0] * 9
    try:
        m = spec.compile()
    except ValueError as exc:
        raise ValueError(f"MuJoCo could not compile {plant.name!r}: {exc}") from None
    got = [m.joint(i).name for i in range(m.njnt)]
    if got != list(names) or m.nv != plant.nq:
        raise ValueError(f"MuJoCo's model of {plant.name!r} has joints {got}, the plant "
                         f"{list(names)}")
    return m


def run(run: Run, form=None) -> Trajectory:
    """Run a validated sampled run on MuJoCo (:func:`why_not` is None); its trajectory."""
    mujoco = _mujoco()
    plant, law, fx = run.plant, run.law, run.effects
    wa = fx.wa if fx is not None else 0.0
    m, source = mujoco_model(plant, run.h, viscous=None if fx is None else fx.Fv,
                             bandwidth=wa)
    d = mujoco.MjData(m)
    t, R, RD, RDD = run.t, run.R, run.RD, run.RDD
    N, S, n = len(t) - 1, run.substeps, plant.nq
    Q = np.empty((N + 1, n))
    QD = np.empty_like(Q)
    TAU = np.empty_like(Q)
    U = np.empty((N, n))
    q, qd = run.q0, run.qd0
    d.qpos[:], d.qvel[:] = q, qd
    z = run.x0
    Q[0], QD[0] = q, qd
    lower, upper = run.lower, run.upper
    coulomb = fx is not None and fx.Fc is not None and np.any(fx.Fc > 0)
    previous = mujoco.get_mjcb_passive()
    if coulomb:
        Fc, veps = fx.Fc, fx.veps

        def passive(m_, d_):
            d_.qfrc_passive[:] -= Fc * np.tanh(d_.qvel / veps)

        mujoco.set_mjcb_passive(passive)
    try:
        mujoco.mj_forward(m, d)
        for k in range(N):
            qm, qdm = (q, qd) if fx is None else fx.measure(k, q, qd)
            if k:
                tau, z = law.step(t[k], qm, qdm, R[k], RD[k], RDD[k], z)
                if not np.isfinite(tau).all():
                    hit = first_bad_torque(np.asarray([tau]))
                    raise law_divergence(plant, law.name, float(t[k]), hit[1])
            else:
                tau, z = check_step_output(law, law.step(t[0], qm, qdm, R[0], RD[0], RDD[0],
                                                         z), t[0])
            if fx is not None:
                tau = fx.saturate(tau)
            U[k] = TAU[k] = tau
            if k == 0 and wa:
                d.act[:] = U[0]  # at rest on the first command, as the Python engine starts
            for s in range(S):
                d.ctrl[:] = U[k] if fx is None else fx.applied(U, k, s, S)
                mujoco.mj_step(m, d)
            q, qd = d.qpos.copy(), d.qvel.copy()
            Q[k + 1], QD[k + 1] = q, qd
            bad = diverged_joint(q, qd, lower, upper)
            if bad is not None:
                raise divergence(plant, float(t[k + 1]), q, qd, *bad)
    finally:
        if coulomb:
            mujoco.set_mjcb_passive(previous)
    TAU[N] = TAU[N - 1]
    traj = make_trajectory(run, Q, QD, TAU)
    traj.info["mujoco"] = {"version": mujoco.__version__, "integrator": "RK4",
                           "timestep_s": run.h,
                           "model": source}
    return traj
