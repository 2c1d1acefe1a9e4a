"""A tuned design as a file: ``design.json``'s format, its controller record, the law it holds.

:meth:`rrr_pin.campaign.tuning.TuneResult.to_dict` writes the record (:func:`k_record` for
``K``); :func:`load_design` reads and checks a file, naming it; :func:`tuned_law` builds the
law again on an arm (:func:`law_of`).
"""

from __future__ import annotations

import json

import numpy as np

__all__ = ["DESIGN_FORMAT", "law_of", "k_record", "load_design", "tuned_law"]

#: ``format`` of a ``design.json``.
DESIGN_FORMAT = "rrr-pin-design/1"


def _diagonal(Ks):
    """``diag(K_1, ..., K_n)`` as one ``control.TransferFunction`` (None: 0 on that joint)."""
    import control

    from ..control.sampled_loops import siso_coefficients

    n = len(Ks)
    nd = [siso_coefficients(k) if k is not None else (np.zeros(1), np.ones(1)) for k in Ks]
    num = [[nd[i][0] if i == j else [0.0] for j in range(n)] for i in range(n)]
    den = [[nd[i][1] if i == j else [1.0] for j in range(n)] for i in range(n)]
    return control.tf(num, den)


def law_of(nominal, lam, K, name: str = "tuned"):
    """Return the tuned law ``(lam, K)`` on ``nominal`` (``K`` per joint: a diagonal one)."""
    from ..control.laws import TrackingController

    if isinstance(K, list | tuple):
        K = _diagonal(K)
    return TrackingController(nominal=nominal, lam=lam, K=K, name=name, label="tuned design")


def k_record(K):
    """``design.json``'s ``K``: ``{num, den}``, or ``{"per_joint": [{num, den}, ...]}``."""
    from ..control.sampled_loops import siso_coefficients

    if K is None:
        return None
    if isinstance(K, list | tuple):
        return {"per_joint": [k_record(k) for k in K]}
    num, den = siso_coefficients(K)
    return {"num": num.tolist(), "den": den.tolist()}


def load_design(path) -> dict:
    """Read a ``design.json`` (:meth:`TuneResult.to_dict`), checking its format.

    Raises
    ------
    ValueError
        Not a design file (its ``format`` is not :data:`DESIGN_FORMAT`), or unreadable JSON.
    """
    try:
        with open(path) as fh:
            data = json.load(fh)
    except json.JSONDecodeError as exc:
        raise ValueError(f"--design {path}: not JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != DESIGN_FORMAT:
        raise ValueError(f"--design {path}: not an rrr-pin design (format "
                         f"{data.get('format') if isinstance(data, dict) else None!r}, "
                         f"expected {DESIGN_FORMAT!r}); write one with rrr-pin design "
                         f"--require ...")
    missing = [key for key in ("robot", "joints", "lam_rad_s", "K") if key not in data]
    if missing:  # K null is FL alone, as the tuner writes it; a missing K is another law
        raise ValueError(f"--design {path}: no {', '.join(missing)} (a design.json written by "
                         f"rrr-pin design --require ... has them all; K null for FL alone)")
    K = data["K"]
    for k in (K["per_joint"] if isinstance(K, dict) and "per_joint" in K and
              isinstance(K["per_joint"], list) else [K]):
        if k is not None and not _k_ok(k):
            raise ValueError(f"--design {path}: K = {json.dumps(k)[:120]} is not a transfer "
                             f"function {{\"num\": [...], \"den\": [...]}} of finite "
                             f"coefficients, den[0] != 0, proper (len(num) <= len(den))")
    return data


def _k_ok(k) -> bool:
    """Whether ``k`` is ``{num, den}`` of a proper SISO transfer function with finite numbers."""
    if not isinstance(k, dict) or set(k) != {"num", "den"}:
        return False
    try:
        num, den = (np.asarray(k[key], dtype=float) for key in ("num", "den"))
    except (TypeError, ValueError):
        return False
    return bool(num.ndim == den.ndim == 1 and num.size and den.size and den[0] != 0
                and num.size <= den.size and np.all(np.isfinite(num))
                and np.all(np.isfinite(den)))


def tuned_law(design: dict, nominal, name: str = "tuned"):
    """Build the tuned law of a ``design.json`` record on ``nominal``.

    ``rrr_pin.tuned_law(rrr_pin.load_design("tuned/design.json"), robot)`` is the law that
    ``rrr-pin design --require ...`` wrote, ready for :func:`rrr_pin.simulate` or a campaign.

    Parameters
    ----------
    design : dict
        A record read by :func:`load_design`.
    nominal : rrr_pin.model.plant.Plant
        The arm it was tuned for (same name and joints).
    name : str
        The law's name in runs and tables.

    Returns
    -------
    rrr_pin.ControlLaw
        The feedback-linearizing law with the design's ``lam_rad_s`` [rad/s] (one, or one per
        joint) and its loop-shaping controller ``K`` (none: FL alone).

    Raises
    ------
    ValueError
        The design was tuned for another arm (its robot name or joints differ).
    """
    import control

    if design.get("robot") != nominal.name or list(design.get("joints", [])) != \
            list(nominal.joint_names):
        raise ValueError(f"the design was tuned for {design.get('robot')!r} (joints "
                         f"{design.get('joints')}), not for {nominal.name!r} (joints "
                         f"{list(nominal.joint_names)}): tune one with rrr-pin design "
                         f"--robot ...")
    K = design.get("K")
    if K is not None and "per_joint" in K:
        K = [None if k is None else control.tf(k["num"], k["den"]) for k in K["per_joint"]]
    elif K is not None:
        K = control.tf(K["num"], K["den"])
    # lam_rad_s: a number, or a list of one per joint (checked by the law, naming the joint)
    return law_of(nominal, design.get("lam_rad_s"), K, name)
