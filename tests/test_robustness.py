"""Tests of rrr_pin.robust.robustness: H-inf norm, NCF index, barrier checks (paper sec. 4.4)."""

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.robust.barriers import robust_performance_barrier, robust_stability_barrier
from rrr_pin.robust.loopshaping import fl_plant
from rrr_pin.robust.lti import expand_diagonal
from rrr_pin.robust.robustness import (
    check_robust_performance,
    check_robust_stability,
    hinf_norm,
    is_internally_stable,
    ncf_gamma,
    sigma,
)

s = control.tf("s")
#: The paper's controller as printed, eq. (18) (an independent reference for the checks).
K_EQ18 = control.ss(47.40 * (s + 134.75) * (s + 12.17) / ((s + 513.37) * (s + 0.19)))


def db(x):
    return 20 * np.log10(np.abs(x))


@pytest.mark.parametrize("zeta", [0.05, 0.3, 0.7])
def test_hinf_norm_resonance_closed_form(zeta):
    # 1/(s^2 + 2 zeta s + 1): peak 1/(2 zeta sqrt(1 - zeta^2)) at sqrt(1 - 2 zeta^2) if
    # zeta < 1/sqrt(2), else 1 at w = 0
    norm, wpk = hinf_norm(control.tf([1.0], [1.0, 2 * zeta, 1.0]))
    if zeta < 1 / np.sqrt(2):
        assert_allclose(norm, 1 / (2 * zeta * np.sqrt(1 - zeta**2)), rtol=1e-9)
        assert_allclose(wpk, np.sqrt(1 - 2 * zeta**2), rtol=1e-4)   # flat peak: ~sqrt(rtol)
    else:
        assert_allclose(norm, 1.0, rtol=1e-9)


@pytest.mark.parametrize("seed", range(8))
def test_hinf_norm_vs_slycot(seed):
    rng = np.random.default_rng(seed)
    n, p, m = rng.integers(1, 7, size=3)
    A = rng.standard_normal((n, n))
    A -= (np.linalg.eigvals(A).real.max() + rng.uniform(0.01, 1.0)) * np.eye(n)
    D = rng.standard_normal((p, m)) * (seed % 2)
    sys = control.ss(A, rng.standard_normal((n, m)), rng.standard_normal((p, n)), D)
    # slycot AB13DD (control.linfnorm, tol 1e-10) vs our Bruinsma-Steinbuch (rtol 1e-10)
    assert_allclose(hinf_norm(sys)[0], control.linfnorm(sys)[0], rtol=1e-8)


def test_hinf_norm_unstable_and_static():
    assert hinf_norm(control.tf([1.0], [1.0, -1.0]))[0] == np.inf
    D = np.array([[3.0, 0.0], [0.0, 4.0]])
    static = control.ss(np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((2, 0)), D)
    assert hinf_norm(static)[0] == 4.0


@pytest.mark.parametrize(("g", "k"), [(2.0, 0.5), (1.0, 1.0), (-0.3, 2.0)],
                         ids=["g2-k0.5", "g1-k1", "g-0.3-k2"])
def test_ncf_gamma_static_closed_form(g, k):
    # static loop: [1; k](1 + g k)^-1 [1 g] is rank one, norm sqrt(1+k^2) sqrt(1+g^2)/|1+gk|
    G = control.tf([g], [1.0])
    K = control.tf([k], [1.0])
    expect = np.sqrt(1 + k**2) * np.sqrt(1 + g**2) / abs(1 + g * k)
    assert_allclose(ncf_gamma(G, K), expect, rtol=1e-12)


def test_ncf_gamma_unstable_loop_is_inf():
    G = control.tf([1.0], [1.0, -1.0])
    assert not is_internally_stable(G, control.tf([0.5], [1.0]))
    assert ncf_gamma(G, control.tf([0.5], [1.0])) == np.inf
    assert is_internally_stable(G, control.tf([2.0], [1.0]))


def test_sigma_diagonal():
    G = fl_plant(45.0, 3)
    w = np.logspace(-1, 3, 9)
    sv = sigma(G, w)
    # diagonal identical channels: all singular values equal |lam^2 / (jw + lam)^2|
    assert_allclose(sv, np.tile(np.abs(45.0**2 / (1j * w + 45.0) ** 2), (3, 1)), rtol=1e-12)


# --- paper sec. 4.4 ---------------------------------------------------------------------------

def test_paper_verdicts_against_eq18():
    G = fl_plant(45.0, 3)
    K = expand_diagonal(K_EQ18, 3)
    rs = check_robust_stability(G, K, robust_stability_barrier())
    rp = check_robust_performance(G, K, robust_performance_barrier(), w_max=100.0)
    assert rs.ok and not rp.ok             # the paper: RS satisfied, RP not achievable
    # RP is worst at the band edge w_p = 100 rad/s; margin computed by hand from eq. (18)
    jw = 100j
    L = (47.40 * (jw + 134.75) * (jw + 12.17) / ((jw + 513.37) * (jw + 0.19))
         * 45.0**2 / (jw + 45.0) ** 2)
    rpb = -1e6 / ((jw - 800) * (jw + 100))
    assert_allclose(rp.worst_frequency, 100.0, rtol=1e-12)
    assert_allclose(rp.margin_db, db(L) - db(rpb), atol=1e-9)
    # RS: dense brute-force grid (2e5 points around the resonance) as reference
    w = np.linspace(150.0, 300.0, 200001)
    T = (lambda L: L / (1 + L))(K_EQ18(1j * w) * 45.0**2 / (1j * w + 45.0) ** 2)
    m = db(1000 / (1j * w + 200)) - db(T)
    # refined vs grid minimum: spacing 7.5e-4 rad/s -> within 1e-6 dB and 0.01 rad/s
    assert_allclose(rs.margin_db, m.min(), atol=1e-6)
    assert_allclose(rs.worst_frequency, w[np.argmin(m)], atol=1e-2)
    assert rs.margin_db > 10.0


def test_paper_design_checks_match_eq18():
    from rrr_pin.robust.loopshaping import design

    d = design()
    G, K = fl_plant(45.0, 3), expand_diagonal(K_EQ18, 3)
    ref_rs = check_robust_stability(G, K, robust_stability_barrier())
    ref_rp = check_robust_performance(G, K, robust_performance_barrier())
    # the reduced K differs from the printed eq. (18) by < 0.03 % per coefficient
    assert_allclose(d.robust_stability.margin_db, ref_rs.margin_db, atol=0.01)
    assert_allclose(d.robust_performance.margin_db, ref_rp.margin_db, atol=0.01)


def test_checks_fail_cases():
    G = fl_plant(45.0, 1)
    RSB, RPB = robust_stability_barrier(), robust_performance_barrier()
    # high gain: |T| ~ 1 far beyond 1000 rad/s where RSB < 0 dB -> RS violated
    rs = check_robust_stability(G, control.tf([1e4], [1.0]), RSB)
    assert not rs.ok and rs.margin_db < 0 and rs.worst_frequency > 500
    # unstable loop: fails with -inf margin
    bad = control.tf([-2.0], [1.0])
    for res in (check_robust_stability(G, bad, RSB), check_robust_performance(G, bad, RPB)):
        assert not res.ok and res.margin_db == -np.inf and np.isnan(res.worst_frequency)
    # a big low-frequency gain passes RP at the low end of the band (integrator-like)
    rp = check_robust_performance(G, control.tf([1e5, 1e5 * 50], [1.0, 1e-3]), RPB, w_max=10.0)
    assert rp.ok and rp.margin_db > 0


def test_check_bad_input():
    G = fl_plant(45.0, 1)
    K = control.tf([1.0], [1.0])
    with pytest.raises(ValueError, match="w_max"):
        check_robust_performance(G, K, robust_performance_barrier(), w_max=-1.0)
    with pytest.raises(ValueError, match="omega"):
        check_robust_stability(G, K, robust_stability_barrier(), omega=[-1.0, 2.0])
