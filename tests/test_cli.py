"""The command line end to end, on every kind of plant (serial arms and closed chains).

The shared runs (``reproduced`` of tests/conftest.py: one ``rrr-pin reproduce`` per plant kind)
are read by every test that only inspects their outputs.
"""

import json

import numpy as np
import pytest

from rrr_pin import cli
from rrr_pin.model.dynamics import load_robot
from rrr_pin.model.plant import CAPABILITIES, URDF

KEYS = {"rms_error", "max_error", "rms_torque", "peak_torque"}

#: The kinds of plant every shared-run test reads (indirect parametrization of ``reproduced``).
KINDS = ["rrr", "fivebar"]

#: Each kind's study reference (``--reference study``): an arm's sine, a mechanism's task path
#: (a spline through its inverse kinematics).
REFERENCE_KIND = {"rrr": "sine", "fivebar": "spline"}


@pytest.mark.parametrize("reproduced, plant", [(k, k) for k in KINDS], indirect=True, ids=KINDS)
def test_reproduce_writes_everything(reproduced, plant):
    assert reproduced.code == 0, reproduced.stderr
    out = reproduced.out
    for name in ("fig2", "fig3", "fig4a", "fig4b", "fig5_nominal", "fig6_uncertain",
                 "certificates", "margins"):
        assert (out / f"{name}.png").stat().st_size > 10_000
    # a plant with a task path (a mechanism's) has its figure, the others none
    assert (out / "task_path.png").exists() == (plant.task_points(0.3) is not None)
    # each uncertain plant as its own description (URDF, MJCF), which loads back
    suffix = plant.source_text()[1]
    plants = sorted((out / "plants").iterdir())
    assert [p.name for p in plants] == [f"{plant.name}_000{suffix}", f"{plant.name}_001{suffix}"]
    assert [load_robot(p).nq for p in plants] == [plant.nq] * 2
    assert "| Uncertain plants: RMS error FL alone / H-inf+FL" in (out / "results.md").read_text()
    assert (out / "report.html").stat().st_size > 10_000


@pytest.mark.parametrize("reproduced, plant", [(k, k) for k in KINDS], indirect=True, ids=KINDS)
def test_results_json_layout(reproduced, plant, strict_json):
    data = strict_json((reproduced.out / "results.json").read_text())
    assert data["robot"] == plant.name and data["joint_names"] == plant.joint_names
    assert data["reference"]["kind"] == REFERENCE_KIND[plant.name]
    assert data["reference"]["duration_s"] == 0.3
    # a plant that records its loop drift (a closed chain) has it per run, in metres
    keys = KEYS | ({"drift_m"} if plant.loop_closures else set())
    for group in ("nominal", "uncertain"):
        for key in ("fl", "hinf"):
            assert set(data[group][key]) == keys
            assert all(len(data[group][key][k]) == plant.nq for k in KEYS)
    samples = data["uncertain"]["samples"]
    assert [s["seed"] for s in samples] == [[0, 0], [0, 1]]
    assert {"fl", "hinf", "parameters", "status", "certificate"} <= set(samples[0])
    assert [s["status"] for s in samples] == ["ok", "ok"]
    summary = data["summary"]
    # the headline nominal error is the largest of the per-joint maxima, and the paper's
    # nominal claim in results.md is read from it
    nom = summary["nominal_max_error"]
    assert nom == {k: max(data["nominal"][k]["max_error"]) for k in ("fl", "hinf")}
    assert (f"max abs error: FL {nom['fl']:.3g} rad, H-inf+FL {nom['hinf']:.3g} rad"
            in (reproduced.out / "results.md").read_text())
    assert summary["error_ratio_uncertain"]["hinf"] > 0
    assert len(summary["error_ratio_uncertain_per_joint"]["hinf"]) == plant.nq
    assert summary["torque_ratio_uncertain"]["hinf"] > 0
    assert summary["samples_certified"] == sum(s["certificate"]["certified"] for s in samples)
    assert data["config"]["engine"] == "auto" and data["config"]["baseline"] == "fl"
    # The design recorded beside the study is the paper's (eq. 18 within 0.5 %).
    assert abs(data["design"]["gamma_min"] / 2.1436 - 1) < 5e-3


@pytest.mark.parametrize("reproduced, plant", [(k, k) for k in KINDS], indirect=True, ids=KINDS)
def test_reproduce_prints_the_report_lines(reproduced, plant):
    # The CLI prints the report layer's lines (rrr_pin.report.results.summary_lines).
    printed = reproduced.stdout.splitlines()
    out = reproduced.out
    summary = json.loads((out / "results.json").read_text())["summary"]
    assert printed[0].startswith(f"{plant.name}: {plant.nq} joints, gamma = 2.14")
    assert printed[1] == "nominal max |e| [rad]: " + ", ".join(
        f"{k} {v:.3g}" for k, v in summary["nominal_max_error"].items())
    assert printed[2].startswith("uncertain (2 plants): RMS error fl / hinf = ")
    assert printed[3].startswith(f"certified (frozen nu-gap < b = {summary['certificate_b']:.4g}"
                                 f"): {summary['samples_certified']} of 2 plants")
    figures = len(list(out.glob("*.png")))
    assert printed[-2] == (f"wrote {out}/results.json, results.md, plants/, {figures} figures "
                           f"and report.html (open it in a browser)")
    assert printed[-1].startswith("wrote 6 trajectories")  # --save-trajectories


@pytest.mark.parametrize("extra", [
    ["--controllers", "fl,hinf,pd", "--reference", "quintic", "--to", "0.3,-0.2,0.4",
     "--q0", "0.05,0,0"],
    ["--controllers", "pd,fl", "--reference", "line", "--end", "0.6,0.1,1.9"],
], ids=["quintic-3-laws", "line-pd-baseline"])
def test_reproduce_references_and_controllers(tmp_path, extra, without_figures):
    out = tmp_path / "r"
    assert cli.main(["reproduce", "--out", str(out), "--samples", "1", "--duration", "0.3",
                     "--jobs", "1", "--no-progress", "--no-certify"] + extra) == 0
    data = json.loads((out / "results.json").read_text())
    names = extra[1].split(",")
    assert [c["name"] for c in data["controllers"]] == names
    assert data["summary"]["baseline"] == names[0]
    assert set(data["summary"]["error_ratio_uncertain"]) == set(names[1:])


@pytest.mark.parametrize("reproduced, plant", [(k, k) for k in KINDS], indirect=True, ids=KINDS)
def test_reproduce_saves_trajectories(reproduced, plant):
    from numpy.testing import assert_allclose

    from rrr_pin.sim.trajectory import Trajectory

    out = reproduced.out  # the shared run, with --save-trajectories csv
    assert reproduced.stdout.splitlines()[-1] == (f"wrote 6 trajectories to {out}/trajectories/ "
                                                  f"(csv)")
    files = sorted(p.name for p in (out / "trajectories").iterdir())
    assert files == [f"{p}_{law}.csv" for p in ("nominal", "sample000", "sample001")
                     for law in ("fl", "hinf")]
    data = json.loads((out / "results.json").read_text())
    for name, group in (("nominal", data["nominal"]), ("sample001",
                                                       data["uncertain"]["samples"][1])):
        traj = Trajectory.load(out / "trajectories" / f"{name}_hinf.csv")
        assert traj.joint_names == data["joint_names"] == plant.joint_names
        assert traj.controller == "hinf"
        assert_allclose(traj.t[-1], 0.3, rtol=0, atol=1e-12)  # the grid's last point
        # The file holds the run whose figures results.json reports: RMS error recomputed
        # from it (rtol 1e-12: the same float64 arrays, summed in the same order).
        e = traj.r - traj.q
        assert_allclose(np.sqrt(np.mean(e * e, axis=0)), group["hinf"]["rms_error"],
                        rtol=1e-12)
    args = cli.build_parser().parse_args(["reproduce", "--save-trajectories"])
    assert args.save_trajectories == "npz"  # the documented default format


@pytest.mark.parametrize("argv,message", [
    (["reproduce", "--robot", "nosuch"], "unknown robot 'nosuch'"),
    (["reproduce", "--robot", "nosuch.xml"], "MJCF file not found: nosuch.xml"),
    (["reproduce", "--lock", "joint1"], "--lock expects JOINT=VALUE"),
    (["reproduce", "--home", "0,0,3.0"], "reference for joint 'joint3' spans"),
    (["reproduce", "--home", "0,0"], "Expected --home of shape (3,), got (2,)"),
    (["reproduce", "--robot", "ur5", "--lock", "nojoint=0"], "nojoint"),
    (["reproduce", "--amp", "nan"], "--amp must be a finite number"),
    (["reproduce", "--amp", "inf"], "--amp must be a finite number"),
    (["reproduce", "--duration", "1e-4"], "shorter than one RK4 step"),
    (["reproduce", "--duration", "1e-4", "--rate", "1000"], "shorter than one control period"),
    (["reproduce", "--jobs", "0"], "--jobs must be an integer >= 1, got 0"),
    (["reproduce", "--jobs", "-1"], "--jobs must be an integer >= 1, got -1"),
    (["reproduce", "--seed", "-1"], "--seed must be an integer >= 0, got -1"),
    (["reproduce", "--samples", "-1"], "--samples must be an integer >= 0, got -1"),
    (["reproduce", "--dt", "0"], "--dt must be a finite number > 0 [s], got 0.0"),
    (["reproduce", "--rate", "nan"], "--rate must be a finite number > 0 [Hz], got nan"),
    (["reproduce", "--delay=-1e-3", "--rate", "1000"],
     "--delay must be a finite number >= 0, got -0.001"),
    (["reproduce", "--delay", "1e-3"], "give --rate HZ too"),
    (["reproduce", "--q0", "0,nan,0"], "--q0 must be finite"),
    (["reproduce", "--controllers", "fl,lqr"], "unknown controller 'lqr'"),
    (["reproduce", "--baseline", "pd"], "--baseline 'pd' is not among --controllers"),
    (["reproduce", "--q0", "0,0"], "Expected --q0 of shape (3,), got (2,)"),
    (["reproduce", "--reference", "quintic"], "needs --to"),
    (["reproduce", "--reference", "spline"], "needs --csv"),
    (["reproduce", "--reference", "line", "--end", "9,0,1"], "did not converge"),
    (["reproduce", "--reference", "quintic", "--to", "0,0,0", "--move-time", "0"],
     "--move-time must be a finite number > 0, got 0.0"),
    (["reproduce", "--reference", "circle"], "needs --radius"),
    (["reproduce", "--reference", "circle", "--radius", "-0.1"],
     "--radius must be a finite number > 0, got -0.1"),
    (["reproduce", "--reference", "circle", "--radius", "0.05", "--normal", "0,0,0"],
     "--normal must be a non-zero vector (a direction), got [0.0, 0.0, 0.0]"),
    (["montecarlo", "--samples", "0"], "--samples must be an integer >= 1, got 0"),
], ids=["robot", "mjcf", "lock-syntax", "home-limits", "home-size", "lock-unknown", "amp-nan",
        "amp-inf", "short", "short-sampled", "jobs0", "jobs-1", "seed", "samples", "dt",
        "rate-nan", "delay", "delay-no-rate", "q0-nan", "controller", "baseline", "q0",
        "quintic", "spline", "ik", "move-time", "circle-radius", "circle-radius-negative",
        "circle-normal", "mc-samples"])
def test_reproduce_bad_input(argv, message, capsys, tmp_path):
    assert cli.main(argv + ["--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


@pytest.mark.parametrize("robot", ["fivebar", "delta"])
@pytest.mark.parametrize("argv, what", [
    (["export", "--rate", "1000"], "export"),
    (["identify", "--design-excitation"], "rrr-pin identify"),
    (["identify", "--data", "measurements.csv"], "rrr-pin identify"),
], ids=["export", "identify-excitation", "identify-data"])
def test_commands_refuse_a_plant_without_their_capability_by_name(argv, what, robot, tmp_path,
                                                                   capsys):
    # export and identify need a serial tree described by a URDF; a closed chain declares no
    # such capability and is refused by it (rrr_pin.model.plant.Plant.require), naming both.
    out = tmp_path / "out"
    assert cli.main([*argv, "--robot", robot, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rrr-pin {argv[0]}: error: {what}")
    assert f"needs {CAPABILITIES[URDF]}, which the closed chain {robot!r} does not have" in err
    assert "Traceback" not in err and not out.exists()


def test_check_dynamics_refuses_an_mjcf(capsys):
    assert cli.main(["check-dynamics", "--urdf", "mjcf/fivebar.xml"]) == 2
    err = capsys.readouterr().err
    assert "check-dynamics --urdf mjcf/fivebar.xml (it compares a serial arm with the RRR's " \
           "closed form eq. (2)-(7))" in err
    assert f"needs {CAPABILITIES[URDF]}, which the closed chain 'fivebar'" in err


@pytest.mark.parametrize("robot, argv, message", [
    # (the engines' refusals of each law and plant: test_study, before any run)
    ("fivebar", ["--reference", "circle", "--radius", "0.05"],
     "--reference circle needs named frames placed by forward kinematics of the actuated "
     "joints, which the closed chain 'fivebar' does not have"),
    ("fivebar", ["--lock", "qa1=0"], "joints of a closed chain cannot be locked"),
    ("fivebar", ["--controllers", "fl,fl"], "control law names must be unique, repeated: fl"),
    ("fivebar", ["--home", "0,0,0"], "Expected --home of shape (2,), got (3,)"),
    ("delta", ["--controllers", "fl,bogus"], "unknown controller 'bogus'; built-in controllers"),
], ids=["fivebar-circle", "fivebar-lock", "fivebar-repeated", "fivebar-home", "delta-unknown"])
def test_reproduce_refuses_what_the_plant_or_engine_cannot_run(robot, argv, message, tmp_path,
                                                               capsys):
    # Refused by name before any run: no results.json (the design figures may be written).
    out = tmp_path / "o"
    assert cli.main(["reproduce", "--robot", robot, *argv, "--samples", "0", "--duration",
                     "0.01", "--rate", "1000", "--no-certify", "--no-progress", "--out",
                     str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (out / "results.json").exists()


@pytest.mark.parametrize("cmd", [["reproduce", "--no-progress"],
                                 ["montecarlo", "--samples", "2", "--no-progress"],
                                 ["stress", "--effect", "delay"]],
                         ids=["reproduce", "montecarlo", "stress"])
def test_out_is_a_file(tmp_path, capsys, cmd):
    # One writability check (rrr_pin.outputs.check_writable) for every command.
    f = tmp_path / "file"
    f.write_text("x")
    assert cli.main(cmd + ["--out", str(f)]) == 2
    err = capsys.readouterr().err
    assert "exists and is not a folder" in err and "Traceback" not in err


def test_reproduce_circle_reference_starts_where_the_frame_is(tmp_path, rrr,
                                                             without_figures):
    # The circle of --reference circle starts at the frame's position at the start
    # configuration: centre + radius * start_dir is that point (rrr_pin.control.paths).
    import ast

    import numpy as np

    out = tmp_path / "c"
    assert cli.main(["reproduce", "--out", str(out), "--samples", "0", "--duration", "0.3",
                     "--jobs", "1", "--no-progress", "--reference", "circle", "--radius",
                     "0.05", "--home", "0.3,0.6,-1.2", "--no-certify"]) == 0
    source = json.loads((out / "results.json").read_text())["reference"]["source"]
    assert source.startswith("task-space circle of frame ")
    path = ast.literal_eval(source[source.index("{"):source.index("}, fk_error_m") + 1])
    assert path["kind"] == "circle" and path["radius_m"] == 0.05
    robot = rrr
    start = np.array([0.3, 0.6, -1.2])  # --home: a bent arm, the circle within reach
    p0 = robot.frame_placement(start, robot.model.frames[len(robot.model.frames) - 1].name)
    np.testing.assert_allclose(np.add(path["center_m"], 0.05 * np.array(path["start_dir"])),
                               p0[:3, 3], rtol=0, atol=1e-12)  # round-off of c + r u only


def test_help_loads_no_numerical_library():
    # `rrr-pin --help` must answer at once: building the parser imports neither Pinocchio nor
    # python-control (timing itself is measured in scripts/bench.py, never asserted).
    import subprocess
    import sys

    code = ("import sys, rrr_pin.cli as c; c.build_parser(); "
            "print(sorted(m for m in ('pinocchio', 'control', 'numpy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip().splitlines()[-1]
    assert out == "[]"


def test_version_prints_the_package_version(capsys):
    import rrr_pin

    with pytest.raises(SystemExit) as info:
        cli.main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"rrr-pin {rrr_pin.__version__}"
    # the package's namespace holds its version string, not importlib's version() function
    assert not hasattr(rrr_pin, "version")


def test_verbose_shows_the_library_log_on_stderr(capsys):
    import logging

    argv = ["check-dynamics", "--samples", "1"]
    line = ("INFO rrr_pin.model.dynamics: loaded rrr from <params>: 3 joints (joint1, joint2, "
            "joint3)")
    assert cli.main(argv) == 0
    assert "INFO" not in capsys.readouterr().err
    for verbose in (["-v"] + argv, argv + ["-v"], ["-vv"] + argv):
        assert cli.main(verbose) == 0
        err = capsys.readouterr().err
        assert err.count(line) == 1, verbose  # once: an earlier call's handler is removed
    logger = logging.getLogger("rrr_pin")
    assert logger.handlers == [] and logger.level == logging.NOTSET


def test_help_texts_have_no_doubled_percent(capsys):
    with pytest.raises(SystemExit):
        cli.main(["montecarlo", "--help"])
    out = capsys.readouterr().out
    assert "%%" not in out and "20 % inertia" in out


@pytest.mark.parametrize("value, shown", [("-1e-3", "-0.001"), ("-2.5E+1", "-25.0"), ("-1", "-1")],
                         ids=["exponent", "exponent-upper", "integer"])
def test_negative_option_values_reach_the_options_check(capsys, tmp_path, value, shown):
    # argparse alone reads "-1e-3" as an option ("expected one argument")
    assert cli.main(["reproduce", "--dt", value, "--out", str(tmp_path / "o"),
                     "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"--dt must be a finite number > 0 [s], got {shown}" in err


@pytest.mark.parametrize("argv, message", [
    (["--torque-limit", "-5%", "--rate", "1000"], "--torque-limit '-5%': the percent must be "
                                                  "finite and > 0"),
    (["--home", "-9,0,0"], "reference for joint 'joint1' spans [-9.5, -8.5] rad, outside its "
                           "limits"),
], ids=["percent", "list"])
def test_negative_percent_and_list_values_reach_the_options_check(capsys, tmp_path, argv,
                                                                   message):
    # before: "argument --torque-limit: expected one argument" (issue 31)
    assert cli.main(["reproduce", *argv, "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    assert message in capsys.readouterr().err


# --- issue 24: nothing silently substituted (rounded, clipped) and no endless work -------------

@pytest.mark.parametrize("argv, message", [
    # Before: no delay at all (campaign.csv byte-identical to a run without --delay).
    (["montecarlo", "--samples", "1", "--delay", "0.0004"],
     "--delay = 0.0004 s is not a whole number of plant sub-steps h = 0.001 s (0.4 of them): "
     "the nearest realizable values are 0 s and 0.001 s"),
    # Before: ran as 2 ms, summary.json said 1.6 ms.
    (["montecarlo", "--samples", "1", "--delay", "0.0016"],
     "the nearest realizable values are 0.001 s and 0.002 s"),
    # Before: accepted and recorded, the sub-step became 1/rate.
    (["stress", "--effect", "delay", "--dt", "0.5"],
     "--dt = 0.5 s does not divide the control period 1/rate = 0.001 s into whole RK4 "
     "sub-steps (0.002 of them): the nearest realizable sub-steps are 0.001 s (1 sub-step)"),
    (["reproduce", "--rate", "1000", "--dt", "3e-4"],
     "the nearest realizable sub-steps are 0.000333333333333 s (3 sub-steps) and 0.00025 s "
     "(4 sub-steps)"),
    (["reproduce", "--rate", "1000", "--duration", "0.0015"],
     "--duration = 0.0015 s is not a whole number of control periods 1/rate = 0.001 s"),
    (["reproduce", "--duration", "1.00005"],
     "--duration = 1.00005 s is not a whole number of RK4 steps dt = 0.001 s"),
    # Before: ran at 2.83 rad (45 % of the joint's range).
    (["reproduce", "--amp", "10"],
     "--amp = 10 rad is too large for joint 'joint1' (limits [-3.142, 3.142] rad): the largest "
     "amplitude they allow about the default home (range / 2.2) is 2.856 rad"),
    # Before: hung (1e10 control periods).
    (["montecarlo", "--samples", "1", "--rate", "1e9"],
     "--duration = 10 s at rate = 1e+09 Hz is 1e+10 control periods"),
    # Before: hung (2e8 RK4 steps).
    (["reproduce", "--duration", "2000", "--dt", "1e-5"],
     "--duration = 2000 s is 2e+08 RK4 steps dt = 1e-05 s: 2e+08 RK4 steps and 2e+08 stored "
     "samples"),
    # Before: a MemoryError traceback after allocating gigabytes.
    (["montecarlo", "--samples", "1", "--duration", "1e5"],
     "above the bounds of 1e+07 RK4 steps and 1e+06 samples"),
], ids=["delay-below-step", "delay-between-steps", "stress-dt-above-period", "dt-not-dividing",
        "duration-off-period", "duration-off-dt", "amp-too-large", "rate-1e9", "duration-dt",
        "duration-1e5"])
def test_nothing_silently_substituted(argv, message, capsys, tmp_path):
    out = tmp_path / "o"
    assert cli.main(argv + ["--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())  # refused before any work


def test_force_lifts_the_work_bound(monkeypatch, capsys, tmp_path):
    # With the bound lowered to 10 RK4 steps, a 20 ms run at 1 kHz (20 steps) is refused, and
    # runs with --force.
    from rrr_pin.sim import simulation

    monkeypatch.setattr(simulation, "MAX_SUBSTEPS", 10)
    argv = ["montecarlo", "--samples", "1", "--jobs", "1", "--duration", "0.02",
            "--no-progress", "--controllers", "fl"]
    assert cli.main(argv + ["--out", str(tmp_path / "a")]) == 2
    assert "above the bounds of 1e+01 RK4 steps" in capsys.readouterr().err
    assert cli.main(argv + ["--out", str(tmp_path / "b"), "--force"]) == 0
    summary = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert summary["summary"]["samples"] == 1
    assert "force" not in summary["settings"]  # a permission, not a setting of the numbers


def test_force_help_names_the_bounds():
    # The help spells the bounds without importing them (it must not load NumPy).
    from rrr_pin.sim.simulation import MAX_SAMPLES, MAX_SUBSTEPS

    text = cli.build_parser()._subparsers._group_actions[0].choices["montecarlo"].format_help()
    assert f"{MAX_SUBSTEPS:.0e}".replace("+0", "") in text
    assert f"{MAX_SAMPLES:.0e}".replace("+0", "") in text


def test_summary_records_the_delay_realized(tmp_path):
    # 2 ms at 1 kHz with the default sub-step (1 ms): 2 sub-steps, recorded as realized.
    out = tmp_path / "o"
    assert cli.main(["montecarlo", "--samples", "1", "--jobs", "1", "--duration", "0.05",
                     "--controllers", "fl", "--rate", "1000", "--delay", "0.002",
                     "--no-progress", "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["settings"]["dt_s"] == 1e-3
    fx = s["settings"]["effects"]
    assert fx["delay_substeps"] == 2 and fx["delay_s"] == 2 * 1e-3


@pytest.mark.parametrize("argv, option", [
    (["urdf", "--params", "{dir}"], "--params"),
    (["check-dynamics", "--urdf", "{dir}"], "--urdf"),
    (["check-dynamics", "--params", "{dir}"], "--params"),
    (["reproduce", "--robot", "{dir}", "--out", "{dir}/o"], "--robot"),
    (["reproduce", "--reference", "spline", "--csv", "{dir}", "--out", "{dir}/o"], "--csv"),
    (["montecarlo", "--samples", "1", "--robot", "{dir}", "--out", "{dir}/o"], "--robot"),
    (["stress", "--effect", "delay", "--robot", "{dir}", "--out", "{dir}/o"], "--robot"),
], ids=["urdf-params", "check-urdf", "check-params", "reproduce-robot", "reproduce-csv",
        "montecarlo-robot", "stress-robot"])
def test_a_folder_given_for_a_file_is_refused_as_a_folder(argv, option, tmp_path, capsys):
    # It said "file not found" (the folder exists).
    folder = tmp_path / "a.urdf"
    folder.mkdir()
    assert cli.main([a.format(dir=folder) for a in argv]) == 2
    err = capsys.readouterr().err
    assert f"{option} {folder}: is a directory, expected a file" in err
    assert "Traceback" not in err


@pytest.mark.parametrize("argv, message", [
    (["--lam", "1e9"], "--lam must be in [1e-06, 1e+07] rad/s"),
    (["--lam", "1e-9"], "--lam must be in [1e-06, 1e+07] rad/s"),
    (["--lam", "nan"], "--lam must be a finite number > 0 [rad/s], got nan"),
    (["--factor", "0.5"], "--factor must be >= 1 (1 = optimal controller), got 0.5"),
    (["--factor", "inf"], "--factor must be finite, got inf"),
    (["--joints", "0"], "--joints must be an integer in [1, 1000], got 0"),
], ids=["lam-huge", "lam-tiny", "lam-nan", "factor-below-1", "factor-inf", "joints-0"])
def test_design_names_its_options(argv, message, capsys):
    # --lam 1e9 failed deep inside the synthesis ("Riccati equation without stabilizing
    # solution"); lam, factor and n were named as the Python arguments.
    assert cli.main(["design", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err



@pytest.mark.parametrize("engine", ["python", "compiled"])
def test_threads_for_an_engine_that_has_none_are_refused(engine, tmp_path, capsys):
    # issue 50's probe: --threads 2 --engine compiled was accepted without a word
    assert cli.main(["montecarlo", "--samples", "1", "--threads", "2", "--engine", engine,
                     "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"--threads 2 with --engine {engine}: threads are the batched engine's" in err
    assert "Traceback" not in err and not (tmp_path / "o").exists()


@pytest.mark.parametrize("name", ["xarm7", "panda", "rrr", "fivebar"])
def test_a_folder_does_not_shadow_a_robot_name(name, tmp_path, monkeypatch):
    # Issue 31: `--robot xarm7 --out xarm7` claimed the folder first, then refused the name
    # as "is a directory, expected a file". A built-in name resolves before any path.
    from rrr_pin.cli.common import not_a_folder
    from rrr_pin.model.robots import read_source

    monkeypatch.chdir(tmp_path)
    (tmp_path / name).mkdir()
    not_a_folder(robot=name)  # no error: a name, not the folder
    if name != "fivebar":
        assert read_source(name)[1] == name
    (tmp_path / "myarm").mkdir()
    with pytest.raises(ValueError, match="--robot myarm: is a directory, expected a file"):
        not_a_folder(robot="myarm")


def test_a_negative_percentage_reaches_the_options_own_check(capsys, tmp_path):
    # Issue 31: `--torque-limit -5%` said "expected one argument" (argparse took it for an
    # option); joined as --torque-limit=-5% it reaches the torque-limit rule.
    from rrr_pin.cli.common import negative_values

    assert negative_values(["--torque-limit", "-5%"]) == ["--torque-limit=-5%"]
    # "-1" is joined too: "--x=-1" is what argparse reads "--x -1" as
    assert negative_values(["--dt", "-1e-3", "--x", "-1"]) == ["--dt=-1e-3", "--x=-1"]
    assert cli.main(["reproduce", "--torque-limit", "-5%", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "--torque-limit" in err and "expected one argument" not in err


def test_every_plant_effect_is_an_option_spelled_as_its_field():
    # issue 50: montecarlo had no torque limit and no sensor noise; Python spelled the
    # actuator `bandwidth`. Each PlantEffects field is an option of reproduce and montecarlo,
    # --name-with-dashes for name_with_underscores (but --noise-seed for seed), parsed into
    # the field; the friction's three fields are --friction's (viscous=,coulomb=,smooth=).
    import dataclasses

    from rrr_pin.cli.build import settings_from_args
    from rrr_pin.control.effects import PlantEffects

    parser = cli.build_parser()
    for command in ("reproduce", "montecarlo"):
        options = {a.dest for a in parser._subparsers._group_actions[0].choices[command]._actions}
        for f in dataclasses.fields(PlantEffects):
            if f.name in ("viscous", "coulomb", "coulomb_velocity"):
                assert "friction" in options
            else:
                assert ("noise_seed" if f.name == "seed" else f.name) in options, f.name
    args = parser.parse_args(["montecarlo", "--samples", "1", "--rate", "1000", "--delay", "0.002",
                              "--actuator-bandwidth", "300", "--noise-q", "1e-4/2e-4/3e-4",
                              "--noise-qd", "1e-3", "--noise-seed", "7", "--encoder-counts",
                              "4096", "--stiffness", "2e4", "--motor-inertia", "0.05",
                              "--transmission-damping", "20", "--friction",
                              "viscous=0.5,coulomb=1"])
    got = settings_from_args(args, 3).effects
    assert got == PlantEffects(delay=0.002, actuator_bandwidth=300.0,
                               noise_q=(1e-4, 2e-4, 3e-4), noise_qd=1e-3, seed=7,
                               encoder_counts=4096, stiffness=2e4, motor_inertia=0.05,
                               transmission_damping=20.0, viscous=0.5, coulomb=1.0)
    for argv, message in ((["--noise-seed", "3"], "--noise-seed seeds the sensor noise"),
                          (["--motor-inertia", "0.1"], "give --stiffness K too"),
                          (["--noise-q", "x"], "--noise-q expects a number")):
        with pytest.raises(ValueError, match=message):
            settings_from_args(parser.parse_args(["montecarlo", "--samples", "1", *argv]), 3)


def test_no_option_shadows_the_command_name():
    # issue 47's --command (the torque convention) once took argparse's dest "command", the
    # subcommand's: every error of export then read "rrr-pin full: error: ...".
    parser = cli.build_parser()
    for name, sub in parser._subparsers._group_actions[0].choices.items():
        assert "command" not in {a.dest for a in sub._actions}, name
