r"""What a certificate covers: the loop it was computed on, and that loop behind a run's effects.

The frozen-configuration certificate of :class:`~rrr_pin.robust.certificates.CertificateSpec`
is computed on the continuous feedback-linearized loop without effects (nu-gap of each frozen
linearization against ``b(Gs, Ks)``, the paper's eq. 12-13). A campaign whose laws run
sampled at a rate, behind a delay and an actuator, runs another loop. :func:`certify_run`
certifies that loop too, by an **exact discrete check per frozen configuration**: the
loop-shaping law ``K = W1 Ks W2`` of the certificate, sampled at the run's rate (Tustin,
zero-order hold), on the plant linearized at rest at each of the certificate's frozen
configurations, with the actuator as states and the (fractional) delay as delayed-input
states (:meth:`~rrr_pin.control.sampled_loops.LoopSet.spectral_radius`; Franklin, Powell &
Workman sec. 4.3.4): the plant is certified only if both the nu-gap test holds and every
such closed loop has spectral radius below 1. :func:`certificate_loop` writes down what is
covered and what is not (friction, torque limits, noise, quantization and joint stiffness
are not: a run with them says so).

References
----------
.. [1] The paper, eq. (12)-(13).
.. [2] G. F. Franklin, J. D. Powell, M. Workman, *Digital Control of Dynamic Systems*, 3rd
   ed., 1998, sec. 4.3.4.
"""

from __future__ import annotations

import numpy as np

__all__ = ["certificate_loop", "certify_run", "UNCOVERED_EFFECTS"]

#: Effects of :class:`~rrr_pin.control.effects.PlantEffects` no certificate covers, by the
#: test that says whether a run has them.
UNCOVERED_EFFECTS = {
    "friction": lambda fx: fx.friction,
    "torque_limit": lambda fx: fx.torque_limit is not None,
    "noise": lambda fx: fx.noisy,
    "encoder_counts": lambda fx: fx.encoder_counts is not None,
    "stiffness": lambda fx: fx.stiffness is not None,
}


def _delay_actuator(run) -> tuple[float, float | None]:
    fx = run.effects
    return (float(fx.delay), fx.actuator_bandwidth) if fx is not None else (0.0, None)


def certificate_loop(lam: float, points: int, run) -> dict:
    """Return the loop a certificate covers under the run settings ``run``.

    Parameters
    ----------
    lam : float
        The certificate's FL bandwidth [rad/s] (``CertificateSpec.lam``).
    points : int
        Its frozen configurations (``CertificateSpec.points``).
    run : RunSettings

    Returns
    -------
    dict
        ``plant`` (what is linearized), ``law`` (``lam``, the loop-shaping ``K``), ``rate_hz``
        (None: continuous), ``delay_s``, ``actuator_rad_s``, ``method`` and ``not_covered``
        (the run's effects the certificate does not cover, by name; empty: all covered).
    """
    delay, wa = _delay_actuator(run)
    fx = run.effects
    uncovered = [name for name, has in UNCOVERED_EFFECTS.items()
                 if fx is not None and has(fx)]
    method = ("frozen nu-gap < b(Gs, Ks) of the continuous loop (eq. 12-13), at "
              f"{points} configurations of the reference")
    if run.rate is not None:
        method += (" and the exact discrete closed loop at each (sampled law, actuator and "
                   "delay as states) with spectral radius < 1")
    return {"plant": "each plant's frozen linearizations along the reference",
            "law": f"loop-shaping FL, lam = {lam:g} rad/s, K = W1 Ks W2",
            "rate_hz": run.rate, "delay_s": delay if run.rate is not None else 0.0,
            "actuator_rad_s": wa if run.rate is not None else None,
            "method": method, "not_covered": uncovered}


def certify_run(spec, nominal, plant, reference, run) -> dict:
    """Certify ``plant`` for the loop the run settings ``run`` simulate.

    The nu-gap certificate (:meth:`CertificateSpec.certify`), and with a rate the exact
    discrete check of the module docstring at the same configurations.

    Returns
    -------
    dict
        ``certified`` (bool: both hold), ``nugap_max``, ``b`` and, with a rate,
        ``spectral_radius`` (the largest over the configurations).
    """
    out = spec.certify(nominal, plant, reference, run.duration)
    if run.rate is None:
        return out
    import control

    from ..control.sampled_loops import LoopSet

    K = control.ss(*spec.W1) * control.ss(*spec.Ks) * control.ss(*spec.W2)
    if K.ninputs > 1:           # a diagonal copy: the law's per-joint K is one block
        K = K[0, 0]
    delay, wa = _delay_actuator(run)
    t = np.linspace(0.0, float(run.duration), spec.points)
    rho = 0.0
    for q in np.asarray(reference.sample(t)[0], dtype=float):
        loops = LoopSet(nominal, [plant], q, run.rate, omega=np.array([1.0]))
        rho = max(rho, float(loops.spectral_radius(loops.law(spec.lam, K), delay, wa)[0]))
    out["spectral_radius"] = rho
    out["certified"] = bool(out["certified"] and rho < 1.0)
    return out
