"""What a person reads: results tables, figures, the 3D viewer and the HTML report.

Holds :mod:`~rrr_pin.report.results` (``results.json``, ``results.md``),
:mod:`~rrr_pin.report.plotting` (matplotlib figures, Agg), :mod:`~rrr_pin.report.viewer`
(MeshCat scenes) and :mod:`~rrr_pin.report.html` (the self-contained ``report.html``).

Layer: above :mod:`rrr_pin.campaign`. May import every layer below it, never
:mod:`rrr_pin.cli`.
"""
