"""Tests of rrr_pin.robust.gap: gap and nu-gap against MATLAB's examples, closed forms, a grid."""

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.robust.gap import directed_gap, gapmetric, nugap
from rrr_pin.robust.lti import DimensionMismatchError, NonFiniteSystemError, TimebaseMismatchError
from rrr_pin.robust.ncf import ncfmargin

s = control.tf("s")


def kappa_max(P1, P2, z):
    """sup of the chordal distance kappa(P1, P2) on the points z (Vinnicombe 2001, eq. 3.3)."""
    H1 = np.moveaxis(np.asarray(P1(z, squeeze=False)), -1, 0)      # (N, p, m)
    H2 = np.moveaxis(np.asarray(P2(z, squeeze=False)), -1, 0)
    p, m = H1.shape[1:]

    def isqrt(M):
        d, V = np.linalg.eigh(M)
        return (V / np.sqrt(d)[:, None, :]) @ np.conj(np.swapaxes(V, 1, 2))

    H2h, H1h = np.conj(np.swapaxes(H2, 1, 2)), np.conj(np.swapaxes(H1, 1, 2))
    K = isqrt(np.eye(p) + H2 @ H2h) @ (H1 - H2) @ isqrt(np.eye(m) + H1h @ H1)
    return float(np.linalg.norm(K, 2, axis=(1, 2)).max())


def test_matlab_example_stable_unstable():
    # MATLAB documentation, gapmetric: P1 = 1/(s - 0.001), P2 = 1/(s + 0.001) ->
    # gap = 0.0021, nugap = 0.0020. MATLAB's gap is an upper bound within tol = 1e-3.
    gap, nu = gapmetric(1 / (s - 0.001), 1 / (s + 0.001))
    # closed form: kappa(w) = 2a / (w^2 + a^2 + 1), largest at w = 0
    assert_allclose(nu, 2e-3 / (1 + 1e-6), rtol=1e-8)
    assert nu <= gap <= 0.0021 + 5e-5
    assert gap > 0.0021 - 1e-3


def test_matlab_example_with_margin():
    # MATLAB documentation, gapmetric: P1 = (s+2)/(s^2+5s+10), P2 = (s+1)/(s^2+3s+10) ->
    # gap = 0.1391, nugap = 0.1390, and b(P1, 4.4/s) = 0.1961 > gap: C stabilizes P2
    P1, P2, C = (s + 2) / (s**2 + 5 * s + 10), (s + 1) / (s**2 + 3 * s + 10), 4.4 / s
    gap, nu = gapmetric(P1, P2)
    assert_allclose(nu, 0.1390, atol=5e-5)      # 4 decimals printed
    # MATLAB's gap is an upper bound within its tol = 1e-3 (documented): 0.1391 - 1e-3 < gap
    assert nu <= gap <= 0.1391 + 5e-5 and gap > 0.1391 - 1e-3
    assert ncfmargin(P1, C)[0] > gap and ncfmargin(P2, C)[0] > 0


@pytest.mark.parametrize(("p1", "p2"), [(2.0, 0.5), (-1.0, 3.0), (0.0, 10.0)])
def test_static_gains_chordal_distance(p1, p2):
    # constant plants: both metrics are the chordal distance |p1 - p2| / sqrt((1+p1^2)(1+p2^2))
    ref = abs(p1 - p2) / np.sqrt((1 + p1**2) * (1 + p2**2))
    gap, nu = gapmetric(p1, p2)
    assert_allclose(nu, ref, rtol=1e-12)
    assert_allclose(gap, ref, rtol=2e-6)         # bisection to rtol 1e-6


def test_winding_number_condition():
    # k/(s - 1) vs k/(s + 1): sup kappa = 2k/(1 + k^2) at w = 0. For k = 0.5 (0.8 < 1) the
    # winding condition fails (wno det(1 + P2~ P1) = 0 but one RHP pole differs): nugap = 1.
    # For k = 1000 the high gain makes them close: nugap = sup kappa = 2e3/(1 + 1e6).
    gap, nu = gapmetric(0.5 / (s - 1), 0.5 / (s + 1))
    assert nu == 1.0 and gap == 1.0
    gap, nu = gapmetric(1000 / (s - 1), 1000 / (s + 1))
    assert_allclose(nu, 2e3 / (1 + 1e6), rtol=1e-8)
    assert nu <= gap < 0.01


def random_plant(rng, n, p, m, unstable):
    A = rng.standard_normal((n, n))
    A -= (np.linalg.eigvals(A).real.max() + (-0.5 if unstable else 0.3)) * np.eye(n)
    return control.ss(A, rng.standard_normal((n, m)), rng.standard_normal((p, n)),
                      0.3 * rng.standard_normal((p, m)))


@pytest.mark.parametrize("seed", range(6))
def test_properties_random_mimo(seed):
    rng = np.random.default_rng(seed)
    P1 = random_plant(rng, 3, 2, 2, unstable=seed % 2 == 0)
    P2 = control.ss(P1.A + 0.3 * rng.standard_normal((3, 3)), P1.B, P1.C, P1.D)
    gap, nu = gapmetric(P1, P2)
    gap21, nu21 = gapmetric(P2, P1)
    # symmetric; nugap <= gap <= 1 (bisection rtol 1e-6 on the upper-bound gap)
    assert_allclose([gap21, nu21], [gap, nu], rtol=2e-6)
    assert nu <= gap * (1 + 1e-9) <= 1.0
    # the two directed gaps are equal when < 1 (Georgiou and Smith 1990): two different
    # Riccati problems agreeing is an independent check of the directed-gap solver
    if gap < 1:
        assert_allclose(directed_gap(P1, P2), directed_gap(P2, P1), rtol=2e-6)
    # nugap against the chordal distance on a dense grid (winding condition holds here)
    w = np.concatenate([[0.0], np.logspace(-3, 3, 6001)])
    assert_allclose(nu, kappa_max(P1, P2, 1j * w), rtol=1e-4)     # grid resolution
    # 0 for equal plants (the Riccati test resolves the gap to ~1e-6 near 0)
    g0, n0 = gapmetric(P1, P1)
    assert n0 < 1e-9 and g0 < 1e-5


def test_discrete_nugap_against_unit_circle_grid():
    rng = np.random.default_rng(11)
    A = 0.4 * rng.standard_normal((3, 3))
    P1 = control.ss(A, rng.standard_normal((3, 2)), rng.standard_normal((2, 3)),
                    np.zeros((2, 2)), 0.01)
    P2 = control.ss(A * 1.1, P1.B, P1.C, P1.D, 0.01)
    gap, nu = gapmetric(P1, P2)
    theta = np.linspace(0.0, np.pi, 20001)
    assert_allclose(nu, kappa_max(P1, P2, np.exp(1j * theta)), rtol=1e-4)
    assert nu <= gap <= 1.0


def test_stabilized_within_nugap_of_b():
    # Vinnicombe th. 3.8: nugap(P0, P1) < b(P0, C)  =>  C stabilizes P1 (seeded plants)
    rng = np.random.default_rng(42)
    P0 = (s + 2) / (s**2 + 5 * s + 10)
    C = 4.4 / s
    b = ncfmargin(P0, C)[0]
    checked = 0
    for _ in range(40):
        num = [1.0, 2.0 + rng.normal(0, 0.5)]
        den = [1.0, 5.0 + rng.normal(0, 1.5), 10.0 + rng.normal(0, 3.0)]
        P1 = control.tf(num, den)
        if nugap(P0, P1) < b:
            checked += 1
            assert np.all(control.feedback(P1 * C).poles().real < 0)
    assert checked >= 5


def test_gap_bad_input():
    with pytest.raises(DimensionMismatchError, match="same shape"):
        gapmetric(1 / (s + 1), np.eye(2))
    with pytest.raises(TimebaseMismatchError, match="do not mix"):
        gapmetric(1 / (s + 1), control.tf([1.0], [1.0, -0.5], 0.1))
    with pytest.raises(NonFiniteSystemError, match="P2 has non-finite"):
        gapmetric(1 / (s + 1), control.tf([np.nan], [1.0, 1.0]))


def _chordal_sup(P1, P2, w):
    # Independent of the graph symbols and of hinf_norm: the chordal distance from the
    # frequency responses, kappa = sigma_max((I + P2 P2*)^-1/2 (P1 - P2) (I + P1* P1)^-1/2),
    # on a grid, then refined by a bounded scalar search around the grid's best point.
    from scipy.linalg import sqrtm
    from scipy.optimize import minimize_scalar

    def kappa(wk):
        a, b = np.atleast_2d(P1(1j * wk)), np.atleast_2d(P2(1j * wk))
        left = np.linalg.inv(sqrtm(np.eye(a.shape[0]) + b @ b.conj().T))
        right = np.linalg.inv(sqrtm(np.eye(a.shape[1]) + a.conj().T @ a))
        return np.linalg.norm(left @ (a - b) @ right, 2)

    vals = np.array([kappa(wk) for wk in w])
    k = int(np.argmax(vals))
    lo, hi = w[max(k - 1, 0)], w[min(k + 1, len(w) - 1)]
    best = minimize_scalar(lambda x: -kappa(10.0 ** x), bounds=(np.log10(lo), np.log10(hi)),
                           method="bounded", options={"xatol": 1e-10})
    return max(vals[k], -best.fun)


def test_nugap_of_nearly_identical_plants_is_not_low():
    # Pairs of plants 1e-5 .. 1e-4 apart (A perturbed): the graph-symbol product has nearly
    # cancelling poles and zeros, and the Hamiltonian search of hinf_norm stopped early; these
    # seeded cases came out 0.6-1.7 % low before (issue 21, item 2). Now equal to the sup of
    # the chordal distance, found independently, to 1e-6 relative (the refinement's accuracy)
    # or 1e-9 absolute: a norm of O(1) graph symbols resolves a gap near 0 to a few 1e-10
    # (measured: 2.4e-10 on a 6.7e-6 gap with SciPy 1.17, slycot 0.7.1; gapmetric's docstring).
    rng = np.random.default_rng(0)
    cases = []
    for _ in range(20):
        n, m = int(rng.integers(3, 9)), int(rng.integers(1, 3))
        A = rng.normal(size=(n, n))
        A -= (max(np.linalg.eigvals(A).real) + rng.uniform(0.1, 2)) * np.eye(n)
        B, C, D = rng.normal(size=(n, m)), rng.normal(size=(m, n)), 0.1 * rng.normal(size=(m, m))
        eps = 10 ** rng.uniform(-5, -2)
        cases.append((control.ss(A, B, C, D),
                      control.ss(A * (1 + eps * rng.normal(size=A.shape)), B, C, D)))
    w = np.logspace(-3, 4, 1401)
    for k in (0, 6, 13, 17, 19):  # the ones that were low by more than 0.5 %
        P1, P2 = cases[k]
        assert_allclose(nugap(P1, P2), _chordal_sup(P1, P2, w), rtol=1e-6, atol=1e-9)
