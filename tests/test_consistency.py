"""Tests of rrr_pin.model.identification.consistency's solver wrapper."""

import warnings

import pytest

from rrr_pin.model.identification import consistency
from rrr_pin.model.identification.consistency import SolverAccuracyWarning


class _Problem:
    """A stand-in for a cvxpy problem whose solve warns as cvxpy does on 'optimal_inaccurate'."""

    status = "optimal_inaccurate"

    def solve(self, solver):
        warnings.warn("Solution may be inaccurate. Try another solver, adjusting the solver "
                      "settings, or solve with verbose=True for more information.", UserWarning,
                      stacklevel=2)
        warnings.warn("another warning", RuntimeWarning, stacklevel=2)


def test_an_inaccurate_solution_is_one_named_warning_per_process(monkeypatch):
    # issue 50: cvxpy's raw "Solution may be inaccurate" was printed at every draw of a
    # campaign; it is now one SolverAccuracyWarning naming the problem, per process; other
    # warnings pass through as they came.
    monkeypatch.setattr(consistency, "_WARNED", set())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):
            assert consistency._solve(_Problem(), "nearest test") == "optimal_inaccurate"
    mine = [w for w in caught if w.category is SolverAccuracyWarning]
    assert len(mine) == 1 and "consistency SDP (nearest test)" in str(mine[0].message)
    assert [str(w.message) for w in caught if w.category is RuntimeWarning] == \
        ["another warning"] * 3
    assert not any("Try another solver" in str(w.message) for w in caught)


def test_a_solver_failure_names_the_problem():
    class Failing:
        def solve(self, solver):
            raise RuntimeError("Solver 'CLARABEL' failed")

    with pytest.raises(ValueError, match=r"the consistency SDP \(nearest x\) failed: Solver"):
        consistency._solve(Failing(), "nearest x")
