"""A run's failure travels back from a worker process whole: type, message and attributes.

A campaign on ``--jobs 2`` runs its plants in worker processes; an exception that ends a run as
a recorded outcome (a plant's ``failures``, a divergence) is pickled on its way back. An
exception whose ``__init__`` takes more than the message cannot be rebuilt by the default
pickling (``BaseException.__reduce__`` passes ``args`` only), and the worker pool then breaks
instead of recording the row: this is what these tests guard.
"""

from __future__ import annotations

import pickle
from concurrent.futures import ProcessPoolExecutor

import pytest

from rrr_pin.model.closed_chain import ConstraintDrift, LoopClosureError, SingularConfiguration
from rrr_pin.model.plant import EFFORT_LIMITS, CapabilityError
from rrr_pin.sim.trajectory import SimulationDiverged

# Each failure with the attributes a recorded row reads from it.
FAILURES = [
    (SingularConfiguration("type-II singularity at t = 1.305 s: cond(J_p) = 3.1e+09", 3.1e9),
     {"cond": 3.1e9}),
    (CapabilityError("plant 'fivebar' has no effort limits", EFFORT_LIMITS),
     {"capability": EFFORT_LIMITS}),
    (SimulationDiverged("diverged at t = 0.42 s (joint2)", 0.42, "joint2"),
     {"time": 0.42, "joint": "joint2"}),
    (LoopClosureError("the loop does not close near the seed"), {}),
    (ConstraintDrift("loop gap 2e-07 m at t = 0.3 s"), {}),
]


def _raise(exc):
    raise exc


@pytest.mark.parametrize("exc, attrs", FAILURES, ids=[type(e).__name__ for e, _ in FAILURES])
def test_failure_pickles_whole(exc, attrs):
    back = pickle.loads(pickle.dumps(exc))
    assert type(back) is type(exc)
    assert str(back) == str(exc)
    for key, value in attrs.items():
        assert getattr(back, key) == value


def test_failures_cross_a_worker_process():
    # The path a campaign's row takes: raised in a worker, re-raised in the parent.
    with ProcessPoolExecutor(max_workers=1) as pool:
        for exc, attrs in FAILURES:
            with pytest.raises(type(exc)) as info:
                pool.submit(_raise, exc).result(timeout=60)
            assert str(info.value) == str(exc)
            for key, value in attrs.items():
                assert getattr(info.value, key) == value
