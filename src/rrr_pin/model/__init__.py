"""The plant: the plant protocol, serial arms and closed chains, their sources and dynamics.

Holds :mod:`~rrr_pin.model.plant` (the ``Plant`` protocol every layer above uses, declared
capabilities, the ``UncertaintySet`` base), :mod:`~rrr_pin.model.dh` (the paper's Tables 1-2),
:mod:`~rrr_pin.model.urdf` (the URDF generator), :mod:`~rrr_pin.model.robots` (where an arm
comes from: the paper's RRR, an example-robot-data name or a URDF path),
:mod:`~rrr_pin.model.dynamics` (``Robot``, ``load_robot``: M, V, G through Pinocchio), with
:mod:`~rrr_pin.model.urdf_checks` (a URDF's inertials, joints and tree checked before Pinocchio
reads it) and :mod:`~rrr_pin.model.locks` (joints locked: checked, removed, mimic joints),
:mod:`~rrr_pin.model.closed_form` (the corrected eq. (2)-(7)), :mod:`~rrr_pin.model.uncertainty`
(seeded uncertain plants as URDF), :mod:`~rrr_pin.model.drawn` (an uncertain arm's numbers put
together into its Pinocchio model as the URDF reader would, without the text),
:mod:`~rrr_pin.model.identification` (a subpackage, one
module per concept: base inertial parameters and friction from measured torques, logs, a
physically consistent URDF, the identified uncertainty),
:mod:`~rrr_pin.model.excitation` (Fourier excitation trajectories for it),
:mod:`~rrr_pin.model.mechanisms` (parallel mechanisms as data: one module per kind, its
parameters, MJCF, closed-form kinematics and task path, one registry) and
:mod:`~rrr_pin.model.closed_chain` (``ClosedChain``: loop closure and the reduced dynamics in
actuated coordinates), with :mod:`~rrr_pin.model.mjcf_checks` (an MJCF's loops, or a serial
MJCF arm's joints, tendons, equalities and actuators, checked in Python before Pinocchio's parser
reads the file), and :mod:`~rrr_pin.model.joint_map` (a law's model and the simulated plant
paired joint by joint). Only this layer knows the kinds of plant.

Layer: the lowest. May import :mod:`rrr_pin.validation` only.
"""
