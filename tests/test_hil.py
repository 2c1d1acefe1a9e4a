"""`rrr-pin hil`: the exported controller in real time against the simulated arm (issue 35).

The default run drives 2e4 cycles of the paper's H-infinity + FL on the RRR with the harness's
clock at 10 kHz (the arm still advances one 1 ms law period a cycle): 2 s instead of the 20 s
of a 1 kHz clock, which the suite's 3 minutes cannot hold. Its timing figures are printed, not
asserted (they are the machine's); what is asserted is the closed loop's arithmetic.
"""

from __future__ import annotations

import json
import shutil

import pytest
from numpy.testing import assert_allclose

from rrr_pin import default_reference, load_robot, simulate
from rrr_pin import export as export_law
from rrr_pin.cli import main
from rrr_pin.control.effects import PlantEffects
from rrr_pin.deploy.hil import hil
from rrr_pin.validation import FieldError

pytestmark = pytest.mark.skipif(shutil.which("cmake") is None or shutil.which("cc") is None,
                                reason="no cmake or C compiler")


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    robot = load_robot("rrr")
    folder = tmp_path_factory.mktemp("hil") / "hinf"
    return export_law("hinf", robot, 1000.0, folder), folder, robot


@pytest.fixture(scope="module")
def run(exported, tmp_path_factory):
    _, folder, _ = exported
    out = tmp_path_factory.mktemp("hil_out")
    return hil(folder, 20_000, out, rate=10_000.0), out


def test_hil_json_has_exactly_the_issue_keys(run, capsys):
    res, out = run
    summary = json.loads((out / "hil.json").read_text())
    assert set(summary) == {"cycles", "missed", "latency_us", "jitter_us",
                            "max_error_vs_offline_rad", "status", "diverged_at_s"}
    # the ideal loop completes; missed deadlines (a loaded machine: the arm holds the torque
    # of the period) can break the 10 kHz-clocked H-inf loop, which the status then says
    if summary["missed"] == 0:
        assert summary["status"] == "completed" and summary["diverged_at_s"] is None
    else:
        assert summary["status"] in ("completed", "diverged")
        assert (summary["diverged_at_s"] is None) == (summary["status"] == "completed")
    assert set(summary["latency_us"]) == {"p50", "p99", "p999", "p9999", "max"}
    assert summary["cycles"] == 20_000
    run_record = json.loads((out / "hil_run.json").read_text())
    assert run_record["clock_rate_hz"] == 10_000.0 and run_record["law_rate_hz"] == 1000.0
    with capsys.disabled():  # the figures of this machine, printed, not asserted
        print(f"\nhil 2e4 cycles at 10 kHz: {summary}; SCHED_FIFO {run_record['sched_fifo']}, "
              f"mlockall {run_record['mlockall']}, load {run_record['loadavg_before']}")


def test_closed_loop_equals_the_offline_loop(run):
    """Bit for bit once the missed deadlines (the arm holding its torque) are replayed."""
    res, _ = run
    assert_allclose(res.q_hil, res.q_replay, rtol=0, atol=0)
    assert res.run["max_error_vs_replay_rad"] == 0.0
    # the replay with no hold is the offline loop: with no missed deadline, the same bits
    if res.summary["missed"] == 0:
        assert res.summary["max_error_vs_offline_rad"] == 0.0
    else:
        assert res.summary["max_error_vs_offline_rad"] > 0.0


def test_offline_loop_is_rrr_pin_simulate(run, exported):
    """The harness's arm (generated M, h; Gaussian elimination; RK4) against simulate()."""
    res, _ = run
    ex, _, robot = exported
    ref = default_reference(robot)
    r0, rd0, _ = ref(0.0)
    traj = simulate(robot, ex.law, ref, 2.0, q0=r0, qd0=rd0, engine="python")
    # two dynamics implementations (generated C vs Pinocchio's ABA) and two laws (C vs
    # numpy) over 2000 steps: round-off, which the stable loop does not grow past 1e-9 rad
    assert_allclose(res.q_offline[:2000], traj.q[:2000], rtol=0, atol=1e-9)


def test_cli_hil_and_refusals(exported, tmp_path, capsys):
    _, folder, _ = exported
    assert main(["hil", str(folder), "--cycles", "500", "--rate", "5000", "--out",
                 str(tmp_path / "h")]) == 0
    text = capsys.readouterr().out
    assert "latency [us] (tick -> torque written): p50" in text and "missed deadlines" in text
    assert main(["hil", str(folder), "--cycles", "0", "--out", str(tmp_path / "z")]) == 2
    assert "cycles must be an integer in [1, 20000000], got 0" in capsys.readouterr().err
    assert main(["hil", str(tmp_path), "--cycles", "10", "--out", str(tmp_path / "y")]) == 2
    assert "holds no controller.json" in capsys.readouterr().err


def test_a_rate_the_loop_cannot_meet_is_refused(exported, tmp_path):
    _, folder, _ = exported
    with pytest.raises(FieldError, match=r"rate = 1e\+08 Hz: one cycle of the law and the "
                                         r"simulated arm took .* us offline, longer than the "
                                         r"period 0.0 us"):
        hil(folder, 1000, tmp_path / "fast", rate=1e8)
    assert not (tmp_path / "fast" / "hil.json").exists()


def test_a_delay_that_breaks_the_law_diverges_as_the_offline_replay(exported, tmp_path):
    """20 ms of transport delay: the loop diverges, in hil as offline and in rrr_pin.simulate."""
    from rrr_pin.sim.trajectory import SimulationDiverged

    ex, folder, robot = exported
    res = hil(folder, 400, tmp_path / "d", rate=10_000.0, effects=PlantEffects(delay=0.02))
    assert res.summary["status"] == "diverged"
    # the replay of the real-time run's missed deadlines diverges with it, bit for bit (hil
    # checks the cycle); with no deadline missed, that replay is the offline loop
    assert_allclose(res.q_hil, res.q_replay, rtol=0, atol=0)
    if res.summary["missed"] == 0:
        assert res.summary["diverged_at_s"] == res.run["offline_diverged_at_s"]
        assert_allclose(res.q_hil, res.q_offline, rtol=0, atol=0)
    ref = default_reference(robot)
    r0, rd0, _ = ref(0.0)
    with pytest.raises(SimulationDiverged) as caught:
        simulate(robot, ex.law, ref, 1.0, q0=r0, qd0=rd0, engine="python", dt=1e-3,
                 effects=PlantEffects(delay=0.02))
    # the Python engine dates a sampled run's divergence at the end of the period, as hil
    assert caught.value.time == pytest.approx(res.run["offline_diverged_at_s"], abs=1e-12)
    saved = json.loads((tmp_path / "d" / "hil.json").read_text())
    assert saved["status"] == "diverged"
    assert saved["diverged_at_s"] == res.summary["diverged_at_s"]


def test_delay_off_the_law_grid_is_refused(exported, tmp_path):
    _, folder, _ = exported
    with pytest.raises(FieldError, match=r"delay"):
        hil(folder, 10, tmp_path / "x", effects=PlantEffects(delay=0.0015))


def _copy(folder, tmp_path):
    dest = tmp_path / "copy"
    shutil.copytree(folder, dest, ignore=shutil.ignore_patterns("build"))
    return dest


@pytest.mark.parametrize("edit, message", [
    (("controller.json", '"rate_hz": 1000.0', '"rate_hz": 250.0'),
     r"controller.json says rate_hz = 250.0, the code \(controller.h CTRL_RATE_HZ\) is "
     r"compiled for 1000.0"),
    (("controller.json", '"name": "hinf"', '"name": "fl"'),
     r"law.name = 'fl', the code \(controller.h CTRL_LAW_NAME\) is compiled for 'hinf'"),
    (("model.txt", None, None), r"model.txt: the model's fingerprint .* is not "
                                r"controller.json's"),
], ids=["rate", "law", "fingerprint"])
def test_an_export_whose_files_disagree_is_refused_before_a_cycle(exported, tmp_path, capsys,
                                                                   edit, message):
    """The hostile-input probe of issue 47: rate_hz edited to 250 Hz, a law renamed, a model
    swapped; each refused (exit 2), naming both values, before anything is built or run."""
    _, folder, _ = exported
    bad = _copy(folder, tmp_path)
    name, old, new = edit
    if name == "model.txt":  # another arm's model in the folder
        (bad / name).write_text(load_robot("ur5").model.saveToString())
    else:
        text = (bad / name).read_text()
        assert old in text
        (bad / name).write_text(text.replace(old, new, 1))
    with pytest.raises(ValueError, match=message):
        hil(bad, 10, tmp_path / "o")
    assert main(["hil", str(bad), "--cycles", "10", "--out", str(tmp_path / "o2")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o" / "hil.json").exists()


@pytest.mark.slow
@pytest.mark.parametrize("command, atol", [("full", 1e-9), ("no-gravity", 5e-6)])
def test_hil_on_a_urdf_path_export_of_an_identified_arm(tmp_path, command, atol):
    """An arm that has no name to be loaded by (a URDF path, its masses 'identified' 10 %
    heavier): hil simulates the model the export embeds, as rrr_pin.simulate does."""
    import re

    urdf = re.sub(r'<mass value="([0-9.eE+-]+)"',
                  lambda m: f'<mass value="{float(m.group(1)) * 1.1!r}"', load_robot("rrr").urdf)
    path = tmp_path / "identified.urdf"
    path.write_text(urdf)
    robot = load_robot(str(path))
    folder = tmp_path / "ex"
    ex = export_law("fl", robot, 1000.0, folder, command=command)
    assert ex.dynamics == "dyngen"
    res = hil(folder, 2000, tmp_path / "h", rate=10_000.0)
    ref = default_reference(robot)
    r0, rd0, _ = ref(0.0)
    traj = simulate(robot, ex.law, ref, 2.0, q0=r0, qd0=rd0, engine="python")
    # full: two dynamics implementations (generated C vs Pinocchio), round-off below 1e-9 rad.
    # no-gravity: the simulated drive adds Ghat(q) at every RK4 stage (a drive compensates
    # continuously) where the law held it over the period: O(Ts^2) a step, 9.2e-7 rad measured
    # over 2 s
    assert_allclose(res.q_offline[:2000], traj.q[:2000], rtol=0, atol=atol)


@pytest.mark.slow
def test_harness_processes_end_with_their_parent(exported, tmp_path):
    """SIGKILL to the process running hil: both harness processes are gone within a second."""
    import os
    import signal
    import subprocess
    import sys
    import time

    _, folder, _ = exported
    script = (f"from rrr_pin.deploy.hil import hil; hil({str(folder)!r}, 1_000_000, "
              f"{str(tmp_path / 'k')!r}, rate=1000.0)")
    proc = subprocess.Popen([sys.executable, "-c", script], env={**os.environ})
    deadline = time.time() + 300
    pids = []
    while time.time() < deadline and len(pids) < 2:  # the build, then both processes
        time.sleep(0.5)
        out = subprocess.run(["pgrep", "-f", "rrr_pin_hil hil"], capture_output=True,
                             text=True).stdout.split()
        pids = [int(p) for p in out]
    assert len(pids) >= 2, "the harness did not start"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    time.sleep(1.0)
    alive = [p for p in pids if os.path.exists(f"/proc/{p}")
             and "Z" not in open(f"/proc/{p}/stat").read().split()[2]]
    assert not alive, f"harness processes {alive} outlived their parent"


def test_a_second_hil_of_the_model_reuses_its_build(exported, tmp_path):
    """The harness build is kept per model (build_cache): a second hil recompiles nothing."""
    import os
    import resource

    from rrr_pin.deploy.hil import build_cache

    ex, folder, _ = exported
    root = build_cache(ex.record["model"]["fingerprint"], ex.dynamics)
    assert (root / "build" / "rrr_pin_hil").is_file()  # the module's runs built it
    stamp = os.stat(root / "build" / "rrr_pin_hil").st_mtime_ns

    def cpu():
        return sum(getattr(resource.getrusage(who), f) for who in
                   (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
                   for f in ("ru_utime", "ru_stime"))

    before = cpu()
    hil(folder, 200, tmp_path / "again", rate=2000.0)
    # no compile: the executable is not relinked, and the call costs well under the 5 s of
    # CPU issue 47 allows (measured 1.5 s for a Panda with another law, load average 20)
    assert os.stat(root / "build" / "rrr_pin_hil").st_mtime_ns == stamp
    assert cpu() - before < 5.0


def test_actuator_and_friction_as_the_engines(exported, tmp_path, capsys):
    """An actuator of 200 rad/s and joint friction: hil's arm is rrr_pin.simulate's."""
    ex, folder, robot = exported
    fx = PlantEffects(actuator_bandwidth=200.0, viscous=(0.4, 0.3, 0.2), coulomb=0.5,
                      coulomb_velocity=0.05)
    res = hil(folder, 1000, tmp_path / "fx", rate=10_000.0, effects=fx)
    ref = default_reference(robot)
    r0, rd0, _ = ref(0.0)
    traj = simulate(robot, ex.law, ref, 1.0, q0=r0, qd0=rd0, engine="python", dt=1e-3,
                    effects=fx)
    # the same RK4 stages and effects, two dynamics implementations (generated C vs
    # Pinocchio's ABA): round-off, below 1e-9 rad over 1000 periods
    assert_allclose(res.q_offline[:1000], traj.q[:1000], rtol=0, atol=1e-9)
    assert res.run["effects"]["actuator_bandwidth_rad_s"] == 200.0
    assert main(["hil", str(folder), "--cycles", "10", "--rate", "2000", "--friction",
                 "viscous=1/2", "--out", str(tmp_path / "bad")]) == 2
    assert "--friction viscous=1/2: 2 values" in capsys.readouterr().err
    with pytest.raises(FieldError, match=r"noise_q: hil's simulated arm realizes the delay"):
        hil(folder, 10, tmp_path / "n", effects=PlantEffects(noise_q=1e-3))
