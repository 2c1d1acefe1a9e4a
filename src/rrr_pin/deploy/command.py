r"""The hardware's torque convention of an exported law: :data:`COMMANDS`, :func:`check_command`.

A torque-controlled arm does not always take the whole torque a law computes. libfranka's
``franka::Torques`` are the commanded torques *without* gravity and friction: the robot adds
its own gravity and friction compensation, so a law that outputs ``M a + h`` (gravity
included) compensates gravity twice. The export therefore writes the law's torque **in the
convention the drive expects** (``rrr-pin export --command``):

.. math:: \tau_{cmd} = \tau_{law}(q, \dot q, r, \dot r, \ddot r)
          - \delta_G \hat G(q) - \delta_F \hat\tau_F(\dot q)

with ``delta_G`` and ``delta_F`` the terms the convention removes (:class:`TorqueCommand`):
``full`` removes nothing (the law's torque, the default), ``no-gravity`` removes the nominal
gravity torque ``Ghat(q)`` (of the law's own model), ``no-gravity-no-friction`` also removes
the law's friction compensation ``Fv qd + Fc tanh(qd / v_eps)``. The terms are removed
*after* everything else the law does (anti-windup clipping included), so the law's state and
its clipping act on the whole torque the joint receives once the drive adds its part back.
The safe torque of a fault (gravity compensation) follows the same convention: ``Ghat(q)``
under ``full``, zero under the others (the drive holds the arm itself).

A convention the law cannot honour is refused by name (:func:`check_command`): removing
gravity from a law whose model has none (zero gravity vector), removing friction from a law
that compensates none.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..validation import FieldError

__all__ = ["TorqueCommand", "COMMANDS", "DEFAULT_COMMAND", "check_command", "removed_torque"]


@dataclass(frozen=True)
class TorqueCommand:
    """One torque convention: which of the law's terms the drive adds itself.

    Attributes
    ----------
    name : str
        The ``--command`` value (``controller.json`` ``command.name``).
    removes_gravity : bool
        The command excludes the nominal gravity torque ``Ghat(q)`` [N m].
    removes_friction : bool
        The command excludes the law's friction compensation [N m].
    meaning : str
        One line for the record and the help.
    """

    name: str
    removes_gravity: bool
    removes_friction: bool
    meaning: str

    def as_dict(self) -> dict:
        """Return the record of ``controller.json`` (``command``)."""
        return {"name": self.name, "removes_gravity": self.removes_gravity,
                "removes_friction": self.removes_friction, "meaning": self.meaning,
                "model": "tau_cmd = tau_law - [removes_gravity] Ghat(q) "
                         "- [removes_friction] (Fv qd + Fc tanh(qd / v_eps))"}


#: The conventions, by ``--command`` name.
COMMANDS = {c.name: c for c in (
    TorqueCommand("full", False, False,
                  "the law's whole torque (M a + h [+ friction]): a bare motor driver, a joint "
                  "torque interface that adds nothing"),
    TorqueCommand("no-gravity", True, False,
                  "the law's torque minus Ghat(q): the drive adds gravity compensation"),
    TorqueCommand("no-gravity-no-friction", True, True,
                  "the law's torque minus Ghat(q) and its friction compensation: the drive adds "
                  "both (libfranka franka::Torques)"),
)}

DEFAULT_COMMAND = "full"


def _has_gravity(model) -> bool:
    return bool(np.any(np.asarray(model.gravity.linear) != 0.0))


def check_command(command, form) -> TorqueCommand:
    """Return the convention named ``command`` for the compiled ``form``, or refuse it.

    Parameters
    ----------
    command : str or TorqueCommand
        A name of :data:`COMMANDS`.
    form : FLForm, FLFrictionForm, FLAWForm or PDForm
        The exported law's compiled form (its ``nominal`` model gives the gravity).

    Raises
    ------
    FieldError
        An unknown name; ``no-gravity*`` for a law whose model has no gravity; ``*no-friction``
        for a law that compensates no friction (the message names what would do).
    """
    if isinstance(command, TorqueCommand):
        command = command.name
    if command not in COMMANDS:
        raise FieldError("command", f"{{name}} = {command!r} is not a torque convention "
                                    f"({', '.join(COMMANDS)})")
    conv = COMMANDS[command]
    if conv.removes_gravity and not _has_gravity(form.nominal.model):
        raise FieldError("command", f"{{name}} = {command!r}: the law's model "
                                    f"{form.nominal.name!r} has no gravity (gravity vector 0), "
                                    f"so its torque holds no gravity term to remove; use "
                                    f"{{name}} = 'full'")
    if conv.removes_friction and form.kind != "fl_friction":
        raise FieldError("command", f"{{name}} = {command!r}: law kind {form.kind!r} "
                                    f"compensates no friction, so there is none to remove; use "
                                    f"{{name}} = 'no-gravity' (or export with friction "
                                    f"compensation)")
    return conv


def removed_torque(command: TorqueCommand, form, q, qd) -> np.ndarray:
    """Return the torque the convention removes from the law's, shape (n,) [N m].

    ``Ghat(q)`` (Pinocchio's ``computeGeneralizedGravity`` on the law's model) when it removes
    gravity, plus ``Fv qd + Fc tanh(qd / v_eps)`` when it removes friction. The Python twin of
    what the exported C subtracts; the exported torque is the law's minus this.

    Parameters
    ----------
    command : TorqueCommand
    form : compiled form
    q : array-like, shape (n,)
        Joint positions [rad].
    qd : array-like, shape (n,)
        Joint velocities [rad/s].
    """
    import pinocchio as pin

    q = np.asarray(q, dtype=float)
    qd = np.asarray(qd, dtype=float)
    out = np.zeros(q.shape[0])
    if command.removes_gravity:
        model = form.nominal.model
        out = out + pin.computeGeneralizedGravity(model, model.createData(), q)
    if command.removes_friction:
        out = out + (form.viscous * qd + form.coulomb * np.tanh(qd / form.coulomb_velocity))
    return out
