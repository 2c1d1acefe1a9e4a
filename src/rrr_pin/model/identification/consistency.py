r"""Physically consistent standard parameters from estimated base ones (Wensing, Kim & Slotine).

A body's parameters are those of a mass distribution exactly when its pseudo-inertia

.. math:: J = \begin{bmatrix} \tfrac12 \operatorname{tr}(I) 1 - I & m c \\ m c^T & m
          \end{bmatrix} \succeq 0 .

:func:`consistent_parameters` solves two semidefinite programs (cvxpy, Clarabel), with
``J_b >= eps_b 1`` (``eps_b = 1e-6`` of the largest eigenvalue of the nominal body's ``J``, a
margin so that the URDF written passes the strict checks): the base parameters as close to the
estimate as the constraint allows (in the metric of the estimate's covariance; the estimate
itself when it is consistent, up to the margin), then, among those, the standard parameters
closest to the nominal URDF's (each relative to its nominal size), which fixes the directions
that the data cannot see.

References
----------
.. [1] P. M. Wensing, S. Kim and J.-J. E. Slotine, "Linear matrix inequalities for physically
   consistent inertial parameter identification: a statistical perspective on the mass
   distribution", IEEE RA-L 3(1), 2017.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

from ...validation import FieldError
from .regressors import BaseParameters, IdentificationError

__all__ = [
    "SolverAccuracyWarning",
    "PSEUDO_INERTIA_MARGIN",
    "CONSISTENCY_CONFIDENCE",
    "pseudo_inertia",
    "pseudo_inertia_lmis",
    "parameter_weights",
    "plausible_set",
    "consistent_parameters",
    "urdf_with_parameters",
]

#: Margin of the pseudo-inertias, relative to the largest eigenvalue of the nominal body's.
PSEUDO_INERTIA_MARGIN = 1e-6

#: Confidence of the region outside which no consistent arm may lie (else: refused).
CONSISTENCY_CONFIDENCE = 0.999


# --- physical consistency ---------------------------------------------------------------------

def pseudo_inertia(phi_body) -> np.ndarray:
    """Pseudo-inertia ``J`` (shape (4, 4)) of one body's 10 standard parameters (Wensing 2017)."""
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = np.asarray(phi_body, dtype=float)
    I = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    J = np.zeros((4, 4))
    J[:3, :3] = 0.5 * np.trace(I) * np.eye(3) - I
    J[:3, 3] = J[3, :3] = (hx, hy, hz)
    J[3, 3] = m
    return J


def _pseudo_inertia_basis() -> np.ndarray:
    """``A[i]`` (shape (10, 4, 4)): ``J = sum_i phi_i A[i]``."""
    return np.array([pseudo_inertia(e) for e in np.eye(10)])


def pseudo_inertia_lmis(phi_var, nb: int, margins):
    """Return the LMIs ``J_b(phi) >= margins[b] 1`` (cvxpy) of the ``nb`` bodies of ``phi_var``."""
    A = _pseudo_inertia_basis()
    out = []
    for b in range(nb):
        J = sum(phi_var[10 * b + i] * A[i] for i in range(10))
        out.append(0.5 * (J + J.T) >> margins[b] * np.eye(4))
    return out


def _margins(phi0) -> np.ndarray:
    nb = len(phi0) // 10
    return np.array([PSEUDO_INERTIA_MARGIN * max(np.linalg.eigvalsh(
        pseudo_inertia(phi0[10 * b:10 * b + 10]))[-1], 1e-12) for b in range(nb)])


def parameter_weights(phi0) -> np.ndarray:
    """Per-parameter weights 1 / size: the nominal's, floored at 1e-3 of its body's largest."""
    w = np.empty_like(phi0)
    for b in range(len(phi0) // 10):
        x = np.abs(phi0[10 * b:10 * b + 10])
        w[10 * b:10 * b + 10] = 1.0 / np.maximum(x, 1e-3 * max(x.max(), 1e-12))
    return w


class SolverAccuracyWarning(UserWarning):
    """cvxpy's solver ended short of its tolerances on a consistency SDP (its status says which).

    Issued with one fixed message per kind of problem, so Python's default filter prints it
    once per process and problem, where cvxpy printed its own words at every draw; the
    solution is still checked by the caller (consistency, distance) before it is used.
    """


#: The problems whose inaccurate solution this process has warned about.
_WARNED: set = set()


def _solve(problem, what: str):
    import warnings

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            problem.solve(solver="CLARABEL")
    except Exception as exc:  # cvxpy.SolverError: say which problem
        raise IdentificationError(f"the consistency SDP ({what}) failed: {exc}") from None
    if any("inaccurate" in str(w.message) for w in caught) and what not in _WARNED:
        _WARNED.add(what)  # a set, not the registry: catch_warnings resets the registries
        warnings.warn(f"the consistency SDP ({what}): Clarabel's solution may be inaccurate "
                      f"(cvxpy's status 'optimal_inaccurate'; shown once per process)",
                      SolverAccuracyWarning, stacklevel=2)
    for w in caught:  # anything else is passed on as it came
        if "inaccurate" not in str(w.message):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return problem.status


def plausible_set(phi_var, phi0, *, mass_band: float | None = None,
                  inertia_band: float | None = None) -> list:
    r"""Return the cvxpy constraints of the plausibility bands around nominal parameters.

    ``mass_band = f``: ``m0_b / f <= m_b <= f m0_b``. ``inertia_band = f``:

    .. math:: J_{0,b} / f \preceq J_b(\phi) \preceq f J_{0,b}

    for every body (``J0_b`` the pseudo-inertia of ``phi0``'s body): the mass, the first
    moments and the second moments (hence the inertia about any axis) stay within a factor
    ``f`` of the nominal's, in every direction.

    Raises
    ------
    rrr_pin.validation.FieldError
        A band that is not a finite factor > 1.
    """
    out = []
    for key, f in (("mass_band", mass_band), ("inertia_band", inertia_band)):
        if f is not None and not (math.isfinite(f) and f > 1.0):
            raise FieldError(key, "{name} must be a finite factor > 1 (within [x0 / f, f x0] "
                             f"of the nominal), got {f!r}")
    if mass_band is not None:
        m0 = phi0[0::10]
        out += [phi_var[0::10] >= m0 / mass_band, phi_var[0::10] <= m0 * mass_band]
    if inertia_band is not None:
        A = _pseudo_inertia_basis()
        for b in range(len(phi0) // 10):
            J = sum(phi_var[10 * b + i] * A[i] for i in range(10))
            J = 0.5 * (J + J.T)
            J0 = pseudo_inertia(phi0[10 * b:10 * b + 10])
            out += [J - J0 / inertia_band >> 0, inertia_band * J0 - J >> 0]
    return out


def consistent_parameters(base: BaseParameters, theta, A, phi0, *, sigma: float | None = None,
                          confidence: float = CONSISTENCY_CONFIDENCE, refuse: bool = True,
                          mass_band: float | None = None, inertia_band: float | None = None):
    r"""Find the standard parameters of a physically consistent arm nearest to estimated base ones.

    Stage 1: ``t* = min ||A (K phi - theta)||`` over ``phi`` with every pseudo-inertia
    ``J_b >= eps_b 1``. Stage 2: ``min ||w (phi - phi0)||`` with ``||A (K phi - theta)|| <=
    t* + 1e-6 ||A theta||`` and the same LMIs (``w``: :func:`parameter_weights`); if the solver
    fails on stage 2, stage 1's arm is kept and ``info["stage2"]`` says so.

    Parameters
    ----------
    base : BaseParameters
    theta : ndarray, shape (p,)
        Estimated base parameters.
    A : ndarray, shape (p, p)
        Metric: ``A^T A = W^T W / rows`` of the (weighted) base regressor, so ``||A d||`` is the
        RMS torque change [N m] that the change ``d`` makes over the data.
    phi0 : ndarray, shape (10 nq,)
        Nominal standard parameters (the URDF's), for the directions the data cannot see.
    sigma : float, optional
        Noise level of ``||A d||`` (``sigma / sqrt(rows)`` of the fit); with it, a nearest
        consistent point outside the ``confidence`` region of the estimate is refused, unless
        its distance is below ``10 PSEUDO_INERTIA_MARGIN ||A theta||`` (what the margin alone
        can cost: an estimate on the boundary, e.g. noise-free data of thin rods).
    refuse : bool, default True
        ``False``: such a point is kept with a warning (``info["outside_confidence"]``), for
        real logs whose model error (friction, flexibility) the noise model does not cover.
    mass_band : float, optional
        Plausibility bound ``f > 1``: every body's mass within ``[m0 / f, f m0]`` of the
        nominal's ``m0`` (both stages). Default: no bound beyond positive definiteness.
    inertia_band : float, optional
        Plausibility bound ``f > 1`` on the whole body: ``J0_b / f <= J_b <= f J0_b`` in the
        Loewner order, ``J0_b`` the nominal's pseudo-inertia (both stages;
        :func:`plausible_set`).

    Returns
    -------
    phi : ndarray, shape (10 nq,)
    info : dict
        ``distance_rms_Nm`` (``t*``, stage 1's optimum), ``mahalanobis`` (``t* / sigma``, or
        None), ``distance_returned_rms_Nm`` and ``mahalanobis_returned``: the same for the arm
        returned (stage 2's, within ``1e-6 ||A theta||`` of stage 1's), statuses.

    Raises
    ------
    IdentificationError
        The SDP is infeasible or fails, or (with ``sigma``) no consistent arm lies inside the
        ``confidence`` region of the estimate.
    """
    import cvxpy as cp
    from scipy.stats import chi2

    phi0 = np.asarray(phi0, dtype=float)
    nb = len(phi0) // 10
    margins = _margins(phi0)
    if inertia_band is not None:
        # J >= J0 / f already keeps J positive semi-definite; a margin above lambda_min(J0) / f
        # would refuse the nominal itself when its bodies are thin (rods: J0 of rank 2)
        margins = np.array([min(margins[b], max(np.linalg.eigvalsh(pseudo_inertia(
            phi0[10 * b:10 * b + 10]))[0], 0.0) / inertia_band) for b in range(nb)])
    phi = cp.Variable(len(phi0))
    resid = A @ (base.K @ phi) - A @ theta
    lmis = pseudo_inertia_lmis(phi, nb, margins)
    lmis = lmis + plausible_set(phi, phi0, mass_band=mass_band, inertia_band=inertia_band)
    p1 = cp.Problem(cp.Minimize(cp.norm(resid)), lmis)
    status = _solve(p1, "nearest consistent base parameters")
    # An inaccurate end is kept only when its point checks: every pseudo-inertia positive
    # semi-definite (then t* is the measured distance of a consistent arm, an upper bound on
    # the optimum); the status is recorded in info["stage1"].
    def psd(v):  # round-off of a rank-deficient (thin-rod) body: 1e-9 of its largest
        w = np.linalg.eigvalsh(pseudo_inertia(v))
        return w[0] >= -1e-9 * max(w[-1], 0.0)

    if status == "optimal_inaccurate" and phi.value is not None and all(
            psd(np.asarray(phi.value, float)[10 * b:10 * b + 10]) for b in range(nb)):
        status1 = "optimal_inaccurate: kept, every pseudo-inertia checked positive semi-definite"
        p1_value = float(np.linalg.norm(A @ (base.K @ np.asarray(phi.value, float) - theta)))
    elif status == "optimal":
        status1 = "optimal"
        p1_value = float(p1.value)
    else:
        status1 = f"{status} (its point not checked consistent)"
    if not status1.startswith("optimal") or "not checked" in status1:
        raise IdentificationError(f"the consistency SDP (nearest consistent base parameters) "
                                  f"ended {status!r}: no physically consistent arm found")
    t_star = p1_value
    scale = float(np.linalg.norm(A @ theta))
    mahal = None
    if sigma is not None and sigma > 0.0:
        mahal = t_star / sigma
        limit = math.sqrt(chi2.ppf(confidence, base.p))
        outside = bool(mahal > limit and t_star > 10.0 * PSEUDO_INERTIA_MARGIN * scale)
        if outside and not refuse:
            import warnings

            warnings.warn(f"the nearest physically consistent arm lies at Mahalanobis "
                          f"distance {mahal:.4g} from the estimate, outside its "
                          f"{confidence:.1%} confidence region (RMS torque change "
                          f"{t_star:.4g} N m): kept, as asked", stacklevel=3)
        elif outside:
            raise IdentificationError(
                f"infeasible consistency problem: no physically consistent arm (every body's "
                f"pseudo-inertia positive semi-definite) has base parameters inside the "
                f"{confidence:.1%} confidence region of the estimate; the nearest lies at "
                f"Mahalanobis distance {mahal:.4g} > {limit:.4g} (RMS torque change "
                f"{t_star:.4g} N m). The data do not fit a rigid arm with this URDF's "
                f"kinematics: check the joint order, torque signs and units, and unmodelled "
                f"friction or payload; to keep the nearest consistent arm anyway: "
                f"refuse_inconsistent=False (command line: --keep-inconsistent)")
    phi1 = np.asarray(phi.value, dtype=float)
    p2 = cp.Problem(cp.Minimize(cp.norm(cp.multiply(parameter_weights(phi0), phi - phi0))),
                    [cp.norm(resid) <= t_star + 1e-6 * scale] + lmis)
    try:
        status2 = _solve(p2, "nearest standard parameters")
    except IdentificationError:
        status2 = "solver_error"
    # Stage 2 only chooses among equally good arms: if it fails, stage 1's arm is kept. An
    # inaccurate end (real logs: parameters over 6 decades) is kept when it checks: every
    # pseudo-inertia positive semi-definite and the torque change within 1e-5 ||A theta||.
    if status2 == "optimal_inaccurate" and phi.value is not None:
        cand = np.asarray(phi.value, dtype=float)
        ok = all(np.linalg.eigvalsh(pseudo_inertia(cand[10 * b:10 * b + 10])).min() >= 0.0
                 for b in range(nb))
        if ok and np.linalg.norm(A @ (base.K @ cand - theta)) <= t_star + 1e-5 * scale:
            status2 = "optimal"
            phi.value = cand
    out = np.asarray(phi.value, dtype=float) if status2 == "optimal" else phi1
    # Where the arm returned sits (stage 2 may move up to 1e-6 ||A theta|| beyond stage 1).
    final = float(np.linalg.norm(A @ (base.K @ out - theta)))
    return out, {"stage1": status1, "stage2": status2 if status2 == "optimal" else
                 f"{status2}: kept the stage-1 arm",
        "distance_rms_Nm": t_star, "mahalanobis": mahal,
        "distance_returned_rms_Nm": final, "mass_band": mass_band,
        "inertia_band": inertia_band,
        "bounded": "; ".join(
            ([f"every body's mass in [m0 / {mass_band:g}, {mass_band:g} m0] of the nominal "
              f"URDF's"] if mass_band else [])
            + ([f"every body's pseudo-inertia between J0 / {inertia_band:g} and "
                f"{inertia_band:g} J0 of the nominal URDF's (mass, first and second moments)"]
               if inertia_band else [])) or "pseudo-inertia only",
        "outside_confidence": bool(
            sigma is not None and sigma > 0.0 and mahal > math.sqrt(chi2.ppf(confidence, base.p))
            and t_star > 10.0 * PSEUDO_INERTIA_MARGIN * scale),
        "mahalanobis_returned": None if mahal is None else final / sigma,
        "feasible_at_estimate":
        bool(t_star <= 1e-6 * max(scale, 1e-300)), "pseudo_inertia_margins": margins.tolist()}


def urdf_with_parameters(urdf: str, links, phi, *, moving=None, friction=None,
                         locked=None) -> str:
    """Return the URDF text with each moving body's inertial replaced by standard parameters.

    Parameters
    ----------
    urdf : str
        The nominal URDF text (kinematics kept as is).
    links : sequence of str, shape (nq,)
        The body links (:func:`body_links`), each given the body's whole inertial (in the link
        frame, which is the joint frame); every other link fixed to it loses its
        ``<inertial>`` (Pinocchio had merged it into the body).
    phi : ndarray, shape (10 nq,)
        Standard parameters, Pinocchio's order.
    moving : sequence of str, optional
        The model's joints; any other non-fixed joint of the URDF is locked (Pinocchio merged
        its child into the body) and treated as fixed. Default: every joint.
    friction : dict, optional
        ``{joint: {"viscous_Nms_rad", "coulomb_Nm", ...}}``: written as each joint's
        ``<dynamics damping=... friction=...>`` (URDF's viscous and Coulomb coefficients; the
        offset has no URDF field and stays in ``identification.json``; a negative coefficient,
        which URDF readers refuse and which would feed energy in, is written as 0, the
        nearest admissible value, and stays as estimated in the JSON, warned).
    locked : dict, optional
        ``{joint: value}`` [rad or m]: each written as a ``fixed`` joint at that value (its
        motion folded into its ``<origin>``; ``<axis>``, ``<limit>``, ``<mimic>`` and
        ``<dynamics>`` dropped), so the URDF loads as the arm it was identified as, without
        the locks repeated.

    Returns
    -------
    str
        URDF text; its inertials are checked by
        :func:`rrr_pin.model.urdf_checks.check_urdf_inertials` (raises ``RobotModelError``).
    """
    from ..urdf_checks import check_urdf_inertials

    root = ET.fromstring(urdf)
    by_name = {link.get("name"): link for link in root.findall("link")}
    children = {}
    for joint in root.findall("joint"):
        children.setdefault(joint.find("parent").get("link"), []).append(joint)
    for b, name in enumerate(links):
        inertia = pin.Inertia.FromDynamicParameters(np.asarray(phi[10 * b:10 * b + 10], float))
        stack = [name]
        while stack:  # links fixed to the body: their inertial is now in the body's
            current = stack.pop()
            for joint in children.get(current, []):
                if joint.get("type") == "fixed" or (
                        moving is not None and joint.get("name") not in moving):
                    child = joint.find("child").get("link")
                    el = by_name[child].find("inertial")
                    if el is not None:
                        by_name[child].remove(el)
                    stack.append(child)
        link = by_name[name]
        old = link.find("inertial")
        index = list(link).index(old) if old is not None else 0
        if old is not None:
            link.remove(old)
        el = ET.Element("inertial")
        c, Ic = inertia.lever, inertia.inertia
        ET.SubElement(el, "origin", xyz=" ".join(repr(float(x)) for x in c), rpy="0 0 0")
        ET.SubElement(el, "mass", value=repr(float(inertia.mass)))
        ET.SubElement(el, "inertia", **{k: repr(float(Ic[i, j])) for k, (i, j) in (
            ("ixx", (0, 0)), ("ixy", (0, 1)), ("ixz", (0, 2)), ("iyy", (1, 1)),
            ("iyz", (1, 2)), ("izz", (2, 2)))})
        link.insert(index, el)
    for joint in root.findall("joint"):
        f = (friction or {}).get(joint.get("name"))
        if f is None:
            continue
        # URDF: >= 0; a negative estimate is written as 0 (not left at the nominal's value)
        values = {"damping": max(float(f["viscous_Nms_rad"]), 0.0),
                  "friction": max(float(f["coulomb_Nm"]), 0.0)}
        el = joint.find("dynamics")
        if el is None:
            el = ET.SubElement(joint, "dynamics")
        for k, v in values.items():
            el.set(k, repr(v))
    for joint in root.findall("joint"):
        if joint.get("name") in (locked or {}):
            _fix_joint(joint, float(locked[joint.get("name")]))
    text = ET.tostring(root, encoding="unicode")
    check_urdf_inertials(text)
    return text


def _fix_joint(joint, value: float) -> None:
    """Make a URDF ``<joint>`` fixed at ``value`` [rad or m] (its motion into its origin)."""
    origin = joint.find("origin")
    xyz = [float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None
                              else "0 0 0").split()]
    rpy = [float(v) for v in (origin.get("rpy", "0 0 0") if origin is not None
                              else "0 0 0").split()]
    axis_el = joint.find("axis")
    axis = np.array([float(v) for v in (axis_el.get("xyz", "1 0 0") if axis_el is not None
                                        else "1 0 0").split()])
    axis = axis / np.linalg.norm(axis)
    M = pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(xyz))
    if joint.get("type") == "prismatic":
        motion = pin.SE3(np.eye(3), value * axis)
    else:
        motion = pin.SE3(pin.AngleAxis(value, axis).matrix(), np.zeros(3))
    M = M * motion
    for tag in ("axis", "limit", "mimic", "dynamics", "calibration", "safety_controller"):
        for el in joint.findall(tag):
            joint.remove(el)
    if origin is None:
        origin = ET.SubElement(joint, "origin")
    origin.set("xyz", " ".join(repr(float(v)) for v in M.translation))
    origin.set("rpy", " ".join(repr(float(v)) for v in pin.rpy.matrixToRpy(M.rotation)))
    joint.set("type", "fixed")


# --- estimation -------------------------------------------------------------------------------
