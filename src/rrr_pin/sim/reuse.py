"""Reuse of the preparation of runs across the runs of a campaign (:func:`reuse_preparation`).

A campaign runs the same laws on the same reference for thousands of plants, and each law on
the same plants. Inside :func:`reuse_preparation`, :func:`reused` computes a value once per
object (held by identity) and key, and hands every later caller the value stored. The values
are the ones each caller would compute, so results are bit for bit those of separate runs.
"""

from __future__ import annotations

from contextlib import contextmanager

__all__ = ["reuse_preparation", "reusing", "reused", "lookup", "keep"]

#: The values kept, active only inside :func:`reuse_preparation` (``None`` outside):
#: ``key -> (object, value)``; and the block's lasting values (``keep=``), or None.
_REUSE: dict | None = None
_LASTING: dict | None = None


@contextmanager
def reuse_preparation(keep: dict | None = None):
    """Within the block, runs of the same reference, law and plant share their preparation.

    Inside this context :func:`rrr_pin.sim.simulation.simulate` samples each reference once
    per grid and discretizes each built-in law once per ``(rate, method)``, and the batched
    engine reads each plant's parameter vector once for all laws, instead of once per run.
    Results are bit for bit those of separate runs: the values kept are the ones a run would
    compute. Laws, references and plants must not be changed inside the block (the values
    are kept by their identity). Re-entrant; the values are dropped when the outermost block
    exits, except the lasting ones (:func:`reused` with ``lasting=True``: a law's or a
    reference's), which go to ``keep`` when it is given: a campaign's job keeps them across
    its chunks.
    """
    global _REUSE, _LASTING
    outer = _REUSE is None
    lasting = keep is not None and _LASTING is None
    if outer:
        _REUSE = {}
    if lasting:
        _LASTING = keep
    try:
        yield
    finally:
        if outer:
            _REUSE = None
        if lasting:
            _LASTING = None


def reusing() -> bool:
    """Whether a :func:`reuse_preparation` block is active."""
    return _REUSE is not None


def reused(obj, key, make, *, lasting: bool = False):
    """``make()``, once per ``obj`` (by identity) and ``key`` inside :func:`reuse_preparation`.

    Outside the block ``make()`` is called every time. Threads preparing runs at once (a
    campaign's ``--threads``) all get the first value stored; an entry of another object that
    had the same ``id`` is replaced, never returned. ``lasting``: kept in the block's ``keep``
    dictionary when it has one (for objects that live as long as it: a job's laws and
    reference), else in the block's.
    """
    cache = _LASTING if lasting and _LASTING is not None else _REUSE
    if cache is None:
        return make()
    full = (id(obj), key)
    hit = cache.get(full)
    if hit is None or hit[0] is not obj:
        made = (obj, make())
        if hit is None:
            hit = cache.setdefault(full, made)  # threads: the first stored is everyone's
        else:
            hit = cache[full] = made  # a stale entry: another object of the same id
    return hit[1]


def lookup(obj, key):
    """Return the value kept for ``obj`` and ``key`` (:func:`keep`, :func:`reused`), or None."""
    cache = _REUSE
    hit = None if cache is None else cache.get((id(obj), key))
    return hit[1] if hit is not None and hit[0] is obj else None


def keep(obj, key, value) -> None:
    """Keep ``value`` for ``obj`` and ``key`` inside :func:`reuse_preparation` (else nothing)."""
    cache = _REUSE
    if cache is not None:
        cache[(id(obj), key)] = (obj, value)
