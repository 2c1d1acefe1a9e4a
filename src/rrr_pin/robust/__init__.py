"""Robust-control design and analysis on python-control LTI objects (paper, section 4).

Holds :mod:`~rrr_pin.robust.lti` (LTI input checks), :mod:`~rrr_pin.robust.barriers`
(eq. 12-15), :mod:`~rrr_pin.robust.ncf` (``ncfsyn``, ``ncfsyn_2dof``, ``ncfmargin``),
:mod:`~rrr_pin.robust.gap`
(gap and nu-gap), :mod:`~rrr_pin.robust.reduction` (eq. 18 with its guarantee),
:mod:`~rrr_pin.robust.loopshaping` (eq. 11, 16-17, ``design``, ``loopsyn``),
:mod:`~rrr_pin.robust.robustness` (section 4.4), :mod:`~rrr_pin.robust.certificates`
(frozen-configuration nu-gap certificates), :mod:`~rrr_pin.robust.mu` (``mussv``,
``robstab``: mixed real/complex structured singular value and robust stability margin) and
:mod:`~rrr_pin.robust.hinfstruct` (fixed-structure H-infinity synthesis of tunable blocks).

Layer: above :mod:`rrr_pin.model`. May import :mod:`rrr_pin.validation` and
:mod:`rrr_pin.model`.
"""
