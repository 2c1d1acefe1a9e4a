"""The grid screens of :mod:`rrr_pin.control.grid_bounds` give the full grid's values.

Independent reference: LAPACK at every grid point (``numpy.linalg.svd`` / ``eigvals`` on the
whole stack), the path the screens replace; the tuner's estimates with ``screen=False``; and
scipy's ``tf2ss`` + ``cont2discrete`` for the hand-written Tustin realization.
"""

from __future__ import annotations

import control
import numpy as np
import pytest
import scipy.signal
from numpy.testing import assert_allclose

from rrr_pin.control.grid_bounds import (
    crossing_intervals,
    gershgorin_discs,
    level_sigmas,
    peak_sigma,
    sigma_bounds,
)
from rrr_pin.control.sampled_loops import (
    _tustin_ss,
    actuator_margin_from_response,
    delay_margin_from_response,
)


def _stack(rng, coupling, shape=(6, 120, 3, 3)):
    """A seeded stack of loop-like responses: a diagonal falling as 1/w^2 plus coupling."""
    w = np.geomspace(0.1, 3000.0, shape[1])
    s = 1j * w[None, :, None]
    diag = (2.0 * 40.0 * s + 1600.0 * (1 + rng.uniform(0.5, 2.0, (shape[0], 1, 3)))
            ) / (s * s)
    L = np.zeros(shape, complex)
    idx = np.arange(3)
    L[..., idx, idx] = diag * rng.uniform(0.8, 1.2, (shape[0], 1, 3))
    off = rng.normal(size=shape) + 1j * rng.normal(size=shape)
    off[..., idx, idx] = 0.0
    L += coupling * np.abs(diag).mean(axis=-1)[..., None, None] * off
    return L, w


@pytest.mark.parametrize("coupling", [0.0, 0.05, 0.5, 3.0], ids=["diag", "weak", "mid",
                                                                  "strong"])
def test_sigma_screens_equal_lapack_everywhere(coupling):
    rng = np.random.default_rng(11)
    L, _ = _stack(rng, coupling)
    S = np.linalg.inv(np.eye(3) + L)
    full = np.linalg.svd(S, compute_uv=False)[..., 0]
    lo, hi = sigma_bounds(S)
    assert np.all(lo <= full * (1 + 1e-12)) and np.all(full <= hi * (1 + 1e-12))
    # the peak: the same singular values at the same points (bitwise, one LAPACK routine)
    assert_allclose(peak_sigma(S - 0.5 * np.eye(3)),
                    np.linalg.svd(S - 0.5 * np.eye(3), compute_uv=False)[..., 0].max(axis=1),
                    rtol=0, atol=0)
    lvl = 1 / np.sqrt(2)
    sig = level_sigmas(S, lvl)
    first = np.argmax(full >= lvl, axis=1)
    rows = np.arange(S.shape[0])
    assert np.array_equal(np.argmax(sig >= lvl, axis=1), first)
    assert_allclose(sig[rows, first], full[rows, first], rtol=0, atol=0)
    assert_allclose(sig[rows, first - 1], full[rows, first - 1], rtol=0, atol=0)


@pytest.mark.parametrize("coupling", [0.0, 0.05, 0.5, 3.0], ids=["diag", "weak", "mid",
                                                                  "strong"])
def test_crossing_screens_give_the_full_grid_margins(coupling):
    rng = np.random.default_rng(12)
    L, w = _stack(rng, coupling)
    eigs = np.linalg.eigvals(L)
    discs = gershgorin_discs(L)
    for factor, kind, margin in [
            (None, "modulus", delay_margin_from_response),
            (300.0 / (1j * w + 300.0), "modulus", delay_margin_from_response),
            (np.exp(-1j * w * 0.002), "real", actuator_margin_from_response)]:
        f = np.ones(w.size) if factor is None else factor
        full = margin(None, w, eigs * f[None, :, None])
        iv = crossing_intervals(discs, factor, kind)
        need = np.zeros(L.shape[:2], bool)
        need[:, :-1] |= iv
        need[:, 1:] |= iv
        part = np.full(eigs.shape, np.nan, complex)
        part[need] = eigs[need]
        assert_allclose(margin(None, w, part * f[None, :, None], iv), full, rtol=0, atol=0)
        if coupling <= 0.05:
            assert need.mean() < 0.5   # the screen skips most points of a near-diagonal loop


@pytest.mark.parametrize("num, den", [([1.0, 3.0, 7.0], [1.0, 20.0, 100.0]), ([2.0], [1.0]),
                                      ([0.5, 4.0], [0.01, 1.0]),
                                      ([1.0, 2.0, 3.0, 4.0], [2.0, 5.0, 7.0, 9.0])],
                         ids=["order2", "gain", "lead", "order3"])
def test_tustin_realization_is_scipys(num, den):
    A, B, C, D = scipy.signal.tf2ss(num, den)
    got = _tustin_ss(control.tf(num, den), 1e-3)
    if len(den) == 1:   # a static gain: no state here (scipy keeps a dummy one), D alike
        assert got[0].shape == (0, 0) and got[3] == D[0, 0]
        return
    want = scipy.signal.cont2discrete((A, B, C, D), 1e-3, method="bilinear")[:4]
    for g, x in zip(got, want, strict=True):
        g, x = np.asarray(g, float), np.asarray(x, float)
        assert g.size == x.size
        assert_allclose(g.ravel(), x.ravel(), rtol=1e-13, atol=1e-15)


def test_tuner_estimates_are_the_same_screened_or_not(rrr, paper):
    from rrr_pin import Tolerances
    from rrr_pin.campaign.requirements import (
        ActuatorBandwidth,
        Bandwidth,
        DelayMargin,
        DiskMargin,
        NoiseGain,
    )
    from rrr_pin.campaign.tuning import _context, _Eval
    from rrr_pin.control.references import default_reference

    plants = [rrr] + [rrr.perturbed(np.random.default_rng([0, k]), Tolerances())[0]
                      for k in range(2)]
    ctx = _context(rrr, plants, default_reference(rrr), 1000.0, {}, 2.0)
    reqs = [DelayMargin(0.006), DelayMargin(0.006, actuator=300.0), DiskMargin(0.5),
            ActuatorBandwidth(300.0, delay=0.002), ActuatorBandwidth(300.0), Bandwidth(20.0),
            NoiseGain(1.0)]
    for lam, K in ((45.0, paper.K_reduced), (100.0, None), (30.0, control.tf([2, 10],
                                                                              [1, 50]))):
        vals = {}
        for screen in (True, False):
            ctx.screen = screen
            ev = _Eval(ctx, lam, K)
            vals[screen] = [r.estimate(ctx, ev) for r in reqs]
        # the same LAPACK routines on the points that decide: equal to rounding
        assert_allclose(vals[True], vals[False], rtol=1e-12)
