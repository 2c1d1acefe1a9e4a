"""Tests of rrr_pin.robust.ncf.

ncfmargin against MATLAB's examples and closed forms; discrete ncfsyn against Octave.
"""

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.robust.gap import gapmetric
from rrr_pin.robust.ncf import (
    HiddenModeError,
    SynthesisError,
    graph_symbols,
    ncfmargin,
    ncfsyn,
)
from rrr_pin.robust.robustness import ncf_loop

s = control.tf("s")


@pytest.mark.parametrize(("P", "C", "b"), [
    # MATLAB Robust Control Toolbox documentation, ncfmargin example: p = 4/(s - 0.001),
    # low-gain cL = 1 -> 0.7069, high-gain cH = 10 -> 0.0995 (negative feedback, sign -1)
    (4 / (s - 0.001), 1.0, 0.7069),
    (4 / (s - 0.001), 10.0, 0.0995),
    # MATLAB documentation, gapmetric example: P1 = (s+2)/(s^2+5s+10), C = 4.4/s -> 0.1961
    ((s + 2) / (s**2 + 5 * s + 10), 4.4 / s, 0.1961),
], ids=["matlab-low-gain", "matlab-high-gain", "matlab-gapmetric-example"])
def test_ncfmargin_matlab_examples(P, C, b):
    # published to 4 decimals: half a unit of the last digit
    assert_allclose(ncfmargin(P, C)[0], b, atol=5e-5)


def test_ncfmargin_siso_frequency_formula():
    # SISO: b = inf_w |1 + P C| / sqrt((1 + |P|^2)(1 + |C|^2)) (Vinnicombe 2001, eq. 1.20),
    # evaluated on a dense grid: independent of the state-space 4-block norm
    P = (s + 3) / (s**2 + 0.4 * s + 4)
    C = 2 / (s + 2)                 # closed loop s^3 + 2.4 s^2 + 6.8 s + 14: stable
    w = np.logspace(-3, 4, 200001)
    p, c = P(1j * w), C(1j * w)
    ref = np.min(np.abs(1 + p * c) / np.sqrt((1 + np.abs(p) ** 2) * (1 + np.abs(c) ** 2)))
    b, wpk = ncfmargin(P, C)
    assert_allclose(b, ref, rtol=1e-6)        # grid minimum of a smooth function, dw/w ~ 1e-4
    assert_allclose(wpk, w[np.argmin(np.abs(1 + p * c) / np.sqrt(
        (1 + np.abs(p) ** 2) * (1 + np.abs(c) ** 2)))], rtol=1e-2)


def random_plant(rng, n, p, m, unstable=False):
    A = rng.standard_normal((n, n))
    A -= (np.linalg.eigvals(A).real.max() + (-0.5 if unstable else 0.3)) * np.eye(n)
    return control.ss(A, rng.standard_normal((n, m)), rng.standard_normal((p, n)),
                      0.3 * rng.standard_normal((p, m)))


@pytest.mark.parametrize("seed", range(4))
def test_ncfmargin_symmetric_and_inverse_gamma(seed):
    rng = np.random.default_rng(seed)
    P = random_plant(rng, 3, 2, 2, unstable=seed % 2 == 1)
    r = ncfsyn(P, factor=1.2)
    # b(Gs, Ks) = 1/gamma for the central controller; slycot AB13DD as independent norm
    assert_allclose(ncfmargin(r.Gs, r.Ks)[0], 1 / r.gamma, rtol=1e-9)
    assert_allclose(ncfmargin(r.Gs, r.Ks)[0], 1 / control.linfnorm(ncf_loop(r.Gs, r.Ks))[0],
                    rtol=1e-7)
    # b(P, C) = b(C, P) (Vinnicombe 2001, sec. 1.4)
    assert_allclose(ncfmargin(r.Gs, r.Ks)[0], ncfmargin(r.Ks, r.Gs)[0], rtol=1e-9)


def test_ncfmargin_unstable_loop_is_zero():
    b, w = ncfmargin(1 / (s - 1), 0.5)          # closed-loop pole at s = 0.5
    assert b == 0.0 and np.isnan(w)


def test_graph_symbols_normalized():
    rng = np.random.default_rng(5)
    P = random_plant(rng, 4, 2, 3, unstable=True)
    G, Gt = graph_symbols(P)
    w = np.logspace(-2, 2, 9)
    for wk in w:
        g, gt = np.asarray(G(1j * wk)), np.asarray(Gt(1j * wk))
        # G~G = I, Gt Gt~ = I, Gt G = 0 on the imaginary axis (rounding)
        assert_allclose(g.conj().T @ g, np.eye(3), atol=1e-10)
        assert_allclose(gt @ gt.conj().T, np.eye(2), atol=1e-10)
        assert_allclose(gt @ g, 0, atol=1e-10)
        # N M^-1 = P
        assert_allclose(g[:2] @ np.linalg.inv(g[2:]), np.asarray(P(1j * wk)), rtol=1e-9)
    assert np.all(G.poles().real < 0) and np.all(Gt.poles().real < 0)


# --- discrete time ----------------------------------------------------------------------------

A_D = np.array([[0.9, 0.2, 0.0], [-0.1, 0.8, 0.3], [0.0, 0.1, 1.05]])
B_D = np.array([[1.0, 0.0], [0.0, 1.0], [0.5, 0.2]])
C_D = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
P_D = control.ss(A_D, B_D, C_D, np.diag([0.1, 0.2]), 0.1)      # unstable (z = 1.05...)
#: Octave 7.3.0, control 3.4.0, ncfsyn(P_D, [], [], 1.2) (SLICOT SB10ZD): info.Ks, a
#: positive-feedback controller, and its index gamma = norm(N, inf) = 2.247579537483.
KS_OCTAVE = (
    [[0.33687858115142788, -0.00076482223801325642, -0.48901235458782444],
     [0.38496051268562109, 0.71691828778954358, -1.08472725764945],
     [-0.22389714884372958, -0.01443902866091179, 0.44438317875682282]],
    [[0.072841768343640381, -0.059027372229584978], [-0.12715890166521099, 0.11101334950122665],
     [0.043291700043335081, 0.10863224174273393]],
    [[-0.043894336439900386, -0.21658745130364523, -0.27695834364272548],
     [0.49574019836779559, -0.092375639865181561, -0.93178427566307775]],
    [[-0.44822068113403046, -0.38299437113110246], [-0.090786945258551313, -0.49771951057506691]],
)


def test_discrete_ncfmargin_against_octave_controller():
    Ko = control.ss(*KS_OCTAVE, 0.1)
    # Octave's K is for positive feedback: our negative-feedback margin of -K; Octave prints
    # 12 decimals
    assert_allclose(1 / ncfmargin(P_D, -Ko)[0], 2.247579537483, rtol=1e-10)


def test_discrete_ncfsyn_is_octaves_controller_sb10zd():
    # Octave 7.3.0 / control 3.4.0: [K, N, gamma, info] = ncfsyn(P_D, [], [], 1.2) (SB10ZD,
    # D != 0); info.Ks is the positive-feedback controller, ours the negative-feedback -Ks.
    # Solved in discrete time now, it is the same controller: frequency responses to 1e-10
    # (Octave's 17 printed digits) and the same achieved gamma.
    r = ncfsyn(P_D, factor=1.2)
    Ko = control.ss(*KS_OCTAVE, 0.1)
    z = np.exp(1j * np.linspace(0.0, np.pi, 50))
    assert_allclose(np.asarray(r.Ks(z)), -np.asarray(Ko(z)), rtol=1e-10, atol=1e-12)
    assert_allclose(r.gamma, 2.247579537483, rtol=1e-11)
    # gamma_min from the discrete Riccati equations = the bilinear route's (factor 1)
    assert_allclose(r.gamma_min, ncfsyn(P_D).gamma_min, rtol=1e-10)


def test_discrete_ncfsyn_is_octaves_controller_sb10kd():
    # Octave 7.3.0 / control 3.4.0 (SB10KD, D = 0):
    #   G = ss(tf([0.1 0.05], [1 -1.2 0.5], 0.05)); [K, N, gamma, info] = ncfsyn(G, [], [], 1.1)
    #   -> gamma = 1.1118219261627, info.Ks below (positive feedback), G's realization below
    G = control.ss([[1.6653345369377348e-16, 0.50000000000000022],
                    [-0.99999999999999978, 1.2000000000000002]],
                   [[-0.05000000000000001], [0.10000000000000001]], [[0.0, 1.0]], [[0.0]], 0.05)
    Ko = control.ss([[-0.09948374901076569, 0.54258513721402613],
                     [-0.80103250197846809, 0.99172495223982016]],
                    [[0.035973764074064843], [0.051157245183998765]],
                    [[1.9896749802153166, -1.511341120145675]], [[-0.059836905616138684]], 0.05)
    r = ncfsyn(G, factor=1.1)
    z = np.exp(1j * np.linspace(0.0, np.pi, 50))
    assert_allclose(np.asarray(r.Ks(z)).ravel(), -np.asarray(Ko(z)).ravel(), rtol=1e-10)
    # gamma: Octave's 1.1118219261627 is 1.2e-5 low; the loop with Octave's own controller
    # has ||.||_inf = 1.11183499 by SLICOT AB13DD (control.linfnorm, discrete) and by a
    # 200001-point unit-circle sweep (measured), and that is what ours must equal
    loop = ncf_loop(G, -Ko)
    ref = control.linfnorm(control.ss(loop.A, loop.B, loop.C, loop.D, 0.05), tol=1e-10)[0]
    assert_allclose(r.gamma, ref, rtol=1e-9)
    assert_allclose(r.gamma, 1.1118219261627, rtol=2e-5)
    assert_allclose(r.gamma_min, ncfsyn(G).gamma_min, rtol=1e-10)   # bilinear route


# SLICOT's own example programs (doc/SB10KD.html and doc/SB10ZD.html of SLICOT-Reference):
# data and the controllers printed as "Program Results" (4 decimals, positive feedback, FACTOR
# = 1.1). The printed matrices are the realization our formulas give too.
A_KD = [[0.2, 0.0, 0.3, 0.0, -0.3, -0.1], [-0.3, 0.2, -0.4, -0.3, 0.0, 0.0],
        [-0.1, 0.1, -0.1, 0.0, 0.0, -0.3], [0.1, 0.0, 0.0, -0.1, -0.1, 0.0],
        [0.0, 0.3, 0.6, 0.2, 0.1, -0.4], [0.2, -0.4, 0.0, 0.0, 0.2, -0.2]]
A_ZD = [[0.2, 0.0, 3.0, 0.0, -0.3, -0.1], [-3.0, 0.2, -0.4, -0.3, 0.0, 0.0],
        [-0.1, 0.1, -1.0, 0.0, 0.0, -3.0], [1.0, 0.0, 0.0, -1.0, -1.0, 0.0],
        [0.0, 0.3, 0.6, 2.0, 0.1, -0.4], [0.2, -4.0, 0.0, 0.0, 0.2, -2.0]]
B_SL = [[-1.0, -2.0], [1.0, 3.0], [-3.0, -4.0], [1.0, -2.0], [0.0, 1.0], [1.0, 5.0]]
C_SL = [[1.0, -1.0, 2.0, -2.0, 0.0, -3.0], [-3.0, 0.0, 1.0, -1.0, 1.0, -1.0]]
SLICOT_EXAMPLES = {
    "SB10KD": (control.ss(A_KD, B_SL, C_SL, np.zeros((2, 2)), True), (
        [[0.0337, 0.0222, 0.0858, 0.1264, -0.1872, 0.1547],
         [0.4457, 0.0668, -0.2255, -0.3204, -0.4548, -0.0691],
         [-0.2419, -0.2506, -0.0982, -0.1321, -0.0130, -0.0838],
         [-0.4402, 0.3654, -0.0335, -0.2444, 0.6366, -0.6469],
         [-0.3623, 0.3854, 0.4162, 0.4502, 0.0065, 0.1261],
         [-0.0121, -0.4377, 0.0604, 0.2265, -0.3389, 0.4542]],
        [[0.0931, -0.0269], [-0.0872, 0.1599], [0.0956, -0.1469], [-0.1728, 0.0129],
         [0.2022, -0.1154], [0.2419, -0.1737]],
        [[-0.3677, 0.2188, 0.0403, -0.0854, 0.3564, -0.3535],
         [0.1624, -0.0708, 0.0058, 0.0606, -0.2163, 0.1802]],
        [[-0.0857, -0.0246], [0.0460, 0.0074]])),
    "SB10ZD": (control.ss(A_ZD, B_SL, C_SL + [[2.0, 4.0, -3.0, 0.0, 5.0, 1.0]],
                          [[10.0, -6.0], [-7.0, 8.0], [2.0, -4.0]], True), (
        [[1.0128, 0.5101, -0.1546, 1.1300, 3.3759, 0.4911],
         [-2.1257, -1.4517, -0.4486, 0.3493, -1.5506, -1.4296],
         [-1.0930, -0.6026, -0.1344, 0.2253, -1.5625, -0.6762],
         [0.3207, 0.1698, 0.2376, -1.1781, -0.8705, 0.2896],
         [0.5017, 0.9006, 0.0668, 2.3613, 0.2049, 0.3703],
         [1.0787, 0.6703, 0.2783, -0.7213, 0.4918, 0.7435]],
        [[0.4132, 0.3112, -0.8077], [0.2140, 0.4253, 0.1811], [-0.0710, 0.0807, 0.3558],
         [-0.0121, -0.2019, 0.0249], [0.1047, 0.1399, -0.0457], [-0.2542, -0.3472, 0.0523]],
        [[-0.0372, -0.0456, -0.0040, 0.0962, -0.2059, -0.0571],
         [0.1999, 0.2994, 0.1335, -0.0251, -0.3108, 0.2048]],
        [[0.0629, -0.0022, 0.0363], [-0.0228, 0.0195, 0.0600]])),
}


@pytest.mark.parametrize("name", list(SLICOT_EXAMPLES))
def test_discrete_ncfsyn_reproduces_slicot_example_results(name):
    P, (Ak, Bk, Ck, Dk) = SLICOT_EXAMPLES[name]
    r = ncfsyn(P, factor=1.1)
    # the same matrices to the 4 printed decimals (negative feedback: Ck, Dk change sign)
    for got, ref in zip((r.Ks.A, r.Ks.B, -r.Ks.C, -r.Ks.D), (Ak, Bk, Ck, Dk), strict=True):
        assert_allclose(got, ref, atol=5.01e-5)
    # the printed controller, as a system: a small nu-gap to ours (4-decimal rounding)
    printed = control.ss(Ak, Bk, -np.asarray(Ck), -np.asarray(Dk), True)
    assert gapmetric(r.Ks, printed)[1] < 1e-3
    assert np.abs(control.feedback(P, r.Ks).poles()).max() < 1


def test_discrete_ncfsyn_no_longer_copies_the_nyquist_gain():
    # issue 21: the paper's shaped plant at 1 kHz with factor 1.01; through the bilinear map
    # the central controller had a pole at z = -0.669 and |Ks(-1)| = 1.9e-4 (measured before
    # the change). Solved in discrete time (SB10ZD's method, checked against Octave above), its
    # poles are 0.989, 0.535 and 0.100 (measured); gamma stays within factor * gamma_min.
    G = control.c2d(control.tf([45.0**2], [1.0, 90.0, 45.0**2]), 1e-3, "zoh")
    W1 = control.c2d(control.tf([25.0, 25.0 * 11.5], [1.0, 0.19]), 1e-3, "tustin")
    r = ncfsyn(G, W1, factor=1.01)
    assert np.all(r.Ks.poles().real > 0)
    assert r.gamma_min <= r.gamma <= 1.01 * r.gamma_min * (1 + 1e-9)
    assert_allclose(1 / ncfmargin(r.Gs, r.Ks)[0], r.gamma, rtol=1e-9)
    assert_allclose(r.gamma_min, ncfsyn(G, W1).gamma_min, rtol=1e-9)      # bilinear route


@pytest.mark.parametrize(("P", "gamma_near_opt", "f"), [
    # Octave 7.3.0 / control 3.4.0: ncfsyn(P_D, [], [], 1.0001) (SB10ZD, D != 0) -> gamma
    (P_D, 2.031557145570, 1.0001),
    # Octave: ncfsyn(ss(tf([0.1 0.05], [1 -1.2 0.5], 0.05)), [], [], 1.000001) (SB10KD)
    (control.ss(control.tf([0.1, 0.05], [1.0, -1.2, 0.5], 0.05)), 1.078585403904, 1.000001),
], ids=["mimo-D-sb10zd", "siso-sb10kd"])
def test_discrete_ncfsyn_gamma_min_against_octave(P, gamma_near_opt, f):
    r = ncfsyn(P)
    # Octave's suboptimal controller achieves gamma_min <= gamma <= f gamma_min
    assert r.gamma_min <= gamma_near_opt * (1 + 1e-12)
    assert gamma_near_opt <= f * r.gamma_min * (1 + 1e-12)
    # the optimal discrete controller: stabilizing (|z| < 1), b(Gs, Ks) = 1/gamma_min
    assert r.Ks.dt == P.dt
    assert np.abs(control.feedback(P, r.Ks).poles()).max() < 1
    assert_allclose(ncfmargin(r.Gs, r.Ks)[0], 1 / r.gamma_min, rtol=1e-7)


def test_continuous_ncfsyn_against_octave_mimo():
    P = control.ss([[-1, 2, 0], [0, 0.5, 1], [1, 0, -3]], [[1, 0], [0, 1], [1, 1]],
                   [[1, 0, 1], [0, 1, 0]], [[0, 0.3], [0, 0]])
    # Octave 7.3.0 / control 3.4.0, ncfsyn(P, [], [], 1.0) (SB10ID): gamma = 1.757348802922
    assert_allclose(ncfsyn(P).gamma_min, 1.757348802922, rtol=1e-11)


@pytest.mark.parametrize("factor", [1.0, 1.1])
def test_discrete_ncfsyn_unstable_siso(factor):
    # Octave 7.3.0's SB10KD path refuses this plant ("closed-loop system is unstable"); the
    # reference is then the defining property of the central controller.
    P = control.tf([1.0, 0.5], [1.0, -2.2, 1.17], 0.1)          # poles 1.3 and 0.9: unstable
    r = ncfsyn(P, factor=factor)
    assert np.abs(control.feedback(control.ss(P), r.Ks).poles()).max() < 1
    assert r.gamma_min * (1 - 1e-9) <= r.gamma <= factor * r.gamma_min * (1 + 1e-9)
    assert_allclose(1 / ncfmargin(P, r.Ks)[0], r.gamma, rtol=1e-9)


def test_discrete_paper_design_unit_circle_grid():
    # the paper's shaped plant sampled at 1 kHz (G by ZOH, W1 by Tustin); the 4-block norm
    # evaluated directly on the unit circle (no bilinear map) must equal the achieved gamma
    G = control.c2d(control.tf([45.0**2], [1.0, 90.0, 45.0**2]), 1e-3, "zoh")
    W1 = control.c2d(control.tf([25.0, 25.0 * 11.5], [1.0, 0.19]), 1e-3, "tustin")
    r = ncfsyn(G, W1)
    theta = np.concatenate([np.logspace(-7, np.log10(np.pi), 40001)])
    z = np.exp(1j * theta)
    g, k = np.asarray(r.Gs(z)).ravel(), np.asarray(r.Ks(z)).ravel()
    # SISO 4-block [1; k](1 + g k)^-1 [1 g] has rank one: norm sqrt(1+|k|^2) sqrt(1+|g|^2)/|1+gk|
    peak = np.max(np.sqrt(1 + np.abs(k) ** 2) * np.sqrt(1 + np.abs(g) ** 2) / np.abs(1 + g * k))
    assert_allclose(peak, r.gamma, rtol=1e-5)                    # grid resolution
    assert np.abs(control.feedback(r.Gs, r.Ks).poles()).max() < 1


def test_ncfsyn_unpacks_as_matlab_with_the_closed_loop_norm_gamma():
    # [K, CL, gamma, info] = ncfsyn(G, W1, W2) as in MATLAB (issue 21, item 6). ||CL||_inf is
    # checked by python-control's linfnorm (SLICOT AB13DD through slycot), an independent
    # H-infinity norm, to its 1e-6 relative tolerance.
    G = control.tf([200.0], [10.0, 1.0]) * control.tf([1.0], [0.05, 1.0]) ** 2
    W1 = control.tf([1.0, 2.0], [1.0, 1e-3])
    result = ncfsyn(G, W1)
    K, CL, gamma, info = result
    assert K is info.K and info is result and gamma == info.gamma
    assert (CL.noutputs, CL.ninputs) == (2, 2)
    assert_allclose(control.linfnorm(CL, tol=1e-8)[0], gamma, rtol=1e-6)


def test_ncfmargin_takes_the_feedback_sign():
    # MATLAB's ncfmargin(P, C, sign): the documented example (b = 0.7069 for P = 4/(s - 0.001),
    # C = 1, negative feedback) and the same loop written with a positive-feedback C = -1.
    P = control.tf(4, [1, -0.001])
    b, _ = ncfmargin(P, 1.0)
    assert_allclose(b, 0.7069, atol=5e-5)  # MATLAB documentation, 4 digits
    assert ncfmargin(P, -1.0, sign=+1)[0] == b
    assert ncfmargin(P, 1.0, sign=-1)[0] == b
    for bad in (0, 2, True, "-1"):
        with pytest.raises(ValueError, match=r"sign must be -1 \(u = -C y\) or \+1"):
            ncfmargin(P, 1.0, sign=bad)


@pytest.mark.parametrize("factor", [1.0, 1.2], ids=["bilinear", "discrete-riccati"])
def test_discrete_ncfsyn_refuses_an_unstabilizable_mode(factor):
    # mode z = 1.5 is unstable and uncontrollable (PBH): no controller stabilizes it
    P = control.ss([[0.5, 0.0], [0.0, 1.5]], [[1.0], [0.0]], [[1.0, 1.0]], [[0.0]], 0.1)
    with pytest.raises(HiddenModeError, match=r"uncontrollable mode at z = 1.5 with \|z\| >= 1"):
        ncfsyn(P, factor=factor)


def test_discrete_ncfsyn_plant_pole_at_nyquist():
    # a plant pole at z = -1 has no bilinear image: factor 1 is refused by name; factor > 1
    # is solved in discrete time and must satisfy the defining property of the central
    # controller, gamma_min <= gamma <= factor gamma_min, with a stable loop
    P = control.tf([1.0], [1.0, 1.0], 0.1)
    with pytest.raises(SynthesisError, match="pole at z = -1"):
        ncfsyn(P)
    r = ncfsyn(P, factor=1.2)
    assert np.abs(control.feedback(control.ss(P), r.Ks).poles()).max() < 1
    assert r.gamma_min * (1 - 1e-9) <= r.gamma <= 1.2 * r.gamma_min * (1 + 1e-9)


# --- two degrees of freedom (Hoyle, Hyde & Limebeer; S&P sec. 9.4.3) ----------------------------

# The published case: RobustAndOptimalControl.jl, test/test_glover_mcfarlane.jl ("2 DOF GMcF",
# commit d7f57a9, 2022): P = (s + 5)/(s^2 + 2 s + 10), W1 = 1/s, Tref = 1/(s + 1),
# glover_mcfarlane_2dof(P, Tref, 1.1, 1.1; W1) gives dcgain(info.Gcl) = 1 (rtol 1e-4). The same
# file's 1-DOF design of that plant, glover_mcfarlane(P, 1.1; W1), gives info.margin = 0.6325
# (atol 1e-3), i.e. gamma = 1.1 gamma_min.
_P_JL = control.tf([1, 5], [1, 2, 10])
_W1_JL = control.tf(1, [1, 0])


def _ncf_2dof_index(res, w):
    """max_w sigma_max of S&P eq. (9.84) on a grid, from graph_symbols' Mt (not the Table 9.3 P)."""
    from rrr_pin.robust.ncf import graph_symbols

    _, Gt = graph_symbols(res.Gs)
    mr, p = res.Tref.ninputs, res.Gs.noutputs
    def fr(sys):
        r = sys.frequency_response(w, squeeze=False)
        return np.moveaxis(r.magnitude * np.exp(1j * r.phase), -1, 0)     # (len(w), p, m)

    Gs, Ks, Tr, Mt = fr(res.Gs), fr(res.Ks), fr(res.Tref), -fr(Gt)[:, :, :p]
    K1s, K2s = Ks[:, :, :mr], Ks[:, :, mr:]
    Minv = np.linalg.inv(Mt)                                # stacked over the grid
    S = np.linalg.inv(np.eye(p) - Gs @ K2s)
    Si = np.linalg.inv(np.eye(K2s.shape[1]) - K2s @ Gs)
    rho = res.rho
    us = np.concatenate([rho * Si @ K1s, K2s @ S @ Minv], axis=2)
    ys = np.concatenate([rho * S @ Gs @ K1s, S @ Minv], axis=2)
    e = np.concatenate([rho * rho * (S @ Gs @ K1s - Tr), rho * S @ Minv], axis=2)
    out = np.linalg.svd(np.concatenate([us, ys, e], axis=1), compute_uv=False)[:, 0]
    return max(out)


@pytest.mark.parametrize("Tref", [control.tf(1, [1, 1]),
                                  pytest.param(control.tf(1, [1, 1]) ** 2, marks=pytest.mark.slow)],
                         ids=["jl-test-1st-order", "jl-docs-2nd-order"])
def test_ncfsyn_2dof_published_dc_gain_and_gamma(Tref):
    from rrr_pin.robust.ncf import ncfsyn_2dof

    res = ncfsyn_2dof(_P_JL, Tref, 1.1, _W1_JL)
    K1, K2, gamma, info = res
    # Published: dcgain(closed loop) = 1, rtol 1e-4 (RobustAndOptimalControl.jl).
    assert_allclose(control.dcgain(res.CL), 1.0, rtol=1e-4)
    assert np.all(np.real(res.CL.poles()) < 0)
    # gamma is the norm of eq. (9.84): recomputed on a grid from the normalized left factor Mt
    # (graph_symbols), not from the generalized plant. A grid only bounds a peak from below;
    # 2000 points per 5 decades resolve these well-damped peaks to 1e-3.
    index = _ncf_2dof_index(res, np.logspace(-3, 3, 2400))
    assert index <= gamma * (1 + 1e-9)
    assert_allclose(index, gamma, rtol=1e-3)
    assert gamma <= 1.1 * res.gamma_opt * (1 + 1e-9)
    # The 2-DOF index contains the 1-DOF one (its phi -> [us; ys] block is the NCF loop of
    # (Gs, K2s)), so gamma_opt >= the 1-DOF gamma_min; the published 1-DOF margin 0.6325 at
    # gamma = 1.1 gamma_min gives gamma_min = 1 / (1.1 * 0.6325).
    one = ncfsyn(_P_JL, _W1_JL, factor=1.1)
    assert_allclose(1.0 / one.gamma, 0.6325, atol=1e-3)
    assert res.gamma_opt >= one.gamma_min


def test_ncfsyn_2dof_refuses_a_bad_reference_model():
    from rrr_pin.robust.ncf import ncfsyn_2dof
    from rrr_pin.validation import FieldError

    with pytest.raises(FieldError, match="Tref.*must be stable.*1"):
        ncfsyn_2dof(_P_JL, control.tf(1, [1, -1]), 1.1, _W1_JL)
    with pytest.raises(ValueError, match="Tref must be proper"):
        ncfsyn_2dof(_P_JL, control.tf([1, 0, 0], [1, 1]), 1.1, _W1_JL)
    with pytest.raises(FieldError, match="rho"):
        ncfsyn_2dof(_P_JL, control.tf(1, [1, 1]), 0.0, _W1_JL)
    with pytest.raises(FieldError, match="factor.*> 1"):
        ncfsyn_2dof(_P_JL, control.tf(1, [1, 1]), 1.1, _W1_JL, factor=1.0)


def test_ncfsyn_2dof_refuses_a_w2_with_a_singular_d():
    # Before (issue 31): numpy's "Singular matrix" from the dc prefilter, which inverts W2. A
    # strictly proper W1 (1/s) is the published case above and stays accepted; without the
    # prefilter, W2 is not inverted and a strictly proper W2 stays accepted too.
    from rrr_pin.robust.ncf import WeightError, ncfsyn_2dof

    Tref, W2 = control.tf(1, [1, 1]), control.tf(1, [1, 1])
    with pytest.raises(WeightError, match=r"W2 must be biproper .*D = \[\[0.0\]\].*match_dc"):
        ncfsyn_2dof(_P_JL, Tref, 1.1, _W1_JL, W2)
    res = ncfsyn_2dof(_P_JL, Tref, 1.1, _W1_JL, W2, match_dc=False)
    assert np.all(res.CL.poles().real < 0)
