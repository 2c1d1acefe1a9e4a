r"""The planar 5-bar of the DexTAR class: parameters, kinematics, MJCF and task path.

In the vertical ``x-z`` plane. Base joints ``A1 = (-d/2, 0)``, ``A2 = (d/2, 0)`` (in ``x, z``),
axes along ``-y``, so an angle turns ``+x`` towards ``+z``. Coordinates
``q = (qa1, qp1, qa2, qp2)``: ``qa_i`` the absolute angle of proximal link ``i`` from ``+x``,
``qp_i`` the angle of distal link ``i`` relative to it. Elbows ``E_i = A_i + l1 u(qa_i)``,
tip ``P = E_i + l2 u(qa_i + qp_i)`` with ``u(a) = (cos a, sin a)``. Working mode: the left
elbow turned outward (``qa1 = atan2(P - A1) + beta_1``), the right one too
(``qa2 = atan2(P - A2) - beta_2``); assembly mode: the tip above the line ``E1 E2``. The loop
closes iff the elbows are at most ``2 l2`` apart; it is a type-II (parallel) singularity when
the distal links are aligned.

Task path (the study's reference): a circle of :data:`CIRCLE_RADIUS` through ``home``, its
centre above it, run once per period with a quintic time law (:func:`circle_point`).

References
----------
.. [1] L. Campos, F. Bourbonnais, I. Bonev, P. Bigras, "Development of a five-bar parallel
   robot with large workspace", ASME IDETC 2010 (the DexTAR).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .base import (
    DISTAL_RGBA,
    LINK_RGBA,
    Mechanism,
    MechanismError,
    check_params,
    closures,
    cylinder,
    inertial,
    num,
    quintic,
)

__all__ = ["FiveBarParams", "FiveBar", "FIVEBAR", "fivebar_ik", "fivebar_fk", "fivebar_elbows",
           "circle_point", "CIRCLE_RADIUS"]

#: Radius [m] of the 5-bar's task circle.
CIRCLE_RADIUS = 0.05


@dataclass(frozen=True)
class FiveBarParams:
    """A planar 5-bar in the ``x-z`` plane (module docstring), lengths [m], masses [kg].

    Parameters
    ----------
    d : float
        Distance between the two actuated base joints [m].
    l1, l2 : float
        Proximal and distal link lengths [m].
    m1, m2 : float
        Proximal and distal link masses [kg].
    radius : float
        Link cylinder radius [m] (inertia and drawing).
    home_x, home_z : float
        Tip position of the ``home`` keyframe [m].
    name : str
        Model name.
    """

    d: float = 0.12
    l1: float = 0.23
    l2: float = 0.23
    m1: float = 0.5
    m2: float = 0.3
    radius: float = 0.01
    home_x: float = 0.0
    home_z: float = 0.32
    name: str = "fivebar"

    def __post_init__(self) -> None:
        check_params(self)
        if self.d >= 2.0 * (self.l1 + self.l2):
            raise MechanismError(
                f"5-bar loop cannot close: base distance d = {self.d:g} m is at least "
                f"2 (l1 + l2) = {2.0 * (self.l1 + self.l2):g} m (triangle inequality)")



def fivebar_ik(params: FiveBarParams, p) -> np.ndarray:
    """Actuated angles ``(qa1, qa2)`` [rad] putting the 5-bar's tip at ``p = (x, z)`` [m].

    Working mode of the module docstring. Raises :class:`MechanismError` if ``p`` is out of
    reach of a leg (``|P - A_i|`` outside ``[|l1 - l2|, l1 + l2]``).
    """
    x, z = (float(v) for v in p)
    out = []
    for sign, ax in ((1.0, -0.5 * params.d), (-1.0, 0.5 * params.d)):
        cx, cz = x - ax, z
        rho = math.hypot(cx, cz)
        c = (params.l1 ** 2 + rho ** 2 - params.l2 ** 2) / (2.0 * params.l1 * rho) if rho else 2
        if not -1.0 <= c <= 1.0:
            raise MechanismError(f"5-bar tip ({x:g}, {z:g}) m is out of reach of the "
                                 f"{'left' if sign > 0 else 'right'} leg ({rho:.4g} m from "
                                 f"its base joint, reach [{abs(params.l1 - params.l2):g}, "
                                 f"{params.l1 + params.l2:g}] m)")
        out.append(math.atan2(cz, cx) + sign * math.acos(c))
    return np.array(out)


def fivebar_elbows(params: FiveBarParams, qa) -> tuple[np.ndarray, np.ndarray]:
    """Elbow points ``E1, E2`` (``x, z``) [m] of actuated angles ``qa`` [rad]."""
    e1 = np.array([-0.5 * params.d + params.l1 * math.cos(qa[0]), params.l1 * math.sin(qa[0])])
    e2 = np.array([0.5 * params.d + params.l1 * math.cos(qa[1]), params.l1 * math.sin(qa[1])])
    return e1, e2


def fivebar_fk(params: FiveBarParams, qa) -> np.ndarray:
    """Tip ``(x, z)`` [m] of actuated angles ``qa = (qa1, qa2)`` [rad] (assembly mode: up).

    The intersection of the circles of radius ``l2`` about the elbows; :class:`MechanismError`
    if the elbows are more than ``2 l2`` apart (the loop cannot close) or coincide.
    """
    e1, e2 = fivebar_elbows(params, qa)
    w = e2 - e1
    dist = float(np.hypot(*w))
    if not 0.0 < dist <= 2.0 * params.l2:
        raise MechanismError(f"5-bar loop cannot close at qa = {np.asarray(qa)} rad: elbows "
                             f"{dist:.6g} m apart, distal links reach 2 l2 = "
                             f"{2.0 * params.l2:g} m")
    h = math.sqrt(max(params.l2 ** 2 - 0.25 * dist * dist, 0.0))
    return 0.5 * (e1 + e2) + h * np.array([-w[1], w[0]]) / dist



def circle_point(params: FiveBarParams, t, period: float, radius: float = CIRCLE_RADIUS
                 ) -> np.ndarray:
    """Tip position ``(x, z)`` [m], shape (len(t), 2), of the 5-bar's circle at times ``t``.

    A circle of ``radius`` through ``home``, its centre ``radius`` above it, run once in
    ``period`` with a quintic time law (at rest at both ends).
    """
    s = quintic(np.atleast_1d(np.asarray(t, dtype=float)) / period)
    a = 2.0 * math.pi * s
    return np.column_stack([params.home_x + radius * np.sin(a),
                            params.home_z + radius - radius * np.cos(a)])


class FiveBar(Mechanism):
    """The planar 5-bar (module docstring); its one instance is :data:`FIVEBAR`."""

    name = "fivebar"
    title = "planar 5-bar"
    params = FiveBarParams
    path_label = "tip circle (reference)"
    lengths = ("d", "l1", "l2")

    def ik(self, params, p) -> np.ndarray:
        """:func:`fivebar_ik`."""
        return fivebar_ik(params, p)

    def fk(self, params, qa) -> np.ndarray:
        """:func:`fivebar_fk`."""
        return fivebar_fk(params, qa)

    def elbows(self, params, qa) -> list:
        """Return the two elbow points ``(x, z)`` [m] (:func:`fivebar_elbows`)."""
        return list(fivebar_elbows(params, qa))

    def home(self, params) -> np.ndarray:
        """Return ``(qa1, qp1, qa2, qp2)`` [rad] of the ``home`` tip point."""
        p = np.array([params.home_x, params.home_z])
        qa = fivebar_ik(params, p)
        q = []
        for a, e in zip(qa, fivebar_elbows(params, qa), strict=True):
            q += [a, math.remainder(math.atan2(p[1] - e[1], p[0] - e[0]) - a, 2.0 * math.pi)]
        return np.array(q)

    def body(self, params) -> list[str]:
        """Return the MJCF lines: two legs of two links, the tips joined, two base motors."""
        rho = params.radius
        out = ['  <worldbody>',
               '    <!-- one jointless top-level body: the parser keeps only the first -->',
               '    <body name="base" pos="0 0 0">']
        for side, sign in (("1", -1.0), ("2", 1.0)):
            out += [
                f'      <body name="proximal{side}" pos="{num(sign * params.d / 2.0)} 0 0">',
                f'        <joint name="qa{side}" type="hinge" axis="0 -1 0"/>',
                f'        {inertial(params.m1, params.l1, rho)}',
                f'        {cylinder(params.l1, rho, LINK_RGBA)}',
                f'        <body name="distal{side}" pos="{num(params.l1)} 0 0">',
                f'          <joint name="qp{side}" type="hinge" axis="0 -1 0"/>',
                f'          {inertial(params.m2, params.l2, rho)}',
                f'          {cylinder(params.l2, rho, DISTAL_RGBA)}',
                f'          <site name="tip{side}" pos="{num(params.l2)} 0 0"/>',
                '        </body>',
                '      </body>']
        out += ['    </body>', '  </worldbody>']
        return out + closures([("loop", "tip1", "tip2")], ["qa1", "qa2"])

    def task_point(self, params, t, period: float) -> np.ndarray:
        """:func:`circle_point`: the tip circle ``(x, z)`` [m]."""
        return circle_point(params, t, period)

    def path_source(self, params, period: float, step: float) -> str:
        """``tip circle of radius 50 mm through home, period 2 s, IK every 5 ms``."""
        return (f"tip circle of radius {CIRCLE_RADIUS * 1000:g} mm through home, period "
                f"{period:g} s, IK every {step * 1000:g} ms")

    def world_points(self, params, points) -> np.ndarray:
        """Tip points ``(x, z)`` in the vertical plane as ``(x, 0, z)`` [m]."""
        points = np.asarray(points, dtype=float)
        return np.column_stack([points[:, 0], np.zeros(len(points)), points[:, 1]])


#: The 5-bar, as registered in :data:`rrr_pin.model.mechanisms.MECHANISMS`.
FIVEBAR = FiveBar()
