r"""The paper's closed-form dynamics of the RRR arm, eq. (2)-(7), with its errata corrected.

The model is the paper's eq. (1), ``M(q) qdd + V(q, qd) + G(q) = tau``, written coefficient by
coefficient:

.. math::

    M = [D_{ij}], \qquad
    V_i = \sum_j D_{ijj} \dot q_j^2 + 2 \sum_{j<k} D_{ijk} \dot q_j \dot q_k, \qquad
    G = [D_1, D_2, D_3]^T,

so the ``D_ijk`` are the Christoffel symbols of the first kind of ``M``,

.. math::

    D_{ijk} = \tfrac12 \left( \frac{\partial D_{ij}}{\partial q_k}
        + \frac{\partial D_{ik}}{\partial q_j}
        - \frac{\partial D_{jk}}{\partial q_i} \right).

The coefficients below are the printed eq. (7) with every erratum corrected; each correction
carries a comment with what the paper printed and why it is wrong, and ``docs/errata.md``
records the evidence (a Lagrangian derivation and the comparison with Pinocchio).
:func:`printed_coefficients` keeps eq. (7) exactly as printed, for that record.

This module is the independent reference that the Pinocchio model (:mod:`rrr_pin.model.dynamics`) is
tested against. It holds for the paper's structure only (DH Table 1): link 1 vertical
(``a=0, d=l1, alpha=pi/2``), links 2 and 3 in the vertical plane (``a=l_i, d=0, alpha=0``), no
joint offsets, centres of mass on the link segments and principal axes along the DH frames
(the conventions of :mod:`rrr_pin.model.dh`). Gravity ``params.g`` points along ``-z`` of frame 0,
the joint-1 axis; that is why ``D1 = 0``.

References
----------
.. [1] The paper: "H-infinity control + feedback linearization of a 3-DOF RRR spatial serial
   mechanism", section 2, eq. (1)-(7), Tables 1 and 2.
.. [2] M. W. Spong, S. Hutchinson, M. Vidyasagar, *Robot Modeling and Control*, 2006, sec. 7.3
   (Christoffel symbols of the first kind).

"""

from __future__ import annotations

import math

import numpy as np

from ..validation import check_count, check_positive, check_vector
from .dh import ArmParams

__all__ = [
    "coefficients",
    "MAX_CHECK_SAMPLES",
    "printed_coefficients",
    "robot_coefficients",
    "M",
    "V",
    "G",
    "compare_with_pinocchio",
    "COEFFICIENT_NAMES",
]

#: Names of the coefficients of eq. (2)-(4): ``D1..D3`` (G), ``Dij`` with ``i <= j`` (M) and
#: ``Dijk`` with ``j <= k`` (V).
COEFFICIENT_NAMES = (
    tuple(f"D{i}" for i in (1, 2, 3))
    + tuple(f"D{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3) if i <= j)
    + tuple(f"D{i}{j}{k}" for i in (1, 2, 3) for j in (1, 2, 3) for k in (1, 2, 3) if j <= k)
)

_TOL = 1e-12  # slack on the structural DH values (they are exact in any sane parameter file)


def _check_params(params: ArmParams) -> None:
    """Raise ``ValueError`` unless ``params`` has the paper's RRR structure (Table 1)."""
    if not isinstance(params, ArmParams):
        raise ValueError(f"params must be an ArmParams, got {type(params).__name__}")
    if params.n != 3:
        raise ValueError(f"the closed form needs the paper's 3-link RRR arm, got {params.n} "
                         f"links")
    expected = (
        {"a": 0.0, "alpha": math.pi / 2},
        {"d": 0.0, "alpha": 0.0},
        {"d": 0.0, "alpha": 0.0},
    )
    for k, (link, fields) in enumerate(zip(params.links, expected, strict=True)):
        for name, value in {**fields, "theta_offset": 0.0}.items():
            got = getattr(link, name)
            if abs(got - value) > _TOL:
                raise ValueError(f"the closed form needs the paper's RRR structure (Table 1): "
                                 f"links[{k}].{name} must be {value!r}, got {got!r}")
    if params.links[0].d <= 0.0:
        raise ValueError(f"the closed form needs links[0].d = l1 > 0, got "
                         f"{params.links[0].d!r}")
    for k in (1, 2):
        if params.links[k].a <= 0.0:
            raise ValueError(f"the closed form needs links[{k}].a = l{k + 1} > 0, got "
                             f"{params.links[k].a!r}")


def coefficients(params: ArmParams, q) -> dict[str, float]:
    """Return the coefficients ``D_i, D_ij, D_ijk`` of eq. (7), corrected.

    Parameters
    ----------
    params : ArmParams
        An arm of the paper's RRR structure (DH Table 1; any masses, lengths, centres of mass,
        principal moments and ``g``). Uses ``params.m`` [kg], ``params.l`` [m], ``params.lg``
        [m], ``params.J`` (columns ``Jx, Jy, Jz``) [kg m^2] and ``params.g`` [m/s^2].
    q : array-like, shape (3,)
        Joint angles [rad].

    Returns
    -------
    dict of str to float
        One entry per name in :data:`COEFFICIENT_NAMES`: ``D1..D3`` [N m] (gravity, eq. 4),
        ``Dij`` for ``i <= j`` [kg m^2] (inertia, eq. 2; ``Dji = Dij``), and ``Dijk`` for
        ``j <= k`` [kg m^2] (Christoffel symbols of the first kind, eq. 3; ``Dikj = Dijk``).

    Raises
    ------
    ValueError
        ``params`` is not of the paper's RRR structure (naming the mismatching field), or ``q``
        has the wrong shape or is not finite.

    """
    _check_params(params)
    return _coefficients(params, check_vector("q", q, 3))


def _coefficients(params: ArmParams, q: np.ndarray) -> dict[str, float]:
    """:func:`coefficients` of checked ``params`` (RRR structure) and ``q`` (shape (3,))."""
    m, l, lg, J, g = params.m, params.l, params.lg, params.J, params.g  # noqa: E741
    m2, m3 = m[1], m[2]
    l2 = l[1]
    lg2, lg3 = lg[1], lg[2]
    (_, Jy1, _), (Jx2, Jy2, Jz2), (Jx3, Jy3, Jz3) = J
    _, q2, q3 = q
    c2, s2, c3, s3 = math.cos(q2), math.sin(q2), math.cos(q3), math.sin(q3)
    c23, s23 = math.cos(q2 + q3), math.sin(q2 + q3)
    # Horizontal distance of the link-3 centre of mass from the joint-1 axis, and its height
    # above joint 2.
    r3 = l2 * c2 + lg3 * c23
    h3 = l2 * s2 + lg3 * s23

    D = dict.fromkeys(COEFFICIENT_NAMES, 0.0)

    # Gravity, eq. (4). D1 = 0 because the joint-1 axis is vertical (parallel to gravity): the
    # potential energy does not depend on q1.
    # Erratum: the paper prints D2 = m2 lg2 cos(q2) + m3 (l2 cos(q2)) + lg3 cos(q2 + q3), without
    # g (the only G term with units of N m must carry it) and with the parenthesis closed too
    # early (lg3 cos(q2 + q3) is the link-3 lever arm, it must be multiplied by m3).
    D["D2"] = g * (m2 * lg2 * c2 + m3 * r3)
    # Erratum: the paper prints D3 = m3 lg3 cos(q2 + q3), without g.
    D["D3"] = g * m3 * lg3 * c23

    # Inertia matrix, eq. (2).
    # Erratum: the paper prints Jy3 cos^2(q2 + q2); the angle of link 3 is q2 + q3.
    D["D11"] = (Jx2 * s2**2 + Jx3 * s23**2 + Jy1 + Jy3 * c23**2
                + (Jy2 + m2 * lg2**2) * c2**2 + m3 * r3**2)
    D["D22"] = Jz2 + Jz3 + m2 * lg2**2 + m3 * (l2**2 + 2.0 * l2 * lg3 * c3 + lg3**2)
    D["D33"] = Jz3 + m3 * lg3**2
    D["D23"] = Jz3 + m3 * lg3 * (l2 * c3 + lg3)
    # D12 = D13 = 0: joints 2 and 3 move in the vertical plane through the joint-1 axis.

    # Centrifugal and Coriolis coefficients, eq. (3): D1jk = dD11/dq (1/2 where j != k, see
    # below), D211 = -dD11/dq2 / 2, D311 = -dD11/dq3 / 2, and the planar 2R terms in q3.
    # Erratum: the paper prints D112 = 1/2 sin(2(q2+q3)) (Jx3 - Jy3) + sin(2 q2) (Jx2 - Jy2 -
    # m2 lg2^2) - 2 m3 (l2 cos q2 + lg3 cos(q2+q3)) (l2 sin q2 + lg3 sin(q2+q3)), i.e. the 1/2
    # multiplies the first term only. With the explicit 2 in eq. (3), D112 must be the
    # Christoffel symbol 1/2 dD11/dq2: the factor 1/2 multiplies all three terms (the last two
    # are printed twice too large).
    D["D112"] = (0.5 * math.sin(2.0 * (q2 + q3)) * (Jx3 - Jy3)
                 + 0.5 * math.sin(2.0 * q2) * (Jx2 - Jy2 - m2 * lg2**2)
                 - m3 * r3 * h3)
    D["D113"] = s23 * (-m3 * l2 * lg3 * c2 + (Jx3 - Jy3 - m3 * lg3**2) * c23)
    # Erratum: the paper prints D211 = 1/2 (-Jx2 sin(2 q2)) + (Jy2 + m2 lg2^2) sin(2 q2) +
    # m3 (sin(2 q2)) l2^2 + 2 l2 lg3 sin(2 q2 + q3) + (-Jx3 + Jy3 + m3 lg3^2) sin(2 q2): the 1/2
    # must multiply every term, m3 must multiply 2 l2 lg3 sin(2 q2 + q3) as well, and the last
    # term's angle is 2 (q2 + q3), not 2 q2. Corrected, D211 = -D112 (Christoffel identity
    # D211 = -1/2 dD11/dq2, as D12 = 0).
    D["D211"] = 0.5 * (-Jx2 * math.sin(2.0 * q2)
                       + (Jy2 + m2 * lg2**2) * math.sin(2.0 * q2)
                       + m3 * (l2**2 * math.sin(2.0 * q2)
                               + 2.0 * l2 * lg3 * math.sin(2.0 * q2 + q3))
                       + (-Jx3 + Jy3 + m3 * lg3**2) * math.sin(2.0 * (q2 + q3)))
    # Erratum: the paper does not print D223 at all (its list of zeros names D123, D222, D212,
    # D213), so read literally eq. (3) misses the Coriolis torque -2 m3 l2 lg3 sin(q3) qd2 qd3
    # on joint 2. Christoffel: D223 = 1/2 dD22/dq3 = -m3 l2 lg3 sin(q3) (equal to D233).
    D["D223"] = -m3 * l2 * lg3 * s3
    D["D233"] = -m3 * l2 * lg3 * s3
    D["D311"] = (m3 * l2 * lg3 * c2 + (-Jx3 + Jy3 + m3 * lg3**2) * c23) * s23
    D["D322"] = m3 * l2 * lg3 * s3
    # All other Dijk are 0 (D111, D122, D133, D123, D212, D213, D222, D312, D313, D323, D333).
    return D


def printed_coefficients(params: ArmParams, q) -> dict[str, float]:
    """Return the coefficients of eq. (7) exactly as printed, errata included.

    For the errata record only (``docs/errata.md`` and the tests that show each erratum is
    real); use :func:`coefficients` for anything else. Printed expressions are read literally
    (operator precedence as typeset); ``D223``, which the paper does not print, is 0.

    Parameters
    ----------
    params : ArmParams
        An arm of the paper's RRR structure (see :func:`coefficients`).
    q : array-like, shape (3,)
        Joint angles [rad].

    Returns
    -------
    dict of str to float
        Same keys and units as :func:`coefficients` (the printed ``D2, D3`` lack ``g``, so
        they are in N m per m/s^2).

    """
    D = coefficients(params, q)
    m, l, lg, J = params.m, params.l, params.lg, params.J  # noqa: E741
    m2, m3, l2, lg2, lg3 = m[1], m[2], l[1], lg[1], lg[2]
    (_, Jy1, _), (Jx2, Jy2, _), (Jx3, Jy3, _) = J
    _, q2, q3 = np.asarray(q, dtype=float)
    c2, s2 = math.cos(q2), math.sin(q2)
    c23, s23 = math.cos(q2 + q3), math.sin(q2 + q3)
    D["D2"] = m2 * lg2 * c2 + m3 * (l2 * c2) + lg3 * c23
    D["D3"] = m3 * lg3 * c23
    D["D11"] = (Jx2 * s2**2 + Jx3 * s23**2 + Jy1 + Jy3 * math.cos(q2 + q2) ** 2
                + (Jy2 + m2 * lg2**2) * c2**2 + m3 * (l2 * c2 + lg3 * c23) ** 2)
    D["D112"] = (0.5 * math.sin(2.0 * (q2 + q3)) * (Jx3 - Jy3)
                 + math.sin(2.0 * q2) * (Jx2 - Jy2 - m2 * lg2**2)
                 - 2.0 * m3 * (l2 * c2 + lg3 * c23) * (l2 * s2 + lg3 * s23))
    D["D211"] = (0.5 * (-Jx2 * math.sin(2.0 * q2)) + (Jy2 + m2 * lg2**2) * math.sin(2.0 * q2)
                 + m3 * math.sin(2.0 * q2) * l2**2 + 2.0 * l2 * lg3 * math.sin(2.0 * q2 + q3)
                 + (-Jx3 + Jy3 + m3 * lg3**2) * math.sin(2.0 * q2))
    D["D223"] = 0.0
    return D


def _assemble_M(D: dict[str, float]) -> np.ndarray:
    return np.array([
        [D["D11"], D["D12"], D["D13"]],
        [D["D12"], D["D22"], D["D23"]],
        [D["D13"], D["D23"], D["D33"]],
    ])


def _assemble_V(D: dict[str, float], qd: np.ndarray) -> np.ndarray:
    b = np.array([[D[f"D{i}{j}{j}"] for j in (1, 2, 3)] for i in (1, 2, 3)])
    c = np.array([[D[f"D{i}{j}{k}"] for j, k in ((1, 2), (1, 3), (2, 3))] for i in (1, 2, 3)])
    qd1, qd2, qd3 = qd
    return b @ qd**2 + 2.0 * c @ np.array([qd1 * qd2, qd1 * qd3, qd2 * qd3])


def M(params: ArmParams, q) -> np.ndarray:
    """Inertia matrix, eq. (2), from the corrected coefficients of eq. (7).

    Parameters
    ----------
    params : ArmParams
        An arm of the paper's RRR structure (see :func:`coefficients`).
    q : array-like, shape (3,)
        Joint angles [rad].

    Returns
    -------
    M : ndarray, shape (3, 3)
        Symmetric positive definite inertia matrix ``[D_ij]`` [kg m^2].

    """
    return _assemble_M(coefficients(params, q))


def V(params: ArmParams, q, qd) -> np.ndarray:
    r"""Centrifugal and Coriolis torques, eq. (3), from the corrected coefficients of eq. (7).

    .. math::

        V = [D_{ijj}] \, [\dot q_1^2, \dot q_2^2, \dot q_3^2]^T
            + 2 \, [D_{ijk}]_{j<k} \, [\dot q_1 \dot q_2, \dot q_1 \dot q_3,
            \dot q_2 \dot q_3]^T

    Parameters
    ----------
    params : ArmParams
        An arm of the paper's RRR structure (see :func:`coefficients`).
    q : array-like, shape (3,)
        Joint angles [rad].
    qd : array-like, shape (3,)
        Joint velocities [rad/s].

    Returns
    -------
    V : ndarray, shape (3,)
        Joint torques [N m].

    """
    qd = check_vector("qd", qd, 3)
    return _assemble_V(coefficients(params, q), qd)


def G(params: ArmParams, q) -> np.ndarray:
    """Gravity torques, eq. (4), ``[D1, D2, D3]^T`` from the corrected eq. (7).

    Parameters
    ----------
    params : ArmParams
        An arm of the paper's RRR structure (see :func:`coefficients`); gravity
        ``params.g`` [m/s^2] along ``-z`` of frame 0.
    q : array-like, shape (3,)
        Joint angles [rad].

    Returns
    -------
    G : ndarray, shape (3,)
        Joint torques [N m].

    """
    D = coefficients(params, q)
    return np.array([D["D1"], D["D2"], D["D3"]])


def robot_coefficients(robot, q) -> dict[str, float]:
    """Return the same named coefficients, extracted from a 3-joint Pinocchio model.

    ``Dij`` and ``Di`` are read from the model's ``M(q)`` and ``G(q)``; the Christoffel
    symbols from ``V`` by polarization, ``D_ijj = V_i(q, e_j)`` and
    ``2 D_ijk = V_i(q, e_j + e_k) - V_i(q, e_j) - V_i(q, e_k)`` (``V`` is a quadratic form in
    ``qd``), with ``e_j`` the unit joint velocities.

    Parameters
    ----------
    robot : rrr_pin.model.dynamics.Robot
        A model with 3 joints (e.g. ``load_robot(params, gravity=params.g)``).
    q : array-like, shape (3,)
        Joint angles [rad].

    Returns
    -------
    dict of str to float
        Keys and units as :func:`coefficients`.

    """
    if robot.nq != 3:
        raise ValueError(f"robot must have 3 joints to compare with the closed form, got "
                         f"{robot.nq}")
    q = check_vector("q", q, 3)
    Mq, Gq = robot.M(q), robot.G(q)
    e = np.eye(3)
    Vjj = [robot.V(q, e[j]) for j in range(3)]
    D = {}
    for i in range(3):
        D[f"D{i + 1}"] = float(Gq[i])
        for j in range(3):
            if i <= j:
                D[f"D{i + 1}{j + 1}"] = float(Mq[i, j])
            D[f"D{i + 1}{j + 1}{j + 1}"] = float(Vjj[j][i])
    for j, k in ((0, 1), (0, 2), (1, 2)):
        Vjk = robot.V(q, e[j] + e[k]) - Vjj[j] - Vjj[k]
        for i in range(3):
            D[f"D{i + 1}{j + 1}{k + 1}"] = 0.5 * float(Vjk[i])
    return D


#: Largest number of random states of :func:`compare_with_pinocchio` (about 1 minute; each is
#: kept for the comparison's report).
MAX_CHECK_SAMPLES = 10**6


def compare_with_pinocchio(robot, params: ArmParams, samples: int = 200, seed: int = 0,
                           qd_max: float = 5.0) -> dict[str, dict[str, float]]:
    """Largest differences between a Pinocchio model and the closed form on random states.

    States: ``q`` uniform in ``[-pi, pi]^3``, ``qd`` uniform in ``[-qd_max, qd_max]^3``, drawn
    from ``np.random.default_rng(seed)``.

    Parameters
    ----------
    robot : rrr_pin.model.dynamics.Robot
        The Pinocchio model (3 joints), with its own gravity.
    params : ArmParams
        The parameter set of the closed form (paper's RRR structure).
    samples : int, default 200
        Number of random states, >= 1.
    seed : int, default 0
        Seed of the random states.
    qd_max : float, default 5
        Largest joint speed [rad/s].

    Returns
    -------
    dict
        For each of ``"M"``, ``"V"`` and ``"G"``: ``{"abs": a, "scale": s, "rel": a / s}``
        with ``a`` the largest absolute entry difference over all states [kg m^2 or N m],
        ``s`` the largest absolute entry of the Pinocchio quantity over all states (same unit)
        and ``rel = a / s`` the norm-wise relative difference (entry-wise ratios are useless
        here: ``D12 = D1 = 0`` exactly). If ``s == 0``, ``rel`` is 0 when ``a == 0`` and
        ``inf`` otherwise.

    Raises
    ------
    ValueError
        ``params`` is not of the paper's RRR structure, ``robot`` does not have 3 joints,
        ``samples`` is not an integer >= 1, ``seed`` not an integer >= 0, or ``qd_max`` not
        finite and >= 0.

    """
    _check_params(params)
    if robot.nq != 3:
        raise ValueError(f"robot must have 3 joints to compare with the closed form, got "
                         f"{robot.nq}")
    samples = check_count("samples", samples, 1, high=MAX_CHECK_SAMPLES)
    seed = check_count("seed", seed, 0)
    qd_max = check_positive("qd_max", qd_max, allow_zero=True, unit="rad/s")
    rng = np.random.default_rng(seed)
    qs = rng.uniform(-math.pi, math.pi, size=(samples, 3))
    qds = rng.uniform(-qd_max, qd_max, size=(samples, 3))
    diff = {"M": 0.0, "V": 0.0, "G": 0.0}
    scale = {"M": 0.0, "V": 0.0, "G": 0.0}
    for q, qd in zip(qs, qds, strict=True):
        # Checked once above: the rows of qs and qds are finite float64 arrays of shape (3,).
        D = _coefficients(params, q)
        pairs = {
            "M": (_assemble_M(D), robot.M(q, check=False)),
            "V": (_assemble_V(D, qd), robot.V(q, qd, check=False)),
            "G": (np.array([D["D1"], D["D2"], D["D3"]]), robot.G(q, check=False)),
        }
        for key, (closed, pin_value) in pairs.items():
            diff[key] = max(diff[key], float(np.max(np.abs(closed - pin_value))))
            scale[key] = max(scale[key], float(np.max(np.abs(pin_value))))
    out = {}
    for key in diff:
        if scale[key] > 0.0:
            rel = diff[key] / scale[key]
        else:
            rel = 0.0 if diff[key] == 0.0 else math.inf
        out[key] = {"abs": diff[key], "scale": scale[key], "rel": rel}
    return out
