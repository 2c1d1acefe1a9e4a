"""Monte Carlo robustness campaigns: thousands of seeded uncertain plants, any set of laws.

Each sample ``k`` of a campaign with seed ``s`` is the plant the nominal draws,
``nominal.perturbed(default_rng([s, k]), settings.tolerances)``
(:meth:`rrr_pin.model.plant.Plant.perturbed`: a serial arm's URDF or DH parameters, a closed
chain's mechanism parameters); it is generated, simulated under every law
(:func:`rrr_pin.campaign.runner.run_laws`) and reduced to figures inside the worker, so only a
row of numbers travels back. The nominal plant runs too, as the row of index -1
(:attr:`Campaign.nominal`, in ``summary.json``). Rows are put in sample order, so the results
are identical whatever the number of workers or where they run.

Workers: ``jobs`` local processes (:class:`concurrent.futures.ProcessPoolExecutor`) or a Dask
distributed cluster (``scheduler="tcp://host:8786"``, through ``Client.get_executor()``, which
is a ``concurrent.futures.Executor`` too): one code path, two executors.

A sample where a law's run ends (a divergence, or a plant's own failure such as a closed chain's
type-II singularity) is recorded with its status and parameters, with the figures of the laws
that ran; the campaign goes on. A plant that records more per run (a closed chain's loop drift)
adds ``<law>_drift`` [m] to its rows (:attr:`Campaign.per_law`).
"""

from __future__ import annotations

import itertools
import logging
import math
import pickle
import signal
import threading
import uuid
from concurrent.futures import Executor
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from ..control.references import Reference, study_reference
from ..sim.batched import BATCH_MAX, MAX_THREADS, thread_pool, warm
from ..sim.engine_names import AUTO, CODEGEN
from ..sim.simulation import reuse_preparation
from ..validation import check_count
from .coverage import certificate_loop
from .executors import CampaignInterrupted, check_jobs, interrupt_on_signals, run_tasks
from .runner import (
    RunSettings,
    check_laws,
    check_runs,
    error_ratios,
    failure_text,
    run_laws,
    run_laws_batch,
    run_metrics,
)
from .settings import Settings
from .store import CampaignStore

if TYPE_CHECKING:
    from ..robust.certificates import CertificateSpec

__all__ = ["Campaign", "CampaignSettings", "CampaignJob", "CampaignChunk", "NOMINAL_INDEX",
           "check_campaign", "run_campaign",
           "run_chunk", "run_samples", "sample_row", "campaign_summary", "campaign_columns",
           "open_store", "store_settings", "OUTPUTS"]

logger = logging.getLogger(__name__)

#: Final files of a campaign, rebuilt from the stored rows at the end of every run.
OUTPUTS = ("campaign.csv", "samples.jsonl", "summary.json", "montecarlo.png", "report.html",
           "certificates.png")


@dataclass(frozen=True)
class CampaignSettings(Settings):
    """What a campaign computes: :class:`~rrr_pin.campaign.settings.Settings` with its defaults.

    Recorded whole in ``summary.json`` and in the store's manifest (a resume must match it).

    Parameters
    ----------
    samples : int
        Number of plants, >= 1.
    seed, baseline
        As in :class:`~rrr_pin.campaign.settings.Settings`.
    tolerances : UncertaintySet
        As in :class:`~rrr_pin.campaign.settings.Settings`: any set the plant accepts.
    run : RunSettings
        How each run is simulated (default: 10 s, 1 kHz sampled laws).
    """

    MIN_SAMPLES: ClassVar[int] = 1

    run: RunSettings = field(default_factory=lambda: RunSettings(duration=10.0, rate=1000.0))


#: Index of the nominal plant's row (kept out of :attr:`Campaign.rows`).
NOMINAL_INDEX = -1


@dataclass(frozen=True)
class CampaignJob:
    """What every sample of a campaign shares, sent to the workers with each chunk.

    Attributes
    ----------
    settings : Settings
    laws : tuple of ControlLaw or SampledLaw
    reference : Reference
    nominal : Plant
        The nominal plant the samples are drawn around (its row is index -1), and the
        certificate's model.
    certificate : CertificateSpec or None
    batch : int
        Plants per batched rollout (:func:`rrr_pin.campaign.runner.run_laws_batch`); changes
        no number, so it is not recorded.
    threads : int
        Threads of the batched engine in each worker (a batch per thread); changes no number,
        so it is not recorded.

    A job travels with each of its chunks, but a worker process unpickles it once: it is sent
    as bytes under a token made at construction (a ``replace``-d job gets its own), and a
    process that holds the job of that token already uses it (:func:`_arrived`). So the
    preparation its laws and reference share (a law's sampled form, the reference sampled on
    the grid: :func:`rrr_pin.sim.reuse.reuse_preparation`) is made once per process, not
    once per chunk.
    """

    settings: Settings
    laws: tuple
    reference: Reference
    nominal: object
    certificate: CertificateSpec | None = None
    batch: int = 16
    threads: int = 1

    def __post_init__(self) -> None:
        self.__dict__["_token"] = uuid.uuid4().hex

    def __reduce__(self):
        state = {f.name: getattr(self, f.name) for f in fields(self)}
        return _arrived, (self.__dict__["_token"], pickle.dumps(state, pickle.HIGHEST_PROTOCOL))

    def _kept(self) -> dict:
        """Return the preparation this job's laws and reference share, kept across chunks."""
        return self.__dict__.setdefault("_prepared", {})

    def rows(self, indices) -> list[dict]:
        """Simulate samples ``indices``, in order, and return their rows (:func:`run_chunk`).

        The plants run together, ``batch`` per batched rollout where the engine allows
        (:func:`rrr_pin.campaign.runner.run_laws_batch`); each row is made from its own
        plant's values only, so rows do not depend on the chunk or the batch.
        """
        # One reference and one set of laws for every sample: the reference is sampled and the
        # laws discretized once per job in this process (kept across its chunks; bit-identical
        # to doing it per run).
        indices = tuple(indices)
        with reuse_preparation(keep=self._kept()):
            if self.threads == 1:
                made = [_sample(self, k) for k in indices]
                runs = run_laws_batch([plant for _, plant in made], self.laws, self.reference,
                                      self.settings.run, batch=self.batch, figures=True)
            else:
                # Threads: each batch of plants runs on the pool (its C++ loop without the
                # GIL) while this thread draws the next batch's plants.
                made, futures = [], []
                pool = thread_pool(self.threads)
                for s in range(0, len(indices), self.batch):
                    group = [_sample(self, k) for k in indices[s:s + self.batch]]
                    made += group
                    futures.append(pool.submit(
                        run_laws_batch, [plant for _, plant in group], self.laws,
                        self.reference, self.settings.run, batch=self.batch, figures=True))
                runs = [r for f in futures for r in f.result()]
            return [_row(self, k, parameters, plant, r)
                    for k, (parameters, plant), r in zip(indices, made, runs, strict=True)]


#: The jobs this process received last, by token (:meth:`CampaignJob.__reduce__`).
_ARRIVED: dict = {}
_ARRIVED_MAX = 4
_ARRIVED_LOCK = threading.Lock()


def _arrived(token: str, payload: bytes) -> CampaignJob:
    """Return the job of ``token``: the one this process holds, or ``payload`` unpickled."""
    with _ARRIVED_LOCK:  # a Dask worker's threads unpickle tasks at once
        job = _ARRIVED.get(token)
        if job is None:
            job = CampaignJob(**pickle.loads(payload))
            job.__dict__["_token"] = token
            while len(_ARRIVED) >= _ARRIVED_MAX:
                _ARRIVED.pop(next(iter(_ARRIVED)))
            _ARRIVED[token] = job
        return job


@dataclass(frozen=True)
class CampaignChunk:
    """Samples ``indices`` of campaign ``job``: one task of a worker (:func:`run_chunk`).

    ``job`` is a :class:`CampaignJob` or any picklable object with ``rows(indices) -> list
    of dict``.
    """

    job: CampaignJob
    indices: tuple


@dataclass
class Campaign:
    """Rows of a campaign, one per sample, in sample order.

    Attributes
    ----------
    robot : str
    joint_names : list of str
    laws : list of dict
        Each law's description (``name``, ``label``, ...), in order.
    rows : list of dict
        ``index``, ``seed``, ``status`` (``"ok"``, or which laws diverged and why),
        ``parameters`` and, per law that ran, ``<law>_engine`` (the engine that ran it:
        ``"codegen"``, ``"compiled"`` or ``"python"``), ``<law>_rms_error``,
        ``<law>_max_error`` [rad], ``<law>_rms_torque`` [N m], ``<law>_rms_error_<joint>``
        [rad]; per law other than the baseline, ``error_ratio_<law>`` and ``torque_ratio_<law>``
        (:func:`rrr_pin.campaign.runner.error_ratios`); a ratio that is undefined (0/0) is
        left out and ``undefined`` says which and why.
    settings : dict
        :meth:`CampaignSettings.to_dict` plus the reference.
    nominal : dict or None
        The nominal plant's row (same keys, ``index`` -1; None if a store from before held
        none).
    per_law : tuple of str
        Further per-law keys of the rows, ``<law>_<key>`` (``engine``; a closed chain's
        ``drift`` [m], the largest loop gap of the run); written to ``campaign.csv``.
    joint_dynamics : dict or None
        The nominal plant's armature, damping and friction and their source
        (:meth:`rrr_pin.model.plant.Plant.joint_dynamics`); each drawn arm's are in its row's
        ``parameters["joint_dynamics"]``.
    """

    robot: str
    joint_names: list
    laws: list
    rows: list
    settings: dict = field(default_factory=dict)
    nominal: dict | None = None
    per_law: tuple = ()
    joint_dynamics: dict | None = None

    @property
    def names(self) -> list[str]:
        """Law names, in order."""
        return [d["name"] for d in self.laws]

    @property
    def baseline(self) -> str:
        """Name of the baseline law."""
        return self.settings["baseline"]

    def summary(self) -> dict:
        """Median, 95th percentile and worst of each metric: :func:`campaign_summary` (self)."""
        return campaign_summary(self)

    def _repr_html_(self) -> str:
        """Summary table for notebooks: per law, median and worst RMS error and status."""
        import html

        s = self.summary()
        run = self.settings
        rate = (f"{run['rate_hz']:g} Hz (sampled laws)" if run.get("rate_hz")
                else "continuous-time laws")
        head = (f"<caption>Monte Carlo campaign on {html.escape(self.robot)}: "
                f"{run['duration_s']:g} s, {rate}, {s['samples']} plants, baseline "
                f"{html.escape(self.baseline)}</caption><tr><th>law</th>"
                "<th>median RMS error [rad]</th><th>95th percentile RMS error [rad]</th>"
                "<th>worst RMS error [rad]</th><th>status</th></tr>")
        rows = []
        for d in self.laws:
            m = s.get(f"{d['name']}_rms_error")
            cells = ("".join(f"<td>{m[k]:.4g}</td>" for k in ("median", "p95", "worst"))
                     if m else "<td>-</td>" * 3)
            ran = m["count"] if m else 0
            rows.append(f"<tr><td>{html.escape(d['label'])} (<code>{html.escape(d['name'])}"
                        f"</code>)</td>{cells}<td>ran on {ran} of {s['samples']} plants"
                        f"</td></tr>")
        return f"<table>{head}{''.join(rows)}</table>"


def sample_row(job: CampaignJob, k: int) -> dict:
    """Generate sample ``k`` (-1: the nominal), run every law on it and reduce it to one row."""
    parameters, plant = _sample(job, k)
    return _row(job, k, parameters, plant, run_laws(plant, job.laws, job.reference,
                                                    job.settings.run))


def _sample(job: CampaignJob, k: int):
    """Sample ``k``'s parameters record and plant (-1: the nominal plant, ``{}``)."""
    if k == NOMINAL_INDEX:
        return {}, job.nominal
    plant, parameters = job.nominal.perturbed(
        np.random.default_rng([int(job.settings.seed), int(k)]), job.settings.tolerances,
        name=f"sample{k:05d}")
    return parameters, plant


def _row(job: CampaignJob, k: int, parameters, plant, runs: dict) -> dict:
    """Reduce sample ``k``'s runs (by law name) to its row, from its own values only."""
    settings = job.settings
    seed = None if k == NOMINAL_INDEX else [int(settings.seed), int(k)]
    row = {"index": k, "seed": seed, "status": "ok", "parameters": parameters}
    bad = [f"{name}: {failure_text(v)}" for name, v in runs.items() if isinstance(v, Exception)]
    if bad:
        row["status"] = "diverged: " + "; ".join(bad)
    joints = job.nominal.joint_names
    figures = {name: run_metrics(t, joints) for name, t in runs.items()
               if not isinstance(t, Exception)}
    for name, m in figures.items():
        row.update({f"{name}_{key}": v for key, v in m.items()})
    for name, t in runs.items():  # the engine that ran it, not the one asked for ("auto")
        engine = getattr(t, "info", {}).get("engine")
        if engine is not None:
            row[f"{name}_engine"] = engine
    undefined = []
    for name, r in error_ratios(figures, settings.baseline).items():
        for key in ("error_ratio", "torque_ratio"):
            if r[key] is not None:  # an undefined ratio is left out, its reason stated
                row[f"{key}_{name}"] = r[key]
        undefined += r.get("undefined", [])
    if undefined:
        row["undefined"] = "; ".join(undefined)
    if job.certificate is not None and k != NOMINAL_INDEX:
        from .coverage import certify_run

        cert = certify_run(job.certificate, job.nominal, plant, job.reference, settings.run)
        row["certified"], row["nugap_max"] = cert["certified"], cert["nugap_max"]
    return row


def run_chunk(task: CampaignChunk) -> list[dict]:
    """Simulate the samples of one chunk, in order (runs in a worker): ``job.rows(indices)``."""
    return task.job.rows(task.indices)


def check_campaign(nominal, laws, settings: CampaignSettings, *,
                   reference: Reference | None = None) -> tuple[list, Reference]:
    """Every refusal of :func:`run_campaign` that needs no run, before any work; its inputs.

    A caller that opens a store first (``rrr-pin montecarlo``) calls this before it, so that a
    refused campaign leaves no ``campaign.json`` or empty ``parts.jsonl`` behind.

    Returns
    -------
    (list, Reference)
        The checked laws and the reference (the plant's study reference if ``None``).

    Raises
    ------
    TypeError, ValueError
        The laws, the reference on the plant, a run setting or engine that cannot run a law on
        it (:func:`rrr_pin.campaign.runner.check_runs`), an uncertainty set the plant does not
        accept (sample 0 is drawn).
    """
    laws = check_laws(laws, nominal.nq, settings.baseline)
    reference = (study_reference(nominal, settings.run.duration) if reference is None
                 else reference)
    reference.check_limits(nominal, duration=settings.run.duration)
    check_runs(nominal, laws, reference, settings.run)
    # the uncertainty set, refused up front if the plant does not take it (draws sample 0)
    nominal.perturbed(np.random.default_rng([int(settings.seed), 0]), settings.tolerances)
    return laws, reference


def run_campaign(nominal, laws, settings: CampaignSettings, *,
                 reference: Reference | None = None, jobs: int | None = None,
                 scheduler: str | None = None, executor: Executor | None = None,
                 chunk: int | None = None, progress=None, store: CampaignStore | None = None,
                 certificate=None, batch: int = 16, threads: int = 1) -> Campaign:
    """Run every law on the nominal plant and ``settings.samples`` seeded uncertain plants.

    Parameters
    ----------
    nominal : Plant
        Nominal plant, a serial arm or a closed chain (the samples are drawn around it:
        :meth:`~rrr_pin.model.plant.Plant.perturbed`).
    laws : sequence of ControlLaw or SampledLaw
        Built-in (:func:`rrr_pin.campaign.runner.make_laws`) or your own; picklable (a worker
        process receives them); the baseline among them.
    settings : CampaignSettings
    reference : Reference, optional
        Default :func:`rrr_pin.control.references.study_reference` of ``nominal`` over the
        run's duration.
    jobs : int, optional
        Local worker processes, >= 1 (default ``min(2, CPUs)``); 1 runs in this process.
    scheduler : str, optional
        Address of a Dask distributed scheduler; the same tasks go there instead.
    executor : concurrent.futures.Executor, optional
        Any executor to use as is (overrides ``jobs`` and ``scheduler``).
    chunk : int, optional
        Samples per task (default: about 8 tasks per worker, at most 32 samples).
    batch : int, default 16
        Plants per batched rollout, 1 to 16 (:mod:`rrr_pin.sim.batched`, used under
        ``engine="auto"`` when the plant's structure has generated dynamics); rows are the same
        for every batch size, number of workers and chunk size.
    threads : int, default 1
        Threads of the batched engine in each worker process (one batch of plants per thread,
        the GIL released), 1 to :data:`rrr_pin.sim.batched.MAX_THREADS`: one process
        (``jobs=1``) can use every core; rows are the same for every thread count.
    progress : callable, optional
        ``progress(done, total)`` after each finished chunk (``total = samples + 1``, the
        nominal plant counted).
    certificate : rrr_pin.robust.certificates.CertificateSpec, optional
        Certify every plant (frozen-configuration nu-gap < b(Gs, Ks)) and add the columns
        ``certified`` and ``nugap_max`` beside the simulated outcome (about 0.3 s per plant).
    store : CampaignStore, optional
        Append every finished chunk to this store (opened with :func:`open_store` before any
        work) and compute only the samples it does not hold yet; the rows returned are the
        store's, so a resumed campaign equals an uninterrupted one.

    Returns
    -------
    Campaign

    Raises
    ------
    CampaignInterrupted
        Ctrl-C or SIGTERM (``.signum``); ``.done`` samples are finished (and on disk, with a
        store).
    WorkersLost
        Local worker processes died or no Dask worker was left; finished samples are kept.
    SchedulerUnreachable
        The Dask scheduler cannot be reached.
    TypeError, ValueError
        Before any work: an uncertainty set the plant does not accept, a run setting or engine
        that cannot run a law on it (:func:`rrr_pin.campaign.runner.check_runs`).
    """
    laws, reference = check_campaign(nominal, laws, settings, reference=reference)
    batch = check_count("batch", batch, 1, BATCH_MAX)
    threads = check_count("threads", threads, 1, MAX_THREADS)
    if settings.run.engine in (AUTO, CODEGEN):
        warm(nominal)  # a structure met for the first time is built once, before the workers
    job = CampaignJob(settings=settings, laws=tuple(laws), reference=reference,
                      nominal=nominal, certificate=certificate, batch=batch, threads=threads)
    samples = int(settings.samples)
    rows = run_samples(job, itertools.chain((NOMINAL_INDEX,), range(samples)),
                       total=samples + 1,
                       name=nominal.name, jobs=jobs, scheduler=scheduler, executor=executor,
                       chunk=chunk, store=store, progress=progress,
                       max_chunk=max(32, 4 * batch * threads),
                       min_chunk=1 if threads == 1 else 4 * batch * threads, unit=batch)
    per_law = ("drift",) if any(f"{law.name}_drift" in r for r in rows for law in laws) else ()
    per_law += ("engine",)
    return Campaign(robot=nominal.name, joint_names=list(nominal.joint_names),
                    laws=[law.describe() for law in laws],
                    rows=[r for r in rows if r["index"] != NOMINAL_INDEX],
                    settings={**settings.to_dict(), "reference": reference.to_dict(),
                              **({"certificate": certificate_loop(certificate.lam,
                                                                   certificate.points,
                                                                   settings.run)}
                                 if certificate is not None else {})},
                    nominal=next((r for r in rows if r["index"] == NOMINAL_INDEX), None),
                    per_law=per_law, joint_dynamics=nominal.joint_dynamics())


def _chunk_size(total: int, workers: int, max_chunk: int, min_chunk: int, unit: int) -> int:
    """Return the default chunk: about 8 per worker, in ``[min_chunk, max_chunk]``, whole units.

    About 8 tasks per worker: a task costs a few ms of set-up, while the last task of one
    worker leaves the others idle (:func:`_blocks` shrinks the last ones). Whole batches
    (``unit``) once a chunk holds more than one: the batched engine runs a batch of 15 plants
    as 16 (:data:`rrr_pin.sim.batched.LANES`), so a chunk of 63 costs as much as one of 64
    (before that padding, chunks of 63 made the RRR campaign's C++ loop 7 % slower).
    Small campaigns keep small chunks, so that every worker gets some.
    """
    size = max(min_chunk, min(max_chunk, math.ceil(min(total, 10**6) / (8 * workers))))
    return unit * math.ceil(size / unit) if size > unit else size


def _blocks(todo, n: int, size: int, tail: int, unit: int):
    """Yield ``todo`` in chunks of ``size``; once less than ``tail`` chunks' work is left, smaller.

    ``todo`` is any iterable of ``n`` indices, read lazily (a chunk at a time: any number of
    samples streams). A chunk of the last ``tail`` rounds takes about ``1 / tail`` of what is
    left, rounded up to a multiple of ``unit`` (at least ``unit``, at most ``size``): the last
    chunk of one worker then leaves the others idle for less time. Which samples go together
    changes no row.
    """
    it, i = iter(todo), 0
    while i < n:
        step = size
        if n - i < tail * size:
            step = min(size, max(unit, math.ceil(math.ceil((n - i) / tail) / unit) * unit))
        block = tuple(itertools.islice(it, step))
        if not block:
            return
        yield block
        i += len(block)


def run_samples(job, indices, *, total: int, name: str, jobs: int | None = None,
                scheduler: str | None = None, executor: Executor | None = None,
                chunk: int | None = None, store: CampaignStore | None = None, progress=None,
                max_chunk: int = 32, min_chunk: int = 1, unit: int = 1) -> list[dict]:
    """Run the samples ``indices`` of ``job`` in chunks on the executor; return every row.

    The machinery every campaign shares: chunks of samples (:class:`CampaignChunk`) go to
    :func:`rrr_pin.campaign.executors.run_tasks` (this process, local processes or Dask), each
    finished chunk is appended to ``store`` (the samples it holds already are skipped), and
    Ctrl-C or SIGTERM stops with :class:`CampaignInterrupted`.

    Parameters
    ----------
    job : CampaignJob or object with ``rows(indices) -> list of dict``
        Picklable; the rows carry an integer ``"index"``.
    indices : iterable of int
        The samples of the campaign, in order.
    total : int
        How many they are (for messages and ``progress``).
    name : str
        The robot's name (for the log).
    jobs, scheduler, executor, chunk, store, progress
        As in :func:`run_campaign`.
    max_chunk : int, default 32
        Largest default chunk (a chunk's cost should stay well below a second).
    min_chunk : int, default 1
        Smallest default chunk (a job's threads need a batch of plants each).
    unit : int, default 1
        The default chunk is a whole number of ``unit`` samples (a batch of the batched
        engine; :func:`_chunk_size`), and its last chunks shrink in steps of ``unit`` so that
        the workers finish together (:func:`_blocks`).

    Returns
    -------
    list of dict
        The rows, sorted by index: the store's (also those of earlier runs) with a store.
    """
    jobs = check_jobs(jobs)
    workers = jobs if executor is None and scheduler is None else 4
    size = chunk or _chunk_size(total, workers, max_chunk, min_chunk, unit)
    done = store.done() if store is not None else set()
    todo = (k for k in indices if k not in done)   # lazily: never the list of every index
    tail = 1 if chunk else 2 * workers  # the chunks of the last rounds shrink (default chunk)
    tasks = (CampaignChunk(job, block)
             for block in _blocks(todo, total - len(done), size, tail,
                                  max(unit, min_chunk)))
    rows: list[dict] = []
    finished = len(done)
    samples = total
    where = f" and saved in {str(store.out)!r}; rerun with --resume" if store is not None else ""
    logger.info("campaign on %s: %d laws (%s), %d samples (seed %d), %d already done, "
                "chunks of %d", name, len(job.laws), ", ".join(law.name for law in job.laws),
                samples, job.settings.seed, len(done), size)
    try:
        with interrupt_on_signals():
            for _, chunk_rows in run_tasks(run_chunk, tasks, jobs=jobs, scheduler=scheduler,
                                           executor=executor):
                if store is not None:
                    store.append(chunk_rows)
                else:
                    rows.extend(chunk_rows)
                finished += len(chunk_rows)
                if progress:
                    progress(finished, samples)
    except KeyboardInterrupt as exc:
        raise CampaignInterrupted(f"campaign interrupted ({exc or 'Ctrl-C'}): {finished} of "
                                  f"{samples} samples done{where}", done=finished,
                                  signum=getattr(exc, "signum", signal.SIGINT)) from None
    except CampaignInterrupted as exc:
        raise type(exc)(f"{exc}; {finished} of {samples} samples done{where}",
                        done=finished) from None
    rows = store.rows() if store is not None else sorted(rows, key=lambda r: r["index"])
    logger.info("campaign on %s done: %d samples", name, len(rows))
    return rows


def _metrics(names, baseline):
    """Per-sample scalar metrics and the direction that is "worst" for each."""
    out = {}
    for name in names:
        out.update({f"{name}_rms_error": "max", f"{name}_max_error": "max",
                    f"{name}_rms_torque": "max"})
    for name in names:
        if name != baseline:
            out[f"error_ratio_{name}"] = "min"
            out[f"torque_ratio_{name}"] = "max"
    return out


def campaign_columns(names, baseline, joint_names, certified: bool = False,
                     undefined: bool = False, per_law=()) -> list[str]:
    """Columns of ``campaign.csv``, in order (``undefined``: the reasons of undefined ratios).

    ``per_law``: further keys ``<law>_<key>`` (:attr:`Campaign.per_law`), after the metrics.
    """
    columns = ["index", "seed", "status"] + (["certified", "nugap_max"] if certified else [])
    columns += list(_metrics(names, baseline))
    columns += [f"{name}_{key}" for key in per_law for name in names]
    for name in names:
        columns += [f"{name}_rms_error_{j}" for j in joint_names]
    return columns + (["undefined"] if undefined else [])


def campaign_summary(campaign: Campaign) -> dict:
    """Median, 95th percentile and worst of each metric over the samples where it exists.

    Returns
    -------
    dict
        ``samples``, ``samples_ok`` (every law ran), ``samples_diverged``, ``diverged`` (their
        indices), ``baseline``, ``fraction_better`` (per law other than the baseline: share of
        the samples where both ran in which the law's RMS error is smaller) and, per metric
        (and per law ``<law>_drift`` [m] of a closed chain, worst the largest),
        ``{median, p95, worst, count}`` ("worst" is the maximum, except for the error ratios,
        where it is the minimum: the least benefit over the baseline); ``undefined``
        (when some ratio is undefined, e.g. 0/0): per ratio, the number of samples where it
        is (they are left out of its figures); ``engines``: per law, how many samples each
        engine ran; ``per_law``: per law, the samples it ``ran`` on and ``diverged`` on, and
        ``status`` ("fl ran on 20, tuned on 20, hinf diverged on 20"); with certificates,
        ``certified_ran`` and ``certified_diverged`` per law (a plant whose law diverged is
        never counted as certified for that law) and ``certificate`` (the loop it covers,
        :func:`rrr_pin.campaign.coverage.certificate_loop`).
    """
    rows, base = campaign.rows, campaign.baseline
    ok = [r for r in rows if r["status"] == "ok"]
    out = {"samples": len(rows), "samples_ok": len(ok), "samples_diverged": len(rows) - len(ok),
           "diverged": [r["index"] for r in rows if r["status"] != "ok"], "baseline": base,
           "fraction_better": {}}
    for name in campaign.names:
        key = f"error_ratio_{name}"
        both = [r for r in rows if key in r]
        if name != base and both:
            out["fraction_better"][name] = float(np.mean([r[key] > 1.0 for r in both]))
    engines = {}
    for name in campaign.names:
        ran = [r[f"{name}_engine"] for r in rows if f"{name}_engine" in r]
        if ran:
            engines[name] = {e: ran.count(e) for e in sorted(set(ran))}
    if engines:
        out["engines"] = engines
    metrics = _metrics(campaign.names, base)
    if "drift" in campaign.per_law:
        metrics.update({f"{name}_drift": "max" for name in campaign.names})
    for metric, worst in metrics.items():
        v = np.array([r[metric] for r in rows if metric in r])
        if v.size:
            out[metric] = {"median": float(np.median(v)), "p95": float(np.percentile(v, 95)),
                           "worst": float(v.max() if worst == "max" else v.min()),
                           "count": int(v.size)}
    undefined = {}
    for name in campaign.names:  # both laws ran, yet no ratio: it is undefined on that row
        ran = [r for r in rows if f"{name}_rms_error" in r and f"{base}_rms_error" in r]
        for key in (f"error_ratio_{name}", f"torque_ratio_{name}"):
            count = sum(1 for r in ran if key not in r) if name != base else 0
            if count:
                undefined[key] = count
    if undefined:
        out["undefined"] = undefined
    ran = {name: {r["index"] for r in rows if f"{name}_rms_error" in r}
           for name in campaign.names}
    out["per_law"] = {name: {"ran": len(ran[name]), "diverged": len(rows) - len(ran[name])}
                      for name in campaign.names}
    out["status"] = ", ".join(
        f"{name} ran on {c['ran']}" + (f" (diverged on {c['diverged']})"
                                       if c["ran"] and c["diverged"] else "")
        if c["ran"] else f"{name} diverged on {c['diverged']}"
        for name, c in out["per_law"].items())
    certs = [r for r in rows if "certified" in r]
    if certs:
        good = [r["index"] for r in certs if r["certified"]]
        out["certified_ran"] = {n: sum(1 for k in good if k in ran[n]) for n in campaign.names}
        out["certified_diverged"] = {n: len(good) - out["certified_ran"][n]
                                     for n in campaign.names}
        if "certificate" in campaign.settings:
            out["certificate"] = campaign.settings["certificate"]
        out["certified"] = sum(1 for r in certs if r["certified"])
        out["certified_and_ran"] = sum(1 for r in certs if r["certified"] and
                                       r["status"] == "ok")
        out["not_certified_but_ran"] = sum(1 for r in certs if not r["certified"] and
                                           r["status"] == "ok")
        out["nugap_max"] = max(r["nugap_max"] for r in certs)
    return out


def store_settings(nominal, laws, settings: CampaignSettings, reference,
                   certificate=None) -> dict:
    """Everything that changes a row, JSON-ready: a resume must match it exactly.

    The plant's name and :meth:`~rrr_pin.model.plant.Plant.fingerprint` (the hash of its URDF
    or MJCF, its locks and gravity), the laws, the settings, the reference and the certificate.
    """
    return {"robot": nominal.name, **nominal.fingerprint(),
            "controllers": [law.describe() for law in laws], **settings.to_dict(),
            "reference": reference.to_dict(),
            "certificate": certificate.to_dict() if certificate is not None else None}


def open_store(out, robot, laws, settings: CampaignSettings, reference, *, resume: bool = False,
               overwrite: bool = False, certificate=None) -> CampaignStore:
    """Open the campaign store in ``out`` before any work (see :mod:`rrr_pin.campaign.store`).

    Raises
    ------
    rrr_pin.campaign.store.StoreError
        ``out`` not writable, not empty (without ``resume``/``overwrite``), or recorded with
        other settings (``resume``).
    """
    return CampaignStore.open(out, settings=store_settings(robot, laws, settings, reference,
                                                           certificate),
                              resume=resume, overwrite=overwrite, outputs=OUTPUTS)
