"""run_tasks: streaming, jobs validation, killed local workers, SIGTERM + resume, real Dask faults.

The task functions are module-level so that local processes and Dask workers can unpickle them.
"""

import itertools
import json
import multiprocessing
import os
import signal
import subprocess
import sys
import threading
import time
import weakref
from contextlib import closing
from pathlib import Path

import pytest

from rrr_pin.campaign.executors import (
    SchedulerUnreachable,
    WorkersLost,
    check_jobs,
    interrupt_on_signals,
    run_tasks,
)
from rrr_pin.campaign.store import PARTS, CampaignStore

TESTS = Path(__file__).parent


def square(k: int) -> int:
    return k * k


def slow_square(task) -> int:
    k, delay = task
    time.sleep(delay)
    return k * k


def square_or_die(task) -> int:
    """Kill this worker process (as the OOM killer would) on sample ``kill_at``."""
    k, kill_at = task
    if k == kill_at:
        os.kill(os.getpid(), signal.SIGKILL)
    time.sleep(0.02)
    return k * k


def square_or_raise(k: int) -> int:
    if k == 3:
        raise ZeroDivisionError("sample 3 divided by zero")
    return k * k


def marked_square(task) -> int:
    """Leave a file named after this worker's pid in ``folder``, then square slowly."""
    k, delay, folder = task
    Path(folder, str(os.getpid())).touch()
    time.sleep(delay)
    return k * k


def endless_pool(folder: str, method: str) -> None:
    """Run tasks on 2 local workers until killed (in a subprocess of the tests below)."""
    import rrr_pin.campaign.executors as ex

    if method == "fork-no-prctl":  # the portable watch alone: inherited by the forked workers
        ex._pdeathsig = lambda signum: False
    multiprocessing.set_start_method(method.split("-")[0])
    for _ in run_tasks(marked_square, ((k, 0.05, folder) for k in range(10**9)), jobs=2):
        pass


def alive(pids) -> list[int]:
    """The pids of ``pids`` still running (a zombie awaiting its reaper is dead)."""
    psutil = pytest.importorskip("psutil")
    out = []
    for pid in pids:
        try:
            if psutil.Process(pid).status() != psutil.STATUS_ZOMBIE:
                out.append(pid)
        except psutil.NoSuchProcess:
            pass
    return out


def no_children_left(timeout: float = 10.0) -> bool:
    """True once this process has no live child processes (pool workers all stopped)."""
    end = time.monotonic() + timeout
    while multiprocessing.active_children():
        if time.monotonic() > end:
            return False
        time.sleep(0.05)
    return True


# --- validation -----------------------------------------------------------------------------

@pytest.mark.parametrize("jobs", [0, -1], ids=["zero", "negative"])
def test_jobs_below_one_is_refused_at_the_call(jobs):
    with pytest.raises(ValueError, match=rf"jobs must be an integer >= 1 .*got {jobs}"):
        run_tasks(square, range(3), jobs=jobs)  # raises before any iteration


@pytest.mark.parametrize("jobs", [2.5, True, "2"], ids=["float", "bool", "str"])
def test_jobs_not_an_integer_is_refused(jobs):
    with pytest.raises(TypeError, match="jobs must be an integer >= 1"):
        check_jobs(jobs)


def test_other_arguments_are_checked():
    with pytest.raises(ValueError, match="max_in_flight must be an integer >= 1, got 0"):
        run_tasks(square, range(3), jobs=1, max_in_flight=0)
    with pytest.raises(ValueError, match="no_worker_timeout must be a finite number > 0"):
        run_tasks(square, range(3), scheduler="tcp://127.0.0.1:1",
                  no_worker_timeout=float("nan"))
    with pytest.raises(ValueError, match="retries must be an integer >= 0, got -1"):
        run_tasks(square, range(3), retries=-1)
    with pytest.raises(ValueError, match="either scheduler .* or executor"):
        run_tasks(square, range(3), scheduler="tcp://127.0.0.1:1", executor=object())


# --- local processes ------------------------------------------------------------------------

@pytest.mark.parametrize("jobs", [1, 2], ids=["in-process", "two-processes"])
def test_every_task_once_with_its_result(jobs):
    got = list(run_tasks(square, range(30), jobs=jobs))
    assert sorted(task for task, _ in got) == list(range(30))
    assert all(result == task * task for task, result in got)  # k^2 computed here


@pytest.mark.parametrize("jobs", [1, 2], ids=["in-process", "two-processes"])
def test_a_huge_lazy_task_stream_is_taken_as_needed(jobs):
    pulled = itertools.count()

    def tasks():  # 10**12 tasks: building them all would exhaust memory
        for k in range(10**12):
            next(pulled)
            yield k

    with closing(run_tasks(square, tasks(), jobs=jobs, max_in_flight=4)) as gen:
        first = list(itertools.islice(gen, 10))
    assert all(r == k * k for k, r in first)
    assert next(pulled) <= 10 + 4 + 1  # at most max_in_flight ahead of the 10 taken
    assert no_children_left()  # close() stopped the pool


def test_a_callers_executor_is_used_and_left_running():
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(2) as ex:
        got = dict(run_tasks(square, range(12), executor=ex, max_in_flight=3))
        assert ex.submit(square, 5).result() == 25  # still usable: not shut down
    assert got == {k: k * k for k in range(12)}


def test_an_exception_in_a_task_comes_back_unchanged():
    with pytest.raises(ZeroDivisionError, match="sample 3") as info:
        for _ in run_tasks(square_or_raise, range(10), jobs=2, max_in_flight=2):
            pass
    assert any("tasks had finished" in n for n in info.value.__notes__)
    assert no_children_left()


def test_a_killed_local_worker_stops_with_the_finished_count():
    got = []
    start = time.monotonic()
    with pytest.raises(WorkersLost, match="local worker process died") as info:
        for task, result in run_tasks(square_or_die, ((k, 6) for k in range(40)), jobs=2,
                                      max_in_flight=2):
            got.append((task[0], result))
    elapsed = time.monotonic() - start
    # with 2 in flight, task 6 is submitted only after 5 results were handed over
    assert info.value.done == len(got) >= 5
    assert all(r == k * k for k, r in got)
    assert 6 not in [k for k, _ in got]
    assert no_children_left()
    assert elapsed < 60  # liveness bound: the run must not hang


def test_sigterm_inside_interrupt_on_signals_raises_keyboardinterrupt_and_stops_workers():
    got = []
    timer = threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGTERM))
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(KeyboardInterrupt, match="SIGTERM"):
        with interrupt_on_signals():
            timer.start()
            for task, _ in run_tasks(slow_square, ((k, 0.2) for k in range(10**6)), jobs=2):
                got.append(task)
    timer.join()
    assert signal.getsignal(signal.SIGTERM) is before  # handler restored
    assert 0 < len(got) < 100
    assert no_children_left()


def test_an_interrupted_pool_is_stopped_with_its_manager_thread_joined():
    # Deterministic form of an intermittent exit message: an interrupted run left the pool's
    # manager thread closing its wake-up pipe while concurrent.futures' exit handler wrote to
    # it, "Exception ignored ... OSError: [Errno 9] Bad file descriptor" (3 of 9 Ctrl-C's).
    # No manager thread may outlive the stop.
    for _ in range(5):
        with pytest.raises(KeyboardInterrupt):
            with interrupt_on_signals():
                threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT)).start()
                for _ in run_tasks(slow_square, ((k, 0.2) for k in range(10**6)), jobs=2):
                    pass
        managers = [t for t in threading.enumerate()
                    if "ExecutorManagerThread" in type(t).__name__]
        assert managers == []
        assert no_children_left()


@pytest.mark.parametrize("method", ["fork", "fork-no-prctl", "spawn", "forkserver"])
def test_local_workers_die_with_a_killed_parent(tmp_path, method):
    # kill -9 of the main process: no handler runs there, so only the workers' own watch of
    # their parent (prctl on Linux, the multiprocessing sentinel) can stop them. forkserver:
    # the workers' parent is the server, which lives as long as they do (prctl cannot help).
    code = (f"import sys; sys.path.insert(0, {str(TESTS)!r}); import test_executors as t; "
            f"t.endless_pool({str(tmp_path)!r}, {method!r})")
    proc = subprocess.Popen([sys.executable, "-c", code])
    try:
        deadline = time.monotonic() + 60
        while len(list(tmp_path.iterdir())) < 2:  # both workers initialized and working
            assert time.monotonic() < deadline and proc.poll() is None, "pool did not start"
            time.sleep(0.05)
        workers = [int(p.name) for p in tmp_path.iterdir()]
        assert proc.pid not in workers and alive(workers) == workers
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        end = time.monotonic() + 10  # liveness bound; they go within ~0.1 s here
        while alive(workers) and time.monotonic() < end:
            time.sleep(0.05)
        assert alive(workers) == []
    finally:
        proc.kill()
        for pid in alive([int(p.name) for p in tmp_path.iterdir()]):
            os.kill(pid, signal.SIGKILL)


# --- a whole interrupted campaign (subprocess, SIGTERM) and its resume -----------------------

SETTINGS = {"seed": 7, "samples": 30}


def campaign_chunk(indices):
    """Rows of one chunk of the toy campaign (slow enough to be interrupted)."""
    from test_store import toy_row

    time.sleep(0.2)
    return [toy_row(SETTINGS["seed"], k) for k in indices]


def run_toy_campaign(out, resume=False, jobs=2) -> int:
    """What the CLI does: store opened first, rows appended per chunk, clean stop on signals."""
    from test_store import OUTPUTS, write_tables

    with CampaignStore.open(out, settings=SETTINGS, resume=resume, overwrite=False,
                            outputs=OUTPUTS) as store:
        todo = [k for k in range(SETTINGS["samples"]) if k not in store.done()]
        chunks = (todo[i:i + 2] for i in range(0, len(todo), 2))
        try:
            with interrupt_on_signals():
                for _, rows in run_tasks(campaign_chunk, chunks, jobs=jobs, max_in_flight=2):
                    store.append(rows)
        except KeyboardInterrupt as exc:
            print(f"interrupted ({exc}): {len(store.done())} of {SETTINGS['samples']} "
                  f"samples done, kept in {store.parts_path}; rerun with --resume")
            return 130
        write_tables(store)
    return 0


def test_sigterm_keeps_finished_samples_and_resume_is_byte_identical(tmp_path):
    from test_store import OUTPUTS

    out = tmp_path / "interrupted"
    code = (f"import sys; sys.path.insert(0, {str(TESTS)!r}); import test_executors as t; "
            f"sys.exit(t.run_toy_campaign({str(out)!r}))")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    parts = out / PARTS
    deadline = time.monotonic() + 60
    while not (parts.exists() and len(parts.read_bytes().splitlines()) >= 6):
        assert time.monotonic() < deadline and proc.poll() is None, "campaign did not start"
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    stdout, _ = proc.communicate(timeout=60)
    assert proc.returncode == 130, stdout
    kept = len(parts.read_bytes().splitlines())
    assert 6 <= kept < 30
    assert f"{kept} of 30 samples done" in stdout
    assert not any((out / n).exists() for n in OUTPUTS)  # no table from a partial run

    assert run_toy_campaign(out, resume=True) == 0
    ref = tmp_path / "straight"
    assert run_toy_campaign(ref, jobs=1) == 0
    for name in OUTPUTS:
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name
    rows = [json.loads(s) for s in parts.read_text().splitlines()]
    assert sorted(r["index"] for r in rows) == list(range(30))  # each sample exactly once


# --- Dask on loopback -----------------------------------------------------------------------

def test_unreachable_scheduler_fails_fast_and_clearly(monkeypatch):
    distributed = pytest.importorskip("distributed")
    clients = []
    init = distributed.Client.__init__

    def spy(self, *args, **kwargs):
        clients.append(weakref.ref(self))
        init(self, *args, **kwargs)

    monkeypatch.setattr(distributed.Client, "__init__", spy)
    start = time.monotonic()
    with pytest.raises(SchedulerUnreachable,
                       match=r"could not reach the Dask scheduler at '127.0.0.1:1' within 2 s"):
        next(run_tasks(square, range(3), scheduler="127.0.0.1:1", connect_timeout=2))
    assert time.monotonic() - start < 30  # liveness bound (2 s asked)
    # the half-built Client is gone: its __del__ cannot later stall another Dask loop
    assert clients and clients[0]() is None
    with pytest.raises(SchedulerUnreachable, match="nonsense:::"):
        next(run_tasks(square, range(3), scheduler="nonsense:::"))


@pytest.fixture
def cluster():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=":0") as c:
        yield c


def kill_workers(cluster, count):
    """SIGKILL ``count`` worker processes; their nannies are told not to restart them."""
    for nanny in list(cluster.workers.values())[:count]:
        nanny.close_gracefully()
        os.kill(nanny.pid, signal.SIGKILL)


def test_dask_worker_killed_mid_run_the_other_finishes(cluster):
    got = []
    for task, result in run_tasks(slow_square, ((k, 0.1) for k in range(20)),
                                  scheduler=cluster.scheduler_address, no_worker_timeout=20):
        got.append((task[0], result))
        if len(got) == 3:
            time.sleep(0.5)  # results finished on the victim die with it: recomputed
            kill_workers(cluster, 1)
    assert sorted(k for k, _ in got) == list(range(20))  # every task once, none lost
    assert all(r == k * k for k, r in got)


# This test caught a hang: a result finished on a worker that died before it was gathered
# made Future.result() wait forever; run_tasks now gathers with a timeout and keeps watching.
def test_dask_all_workers_killed_fails_within_the_timeout(cluster):
    got = []
    timeout = 4.0
    with pytest.raises(WorkersLost, match="no Dask worker left for 4 s") as info:
        for task, result in run_tasks(slow_square, ((k, 0.1) for k in range(50)),
                                      scheduler=cluster.scheduler_address,
                                      no_worker_timeout=timeout):
            got.append((task[0], result))
            if len(got) == 3:
                # let the tasks in flight finish, so their results die with the workers
                time.sleep(0.5)
                kill_workers(cluster, 2)
                killed = time.monotonic()
    waited = time.monotonic() - killed
    assert info.value.done == len(got) >= 3
    assert all(r == k * k for k, r in got)
    assert waited < 2 * timeout  # liveness bound: it gives up instead of hanging forever


def test_dask_scheduler_killed_mid_run_gives_workers_lost(tmp_path):
    # The scheduler in its own process, so that it can be killed as a crash would; one worker.
    # Both import this module (the scheduler unpickles the task graph): PYTHONPATH.
    pytest.importorskip("distributed")
    info = tmp_path / "scheduler.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS),
                                                        os.environ.get("PYTHONPATH", "")])}
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    scheduler = subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host",
                                  "127.0.0.1", "--port", "0", "--dashboard-address", ":0",
                                  "--scheduler-file", str(info)], env=env, **quiet)
    worker = None
    try:
        deadline = time.monotonic() + 60
        while not (info.exists() and info.stat().st_size):
            assert time.monotonic() < deadline, "the scheduler did not start"
            time.sleep(0.1)
        time.sleep(0.2)  # the file is written whole, but give its writer a moment
        address = json.loads(info.read_text())["address"]
        worker = subprocess.Popen([sys.executable, "-m", "dask", "worker", address,
                                   "--nthreads", "2", "--no-nanny", "--no-dashboard"],
                                  env=env, **quiet)
        got = []
        with pytest.raises(WorkersLost, match="the Dask scheduler was lost") as lost:
            for task, result in run_tasks(slow_square, ((k, 0.1) for k in range(10**6)),
                                          scheduler=address, connect_timeout=3,
                                          no_worker_timeout=60):
                got.append((task[0], result))
                if len(got) == 3:
                    os.kill(scheduler.pid, signal.SIGKILL)
                    killed = time.monotonic()
        # well before no_worker_timeout: the closed client is seen, not an empty cluster
        assert time.monotonic() - killed < 30
        assert lost.value.done == len(got) >= 3
        assert all(r == k * k for k, r in got)
    finally:
        for p in (scheduler, worker):
            if p is not None:
                p.kill()
                p.wait(10)
