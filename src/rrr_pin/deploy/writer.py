r"""Export a built-in law as a self-contained C folder: :func:`export`, :func:`prepare_export`.

What is exported is the law's **compiled form** (:class:`~rrr_pin.control.laws.FLForm`,
:class:`~rrr_pin.control.laws.PDForm`) sampled at the rate: the declaration the compiled
engine already trusts to reproduce the Python law exactly. A continuous ``K`` is discretized
here (``method``, Tustin by default, optionally prewarped); a discrete ``K``
(:class:`~rrr_pin.control.laws.DiscreteTrackingController`) is exported as given. The Python
twin of the exported code, the :class:`~rrr_pin.control.laws.SampledLaw` it reproduces, is
:attr:`Export.law`.

The folder (:data:`FILES`): ``controller.h``, ``controller.c`` (the law, C99), ``dynamics.h``
and ``dynamics.c`` + ``codegen_rrr.c`` (the nominal RRR's generated dynamics) or
``dynamics.cpp`` (Pinocchio C++ on the embedded model), ``CMakeLists.txt``, ``main.c``,
and ``controller.json``; with ``rrr-pin export --ros2``, a ros2_control package in ``ros2/``
(:mod:`rrr_pin.deploy.ros2`).
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..control.catalog import LAWS, make_law
from ..control.laws import (
    AntiWindupTracking,
    DiscreteTrackingController,
    FLAWForm,
    FLForm,
    FLFrictionForm,
    PDForm,
    SampledLaw,
    TrackingController,
    check_law,
)
from ..control.laws.tracking import lam_record
from ..outputs import OutputDir, writing
from ..sim.codegen import fingerprint
from ..validation import FieldError, check_positive, check_rate
from . import period, sources
from .command import DEFAULT_COMMAND, TorqueCommand, check_command

__all__ = ["Export", "ExportError", "export", "prepare_export", "check_exportable", "FILES",
           "DYNAMICS",
           "FORMAT", "read_record",
           "EXPRESSIBLE_JOINTS", "generated_rrr_source"]

#: ``controller.json``'s format name; its version is ``VERSION``.
FORMAT = "rrr-pin-controller"
VERSION = 1

def read_record(folder) -> dict:
    """Return the ``controller.json`` of an exported folder, its format checked.

    Raises
    ------
    FileNotFoundError
        ``folder`` holds no ``controller.json``.
    ValueError
        The record is not of :data:`FORMAT`.
    """
    folder = Path(folder)
    path = folder / "controller.json"
    if not path.is_file():
        raise FileNotFoundError(f"{folder} holds no controller.json: not a folder written by "
                                f"rrr-pin export (rrr_pin.export)")
    record = json.loads(path.read_text())
    if record.get("format") != FORMAT:
        raise ValueError(f"{path} is not a {FORMAT!r} record (format = "
                         f"{record.get('format')!r})")
    return record


#: The compiled forms whose law carries a controller K (A, B, C, D) besides feedback
#: linearization; PDForm has none. The exported C implements exactly these and PDForm.
_K_FORMS = (FLForm, FLFrictionForm, FLAWForm)

#: Every file an export may write (the dynamics files depend on the model).
FILES = ("controller.h", "controller.c", "dynamics.h", "dynamics.c", "codegen_rrr.c",
         "dyn_model.c", "dyn_common.h", "dynamics.cpp", "CMakeLists.txt", "main.c",
         "model.txt", "controller.json")

#: The dynamics an export can carry: the nominal RRR's CppADCodeGen C, the C of
#: :mod:`rrr_pin.sim.dyngen` for a chain of revolute x/y/z joints (no Pinocchio to build or
#: link), Pinocchio C++ for any other expressible model.
DYNAMICS = ("generated", "dyngen", "pinocchio")

#: Pinocchio joint types the C API (one ``q`` and one ``qd`` per joint) expresses.
EXPRESSIBLE_JOINTS = ("JointModelRX", "JointModelRY", "JointModelRZ",
                      "JointModelRevoluteUnaligned", "JointModelPX", "JointModelPY",
                      "JointModelPZ", "JointModelPrismaticUnaligned")

#: What a law must declare to be exported (the refusal's text).
EXPORTABLE = ("an exportable law must declare, by compiled_form(), an FLForm (lam and the "
              "discrete A, B, C, D of its K), an FLAWForm (the same with the anti-windup gain "
              "L and the torque limits), an FLFrictionForm (an FLForm with friction "
              "compensation) or a PDForm (Kp, Kd) that reproduces it exactly, "
              "for its own class: the built-in laws fl, hinf, hinf_aw and pd do "
              "(fl_controller, hinf_fl_controller, hinf_aw_controller, pd_controller, and "
              "their sampled versions; fl and hinf with friction compensation too); hinf_aw "
              "with friction compensation, hinf2dof, a subclass or a law of your own does not")


class ExportError(ValueError):
    """A law, model or rate that cannot be exported (the message says why and what would do)."""


@dataclass(frozen=True)
class Export:
    """The files of one export, ready to write, and the law they reproduce.

    Attributes
    ----------
    law : SampledLaw
        The Python twin of the exported code: ``ctrl_step`` computes its :meth:`step`.
    form : FLForm or PDForm
        The compiled form transcribed (matrices discrete at :attr:`rate`).
    rate : float
        Sampling rate [Hz].
    dynamics : {"generated", "dyngen", "pinocchio"}
        Which dynamics the folder carries (:data:`DYNAMICS`).
    files : dict
        File name -> text, in :data:`FILES` order.
    record : dict
        The content of ``controller.json``.
    continuous : tuple or None
        ``K``'s continuous ``(A, B, C, D)`` that ``ctrl_step_dt`` discretizes at each measured
        period (None: a law without ``K``, a discrete ``K`` as given, or a method other than
        those of :data:`rrr_pin.deploy.period.GBT_ALPHA`).
    command : TorqueCommand or None
        The torque convention of ``ctrl_step``'s output (:mod:`rrr_pin.deploy.command`);
        None reads as ``full``.
    """

    law: object
    form: object
    rate: float
    dynamics: str
    files: dict = field(repr=False)
    record: dict = field(repr=False)
    continuous: tuple | None = field(default=None, repr=False, compare=False)
    command: TorqueCommand | None = None

    def write(self, folder) -> list[Path]:
        """Write the files into ``folder`` (which must exist); return their paths."""
        out = []
        for name, text in self.files.items():
            path = Path(folder) / name
            with writing(path):
                path.write_bytes(text.encode("ascii"))
            out.append(path)
        return out


def generated_rrr_source() -> tuple[str, str] | None:
    """Return ``(fingerprint, text)`` of the generated RRR dynamics, or None if not installed.

    The file is ``rrr_pin/_ext/generated/codegen_rrr.c`` (:mod:`rrr_pin.sim.codegen`); its header
    records the fingerprint of the model it was generated for.
    """
    path = Path(__file__).resolve().parents[1] / "_ext" / "generated" / "codegen_rrr.c"
    if not path.is_file():
        return None
    text = path.read_text(encoding="ascii")
    for line in text.splitlines()[:12]:
        if line.startswith(" * fingerprint: "):
            return line.split(": ", 1)[1].strip(), text
    return None


def _check_model(robot) -> None:
    """Refuse a model the C API cannot express (one q and one qd per 1-DOF joint, ASCII names)."""
    model = robot.model
    if model.nq != model.nv:
        raise ExportError(f"robot {robot.name!r}: nq = {model.nq} != nv = {model.nv}; the "
                          f"exported API has one q and one qd per joint")
    for i in range(1, model.njoints):
        kind = model.joints[i].shortname()
        if kind not in EXPRESSIBLE_JOINTS:
            raise ExportError(f"robot {robot.name!r}: joint {model.names[i]!r} is a {kind}; the "
                              f"exported API expresses 1-DOF revolute and prismatic joints only "
                              f"({', '.join(EXPRESSIBLE_JOINTS)})")
    for name in robot.joint_names:
        if not name.isascii() or not name.isprintable():
            raise ExportError(f"robot {robot.name!r}: joint name {name!r} is not printable "
                              f"ASCII; the C header cannot carry it")


def _discretize(law: TrackingController, rate: float, method: str, prewarp):
    """``law``'s K discretized at ``rate``: the DiscreteTrackingController twin."""
    import control

    Ts = 1.0 / rate
    kwargs = {}
    if prewarp is not None:
        prewarp = check_positive("prewarp", prewarp, unit="rad/s")
        if method not in ("tustin", "bilinear"):
            raise FieldError("prewarp", f"{{name}} applies to the Tustin method only, got "
                                        f"method = {method!r}")
        nyquist = math.pi * rate
        if prewarp >= nyquist:
            raise FieldError("prewarp", f"{{name}} = {prewarp:g} rad/s is at or above the "
                                        f"Nyquist frequency pi * rate = {nyquist:.6g} rad/s "
                                        f"of rate = {rate:g} Hz; Tustin cannot prewarp there")
        kwargs["prewarp_frequency"] = prewarp
    try:
        Kd = control.sample_system(law.K, Ts, method=method, **kwargs)
    except ValueError as exc:
        raise FieldError("method", f"{{name}} = {method!r}: {exc}") from exc
    A = np.asarray(Kd.A, dtype=float)
    if A.size:
        _check_stable_after(law, A, rate, method)
    return DiscreteTrackingController(law.nominal, law.lam, Kd, name=law.name, label=law.label,
                                      friction=law.friction)


def _twin(law, rate, method: str, prewarp):
    """Return the sampled law the exported code reproduces, and its rate [Hz]."""
    if isinstance(law, SampledLaw):
        if rate is not None and not math.isclose(check_rate("rate", rate), law.rate):
            raise FieldError("rate", f"law {law.name!r} is sampled at {law.rate:g} Hz; "
                                     f"{{name}} = {rate!r} asks for another rate")
        if prewarp is not None:
            raise FieldError("prewarp", f"law {law.name!r} is already discrete: {{name}} "
                                        f"does not apply")
        return law, check_rate("rate", law.rate)
    if rate is None:
        raise FieldError("rate", f"law {law.name!r} is continuous-time; the exported code runs "
                                 f"at a fixed rate: give {{name}} [Hz] (e.g. 1000), at which "
                                 f"its K is discretized by {method!r}")
    rate = check_rate("rate", rate)
    if type(law) is TrackingController and law.nx:
        return _discretize(law, rate, method, prewarp), rate
    if prewarp is not None:
        raise FieldError("prewarp", f"law {law.name!r} has no K to discretize: {{name}} does "
                                    f"not apply" if not law.nx else
                                    f"law {law.name!r} ({type(law).__name__}) is discretized "
                                    f"by its own sampled(); {{name}} applies to "
                                    f"TrackingController (hinf) only")
    twin = law.sampled(rate, method)
    if isinstance(law, AntiWindupTracking) and twin.nx:
        _check_stable_after(law, twin.compiled_form().A, rate, method)
    return twin, rate


def _continuous_k(law, method: str):
    """K's continuous ``(A, B, C, D)`` when ``ctrl_step_dt`` can discretize it per period."""
    if isinstance(law, SampledLaw) or method not in period.GBT_ALPHA or not law.nx:
        return None
    form = law.compiled_form()  # TrackingController, AntiWindupTracking: K continuous
    if type(form) not in _K_FORMS:
        return None
    return tuple(np.asarray(M, dtype=float) for M in (form.A, form.B, form.C, form.D))


def _check_stable_after(law, A, rate: float, method: str) -> None:
    """Refuse a K that ``method`` at ``rate`` made unstable (``A`` its discrete matrix)."""
    rho = float(np.max(np.abs(np.linalg.eigvals(A))))
    if not rho <= 1.0 + 1e-9:
        raise FieldError("rate", f"K of law {law.name!r} discretized by {method!r} at "
                                 f"{{name}} = {rate:g} Hz is unstable (pole |z| = "
                                 f"{rho:.6g} > 1); raise the rate or use method='tustin', "
                                 f"which keeps a stable K stable")


def _design_record(design) -> dict | None:
    if design is None:
        return None
    return {"gamma": float(design.ncf.gamma), "gamma_min": float(design.ncf.gamma_min),
            "emax": float(design.ncf.emax), "gamma_reduced": float(design.gamma_reduced),
            "b_reduced": 1.0 / float(design.gamma_reduced), "lam": float(design.lam),
            "reduction": design.reduction.as_dict(),
            "robust_stability": {"ok": bool(design.robust_stability.ok),
                                 "margin_db": float(design.robust_stability.margin_db)},
            "robust_performance": {"ok": bool(design.robust_performance.ok),
                                   "margin_db": float(design.robust_performance.margin_db)}}


def _model_parameters(robot, compensated: bool) -> dict:
    """Return the inertial parameters the exported dynamics carry (an identified model's too).

    Per joint, the 10 parameters of its body in Pinocchio's ``toDynamicParameters`` order
    (``m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz``, about the joint frame, SI),
    and the model's armature, damping and friction. The law compensates ``M(q)`` (armature
    included) and ``h(q, qd)``; the URDF's damping and friction are recorded, and compensated
    only by a law exported with friction compensation (``compensated``; its values are
    ``law.friction_compensation``'s, which may come from elsewhere than the URDF).
    """
    model = robot.model
    return {"parameters": {
        "layout": "per joint: m, m*c_x, m*c_y, m*c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz "
                  "(about the joint frame) [kg, kg m, kg m^2]",
        "values": [model.inertias[i].toDynamicParameters().tolist()
                   for i in range(1, model.njoints)],
        "armature": model.armature.tolist(), "damping": model.damping.tolist(),
        "friction": model.friction.tolist(),
        "friction_compensated": bool(compensated)}}


#: Why an export needs a URDF-described serial tree (the refusal's reason).
_NEEDS = ("the exported C code holds a serial tree's dynamics (CRBA and RNEA, or its generated "
          "C) and no loop closure")


def check_exportable(robot) -> None:
    """Refuse, by name, a plant the exported C code cannot hold.

    Raises
    ------
    TypeError
        Not a plant (:func:`rrr_pin.load_robot` gives one).
    rrr_pin.model.plant.CapabilityError
        A plant without :data:`rrr_pin.model.plant.URDF` (a closed chain).
    """
    from ..model.plant import URDF, Plant

    if not isinstance(robot, Plant):
        raise TypeError(f"robot must be a plant (rrr_pin.load_robot), got "
                        f"{type(robot).__name__}")
    robot.require(URDF, f"export ({_NEEDS})")


def prepare_export(law, robot, rate: float | None = None, *, method: str = "tustin",
                   prewarp: float | None = None, design=None,
                   dynamics: str = "auto", command: str = DEFAULT_COMMAND) -> Export:
    """Check and build an export of ``law`` on ``robot`` at ``rate``, without writing.

    Parameters as for :func:`export`.

    Returns
    -------
    Export
    """
    check_exportable(robot)
    _check_model(robot)
    if isinstance(law, str):
        if law not in LAWS:
            raise FieldError("law", f"{{name}} = {law!r} is not a built-in law "
                                    f"({', '.join(LAWS)})")
        if law in ("hinf", "hinf_aw") and design is None:
            from ..robust.loopshaping import design as make_design

            design = make_design(lam=45.0, n=robot.nq)
        law = make_law(law, robot, **({"K": design.K_reduced} if law in ("hinf", "hinf_aw")
                                      else {}))
    check_law(law, robot.nq)
    fp = fingerprint(robot.model)
    twin, rate = _twin(law, rate, method, prewarp)
    form = twin.compiled_form()
    if type(form) not in (*_K_FORMS, PDForm):
        raise ExportError(f"law {law.name!r} ({type(law).__name__}) cannot be exported: "
                          f"{EXPORTABLE}")
    law_fp = fingerprint(form.nominal.model)
    if law_fp != fp:
        raise ExportError(f"law {law.name!r} was built on the model {form.nominal.name!r} "
                          f"(fingerprint {law_fp[:12]}...), not on robot {robot.name!r} "
                          f"({fp[:12]}...); build the law on the robot it is exported for")
    conv = check_command(command, form)
    if dynamics != "auto" and dynamics not in DYNAMICS:
        raise FieldError("dynamics", f"{{name}} must be 'auto' or one of {', '.join(DYNAMICS)}, "
                                     f"got {dynamics!r}")
    generated = generated_rrr_source()
    available = generated is not None and generated[0] == fp
    if dynamics == "generated" and not available:
        raise FieldError("dynamics", f"{{name}} = 'generated': no generated dynamics for robot "
                                     f"{robot.name!r} (fingerprint {fp[:12]}...); only the "
                                     f"nominal RRR has them")
    from ..sim.dyncache import generatable

    if dynamics == "dyngen" and not generatable(robot.model):
        raise FieldError("dynamics", f"{{name}} = 'dyngen': robot {robot.name!r} has a joint "
                                     f"other than a revolute joint about x, y or z; the "
                                     f"generator (rrr_pin.sim.dyngen) does not handle it")
    use_generated = available and dynamics in ("auto", "generated")
    if use_generated:
        dynamics = "generated"
    elif dynamics == "auto":
        dynamics = "dyngen" if generatable(robot.model) else "pinocchio"
    import pinocchio as pin

    from .. import __version__

    n, nx = robot.nq, twin.nx
    continuous = _continuous_k(law, method)
    k_method = None if isinstance(law, SampledLaw) else method  # None: K discrete as given
    step_dt = period.step_dt_text(form, continuous, method=k_method, prewarp=prewarp)
    where = {"generated": "generated plain C of the nominal RRR (codegen_rrr.c)",
             "dyngen": "generated plain C of the structure, the model's numbers as constants "
                       "(dyn_model.c, dynamics.c; no Pinocchio)",
             "pinocchio": "Pinocchio C++ on the embedded model (dynamics.cpp)"}[dynamics]
    files = {
        "controller.h": sources.controller_h(n=n, nx=nx, rate=rate, law=twin.name,
                                             kind=form.kind, joints=robot.joint_names,
                                             fingerprint=fp, dynamics=where,
                                             step_dt=step_dt, command=conv),
        "controller.c": sources.controller_c(form, law=twin.name, rate=rate, command=conv)
        + period.controller_step_dt_c(form, continuous, method=k_method, prewarp=prewarp),
        "dynamics.h": sources.dynamics_h(where),
    }
    if use_generated:
        files["dynamics.c"] = sources.dynamics_codegen_c()
        files["codegen_rrr.c"] = generated[1]
    elif dynamics == "dyngen":
        files.update(sources.dynamics_dyngen(robot.model, robot.name, fp))
    else:
        files["dynamics.cpp"] = sources.dynamics_pinocchio_cpp(robot.model.saveToString(),
                                                              robot.name)
    q0 = np.clip(robot.neutral(), robot.lower, robot.upper)
    files["CMakeLists.txt"] = sources.cmakelists(pinocchio=dynamics == "pinocchio",
                                                 dyngen=dynamics == "dyngen",
                                                 version=pin.__version__,
                                                 python=sys.executable)
    files["main.c"] = sources.main_c(q0=q0)
    # the model itself (Pinocchio's text serialization), which rrr-pin hil simulates: a URDF
    # path or an identified arm needs no name to be found again
    files["model.txt"] = robot.model.saveToString()
    if form.kind == "pd":
        law_record = {"kind": "pd", "Kp": form.Kp.tolist(), "Kd": form.Kd.tolist()}
    else:
        A, B, C, D = form.A, form.B, form.C, form.D
        if isinstance(law, DiscreteTrackingController):
            source = "discrete K as given"
        elif nx:
            source = "continuous K discretized here"
        else:
            source = "no K (feedback linearization alone)"
        # lam: a number, or a list of one per joint
        law_record = {"kind": "fl", "lam": lam_record(form.lam), "A": A.tolist(),
                      "B": B.tolist(),
                      "C": C.tolist(), "D": D.tolist(), "Ts": 1.0 / rate,
                      "method": None if isinstance(law, DiscreteTrackingController) or not nx
                      else method, "prewarp_rad_s": prewarp, "K_source": source}
        if form.kind == "fl_friction":  # tau += Fv qd + Fc tanh(qd / v_eps)
            law_record.update(kind="fl_friction", friction_compensation={
                "viscous_Nms_rad": form.viscous.tolist(), "coulomb_Nm": form.coulomb.tolist(),
                "coulomb_velocity_rad_s": form.coulomb_velocity,
                "model": "tau += Fv qd + Fc tanh(qd / v_eps)",
                "source": law.friction.source if law.friction is not None else ""})
        if form.kind == "fl_aw":  # Hanus: x+ = A x + B e + L (y_hat - y), tau clipped
            law_record.update(kind="fl_aw", L=form.L.tolist(),
                              torque_limit_Nm=form.limit.tolist(),
                              anti_windup="Hanus self-conditioned K, L = B D^-1")
    record = {
        "format": FORMAT, "version": VERSION, "rrr_pin_version": __version__,
        "pinocchio_version": pin.__version__,
        "law": {"name": twin.name, "label": twin.label or twin.name,
                "class": f"{type(law).__module__}.{type(law).__qualname__}", **law_record},
        "rate_hz": rate, "nq": n, "nx": nx, "joints": list(robot.joint_names),
        "command": conv.as_dict(),
        "ctrl_step_dt": {"period": step_dt, "K_continuous": None if continuous is None else
                         dict(zip("ABCD", (M.tolist() for M in continuous), strict=True)),
                         "method": None if continuous is None else method,
                         "alpha": None if continuous is None else period.GBT_ALPHA[method],
                         "prewarp_rad_s": None if continuous is None else prewarp},
        "model": {"name": robot.name, "fingerprint": fp, "dynamics": dynamics,
                  **_model_parameters(robot, form.kind == "fl_friction")},
        "design": _design_record(design),
    }
    files["controller.json"] = json.dumps(record, indent=2, sort_keys=True) + "\n"
    return Export(twin, form, rate, dynamics, files, record, continuous, conv)


def export(law, robot, rate: float | None = None, out="controller", *, method: str = "tustin",
           prewarp: float | None = None, design=None, dynamics: str = "auto",
           command: str = DEFAULT_COMMAND, overwrite: bool = False) -> Export:
    """Write ``law`` on ``robot`` at ``rate`` as a self-contained C folder ``out``.

    The folder holds ``controller.h``/``controller.c`` (C99: no allocation, no mutable global,
    re-entrant) with ``ctrl_reset``/``ctrl_step`` (and ``ctrl_step_dt``, the law over a measured
    period), the nominal model's dynamics (the generated
    C of the nominal RRR, or a C++ file calling Pinocchio on the embedded model), a
    ``CMakeLists.txt`` (static library ``rrr_pin_ctrl``), an example ``main.c`` and
    ``controller.json`` (:func:`rrr_pin.deploy.ros2.write_ros2_package` adds a ros2_control
    package). The same
    arguments give byte-identical files.

    Parameters
    ----------
    law : ControlLaw, SampledLaw or str
        A built-in law (:func:`~rrr_pin.control.laws.fl_controller`,
        :func:`~rrr_pin.control.laws.hinf_fl_controller`,
        :func:`~rrr_pin.control.laws.pd_controller`, or their sampled versions) built on
        ``robot``, or its name (``"fl"``, ``"hinf"``: the paper's reduced design, ``"pd"``).
    robot : Robot
        The law's nominal model (its fingerprint must equal the law's).
    rate : float, optional
        Sampling rate [Hz]; required for a continuous law, equal to a sampled law's own.
    out : path-like, default "controller"
        Output folder; claimed as :mod:`rrr_pin.outputs` says (refused if not empty, unless
        ``overwrite``).
    method : str, default "tustin"
        Discretization of a continuous ``K`` (:func:`control.sample_system`).
    prewarp : float, optional
        Tustin prewarp frequency [rad/s], below the Nyquist frequency ``pi * rate``.
    design : Design, optional
        The source design, whose ``gamma`` and margins ``controller.json`` records (the
        ``"hinf"`` name uses the paper's design and records it).
    dynamics : {"auto", "generated", "dyngen", "pinocchio"}, default "auto"
        The model's dynamics in the folder (:data:`DYNAMICS`): the generated C of the nominal
        RRR when it is that model (``"auto"``, or required by ``"generated"``), else the
        generated C of :mod:`rrr_pin.sim.dyngen` for a chain of revolute x/y/z joints (no
        Pinocchio to build or link; armature included), else Pinocchio C++.
    command : {"full", "no-gravity", "no-gravity-no-friction"}, default "full"
        The torque convention of the drive (:mod:`rrr_pin.deploy.command`): ``ctrl_step``'s
        torque is the law's minus ``Ghat(q)`` (``no-gravity``), and minus the law's friction
        compensation too (``no-gravity-no-friction``); recorded in ``controller.json``
        (``command``), applied to the safe torque ``ctrl_safe_torque``.
    overwrite : bool, default False
        Replace a previous export in ``out``.

    Returns
    -------
    Export
        The files written and :attr:`Export.law`, the Python law the code reproduces.

    Raises
    ------
    ExportError
        A law that declares no compiled form (with what an exportable law must declare), a
        law built on another model, joints the C API cannot express.
    FieldError
        A continuous law without ``rate``, a ``rate`` other than a sampled law's, a prewarp
        at or above Nyquist, a ``K`` unstable once discretized, a ``command`` the law cannot
        honour (:func:`rrr_pin.deploy.command.check_command`).
    OutputError
        ``out`` not empty without ``overwrite``, not writable, or another tool's.
    """
    prepared = prepare_export(law, robot, rate, method=method, prewarp=prewarp, design=design,
                              dynamics=dynamics, command=command)
    settings = {"law": prepared.law.name, "robot": robot.name, "rate": prepared.rate,
                "method": method, "prewarp": prewarp, "dynamics": prepared.dynamics,
                "command": prepared.command.name}
    with OutputDir.claim(out, "export", overwrite=overwrite, settings=settings,
                         option="out") as run:
        prepared.write(run.path)
    return prepared
