"""The dynamics check as text: Pinocchio's M, V, G against the paper's closed form.

:func:`comparison_lines` turns :func:`rrr_pin.model.closed_form.compare_with_pinocchio`'s
result into a table and a verdict for a terminal.
"""

from __future__ import annotations

__all__ = ["comparison_lines"]

#: Units of the compared quantities.
_UNITS = {"M": "kg m^2", "V": "N m", "G": "N m"}


def comparison_lines(result: dict, rtol: float) -> tuple[list[str], list[str]]:
    """Return the comparison table and verdict as text lines, and the keys that fail ``rtol``.

    Parameters
    ----------
    result : dict
        ``{"M" | "V" | "G": {"abs", "scale", "rel"}}``, largest absolute difference, largest
        Pinocchio entry and their ratio.
    rtol : float
        Largest accepted relative difference.

    Returns
    -------
    lines : list of str
        Header, one row per quantity (``ok`` or ``FAIL``), then ``OK: ...`` or ``FAIL: ...``.
    failed : list of str
        The quantities whose relative difference exceeds ``rtol``.
    """
    lines = [f"{'':3}{'max |diff|':>12}  {'max |Pinocchio|':>16}  {'rel. diff':>10}  unit"]
    failed = [key for key, row in result.items() if not row["rel"] <= rtol]
    lines += [f"{key:3}{row['abs']:12.3e}  {row['scale']:16.3e}  {row['rel']:10.3e}  "
              f"{_UNITS[key]:7} {'FAIL' if key in failed else 'ok'}"
              for key, row in result.items()]
    lines.append(f"FAIL: {', '.join(failed)} differ by more than rtol = {rtol:g}" if failed
                 else f"OK: all relative differences <= rtol = {rtol:g}")
    return lines, failed
