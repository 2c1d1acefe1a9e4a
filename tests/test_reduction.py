"""Tests of rrr_pin.robust.reduction: NCF balanced truncation and the nu-gap reduction guarantee."""

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.robust.loopshaping import fl_plant, zpk_data
from rrr_pin.robust.ncf import ncfmargin, ncfsyn
from rrr_pin.robust.reduction import ncf_reduce, reduction_guarantee


def test_paper_eq18_reduction_guarantee(paper):
    g = fl_plant(45.0, 1)
    r = paper.reduction
    assert r.guaranteed and r.nugap < r.b
    # Vinnicombe th. 3.8: the guaranteed margin is a lower bound of the computed one
    assert r.b_lower <= r.b_reduced * (1 + 1e-9)
    assert_allclose(r.b_reduced, ncfmargin(g, paper.K_reduced)[0], rtol=1e-12)
    # the final loop is stable (python-control's own interconnection)
    assert np.all(control.feedback(g * paper.K_reduced).poles().real < 0)


def test_ncf_reduce_paper(paper):
    g = fl_plant(45.0, 1)
    r = ncf_reduce(g, paper.K_full, 2)
    assert r.Kr.nstates == 2 and r.guaranteed
    # Glover (1984): ||G - Gr||_inf <= 2 sum of the discarded Hankel singular values
    assert r.eps <= 2 * np.sum(r.hsv[2:]) * (1 + 1e-6)
    assert r.b_lower <= r.b_reduced * (1 + 1e-9)
    assert np.all(control.feedback(g * r.Kr).poles().real < 0)
    # the coprime-factor reduction also gives the paper's eq. (18):
    # K = 47.40 (s + 134.75)(s + 12.17) / ((s + 513.37)(s + 0.19)), 0.5 % per coefficient
    k, z, p = zpk_data(r.Kr)
    assert_allclose(k, 47.40, rtol=5e-3)
    assert_allclose(np.sort(z.real), [-134.75, -12.17], rtol=5e-3)
    assert_allclose(np.sort(p.real), [-513.37, -0.19], rtol=5e-3)


def random_plant(rng, n, p, m):
    A = rng.standard_normal((n, n))
    A -= (np.linalg.eigvals(A).real.max() - 0.5) * np.eye(n)           # unstable
    return control.ss(A, rng.standard_normal((n, m)), rng.standard_normal((p, n)),
                      np.zeros((p, m)))


@pytest.mark.parametrize("seed", range(6))
def test_ncf_reduce_guarantee_random(seed):
    rng = np.random.default_rng(seed)
    P = random_plant(rng, 5, 2, 2)
    K = ncfsyn(P, factor=1.3).Ks                 # 5 states, often unstable itself
    for order in (4, 3, 2):
        r = ncf_reduce(P, K, order)
        assert r.Kr.nstates == order
        assert r.eps <= 2 * np.sum(r.hsv[order:]) * (1 + 1e-6)
        stable = bool(np.all(control.feedback(P, r.Kr).poles().real < 0))
        if r.guaranteed:                         # the theorem: eps < b  =>  stable
            assert stable
            assert r.b_lower <= r.b_reduced * (1 + 1e-9)
        assert (r.b_reduced > 0) == stable


@pytest.mark.parametrize("seed", range(4))
def test_reduction_guarantee_arcsin_bound(seed):
    rng = np.random.default_rng(10 + seed)
    P = random_plant(rng, 3, 1, 1)
    K = ncfsyn(P).Ks
    Kr = control.ss(K.A * (1 + 0.05 * rng.standard_normal()), K.B, K.C, K.D)
    g = reduction_guarantee(P, K, Kr)
    if g.guaranteed:
        assert np.all(control.feedback(P, Kr).poles().real < 0)
        # arcsin b(P, Kr) >= arcsin b(P, K) - arcsin nugap(K, Kr)
        assert np.arcsin(g.b_reduced) >= np.arcsin(g.b) - np.arcsin(g.nugap) - 1e-9
