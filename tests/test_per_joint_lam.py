"""The FL bandwidth ``lam`` per joint (issue 34, item 1): one law, every implementation.

A vector ``lam`` with equal entries is the scalar law bit for bit; a per-joint ``lam`` gives the
same torque in Python, on the compiled and the batched engines and in the exported C; each
joint's FL error dynamics have a double pole at ``-lam_j``; the tuner tunes one per joint.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from rrr_pin.control.laws import AntiWindupTracking, TrackingController, fl_controller
from rrr_pin.control.laws.antiwindup import hinf_aw_controller
from rrr_pin.control.laws.tracking import hinf_fl_controller
from rrr_pin.control.references import QuinticReference, default_reference
from rrr_pin.control.structures import PerJoint, make_structure
from rrr_pin.sim.simulation import simulate, simulate_batch
from rrr_pin.validation import FieldError

LAMS = (30.0, 45.0, 80.0)
RATE = 1000.0


@pytest.fixture(scope="module")
def paper_K(paper):
    return paper.K_reduced


def _states(rng, n, nx):
    q, qd, r, rd, rdd = (rng.uniform(-3.0, 3.0, n) for _ in range(5))
    return q, qd, r, rd, rdd, rng.standard_normal(nx)


def test_equal_entries_are_the_scalar_law_bit_for_bit(rrr, paper_K):
    scalar = TrackingController(rrr, 45.0, paper_K)
    vector = TrackingController(rrr, [45.0, 45.0, 45.0], paper_K)
    assert vector.describe()["lam_rad_s"] == [45.0, 45.0, 45.0]
    rng = np.random.default_rng(34)
    for law_s, law_v in ((scalar, vector), (scalar.sampled(RATE), vector.sampled(RATE))):
        for _ in range(200):
            s = _states(rng, 3, scalar.nx)
            if hasattr(law_s, "step"):
                for a, b in zip(law_s.step(0.0, *s), law_v.step(0.0, *s), strict=True):
                    assert_array_equal(a, b)
            else:
                assert_array_equal(law_s.torque(0.0, *s), law_v.torque(0.0, *s))
                assert_array_equal(law_s.derivative(0.0, *s), law_v.derivative(0.0, *s))
    ref = default_reference(rrr)
    for engine in ("compiled", "python"):
        a = simulate(rrr, scalar, ref, 0.2, rate=RATE, engine=engine)
        b = simulate(rrr, vector, ref, 0.2, rate=RATE, engine=engine)
        assert b.info["engine"] == engine
        for key in ("q", "qd", "tau"):
            assert_array_equal(getattr(a, key), getattr(b, key))
    (a,), (b,) = (simulate_batch([rrr], law, ref, 0.2, rate=RATE) for law in (scalar, vector))
    assert b.info["engine"] == "codegen"
    assert_array_equal(a.tau, b.tau)


@pytest.mark.parametrize("kind", ["fl", "aw"])
def test_per_joint_lam_is_one_torque_in_every_engine(rrr, paper_K, kind):
    limit = (20.0, 60.0, 20.0)
    law = (TrackingController(rrr, LAMS, paper_K) if kind == "fl" else
           AntiWindupTracking(rrr, LAMS, paper_K, name="aw", torque_limit=limit))
    # random starts: the first sample of each engine is the law at (q0, qd0, r(0), ...), the
    # same inputs, so the engines must agree to round-off (Eigen vs numpy, 1e-12 relative)
    rng = np.random.default_rng(7)
    ref = QuinticReference(np.zeros(3), np.full(3, 0.3), 0.5)
    lo, hi = np.asarray(rrr.lower), np.asarray(rrr.upper)
    for _ in range(5):
        q0 = rng.uniform(np.maximum(lo, -2.0), np.minimum(hi, 2.0))
        qd0 = rng.uniform(-2.0, 2.0, 3)
        runs = [simulate(rrr, law, ref, 0.05, rate=RATE, q0=q0, qd0=qd0, engine=e, check=False)
                for e in ("python", "compiled")]
        runs += simulate_batch([rrr], law, ref, 0.05, rate=RATE, q0=q0, qd0=qd0, check=False)
        assert [t.info["engine"] for t in runs] == ["python", "compiled", "codegen"]
        for t in runs[1:]:
            assert_allclose(t.tau[0], runs[0].tau[0], rtol=1e-12, atol=1e-12)
            # the whole closed loop: tests/test_engines.py's tolerances (state round-off x lam^2)
            assert_allclose(t.tau, runs[0].tau, rtol=0.0, atol=1e-7)
    # a different lam on each joint really changes the torque (not one entry used)
    assert not np.allclose(simulate(rrr, law, ref, 0.05, rate=RATE).tau,
                           simulate(rrr, TrackingController(rrr, 45.0, paper_K), ref, 0.05,
                                    rate=RATE).tau)


def test_per_joint_lam_exported_c_steps_as_python(rrr, paper_K, tmp_path):
    if shutil.which("cc") is None:
        pytest.skip("no C compiler")
    from test_export import _compile_shared, _random_steps

    from rrr_pin import export as export_law
    from rrr_pin import exported_law

    for name, law in (("fl", TrackingController(rrr, LAMS, paper_K, name="pj")),
                      ("aw", AntiWindupTracking(rrr, LAMS, paper_K, name="pj_aw",
                                                torque_limit=(20.0, 60.0, 20.0)))):
        folder = tmp_path / name
        ex = export_law(law, rrr, RATE, folder)
        assert ex.record["law"]["lam"] == list(LAMS)
        record = json.loads((folder / "controller.json").read_text())
        assert record["law"]["lam"] == list(LAMS)
        assert "static const double LAM[CTRL_NQ] = {30.0, 45.0, 80.0};" in \
            (folder / "controller.c").read_text()
        c_law = exported_law(folder, _compile_shared(folder))
        # 500 random states: the C transcription against the Python law, round-off only
        assert _random_steps(ex.law, c_law, 500, seed=34, normwise=name == "aw") <= 1e-12


def test_ros2_package_takes_lam_as_a_list(rrr, paper_K, tmp_path):
    """The ros2_control package of a per-joint law, compiled against the stubs and driven."""
    import subprocess

    import yaml
    from test_ros2_package import (
        CC,
        CXX,
        STUBS,
        TS,
        WARN,
        _drive,
        _params,
        _started,
        _updates,
        _vec,
    )

    from rrr_pin import export as export_law
    from rrr_pin.deploy.ros2 import write_ros2_package

    if CC is None or CXX is None:
        pytest.skip("no C/C++ compiler")
    folder = tmp_path / "e"
    ex = export_law(TrackingController(rrr, LAMS, paper_K, name="pj"), rrr, RATE, folder)
    write_ros2_package(ex, rrr, folder, name="rrr_pin_controller")  # the stub driver's default
    doc = yaml.safe_load((folder / "ros2" / "config" / "rrr_pin_controller.yaml").read_text())
    assert doc["rrr_pin_controller"]["ros__parameters"]["lam"] == list(LAMS)
    objs = []
    for f in ("controller.c", "dynamics.c", "codegen_rrr.c"):
        obj = folder / (f + ".o")
        subprocess.run([CC, "-std=c99", *WARN, "-O2", "-c", str(folder / f), "-o", str(obj)],
                       check=True, capture_output=True, text=True)
        objs.append(str(obj))
    exe = folder / "drive"
    done = subprocess.run(
        [CXX, "-std=c++17", *WARN, "-O1", f"-I{STUBS}", f"-I{folder}",
         f"-I{folder / 'ros2' / 'include'}",
         str(folder / "ros2" / "src" / "exported_law_controller.cpp"),
         str(STUBS / "drive_controller.cpp"), *objs, "-o", str(exe), "-lm"],
        capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr  # no warning allowed either (-Werror)
    rng = np.random.default_rng(35)
    lines = _started(folder, torque_limit=[1e12] * 3)  # no clip: the law's own torque
    steps = []
    for _ in range(100):
        q, qd, r, rd, rdd = (rng.uniform(-3.0, 3.0, 3) for _ in range(5))
        steps.append((q, qd, r, rd, rdd))
        lines += [f"ref 3 {_vec(r)} 3 {_vec(rd)} 3 {_vec(rdd)}",
                  f"update {TS!r} {_vec(q)} {_vec(qd)}"]
    out, err = _drive(exe, lines)
    assert out[:3] == ["init SUCCESS", "configure SUCCESS", "activate SUCCESS"], err
    tau, _, _ = _updates(out)
    x = ex.law.initial_state()
    for k, step in enumerate(steps):
        tau_py, x = ex.law.step(k * TS, *step, x)
        # Python (Pinocchio, numpy) against the controller's C (generated dynamics): round-off
        assert_allclose(tau[k], tau_py, rtol=1e-12, atol=0)
    # a lam other than the compiled one is refused at configure
    out, err = _drive(exe, [*_params(folder, lam=[30.0, 45.0, 81.0]), "init", "configure"])
    assert out == ["init SUCCESS", "configure ERROR"]
    assert "parameter lam differs from the per-joint lam compiled" in err


def test_each_joint_has_its_double_pole_at_minus_lam(rrr):
    """FL alone with lam per joint on its own nominal: e_j'' + 2 lam_j e_j' + lam_j^2 e_j = 0."""
    from rrr_pin.control.analysis import parametric_loop

    law = fl_controller(rrr, lam=list(LAMS))
    # the loop's state matrix on the nominal plant (the parametric loop's A, errors at 0)
    poles = np.linalg.eigvals(parametric_loop(law, np.zeros(3)).M.A)
    # closed form: a double pole at -lam_j per joint; a double root moves by ~sqrt(eps) lam
    assert_allclose(np.sort(poles.real), np.sort(np.repeat(-np.array(LAMS), 2)), rtol=1e-6)
    assert_allclose(poles.imag, 0.0, atol=1e-6 * max(LAMS))
    # and the nonlinear simulation (continuous law, RK4 at 0.1 ms) of an initial error
    # e_j(0) = 0.1 rad, e_j'(0) = 0 on a constant reference: (1 + lam_j t) exp(-lam_j t) e_j(0)
    q_ref = np.array([0.2, -0.4, 0.6])
    ref = QuinticReference(q_ref, q_ref, 1.0)
    traj = simulate(rrr, law, ref, 0.1, dt=1e-4, q0=q_ref - 0.1, engine="python")
    t = traj.t[:, None]
    lam = np.array(LAMS)[None, :]
    expected = 0.1 * (1.0 + lam * t) * np.exp(-lam * t)
    assert_allclose(q_ref - traj.q, expected, rtol=0.0, atol=1e-9)  # RK4 at 0.1 ms: ~1e-11


def test_bad_lam_is_named(rrr, paper_K, paper):
    with pytest.raises(FieldError, match=r"lam must be one number or one per joint \(3: "
                                         r"joint1, joint2, joint3\).*got shape \(2,\)"):
        TrackingController(rrr, [45.0, 45.0], None)
    with pytest.raises(FieldError, match=r"lam\[1\] \(joint 'joint2'\) must be a finite "
                                         r"number > 0 \[rad/s\], got -3.0"):
        TrackingController(rrr, [45.0, -3.0, 45.0], None)
    with pytest.raises(FieldError, match=r"lam\[2\] \(joint 'joint3'\).*got nan"):
        fl_controller(rrr, [45.0, 45.0, float("nan")])
    with pytest.raises(ValueError, match="lam must be a positive finite bandwidth"):
        TrackingController(rrr, 0.0, None)
    # the paths built on one FL plant refuse a vector by name
    from rrr_pin.robust.certificates import frozen_linearization
    from rrr_pin.robust.loopshaping import design, fl_plant

    for call, where in (
            (lambda: design(lam=list(LAMS)), "the loop-shaping design"),
            (lambda: fl_plant(list(LAMS), 3), "the FL plant"),
            (lambda: hinf_fl_controller(rrr, paper_K, list(LAMS)), "the hinf law"),
            (lambda: hinf_aw_controller(rrr, paper_K, list(LAMS)), "the hinf_aw law"),
            (lambda: frozen_linearization(rrr, rrr, np.zeros(3), np.zeros(3), lam=list(LAMS)),
             "the frozen linearization")):
        with pytest.raises(FieldError, match=f"lam must be one number \\[rad/s\\] for {where}"):
            call()


def test_per_joint_lam_structure_tunes_and_round_trips(rrr, tmp_path):
    from rrr_pin.campaign.design_file import load_design, tuned_law
    from rrr_pin.campaign.requirements import DelayMargin, DiskMargin
    from rrr_pin.campaign.tuning import tune

    st = make_structure("gain", lam=45.0, joints=rrr.joint_names, per_joint_lam=True)
    assert isinstance(st, PerJoint) and st.per_joint_lam
    assert st.names == ("lam@joint1", "lam@joint2", "lam@joint3", "k@joint1", "k@joint2",
                        "k@joint3")
    assert_allclose(st.initial(), [45.0] * 3 + [1.0] * 3)
    lam, K = st.split([30.0, 45.0, 80.0, 1.0, 2.0, 3.0])
    assert_allclose(lam, LAMS) and len(K) == 3
    res = tune(rrr, st, [DelayMargin(0.004), DiskMargin(0.5)], plants=1, starts=1,
               simulate=False, maxfev=30)
    assert np.shape(res.lam) == (3,)
    path = tmp_path / "design.json"
    path.write_text(json.dumps(res.to_dict(), default=float))
    data = load_design(path)
    assert data["lam_rad_s"] == [float(x) for x in res.lam]
    assert data["structure"]["lam_per_joint"] is True
    law = tuned_law(data, rrr)
    assert_allclose(law.lam, res.lam, rtol=0, atol=0)
    data["lam_rad_s"] = [45.0, 45.0]
    with pytest.raises(FieldError, match=r"lam must be one number or one per joint"):
        tuned_law(data, rrr)
    # FL alone with one lam per joint is a structure too; the weight's synthesis is not
    assert PerJoint(base=make_structure("fl"), joints=rrr.joint_names,
                    lam="per_joint").K([]) is None
    with pytest.raises(FieldError, match="lam: a per-joint lam with the weight structure: its "
                                         "loop-shaping synthesis is of one FL plant"):
        PerJoint(base=make_structure("weight"), joints=rrr.joint_names, lam="per_joint")
    with pytest.raises(FieldError, match="lam of PerJoint must be None"):
        PerJoint(base=make_structure("gain"), joints=rrr.joint_names, lam=30.0)


def test_cli_design_per_joint_lam_writes_a_list_and_reproduce_runs_it(tmp_path,
                                                                      without_figures):
    from conftest import REPRODUCE, run_cli

    run = run_cli(["design", "--robot", "rrr", "--structure", "gain", "--per-joint-lam",
                   "--samples", "1", "--starts", "1", "--no-simulate", "--require",
                   "delay_margin=0.004", "--require", "disk_margin=0.4"], tmp_path / "d")
    assert run.code == 0, run.stderr
    data = json.loads((tmp_path / "d" / "design.json").read_text())
    assert isinstance(data["lam_rad_s"], list) and len(data["lam_rad_s"]) == 3
    assert "(per joint)" in run.stdout
    rep = run_cli([*REPRODUCE, "--robot", "rrr", "--controllers", "fl,tuned", "--design",
                   str(tmp_path / "d" / "design.json")], tmp_path / "r")
    assert rep.code == 0, rep.stderr
    results = json.loads((tmp_path / "r" / "results.json").read_text())
    assert results["design"]["tuned"]["lam_rad_s"] == data["lam_rad_s"]


def test_cli_per_joint_lam_on_the_papers_design_is_refused(tmp_path):
    from conftest import run_cli

    run = run_cli(["design", "--per-joint-lam"], tmp_path / "d")
    assert run.code == 2 and "--per-joint-lam: the paper's loop-shaping design" in run.stderr
    run = run_cli(["design", "--robot", "rrr", "--structure", "weight", "--per-joint-lam"],
                  tmp_path / "w")
    assert run.code == 2 and "--per-joint-lam: a per-joint lam with the weight structure" in \
        run.stderr


def test_linear_model_loops_per_joint(rrr):
    """Each joint's continuous loop is (2 lam_j s + lam_j^2 (1 + K_j(s))) / s^2 (eq. 10-11)."""
    import control

    from rrr_pin.campaign.design_file import law_of as _law

    Ks = [control.tf([1.0], [1.0]), control.tf([2.0, 30.0], [1.0, 10.0]),
          control.tf([3.0, 5.0], [1.0, 50.0])]
    s = 7.0j
    for lam in (LAMS, 45.0):
        loops = _law(rrr, lam, Ks).linear_model().loops(np.zeros(3))
        assert len(loops) == 3
        for j, (L, K) in enumerate(zip(loops, Ks, strict=True)):
            lj = np.broadcast_to(lam, (3,))[j]
            want = (2 * lj * s + lj * lj * (1 + K(s))) / s ** 2
            assert_allclose(L(s), want, rtol=1e-12)  # a minimal realization: round-off
    # the shared law is still one loop
    assert len(TrackingController(rrr, 45.0, Ks[1]).linear_model().loops(np.zeros(3))) == 1
    # the slowest joint's bandwidth
    assert TrackingController(rrr, LAMS, None).linear_model().bandwidth(np.zeros(3)) == 30.0


def test_the_tuners_loops_use_each_joints_lam(rrr):
    """FL alone, lam per joint, on the digital loop the tuner evaluates (at 100 kHz: ~continuous).

    Per joint L_j = (2 lam_j s + lam_j^2) / s^2: w_c = lam_j sqrt(2 + sqrt 5) and the delay
    margin atan(2 w_c / lam_j) / w_c, least at the fastest joint; the actuator boundary (Routh
    on s^3 + wa s^2 + 2 lam wa s + lam^2 wa) is wa > lam_j / 2, highest at the fastest joint.
    """
    import math

    from test_tuning import _ctx

    from rrr_pin.campaign.requirements import ActuatorBandwidth, DelayMargin
    from rrr_pin.campaign.tuning import _Eval

    lams = np.array([60.0, 100.0, 140.0])
    fast = _ctx(rrr, 1e5)
    ev = _Eval(fast, lams, None)
    taus = [math.atan(2 * math.sqrt(2 + math.sqrt(5))) / (lam * math.sqrt(2 + math.sqrt(5)))
            for lam in lams]
    # as tests/test_tuning.py's shared-lam closed forms: ZOH T/2 and the grid, 0.2 % / 0.5 %
    assert_allclose(DelayMargin(0.001).estimate(fast, ev), min(taus), rtol=2e-3)
    assert_allclose(ActuatorBandwidth(60.0).estimate(fast, ev), lams.max() / 2, rtol=5e-3)
    # equal entries: the shared law's values exactly
    for req in (DelayMargin(0.001), ActuatorBandwidth(60.0)):
        assert req.estimate(fast, _Eval(fast, np.full(3, 100.0), None)) == \
            req.estimate(fast, _Eval(fast, 100.0, None))


def test_a_lam_start_outside_the_search_range_is_refused(rrr):
    # issue 50's probe: --per-joint-lam --lam 600 started at 500 without a word (the start was
    # clipped to LAM_BOUNDS); the start is refused by name, naming the range.
    from rrr_pin.control.structures import LAM_BOUNDS

    lo, hi = LAM_BOUNDS
    for lam in (0.5 * lo, 1.2 * hi):
        with pytest.raises(FieldError, match=rf"^lam_start = {lam:g} rad/s, the start of each "
                                             rf"joint's lam, is outside the search range "
                                             rf"\[{lo:g}, {hi:g}\] rad/s"):
            make_structure("gain", lam=lam, joints=rrr.joint_names, per_joint_lam=True)
    for lam in (lo, hi):  # the ends of the range are starts
        assert_allclose(make_structure("gain", lam=lam, joints=rrr.joint_names,
                                       per_joint_lam=True).initial()[:3], [lam] * 3)


def test_cli_lam_with_tune_lam_is_refused_not_ignored(tmp_path, capsys):
    # issue 50's probe: design --tune-lam --lam 0 started at 50 rad/s without a word
    from rrr_pin.cli import main

    assert main(["design", "--robot", "rrr", "--tune-lam", "--lam", "0", "--out",
                 str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err
    assert "--lam 0 with --tune-lam: the search of lam starts at 50 rad/s" in err
    assert "Traceback" not in err
