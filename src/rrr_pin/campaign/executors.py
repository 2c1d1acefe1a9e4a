"""Run tasks on local processes or a Dask cluster, streamed, and fail clearly on faults.

:func:`run_tasks` takes tasks lazily from any iterable, keeps a bounded number in flight (so a
campaign of 10**12 samples never builds its task list) and yields ``(task, result)`` as each
finishes. The same call runs in this process (``jobs=1``), on ``jobs`` local processes
(:class:`concurrent.futures.ProcessPoolExecutor`), on a Dask distributed cluster
(``scheduler="tcp://host:8786"``) or on an executor the caller owns.

Behaviour on faults
-------------------
Results are handed to the caller as each task finishes, so whatever the caller stored before a
fault is kept; a fault only loses the tasks still running. A local worker process that dies
(killed, out of memory) breaks the pool: the results that had finished are still yielded, then
:class:`WorkersLost` is raised, carrying how many tasks finished. On Dask, the tasks of a worker
that dies are rerun on the remaining workers (by the scheduler, then up to ``retries`` more
times by :func:`run_tasks`); when no worker is left for ``no_worker_timeout`` seconds (60 s by
default), :class:`WorkersLost` is raised instead of waiting forever, and an unreachable
scheduler raises :class:`SchedulerUnreachable` after ``connect_timeout`` (10 s). Ctrl-C, or
SIGTERM inside :func:`interrupt_on_signals`, raises :class:`KeyboardInterrupt` in the caller,
and the pending tasks are cancelled and the local workers stopped without waiting for them.
A Dask scheduler lost in the middle of a run (killed, its host gone) raises
:class:`WorkersLost` too, with the count of the tasks that finished.
Rerun the campaign with ``--resume`` to compute only the samples that are missing.

Local workers die with their parent: each worker process asks the Linux kernel for ``SIGKILL``
when its parent dies (``prctl(PR_SET_PDEATHSIG)``), and watches the main process's
:mod:`multiprocessing` sentinel (a pipe that closes when it dies) from a thread, for the other
systems and the forkserver start method. So ``kill -9`` of the main process leaves no worker
computing, whatever the start method (fork, spawn, forkserver). Dask workers are not ours: they
belong to the cluster the caller gives (``scheduler=``, or a ``distributed.Client``); when
the main process dies, its client disconnects and the scheduler drops the client's tasks,
but the workers stay, as the cluster's owner started them.
"""

from __future__ import annotations

import gc
import itertools
import multiprocessing
import multiprocessing.connection
import operator
import os
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Executor, ProcessPoolExecutor
from concurrent.futures import wait as _cf_wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager

__all__ = [
    "run_tasks", "check_jobs", "default_jobs", "max_jobs", "available_memory",
    "interrupt_on_signals", "exit_status",
    "ExecutorError", "CampaignInterrupted", "WorkersLost", "SchedulerUnreachable",
    "SignalReceived",
]


class ExecutorError(RuntimeError):
    """Tasks could not be run to the end (base class)."""


class CampaignInterrupted(ExecutorError):
    """The run stopped before every task finished.

    Attributes
    ----------
    done : int
        Tasks whose results were yielded to the caller before the stop.
    signum : int or None
        The signal that stopped it (``signal.SIGINT``, ``signal.SIGTERM``), or ``None``.
    """

    def __init__(self, message: str, done: int, signum: int | None = None):
        super().__init__(message)
        self.done = done
        self.signum = signum


class SignalReceived(KeyboardInterrupt):
    """SIGINT or SIGTERM received inside :func:`interrupt_on_signals`.

    A :class:`KeyboardInterrupt`, so ``except KeyboardInterrupt`` handles both signals.

    Attributes
    ----------
    signum : int
        The signal received.
    """

    def __init__(self, signum: int):
        super().__init__(f"received {signal.Signals(signum).name}")
        self.signum = signum


def exit_status(exc: BaseException) -> int:
    """Exit status of a process stopped by ``exc``: 128 + the signal (130 SIGINT, 143 SIGTERM).

    A plain :class:`KeyboardInterrupt` (Ctrl-C under Python's own handler) counts as SIGINT.
    """
    signum = getattr(exc, "signum", None)
    return 128 + int(signal.SIGINT if signum is None else signum)


class WorkersLost(CampaignInterrupted):
    """Workers died: a broken local pool, or no Dask worker left for ``no_worker_timeout``."""


class SchedulerUnreachable(ExecutorError):
    """The Dask scheduler could not be reached (nothing was run)."""


def default_jobs() -> int:
    """Return the default number of local worker processes, ``min(2, CPUs)``."""
    return min(2, os.cpu_count() or 1)


def available_memory() -> int:
    """Return the memory this machine can still give [bytes] (``MemAvailable``; else physical)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 1 << 62


#: Local worker processes per CPU :func:`check_jobs` allows (more only queue for the CPUs).
JOBS_PER_CPU = 4
#: Resident memory one local worker needs at least [bytes] (the imports and a chunk).
WORKER_BYTES = 150 * 1024 * 1024


def max_jobs() -> int:
    """Return the most local worker processes this machine can run (at least 1).

    :data:`JOBS_PER_CPU` per CPU, and no more than the available memory holds at
    :data:`WORKER_BYTES` each.
    """
    return max(1, min(JOBS_PER_CPU * (os.cpu_count() or 1),
                      available_memory() // WORKER_BYTES))


def check_jobs(jobs) -> int:
    """Validate a number of local worker processes; ``None`` gives :func:`default_jobs`.

    Raises
    ------
    TypeError
        ``jobs`` is not an integer (e.g. ``2.5`` or ``True``).
    ValueError
        ``jobs < 1`` (``0``, ``-1``), or more than :func:`max_jobs` (the CPUs times
        :data:`JOBS_PER_CPU`, and what the free memory holds).
    """
    if jobs is None:
        return default_jobs()
    if isinstance(jobs, bool):
        raise TypeError(f"jobs must be an integer >= 1 (local worker processes), got {jobs!r}")
    try:
        n = operator.index(jobs)
    except TypeError:
        raise TypeError(f"jobs must be an integer >= 1 (local worker processes), "
                        f"got {jobs!r}") from None
    if n < 1:
        raise ValueError(f"jobs must be an integer >= 1 (local worker processes), got {n}")
    high = max_jobs()
    if n > high:
        raise ValueError(f"jobs = {n} local worker processes: this machine runs at most "
                         f"{high} ({JOBS_PER_CPU} per CPU of {os.cpu_count() or 1}, "
                         f"{WORKER_BYTES >> 20} MB each of "
                         f"{available_memory() / 1e9:.3g} GB available)")
    return n


def run_tasks(fn: Callable, tasks: Iterable, *, jobs: int | None = None,
              scheduler: str | None = None, executor=None, max_in_flight: int | None = None,
              no_worker_timeout: float = 60.0, retries: int = 2,
              connect_timeout: float = 10.0) -> Iterator[tuple]:
    """Run ``fn(task)`` for each task; yield ``(task, result)`` in completion order.

    Arguments are checked when called; the workers start (and a scheduler is contacted) at the
    first ``next()``. Close the generator (``contextlib.closing``, or let it go out of scope)
    to cancel what is still pending.

    Parameters
    ----------
    fn : callable
        ``fn(task) -> result``, picklable (a module-level function) unless ``jobs=1``.
    tasks : iterable
        Taken lazily, at most ``max_in_flight`` ahead of the finished ones.
    jobs : int, optional
        Local worker processes, >= 1 (default :func:`default_jobs`); 1 runs in this process.
        Ignored with ``scheduler`` or ``executor``.
    scheduler : str, optional
        Address of a Dask distributed scheduler (``"tcp://10.0.0.5:8786"``).
    executor : concurrent.futures.Executor or distributed.Client, optional
        Run there instead; it is not shut down. A ``distributed.Client`` gets the Dask
        fault handling (retries, no-worker timeout).
    max_in_flight : int, optional
        Tasks submitted but not yet yielded; default twice the workers (at least 4 on Dask).
    no_worker_timeout : float, default 60
        Dask only: seconds with no worker in the cluster before :class:`WorkersLost`.
    retries : int, default 2
        Dask only: resubmissions of a task lost with its workers (after the scheduler's own
        reruns, i.e. ``KilledWorker``), >= 0. An exception raised by ``fn`` is never retried.
    connect_timeout : float, default 10
        Dask only: seconds to reach the scheduler before :class:`SchedulerUnreachable`.

    Yields
    ------
    task, result
        Each task with ``fn(task)``, as they finish.

    Raises
    ------
    ValueError, TypeError
        Bad ``jobs`` (0, -1, 2.5), ``max_in_flight``, timeouts or ``retries``; both
        ``scheduler`` and ``executor``.
    WorkersLost
        A local worker process died, or no Dask worker was left for ``no_worker_timeout``;
        ``.done`` tasks were yielded before.
    SchedulerUnreachable
        ``scheduler`` could not be reached within ``connect_timeout``.
    KeyboardInterrupt
        Ctrl-C (or SIGTERM in :func:`interrupt_on_signals`); pending tasks are cancelled.
    Exception
        Whatever ``fn`` raised, unchanged, with a note saying how many tasks had finished.
    """
    if scheduler is not None and executor is not None:
        raise ValueError("give either scheduler (a Dask address) or executor, not both")
    if scheduler is not None and not isinstance(scheduler, str):
        raise TypeError(f"scheduler must be an address string such as "
                        f"'tcp://10.0.0.5:8786', got {scheduler!r}")
    from ..validation import check_count, check_positive  # numpy: not for the CLI's --help

    jobs = check_jobs(jobs)
    if max_in_flight is not None:
        max_in_flight = check_count("max_in_flight", max_in_flight, 1)
    no_worker_timeout = check_positive("no_worker_timeout", no_worker_timeout, unit="s")
    retries = check_count("retries", retries)
    connect_timeout = check_positive("connect_timeout", connect_timeout, unit="s")
    if scheduler is not None or _is_dask_client(executor):
        return _run_dask(fn, tasks, scheduler, executor, max_in_flight, no_worker_timeout,
                         retries, connect_timeout)
    if executor is not None:
        if not isinstance(executor, Executor):
            raise TypeError(f"executor must be a concurrent.futures.Executor or a "
                            f"distributed.Client, got {type(executor).__name__}")
        return _run_futures(fn, tasks, executor, max_in_flight or 8, own=False)
    if jobs == 1:
        return _run_serial(fn, tasks)
    return _run_futures(fn, tasks, None, max_in_flight or 2 * jobs, own=True, jobs=jobs)


@contextmanager
def interrupt_on_signals():
    """Within the block, SIGTERM (and SIGINT) raise :class:`SignalReceived` in this process.

    :class:`SignalReceived` is a :class:`KeyboardInterrupt` that carries the signal number.

    So ``kill <pid>`` from a batch system stops a campaign the way Ctrl-C does: the caller's
    ``except KeyboardInterrupt`` (or ``finally``) keeps what is finished and exits cleanly.
    SIGINT is included because a process started in the background of a non-interactive
    shell inherits SIGINT ignored. The previous handlers are restored on exit. Outside the
    main thread it does nothing (signals are only delivered there).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise SignalReceived(signum)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def _top_up(it: Iterator, room: int, submit: Callable) -> bool:
    """Submit up to ``room`` more tasks taken from ``it``; return whether ``it`` ran out."""
    if room <= 0:
        return False
    taken = 0
    for task in itertools.islice(it, room):
        submit(task)
        taken += 1
    return taken < room


# --- in this process ------------------------------------------------------------------------

def _run_serial(fn, tasks):
    done = 0
    for task in tasks:
        try:
            result = fn(task)
        except Exception as exc:
            exc.add_note(f"(raised by a task after {done} tasks had finished)")
            raise
        done += 1
        yield task, result


# --- concurrent.futures (local processes or a caller's executor) ----------------------------

_PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>


def _pdeathsig(signum: int) -> bool:
    """Ask Linux to send ``signum`` to this process when its parent dies; False elsewhere."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes  # here, in the worker: not at the import of every CLI command
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(signum), 0, 0, 0) == 0
    except (OSError, AttributeError):  # no libc or no prctl: use the sentinel
        return False


def _exit_with(sentinel) -> None:
    """Wait until ``sentinel`` (the parent's pipe) is ready, i.e. the parent died; then exit."""
    multiprocessing.connection.wait([sentinel])
    os._exit(1)


def _die_with_parent() -> None:
    """Make this worker process die when the process that started the pool dies.

    Two watches, as each covers a case the other misses. Linux: ``prctl(PR_SET_PDEATHSIG,
    SIGKILL)``, immediate on the death of the direct parent (the main process with the fork
    and spawn start methods; the parent may die before the call, hence the check after it).
    Everywhere: a daemon thread waits on the :mod:`multiprocessing` sentinel of the main
    process and exits this one. That covers other systems, and the forkserver start method,
    whose server (the direct parent) lives as long as any of its children does.
    """
    parent = multiprocessing.parent_process()
    if parent is None:  # not a multiprocessing child: nothing to watch
        return
    if _pdeathsig(signal.SIGKILL):
        if os.getppid() != parent.pid and not _pid_exists(parent.pid):
            os._exit(1)  # the parent died before prctl took effect
    threading.Thread(target=_exit_with, args=(parent.sentinel,), daemon=True,
                     name="rrr-pin-parent-watch").start()


def _pid_exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def _worker_init() -> None:
    """Local workers die with the main process and leave Ctrl-C to it (it stops them itself)."""
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _stop_pool(pool: ProcessPoolExecutor, kill: bool) -> None:
    """Shut the pool down; with ``kill``, terminate the workers instead of waiting for them."""
    if not kill:
        pool.shutdown(wait=True)
        return
    # Python < 3.14 has no public terminate: the running tasks' results are unwanted.
    processes = list((getattr(pool, "_processes", None) or {}).values())
    # shutdown(wait=False) forgets the pool's manager thread without joining it, and a second
    # shutdown(wait=True) then has nothing to join: the thread, still closing its wake-up pipe,
    # raced concurrent.futures' exit handler writing to it ("Exception ignored ... OSError:
    # [Errno 9] Bad file descriptor", 3 of 9 interrupted runs). Join it here.
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        if p.is_alive():
            p.terminate()
    for p in processes:
        p.join(5.0)
    if manager is not None:
        manager.join(5.0)
    pool.shutdown(wait=True)


def _run_futures(fn, tasks, executor, limit: int, *, own: bool, jobs: int = 0):
    pool = ProcessPoolExecutor(max_workers=jobs, initializer=_worker_init) if own else executor
    it = iter(tasks)
    pending: dict = {}
    done, exhausted, clean = 0, False, False

    def submit(task):
        try:
            pending[pool.submit(fn, task)] = task
        except BrokenProcessPool as exc:
            raise _broken(done, exc) from exc

    try:
        while True:
            exhausted = exhausted or _top_up(it, limit - len(pending), submit)
            if not pending:
                break
            finished, _ = _cf_wait(list(pending), return_when=FIRST_COMPLETED)
            broken, error = None, None
            if any(not f.cancelled() and isinstance(f.exception(), BrokenProcessPool)
                   for f in finished):
                # the pool is dead: hand over every result that did finish, then stop
                finished = [f for f in pending if f.done()]
            for f in finished:
                task = pending.pop(f)
                exc = None if f.cancelled() else f.exception()
                if f.cancelled() or isinstance(exc, BrokenProcessPool):
                    broken = broken or exc or BrokenProcessPool("task cancelled")
                elif exc is not None:
                    error = error or exc
                else:
                    done += 1
                    yield task, f.result()
            if broken is not None:
                raise _broken(done, broken) from broken
            if error is not None:
                error.add_note(f"(raised by a task after {done} tasks had finished)")
                raise error
        clean = True
    finally:
        for f in pending:
            f.cancel()
        if own:
            _stop_pool(pool, kill=not clean)


def _broken(done: int, exc) -> WorkersLost:
    return WorkersLost(f"a local worker process died (killed, or out of memory) after {done} "
                       f"tasks had finished; the pool cannot go on ({exc})", done)


# --- Dask distributed -----------------------------------------------------------------------

def _is_dask_client(obj) -> bool:
    if obj is None:
        return False
    try:
        from distributed import Client
    except ImportError:
        return False
    return isinstance(obj, Client)


def _n_workers(client, timeout: float) -> tuple[int, int]:
    """Return (workers, threads) the scheduler knows now; (0, 0) if it cannot be asked."""
    if client.status != "running":  # reconnecting to a lost scheduler, or closed
        return 0, 0
    try:
        nthreads = client.nthreads(callback_timeout=timeout)
    except Exception:  # lost scheduler: counts as no worker
        return 0, 0
    return len(nthreads), sum(nthreads.values())


def _connect(scheduler: str, connect_timeout: float):
    try:
        from distributed import Client
    except ImportError as exc:
        raise SchedulerUnreachable("a Dask scheduler needs the 'distributed' package "
                                   "(pip install distributed)") from exc
    try:
        return Client(scheduler, timeout=connect_timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        reason = str(exc)
        exc.__traceback__ = None  # its frames hold the half-built Client
    # Free the half-built Client now: collected later, its __del__ can run inside another
    # Dask event-loop start (a LocalCluster's) and deadlock there.
    gc.collect()
    raise SchedulerUnreachable(
        f"could not reach the Dask scheduler at {scheduler!r} within {connect_timeout:g} s "
        f"({reason}); check the address and that `dask scheduler` runs there")


def _run_dask(fn, tasks, scheduler, client, limit, no_worker_timeout, retries,
              connect_timeout):
    from concurrent.futures import CancelledError

    from distributed import KilledWorker
    from distributed.client import ClosedClientError
    from distributed.comm.core import CommClosedError

    own = client is None
    if own:
        client = _connect(scheduler, connect_timeout)
    it = iter(tasks)
    pending: dict = {}  # future -> (task, resubmissions so far)
    ready: queue.SimpleQueue = queue.SimpleQueue()  # futures done, fed by their callbacks
    collect: set = set()  # done futures whose result is not yet in hand
    poll = min(1.0, no_worker_timeout / 4)
    state = {"done": 0, "checked": time.monotonic(), "last_worker": time.monotonic()}
    state["workers"], state["threads"] = _n_workers(client, poll)

    def submit(task, attempts):
        try:
            f = client.submit(fn, task, pure=False)
        except (ClosedClientError, CommClosedError) as exc:
            raise scheduler_lost(f"{type(exc).__name__}: {exc}") from None
        pending[f] = (task, attempts)
        f.add_done_callback(ready.put)

    def scheduler_lost(reason: str) -> WorkersLost:
        return WorkersLost(f"the Dask scheduler was lost (killed, or its host is gone: "
                           f"{reason}); stopped after {state['done']} tasks had finished",
                           state["done"])

    def watchdog():
        """Raise WorkersLost once the cluster had no worker for no_worker_timeout."""
        if client.status == "closed":  # it gave up reconnecting to a lost scheduler
            raise scheduler_lost("the client lost its connection and closed")
        now = time.monotonic()
        if now - state["checked"] >= poll:
            state["workers"], state["threads"] = _n_workers(client, poll)
            state["checked"] = now
        if state["workers"]:
            state["last_worker"] = now
        elif now - state["last_worker"] > no_worker_timeout:
            raise WorkersLost(f"no Dask worker left for {no_worker_timeout:g} s (all died or "
                              f"the scheduler is gone); stopped after {state['done']} tasks "
                              "had finished", state["done"])

    def lost(f, reason):
        """Resubmit the task of a future lost with its workers, up to ``retries`` times."""
        task, attempts = pending.pop(f)
        collect.discard(f)
        if attempts >= retries:
            raise WorkersLost(f"a task was lost with its Dask workers {attempts + 1} times; "
                              f"giving up after {state['done']} tasks had finished "
                              f"({reason})", state["done"])
        submit(task, attempts + 1)

    exhausted = False
    try:
        while True:
            cap = limit or max(4, 2 * state["threads"])
            exhausted = exhausted or _top_up(it, cap - len(pending), lambda t: submit(t, 0))
            if not pending:
                break
            try:  # block only when nothing already known is ready
                if not any(f.done() for f in collect):
                    collect.add(ready.get(timeout=poll))
                while True:
                    collect.add(ready.get_nowait())
            except queue.Empty:
                pass
            for f in list(collect):
                if f not in pending:  # a callback of a future already handled
                    collect.discard(f)
                    continue
                if f.status == "error":
                    exc = f.exception()
                    if not isinstance(exc, KilledWorker):
                        exc.add_note(f"(raised by a task after {state['done']} tasks had "
                                     "finished)")
                        raise exc
                    lost(f, exc)
                elif f.cancelled():
                    lost(f, "cancelled")
                elif f.status == "finished":
                    try:  # the data may have died with its worker: never block on it
                        result = f.result(timeout=poll)
                    except TimeoutError:
                        watchdog()
                        continue
                    except (KilledWorker, CancelledError) as exc:
                        lost(f, exc)
                        continue
                    except (ClosedClientError, CommClosedError) as exc:
                        raise scheduler_lost(f"{type(exc).__name__}: {exc}") from None
                    task, _ = pending.pop(f)
                    collect.discard(f)
                    state["done"] += 1
                    yield task, result
            watchdog()
    finally:
        if pending:
            try:
                client.cancel(list(pending), force=True)
            except Exception:  # the scheduler may be gone already
                pass
        if own:
            try:
                client.close(timeout=min(10.0, connect_timeout))
            except Exception:
                pass
