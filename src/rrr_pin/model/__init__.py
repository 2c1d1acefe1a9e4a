"""The arm: DH parameters, URDF generation and checks, arm sources, Pinocchio dynamics.

Holds :mod:`~rrr_pin.model.dh` (the paper's Tables 1-2), :mod:`~rrr_pin.model.urdf` (the URDF
generator), :mod:`~rrr_pin.model.robots` (where an arm comes from: the paper's RRR, an
example-robot-data name or a URDF path), :mod:`~rrr_pin.model.dynamics` (``Robot``,
``load_robot``: M, V, G through Pinocchio), :mod:`~rrr_pin.model.closed_form` (the corrected
eq. (2)-(7)), :mod:`~rrr_pin.model.uncertainty` (seeded uncertain plants as URDF),
:mod:`~rrr_pin.model.identification` (base inertial parameters from measured torques, a
physically consistent URDF, the identified uncertainty) and :mod:`~rrr_pin.model.excitation`
(Fourier excitation trajectories for it).

Layer: the lowest. May import :mod:`rrr_pin.validation` only.
"""
