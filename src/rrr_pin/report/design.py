"""The loop-shaping design as a person reads it: JSON-ready summaries and text lines.

:func:`design_summary` is the JSON of ``rrr-pin design``; :func:`design_lines` the same design
as text for a terminal; :func:`study_design` the design recorded beside a study (in
``results.json`` and ``report.html``). Every figure comes from a
:class:`rrr_pin.robust.loopshaping.Design`; nothing is recomputed here but the controllers'
zeros and poles.
"""

from __future__ import annotations

from ..robust.loopshaping import zpk_data

__all__ = ["zpk_dict", "design_summary", "design_lines", "study_design", "DESIGN_UNITS"]

#: Units of the keys of :func:`study_design` and :func:`design_summary` that carry no unit
#: suffix ("-": dimensionless; ``K`` maps the error [rad] to the correction ``y`` [rad]).
DESIGN_UNITS = {"gamma_min": "-", "gamma": "-", "emax": "-", "gamma_reduced": "-",
                "gain": "-", "zeros": "rad/s", "poles": "rad/s", "ok": "-",
                "worst_frequency": "rad/s", "ncfmargin": "-"}


def zpk_dict(K) -> dict:
    """Return a SISO controller as JSON: gain, zeros and poles as [real, imag] [rad/s]."""
    k, z, p = zpk_data(K)
    return {"gain": k, "zeros": [[float(v.real), float(v.imag)] for v in z],
            "poles": [[float(v.real), float(v.imag)] for v in p]}


def design_summary(d) -> dict:
    """JSON-ready summary of a design: gammas, both controllers, margins and reductions.

    Parameters
    ----------
    d : rrr_pin.robust.loopshaping.Design

    Returns
    -------
    dict
        ``gamma_min``, ``gamma``, ``emax``, ``gamma_reduced``, ``K_full`` and ``K_reduced``
        (:func:`zpk_dict`), ``robust_stability`` and ``robust_performance`` (the barrier
        checks of eq. (12)-(13)), ``ncfmargin`` and ``reductions`` (the eq. (18) guarantee on
        the plant and shaped loops, and the coprime-factor balanced truncation).
    """
    return {
        "gamma_min": d.ncf.gamma_min, "gamma": d.ncf.gamma, "emax": d.ncf.emax,
        "gamma_reduced": d.gamma_reduced,
        "K_full": zpk_dict(d.K_full), "K_reduced": zpk_dict(d.K_reduced),
        "robust_stability": d.robust_stability.as_dict(),
        "robust_performance": d.robust_performance.as_dict(),
        "ncfmargin": d.ncfmargin,
        "reductions": {
            "eq18": {"plant_loop": d.reduction.as_dict(),
                     "shaped_loop": d.reduction_shaped.as_dict()},
            "ncf_balanced_truncation": d.ncf_reduction.as_dict(),
        },
    }


def _roots(r) -> str:
    return ", ".join(f"{v[0]:.6g}" + (f"{v[1]:+.6g}j" if v[1] else "") for v in r)


def _verdict(name: str, c: dict, where: str) -> str:
    state = "satisfied" if c["ok"] else "NOT satisfied"
    return (f"{name}: {state}, smallest margin {c['margin_db']:.2f} dB "
            f"at {c['worst_frequency']:.4g} rad/s ({where})")


def _vs(x: float, b: float) -> str:
    """Return the inequality that holds between a distance and the margin ``b``: < or >=."""
    return "<" if x < b else ">="


def design_lines(d) -> list[str]:
    """Return a design as text lines (no newlines), for a terminal."""
    out = design_summary(d)
    lines = [f"H-infinity loop shaping, lam = {d.lam:g} rad/s, {d.n} joints, "
             f"factor = {d.factor:g} (negative feedback u = K (r - y), K = k I_{d.n})",
             f"gamma_min = {out['gamma_min']:.4f}   gamma = {out['gamma']:.4f}   "
             f"emax = 1/gamma = {out['emax']:.4f}"]
    for name, key in (("full-order K", "K_full"), ("reduced K (eq. 18)", "K_reduced")):
        K = out[key]
        lines += [f"{name}: gain {K['gain']:.6g}", f"    zeros [rad/s]: {_roots(K['zeros'])}",
                  f"    poles [rad/s]: {_roots(K['poles'])}"]
    lines.append(f"gamma of the reduced K on Gs = {d.gamma_reduced:.4f} "
                 f"({100 * (d.gamma_reduced / d.ncf.gamma - 1):+.4f} %)")
    for where, r in (("shaped loop (Gs, Ks)", d.reduction_shaped),
                     ("plant loop (G, K)", d.reduction)):
        state = "guaranteed" if r.guaranteed else "NOT guaranteed"
        lines.append(f"eq. (18) reduction on the {where}: nugap(full, reduced) = {r.nugap:.3g} "
                     f"{_vs(r.nugap, r.b)} b = {r.b:.4f}: stability {state}; b after >= "
                     f"{r.b_lower:.4f} (computed {r.b_reduced:.4f}, lost {r.margin_lost:.2g})")
    r = d.ncf_reduction
    lines += [f"coprime-factor balanced truncation to {r.Kr.nstates} states: "
              f"||[N - Nr; M - Mr]||_inf = {r.eps:.3g} {_vs(r.eps, r.b)} b = {r.b:.4f}: "
              f"{'guaranteed' if r.guaranteed else 'NOT guaranteed'}, b after {r.b_reduced:.4f}",
              f"NCF margin of the final loop b(G, K) = {d.ncfmargin:.4f}",
              _verdict("robust stability", out["robust_stability"],
                       "sigma_max(T) below RSB, all frequencies"),
              _verdict("robust performance", out["robust_performance"],
                       f"sigma_min(GK) above RPB, w <= {d.w_performance:g} rad/s")]
    return lines


def study_design(d, full_order: bool = False) -> dict:
    """Return the design recorded beside a study: gammas, the controller used and the margins.

    Parameters
    ----------
    d : rrr_pin.robust.loopshaping.Design
    full_order : bool, default False
        The study used ``d.K_full`` instead of the reduced eq. (18) ``d.K_reduced``.
    """
    K = d.K_full if full_order else d.K_reduced
    return {
        "lam_rad_s": d.lam, "gamma_min": d.ncf.gamma_min, "gamma": d.ncf.gamma,
        "emax": d.ncf.emax, "gamma_reduced": d.gamma_reduced,
        "K_used": "full" if full_order else "reduced",
        "K": zpk_dict(K),
        "robust_stability": d.robust_stability.as_dict(),
        "robust_performance": d.robust_performance.as_dict(),
    }
