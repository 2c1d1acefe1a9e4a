"""The options several commands share, declared once (their help names no plant kind).

Nothing here imports a numerical library: ``rrr-pin --help`` stays fast. The engine choices
come from the engine registry (:data:`rrr_pin.sim.engines.ENGINE_CHOICES`), the controllers
and reference kinds from :mod:`rrr_pin.control.catalog`.
"""

from __future__ import annotations

__all__ = ["add_design_argument", "add_overwrite", "add_plant_arguments", "add_law_arguments",
           "add_effect_arguments",
           "add_force_argument", "add_armature_argument", "add_joint_tolerance_arguments",
           "add_reference_arguments"]

_PLANT_HELP = ("plant: 'rrr' (the paper's arm, default), an example-robot-data arm (ur5, ur3, "
               "ur10, panda, kinova, ...), a URDF path, a parallel mechanism by its registered "
               "name (rrr_pin.model.mechanisms.MECHANISMS) or an MJCF path (a serial arm with "
               "its joints' armature, damping and friction loss, or a closed chain with "
               "<equality><connect>)")


def add_overwrite(p) -> None:
    """``--overwrite``: replace this command's previous run in ``--out``."""
    p.add_argument("--overwrite", action="store_true",
                   help="replace the previous run of this command in a non-empty --out (only "
                        "the files its manifest rrr-pin-run*.json lists are removed)")


def add_design_argument(p) -> None:
    """``--design DIR/design.json``: the law ``tuned`` (``rrr-pin design --require ...``)."""
    p.add_argument("--design", metavar="DIR/design.json", default=None,
                   help="a design tuned to requirements (rrr-pin design --robot ARM --require "
                        "NAME=VALUE --out DIR): its law runs as 'tuned' (name it in "
                        "--controllers, e.g. fl,hinf,tuned); the results record the design and "
                        "its requirement table")


def add_armature_argument(p) -> None:
    """``--armature V`` or ``V1/V2/...``: the arm's reflected rotor inertia per joint."""
    p.add_argument("--armature", metavar="V|V1/V2/...", default=None,
                   help="reflected rotor inertia of each joint [kg m^2] (>= 0), added to the "
                        "mass matrix's diagonal in the plant and in the laws' nominal model: "
                        "one value for every joint or one per joint (after --lock) separated "
                        "by '/', e.g. 0.1 or 0.3/0.3/0.3/0.3/0.1/0.1/0.1 (default: none, as a "
                        "URDF carries none; serial arms only); recorded in the results")


def add_joint_tolerance_arguments(p) -> None:
    """``--tolerance-armature``, ``--tolerance-damping``, ``--tolerance-friction``."""
    for key, what in (("armature", "armature (--armature)"),
                      ("damping", "viscous friction (the URDF's <dynamics damping>)"),
                      ("friction", "Coulomb friction (the URDF's <dynamics friction>)")):
        p.add_argument(f"--tolerance-{key}", type=float, default=0.0, metavar="TOL",
                       help=f"uncertain plants: each joint's {what} drawn in [1 - TOL, 1 + TOL] "
                            f"times its nominal value, TOL in [0, 1) (default 0: nominal); "
                            f"relative, so a zero nominal stays zero"
                            + ("" if key == "armature" else "; acts with --friction urdf"))


def add_plant_arguments(p, *, home: bool = True, plant: bool = False) -> None:
    """Declare ``--robot``, ``--lock``, ``--armature``, ``--home``; ``--plant`` if ``plant``.

    ``--home`` unless ``home=False``; ``--plant``, ``--plant-lock`` and ``--joint-map`` (the
    simulated arm when it is not the laws' model) with ``plant=True``.
    """
    p.add_argument("--robot", default="rrr", metavar="NAME|PATH", help=_PLANT_HELP)
    p.add_argument("--lock", action="append", metavar="JOINT=VALUE",
                   help="lock a joint at a position [rad or m] (repeatable), e.g. the Panda's "
                        "fingers: --lock panda_finger_joint1=0 --lock panda_finger_joint2=0")
    add_armature_argument(p)
    if plant:
        p.add_argument("--plant", default=None, metavar="NAME|PATH",
                       help="simulate this arm instead of --robot, which stays the laws' "
                            "model (e.g. --robot panda --plant panda.xml: a design on "
                            "example-robot-data's Panda run on MuJoCo Menagerie's); joints "
                            "paired by order, or by --joint-map; both recorded")
        p.add_argument("--plant-lock", action="append", metavar="JOINT=VALUE",
                       help="lock a joint of --plant (repeatable), e.g. the Menagerie Panda's "
                            "fingers: --plant-lock finger_joint1=0 --plant-lock "
                            "finger_joint2=0")
        p.add_argument("--joint-map", default=None, metavar="MODEL=PLANT,...",
                       help="with --plant: pair the laws' model joints with the plant's by "
                            "name, e.g. panda_joint1=joint1,...; checked to be every joint once, "
                            "in order")
    if home:
        p.add_argument("--home", metavar="Q1,Q2,...", default=None,
                       help="centre of the sinusoid, start of a quintic or task-space motion "
                            "[rad] (default: the neutral configuration, moved inside the "
                            "limits; for line/circle, bent one joint away from it if the frame "
                            "is singular there)")


def add_force_argument(p) -> None:
    """``--force``: run above the work bounds of one run."""
    # The bounds are named, not imported: --help must not load NumPy (rrr_pin.sim does).
    p.add_argument("--force", action="store_true",
                   help="run even above the work bounds of one run (MAX_SUBSTEPS RK4 steps "
                        "and MAX_SAMPLES stored samples of rrr_pin.sim.simulation, 1e7 and "
                        "1e6), refused otherwise before any work")


def add_law_arguments(p, default_duration: float, default_rate) -> None:
    """Declare the controllers, the run settings, the uncertain plants, the plant effects."""
    from ..control.catalog import BUILTIN_LAWS
    from ..sim.engines import ENGINE_CHOICES, ENGINES

    p.add_argument("--controllers", default="fl,hinf", metavar="NAMES",
                   help="comma-separated built-in controllers to compare: "
                        + "; ".join(f"{k} = {v}" for k, v in BUILTIN_LAWS.items())
                        + " (default: fl,hinf, the paper's)")
    p.add_argument("--baseline", default=None, metavar="NAME",
                   help="controller the others are compared with (default: the first)")
    p.add_argument("--duration", type=float, default=default_duration,
                   help=f"simulated time [s] ({default_duration:g}; a mechanism's task path "
                        f"runs once in it)")
    p.add_argument("--dt", type=float, default=None,
                   help="RK4 step [s] (1e-3); with --rate the plant sub-step, which must "
                        "divide 1/rate (default: the largest such step up to 1e-3)")
    p.add_argument("--rate", type=float, default=default_rate, metavar="HZ",
                   help="sampled controllers at this rate [Hz] (zero-order hold, Tustin K)"
                        + (f" ({default_rate:g})" if default_rate else
                           "; default: continuous-time laws as in the paper's Simulink study"))
    p.add_argument("--engine", choices=ENGINE_CHOICES, default=ENGINE_CHOICES[0],
                   help="simulation engine: auto, the first engine that runs each run exactly "
                        "(recorded per run); " + "; ".join(f"{k}: {e.description}"
                                                           for k, e in ENGINES.items()))
    p.add_argument("--q0", metavar="Q1,Q2,...", default=None,
                   help="initial joint positions [rad] (default: on the reference)")
    p.add_argument("--qd0", metavar="V1,V2,...", default=None,
                   help="initial joint velocities [rad/s] (default: on the reference)")
    p.add_argument("--seed", type=int, default=0, help="seed of the uncertain plants (0)")
    p.add_argument("--uncertainty", metavar="IDENTIFICATION.json", default=None,
                   help="draw the uncertain plants from an identification (rrr-pin identify) "
                        "instead of the paper's 20 %% inertia / 5 %% length tolerances; use "
                        "--robot DIR/identified.urdf as the nominal")
    p.add_argument("--confidence", type=float, default=None,
                   help="with --uncertainty only: confidence region the plants are drawn in "
                        "(0.95)")
    add_joint_tolerance_arguments(p)
    p.add_argument("--uncertainty-draws", choices=("reject", "project"), default=None,
                   help="with --uncertainty: a draw with no physically consistent arm is "
                        "rejected and redrawn (reject, default), or moved to the nearest "
                        "consistent arm, its distance recorded (project: for an estimate "
                        "outside the consistent set, identify --keep-inconsistent)")
    p.add_argument("--delay", type=float, default=None, metavar="S",
                   help="plant effect: actuator transport delay [s] (sampled controllers; "
                        "a whole number of plant sub-steps --dt, others are refused)")
    p.add_argument("--actuator-bandwidth", type=float, default=None, metavar="RAD_S",
                   help="plant effect: first-order actuator wa/(s + wa), wa [rad/s] "
                        "(sampled controllers)")
    p.add_argument("--friction", metavar="urdf|viscous=V,coulomb=C[,smooth=S]", default=None,
                   help="plant effect: joint friction Fv qd + Fc tanh(qd / S) opposing the "
                        "motion (sampled controllers): 'urdf[,smooth=S]' = each plant's URDF "
                        "<dynamics damping friction> (an identified URDF's; with --uncertainty, "
                        "each drawn plant's); or Fv [N m s/rad], Fc [N m] and S [rad/s] "
                        "(0.01), one value for every joint or one per joint separated by '/', e.g. "
                        "viscous=0.5/0.5/0.2,coulomb=1")
    add_effect_arguments(p)
    p.add_argument("--compensate-friction", action="store_true",
                   help="the laws fl, hinf and hinf_aw add the friction of their nominal model "
                        "to their torque (that of --friction, or with --friction urdf or "
                        "without it the nominal URDF's <dynamics>); recorded in results.json "
                        "(laws.<name>.friction_compensation)")
    p.add_argument("--jobs", type=int, default=None,
                   help="worker processes (default: min(2, CPUs))")
    add_force_argument(p)
    add_reference_arguments(p)


def add_effect_arguments(p) -> None:
    """Declare the plant effects besides delay, actuator and friction (one per field).

    Each option is its :class:`~rrr_pin.control.effects.PlantEffects` field with ``-`` for
    ``_`` (``--noise-q`` = ``noise_q``), but ``--noise-seed`` (the field ``seed``). A
    per-joint value is one number or one per joint separated by ``/``. All act on sampled
    controllers (``--rate``).
    """
    p.add_argument("--torque-limit", default=None, metavar="auto|P%|T1,T2,...",
                   help="plant effect: actuator limits |tau_j| <= T_j [N m] (torque_limit): "
                        "auto = the URDF's effort limits; P%% = P percent of the peak torque "
                        "the reference asks of the nominal plant, per joint (its inverse "
                        "dynamics over the control instants); or one number per joint; "
                        "reproduce adds hinf_aw to --controllers, told the limits")
    p.add_argument("--noise-q", default=None, metavar="STD[/STD...]",
                   help="plant effect: standard deviation of the Gaussian noise on the "
                        "measured q [rad] (noise_q)")
    p.add_argument("--noise-qd", default=None, metavar="STD[/STD...]",
                   help="plant effect: standard deviation of the Gaussian noise on the "
                        "measured qd [rad/s] (noise_qd)")
    p.add_argument("--noise-seed", type=int, default=None, metavar="N",
                   help="seed of the noise sequences (PlantEffects.seed; default 0)")
    p.add_argument("--encoder-counts", type=int, default=None, metavar="N",
                   help="plant effect: encoder resolution [counts per revolution]: q measured "
                        "in steps of 2 pi / N rad (encoder_counts)")
    p.add_argument("--stiffness", default=None, metavar="K[/K...]",
                   help="plant effect: flexible transmission of stiffness K [N m/rad] "
                        "between motor and link (stiffness)")
    p.add_argument("--motor-inertia", default=None, metavar="B[/B...]",
                   help="with --stiffness: motor-side inertia B [kg m^2] (motor_inertia, "
                        "default 0.01)")
    p.add_argument("--transmission-damping", default=None, metavar="D[/D...]",
                   help="with --stiffness: transmission damping D [N m s/rad] "
                        "(transmission_damping, default 0)")


def add_reference_arguments(p) -> None:
    """Declare the reference group: ``--reference`` and the options of each kind."""
    from ..control.catalog import REFERENCES

    g = p.add_argument_group("reference")
    g.add_argument("--reference", default="study", choices=tuple(REFERENCES),
                   help="; ".join(f"{k}: {v}" for k, v in REFERENCES.items())
                        + " (default: study)")
    g.add_argument("--amp", type=float, default=0.5, help="sine: amplitude [rad] (0.5)")
    g.add_argument("--freq", type=float, default=0.5, help="sine: frequency [Hz] (0.5)")
    g.add_argument("--to", metavar="Q1,Q2,...", default=None, help="quintic: goal [rad]")
    g.add_argument("--move-time", type=float, default=None,
                   help="quintic, line, circle: duration of the motion [s] (default: "
                        "half of --duration)")
    g.add_argument("--csv", metavar="PATH", default=None,
                   help="spline: waypoints, one row each: time [s], then one column per "
                        "joint [rad]")
    g.add_argument("--frame", default=None,
                   help="line, circle: frame whose origin moves (default: the model's last frame)")
    g.add_argument("--end", metavar="X,Y,Z", default=None,
                   help="line: end point [m] (the line starts where the frame is at --home)")
    g.add_argument("--radius", type=float, default=None,
                   help="circle: radius [m]; the circle starts where the frame is at --home")
    g.add_argument("--normal", metavar="X,Y,Z", default="0,0,1",
                   help="circle: normal of its plane (0,0,1)")
