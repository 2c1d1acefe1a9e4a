"""``ctrl_step_dt``: the exported law computed with the measured period (issue 35).

The C function discretizes K's continuous realization at each period it is given, by the
export's method (scipy's generalized bilinear transform, which python-control's
``sample_system`` calls). The references here are independent of the C: python-control's
``sample_system(K, dt_k, method)`` and the Python law (Pinocchio's CRBA/NLE, numpy) applied
period by period on the same chained state.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin import export as export_law
from rrr_pin import exported_law, hinf_fl_controller, load_robot, ncfsyn
from rrr_pin.control.laws import DiscreteTrackingController, hinf_aw_controller
from rrr_pin.control.laws.antiwindup import SampledAntiWindup, hanus_gain
from rrr_pin.robust.loopshaping import design, fl_plant, lag_weight

CC = shutil.which("cc")
RATE = 1000.0
TS = 1.0 / RATE
OK, EPERIOD = 0, 3
#: The torque limits of issue 20 for hinf_aw (about 10 % below the reference's peak) [N m].
AW_LIMIT = (150.0, 270.0, 45.0)


def _compile(folder: Path) -> Path:
    """The folder's C (C99, -pedantic, no warning allowed) as a shared library."""
    objs = []
    for f in ("controller.c", "dynamics.c", "codegen_rrr.c"):
        obj = folder / (f + ".o")
        subprocess.run([CC, "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O2",
                        "-fPIC", "-c", str(folder / f), "-o", str(obj)], check=True,
                       capture_output=True, text=True)
        objs.append(str(obj))
    lib = folder / "libdirect.so"
    subprocess.run([CC, "-shared", "-o", str(lib), *objs, "-lm"], check=True)
    return lib


@pytest.fixture(scope="module")
def laws(tmp_path_factory):
    """name -> (continuous law, export, loaded C law) on the RRR at 1 kHz."""
    if CC is None:
        pytest.skip("no C compiler")
    rrr = load_robot("rrr")
    K = design(lam=45.0, n=3).K_reduced
    quick = ncfsyn(fl_plant(45.0, 1), lag_weight()).K  # full order, one joint: 3 copies
    cases = {
        "hinf": (hinf_fl_controller(rrr, K), {}),
        "hinf_prewarp": (hinf_fl_controller(rrr, quick), {"prewarp": 300.0}),
        "hinf_backward": (hinf_fl_controller(rrr, quick), {"method": "backward_diff"}),
        "hinf_aw": (hinf_aw_controller(rrr, K, torque_limit=AW_LIMIT), {}),
        "hinf_zoh": (hinf_fl_controller(rrr, quick), {"method": "zoh"}),
        "fl": ("fl", {}),
        "pd": ("pd", {}),
    }
    root = tmp_path_factory.mktemp("period")
    out = {}
    for name, (law, kwargs) in cases.items():
        ex = export_law(law, rrr, RATE, root / name, **kwargs)
        out[name] = (law, ex, exported_law(root / name, _compile(root / name)))
    return out


def _inputs(rng, n=3):
    return [rng.uniform(-1.5, 1.5, n) for _ in range(5)]


@pytest.mark.parametrize("name", ["hinf", "hinf_prewarp", "hinf_aw", "hinf_zoh", "fl", "pd"])
def test_nominal_period_is_ctrl_step_bit_for_bit(laws, name):
    _, ex, c_law = laws[name]
    rng = np.random.default_rng(1)
    x_a = x_b = c_law.initial_state()
    for _ in range(200):
        q, qd, r, rd, rdd = _inputs(rng)
        tau_a, x_a = c_law.step(0.0, q, qd, r, rd, rdd, x_a)
        tau_b, x_b, rc = c_law.step_dt(q, qd, r, rd, rdd, x_b, TS)
        assert rc == OK
        assert_allclose(tau_b, tau_a, rtol=0, atol=0)
        assert_allclose(x_b, x_a, rtol=0, atol=0)


def _python_step(law, ex, dt, method, prewarp):
    """The Python law at period ``dt``: K by python-control's sample_system (independent)."""
    kwargs = {} if prewarp is None else {"prewarp_frequency": prewarp}
    A, B, C, D = law.continuous_matrices()
    Kd = control.sample_system(control.ss(A, B, C, D), dt, method=method, **kwargs)
    if ex.form.kind == "fl_aw":
        mats = tuple(np.asarray(M, dtype=float) for M in (Kd.A, Kd.B, Kd.C, Kd.D))
        gain = hanus_gain(law.name, "Dd", *mats, discrete=True)
        return SampledAntiWindup(law, 1.0 / dt, method, mats, gain)
    return DiscreteTrackingController(law.nominal, law.lam, Kd, name=law.name)


@pytest.mark.parametrize("name, method, prewarp", [
    ("hinf", "tustin", None), ("hinf_prewarp", "tustin", 300.0),
    ("hinf_backward", "backward_diff", None), ("hinf_aw", "tustin", None)],
    ids=["tustin", "tustin prewarped", "backward_diff", "hinf_aw tustin"])
def test_jittered_periods_equal_sample_system_step_by_step(laws, name, method, prewarp):
    """A seeded sequence of periods inside +-20 %: each step is python-control's K at dt_k."""
    law, ex, c_law = laws[name]
    rng = np.random.default_rng(35)
    periods = TS * (1.0 + rng.uniform(-0.2, 0.2, 150))
    periods[0] = math.nextafter(TS, 1.0)  # one ulp off: the C formula, not the tables
    x_c = x_py = c_law.initial_state()
    moved = 0.0
    for dt in periods:
        q, qd, r, rd, rdd = _inputs(rng)
        tau_c, x_c_next, rc = c_law.step_dt(q, qd, r, rd, rdd, x_c, dt)
        assert rc == OK
        tau_py, x_py = _python_step(law, ex, dt, method, prewarp).step(0.0, q, qd, r, rd,
                                                                        rdd, x_py)
        # C (generated dynamics, hand-written LU) against numpy/scipy on Pinocchio: round-off
        # of a torque of tens to hundreds of N m, relative
        assert_allclose(tau_c, tau_py, rtol=1e-12, atol=0)
        # the state: normwise (A x + B e (+ L dy) cancels in its small entries)
        assert_allclose(x_c_next, x_py, rtol=0, atol=1e-12 * np.abs(x_py).max())
        # the same state through the nominal step: how much the period changed the torque
        # and the next state (hinf_aw's torque sits on its limits at most of these inputs)
        tau_nom, x_nom = c_law.step(0.0, q, qd, r, rd, rdd, x_c)
        moved = max(moved, float(np.max(np.abs(tau_nom - tau_c))),
                    float(np.max(np.abs(x_nom - x_c_next))))
        x_c = x_c_next
    assert moved > 1e-3  # the period is used: not the nominal K quietly


@pytest.mark.parametrize("name", ["fl", "pd"])
def test_a_law_without_k_does_not_depend_on_the_period(laws, name):
    _, ex, c_law = laws[name]
    assert "period-free" in ex.record["ctrl_step_dt"]["period"]
    rng = np.random.default_rng(2)
    for dt in TS * (1.0 + rng.uniform(-0.2, 0.2, 50)):
        q, qd, r, rd, rdd = _inputs(rng)
        tau_a, _ = c_law.step(0.0, q, qd, r, rd, rdd, c_law.initial_state())
        tau_b, _, rc = c_law.step_dt(q, qd, r, rd, rdd, c_law.initial_state(), dt)
        assert rc == OK
        assert_allclose(tau_b, tau_a, rtol=0, atol=0)


@pytest.mark.parametrize("name", ["hinf", "hinf_aw", "fl", "pd"])
@pytest.mark.parametrize("dt", [0.0, -1e-3, float("nan"), float("inf")],
                         ids=["zero", "negative", "nan", "inf"])
def test_a_period_not_finite_or_not_positive_is_refused(laws, name, dt):
    _, _, c_law = laws[name]
    x = np.full(c_law.nx, 0.25)
    tau, x_next, rc = c_law.step_dt(*([np.full(3, 0.1)] * 5), x, dt)
    assert rc == EPERIOD and np.all(np.isnan(tau))  # nothing written
    assert_allclose(x_next, x, rtol=0, atol=0)  # the state untouched


def test_k_without_a_continuous_realization_runs_at_its_period_only(laws):
    """zoh needs a matrix exponential, which the C does not carry: another dt is refused."""
    _, ex, c_law = laws["hinf_zoh"]
    assert ex.continuous is None and "nominal period only" in ex.record["ctrl_step_dt"]["period"]
    args = [np.full(3, 0.1)] * 5
    assert c_law.step_dt(*args, c_law.initial_state(), TS)[2] == OK
    tau, _, rc = c_law.step_dt(*args, c_law.initial_state(), 1.01 * TS)
    assert rc == EPERIOD and np.all(np.isnan(tau))


def test_controller_json_records_the_continuous_k(laws):
    law, ex, c_law = laws["hinf"]
    record = json.loads((c_law.folder / "controller.json").read_text())["ctrl_step_dt"]
    A, B, C, D = law.continuous_matrices()
    for key, M in zip("ABCD", (A, B, C, D), strict=True):
        assert_allclose(np.array(record["K_continuous"][key]), M, rtol=0, atol=0)
    assert record["method"] == "tustin" and record["alpha"] == 0.5
    header = (c_law.folder / "controller.h").read_text()
    assert "#define CTRL_STEP_DT \"K discretized at dt by tustin" in header
    assert "int ctrl_step_dt(" in header
