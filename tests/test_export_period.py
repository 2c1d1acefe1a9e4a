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
from rrr_pin.control.friction import JointFriction
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
        # friction compensation (issue 32) rides in the same law body
        "hinf_friction": (hinf_fl_controller(rrr, K, friction=JointFriction(
            (2.0, 1.5, 0.5), (1.0, 0.8, 0.3), 0.05, source="test")), {}),
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


@pytest.mark.parametrize("name", ["hinf", "hinf_prewarp", "hinf_aw", "hinf_zoh", "hinf_friction",
                                  "fl", "pd"])
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
    return DiscreteTrackingController(law.nominal, law.lam, Kd, name=law.name,
                                      friction=law.friction)


@pytest.mark.parametrize("name, method, prewarp", [
    ("hinf", "tustin", None), ("hinf_prewarp", "tustin", 300.0),
    ("hinf_backward", "backward_diff", None), ("hinf_aw", "tustin", None),
    ("hinf_friction", "tustin", None)],
    ids=["tustin", "tustin prewarped", "backward_diff", "hinf_aw tustin",
         "friction compensated tustin"])
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


# --- the rate the arm's export cannot meet (export refuses, naming the figure) -------------


def _fl_threshold_rate(lam: float) -> float:
    """The slowest rate [Hz] at which FL alone's sampled loop is stable, in closed form.

    Per joint FL leaves ``qdd = u``, ``u = -lam^2 q - 2 lam qd`` held over ``T``: the exact
    zero-order-hold step of the double integrator, ``Phi = [[1, T], [0, 1]]``,
    ``Gamma = [T^2 / 2, T]``, closed by the gain; bisection on ``T`` for ``rho = 1``
    (independent of the loop the export builds, which is any arm's n-joint matrix).
    """
    def rho(T):
        Phi = np.array([[1.0, T], [0.0, 1.0]])
        Gamma = np.array([[T * T / 2.0], [T]])
        return np.max(np.abs(np.linalg.eigvals(Phi - Gamma @ np.array([[lam * lam, 2 * lam]]))))

    lo, hi = 1e-6, 1.0  # stable, unstable
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if rho(mid) < 1.0 else (lo, mid)
    return 1.0 / lo


@pytest.mark.parametrize("robot", ["rrr", "ur5", "panda"])
def test_export_ros2_refuses_a_rate_unstable_inside_the_period_band(robot, tmp_path, capsys):
    """--ros2 accepts periods up to 1.2 / rate and computes with each: the loop must hold there.

    FL alone (lam = 100 rad/s) decouples any arm into the same double integrators: the slowest
    stable rate is the closed form's, on the RRR, UR5 and the Panda alike; over the band
    +-20 %, 1.2 times it.
    """
    from rrr_pin.cli import main
    from rrr_pin.deploy.ros2 import PERIOD_TOLERANCE

    f0 = _fl_threshold_rate(100.0)  # 100.0 Hz
    rate = 1.1 * f0  # stable at 1/rate, unstable at the band's slow edge 1.2/rate
    out = tmp_path / "e"
    args = ["export", "--robot", robot, "--law", "fl", "--rate", f"{rate:.6g}", "--out",
            str(out)]
    assert main([*args, "--ros2"]) == 2
    err = capsys.readouterr().err
    slow = rate / (1.0 + PERIOD_TOLERANCE)
    assert (f"with --ros2: the controller accepts update periods within +-20 % of 1/rate and "
            f"computes with each, and the sampled loop of 'fl' is unstable at a period of "
            f"{1e3 / slow:.4g} ms") in err
    stated = float(err.split("stable over the whole band from about ")[1].split(" Hz")[0])
    # the search stops within 0.1 % above the threshold; printed to 4 digits
    assert_allclose(stated, f0 * (1.0 + PERIOD_TOLERANCE), rtol=2e-3)
    assert not (out / "controller.c").exists()
    # the same rate without --ros2 (one period, 1/rate) is stable: exported
    assert main(args) == 0
    assert (out / "controller.c").is_file()


def test_export_checks_the_loop_with_the_method_exported(tmp_path, capsys):
    """The loop is checked with K discretized by --method (before: always Tustin's).

    At 150 Hz the paper's K by Tustin holds the loop, by backward differences it does not
    (spectral radius 1.09): before, both were exported. Independent of the linear loop, the
    exported law's Python twin on the nonlinear nominal arm diverges, and Tustin's tracks.
    """
    from rrr_pin.cli import main
    from rrr_pin.control.references import study_reference
    from rrr_pin.deploy.writer import prepare_export
    from rrr_pin.sim.simulation import simulate
    from rrr_pin.sim.trajectory import SimulationDiverged

    args = ["export", "--law", "hinf", "--rate", "150", "--out", str(tmp_path / "e")]
    assert main([*args, "--method", "tustin"]) == 0
    capsys.readouterr()
    assert main([*args, "--method", "backward_diff", "--overwrite"]) == 2
    assert "--rate 150 Hz: the sampled loop of 'hinf' is unstable" in capsys.readouterr().err
    rrr = load_robot("rrr")
    law = hinf_fl_controller(rrr, design(lam=45.0, n=3).K_reduced)
    ref = study_reference(rrr, 3.0)
    twins = {m: prepare_export(law, rrr, 150.0, method=m).law
             for m in ("tustin", "backward_diff")}
    with pytest.raises(SimulationDiverged):
        simulate(rrr, twins["backward_diff"], ref, 3.0, engine="python")
    assert np.max(np.abs(simulate(rrr, twins["tustin"], ref, 3.0, engine="python").error)) < 0.1


@pytest.mark.slow
def test_ur5_ctrl_step_dt_equals_sample_system_step_by_step(tmp_path):
    """UR5 (Pinocchio C++ dynamics, CMake build): jittered periods as python-control's K."""
    if shutil.which("cmake") is None:
        pytest.skip("no cmake")
    from rrr_pin.deploy.loaded import build

    ur5 = load_robot("ur5")
    law = hinf_fl_controller(ur5, design(lam=45.0, n=6).K_reduced)
    ex = export_law(law, ur5, RATE, tmp_path / "ur5", dynamics="pinocchio")
    c_law = exported_law(tmp_path / "ur5", build(tmp_path / "ur5"))
    rng = np.random.default_rng(5)
    x_c = x_py = c_law.initial_state()
    for dt in TS * (1.0 + rng.uniform(-0.2, 0.2, 100)):
        q, qd, r, rd, rdd = _inputs(rng, 6)
        tau_c, x_c, rc = c_law.step_dt(q, qd, r, rd, rdd, x_c, dt)
        assert rc == OK
        tau_py, x_py = _python_step(law, ex, dt, "tustin", None).step(0.0, q, qd, r, rd, rdd,
                                                                       x_py)
        # both on Pinocchio (C++ and Python bindings), K by hand-written LU and by LAPACK;
        # atol 1e-9 N m for a torque entry near zero, which carries the others' round-off
        assert_allclose(tau_c, tau_py, rtol=1e-12, atol=1e-9)
        assert_allclose(x_c, x_py, rtol=0, atol=1e-12 * np.abs(x_py).max())
