"""Tests of rrr_pin.robust.mu against closed forms (mussv, robstab)."""

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.robust.mu import closed_loop_matrix, mussv, robstab
from rrr_pin.validation import FieldError

# The upper bound stops within a relative 5e-3 of the LMI optimum (mu._RTOL).
UPPER_RTOL = 6e-3


def _routh_loop():
    """p(s) = p0(s) + delta, p0 = (s^2 + 0.1 s + 1)(s + 1), as det(1 - M delta), M = -1/p0."""
    s = control.tf("s")
    return control.ss(-1 / ((s**2 + 0.1 * s + 1) * (s + 1)))


def test_full_complex_block_is_the_largest_singular_value():
    # mu of one full complex block is sigma_max(M) (Packard & Doyle 1993, sec. 3).
    rng = np.random.default_rng(1)
    M = rng.standard_normal((3, 3)) + 1j * rng.standard_normal((3, 3))
    upper, lower = mussv(M, [("complex", 3)])
    smax = np.linalg.norm(M, 2)
    assert_allclose(lower, smax, rtol=1e-6)  # the rank-one Delta = v u^H / sigma is exact
    assert smax <= upper[0] <= smax * (1 + UPPER_RTOL)


def test_repeated_real_scalar_is_the_largest_real_eigenvalue():
    # mu of delta I_n is max |real eigenvalue| of M (a real delta with det(I - M delta) = 0
    # is 1/lambda for a real eigenvalue lambda). M = T R T^-1 has eigenvalues 0.5, -2, 1.
    rng = np.random.default_rng(2)
    R = np.triu(rng.standard_normal((3, 3)))
    R[np.diag_indices(3)] = [0.5, -2.0, 1.0]
    T = rng.standard_normal((3, 3))
    upper, lower = mussv(T @ R @ np.linalg.inv(T), [("real", 3)])
    assert_allclose(lower, 2.0, rtol=1e-6)
    assert 2.0 * (1 - 1e-9) <= upper[0] <= 2.0 * 1.05  # the D,G bound need not be exact


def test_real_scalar_with_complex_value_has_mu_zero_and_complex_block_its_modulus():
    # For a scalar m, mu_real = |m| if m is real, else 0; mu_complex = |m|.
    M = np.array([[[0.3 + 0.4j]], [[-0.7 + 0.0j]]])
    up_r, lo_r = mussv(M, [("real", 1)])
    up_c, lo_c = mussv(M, [("complex", 1)])
    assert_allclose(lo_r, [0.0, 0.7], atol=1e-9)
    assert up_r[0] <= 1e-3 * 0.5 and 0.7 <= up_r[1] <= 0.7 * (1 + UPPER_RTOL)
    assert_allclose(lo_c, [0.5, 0.7], rtol=1e-9)


def test_routh_hurwitz_margin_real_and_complex_differ():
    # Routh-Hurwitz on s^3 + 1.1 s^2 + 1.1 s + (1 + delta): stable iff 1 + delta > 0 and
    # 1.1 * 1.1 > 1 + delta, so the margin is 0.21, lost on the imaginary axis at
    # w = sqrt(1.1) (s^3 + 1.1 s^2 + 1.1 s + 1.21 = (s + 1.1)(s^2 + 1.1)). A complex delta
    # destabilizes earlier, at min_w |p0(jw)| (about 0.14, near the resonance w = 1).
    M = _routh_loop()
    w = np.array([0.0, 0.3, 1.0, 3.0, 10.0])
    real = robstab(M, [("real", 1)], w)
    assert_allclose(real.margin_upper, 0.21, rtol=1e-6)
    assert_allclose(real.critical_frequency, np.sqrt(1.1), rtol=1e-6)
    assert 0.21 / (1 + UPPER_RTOL) <= real.margin_lower <= 0.21 * (1 + 1e-9)
    assert real.vertices_checked == 2
    # the destabilizing delta puts a closed-loop pole on the imaginary axis
    poles = np.linalg.eigvals(closed_loop_matrix(M, real.destabilizing))
    assert_allclose(np.min(np.abs(poles - 1j * np.sqrt(1.1))), 0.0, atol=1e-6)
    ww = np.linspace(0.0, 3.0, 300001)
    p0 = np.abs(((1j * ww) ** 2 + 0.1j * ww + 1) * (1j * ww + 1))
    cplx = robstab(M, [("complex", 1)], w)
    # 1/margin is the H-inf norm of M; the search refines the frequency off the grid
    assert_allclose(cplx.margin_upper, p0.min(), rtol=1e-6)
    assert cplx.margin_lower <= cplx.margin_upper
    assert cplx.margin_upper < 0.7 * real.margin_lower


@pytest.mark.slow
def test_mixed_real_and_complex_bracket_the_vertex_sweep():
    # Two real scalars and a complex scalar on a random stable 3x3 loop: the margin lies
    # between the bounds, and the destabilizing Delta found is on the imaginary axis.
    rng = np.random.default_rng(4)
    A = -np.diag([1.0, 2.0, 3.0]) + 0.3 * rng.standard_normal((3, 3))
    M = control.ss(A, rng.standard_normal((3, 3)), rng.standard_normal((3, 3)), 0)
    w = np.concatenate([[0.0], np.logspace(-1, 1.5, 8)])
    r = robstab(M, [("real", 1), ("real", 1), ("complex", 1)], w)
    assert r.margin_lower <= r.margin_upper
    poles = np.linalg.eigvals(closed_loop_matrix(M, r.destabilizing))
    assert np.min(np.abs(poles.real)) < 1e-5


@pytest.mark.parametrize("blocks, match", [
    ([], "at least one block"),
    ([("real", 0)], "blocks\\[0\\] size"),
    ([("full", 1)], "kind in"),
    ("real", "kind in"),
], ids=["empty", "size0", "kind", "string"])
def test_bad_structures_are_refused(blocks, match):
    with pytest.raises(FieldError, match=match):
        mussv(np.eye(1), blocks)


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError, match="blocks adding up to 2"):
        mussv(np.eye(3)[None], [("real", 2)])
    with pytest.raises(FieldError, match="omega"):
        mussv(_routh_loop(), [("real", 1)])
    with pytest.raises(FieldError, match="omega"):
        mussv(_routh_loop(), [("real", 1)], [-1.0])
    with pytest.raises(FieldError, match="finite"):
        mussv(np.array([[[np.nan]]]), [("real", 1)])
    s = control.tf("s")
    with pytest.raises(FieldError, match="not stable"):
        robstab(control.ss(1 / (s - 1)), [("real", 1)])
