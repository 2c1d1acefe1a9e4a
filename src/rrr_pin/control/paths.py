"""Task-space paths placed from where the arm starts.

:func:`circle_from_start` builds the :class:`~rrr_pin.control.references.CirclePath` whose
motion begins at a given point, as ``rrr-pin reproduce --reference circle`` needs: the point
where the frame is at the start configuration.
"""

from __future__ import annotations

import numpy as np

from ..validation import check_direction, check_positive, check_vector
from .references import CirclePath

__all__ = ["circle_from_start"]


def circle_from_start(p0, radius: float, normal=(0.0, 0.0, 1.0)) -> CirclePath:
    r"""Circle of ``radius`` in the plane normal to ``normal`` whose motion starts at ``p0``.

    The start direction ``u`` is the base axis x projected on the plane (the axis y when
    ``normal`` is within about 26 degrees of x, where the projection would be short), made
    unit; the centre is ``p0 - radius u``, so the motion starts at ``p0`` and turns once,
    counter-clockwise about ``normal``.

    .. math:: c = p_0 - r\,u, \qquad u = \frac{e - n (e^T n)/(n^T n)}{\lVert\cdot\rVert}

    Parameters
    ----------
    p0 : array-like, shape (3,)
        Start point [m].
    radius : float
        Radius [m], > 0.
    normal : array-like, shape (3,), default (0, 0, 1)
        Normal of the circle's plane (any non-zero length; it is made unit).

    Returns
    -------
    CirclePath

    Raises
    ------
    ValueError
        ``p0`` or ``normal`` not a finite 3-vector, ``normal`` zero, ``radius`` not > 0.
    """
    p0 = check_vector("p0", p0, 3)
    radius = check_positive("radius", radius, unit="m")
    normal = check_direction("normal", normal, 3)
    u = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 * np.linalg.norm(normal) else \
        np.array([0.0, 1.0, 0.0])
    u = u - normal * (u @ normal) / (normal @ normal)
    u /= np.linalg.norm(u)
    return CirclePath(p0 - radius * u, radius, normal=normal, start_dir=u)
