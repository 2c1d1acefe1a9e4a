"""Tests of rrr_pin.robust.loopshaping: barriers, plant, weights, ncfsyn, reduction, design, CLI."""


import json
import warnings

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.cli import main
from rrr_pin.robust.barriers import (
    barrier_intersection,
    robust_performance_barrier,
    robust_stability_barrier,
)
from rrr_pin.robust.loopshaping import (
    LAM_RANGE,
    design,
    fl_plant,
    lag_weight,
    loopsyn,
    zpk_data,
)
from rrr_pin.robust.lti import (
    DimensionMismatchError,
    ImproperSystemError,
    TimebaseMismatchError,
    expand_diagonal,
)
from rrr_pin.robust.ncf import (
    HiddenModeError,
    WeightError,
    ncfmargin,
    ncfsyn,
    shaped_plant,
)
from rrr_pin.robust.reduction import reduce_controller
from rrr_pin.robust.robustness import ncf_loop

OMEGA = np.logspace(-2, 4, 61)


def static(D):
    """Static gain as a state-space system with no states."""
    D = np.atleast_2d(D)
    return control.ss(np.zeros((0, 0)), np.zeros((0, D.shape[1])), np.zeros((D.shape[0], 0)), D)


def resp(sys, w=OMEGA):
    return np.asarray(sys(1j * np.asarray(w), squeeze=False))


# --- barriers ---------------------------------------------------------------------------------

def test_barriers_reproduce_paper_eq13_eq15():
    s = 1j * OMEGA
    # Closed forms printed in the paper, eq. (13) and (15); exact up to rounding.
    assert_allclose(resp(robust_stability_barrier())[0, 0], 1000 / (s + 200), rtol=1e-12)
    assert_allclose(resp(robust_performance_barrier())[0, 0], -1e6 / ((s - 800) * (s + 100)),
                    rtol=1e-12)


@pytest.mark.parametrize(("rel", "w", "specs", "rsb", "rpb"), [
    # 10 % up to 100 rad/s: eM = (s+100)/1000 -> RSB = 1000/(s+100)
    (0.1, 100.0, ((0.05, 50.0),),
     lambda s: 1000 / (s + 100),
     lambda s: (1000 / (s + 50)) / (1 - (s + 100) / 1000)),
    # one spec only, the strictest error and the widest band are taken from two specs
    (0.3, 300.0, ((0.2, 10.0), (0.4, 20.0)),
     lambda s: 1000 / (s + 300),
     lambda s: (5 * 20 / (s + 20)) / (1 - 0.3 * (s / 300 + 1))),
], ids=["tighter-model", "two-specs"])
def test_barriers_from_requirements(rel, w, specs, rsb, rpb):
    s = 1j * OMEGA
    # Hand-written eq. (12)-(15) for other requirements; exact up to rounding.
    assert_allclose(resp(robust_stability_barrier(rel, w))[0, 0], rsb(s), rtol=1e-12)
    assert_allclose(resp(robust_performance_barrier(specs, rel, w))[0, 0], rpb(s), rtol=1e-12)


def test_barrier_intersection_closed_form():
    # |1000/(jw+200)| = |1e6/((jw-800)(jw+100))|  <=>  u^2 - 3.5e5 u - 3.36e10 = 0, u = w^2
    u = (3.5e5 + np.sqrt(3.5e5**2 + 4 * 3.36e10)) / 2
    wx = barrier_intersection()
    assert wx.shape == (1,)
    assert_allclose(wx[0], np.sqrt(u), rtol=1e-9)     # brentq to xtol 1e-12
    # below the crossing RPB lies above RSB: robust performance impossible there
    w = np.array([1.0, 100.0, 0.99 * wx[0]])
    assert np.all(np.abs(resp(robust_performance_barrier(), w)) >
                  np.abs(resp(robust_stability_barrier(), w)))


@pytest.mark.parametrize(("bad", "match"), [
    ({"rel_error": 0.0}, "rel_error"), ({"w_error": -1.0}, "w_error"),
    ({"rel_error": 1.5}, "rel_error must be < 1"), ({"specs": [0.1, 80]}, "shape"),
    ({"specs": ((0.1, -80.0),)}, "positive"),
], ids=["zero-error", "negative-w", "error>1", "flat-specs", "negative-spec"])
def test_barrier_bad_input(bad, match):
    with pytest.raises(ValueError, match=match):
        robust_performance_barrier(**bad)


# --- plant and weights ------------------------------------------------------------------------

@pytest.mark.parametrize(("lam", "n"), [(45.0, 3), (100.0, 1), (7.5, 6)],
                         ids=["paper", "siso", "six-joints"])
def test_fl_plant_eq11(lam, n):
    G = fl_plant(lam, n)
    assert (G.noutputs, G.ninputs, G.nstates) == (n, n, 2 * n)
    H = resp(G)
    g = lam**2 / (1j * OMEGA + lam) ** 2
    # exact transfer function of eq. (11) on the diagonal, zeros elsewhere
    assert_allclose(H, np.eye(n)[:, :, None] * g, rtol=1e-10, atol=1e-14)


def test_weights_and_shaped_plant():
    s = 1j * OMEGA
    assert_allclose(resp(lag_weight())[0, 0], 25 * (s + 11.5) / (s + 0.19), rtol=1e-12)
    Gs = shaped_plant(fl_plant(45.0, 2), lag_weight(), 2.0)
    expect = 2.0 * 25 * (s + 11.5) / (s + 0.19) * 45**2 / (s + 45) ** 2
    # off-diagonal: rounding of the series realization, ~1e-14 of the |Gs| ~ 3e3 entries
    assert_allclose(resp(Gs), np.eye(2)[:, :, None] * expect, rtol=1e-10, atol=1e-9)


def test_expand_diagonal():
    K = control.tf([2.0, 3.0], [1.0, 4.0])
    Kn = expand_diagonal(K, 4)
    assert isinstance(Kn, control.StateSpace)
    assert (Kn.noutputs, Kn.ninputs, Kn.nstates) == (4, 4, 4)
    assert_allclose(resp(Kn), np.eye(4)[:, :, None] * resp(K)[0, 0], rtol=1e-12, atol=1e-14)
    with pytest.raises(ValueError, match="SISO"):
        expand_diagonal(fl_plant(1.0, 2), 2)


# --- ncfsyn -----------------------------------------------------------------------------------

def generalized_plant(Gs):
    """NCF problem as a standard H-inf problem: w = [w1; w2], u -> z = [y; u], meas. y."""
    A, B, C, D = Gs.A, Gs.B, Gs.C, Gs.D
    n, (p, m) = A.shape[0], D.shape
    Bp = np.hstack([np.zeros((n, p)), B, B])
    Cp = np.vstack([C, np.zeros((m, n)), C])
    Dp = np.block([[np.eye(p), D, D], [np.zeros((m, p + m)), np.eye(m)], [np.eye(p), D, D]])
    return control.ss(A, Bp, Cp, Dp)


def test_ncfsyn_paper_gamma(paper):
    r = paper.ncf
    # The paper prints gamma = 2.1436 and eps = 0.4665 (4 decimals): half a unit of the last digit.
    assert_allclose(r.gamma_min, 2.1436, atol=5e-5)
    assert_allclose(r.emax, 0.4665, atol=5e-5)
    assert r.emax >= 0.2
    # factor = 1: the achieved index is the optimum (to the norm solver's accuracy)
    assert_allclose(r.gamma, r.gamma_min, rtol=1e-8)
    # MIMO 3x3 synthesis == SISO synthesis for the decoupled plant
    siso = ncfsyn(fl_plant(45.0, 1), lag_weight())
    assert_allclose(r.gamma_min, siso.gamma_min, rtol=1e-10)
    assert (r.K.noutputs, r.K.ninputs) == (3, 3)


def test_ncfsyn_gamma_independent_norms(paper):
    r = ncfsyn(fl_plant(45.0, 1), lag_weight())
    # 1) slycot AB13DD (control.linfnorm) on the python-control interconnection
    #    [I; Ks](I + Gs Ks)^-1 [I Gs] (feedback/append, not our ncf_loop); norm to 1e-10.
    eye = static(np.eye(1))
    S = control.feedback(eye, r.Gs * r.Ks)                          # (I + Gs Ks)^-1
    left = control.append(eye, r.Ks) * static(np.ones((2, 1)))  # [I; Ks]
    right = static(np.ones((1, 2))) * control.append(eye, r.Gs)  # [I  Gs]
    lin = control.linfnorm(left * S * right)[0]
    assert_allclose(lin, r.gamma, rtol=1e-7)
    # 2) the optimal H-inf index of the equivalent generalized plant (slycot SB10AD via
    #    control.hinfsyn); SB10AD's gamma iteration stops within ~1e-8 of the optimum.
    _, _, gam, _ = control.hinfsyn(generalized_plant(r.Gs), 1, 1)
    assert_allclose(gam, r.gamma_min, rtol=1e-6)


def test_ncfsyn_internal_stability_and_sign(paper):
    r = ncfsyn(fl_plant(45.0, 1), lag_weight())
    # negative feedback, python-control convention: both loops stable, all states included
    for cl in (control.feedback(r.Gs, r.Ks), control.feedback(fl_plant(45.0, 1), r.K)):
        assert np.all(cl.poles().real < 0)
    # the positive-feedback controller of MATLAB/Octave is -K: it must NOT stabilize here
    assert np.any(control.feedback(r.Gs, -r.Ks).poles().real >= 0)
    # DC tracking of the loop G K: lag weight -> high loop gain, small steady-state error
    T = control.feedback(fl_plant(45.0, 1) * r.K)
    assert_allclose(T.dcgain(), 1.0, atol=2e-3)


def random_plant(rng, n, p, m, unstable, biproper):
    A = rng.standard_normal((n, n))
    shift = np.linalg.eigvals(A).real.max()
    # stable: all poles at Re <= -0.1; unstable: the rightmost pole at Re in [0.5, 2]
    A -= (shift + (-rng.uniform(0.5, 2.0) if unstable else rng.uniform(0.1, 1.0))) * np.eye(n)
    D = rng.standard_normal((p, m)) if biproper else np.zeros((p, m))
    return control.ss(A, rng.standard_normal((n, m)), rng.standard_normal((p, n)), D)


CASES = [(seed, n, p, m, unstable, biproper)
         for seed, (n, p, m) in enumerate([(1, 1, 1), (3, 1, 1), (4, 2, 2), (3, 3, 2), (5, 2, 3)])
         for unstable in (False, True) for biproper in (False, True)]


@pytest.mark.parametrize(("seed", "n", "p", "m", "unstable", "biproper"), CASES,
                         ids=[f"s{c[0]}-{c[1]}x{c[2]}x{c[3]}-{'uns' if c[4] else 'st'}-"
                              f"{'D' if c[5] else '0'}" for c in CASES])
@pytest.mark.parametrize("factor", [1.0, 1.3])
def test_ncfsyn_random_plants(seed, n, p, m, unstable, biproper, factor):
    rng = np.random.default_rng(seed)
    G = random_plant(rng, n, p, m, unstable, biproper)
    assert (np.linalg.eigvals(G.A).real.max() > 0) == unstable
    r = ncfsyn(G, factor=factor)
    # internal stability via python-control's own feedback interconnection
    assert np.all(control.feedback(r.Gs, r.Ks).poles().real < 0)
    # achieved index == independent norm (slycot AB13DD) of the 4-block loop
    assert_allclose(control.linfnorm(ncf_loop(r.Gs, r.Ks))[0], r.gamma, rtol=1e-7)
    # optimality: gamma_min <= gamma <= factor gamma_min (central controller, S&P 9.4.2)
    assert r.gamma_min * (1 - 1e-9) <= r.gamma <= factor * r.gamma_min * (1 + 1e-9)
    if factor == 1.0:
        assert_allclose(r.gamma, r.gamma_min, rtol=1e-7)
        assert r.Ks.nstates < r.Gs.nstates          # the singular direction is eliminated
    else:
        assert r.Ks.nstates == r.Gs.nstates
    assert_allclose(r.emax, 1 / r.gamma, rtol=1e-14)


def test_ncfsyn_hinfsyn_random_mimo():
    rng = np.random.default_rng(7)
    G = random_plant(rng, 3, 2, 2, unstable=True, biproper=True)
    r = ncfsyn(G)
    _, _, gam, _ = control.hinfsyn(generalized_plant(r.Gs), 2, 2)
    # SB10AD's optimal gamma; its bisection stops within ~1e-8 relative
    assert_allclose(gam, r.gamma_min, rtol=1e-6)


def test_ncfsyn_errors():
    G = fl_plant(45.0, 2)
    with pytest.raises(ValueError, match="factor must be >= 1"):
        ncfsyn(G, factor=0.9)
    with pytest.raises(WeightError, match="must be square"):
        ncfsyn(G, W1=control.tf([[[1.0]], [[1.0]]], [[[1.0, 1.0]], [[1.0, 2.0]]]))
    with pytest.raises(WeightError, match="must be 2 x 2"):
        ncfsyn(G, W1=fl_plant(1.0, 3))
    with pytest.raises(ImproperSystemError, match="W2 must be proper"):
        ncfsyn(G, W2=control.tf([1.0, 1.0], [1.0]))
    with pytest.raises(TimebaseMismatchError, match="do not mix"):
        ncfsyn(control.tf([1.0], [1.0, 1.0], 0.1), W1=control.tf([1.0], [1.0, 2.0]))
    # unstable mode at s = 1 that the input cannot reach
    hidden = control.ss([[1.0, 0.0], [0.0, -1.0]], [[0.0], [1.0]], [[1.0, 1.0]], [[0.0]])
    with pytest.raises(HiddenModeError, match="uncontrollable mode at s = 1"):
        ncfsyn(hidden)
    # a weight zero cancelling the unstable plant pole hides it too: W1 before G blocks the
    # input (uncontrollable), W2 after G blocks the output (unobservable)
    G1, Wz = control.tf([1.0], [1.0, -2.0]), control.tf([1.0, -2.0], [1.0, 5.0])
    with pytest.raises(HiddenModeError, match="uncontrollable mode at s = 2"):
        ncfsyn(G1, W1=Wz)
    with pytest.raises(HiddenModeError, match="unobservable mode at s = 2"):
        ncfsyn(G1, W2=Wz)


# --- reduction and eq. (18) -------------------------------------------------------------------

def test_reduced_controller_eq18(paper):
    k, z, p = zpk_data(paper.K_reduced)
    assert paper.K_reduced.nstates == 2
    # eq. (18): K = 47.40 (s + 134.75)(s + 12.17) / ((s + 513.37)(s + 0.19)); the issue's
    # tolerance is 0.5 % on each printed coefficient.
    assert_allclose(k, 47.40, rtol=5e-3)
    assert_allclose(np.sort(z.real), [-134.75, -12.17], rtol=5e-3)
    assert_allclose(np.sort(p.real), [-513.37, -0.19], rtol=5e-3)
    assert np.all(z.imag == 0) and np.all(p.imag == 0)
    # the reduction barely changes the robustness index on Gs
    assert_allclose(paper.gamma_reduced, paper.ncf.gamma, rtol=1e-4)


def test_reduce_controller_against_balred(paper):
    # no fast mode in the optimal K: plain balanced truncation; compare with slycot AB09AD
    # (control.balred, truncation): same Hankel-truncated model up to realization.
    ref = control.balred(paper.K_full, 2, method="truncate")
    assert_allclose(resp(reduce_controller(paper.K_full, 2)), resp(ref), rtol=1e-8)


def test_reduce_controller_fast_pole_and_cancellation():
    s = control.tf("s")
    # 10 (s+1)/(s+2) with a near cancellation at -5 and a fast pole at -1e7 (unit DC gain)
    K = control.ss(10 * (s + 1) * (s + 5.0005) / ((s + 2) * (s + 5)) * 1e7 / (s + 1e7))
    Kr = reduce_controller(K, order=1)
    # residualizing the fast pole and truncating the 1e-4-sized cancellation leaves the
    # first-order lag within ~1e-4 relative
    assert_allclose(resp(Kr), resp(control.ss(10 * (s + 1) / (s + 2))), rtol=2e-4)
    with pytest.raises(ValueError, match="modes with Re"):
        reduce_controller(control.ss(control.tf([1.0], [1.0, -1.0, 2.0])), order=1)


def test_near_optimal_fast_pole_removed():
    d = design(factor=1.0 + 1e-6, n=1)
    _, _, p = zpk_data(d.K_full)
    assert np.abs(p).max() > 1e6           # the near-singular fast pole of the formula
    k, z, p = zpk_data(d.K_reduced)
    assert_allclose(k, 47.40, rtol=5e-3)   # eq. (18) again once it is residualized
    assert_allclose(np.sort(p.real), [-513.37, -0.19], rtol=5e-3)


def test_design_interface(paper):
    d = paper
    for sys in (d.G, d.W1, d.W2, d.Gs, d.K):
        assert (sys.noutputs, sys.ninputs) == (3, 3)
    for K in (d.K_full, d.K_reduced):
        assert isinstance(K, control.StateSpace)
        assert (K.noutputs, K.ninputs) == (1, 1)
    assert d.robust_stability.ok and not d.robust_performance.ok
    with pytest.raises(WeightError, match="diagonal copy"):
        design(W1=static(np.diag([1.0, 2.0, 3.0])))
    with pytest.raises(WeightError, match=r"W1 must be biproper .*D = \[\[0.0\]\]"):
        design(W1=control.tf(1.0, [1.0, 1.0]))


# --- CLI --------------------------------------------------------------------------------------

def test_cli_design_json(capsys, tmp_path, strict_json):
    assert main(["design", "--json", "--joints", "2", "--out", str(tmp_path)]) == 0
    out = strict_json(capsys.readouterr().out)
    for key in ("gamma_min", "gamma", "emax", "K_full", "K_reduced",
                "robust_stability", "robust_performance"):
        assert key in out
    assert_allclose(out["gamma_min"], 2.1436, atol=5e-5)    # paper, 4 decimals
    assert_allclose(out["K_reduced"]["gain"], 47.40, rtol=5e-3)
    assert len(out["K_reduced"]["zeros"][0]) == 2           # [re, im]
    assert out["robust_stability"]["ok"] and not out["robust_performance"]["ok"]
    # issue 11: the final loop's NCF margin and each reduction's guarantee
    assert 0 < out["ncfmargin"] <= 1
    eq18 = out["reductions"]["eq18"]["shaped_loop"]
    assert eq18["guaranteed"] and eq18["nugap"] < eq18["b"]
    assert_allclose(eq18["b"], 1 / out["gamma"], rtol=1e-9)            # b(Gs, Ks) = 1/gamma
    assert_allclose(eq18["b_reduced"], 1 / out["gamma_reduced"], rtol=1e-9)
    assert out["reductions"]["ncf_balanced_truncation"]["guaranteed"]
    for name in ("fig2.png", "fig3.png", "fig4a.png", "fig4b.png", "margins.png"):
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"


def test_cli_design_text_and_error(capsys):
    assert main(["design"]) == 0
    text = capsys.readouterr().out
    assert "gamma_min = 2.1436" in text and "robust performance: NOT satisfied" in text
    assert "eq. (18) reduction on the shaped loop" in text and "stability guaranteed" in text
    assert main(["design", "--factor", "0.5"]) == 2
    assert "factor must be >= 1" in capsys.readouterr().err


# --- loopsyn ----------------------------------------------------------------------------------

G1 = control.tf([45.0**2], [1.0, 90.0, 45.0**2])

#: NASA HiMAT aircraft, 2 x 2, unstable, ill-conditioned: the plant of MathWorks' example
#: "Loop-Shaping Controller Design" (Robust Control Toolbox), target Gd = 8/s.
A_HIMAT = np.array([
    [-2.2567e-02, -3.6617e+01, -1.8897e+01, -3.2090e+01, 3.2509e+00, -7.6257e-01],
    [9.2572e-05, -1.8997e+00, 9.8312e-01, -7.2562e-04, -1.7080e-01, -4.9652e-03],
    [1.2338e-02, 1.1720e+01, -2.6316e+00, 8.7582e-04, -3.1604e+01, 2.2396e+01],
    [0, 0, 1, 0, 0, 0], [0, 0, 0, 0, -30, 0], [0, 0, 0, 0, 0, -30]])
HIMAT = control.ss(A_HIMAT, 30.0 * np.eye(6)[:, 4:], np.eye(6)[[1, 3]], np.zeros((2, 2)))


def test_loopsyn_relative_degree_three_with_an_integrator_target():
    # issue 21: G = 200/((10s+1)(0.05s+1)^2) with Gd = 10/s was refused (W1 = G^-1 Gd improper)
    G = control.tf(200.0, [10.0, 1.0]) * control.tf(1.0, [0.05, 1.0]) ** 2
    Gd = control.tf(10.0, [1.0, 0.0])
    K, CL, gamma, info = loopsyn(G, Gd)
    # the weight: stable, minimum phase, biproper
    assert np.all(info.weight.poles().real < 0) and np.all(info.weight.zeros().real < 0)
    assert info.weight.nstates == len(info.weight.zeros())
    # its magnitude against the closed form |Gd|/|G| = 10 |(10jw+1)(0.05jw+1)^2| / (200 w),
    # half a decade inside the band (at the band ends the weight turns flat: 3 dB per corner)
    lo, hi = info.band
    w = np.logspace(np.log10(lo) + 0.5, np.log10(hi) - 0.5, 400)
    ratio = 10.0 / w * np.abs((10j * w + 1) * (0.05j * w + 1) ** 2) / 200.0
    err = 20 * np.log10(np.abs(info.weight(1j * w)).ravel() / ratio)
    assert np.abs(err).max() < 1.5                       # dB; Bode asymptotes refined
    # alpha = 0.5: b(Gs, Ks) >= 0.5 b_max, with an independent H-inf norm (SLICOT AB13DD)
    b = 1.0 / control.linfnorm(ncf_loop(info.Gs, info.Ks), tol=1e-8)[0]
    assert_allclose(info.b, b, rtol=1e-6)
    assert b >= 0.5 * info.b_max * (1 - 1e-6)
    assert_allclose(info.b_max, 1 / ncfsyn(info.Gs).gamma_min, rtol=1e-12)
    # CL = feedback(G K), stable; gamma = sup sqrt(|Gd S|^2 + |T / Gd|^2) (SISO closed form of
    # the stacked singular value) from python-control's responses of S and T, on the band
    assert np.all(CL.poles().real < 0)
    wb = np.logspace(np.log10(lo), np.log10(hi), 2000)
    S = np.asarray(control.feedback(1, G * K)(1j * wb)).ravel()
    T = np.asarray(CL(1j * wb)).ravel()
    gd = 10.0 / (1j * wb)
    assert_allclose(gamma, np.max(np.sqrt(np.abs(gd * S) ** 2 + np.abs(T / gd) ** 2)),
                    rtol=2e-3)                           # grids of 60 and 2000 per band


def test_loopsyn_tradeoff_unstable_nonminimum_phase():
    # unstable (pole at 1, integrator) and non-minimum phase (zero at 2): the weight fit uses
    # magnitudes only; the loop must still be internally stable
    G = control.tf([-1.0, 2.0], [1.0, -1.0, 0.0]) * control.tf(1.0, [0.1, 1.0])
    Gd = control.tf(1.0, [1.0, 0.0])
    res = {a: loopsyn(G, Gd, alpha=a) for a in (0.0, 0.5, 1.0)}
    for a, r in res.items():
        assert r.b >= a * r.b_max * (1 - 1e-9)           # MATLAB's meaning of alpha
        assert np.all(control.feedback(G * r.K).poles().real < 0)
    # the feasible sets are nested in alpha, so the best gamma cannot improve with alpha
    g = [res[a].gamma for a in (0.0, 0.5, 1.0)]
    assert g[0] <= g[1] * (1 + 1e-9) and g[1] <= g[2] * (1 + 1e-9)
    assert res[1.0].blend == 1.0


def test_loopsyn_mimo_alpha_one_is_ncfsyn_with_the_same_weights():
    # MathWorks' HiMAT example (2 x 2, unstable). The doc states a gap of about 40 dB between
    # the plant's singular values near 8 rad/s: a check of the example data.
    sv = np.linalg.svd(np.asarray(HIMAT(8j)), compute_uv=False)
    assert 35 < 20 * np.log10(sv[0] / sv[1]) < 45
    r = loopsyn(HIMAT, control.tf(8.0, [1.0, 0.0]), alpha=1.0)
    direct = ncfsyn(HIMAT, r.W1)                         # a direct ncfsyn, same weights
    assert_allclose(1 / r.b_max, direct.gamma_min, rtol=1e-10)
    assert_allclose(r.b, 1 / direct.gamma, rtol=1e-10)
    assert_allclose(resp(r.K), resp(direct.K), rtol=1e-8, atol=1e-10)
    assert np.all(control.feedback(HIMAT * r.K, np.eye(2)).poles().real < 0)
    assert (r.W1.noutputs, r.W1.ninputs) == (2, 2)
    # the weight against the log-mean singular value ratio |Gd| / sqrt(s1 s2) of G, with G's
    # response from numpy (C (jwI - A)^-1 B), half a decade inside the band
    lo, hi = r.band
    w = np.logspace(np.log10(lo) + 0.5, np.log10(hi) - 0.5, 200)
    target = [8.0 / wk / np.sqrt(np.prod(np.linalg.svd(
        HIMAT.C @ np.linalg.solve(1j * wk * np.eye(6) - HIMAT.A, HIMAT.B), compute_uv=False)))
        for wk in w]
    err = 20 * np.log10(np.abs(r.weight(1j * w)).ravel() / target)
    assert np.abs(err).max() < 1.5    # dB, the fit's own goal inside the band (measured 0.72)


def test_loopsyn_more_inputs_than_outputs():
    # 1 x 2 plant: W1 = w R with R (2 x 1) the dominant input direction; K is 2 x 1
    G = control.tf([[[1.0], [2.0]]], [[[1.0, 1.0], [1.0, 3.0]]])
    r = loopsyn(G, control.tf(5.0, [1.0, 0.0]))
    assert (r.K.noutputs, r.K.ninputs) == (2, 1)
    assert np.all(control.feedback(control.ss(G) * r.K).poles().real < 0)
    assert r.b >= 0.5 * r.b_max * (1 - 1e-9)


def test_loopsyn_refusals():
    with pytest.raises(ValueError, match=r"alpha must be in \[0, 1\], got 1.5"):
        loopsyn(G1, G1, alpha=1.5)
    with pytest.raises(DimensionMismatchError, match="more outputs than inputs"):
        loopsyn(control.tf([[[1.0]], [[1.0]]], [[[1.0, 1.0]], [[1.0, 2.0]]]), G1)
    with pytest.raises(DimensionMismatchError, match="Gd must be SISO or 2 x 2"):
        loopsyn(fl_plant(45.0, 2), fl_plant(45.0, 3))
    with pytest.raises(TimebaseMismatchError, match="continuous-time"):
        loopsyn(control.c2d(G1, 0.01), G1)
    for band in ((10.0, 1.0), (0.0, 1.0), (1.0, np.inf), "low"):
        with pytest.raises(ValueError, match="band must be"):
            loopsyn(G1, G1, band=band)
    rank1 = control.tf([[[1.0], [1.0]], [[1.0], [1.0]]], [[[1.0, 1.0]] * 2] * 2)
    with pytest.raises(ValueError, match="G loses rank"):
        loopsyn(rank1, control.tf(1.0, [1.0, 0.0]))
    with pytest.raises(ValueError, match="Gd loses rank"):
        loopsyn(fl_plant(45.0, 2), rank1)


def test_loopsyn_target_with_a_singular_d():
    # Gd = 8/s I + J, J the 2 x 2 ones: its D = J is singular, Gd(jw) is not (eigenvalues 8/jw
    # and 8/jw + 2), so Gd^-1 grows like jw/8 along (1, -1). gamma against numpy's
    # sup sigma_max([Gd S; Gd^-1 T]) on a 2000-point grid of the band (loopsyn: 60 a decade)
    G = fl_plant(45.0, 2)
    J = np.ones((2, 2))
    r = loopsyn(G, control.ss(np.zeros((2, 2)), 8.0 * np.eye(2), np.eye(2), J))
    L = control.ss(G * r.K)
    lo, hi = r.band
    worst = 0.0
    for w in np.logspace(np.log10(lo), np.log10(hi), 2000):
        S = np.linalg.inv(np.eye(2) + np.asarray(L(1j * w)))
        gd = 8.0 / (1j * w) * np.eye(2) + J
        stack = np.vstack([gd @ S, np.linalg.solve(gd, np.eye(2) - S)])
        worst = max(worst, np.linalg.svd(stack, compute_uv=False)[0])
    assert_allclose(r.gamma, worst, rtol=2e-3)
    assert np.all(control.feedback(G * r.K, np.eye(2)).poles().real < 0)


# --- design(): diagonal, fast for many joints, reduction guarantees ---------------------------

def test_design_diagonal_equals_mimo_synthesis(paper):
    # the per-joint design copied on the diagonal == the MIMO synthesis of the 3 x 3 plant
    mimo = ncfsyn(fl_plant(45.0, 3), expand_diagonal(lag_weight(), 3))
    assert_allclose(paper.ncf.gamma_min, mimo.gamma_min, rtol=1e-10)
    assert_allclose(resp(paper.ncf.K), resp(mimo.K), rtol=1e-7, atol=1e-9)
    assert paper.reduction.guaranteed and paper.ncf_reduction.guaranteed
    assert_allclose(paper.ncfmargin, ncfmargin(paper.G, paper.K)[0], rtol=1e-9)


def test_design_many_joints():
    # issue 12: --joints 200 ran for minutes; the design is per joint now
    d = design(n=200)
    assert (d.K.noutputs, d.ncf.K.nstates) == (200, 600)
    assert_allclose(d.ncf.gamma_min, 2.1436, atol=5e-5)


@pytest.mark.parametrize(("call", "match"), [
    (lambda: fl_plant(lam=0.0), r"lam must be a finite number > 0 \[rad/s\], got 0\.0"),
    (lambda: fl_plant(lam=True), r"lam must be a finite number > 0 \[rad/s\], got True"),
    (lambda: fl_plant(n=0), r"n must be an integer >= 1, got 0"),
    (lambda: fl_plant(n=2.5), r"n must be an integer >= 1, got 2\.5"),
    (lambda: lag_weight(p=float("nan")), r"p must be a finite number > 0 \[rad/s\], got nan"),
    (lambda: design(n="3"), r"n must be an integer in \[1, 1000\], got '3'"),
    (lambda: reduce_controller(fl_plant(45.0, 1), -1), r"order must be an integer >= 0, got -1"),
    (lambda: reduce_controller(fl_plant(45.0, 1), 1, fast_gap=0),
     r"fast_gap must be a finite number > 0, got 0"),
    (lambda: ncfsyn(fl_plant(45.0, 1), factor=None), r"factor must be a number, got None"),
], ids=["lam-zero", "lam-bool", "n-zero", "n-fraction", "p-nan", "design-n-str",
        "order-negative", "fast-gap-zero", "factor-None"])
def test_scalar_arguments_use_the_shared_validators(call, match):
    with pytest.raises(ValueError, match=match):
        call()


@pytest.mark.parametrize("lam", [1e-9, 0.99e-6, 1.01e7, 1e9], ids=["1e-9", "below", "above",
                                                                    "1e9"])
def test_design_refuses_lam_outside_its_range(lam):
    # 1e9 failed deep inside the synthesis (no stabilizing Riccati solution), 1e8 with a
    # spurious "uncontrollable mode", 1e-8 with an "improper controller".
    with pytest.raises(ValueError, match=r"lam must be in \[1e-06, 1e\+07\] rad/s .* got "):
        design(lam=lam)


@pytest.mark.slow
@pytest.mark.parametrize("lam", LAM_RANGE, ids=["low end", "high end"])
def test_design_succeeds_at_both_ends_of_lam_range(lam):
    # The range keeps a decade inside the measured failures (1e-8 and 1e8 rad/s): the
    # synthesis at the ends still meets its own optimality, gamma = gamma_min (factor 1).
    d = design(lam=lam)
    assert np.isfinite(d.ncf.gamma) and d.ncf.gamma >= 1.0
    assert_allclose(d.ncf.gamma, d.ncf.gamma_min, rtol=1e-9)


@pytest.mark.parametrize("factor", [1.0, 1.2], ids=["paper", "factor-1.2"])
def test_design_lines_print_the_inequality_that_holds(factor):
    # `rrr-pin design --factor 1.2` printed "nugap = 0.456 < b = 0.4024 ... NOT guaranteed"
    # (issue 21, item 6): the sign is now read off the two printed numbers.
    import re

    from rrr_pin.report.design import design_lines

    with warnings.catch_warnings():  # factor 1.2: the 2-state K raises gamma (warned, expected)
        warnings.simplefilter("ignore", RuntimeWarning)
        d = design(lam=45.0, factor=factor)
    lines = [x for x in design_lines(d) if " b = " in x]
    assert len(lines) == 3
    for line in lines:
        x, op, b = re.search(r"= ([0-9.e+-]+) (<|>=) b = ([0-9.]+)", line).groups()
        assert (float(x) < float(b)) == (op == "<"), line
        assert ("NOT guaranteed" in line) == (op == ">="), line


def test_design_order_sets_the_reduced_controller_and_refuses_more_than_full(capsys):
    # rrr-pin design --order N (issue 21, item 6). Order 3 is the full controller: no
    # reduction, so its gamma on the shaped plant is the synthesis' own to round-off.
    d = design(order=3)
    assert d.K_reduced.nstates == 3
    assert_allclose(d.gamma_reduced, d.ncf.gamma, rtol=1e-9)
    with pytest.warns(RuntimeWarning, match="the 1-state reduced controller raises gamma"):
        assert main(["design", "--order", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["K_reduced"]["poles"]) == 1
    assert main(["design", "--order", "4"]) == 2
    err = capsys.readouterr().err
    assert ("--order = 4 is more states than the full-order controller has (3)" in err
            and "Traceback" not in err)
