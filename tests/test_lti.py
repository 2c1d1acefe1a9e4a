"""Tests of rrr_pin.robust.lti: input validation before any conversion, timebases, bilinear maps."""

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.robust.loopshaping import design
from rrr_pin.robust.lti import (
    DimensionMismatchError,
    IllPosedLoopError,
    ImproperSystemError,
    NonFiniteSystemError,
    TimebaseMismatchError,
    check_lti,
    common_timebase,
    to_continuous,
    to_discrete,
)
from rrr_pin.robust.ncf import ncfmargin, ncfsyn


@pytest.mark.parametrize(("sys", "err", "match"), [
    (control.tf([np.nan], [1.0, 1.0]), NonFiniteSystemError, r"K has non-finite .*\(0, 0\)"),
    (control.tf([1.0], [1.0, np.inf]), NonFiniteSystemError, "non-finite"),
    (control.ss([[np.nan]], [[1.0]], [[1.0]], [[0.0]]), NonFiniteSystemError, "A matrix"),
    (control.ss([[-1.0]], [[1.0]], [[1.0]], [[np.inf]]), NonFiniteSystemError, "D matrix"),
    (control.tf([1.0, 2.0, 3.0], [1.0, 1.0]), ImproperSystemError,
     "numerator degree 2 > denominator degree 1"),
    (np.array([[1.0, np.nan]]), NonFiniteSystemError, "gain"),
    (np.zeros((2, 2, 2)), DimensionMismatchError, "2-D gain"),
    ("K", TypeError, "StateSpace"),
    (control.frd([1.0, 2.0], [1.0, 10.0]), TypeError, "FrequencyResponseData"),
], ids=["tf-nan", "tf-inf", "ss-nan", "ss-inf", "improper", "gain-nan", "gain-3d", "str",
        "frd"])
def test_check_lti_named_errors(sys, err, match):
    # checked on the raw coefficients: python-control's ss(tf) never returns on a NaN numerator
    with pytest.raises(err, match=match):
        check_lti(sys, "K")


def test_check_lti_accepts_and_converts():
    out = check_lti(control.tf([1.0, 2.0], [1.0, 3.0]), "K")
    assert isinstance(out, control.StateSpace)
    assert_allclose(out.dcgain(), 2.0 / 3.0, rtol=1e-12)       # (s + 2)/(s + 3) at s = 0
    static = check_lti(2.5, "k")
    assert (static.nstates, static.noutputs, static.ninputs) == (0, 1, 1)
    assert static.D[0, 0] == 2.5


def test_nan_rejected_by_synthesis_and_design():
    # issue 12: these hung inside python-control's conversion; now a named error at once
    with pytest.raises(NonFiniteSystemError, match="G has non-finite"):
        ncfsyn(control.tf([np.nan], [1.0, 1.0]))
    with pytest.raises(NonFiniteSystemError, match="W1 has non-finite"):
        design(W1=control.tf([25.0, np.nan], [1.0, 0.19]))
    with pytest.raises(ImproperSystemError, match="W1 must be proper"):
        design(W1=control.tf([1.0, 1.0], [1.0]))


def test_mixed_timebases_and_ill_posed_loop():
    Pc, Pd = control.tf([1.0], [1.0, 1.0]), control.tf([1.0], [1.0, -0.5], 0.1)
    with pytest.raises(TimebaseMismatchError, match="do not mix"):
        ncfmargin(Pc, control.tf([1.0], [1.0, 2.0], 0.1))
    with pytest.raises(TimebaseMismatchError, match="do not mix"):
        common_timebase(("P", control.ss(Pd)), ("C", control.ss(control.tf([1.0], [1.0, 0.2],
                                                                              0.2))))
    assert common_timebase(("P", control.ss(Pd)), ("k", check_lti(3.0))) == 0.1
    # biproper P with D = 1 and C = -1: I + D_P D_C = 0, the loop has no solution
    P = control.tf([1.0, 2.0], [1.0, 3.0])
    with pytest.raises(IllPosedLoopError, match="ill-posed"):
        ncfmargin(P, -1.0)
    with pytest.raises(DimensionMismatchError, match="Expected C of shape"):
        ncfmargin(P, np.eye(2))


def test_bilinear_maps_frequency_and_roundtrip():
    rng = np.random.default_rng(3)
    A = 0.5 * rng.standard_normal((4, 4))
    Gd = control.ss(A, rng.standard_normal((4, 2)), rng.standard_normal((3, 4)),
                    rng.standard_normal((3, 2)), 0.05)
    Gc = to_continuous(Gd)
    theta = np.linspace(0.1, 3.0, 7)
    # G_c(j tan(theta/2)) = G_d(e^{j theta}): the Cayley map, exact up to rounding
    assert_allclose(np.asarray(Gc(1j * np.tan(theta / 2))), np.asarray(Gd(np.exp(1j * theta))),
                    rtol=1e-10, atol=1e-12)
    back = to_discrete(Gc, 0.05)
    assert back.dt == 0.05
    assert_allclose(np.asarray(back(np.exp(1j * theta))), np.asarray(Gd(np.exp(1j * theta))),
                    rtol=1e-10, atol=1e-12)
    # stability is preserved: |z| < 1  <=>  Re s < 0
    assert np.sum(np.abs(np.linalg.eigvals(A)) < 1) == np.sum(np.linalg.eigvals(Gc.A).real < 0)
