"""From parsed options to the typed inputs of the layers below: plant, settings, reference, laws.

Each builder validates its options once, at this edge, with messages that spell them as the
command line does (``--move-time``). What the options mean is the layers' own: the plant's
capabilities, the reference kinds (:class:`rrr_pin.control.specs.ReferenceSpec`), the
torque-limit rule (:func:`rrr_pin.control.effects.torque_limit_spec`).
"""

from __future__ import annotations

from .common import as_options, floats, not_a_folder, option, parse_lock

__all__ = ["load_plant", "load_model_and_plant", "plant_friction_record", "parse_armature",
           "reference_from_args", "settings_from_args", "tolerances_from_args",
           "friction_spec", "compensation_from_args",
           "laws_from_args", "tuned_from_args", "design_record", "torque_limit_from_args",
           "with_torque_limit", "rejections_line",
           "frozen_configuration"]


def load_plant(args, *, lock: bool = True, robot=None, armature: bool = True):
    """Return the plant of ``--robot`` (and ``--lock``, ``--armature``): any kind load_robot reads.

    ``robot`` stands for ``args.robot`` where a command's ``--robot`` has another default;
    ``armature=False`` where the command's ``--armature`` is not the plant's (``identify``'s
    switch of the armature column).
    """
    from ..model.dynamics import load_robot

    robot = args.robot if robot is None else robot
    not_a_folder(robot=robot)
    with as_options():
        return load_robot(robot, lock=parse_lock(args.lock) if lock else None,
                          armature=parse_armature(getattr(args, "armature", None))
                          if armature else None)


def parse_armature(text: str | None):
    """``--armature``'s ``V`` or ``V1/V2/...`` as numbers (None without it).

    Their count and range are checked against the arm's joints where the arm is loaded
    (:meth:`rrr_pin.model.dynamics.Robot.with_joint_dynamics`).
    """
    if text is None:
        return None
    try:
        values = [float(v) for v in str(text).split("/")]
    except ValueError:
        raise ValueError(f"--armature expects a number [kg m^2] or one per joint separated "
                         f"by '/', got {text!r}") from None
    return values[0] if len(values) == 1 else values


def load_model_and_plant(args):
    """Return ``(model, plant, match)``: the laws' model (``--robot``), the simulated plant.

    Without ``--plant`` the plant is the model and ``match`` is None; with it, ``--plant`` and
    ``--plant-lock`` load the plant and :func:`rrr_pin.model.joint_map.match_joints` pairs the
    joints (``--joint-map``), refusing by name what cannot be paired.
    """
    from ..model.dynamics import load_robot
    from ..model.joint_map import match_joints, parse_joint_map

    model = load_plant(args)
    if args.plant is None:
        if args.joint_map is not None or args.plant_lock:
            raise ValueError("--joint-map and --plant-lock pair and lock the joints of "
                             "--plant: give --plant too")
        return model, model, None
    not_a_folder(plant=args.plant)
    plant = load_robot(args.plant, lock=parse_lock(args.plant_lock, "--plant-lock")
                       if args.plant_lock else None)
    mapping = None if args.joint_map is None else parse_joint_map(args.joint_map)
    return model, plant, match_joints(model, plant, mapping)


def plant_friction_record(plant, run) -> dict | None:
    """Return what runs on ``plant`` with the settings ``run`` apply of its own friction.

    The record of :func:`rrr_pin.control.effects.with_plant_friction` (an MJCF arm's damping
    and friction loss: ``applied``, ``source``, the values and a ``note``), which the command
    prints and writes; None for a plant without friction of its own.
    """
    from ..control.effects import with_plant_friction

    effects = run.effects if run.effects is not None and run.effects.active else None
    return with_plant_friction(plant, effects, run.rate is not None)[1]


def reference_from_args(args, plant):
    """Return the reference of the reference options (``--reference`` and its options)."""
    from ..control.specs import ReferenceSpec

    def values(text, name):
        v = floats(text, name)
        return None if v is None else tuple(v)

    not_a_folder(csv=args.csv)
    spec = ReferenceSpec(kind=args.reference, amp=args.amp, freq=args.freq,
                         home=values(args.home, "--home"), to=values(args.to, "--to"),
                         move_time=args.move_time, csv=args.csv, frame=args.frame,
                         end=values(args.end, "--end"), radius=args.radius,
                         normal=values(args.normal, "--normal"))
    return spec.build(plant, args.duration, label=option)


def settings_from_args(args, n: int):
    """Return the :class:`~rrr_pin.campaign.runner.RunSettings` of the run options."""
    from ..campaign.runner import RunSettings
    from ..control.effects import PlantEffects
    from ..validation import check_count, check_positive, check_vector

    if args.jobs is not None:
        check_count("--jobs", args.jobs, 1)
    check_count("--seed", args.seed)
    for name in ("delay", "actuator_bandwidth"):
        if getattr(args, name) is not None:
            check_positive(option(name), getattr(args, name), allow_zero=name == "delay")
    effects = None
    friction = friction_spec(getattr(args, "friction", None), n)
    others = effect_fields(args)
    if args.delay or args.actuator_bandwidth is not None or friction or others:
        if args.rate is None:
            given = ["--delay"] * bool(args.delay) + ["--actuator-bandwidth"] * (
                args.actuator_bandwidth is not None) + ["--friction"] * bool(friction) + [
                option(k) for k in others]
            raise ValueError(f"{', '.join(given)}: plant effects act on sampled controllers: "
                             f"give --rate HZ too")
        with as_options():
            effects = PlantEffects(delay=args.delay or 0.0,
                                   actuator_bandwidth=args.actuator_bandwidth,
                                   **friction, **others)
    q0, qd0 = (None if text is None else tuple(check_vector(name, floats(text, name), n))
               for text, name in ((args.q0, "--q0"), (args.qd0, "--qd0")))
    with as_options():
        return RunSettings(duration=args.duration, dt=args.dt, rate=args.rate,
                           engine=args.engine, q0=q0, qd0=qd0, effects=effects,
                           force=args.force)


#: The options of :func:`rrr_pin.cli.options.add_effect_arguments` read here, by field:
#: per joint (``/``-separated numbers) or a count.
_PER_JOINT = ("noise_q", "noise_qd", "stiffness", "motor_inertia", "transmission_damping")


def effect_fields(args) -> dict:
    """Return the :class:`~rrr_pin.control.effects.PlantEffects` fields of the options given.

    ``--noise-q 1e-4/2e-4`` -> ``{"noise_q": (1e-4, 2e-4)}``; ``--noise-seed`` -> ``seed``.
    The torque limit is not here (:func:`torque_limit_from_args`: it needs the reference).
    """
    out = {}
    for key in _PER_JOINT:
        text = getattr(args, key, None)
        if text is None:
            continue
        try:
            values = tuple(float(v) for v in str(text).split("/"))
        except ValueError:
            raise ValueError(f"{option(key)} expects a number or one per joint separated by "
                             f"'/', got {text!r}") from None
        out[key] = values[0] if len(values) == 1 else values
    if getattr(args, "encoder_counts", None) is not None:
        out["encoder_counts"] = args.encoder_counts
    if getattr(args, "noise_seed", None) is not None:
        out["seed"] = args.noise_seed
    if ("motor_inertia" in out or "transmission_damping" in out) and "stiffness" not in out:
        raise ValueError("--motor-inertia and --transmission-damping shape a flexible "
                         "transmission: give --stiffness K too")
    if "seed" in out and not ("noise_q" in out or "noise_qd" in out):
        raise ValueError("--noise-seed seeds the sensor noise: give --noise-q or --noise-qd "
                         "too")
    return out


def friction_spec(text, n: int) -> dict:
    """``--friction``'s :class:`~rrr_pin.control.effects.PlantEffects` fields ({} without it).

    ``urdf`` -> ``viscous="urdf", coulomb="urdf"``; ``viscous=V,coulomb=C[,smooth=S]`` (each
    key at most once, ``V`` and ``C`` one number or ``n`` separated by ``/``; a key left out
    is 0) -> ``viscous, coulomb, coulomb_velocity``. Signs and counts are checked here, by name.
    """
    if text is None:
        return {}
    text = text.strip()
    items = [s.strip() for s in text.split(",") if s.strip()]
    keys = {"viscous": "viscous", "coulomb": "coulomb", "smooth": "coulomb_velocity"}
    out = {}
    if items and items[0] == "urdf":
        out = {"viscous": "urdf", "coulomb": "urdf"}
        items = items[1:]
        if any(not s.startswith("smooth=") for s in items):
            raise ValueError(f"--friction urdf takes smooth=S [rad/s] only, got {text!r}")
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or key not in keys or keys[key] in out:
            raise ValueError(f"--friction expects 'urdf' or viscous=V,coulomb=C[,smooth=S] "
                             f"(each key once; V [N m s/rad], C [N m], S [rad/s]), got "
                             f"{text!r}")
        try:
            vals = [float(v) for v in value.split("/")]
        except ValueError:
            raise ValueError(f"--friction {key}={value!r}: not a number (one, or one per "
                             f"joint separated by '/')") from None
        if key == "smooth":
            if len(vals) != 1 or not vals[0] > 0.0:
                raise ValueError(f"--friction smooth={value}: expected one speed > 0 [rad/s]")
            out[keys[key]] = vals[0]
            continue
        if len(vals) not in (1, n):
            raise ValueError(f"--friction {key}={value}: {len(vals)} values; give one, or "
                             f"one per joint ({n})")
        if not all(v >= 0.0 and v != float("inf") for v in vals):
            raise ValueError(f"--friction {key}={value}: expected finite values >= 0 "
                             f"(friction opposes the motion)")
        out[keys[key]] = vals[0] if len(vals) == 1 else tuple(vals)
    if "viscous" not in out and "coulomb" not in out:
        raise ValueError(f"--friction {text!r}: give viscous=V and/or coulomb=C, or 'urdf'")
    return out


def compensation_from_args(args, nominal):
    """``--compensate-friction``'s :class:`~rrr_pin.control.friction.JointFriction`, or None.

    The friction of the laws' nominal model: ``--friction``'s values, or (``--friction urdf``
    or no ``--friction``) the nominal URDF's ``<dynamics>``; all zero is refused by name.
    """
    if not getattr(args, "compensate_friction", False):
        return None
    from ..control.friction import DEFAULT_COULOMB_VELOCITY, JointFriction
    from ..model.plant import JOINT_FRICTION

    spec = friction_spec(getattr(args, "friction", None), nominal.nq)
    veps = spec.get("coulomb_velocity", DEFAULT_COULOMB_VELOCITY)
    if spec and spec.get("viscous") != "urdf":
        f = JointFriction(spec.get("viscous", 0.0), spec.get("coulomb", 0.0), veps,
                          source="--friction").check_joints(nominal.nq)
    else:
        if not nominal.has(JOINT_FRICTION):
            raise ValueError(f"--compensate-friction: the nominal {nominal.name!r} has no "
                             f"joint friction in its description; give --friction "
                             f"viscous=V,coulomb=C")
        fv, fc = nominal.joint_friction()
        with as_options():
            f = JointFriction(fv, fc, veps, source=f"URDF <dynamics> of {nominal.name!r}")
    if not f.active:
        raise ValueError(f"--compensate-friction: the friction of {f.source} is zero on every "
                         f"joint; nothing to compensate (identify with --friction, or give "
                         f"--friction viscous=V,coulomb=C)")
    return f


def tolerances_from_args(args, plant, *, vertices: bool = False):
    """Return the paper's tolerances, or ``--uncertainty``'s identified distribution.

    The tolerances widened by ``--tolerance-armature``, ``--tolerance-damping`` and
    ``--tolerance-friction`` (relative to the nominal's values); ``vertices``: the corners of
    that box (:class:`~rrr_pin.model.uncertainty.ToleranceVertices`).
    """
    from ..model.uncertainty import JOINT_TOLERANCES, Tolerances, ToleranceVertices

    joint = {k: getattr(args, f"tolerance_{k}", 0.0) or 0.0 for k in JOINT_TOLERANCES}
    if args.uncertainty is None:
        if args.confidence is not None:
            raise ValueError(f"--confidence {args.confidence:g} applies to plants drawn from "
                             f"an identification: give --uncertainty IDENTIFICATION.json too "
                             f"(the paper's tolerances have no confidence region)")
        if getattr(args, "uncertainty_draws", None) is not None:
            raise ValueError(f"--uncertainty-draws {args.uncertainty_draws} applies to plants "
                             f"drawn from an identification: give --uncertainty "
                             f"IDENTIFICATION.json too")
        try:
            return (ToleranceVertices if vertices else Tolerances)(**joint)
        except ValueError as exc:  # "armature tolerance must be ..." -> the option's name
            key = str(exc).split(" ", 1)[0]
            raise ValueError(f"--tolerance-{key}: {exc}") from None
    if any(joint.values()):
        raise ValueError("--tolerance-armature, --tolerance-damping and --tolerance-friction "
                         "widen the tolerance box; an identification (--uncertainty) draws "
                         "its own plants: give one or the other")
    from ..model.identification import IdentifiedUncertainty

    not_a_folder(uncertainty=args.uncertainty)
    with as_options():
        tol = IdentifiedUncertainty(args.uncertainty, confidence=0.95 if args.confidence is None
                                    else args.confidence,
                                    draws=getattr(args, "uncertainty_draws", None) or "reject")
    tol.check_robot(plant)
    return tol


def laws_from_args(args, plant, K=None, torque_limit=None, extra=()):
    """Return the ``--controllers`` (plus ``extra`` names) on ``plant``, and the baseline.

    With ``--compensate-friction``, the laws compensate :func:`compensation_from_args`.
    """
    from ..campaign.runner import make_laws

    names = [s.strip() for s in args.controllers.split(",")]
    names += [name for name in extra if name not in names]
    friction = compensation_from_args(args, plant)
    tuned = tuned_from_args(args, plant, names)
    with as_options():
        laws = make_laws([n for n in names if n != "tuned"], plant, K=K,
                         torque_limit=torque_limit, friction=friction) \
            if set(names) - {"tuned"} else []
    if tuned is not None:
        laws.insert(names.index("tuned"), tuned)
    baseline = args.baseline or laws[0].name
    if baseline not in [law.name for law in laws]:
        raise ValueError(f"--baseline {baseline!r} is not among --controllers "
                         f"({args.controllers})")
    return laws, baseline


def tuned_from_args(args, plant, names):
    """Return the law ``tuned`` of ``--design DIR/design.json`` when ``--controllers`` names it.

    Raises
    ------
    ValueError
        ``tuned`` without ``--design``, or a design tuned for another arm.
    """
    path = getattr(args, "design", None)
    if "tuned" not in names:
        return None
    if path is None:
        raise ValueError("--controllers tuned needs --design DIR/design.json (write one with "
                         "rrr-pin design --robot ARM --require NAME=VALUE --out DIR)")
    from ..campaign.design_file import load_design, tuned_law

    not_a_folder(design=path)
    return tuned_law(load_design(path), plant)


def design_record(args) -> dict | None:
    """Return what results record of ``--design``: its path, law and requirement table (or None)."""
    path = getattr(args, "design", None)
    if path is None:
        return None
    from ..campaign.design_file import load_design

    d = load_design(path)
    return {"path": str(path), "robot": d.get("robot"), "lam_rad_s": d.get("lam_rad_s"),
            "K": d.get("K"), "rate_hz": d.get("rate_hz"), "status": d.get("status"),
            "structure": d.get("structure"), "requirements": d.get("requirements")}


def warn_effect_margins(args, laws, rate, effects=None) -> list[str]:
    """Print, once each, the laws whose delay or actuator margin is below the effects.

    The effects requested (``effects``, a :class:`~rrr_pin.control.effects.PlantEffects`)
    and, for ``tuned``, those recorded in ``--design`` (its ``effects``), by
    :func:`rrr_pin.campaign.effect_margins.check_effect_margins`.
    """
    import sys
    import warnings

    from ..campaign.effect_margins import check_effect_margins, design_effects_record

    if rate is None:
        return []
    out = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if effects is not None and (effects.delay or effects.actuator_bandwidth):
            check_effect_margins(laws, rate, effects.delay, effects.actuator_bandwidth)
        path = getattr(args, "design", None)
        tuned = [law for law in laws if law.name == "tuned"]
        if path is not None and tuned:
            from ..campaign.design_file import load_design

            fx = design_effects_record(load_design(path))
            check_effect_margins(tuned, rate, fx.get("delay", 0.0), fx.get("actuator"),
                                 source="recorded in its design")
    for w in caught:
        text = str(w.message)
        if text not in out:
            out.append(text)
            print(f"warning: {text}", file=sys.stderr)
    return out


def torque_limit_from_args(args, plant, reference, settings):
    """Return ``--torque-limit``'s limits [N m] and their rule, or ``(None, {})`` without it."""
    if args.torque_limit is None:
        return None, {}
    from ..control.effects import torque_limit_spec

    if settings.rate is None:
        raise ValueError("--torque-limit acts on sampled controllers (the plant clips the "
                         "torque each control period): give --rate HZ too, e.g. --rate 1000")
    return torque_limit_spec(plant, args.torque_limit, reference, settings.rate,
                             settings.duration, name="--torque-limit")


def with_torque_limit(settings, limit):
    """Return ``settings`` whose plant effects clip the torque at ``limit`` [N m]."""
    import dataclasses

    from ..control.effects import PlantEffects

    effects = dataclasses.replace(settings.effects or PlantEffects(),
                                  torque_limit=tuple(limit.tolist()))
    return dataclasses.replace(settings, effects=effects)


def rejections_line(entries) -> str | None:
    """How many draws of an identified distribution were rejected, or None (tolerances)."""
    drawn = [e["parameters"]["identified"]["rejected"] for e in entries
             if "identified" in (e.get("parameters") or {})]
    if not drawn:
        return None
    outside = sum(d["outside_confidence"] for d in drawn)
    inconsistent = sum(d["inconsistent"] for d in drawn)
    folded = sum(d.get("friction_folded", 0) for d in drawn)
    said = (f"; {folded} drawn friction (or armature) coefficients below 0 folded back to "
            f"|x|" if any("friction_folded" in d for d in drawn) else "")
    if any("projected" in d for d in drawn):  # --uncertainty-draws project: moved, not redrawn
        moved = [d["projected_mahalanobis"] for d in drawn if d["projected"]]
        return (f"identified uncertainty: {len(drawn)} plants drawn; {outside} redrawn outside "
                f"the confidence region; {len(moved)} moved to the nearest physically "
                f"consistent arm" + (f" (by {min(moved):.3g} to {max(moved):.3g} standard "
                                     f"deviations)" if moved else "") + said)
    return (f"identified uncertainty: {len(drawn)} plants drawn; rejected and redrawn: "
            f"{outside} outside the confidence region, {inconsistent} with no physically "
            f"consistent arm" + said)


def frozen_configuration(args, plant):
    """Return ``--home`` checked, or the plant's neutral configuration inside its limits."""
    import numpy as np

    from ..validation import check_vector

    home = floats(args.home, "--home")
    if home is None:
        return np.clip(plant.neutral(), plant.lower, plant.upper)
    home = check_vector("--home", home, plant.nq)
    lower, upper = np.asarray(plant.lower), np.asarray(plant.upper)
    out = np.flatnonzero((home < lower) | (home > upper))
    if out.size:
        j = int(out[0])
        raise ValueError(f"--home {args.home}: {plant.joint_names[j]} = {home[j]:g} is outside "
                         f"its joint limits [{lower[j]:.4g}, {upper[j]:.4g}] [rad or m]")
    return home
