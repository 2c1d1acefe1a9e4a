"""The minimax search (rrr_pin.campaign.minimax) and ``tune(..., search="minimax")``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.campaign.minimax import minimax
from rrr_pin.campaign.requirements import Bandwidth, DelayMargin
from rrr_pin.campaign.tuning import tune
from rrr_pin.control.structures import FLOnly, Gain
from rrr_pin.validation import FieldError


def test_kink_minimum_of_two_parabolas():
    # max((x - 1)^2 + y^2, (x + 1)^2 + 4 y^2) is least at the kink x = 0, y = 0, value 1:
    # neither parabola is stationary there (a smooth method's gradient never vanishes)
    def fun(v):
        x, y = v
        return np.array([(x - 1) ** 2 + y**2, (x + 1) ** 2 + 4 * y**2])

    x, F, nfev = minimax(fun, [2.0, 1.5], [(-5, 5), (-5, 5)], maxfev=200)
    assert nfev <= 200
    # forward differences of step 1e-4 bias the linearization by ~1e-4
    assert_allclose(x, [0.0, 0.0], atol=1e-3)
    assert_allclose(F, 1.0, atol=1e-6)


def test_bounds_are_kept():
    # the unconstrained minimum x = 3 lies outside [0, 1]: the best point is the bound
    x, F, _ = minimax(lambda v: np.array([(v[0] - 3.0) ** 2]), [0.2], [(0.0, 1.0)], 50)
    assert_allclose(x, [1.0], atol=1e-12)
    assert_allclose(F, 4.0, atol=1e-9)


def test_tune_minimax_finds_the_closed_form_trade_off(rrr):
    # as test_tuning's Nelder-Mead check: FL alone, lam free, delay margin c/lam against the
    # bandwidth 1.5538 lam; the best worst ratio is at lam^2 = B c / (1.5538 tau)
    c = math.atan(2 * math.sqrt(2 + math.sqrt(5))) / math.sqrt(2 + math.sqrt(5))
    kb = 1 / math.sqrt(math.sqrt(2) - 1)
    tau, B = 0.005, 300.0
    res = tune(rrr, FLOnly(lam=None), [DelayMargin(tau), Bandwidth(B)], plants=0, rate=1e5,
               starts=1, verify=False, search="minimax", maxfev=40)
    lam = math.sqrt(B * c / (kb * tau))
    assert_allclose(res.lam, lam, rtol=5e-3)  # grid interpolation of both margins
    assert_allclose(res.objective, tau * lam / c, rtol=5e-3)
    assert res.starts[0]["evaluations"] <= 40
    assert res.info["search"].startswith("minimax")


def test_unknown_search_is_refused(rrr):
    with pytest.raises(FieldError, match="search must be 'nelder-mead' or 'minimax'"):
        tune(rrr, Gain(), [DelayMargin(0.003)], plants=0, search="bfgs")
