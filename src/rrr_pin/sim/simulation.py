"""Closed-loop simulation of any plant: one entry point, the engines of one registry.

The plant is any :class:`~rrr_pin.model.plant.Plant`: a serial arm (its full rigid-body model,
Pinocchio's ABA) or a closed chain (the whole tree and its loop closures, Pinocchio's
``constraintDynamics``, projected onto the loop after every step); the law sees only its own
model (:mod:`rrr_pin.control.laws`) and the actuated coordinates. :func:`simulate` validates
its inputs once, samples the reference on the grid where the law is evaluated, and hands the
run to an engine of :mod:`rrr_pin.sim.engines`:

* ``"python"``: :mod:`rrr_pin.sim.python_engine`, the readable reference, runs any law;
* ``"compiled"``: the C++ loop of :mod:`rrr_pin.sim.compiled`, which runs a law only if the law
  declares a :class:`~rrr_pin.control.laws.CompiledForm` it implements for the plant; the two
  agree to round-off (``tests/test_engines.py`` pins every built-in law and reference on both);
* ``"auto"`` (default): the first of :data:`rrr_pin.sim.engines.AUTO_ORDER` that runs the run
  exactly. The engine used is recorded in ``Trajectory.info["engine"]`` and why in
  ``info["engine_note"]``; no law is ever replaced by another.

Integration method: classical fixed-step Runge-Kutta 4.

* Continuous-time laws (``rate=None``, as in the paper's Simulink study): the state
  ``(q, qd, x)`` of arm and law is integrated together with step ``dt``; the law is evaluated at
  every RK4 stage (times ``t_k``, ``t_k + dt/2``, ``t_k + dt``).
* Sampled laws (``rate`` in Hz): at ``t_k = k Ts`` the law reads ``(q_k, qd_k)``, updates its
  state and outputs ``tau_k``, held constant (zero-order hold) while the arm is integrated over
  ``[t_k, t_k + Ts]`` by ``substeps`` RK4 steps of ``Ts / substeps``.

The grid is realized exactly or refused (:func:`time_grid`): a duration must be a whole number
of steps and a sampled run's ``dt`` must divide ``Ts``; nothing is rounded. Before anything is
allocated the run's work is estimated and refused above :data:`MAX_SUBSTEPS` RK4 steps or
:data:`MAX_SAMPLES` stored samples unless ``force=True``.

Divergence (one definition for both engines, :func:`diverged_joint`): a run diverges when, at the
end of a control period (sampled) or of an RK4 step (continuous), a joint's ``q`` or ``qd`` is
NaN/inf, ``|qd|`` exceeds :data:`VELOCITY_LIMIT`, or ``q`` leaves the plant's joint limits
widened by ``limit_margin``.

A law's outputs (:mod:`rrr_pin.control.laws`) are checked on its first call, where a user's law
meets the engine (:func:`~rrr_pin.control.laws.check_law_output`: a wrong type, shape or a NaN
is a ``ValueError`` naming the law), and trusted afterwards. A NaN or inf torque later stops the
run with its own reason (:func:`~rrr_pin.sim.trajectory.law_divergence`): at the control step
where a sampled law returned it, or at the RK4 step one of whose stages did; both engines. Such
a torque makes the state non-finite, so the Python engine looks for it only when the state goes
bad (no cost per step), except with plant effects, where a saturation could clip an inf and a
delay hold a NaN back: there every command is checked.

Accuracy: RK4's global error is ``O(dt^4)``; ``tests/test_simulate.py`` halves the step and shows
the tracking errors move by orders of magnitude less than the differences the study reports.
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass, replace

import numpy as np

from ..control.effects import PlantEffects, check_effects, with_plant_friction
from ..control.laws import ControlLaw, SampledLaw, check_law
from ..control.references import Reference, check_reference, checked_sample
from ..model.plant import JOINT_LIMITS
from ..validation import (
    MULTIPLE_RTOL,
    FieldError,
    check_multiple,
    check_positive,
    check_rate,
    check_vector,
)
from .engine_names import AUTO, CODEGEN
from .engines import check_engine, choose
from .reuse import reuse_preparation, reused, reusing
from .trajectory import Run, SimulationDiverged, Trajectory, diverged_joint

__all__ = [
    "simulate",
    "simulate_batch",
    "check_run",
    "time_grid",
    "TimeGrid",
    "largest_substep",
    "DEFAULT_DT",
    "MAX_SUBSTEPS",
    "MAX_SAMPLES",
]

logger = logging.getLogger(__name__)

#: Default RK4 step of the continuous-time simulation [s], and the largest default plant
#: sub-step of a sampled one.
DEFAULT_DT = 1e-3

#: Most plant RK4 steps one run may take unless ``force=True``: about a minute on the compiled
#: engine (~1.6e5 steps/s for the RRR), an hour on the Python engine.
MAX_SUBSTEPS = 10_000_000

#: Most stored samples one run may hold unless ``force=True``: its arrays take about
#: ``8 (1 + 11 n)`` bytes per sample for ``n`` joints (t, q, qd, tau, the sampled reference
#: and its half-step grid, sensor noise), 270 MB for the RRR, 630 MB for a 7-joint arm.
MAX_SAMPLES = 1_000_000

def _state(name: str, value, default: np.ndarray) -> np.ndarray:
    """Return a checked copy of the initial state ``value``, or of ``default`` if None."""
    if value is None:
        return default.copy()
    return check_vector(name, value, default.shape[0])


@dataclass(frozen=True)
class TimeGrid:
    """The time grid of one run, as :func:`time_grid` realizes it.

    Attributes
    ----------
    n_steps : int
        Control periods (sampled) or RK4 steps (continuous); the run stores ``n_steps + 1``
        samples.
    substeps : int
        Plant RK4 sub-steps per control period (1 for a continuous run).
    h : float
        Plant RK4 step [s]: ``1/rate / substeps``, or ``dt``.
    """

    n_steps: int
    substeps: int
    h: float

    @property
    def work(self) -> int:
        """Plant RK4 steps of the run, ``n_steps * substeps``."""
        return self.n_steps * self.substeps

    def nbytes(self, n: int) -> int:
        """Estimated memory [bytes] of the arrays of a run with ``n`` joints (see MAX_SAMPLES)."""
        return 8 * (1 + 11 * n) * (self.n_steps + 1)


def largest_substep(rate: float, dt_max: float = DEFAULT_DT) -> float:
    """Largest plant sub-step [s] not above ``dt_max`` [s] that divides ``1/rate`` [Hz].

    ``Ts / ceil(Ts / dt_max)`` with ``Ts = 1/rate`` (``dt_max`` itself when it divides
    ``Ts``, to a relative 1e-9).
    """
    Ts = 1.0 / rate
    return Ts / max(1, math.ceil(Ts / dt_max - 1e-9))


def time_grid(duration: float, dt: float | None = None, rate: float | None = None, *,
              n: int | None = None, force: bool = False) -> TimeGrid:
    """Realize ``duration``, ``dt`` and ``rate`` as a grid exactly, or refuse them.

    Nothing is rounded: a sampled run needs ``duration`` to be a whole number of control
    periods ``Ts = 1/rate`` and ``dt`` to divide ``Ts`` into whole sub-steps; a continuous run
    needs ``duration`` to be a whole number of ``dt`` (to a relative
    :data:`rrr_pin.validation.MULTIPLE_RTOL`). The work is estimated before anything is
    allocated and refused above :data:`MAX_SUBSTEPS` plant RK4 steps or :data:`MAX_SAMPLES`
    stored samples per run, unless ``force``.

    Parameters
    ----------
    duration : float
        Simulated time [s], finite and > 0 (checked by the caller).
    dt : float, optional
        RK4 step [s] (continuous) or plant sub-step (sampled), finite and > 0. None: 1e-3 s
        (:data:`DEFAULT_DT`) for a continuous run; for a sampled run the largest sub-step not
        above 1e-3 s that divides ``Ts`` (``Ts / ceil(Ts / 1e-3)``).
    rate : float, optional
        Sampling rate [Hz], finite and > 0; None: a continuous run.
    n : int, optional
        Joints, for the memory estimate in the message.
    force : bool, default False
        Accept a run above the work bounds.

    Returns
    -------
    TimeGrid

    Raises
    ------
    FieldError
        A ``duration`` or ``dt`` off the grid (the message gives the nearest realizable
        values), a ``duration`` shorter than one step, or a run above the bounds (the message
        gives the estimate).
    """
    if rate is not None:
        Ts = 1.0 / rate
        if dt is None:
            substeps = round(Ts / largest_substep(rate))
        else:
            x = Ts / dt
            substeps = round(x)
            if substeps < 1 or abs(x - substeps) > MULTIPLE_RTOL * x:
                raise _dt_refusal(dt, Ts, sorted({max(1, math.floor(x)), max(1, math.ceil(x))}))
        h = Ts / substeps
        if duration < Ts * (1.0 - MULTIPLE_RTOL):
            raise FieldError("duration", f"{{name}} = {duration:g} s is shorter than one "
                                         f"control period (1/rate = {Ts:g} s): nothing to "
                                         f"simulate")
        n_steps = check_multiple("duration", duration, Ts, low=1, unit="s",
                                 step_name="control periods 1/rate")
    else:
        h = DEFAULT_DT if dt is None else dt
        substeps = 1
        if duration < h * (1.0 - MULTIPLE_RTOL):
            raise FieldError("duration", f"{{name}} = {duration:g} s is shorter than one RK4 "
                                         f"step (dt = {h:g} s): nothing to simulate")
        n_steps = check_multiple("duration", duration, h, low=1, unit="s",
                                 step_name="RK4 steps dt")
    grid = TimeGrid(n_steps, substeps, h)
    if not force and (grid.work > MAX_SUBSTEPS or n_steps + 1 > MAX_SAMPLES):
        mem = (f"{grid.nbytes(n) / 1e6:.4g} MB for {n} joints" if n is not None else
               f"{8e-6 * 11 * (n_steps + 1):.4g} MB per joint")
        steps = (f"{n_steps:.4g} control periods of {substeps} RK4 sub-step(s) h = {h:.4g} s"
                 if rate is not None else f"{n_steps:.4g} RK4 steps dt = {h:.4g} s")
        raise FieldError("duration", (
            f"{{name}} = {duration:g} s"
            + (f" at rate = {rate:g} Hz" if rate is not None else "")
            + f" is {steps}: {grid.work:.4g} RK4 steps and {n_steps + 1:.4g} stored samples "
            f"(about {mem}) per run of each law, above the bounds of {MAX_SUBSTEPS:.0e} RK4 "
            f"steps and {MAX_SAMPLES:.0e} samples (rrr_pin.sim.simulation.MAX_SUBSTEPS, "
            f"MAX_SAMPLES); shorten the run, coarsen the step, or force it (force=True, "
            f"--force)"))
    return grid


def _dt_refusal(dt: float, Ts: float, counts) -> FieldError:
    """Return the refusal of a sub-step that does not divide the control period ``Ts``."""
    near = " and ".join(f"{Ts / k:.12g} s ({k} sub-step{'s' if k > 1 else ''})" for k in counts)
    return FieldError("dt", (
        f"{{name}} = {dt:.12g} s does not divide the control period 1/rate = {Ts:.12g} s into "
        f"whole RK4 sub-steps ({Ts / dt:.6g} of them): the nearest realizable sub-steps are "
        f"{near}"))


def simulate(plant, law, reference: Reference, duration: float, *, dt: float | None = None,
             rate: float | None = None, method: str = "tustin", q0=None, qd0=None,
             limit_margin: float = 0.0, engine: str = "auto",
             effects: PlantEffects | None = None, check: bool = True,
             force: bool = False) -> Trajectory:
    """Simulate the closed loop of ``plant`` and ``law`` tracking ``reference``.

    Parameters
    ----------
    plant : Plant
        The true plant (may differ from the law's model): a serial arm or a closed chain
        (:mod:`rrr_pin.model.plant`); plant effects act on its actuated joints.
    law : ControlLaw or SampledLaw
        Any law (:mod:`rrr_pin.control.laws`): a built-in or your own.
    reference : Reference
        Joint reference with ``plant.nq`` joints (:mod:`rrr_pin.control.references`).
    duration : float
        Simulated time [s]: a whole number (>= 1) of steps (``dt``, or ``1/rate`` for sampled
        laws); anything else is refused, not rounded (:func:`time_grid`).
    dt : float, optional
        RK4 step [s] for continuous-time laws (default 1e-3); for sampled laws the plant
        sub-step, which must divide ``Ts = 1/rate`` into whole sub-steps (default: the largest
        such sub-step not above 1e-3 s, ``Ts / ceil(Ts / 1e-3)``). The step used is recorded
        in ``Trajectory.info["dt"]``.
    rate : float, optional
        Run a continuous law as a digital controller at this rate [Hz] (zero-order hold, the
        law's :meth:`~rrr_pin.control.laws.ControlLaw.sampled` form with ``method``). A
        :class:`~rrr_pin.control.laws.SampledLaw` runs at its own rate (``rate`` must then be
        None or equal to it).
    method : str, default "tustin"
        Discretization of a continuous law's state for sampled runs.
    q0, qd0 : array-like, shape (n,), optional
        Initial joint positions [rad] and velocities [rad/s]; default: on the reference,
        ``r(0)`` and ``rd(0)``. The law's state starts at ``law.initial_state()``.
    limit_margin : float, default 0
        Slack beyond the plant's joint limits before the run counts as diverged [rad], >= 0.
    engine : {"auto", "python", "compiled", "codegen"}, default "auto"
        A name of :data:`rrr_pin.sim.engines.ENGINE_CHOICES`; see the module docstring.
        ``"compiled"`` with a law that declares no compiled form raises ``ValueError`` naming
        the law. ``"codegen"``: the compiled loop on dynamics
        generated with the plant's parameters as inputs (:mod:`rrr_pin.sim.batched`), for a
        plant and nominal model of a generated structure (RRR, UR5, Panda); any other
        structure raises ``rrr_pin.sim.batched.StructureMismatch``. Never chosen by ``"auto"``
        for one run; :func:`simulate_batch` picks it for many.
    effects : PlantEffects, optional
        Unmodeled dynamics of the plant (delay, actuator bandwidth, friction, saturation,
        sensor noise, quantization, flexible joints; :mod:`rrr_pin.control.effects`), sampled
        runs only. None (default): the ideal plant.
    check : bool, default True
        Validate the scalar settings ``duration``, ``dt``, ``rate`` and ``limit_margin``
        (finite, > 0; ``limit_margin`` >= 0). ``False`` trusts them as validated by the caller
        (e.g. :class:`rrr_pin.campaign.runner.RunSettings`, which checks them when it is made)
        and only converts them to float. What depends on the plant, the law or the reference
        (sizes, the initial state, joint limits, the RK4 step of a linear law's fastest pole)
        is checked either way; the time grid (whole steps, work bounds) only with ``check``.
    force : bool, default False
        Run even above the work bounds :data:`MAX_SUBSTEPS` (plant RK4 steps) and
        :data:`MAX_SAMPLES` (stored samples), which are otherwise refused before anything is
        allocated (only checked with ``check=True``).

    Returns
    -------
    Trajectory
        Sampled every ``dt`` (continuous) or every ``1/rate`` (sampled).

    Raises
    ------
    SimulationDiverged
        See :func:`diverged_joint`.
    ValueError
        Inconsistent sizes, non-finite or non-positive settings, a duration shorter than one
        step or not a whole number of steps, a ``dt`` that does not divide ``1/rate``, a run
        above the work bounds (without ``force``), a reference or initial state outside the
        joint limits, an engine that cannot run the law, effects with a continuous-time law.
    TypeError
        ``law`` or ``reference`` of the wrong type.
    """
    run = _prepare(plant, law, reference, duration, dt=dt, rate=rate, method=method, q0=q0,
                   qd0=qd0, limit_margin=limit_margin, effects=effects, check=check,
                   force=force)
    return _execute(run, engine)


def check_run(plant, law, reference: Reference, duration: float, *, engine: str = AUTO,
              **kwargs) -> str:
    """Validate one run as :func:`simulate` would, without running it; return its engine.

    The edge check of a study or a campaign, once, before any work: every setting, the
    reference on ``plant``, the initial state, and that ``engine`` can run the law on this
    plant exactly (a refusal names why). A plant's own failure at the start (a closed chain
    whose loop will not close at ``q0``) is not an error of the settings: it is left to the
    run, and the engine is then reported as ``engine``.

    Parameters
    ----------
    plant, law, reference, duration, engine
        As for :func:`simulate`.
    **kwargs
        The other keywords of :func:`simulate`.

    Returns
    -------
    str
        The name of the engine that would run it.
    """
    options = {"dt": None, "rate": None, "method": "tustin", "q0": None, "qd0": None,
               "limit_margin": 0.0, **kwargs}
    try:
        run = _prepare(plant, law, reference, duration, **options)
    except plant.failures as exc:
        if options["q0"] is not None:  # the caller's own initial state: a settings error
            q0 = ", ".join(f"{float(v):.6g}" for v in np.ravel(options["q0"]))
            raise FieldError("q0", "{name} = [" + q0 + "] rad: the plant cannot start "
                             "there: " + str(exc).replace("{", "{{").replace("}", "}}")
                             ) from None
        return engine
    return choose(run, engine)[0].name


def _execute(run: Run, engine: str) -> Trajectory:
    """Run a validated run on ``engine`` (as :func:`simulate` chooses it); record the engine."""
    chosen, form, note = choose(run, engine)
    logger.debug("engine for law %r: %s (%s)", run.law.name, chosen.name, note)
    run.law.reset(run.R[0])  # a run depends on its own inputs only (a chain model's seed)
    traj = chosen.run(run, form)
    traj.info["engine"] = chosen.name
    traj.info["engine_note"] = note
    return traj


def simulate_batch(plants, law, reference: Reference, duration: float, *, batch: int = 16,
                   engine: str = "auto", threads: int = 1, figures: bool = False,
                   **kwargs) -> list:
    """Simulate one law on many plants; diverged runs are returned, not raised.

    With ``engine="auto"`` the plants run ``batch`` at a time on the generated dynamics
    (:func:`rrr_pin.sim.batched.run_batch`) when that engine can run them all (the law's
    compiled form one the compiled engine implements, the plants and the law's model of
    a generated structure, plant effects (every one of ``_ext/effects.hpp``) shared
    by the runs), and one at a time as :func:`simulate` picks
    otherwise. ``engine="codegen"`` requires the batched engine (refusing what it cannot run);
    any other engine runs one plant at a time. Each result is the one :func:`simulate` would
    give with the engine recorded in its ``info["engine"]``; ``batch`` changes no number.

    Parameters
    ----------
    plants : sequence of Robot
        The true arms, each with ``reference``'s joints.
    law, reference, duration
        As for :func:`simulate`.
    batch : int, default 16
        Plants per batched call, 1 to :data:`rrr_pin.sim.batched.BATCH_MAX`.
    engine : {"auto", "python", "compiled", "codegen"}, default "auto"
    threads : int, default 1
        Threads of the batched engine (a batch per thread, the GIL released;
        :func:`rrr_pin.sim.batched.run_batch`); changes no number.
    figures : bool, default False
        Where the batched engine runs, return each run reduced to its figures
        (:class:`~rrr_pin.sim.trajectory.RunFigures`, what a campaign's row needs) instead of
        its trajectory; runs on another engine still return trajectories. Both have
        ``figures(joint_names)`` and ``info``.
    **kwargs
        The other keywords of :func:`simulate` (``dt``, ``rate``, ``method``, ``q0``,
        ``qd0``, ``limit_margin``, ``effects``, ``check``, ``force``).

    Returns
    -------
    list
        Per plant, in order: its :class:`Trajectory`, or the :class:`SimulationDiverged` (or
        the plant's own failure, :attr:`rrr_pin.model.plant.Plant.failures`) it ended with.
    """
    from .batched import BATCH_MAX, batchable, run_batch

    if isinstance(batch, bool) or not isinstance(batch, (int, np.integer)) or not (
            1 <= batch <= BATCH_MAX):
        raise ValueError(f"batch must be an integer in [1, {BATCH_MAX}], got {batch!r}")
    check_engine(engine)
    options = {"dt": None, "rate": None, "method": "tustin", "q0": None, "qd0": None,
               "limit_margin": 0.0, **kwargs}

    def prepared(plant):
        # A plant's own failures (a closed chain whose loop will not close at q0) are its
        # result, as in the run; every other error propagates. The runs share the sampled
        # reference (read-only); a run for another engine gets its own copies below.
        try:
            return _prepare(plant, law, reference, duration, share=True, **options)
        except (SimulationDiverged, *plant.failures) as exc:
            return exc

    def again(plant, first, effects):
        # Another plant of ``first``'s run settings (validated there): only what depends on
        # the plant (:func:`_prepare_like`); a plant of another joint count is prepared whole.
        if plant.nq != first.plant.nq:
            return prepared(plant)
        try:
            return _prepare_like(first, plant, reference, float(options["limit_margin"]),
                                 effects)
        except (SimulationDiverged, *plant.failures) as exc:
            return exc

    with reuse_preparation():
        runs, first, effects = [], None, None
        for p in plants:
            if first is not None:
                runs.append(again(p, first, effects))
                continue
            runs.append(prepared(p))
            if not isinstance(runs[-1], Exception):  # the runs after it are prepared from it
                first, effects = runs[-1], _active_effects(options.get("effects"))
    ready = [r for r in runs if not isinstance(r, Exception)]
    if engine in (AUTO, CODEGEN) and len(ready) == len(runs):
        form = runs[0].law.compiled_form() if runs else None
        if engine == CODEGEN and runs:
            choose(runs[0], CODEGEN)  # the refusal of a run the batched engine cannot run
        if engine == CODEGEN or batchable(runs, form):
            out = run_batch(runs, form, batch=int(batch), threads=threads, figures=figures)
            note = (f"engine={CODEGEN!r} asked" if engine == CODEGEN else
                    f"{AUTO}: {CODEGEN} runs every plant of the batch exactly")
            for r in out:
                if not isinstance(r, SimulationDiverged):
                    r.info["engine"], r.info["engine_note"] = CODEGEN, note
            return out
    # Why not the batched engine, said in each run's engine note (e.g. a structure whose
    # dynamics could not be generated at first use: rrr_pin.sim.dyncache).
    why = None
    if engine == AUTO and ready and ready[0].law.compiled_form() is not None:
        from .batched import why_not

        why = why_not(ready[0], ready[0].law.compiled_form())
    out = []
    for run in runs:
        if isinstance(run, Exception):
            out.append(run)
            continue
        # its own arrays: the runs of a batch share them (_prepare_like), a law may not
        run = replace(run, R=run.R.copy(), RD=run.RD.copy(), RDD=run.RDD.copy(),
                      q0=run.q0.copy(), qd0=run.qd0.copy(), x0=run.x0.copy(),
                      state0=tuple(np.copy(a) for a in run.state0))
        try:
            # One run at a time in the process: a law object is shared by the runs (and a
            # campaign's threads), and the one-plant engines may keep state in it.
            with _ONE_AT_A_TIME:
                traj = _execute(run, engine)
        except (SimulationDiverged, *run.plant.failures) as exc:
            out.append(exc)
            continue
        if why is not None:
            traj.info["engine_note"] += f"; not {CODEGEN} for the batch: {why}"
        out.append(traj)
    return out


_ONE_AT_A_TIME = threading.Lock()


def _sampled_law(law, rate: float, method: str):
    """``law.sampled(rate, method)``, reused inside :func:`reuse_preparation`.

    Reused only for laws with a compiled form (the built-ins): their sampled form is a pure
    function of the law's parameters, whereas a user's ``sampled`` may build fresh state.
    """
    if not reusing() or law.compiled_form() is None:
        return law.sampled(rate, method)
    return reused(law, ("sampled", rate, method), lambda: law.sampled(rate, method),
                  lasting=True)


def _sample_reference(reference, grid_key, grid, share: bool = False
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``reference.sample(grid)`` as contiguous float arrays, checked (finite, (N, n)).

    Inside :func:`reuse_preparation`, sampled once per reference (by identity) and
    ``grid_key`` (which determines ``grid``); each call gets its own copies, or with ``share``
    the cached arrays themselves (read-only for the caller: the batched runs of
    :func:`simulate_batch`, which copy them into a trajectory only when one is made).
    """
    if not reusing():
        return checked_sample(reference, grid)
    arrays = reused(reference, ("sampled", grid_key), lambda: checked_sample(reference, grid),
                    lasting=True)
    return arrays if share else tuple(a.copy() for a in arrays)


def _check_limits(reference, plant, duration: float) -> None:
    """Run ``reference.check_limits(plant, duration=duration)``.

    Inside :func:`reuse_preparation`, a passed check of the generic grid test
    (:meth:`Reference.check_limits`, which depends on the reference and the limits only) is
    not repeated for a plant with the same joint limits.
    """
    if not reusing() or type(reference).check_limits is not Reference.check_limits:
        reference.check_limits(plant, duration=duration)
        return
    # a check that raises keeps nothing: the next plant with these limits is checked again
    reused(reference, ("limits", duration, plant.lower.tobytes(), plant.upper.tobytes()),
           lambda: reference.check_limits(plant, duration=duration), lasting=True)


def _trusted_grid(duration: float, dt: float | None, rate: float | None) -> TimeGrid:
    """Return the grid of settings :func:`time_grid` accepted (no check, no bound)."""
    if rate is None:
        h = DEFAULT_DT if dt is None else dt
        return TimeGrid(round(duration / h), 1, h)
    Ts = 1.0 / rate
    substeps = round(Ts / (largest_substep(rate) if dt is None else dt))
    return TimeGrid(round(duration * rate), substeps, Ts / substeps)


def _prepare(plant, law, reference, duration, *, dt, rate, method, q0, qd0,
             limit_margin, effects=None, check=True, force=False, share=False) -> Run:
    """Validate every input once and sample the reference (the edge of the simulator).

    ``check=False`` trusts the scalar settings (``duration``, ``dt``, ``rate``,
    ``limit_margin``), validated by the caller; they are only converted to float.
    ``share``: the run's reference arrays are those of the :func:`reuse_preparation` cache,
    shared with other runs, not copies (:func:`_sample_reference`).
    """
    n = plant.nq
    check_law(law, n)
    check_reference(reference, plant)
    if check:
        duration = check_positive("duration", duration, unit="s")
        dt = None if dt is None else check_positive("dt", dt, unit="s")
        limit_margin = check_positive("limit_margin", limit_margin, allow_zero=True,
                                      unit="rad")
        if rate is not None:
            rate = check_rate("rate", rate)
    else:
        duration, limit_margin = float(duration), float(limit_margin)
        dt = None if dt is None else float(dt)
        rate = None if rate is None else float(rate)
    effects = _active_effects(effects)
    effects, own_friction = with_plant_friction(plant, effects,
                                                rate is not None or isinstance(law, SampledLaw))
    if effects is not None and rate is None and not isinstance(law, SampledLaw):
        raise ValueError(
            f"effects apply to sampled (digital) controllers only: law {law.name!r} is "
            f"continuous-time; give rate= (e.g. rate=1000) to run it sampled with the effects")
    if isinstance(law, SampledLaw):
        if rate is not None and not math.isclose(rate, law.rate):
            raise ValueError(f"law {law.name!r} is sampled at {law.rate:g} Hz, rate = "
                             f"{rate!r} asks for another rate")
        rate = check_rate("rate", law.rate)  # a user's SampledLaw may hold anything
    elif rate is not None:
        law = _sampled_law(law, rate, method)
    elif not isinstance(law, ControlLaw):
        raise TypeError(f"law must be a ControlLaw or SampledLaw, got {type(law).__name__}")
    if limit_margin:
        plant.require(JOINT_LIMITS, f"limit_margin = {limit_margin:g} rad")
    lower = plant.lower - limit_margin
    upper = plant.upper + limit_margin
    if check:
        tg = time_grid(duration, dt, rate, n=n, force=force)
    else:  # validated by the caller (RunSettings): only the grid's numbers
        tg = _trusted_grid(duration, dt, rate)
    n_steps, substeps, h = tg.n_steps, tg.substeps, tg.h
    if rate is not None:
        Ts = 1.0 / rate
        t = Ts * np.arange(n_steps + 1)
        grid = t
        info = {"method": "RK4 plant, zero-order-hold sampled law", "rate_hz": rate,
                "substeps": substeps, "dt": h}
    else:
        dt = h
        _check_rk4_step(law, dt)
        t = dt * np.arange(n_steps + 1)
        grid = 0.5 * dt * np.arange(2 * n_steps + 1)
        info = {"method": "RK4 (continuous-time law)", "dt": dt}
    _check_limits(reference, plant, float(t[-1]))
    R, RD, RDD = _sample_reference(
        reference, (rate is not None, Ts if rate is not None else dt, n_steps), grid, share)
    q0 = _state("q0", q0, R[0])
    qd0 = _state("qd0", qd0, RD[0])
    _check_initial(plant, q0, qd0, lower, upper)
    state0 = plant.start(q0, qd0)  # the full state (a closed chain closes its loop here)
    x0 = np.asarray(law.initial_state(), dtype=float)
    if x0.shape != (law.nx,):
        raise ValueError(f"law {law.name!r}: initial_state() has shape {x0.shape}, nx = "
                         f"{law.nx}")
    fx = None
    if own_friction is not None:
        info["plant_friction"] = own_friction
    if effects is not None:
        fx = effects.resolve(plant, substeps, h, len(t) - 1)
        info["effects"] = fx.info
    return Run(plant, law, rate is not None, t, R, RD, RDD, q0, qd0, x0, h, substeps,
                lower, upper, info, fx, state0)


def _active_effects(effects):
    """``check_effects(effects)``, None for effects that change nothing."""
    effects = check_effects(effects)
    return effects if effects is not None and effects.active else None


def _prepare_like(first: Run, plant, reference, limit_margin: float, effects) -> Run:
    """:func:`_prepare` of ``plant`` with the settings of ``first``, a run they were validated for.

    Everything that does not depend on the plant is ``first``'s (the law, its sampled form
    and state, the grid, the reference arrays, ``q0`` and ``qd0``: shared, read-only); what
    does is done again as :func:`_prepare` does it: the joint limits and their check of the
    reference, the initial state's test, the plant's start and its effects. ``plant`` has
    ``first.plant``'s joint count (so the law and reference checks hold for it too);
    ``effects`` is the checked, active :class:`PlantEffects` of ``first`` or None.
    """
    if limit_margin:
        plant.require(JOINT_LIMITS, f"limit_margin = {limit_margin:g} rad")
    lower = plant.lower - limit_margin
    upper = plant.upper + limit_margin
    _check_limits(reference, plant, float(first.t[-1]))
    q0, qd0 = first.q0, first.qd0
    _check_initial(plant, q0, qd0, lower, upper)
    state0 = plant.start(q0, qd0)
    info = dict(first.info)
    info.pop("plant_friction", None)
    effects, own_friction = with_plant_friction(plant, effects, first.sampled)
    if own_friction is not None:
        info["plant_friction"] = own_friction
    fx = None
    if effects is not None:
        fx = effects.resolve(plant, first.substeps, first.h, len(first.t) - 1)
        info["effects"] = fx.info
    return replace(first, plant=plant, lower=lower, upper=upper, info=info, effects=fx,
                   state0=state0)


def _check_initial(plant, q0, qd0, lower, upper) -> None:
    """Refuse an initial state that the divergence test of the engines would stop at once."""
    bad = diverged_joint(q0, qd0, lower, upper)
    if bad is not None:
        j = bad[0]
        raise ValueError(f"initial state of joint {plant.joint_names[j]!r} is invalid: "
                         f"{bad[1]} (q0 = {q0[j]:.6g} rad, limits [{plant.lower[j]:.4g}, "
                         f"{plant.upper[j]:.4g}], qd0 = {qd0[j]:.6g} rad/s)")


def _check_rk4_step(law, dt: float) -> None:
    """Refuse a step RK4 cannot integrate for a linear law's fastest pole."""
    mats = getattr(law, "continuous_matrices", None)
    if mats is None:
        return
    A = mats()[0]
    if A.shape[0]:
        fastest = float(np.max(np.abs(np.linalg.eigvals(A))))
        # RK4's stability interval on the negative real axis ends at -2.785.
        if fastest * dt > 2.5:
            raise ValueError(
                f"dt = {dt:g} s is too large for the controller's fastest pole "
                f"({fastest:.4g} rad/s): RK4 needs dt < {2.5 / fastest:.3g} s")
