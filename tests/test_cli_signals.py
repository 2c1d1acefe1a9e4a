"""SIGINT and SIGTERM stop every command with one line, exit 130/143, and no worker left.

Each test runs the real console entry point in a subprocess and signals it, as a user's Ctrl-C
or a batch system's ``kill`` would.
"""

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

psutil = pytest.importorskip("psutil")

CLI = [sys.executable, "-m", "rrr_pin.cli"]


def handles_sigterm(pid: int) -> bool:
    """True once process ``pid`` catches SIGTERM (Linux: the SigCgt mask of /proc/pid/status).

    Python itself catches only SIGINT, so a caught SIGTERM means ``main`` installed its
    handlers: a signal sent from then on reaches them.
    """
    status = Path(f"/proc/{pid}/status")
    if not status.exists():
        pytest.skip("needs Linux /proc to know when the handlers are installed")
    for line in status.read_text().splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    return False


def start(argv, tmp_path):
    """Start ``rrr-pin argv``; return the process and the file that collects its stderr."""
    err = open(tmp_path / "stderr.txt", "w+")  # a file: a pipe would block on surviving workers
    proc = subprocess.Popen(CLI + argv, stdout=subprocess.DEVNULL, stderr=err, text=True)
    return proc, err


def stop(proc, err, sig) -> tuple[int, list[str]]:
    """Send ``sig``; return the exit status and the lines of standard error."""
    proc.send_signal(sig)
    try:
        code = proc.wait(60)  # liveness bound: it must stop, not hang
    finally:
        proc.kill()
    err.seek(0)
    return code, err.read().splitlines()


def alive(procs) -> list:
    """The processes of ``procs`` still running (a zombie awaiting its reaper is dead)."""
    out = []
    for p in procs:
        try:
            if p.status() != psutil.STATUS_ZOMBIE:
                out.append(p)
        except psutil.NoSuchProcess:
            pass
    return out


def none_left(workers, timeout: float = 10.0) -> bool:
    """True if every worker is gone within ``timeout`` s; kills the survivors either way."""
    end = time.monotonic() + timeout
    while alive(workers) and time.monotonic() < end:
        time.sleep(0.05)
    survivors = alive(workers)
    for p in survivors:
        p.kill()
    return not survivors


def test_help_loads_no_numerical_library():
    # main() installs its signal handlers before parsing: that must not import numpy
    code = ("import sys, rrr_pin.cli as c\ntry:\n    c.main(['--help'])\nexcept SystemExit:\n"
            "    pass\nprint(sorted(m for m in ('pinocchio', 'control', 'numpy') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip().splitlines()[-1]
    assert out == "[]"


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_command_without_workers_stops_with_one_line(tmp_path, sig):
    # check-dynamics: a long loop in this process (10**6 states), no handler of its own
    proc, err = start(["check-dynamics", "--samples", "1000000"], tmp_path)
    deadline = time.monotonic() + 60
    while not handles_sigterm(proc.pid):
        assert time.monotonic() < deadline and proc.poll() is None, "did not start"
        time.sleep(0.02)
    time.sleep(0.5)
    code, lines = stop(proc, err, sig)
    assert code == 128 + sig  # 130 or 143, as a shell reports a signal
    assert lines == [f"rrr-pin check-dynamics: interrupted (received {sig.name})"]


def _wait_for_workers(proc, count, what, timeout=120):
    me = psutil.Process(proc.pid)
    deadline = time.monotonic() + timeout
    while len(me.children()) < count or not handles_sigterm(proc.pid):
        assert time.monotonic() < deadline and proc.poll() is None, f"{what} did not start"
        time.sleep(0.05)
    return me.children()


def test_montecarlo_sigterm_in_process_exits_143_with_the_count(tmp_path, capsys):
    # In this process (no start-up cost): a real SIGTERM lands while the samples run.
    from rrr_pin import cli

    parts, stop_watching = tmp_path / "mc" / "parts.jsonl", threading.Event()

    def kill_once_rows_are_stored():
        while not stop_watching.wait(0.02):
            if parts.exists() and parts.read_bytes().count(b"\n") >= 1:
                os.kill(os.getpid(), signal.SIGTERM)
                return

    watcher = threading.Thread(target=kill_once_rows_are_stored)
    watcher.start()
    try:
        code = cli.main(["montecarlo", "--samples", "40", "--duration", "0.2", "--jobs",
                         "1", "--controllers", "fl", "--out",
                         str(tmp_path / "mc"), "--no-progress"])
    finally:
        stop_watching.set()
        watcher.join()
    lines = capsys.readouterr().err.splitlines()
    assert code == 143
    assert len(lines) == 1 and lines[0].startswith(
        "rrr-pin montecarlo: campaign interrupted (received SIGTERM): "), lines
    assert "of 41 samples done" in lines[0] and "--resume" in lines[0]


@pytest.mark.slow
def test_montecarlo_sigterm_exits_143_and_stops_its_workers(tmp_path):
    out = tmp_path / "mc"
    proc, err = start(["montecarlo", "--samples", "40", "--duration", "0.5", "--jobs", "2",
                       "--controllers", "fl",
                       "--engine", "python", "--out", str(out), "--no-progress"], tmp_path)
    workers = _wait_for_workers(proc, 2, "the campaign")
    code, lines = stop(proc, err, signal.SIGTERM)
    assert code == 143
    assert len(lines) == 1 and "campaign interrupted (received SIGTERM)" in lines[0], lines
    assert "samples done" in lines[0] and "--resume" in lines[0]
    assert none_left(workers)


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_reproduce_stops_with_one_line_and_no_worker_left(tmp_path, sig):
    # Before: SIGINT printed a KeyboardInterrupt traceback; SIGTERM killed the main process
    # silently and left its 2 pool workers running.
    out = tmp_path / "results"
    proc, err = start(["reproduce", "--samples", "6", "--duration", "2", "--jobs", "2",
                       "--no-certify", "--engine", "python", "--out", str(out),
                       "--no-progress"], tmp_path)
    workers = _wait_for_workers(proc, 2, "the study", timeout=300)
    code, lines = stop(proc, err, sig)
    assert code == 128 + sig
    assert lines == [f"rrr-pin reproduce: interrupted (received {sig.name}); {out} may hold "
                     "files of this unfinished run"]
    assert none_left(workers)


def test_a_closed_stdout_stops_quietly():
    # `rrr-pin ... | head -1`: the reader goes away; before, the CLI said "cannot write the
    # outputs: Broken pipe (EPIPE) ... free space", a disk-full message for a closed pipe.
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "rrr_pin.cli", "check-dynamics", "--samples",
                             "2000"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # nobody reads: the first print meets EPIPE
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141
    assert "Broken pipe" not in err and "Traceback" not in err


def test_a_refused_reproduce_prints_one_line_and_writes_nothing(tmp_path, capsys):
    # Before: the design figures (fig2-fig4b, margins.png) and two progress-bar lines came
    # before the refusal, and an --overwrite had already removed the previous run.
    from rrr_pin import cli

    out = tmp_path / "results"
    assert cli.main(["reproduce", "--samples", "1", "--duration", "0.2", "--no-certify",
                     "--out", str(out), "--no-progress"]) == 0  # the previous run
    capsys.readouterr()
    keep = sorted(p.name for p in out.iterdir())
    for _ in range(3):  # the worker traceback was 1 in 15: the refusal happens before any pool
        code = cli.main(["reproduce", "--actuator-bandwidth", "1e9", "--rate", "1000",
                         "--out", str(out), "--overwrite"])
        lines = capsys.readouterr().err.splitlines()
        assert code == 2
        assert lines == ["rrr-pin reproduce: error: actuator_bandwidth = 1e+09 rad/s is too fast "
                         "for the plant sub-step h = 0.001 s (RK4 needs wa h < 2.5): lower dt"]
        assert sorted(p.name for p in out.iterdir()) == keep
