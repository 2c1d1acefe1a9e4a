"""What a person reads: results tables, figures, the 3D viewer and the HTML report.

Holds :mod:`~rrr_pin.report.results` (a study's ``results.json``, ``results.md`` and
``report.html``), :mod:`~rrr_pin.report.campaign` (a campaign's tables, summary and
``report.html``), :mod:`~rrr_pin.report.design` (the loop-shaping design as JSON and text),
:mod:`~rrr_pin.report.stress` (a stress search's figure, JSON and table),
:mod:`~rrr_pin.report.dynamics` (the check-dynamics table and verdict),
:mod:`~rrr_pin.report.plotting` (matplotlib figures, Agg), :mod:`~rrr_pin.report.margins`
(singular values, Bode and Nyquist of the loops at the torque input),
:mod:`~rrr_pin.report.viewer` (MeshCat scenes), :mod:`~rrr_pin.report.geometry` (their
visual geometry by description format), :mod:`~rrr_pin.report.html` (the self-contained
``report.html`` page) and :mod:`~rrr_pin.report.jsondata` (strict JSON: ``null`` and a status
for non-finite numbers). Every writer takes a study or a campaign of any plant (serial arm or
closed chain): one schema, one page.

Layer: above :mod:`rrr_pin.campaign`. May import every layer below it, never
:mod:`rrr_pin.cli`.
"""
