"""Every script runs with small settings, so none rots."""

import json
import runpy
import sys
from pathlib import Path

import pytest

# Imported here, not first under capsys: in an editable install, loading the extension may run
# the rebuild hook, which hands sys.stdout to a subprocess (capsys's stream has no fileno).
import rrr_pin.sim.compiled  # noqa: F401

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"

RUNS = [
    ("simulate_nominal.py", ["--duration", "0.2", "--controllers", "fl,hinf,pd",
                             "--out", "{tmp}/nominal.png"]),
    ("simulate_nominal.py", ["--duration", "0.2", "--rate", "1000", "--out",
                             "{tmp}/nominal_sampled.png"]),
    ("uncertain_study.py", ["--samples", "2", "--duration", "0.2", "--jobs", "1",
                            "--controllers", "fl,pd", "--out", "{tmp}/uncertain.png"]),
    ("identify_example.py", ["--quick", "--out", "{tmp}"]),
    ("identify_example.py", ["--quick", "--friction", "--out", "{tmp}"]),
    ("compare_searches.py", ["--starts", "1", "--maxfev", "8", "--nm-maxfev", "6",
                             "--plants", "0", "--out", "{tmp}/searches.png"]),
    ("verdicts_figure.py", ["--plants", "1", "--duration", "0.5", "--out",
                            "{tmp}/verdicts.png"]),
]

# issue 13's keys, and the keys the benchmark had before them (kept for the README's table).
BENCH_KEYS = {"campaign_s", "campaign_bound_s", "python_rollout_ms", "handwritten_python_ms",
              "robot_call_us", "bare_call_us", "cli_help_s", "import_s",
              "machine", "per_call_us", "rollout_ms", "rollout_ms_fl", "floor_ms",
              "ratio_to_floor", "us_per_step", "montecarlo_rollouts_per_s", "settings"}


def run_script(script, args, monkeypatch):
    monkeypatch.setattr(sys, "argv", [str(SCRIPTS / script)] + args)
    runpy.run_path(str(SCRIPTS / script), run_name="__main__")


def test_every_script_is_tested():
    assert {p.name for p in SCRIPTS.glob("*.py")} == {r[0] for r in RUNS} | {
        "bench.py", "codegen.py", "gen_dynamics.py", "report_screenshot.py",
        "panda_heldout.py", "probe_inputs.py",
        "figures_table.py"}  # tests/test_readme.py runs it (--check, and on a changed figure)


def test_report_screenshot_refuses_a_missing_report(tmp_path, monkeypatch, capsys):
    with pytest.raises(SystemExit) as exc:
        run_script("report_screenshot.py", [str(tmp_path / "none.html"),
                                            str(tmp_path / "x.png")], monkeypatch)
    assert exc.value.code == 2
    assert "none.html: no such file" in capsys.readouterr().err


def test_report_screenshot_draws_the_scene(tmp_path, monkeypatch, capsys):
    # A small report (one 0.5 s scene, one ghost) instead of the README's full study.
    import shutil

    import matplotlib.pyplot as plt
    import numpy as np

    if not (shutil.which("chromium") or shutil.which("chromium-browser")) \
            or not shutil.which("chromedriver"):
        pytest.skip("Chromium is missing: apt-get install chromium chromium-driver")
    pytest.importorskip("selenium")
    from rrr_pin.model.dynamics import load_robot
    from rrr_pin.report.html import write_report_html
    from rrr_pin.report.viewer import Scene, Track

    t = np.arange(0.0, 0.5005, 1e-3)
    q = 0.5 * np.sin(np.pi * t[:, None] + 2 * np.pi * np.arange(3) / 3)
    robot = load_robot("rrr")
    scene = Scene("H-inf + FL", robot, [Track("nominal", t, q),
                                        Track("plant 0", t, q + 0.2, opacity=0.35)])
    report = write_report_html(tmp_path / "report.html", title="small", scenes=[scene])
    out = tmp_path / "shot.png"
    run_script("report_screenshot.py", [str(report), str(out), "--scene", "0", "--time", "0.25",
                                        "--width", "640", "--height", "480"], monkeypatch)
    assert f"wrote {out}" in capsys.readouterr().out
    rgb = (plt.imread(out)[..., :3] * 255).astype(int)
    assert rgb.shape == (480, 640, 3)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    # the nominal arm is drawn in orange (MeshCat rendered the scene, not a blank page)
    assert np.count_nonzero((r > 180) & (g > 80) & (g < 180) & (b < 100)) > 200


def test_probe_inputs_classifies_a_few_cases(tmp_path, monkeypatch, capsys):
    # Two of its cases (the whole probe takes minutes, a few s per case): a CLI refusal and an
    # accepted input checked right; the JSON holds the table per family.
    out = tmp_path / "probe.json"
    run_script("probe_inputs.py", ["--cases", "confidence-alone,mat-round-trip",
                                   "--workdir", str(tmp_path / "w"), "--out", str(out)],
               monkeypatch)
    assert "wrote" in capsys.readouterr().out
    report = json.loads(out.read_text())
    assert {c["case"]: c["outcome"] for c in report["cases"]} == {
        "confidence-alone": "clear", "mat-round-trip": "correct"}
    assert report["table"]["all"]["clear"] == 1 and report["table"]["trajectory"]["correct"] == 1


def test_codegen_check_runs(monkeypatch, capsys):
    # --check only: regenerating needs the hand-built generator (docs/codegen.md).
    with pytest.raises(SystemExit) as exc:
        run_script("codegen.py", ["--check"], monkeypatch)
    assert exc.value.code == 0
    assert "up to date" in capsys.readouterr().out


def test_bench_runs_and_reports_its_keys(monkeypatch, capsys):
    # Only that it runs and prints the documented keys: speed is never asserted in tests.
    # every section but 11 (issue 48's design and montecarlo commands, 13 s even --quick: its
    # children are the CLI's own runs, which their tests cover)
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench", SCRIPTS / "bench.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    sections = ",".join(s for s in bench.SECTIONS if s != "11")
    run_script("bench.py", ["--json", "--quick", "--sections", sections], monkeypatch)
    data = json.loads(capsys.readouterr().out)
    assert BENCH_KEYS <= set(data)
    rows = data["compiled_vs_floor"]
    assert {(r["law"], r["time"], r["reference"]) for r in rows} == {
        (law, t, ref) for law in ("fl", "hinf", "pd") for t in ("sampled", "continuous")
        for ref in ("sine", "quintic", "spline", "line")}
    assert set(data["robot_call_us"]) == set(data["bare_call_us"]) == {"M", "V", "G"}
    # The yardstick computes the same trajectory as the Python engine (same operations).
    assert data["handwritten_max_diff_rad"] < 1e-12
    assert data["mu"]["size"] == 10 and data["mu"]["frequencies"] == 1  # the frozen FL loop


def test_bench_table(monkeypatch, capsys):
    run_script("bench.py", ["--quick", "--sections", "1,2,3,4,5"], monkeypatch)  # the tables
    out = capsys.readouterr().out
    for what in ("machine:", "Robot/bare", "floor [ms]", "yardstick", "bound", "rrr-pin --help"):
        assert what in out


@pytest.mark.parametrize("script,args", RUNS, ids=[f"{r[0]}-{i}" for i, r in enumerate(RUNS)])
def test_script_runs(script, args, tmp_path, monkeypatch, capsys):
    run_script(script, [a.format(tmp=tmp_path) for a in args], monkeypatch)
    assert "wrote" in capsys.readouterr().out
    assert list(tmp_path.glob("*.png"))


def test_panda_heldout_on_a_synthetic_split_log(tmp_path, monkeypatch, capsys):
    """A 3 s synthetic Panda log in the per-quantity layout (no real log in the tests): the
    script identifies, predicts, writes its figure and JSON. The log is made by the published
    model itself (Gaz et al.'s bodies and friction), so that model predicts it exactly."""
    import numpy as np

    from rrr_pin.model.dynamics import load_robot, robot_from_xml
    from rrr_pin.model.excitation import FourierTrajectory
    from rrr_pin.model.identification import body_links, urdf_with_parameters

    heldout = runpy.run_path(str(SCRIPTS / "panda_heldout.py"))
    panda = load_robot("panda")  # fingers locked (logged)
    truth = robot_from_xml(urdf_with_parameters(panda.urdf, body_links(panda),
                                                heldout["gaz_phi"](), moving=panda.joint_names),
                           lock=dict(panda.locked))
    rng = np.random.default_rng(0)
    q0 = 0.5 * (panda.lower + panda.upper)
    traj = FourierTrajectory(0.5, 0.15 * rng.standard_normal((7, 3)),
                             0.15 * rng.standard_normal((7, 3)), q0, 1)
    t = np.arange(0.0, 3.0, 0.005)
    q, qd, qdd = traj.sample(t)
    tau = np.array([truth.inverse_dynamics(*x) for x in zip(q, qd, qdd, strict=True)])
    tau += heldout["gaz_friction"](qd)
    for name, x in (("time", t), ("positions", q), ("velocity", qd), ("torques", tau)):
        np.savetxt(tmp_path / f"{name}.txt", x.reshape(-1), fmt="%.17g")
    run_script("panda_heldout.py", [str(tmp_path), "--out", str(tmp_path / "out")],
               monkeypatch)
    assert "wrote" in capsys.readouterr().out
    rec = json.loads((tmp_path / "out" / "panda_heldout.json").read_text())
    # the published model made the log: it predicts the held-out window to the filter's error
    # (the Savitzky-Golay accelerations of a smooth log): far below the torques' size
    assert max(rec["held_out"]["published"]["rms_Nm"]) < 0.05
    assert set(rec["masses_kg"]) == {"identified_friction", "identified_rigid",
                                     "published_gaz2019", "example_robot_data"}
    assert (tmp_path / "out" / "panda_heldout.png").stat().st_size > 10_000
