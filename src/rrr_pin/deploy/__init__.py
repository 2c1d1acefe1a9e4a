"""From design to the robot: export a built-in law as C code that runs in a real-time loop.

Holds :mod:`~rrr_pin.deploy.writer` (:func:`~rrr_pin.deploy.writer.export`: a law's
compiled form, sampled, written as a self-contained C99 folder with the model's dynamics,
CMake and an example), :mod:`~rrr_pin.deploy.ros2` (a ros2_control controller package around
it), :mod:`~rrr_pin.deploy.hil` (the exported controller in real time against a simulated arm,
measured), :mod:`~rrr_pin.deploy.command` (the drive's torque convention, ``--command``),
:mod:`~rrr_pin.deploy.sources` (the text of each file, filled from ``templates/``),
:mod:`~rrr_pin.deploy.period` (``ctrl_step_dt``: the law over a measured period) and
:mod:`~rrr_pin.deploy.loaded` (build the folder, load its library by ``ctypes`` as a
``SampledLaw`` that :func:`rrr_pin.simulate` runs against the Python law).

The package face names the two entry points as issue 19 does: ``rrr_pin.export(law, robot,
rate, out)`` and ``rrr_pin.exported_law(folder)``. This subpackage is called ``deploy``, not
``export``, so that ``rrr_pin.export`` stays the function: importing a subpackage
``rrr_pin.export`` would bind that name to the module.

Layer: above :mod:`rrr_pin.sim`, below :mod:`rrr_pin.campaign`. May import
:mod:`rrr_pin.validation`, :mod:`rrr_pin.outputs`, :mod:`rrr_pin.model`,
:mod:`rrr_pin.robust`, :mod:`rrr_pin.control` and :mod:`rrr_pin.sim`.
"""
