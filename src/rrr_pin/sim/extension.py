"""The compiled extension ``rrr_pin.sim._rollout``: loading, version check, loaded plants.

Shared by the compiled engine (:mod:`rrr_pin.sim.compiled`) and the batched engine
(:mod:`rrr_pin.sim.batched`), which run the same list of C++ laws (:func:`law_name`); imports
nothing of rrr_pin but the compiled forms.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import pinocchio as pin  # loads libpinocchio_default.so before the extension needs it

from ..control.laws.forms import compiled_forms

__all__ = ["EXTENSION", "CompiledRobot", "available", "require", "cached", "cannot_start",
           "effects_struct", "law_name", "law_struct", "law_forms", "law_kinds",
           "effect_fields"]


def _load_extension():
    """Return (module, None) or (None, reason it cannot be used)."""
    try:
        from . import _rollout as ext
    except ImportError as exc:
        return None, (f"rrr_pin's compiled extension (rrr_pin.sim._rollout) is not built or cannot "
                      f"load ({exc}); install the package with `pip install .` or "
                      f"`pip install -e .`, which compiles it")
    if ext.pinocchio_version() != pin.__version__:
        return None, (f"rrr_pin.sim._rollout was compiled against Pinocchio "
                      f"{ext.pinocchio_version()} but Pinocchio {pin.__version__} is installed "
                      f"(its C++ ABI changes between versions); reinstall rrr-pin "
                      f"(`pip install --force-reinstall .`) or install "
                      f"pin=={ext.pinocchio_version()}")
    return ext, None


#: The compiled extension module, or None when it cannot be used (see :func:`require`).
EXTENSION, _UNAVAILABLE = _load_extension()


def available() -> bool:
    """Whether the compiled extension is built and matches the installed Pinocchio."""
    return EXTENSION is not None


def require() -> None:
    """Raise ``ImportError`` saying why the compiled engine cannot run, if it cannot."""
    if EXTENSION is None:
        raise ImportError(_UNAVAILABLE)


def cannot_start(law, form, engine: str) -> str | None:
    """Why a compiled engine cannot start on ``law`` at all (None: it can try).

    Its compiled ``form`` is None (the law declares none), or the extension is not built
    (:func:`require`'s reason). The engines' own refusals follow.
    """
    if form is None:
        cls = type(getattr(law, "law", law)).__name__  # a sampled wrapper: its law's class
        return (f"law {law.name!r} ({cls}) declares no compiled form, so the {engine} engine "
                f"cannot run it")
    return None if EXTENSION is not None else _UNAVAILABLE


@dataclass(frozen=True)
class CompiledRobot:
    """A plant loaded into the extension, reusable across rollouts and threads.

    Attributes
    ----------
    name : str
        Plant name (for messages).
    joint_names : tuple of str
        Names of the actuated joints, shape (nq,).
    description : TreeDescription or None
        What it was loaded from (:meth:`rrr_pin.model.plant.Plant.description`).
    """

    name: str
    joint_names: tuple[str, ...]
    _model: object = field(repr=False)
    description: object = field(default=None, repr=False)

    @property
    def nq(self) -> int:
        """Number of actuated coordinates."""
        return self._model.na

    @property
    def loops(self) -> int:
        """Number of loop closures of its tree (0: a serial tree), as the extension reads them."""
        return self._model.loops


def cached(cache: dict, robot, load):
    """Return ``load(robot)``, kept in ``cache`` by identity of ``robot.model`` (last 8 models)."""
    key = id(robot.model)
    hit = cache.get(key)
    if hit is not None and hit[0] is robot.model:
        return hit[1]
    out = load(robot)
    if len(cache) >= 8:
        cache.pop(next(iter(cache)))
    cache[key] = (robot.model, out)
    return out


def effects_struct(fx):
    """Return the extension's ``Effects`` of a run's ``Resolved`` effects (None: the ideal plant).

    Every field but ``info`` has a namesake in ``Effects`` (``_ext/effects.hpp``), set by name
    when not None (off); the compiled and the batched engines both take it.
    """
    if fx is None:
        return None
    out = EXTENSION.Effects()
    for f in fields(fx):
        value = getattr(fx, f.name)
        if f.name != "info" and value is not None:
            setattr(out, f.name, value)
    return out


def law_name(form) -> str | None:
    """Return the C++ law that implements a compiled form, or None if the extension has none.

    The ``cpp`` set on the form's exact type (``rrr_pin.control.laws.CompiledForm.cpp``; a
    subclass that does not set its own is another law, never run as its base), if it is one
    of the extension's laws (``LAWS``: the list ``RRR_PIN_LAWS`` of ``_ext/law.hpp``, which
    the compiled and the batched engines both expand).
    """
    name = vars(type(form)).get("cpp")
    return name if EXTENSION is not None and name in EXTENSION.LAWS else None


def law_struct(form):
    """Return the extension's law for a compiled form, its fields set by name.

    Every field of the form but ``nominal`` (``engine_fields``) has a namesake in the C++
    law's own list of fields (``fields()`` in ``_ext/law.hpp``); ``form`` is one
    :func:`law_name` names.
    """
    out = getattr(EXTENSION, law_name(form))()
    for key, value in form.engine_fields().items():
        setattr(out, key, value)
    return out


def law_forms() -> list[type]:
    """Return the compiled form types the extension implements (their ``cpp`` in ``LAWS``)."""
    laws = () if EXTENSION is None else EXTENSION.LAWS
    return [cls for cls in compiled_forms() if vars(cls)["cpp"] in laws]


def law_kinds() -> dict:
    """Return ``kind -> C++ law name`` of :func:`law_forms` (what the floor timings take)."""
    return {cls.kind: vars(cls)["cpp"] for cls in law_forms()}


def effect_fields() -> tuple:
    """Return the fields of the extension's ``Effects`` (``_ext/effects.hpp``), sorted.

    The plant effects both compiled engines run: each written once in C++, applied to a
    plant's vectors by the compiled rollout and to each lane entry by the batched one.
    """
    if EXTENSION is None:
        return ()
    return tuple(sorted(name for name in dir(EXTENSION.Effects) if not name.startswith("_")))
