r"""Control laws: the protocol every law follows, and the built-ins.

A **control law** computes the joint torque from the time, the measured state, the reference
and its own state. Two kinds, as in Simulink's continuous and discrete blocks:

* :class:`ControlLaw`, continuous time: ``tau = torque(t, q, qd, r, rd, rdd, x)`` with the law's
  state ``x`` obeying ``xdot = derivative(t, q, qd, r, rd, rdd, x)``; the simulator integrates
  ``x`` with the arm. :meth:`ControlLaw.sampled` gives its digital (sampled) version.
* :class:`SampledLaw`, discrete time at ``rate`` Hz: ``tau, x_next = step(t, q, qd, r, rd,
  rdd, x)``; the torque is held (zero-order hold) until the next sample.

Write your own law by subclassing either one (see the README, "Your own controller"). The
simulator's Python engine runs any law. The compiled engine runs a law only if the law
declares a :class:`CompiledForm` (:meth:`ControlLaw.compiled_form`) that the C++ loop
implements exactly; the built-ins declare one for their exact class only, so a subclass that
overrides a method never runs the built-in's compiled code in its place.

Built in (each uses the NOMINAL model only; the simulated plant may differ):

* :func:`fl_controller`, feedback linearization alone (eq. 20), ``lam = 100`` rad/s;
* :func:`hinf_fl_controller`, H-infinity + feedback linearization (eq. 8-10, 18-19); with a
  discrete-time ``K`` it is a :class:`DiscreteTrackingController`, sampled at ``1 / K.dt`` Hz;
* :func:`hinf_aw_controller`, the same law told the actuator limits, its ``K`` conditioned on
  the torque actually applied (Hanus's self-conditioned form, :class:`AntiWindupTracking`);
* :func:`pd_controller`, the industrial baseline: PD plus gravity compensation,
  ``tau = Kp e + Kd ed + Ghat(q)``.

Block diagram of the two feedback-linearizing laws (one law, ``K = 0`` gives FL alone)::

                 feed-forward  rdd, rd
       r ----+---------------------------------------+
             |                                       v
       r -->(+)-- e --+-----------------> (+) -- lam^2 (e + y) + 2 lam (rd - qd) + rdd = taubar
             ^-       |                    ^                                          |
             |        +--> [ K(s) ] -- y --+                                          v
             |                                          tau = Mhat(q) taubar + Vhat(q, qd) + Ghat(q)
             |                                                                        |
             +-------------------------------------- q, qd <------- [ true arm ] <----+

With ``M = Mhat`` and ``V + G = Vhat + Ghat`` the arm obeys ``qdd = taubar`` and the error
``e = r - q`` obeys

.. math:: \ddot e + 2\lambda \dot e + \lambda^2 (I + K(s))\, e = -\eta,

where ``eta = (M^-1 Mhat - I) taubar + M^-1 (Vhat + Ghat - V - G)`` is zero for an exact model.

Why this feed-forward: it is the paper's eq. (8)-(10), ``taubar = -2 lam qd - lam^2 (q - tauhat)``,
with ``tauhat = Gfl^-1(s) r + K(s) e``, where ``Gfl^-1(s) r = r + 2 rd / lam + rdd / lam^2`` is the
inverse of the linearized plant (11) applied to the reference. That is the standard
two-degree-of-freedom structure: the model-inverse feed-forward makes the nominal reference-to-error
transfer exactly zero for both controllers (so on the exact model both track alike, as the paper
reports for Fig. 5), and the H-infinity controller ``K`` (eq. 18, negative feedback on ``e``) acts
only on the error the model mismatch ``eta`` causes. For FL alone (``K = 0``, ``lam = 100``) the
law reduces to the paper's eq. (20) with feed-forward:
``taubar = rdd + 2 lam (rd - qd) + lam^2 (r - q)``. The paper's open loop (19),
``q/r = K lam^2/(s + lam)^2``, is the loop this law closes around ``e``.

References
----------
.. [1] The paper, eq. (8)-(11), (18)-(20).
.. [2] S. Skogestad, I. Postlethwaite, *Multivariable Feedback Control*, 2nd ed., Wiley 2005,
   sec. 9.4 (two-degrees-of-freedom loop shaping).
.. [3] B. Siciliano et al., *Robotics: Modelling, Planning and Control*, Springer 2009,
   sec. 8.5.2 (PD control with gravity compensation).
.. [4] R. Hanus, M. Kinnaert, J.-L. Henrotte, "Conditioning technique, a general anti-windup
   and bumpless transfer method", *Automatica* 23(6) (1987) 729-739.
"""

from .antiwindup import AntiWindupTracking, hinf_aw_controller
from .forms import (
    CompiledForm,
    FLAWForm,
    FLForm,
    FLFrictionForm,
    PDForm,
    TwoDOFForm,
    compiled_forms,
)
from .pd import PD_BANDWIDTH, PDGravity, PDLinearModel, pd_controller
from .protocol import (
    DEFAULT_RATE,
    ControlLaw,
    LinearModel,
    SampledLaw,
    check_law,
    check_law_output,
    check_step_output,
)
from .tracking import (
    DiscreteTrackingController,
    FLLinearModel,
    TrackingController,
    fl_controller,
    hinf_fl_controller,
)
from .twodof import TREF_BANDWIDTH, TwoDOFController, TwoDOFLinearModel, hinf_2dof_controller

__all__ = [
    "ControlLaw",
    "SampledLaw",
    "CompiledForm",
    "FLForm",
    "FLFrictionForm",
    "FLAWForm",
    "PDForm",
    "TwoDOFForm",
    "compiled_forms",
    "LinearModel",
    "FLLinearModel",
    "PDLinearModel",
    "TrackingController",
    "AntiWindupTracking",
    "DiscreteTrackingController",
    "PDGravity",
    "fl_controller",
    "hinf_fl_controller",
    "hinf_aw_controller",
    "pd_controller",
    "TwoDOFController",
    "TwoDOFLinearModel",
    "hinf_2dof_controller",
    "TREF_BANDWIDTH",
    "check_law",
    "check_law_output",
    "check_step_output",
    "DEFAULT_RATE",
    "PD_BANDWIDTH",
]
