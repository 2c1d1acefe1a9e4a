"""The simulation engines, in one registry: what each is, what it can run, how to run it.

An engine is an :class:`Engine` record: its name, what it is, ``why_not(run, form)`` (None when
it runs the validated :class:`~rrr_pin.sim.trajectory.Run` exactly, otherwise the reason, in
words) and ``run(run, form)``. :data:`ENGINES` holds them by name, and every engine name the
package and the command line use comes from it (:data:`ENGINE_CHOICES`). ``"auto"`` is not an
engine but the policy of :func:`choose`: the first engine of :data:`AUTO_ORDER` that can run
the run exactly, with the reasons recorded (``Trajectory.info["engine_note"]``); nothing is
ever substituted for what was asked.

Built in: ``"python"`` (:mod:`rrr_pin.sim.python_engine`, the reference; runs anything),
``"compiled"`` (:mod:`rrr_pin.sim.compiled`, the C++ loop of a law's compiled form) and
``"codegen"`` (:mod:`rrr_pin.sim.batched`, the same loop on generated dynamics; chosen by
:func:`rrr_pin.sim.simulation.simulate_batch`, never by ``"auto"`` for one run) and
``"mujoco"`` (:mod:`rrr_pin.sim.mujoco_engine`, the plant stepped by MuJoCo, an optional
extra; never chosen by ``"auto"``). A new engine is
its module plus one :func:`register` line here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .engine_names import AUTO, CODEGEN, COMPILED, MUJOCO, PYTHON

__all__ = ["Engine", "ENGINES", "ENGINE_CHOICES", "AUTO_ORDER", "register", "choose",
           "check_engine"]



@dataclass(frozen=True)
class Engine:
    """One simulation engine.

    Attributes
    ----------
    name : str
        Its key (``simulate(engine=...)``, ``--engine``).
    description : str
        What it is, for ``--help`` and the docs.
    why_not : callable
        ``why_not(run, form) -> str | Exception | None``: None when the engine runs ``run``
        (with the law's compiled form ``form``, or None) exactly; otherwise why not, naming
        the law or the plant (an exception of its own type to raise when asked by name).
    run : callable
        ``run(run, form) -> Trajectory``; raises the Python engine's exceptions.
    """

    name: str
    description: str
    why_not: Callable
    run: Callable


#: The registry, by name.
ENGINES: dict[str, Engine] = {}


def register(engine: Engine) -> Engine:
    """Add ``engine`` to :data:`ENGINES` (a name is registered once)."""
    if engine.name in ENGINES or engine.name == AUTO:
        raise ValueError(f"engine {engine.name!r} is registered already")
    ENGINES[engine.name] = engine
    return engine


def _python_why_not(run, form):
    return None


def _python_run(run, form):
    from .python_engine import run_python

    return run_python(run)


def _compiled_why_not(run, form):
    from .compiled import why_not

    return why_not(run, form)


def _compiled_run(run, form):
    from .compiled import run_compiled

    return run_compiled(run, form)


def _codegen_why_not(run, form):
    from .batched import why_not

    return why_not(run, form)


def _codegen_run(run, form):
    from .batched import raise_or_return, run_batch

    return raise_or_return(run_batch([run], form)[0])


def _mujoco_why_not(run, form):
    from .mujoco_engine import why_not

    return why_not(run, form)


def _mujoco_run(run, form):
    from .mujoco_engine import run as run_mujoco

    return run_mujoco(run, form)


register(Engine(PYTHON, "the Python reference loop (runs any law, plant and effect)",
                _python_why_not, _python_run))
register(Engine(COMPILED, "the C++ loop of a law's compiled form on Pinocchio's C++ "
                          "algorithms", _compiled_why_not, _compiled_run))
register(Engine(CODEGEN, "the C++ loop on dynamics generated per arm structure, many plants "
                         "per call", _codegen_why_not, _codegen_run))
register(Engine(MUJOCO, "the plant stepped by MuJoCo (RK4), the laws and effects as in Python; "
                        "a checking engine (pip install 'rrr-pin[mujoco]')",
                _mujoco_why_not, _mujoco_run))

#: What ``"auto"`` tries for one run, in order (the first that can run it exactly).
AUTO_ORDER = (COMPILED, PYTHON)

#: Every accepted ``engine=`` value: ``"auto"`` and the registered engines.
ENGINE_CHOICES = (AUTO, *ENGINES)


def check_engine(name) -> str:
    """Return ``name`` if it is ``"auto"`` or a registered engine; ``ValueError`` otherwise."""
    if name not in ENGINE_CHOICES:
        raise ValueError(f"engine must be one of {', '.join(ENGINE_CHOICES)}, got {name!r}")
    return name


def choose(run, name: str) -> tuple[Engine, object, str]:
    """Return the engine that runs ``run`` for the request ``name``: ``(engine, form, note)``.

    ``form`` is the law's compiled form (None for the Python engine); ``note`` says why this
    engine (``Trajectory.info["engine_note"]``).

    Raises
    ------
    ValueError
        An unknown name, or an engine asked by name that cannot run this run exactly (the
        message gives its reason and the way out).
    """
    check_engine(name)
    law = run.law
    if name == PYTHON:
        return ENGINES[PYTHON], None, f"engine={PYTHON!r} asked"
    form = law.compiled_form()
    if name != AUTO:
        engine = ENGINES[name]
        why = engine.why_not(run, form)
        if isinstance(why, Exception):
            raise why
        if why is not None:
            raise ValueError(f"{why}; use engine={PYTHON!r} (or {AUTO!r}, which picks an "
                             f"engine that can run it)")
        return engine, form, f"engine={name!r} asked"
    reasons = []
    for candidate in AUTO_ORDER:
        engine = ENGINES[candidate]
        why = engine.why_not(run, form)
        if why is None:
            note = (f"{AUTO}: {candidate}" + (f" ({'; '.join(reasons)})" if reasons else
                    f" runs the law's compiled form {type(form).__name__} exactly"))
            return engine, (None if candidate == PYTHON else form), note
        reasons.append(f"not {candidate}: {why}")
    raise AssertionError("the Python engine runs every run")  # pragma: no cover
