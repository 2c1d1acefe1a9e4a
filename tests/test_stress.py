"""Breaking points (rrr_pin.campaign.stress): linear predictions against closed forms, the nonlinear
boundary against the linear prediction on the nominal RRR (and, slow, the 5-bar), the CLI on
every kind of plant."""

import logging
import math

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.campaign.stress import (
    StressSettings,
    _rms,
    barrier_guarantee,
    barrier_met,
    breaking_point,
    continuous_boundary,
    effects_of,
    linear_boundary,
    loop_bandwidth,
    spectral_radius,
    stress,
)
from rrr_pin.cli import main
from rrr_pin.control.effects import PlantEffects
from rrr_pin.control.laws import ControlLaw, TrackingController, fl_controller
from rrr_pin.control.references import default_reference, study_reference


@pytest.mark.parametrize("lam", [45.0, 100.0])
def test_fl_actuator_bound_is_routh(rrr, lam):
    # (2 lam s + lam^2)/s^2 with wa/(s + wa): s^3 + wa s^2 + 2 lam wa s + lam^2 wa; Routh:
    # stable iff wa * 2 lam wa > lam^2 wa, i.e. wa > lam / 2.
    assert_allclose(continuous_boundary(fl_controller(rrr, lam), "actuator"), lam / 2,
                    rtol=1e-5)


@pytest.mark.parametrize("lam", [45.0, 100.0])
def test_fl_delay_margin_is_pm_over_wc(rrr, lam):
    # |L(j wc)| = 1 at wc = lam sqrt(2 + sqrt 5); phase margin atan(2 wc / lam).
    wc = lam * math.sqrt(2 + math.sqrt(5))
    assert_allclose(continuous_boundary(fl_controller(rrr, lam), "delay"),
                    math.atan(2 * wc / lam) / wc, rtol=1e-6)


def test_digital_prediction_tends_to_the_continuous_one(rrr):
    # The discrete analysis (ZOH, fractional delay) at a fast rate: the hold's extra lag is
    # Ts/2, 100 us at 5 kHz on a 6.5 ms margin (1.5 %, above the 2e-3 asserted: the digital
    # margin is the continuous one less the hold's lag); wa moves by about 0.1 / (rate Ts_c),
    # first order in Ts (1e-2 at 20 kHz).
    law = fl_controller(rrr, 100.0)
    wc = 100 * math.sqrt(2 + math.sqrt(5))
    dm = math.atan(2 * wc / 100) / wc
    assert_allclose(linear_boundary(law, "delay", 5000.0) + 0.5 / 5000.0, dm, rtol=2e-3)
    assert abs(linear_boundary(law, "delay", 5000.0) / dm - 1) > 1e-2  # the hold's lag shows
    assert_allclose(linear_boundary(law, "actuator", 20000.0), 50.0, rtol=1e-2)


def test_barrier_guarantees_match_closed_forms():
    # Delay: |e^{-jwt} - 1| = 2 sin(wt/2) <= 0.2 |1 + jw/200|; the binding frequencies are low,
    # where 2 sin(wt/2) ~ wt: a first-order estimate tau ~ 0.2 / w at w ~ 200 gives 1e-3 s.
    assert 0.8e-3 < barrier_guarantee("delay") < 1.3e-3
    # Actuator: |jw/(jw + wa)| <= 0.2 |1 + jw/200| for all w; checked by brute force on a
    # finer, wider grid than the library's, independently of its bisection.
    w = np.logspace(-3, 6, 200001)

    def ok(wa):
        return np.all(w / np.sqrt(w * w + wa * wa) <= 0.2 * np.sqrt(1 + (w / 200) ** 2) + 1e-12)

    g = barrier_guarantee("actuator")
    assert ok(g * 1.001) and not ok(g * 0.99)


@pytest.fixture(scope="module", params=["delay", "actuator"])
def rrr_stress(rrr, request):
    # One search per effect (a worker computes only those of its tests); sweep = 0: no extra
    # runs below the boundary (they draw the figure, not the boundary).
    return stress(rrr, make_laws("fl,hinf,pd", rrr), default_reference(rrr), request.param,
                  StressSettings(sweep=0))


def test_simulated_boundary_within_10_percent_of_prediction(rrr_stress):
    rows = rrr_stress["rows"]
    assert [r["controller"] for r in rows] == ["fl", "hinf", "pd"]
    for r in rows:
        assert r["simulated"] == pytest.approx(r["predicted"], rel=0.10), r["controller"]
        assert r["guaranteed"] is not None and r["barrier_met"]


@pytest.mark.parametrize("effect, factor, broken", [
    ("delay", 0.9, False), ("delay", 1.1, True),
    ("actuator", 1.1, False), ("actuator", 0.9, True)])
def test_python_engine_spot_check(rrr, effect, factor, broken):
    law = fl_controller(rrr)
    pred = linear_boundary(law, effect, 1000.0)
    settings = StressSettings(run=RunSettings(duration=1.5, dt=1e-4, rate=1000.0,
                                              engine="python"))
    size = factor * pred
    if effect == "delay":  # a delay is realized (and accepted) on whole sub-steps of 1e-4 s
        size = round(size / 1e-4) * 1e-4
    rms = _rms(rrr, law, default_reference(rrr), effect, size, settings, 1.5)
    assert (rms > settings.budget) is broken


def test_breaking_point_any_law_no_prediction(rrr):
    # Torque limit on FL: no linear prediction; the search still brackets a boundary.
    out = breaking_point(rrr, fl_controller(rrr), default_reference(rrr), "torque",
                         StressSettings(run=RunSettings(duration=1.0, dt=1e-3, rate=1000.0),
                                        sweep=0, rtol=0.05))
    lo, hi = out["bracket"]
    assert 0 < hi < lo and out["simulated"] == lo


@pytest.mark.parametrize("effect", ["delay", "actuator", "torque"])
def test_law_without_linear_model_is_refused_by_every_prediction(effect):
    # stress() leaves the predictions of such a law empty by catching this TypeError, so each
    # prediction (not only the digital one) must refuse it the same way, whatever the effect.
    class Zero(ControlLaw):
        name, n = "zero", 3

        def torque(self, t, q, qd, r, rd, rdd, x):
            return np.zeros(3)

    for predict in (lambda: linear_boundary(Zero(), "delay", 1000.0),
                    lambda: continuous_boundary(Zero(), effect),
                    lambda: barrier_met(Zero())):
        with pytest.raises(TypeError, match="no linear model of law 'zero'"):
            predict()


@pytest.mark.parametrize("lam", [45.0, 100.0])
def test_fl_digital_loop_without_delay_is_the_zoh_double_integrator(rrr, lam):
    # Per joint, no delay: the zero-order-hold double integrator q+ = q + T qd + T^2/2 u,
    # qd+ = qd + T u (Franklin, Powell & Workman sec. 4.3), with u = -lam^2 q - 2 lam qd. The
    # loop's radius is that 2 x 2 matrix's (the one-sample command buffer adds only zeros).
    # 1e-12: expm of the augmented matrix against the closed form, both in double.
    T = 1e-3
    Phi = np.array([[1.0, T], [0.0, 1.0]])
    Gamma = np.array([[T * T / 2], [T]])
    A = Phi - Gamma @ np.array([[lam * lam, 2 * lam]])
    expected = np.max(np.abs(np.linalg.eigvals(A)))
    assert_allclose(spectral_radius(fl_controller(rrr, lam), 1.0 / T), expected, rtol=1e-12)


class Zero(ControlLaw):
    """A user's law with no linear model."""

    name, n = "zero", 3

    def torque(self, t, q, qd, r, rd, rdd, x):
        return np.zeros(3)


class Retuned(TrackingController):
    """A subclass that changes the law: the built-in's linear model no longer describes it."""

    def _tau(self, q, qd, r, rd, rdd, y):
        return 2.0 * super()._tau(q, qd, r, rd, rdd, y)


@pytest.mark.parametrize("make, name", [(lambda r: Zero(), "zero"),
                                        (lambda r: Retuned(r, 100.0, name="retuned"), "retuned")],
                         ids=["user-law", "subclassed-builtin"])
def test_stress_asks_the_law_for_its_linear_model(rrr, make, name):
    law = make(rrr)
    assert law.linear_model() is None and loop_bandwidth(law, np.zeros(3)) is None
    with pytest.raises(TypeError, match=f"no linear model of law '{name}' .* linear_model"):
        spectral_radius(law, 1000.0)


def test_stress_leaves_the_predictions_of_a_law_without_a_model_empty(rrr):
    # The row of a law without a linear model has no prediction, and its simulated boundary is
    # still searched (here FL alone written by hand: the same law as the built-in, so the
    # same boundary within the bisection's tolerance).
    settings = StressSettings(run=RunSettings(duration=0.5, dt=1e-4, rate=1000.0), sweep=0,
                              rtol=0.05, cycles=0.0)

    class HandFL(ControlLaw):
        name, n, lam = "hand_fl", 3, 100.0

        def torque(self, t, q, qd, r, rd, rdd, x):
            taubar = rdd + 2 * self.lam * (rd - qd) + self.lam ** 2 * (r - q)
            return (pin.crba(rrr.model, rrr.data, q) @ taubar
                    + pin.nonLinearEffects(rrr.model, rrr.data, q, qd))

    out = stress(rrr, [HandFL(), fl_controller(rrr)], default_reference(rrr), "delay", settings)
    hand, builtin = out["rows"]
    assert hand["predicted"] is None and hand["predicted_continuous"] is None
    assert hand["barrier_met"] is None and hand["guaranteed"] is None
    assert builtin["predicted"] is not None
    lo, hi = builtin["bracket"]
    assert lo / 1.1 <= hand["simulated"] <= hi * 1.1


def test_stress_reports_progress_and_logs_each_run(rrr, caplog):
    settings = StressSettings(run=RunSettings(duration=0.2, dt=1e-4, rate=1000.0), sweep=0,
                              rtol=0.05, cycles=0.0)
    calls = []
    with caplog.at_level(logging.DEBUG, logger="rrr_pin.campaign.stress"):
        out = stress(rrr, [fl_controller(rrr), fl_controller(rrr, lam=50.0, name="fl50")],
                     default_reference(rrr), "delay", settings,
                     progress=lambda done, total: calls.append((done, total)))
    assert calls == [(1, 2), (2, 2)]
    for row in out["rows"]:
        mine = [r for r in caplog.records if r.getMessage().startswith(row["controller"] + ",")]
        assert len(mine) == len(row["samples"])  # one DEBUG line per simulated run
        assert sum(r.levelno == logging.INFO and r.getMessage().startswith(
            f"{row['controller']} breaks at delay = {row['simulated']:.4g} s")
            for r in caplog.records) == 1


@pytest.mark.slow
def test_fivebar_delay_breaking_point_matches_the_linear_margin(fivebar):
    # FL alone (lam = 100 rad/s) on the 5-bar's circle: the simulated boundary (delays on the
    # 0.5 ms sub-step grid) against the digital loop's delay margin (FLLinearModel, exact
    # ZOH: the reduced loop in actuated coordinates is the serial one). Band 15 %: the grid's
    # step is 8 % of the margin, and the budget criterion (RMS error over a finite run) lets a
    # slowly unstable loop pass just past the margin.
    settings = StressSettings(run=RunSettings(duration=2.0, dt=5e-4, rate=1000.0), sweep=0)
    row = stress(fivebar, [fl_controller(fivebar, 100.0)], study_reference(fivebar, 2.0),
                 "delay", settings)["rows"][0]
    assert row["status"] == "found"
    lo, hi = row["bracket"]
    assert hi - lo == pytest.approx(5e-4)
    assert 0.85 * row["predicted"] <= row["simulated"] <= 1.15 * row["predicted"]


@pytest.mark.parametrize("stress_run, plant", [
    ("rrr", "rrr"), pytest.param("fivebar", "fivebar", marks=pytest.mark.slow),
], indirect=True, ids=["rrr", "fivebar"])
def test_cli_stress_json(stress_run, plant, strict_json):
    # the shared `rrr-pin stress --effect delay --controllers fl --json -v` of the plant
    assert stress_run.code == 0, stress_run.stderr
    data = strict_json(stress_run.stdout)
    # stderr: the progress bar (tqdm) and, with -v, the library's INFO lines
    assert f"{plant.name}: stress delay" in stress_run.stderr and "1/1" in stress_run.stderr
    assert "INFO rrr_pin.campaign.stress: fl breaks at delay" in stress_run.stderr
    assert data["robot"] == plant.name
    row = data["rows"][0]
    for key in ("controller", "effect", "unit", "predicted", "simulated", "status",
                "guaranteed"):
        assert key in row
    assert row["controller"] == "fl" and row["unit"] == "s"
    assert row["status"] == "found" and row["predicted"] > 0
    assert (stress_run.out / "stress_delay.png").is_file()
    # the runs past the boundary diverge: null with a status (was Infinity, not JSON)
    diverged = [x for x in row["samples"] if x["status"] == "diverged"]
    assert diverged and all(x["rms_error"] is None for x in diverged)
    assert strict_json((stress_run.out / "stress_delay.json").read_text())["rows"][0] == row


@pytest.mark.parametrize("rms, status, simulated, bracket", [
    (0.0, "not broken", None, lambda sizes: [max(sizes), None]),
    (math.inf, "broken at the mildest size tried", None, lambda sizes: [None, min(sizes)]),
], ids=["never-breaks", "always-diverges"])
def test_breaking_point_without_a_boundary(rrr, monkeypatch, strict_json, rms, status,
                                           simulated, bracket):
    # No size breaks (or every size breaks) the loop: no boundary is made up (it was inf or
    # 0.0, and the bracket named a size never run); the bracket holds the extreme size run.
    import rrr_pin.campaign.stress as st

    monkeypatch.setattr(st, "_rms", lambda *args: rms)
    out = breaking_point(rrr, fl_controller(rrr), default_reference(rrr), "delay",
                         StressSettings(run=RunSettings(duration=0.1, rate=1000.0)))
    sizes = [x["size"] for x in out["samples"]]
    assert (out["status"], out["simulated"]) == (status, simulated)
    assert out["bracket"] == bracket(sizes) and sizes == sorted(sizes)
    assert {x["status"] for x in out["samples"]} == {"passed" if rms == 0 else "diverged"}
    row = {"controller": "fl", "predicted": math.inf, "simulated": None, "agreement": None,
           "guaranteed": None, **out}
    result = {"robot": "rrr", "what": "delay", "unit": "s", "budget_rad": 0.05,
              "direction": "up", "elapsed_s": 1.0, "settings": {"rate_hz": 1000.0},
              "rows": [row]}
    from rrr_pin.report.jsondata import dumps
    from rrr_pin.report.stress import stress_lines

    back = strict_json(dumps(result))["rows"][0]
    assert back["predicted"] is None and back["predicted_status"] == "infinite"
    shown = stress_lines(result)[2].split()[2]
    assert shown == (f">{max(sizes):.4g}" if rms == 0 else "-")


def test_cli_stress_no_progress_prints_nothing_on_stderr(tmp_path, capsys):
    assert main(["stress", "--controllers", "fl", "--effect", "delay", "--json",
                 "--duration", "0.2", "--out", str(tmp_path), "--no-progress"]) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("argv, match", [
    (["stress", "--effect", "wind"], "--effect 'wind' is unknown"),
    (["stress", "--effect", "delay", "--budget", "nan"], "--budget"),
    (["montecarlo", "--samples", "1", "--delay", "-0.001"], "--delay must be"),
    (["montecarlo", "--samples", "1", "--actuator-bandwidth", "0"], "--actuator-bandwidth"),
    (["stress", "--effect", "delay", "--with", "actuator"], "--with expects EFFECT=SIZE"),
    (["stress", "--effect", "delay", "--with", "delay=0.001"], "--with: 'delay' is the effect "
                                                               "searched"),
    (["stress", "--effect", "delay", "--with", "wind=3"], "--with: unknown effect 'wind'"),
    (["stress", "--effect", "delay", "--with", "actuator=nan"], "--with: actuator must be a "
                                                                "finite number > 0"),
    (["stress", "--effect", "delay", "--with", "actuator=300,actuator=200"], "each effect once"),
    (["stress", "--effect", "delay", "--robot", "fivebar", "--controllers", "fl,nosuch"],
     "unknown controller 'nosuch'; built-in controllers"),
    (["stress", "--effect", "delay", "--robot", "fivebar", "--lock", "qa1=1"],
     "joints of a closed chain cannot be locked"),
    # before: "... (give --reference sine for a sinusoid)", an option stress does not have
    (["stress", "--effect", "delay", "--robot", "fivebar", "--home", "0,0"],
     "the study reference of 'fivebar' is its task path, which --home does not move (stress "
     "runs the study reference only)"),
], ids=["unknown-effect", "nan-budget", "neg-delay", "zero-bandwidth", "with-no-size",
        "with-itself", "with-unknown", "with-nan", "with-twice", "chain-unknown", "chain-lock",
        "chain-home"])
def test_cli_bad_input_names_the_option(argv, match, capsys, tmp_path):
    assert main(argv + ["--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err
    assert not (tmp_path / "o" / "stress_delay.json").exists()


@pytest.mark.parametrize("effect, expected", [
    ("delay", PlantEffects(delay=0.003)),
    ("actuator", PlantEffects(actuator_bandwidth=0.003)),
    ("stiffness", PlantEffects(stiffness=0.003, motor_inertia=0.01)),
    ("torque", PlantEffects(torque_limit=0.003)),
    ("noise", PlantEffects(noise_q=0.003, noise_qd=0.3, seed=7)),
    ("viscous", PlantEffects(viscous=0.003)),
    ("coulomb", PlantEffects(coulomb=0.003)),
], ids=lambda v: v if isinstance(v, str) else "")
def test_each_searchable_effect_is_one_catalog_entry(effect, expected):
    # the catalog entry alone says which PlantEffects fields a stress size sets (the search,
    # its help and its units read the same entry)
    from rrr_pin.control.catalog import EFFECTS

    assert effects_of(effect, 0.003, seed=7) == expected
    assert set(EFFECTS) == {"delay", "actuator", "stiffness", "torque", "noise", "viscous",
                            "coulomb"}


def test_delays_are_searched_on_whole_sub_steps(rrr):
    # A run realizes only whole sub-steps of delay (others are refused): every delay tried is a
    # multiple of h = 0.5 ms, and the bracket is one sub-step wide or rtol narrow.
    h = 5e-4
    settings = StressSettings(run=RunSettings(duration=1.0, dt=h, rate=1000.0), sweep=2,
                              rtol=0.01)
    out = breaking_point(rrr, fl_controller(rrr), default_reference(rrr), "delay", settings,
                         guess=6e-3)
    k = np.array([run["size"] for run in out["samples"]]) / h
    assert_allclose(k, np.round(k), rtol=0, atol=1e-9)  # multiples of h, to round-off
    lo, hi = out["bracket"]
    assert out["simulated"] == lo and round((hi - lo) / h) == 1
    passed = {round(run["size"] / h): run["status"] == "passed" for run in out["samples"]}
    assert passed[round(lo / h)] and not passed[round(hi / h)]


def test_an_offset_start_outside_the_limits_is_refused(rrr):
    # r(0) + offset beyond pi on joint 1: refused, not clipped to the limit.
    ref = default_reference(rrr)
    settings = StressSettings(run=RunSettings(duration=1.0, dt=1e-3, rate=1000.0), offset=4.0)
    with pytest.raises(ValueError, match=r"offset = 4 rad puts joint 'joint1' at .* outside its "
                                         r"limits \[-3.142, 3.142\]"):
        breaking_point(rrr, fl_controller(rrr), ref, "delay", settings)


# --- combined effects ---------------------------------------------------------------------------

def test_combined_delay_margin_with_a_fixed_actuator(rrr):
    # FL alone, L = (2 lam s + lam^2)/s^2 times wa/(s + wa): PM / wc from a dense numpy grid
    # (independent of control.margin), and the digital loop at 5 kHz tends to it (+ Ts/2, the
    # hold's lag, as for the delay alone): measured 5e-6 apart, 1e-4 allowed (the grid's
    # step is 1e-5 in log10 w).
    lam, wa = 100.0, 300.0
    law = fl_controller(rrr, lam)
    w = np.logspace(0, 4, 400001)
    L = (2 * lam * 1j * w + lam * lam) / (1j * w) ** 2 * wa / (1j * w + wa)
    i = np.argmin(np.abs(np.abs(L) - 1.0))
    dm = (math.pi + np.angle(L[i])) / w[i]
    cont = continuous_boundary(law, "delay", fixed={"actuator": wa})
    assert_allclose(cont, dm, rtol=1e-4)
    assert_allclose(linear_boundary(law, "delay", 5000.0, fixed={"actuator": wa}) + 0.5 / 5000.0,
                    dm, rtol=1e-4)
    assert cont < continuous_boundary(law, "delay")          # the lag eats delay margin


def test_fixed_effects_reach_the_plant_and_the_barrier(rrr):
    assert effects_of("delay", 0.002, fixed={"actuator": 300.0}) == PlantEffects(
        delay=0.002, actuator_bandwidth=300.0)
    # Barrier with a fixed actuator: |e^{-jw tau} wa/(jw + wa) - 1| <= |e_M|; a 300 rad/s
    # actuator alone already exceeds |e_M| (the actuator's own guarantee is 800 rad/s), so no
    # delay is covered; a 2000 rad/s one leaves a smaller delay than none.
    assert barrier_guarantee("delay", {"actuator": 300.0}) is None
    assert 0 < barrier_guarantee("delay", {"actuator": 2000.0}) < barrier_guarantee("delay")
    # No linear model for a fixed stiffness: no digital prediction rather than a wrong one.
    law = fl_controller(rrr)
    assert linear_boundary(law, "delay", 1000.0, fixed={"stiffness": 1e4}) is None


@pytest.mark.slow
def test_combined_breaking_point_of_hinf_matches_its_prediction(rrr):
    # The README example: H-infinity + FL with a 300 rad/s actuator; the delay searched on whole
    # 0.1 ms sub-steps. The digital prediction includes both; 10 % as for each effect alone.
    law = make_laws("hinf", rrr)[0]
    ref = default_reference(rrr)
    pred = linear_boundary(law, "delay", 1000.0, fixed={"actuator": 300.0})
    found = breaking_point(rrr, law, ref, "delay", guess=pred, fixed={"actuator": 300.0})
    assert found["simulated"] == pytest.approx(pred, rel=0.10)
    assert pred < linear_boundary(law, "delay", 1000.0)


# --- torque limit -------------------------------------------------------------------------------

def test_saturation_describing_function_is_the_lower_gain_margin(rrr):
    # df_gain = 1 / |L(j w_pc)| at the phase crossover left of -1: python-control's
    # stability_margins (returnall) lists every gain margin; the one below 1 is that crossing.
    import control

    from rrr_pin.campaign.stress import _saturation_df

    for name in ("fl", "hinf"):
        law = make_laws(name, rrr)[0]
        gain, w = _saturation_df(law, None)
        L = law.linear_model().loops(None)[0]
        gms, _, _, wgs, _, _ = control.stability_margins(L, returnall=True)
        lower = [(g, wg) for g, wg in zip(gms, wgs, strict=True) if 0 < g < 1]
        if name == "fl":
            assert gain is None and not lower
        else:
            (g, wg), = lower
            # The crossing is interpolated between grid points 1e-4 apart in log10 w: 1e-6.
            assert_allclose([gain, w], [g, wg], rtol=1e-6)


def test_torque_guarantee_is_sufficient(rrr):
    # At the guaranteed limit nothing saturates: the run equals the unsaturated one exactly;
    # 5 % below it the saturation acts and the run changes.
    from rrr_pin.campaign.stress import torque_prediction

    law = make_laws("fl", rrr)[0]
    ref = default_reference(rrr)
    settings = StressSettings(run=RunSettings(duration=1.0, dt=1e-4, rate=1000.0))
    pred = torque_prediction(rrr, law, ref, settings)
    e_free = _rms(rrr, law, ref, "torque", 1e12, settings, 1.0)
    assert _rms(rrr, law, ref, "torque", pred["guaranteed"], settings, 1.0) == e_free
    assert _rms(rrr, law, ref, "torque", 0.95 * pred["guaranteed"], settings, 1.0) != e_free
    # The estimate is the reference's own inverse dynamics: pin.rnea every 0.1 ms over the
    # 1.5 s FL runs (150 / lam); a peak of a 3.14 rad/s sine found on another grid moves by
    # ~(w h)^2 / 8, so 1e-5.
    r, rd, rdd = ref.sample(np.linspace(0, 1.5, 15001))
    need = max(np.max(np.abs(pin.rnea(rrr.model, rrr.data, *x))) for x in zip(r, rd, rdd,
                                                                              strict=True))
    assert_allclose(pred["predicted"], need, rtol=1e-5)
    assert pred["expected"] == "below"


@pytest.mark.slow
def test_torque_breaking_points_against_the_predictions(rrr):
    # Every simulated limit is at most the sufficient bound; FL alone and PD (loops never
    # conditionally stable) break below the reference's peak torque but within 15 % of it
    # (the budget tolerates a small shortfall); the H-infinity laws (conditionally stable)
    # break above it.
    laws = make_laws("fl,hinf,pd,hinf2dof", rrr)
    res = stress(rrr, laws, default_reference(rrr), "torque")
    for row in res["rows"]:
        t = row["torque"]
        assert row["simulated"] <= t["guaranteed"], row["controller"]
        ratio = row["simulated"] / t["predicted"]
        if t["expected"] == "below":
            assert 0.85 <= ratio <= 1.0, (row["controller"], ratio)
        else:
            assert ratio > 1.0, (row["controller"], ratio)


def test_an_effect_is_also_named_by_its_field():
    # issue 50: one vocabulary: stress --effect torque_limit is --effect torque, and --with
    # actuator_bandwidth=300 is --with actuator=300 (the option --actuator-bandwidth).
    from rrr_pin.campaign.stress import check_fixed
    from rrr_pin.control.catalog import EFFECT_FIELDS, EFFECTS

    for field, name in EFFECT_FIELDS.items():
        assert name in EFFECTS
        assert effects_of(field, 0.5) == effects_of(name, 0.5)
        assert check_fixed({field: 2.0}) == {name: 2.0}
        assert getattr(effects_of(name, 0.5), field) in (0.5, (0.5,))
