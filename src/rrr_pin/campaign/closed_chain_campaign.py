r"""Monte Carlo campaigns on a parallel mechanism (the 5-bar or the Delta).

The campaign of :mod:`rrr_pin.campaign.montecarlo`, on a closed chain: the same settings
(:class:`~rrr_pin.campaign.montecarlo.CampaignSettings`, with a
:class:`~rrr_pin.model.uncertainty.MechanismUncertainty` as its ``tolerances``), the same
chunks, executors (this process, local processes or Dask), append-only store and resume
(:func:`~rrr_pin.campaign.montecarlo.run_samples`), and the same rows, summary and figures
(:class:`~rrr_pin.campaign.montecarlo.Campaign`). What differs is one sample:

* sample ``k`` of a campaign with seed ``s`` is the mechanism
  :func:`rrr_pin.model.uncertainty.sample_mechanism` draws, ``tol.draw(nominal,
  numpy.random.default_rng([s, k]))`` (by default
  :func:`~rrr_pin.model.mechanisms.perturb_mechanism`, 20 % masses and 5 % lengths, closable);
* every law runs on it with :func:`rrr_pin.sim.closed_chain.simulate_closed_chain` (Pinocchio's
  constraint dynamics; ``engine`` of the run settings: ``auto`` runs ``fl`` and ``hinf`` on the
  compiled closed-chain engine, the other laws on the Python one) on the study's reference
  (:func:`rrr_pin.campaign.closed_chain_study.chain_reference` unless one is given);
* besides the serial arm's figures (``<law>_rms_error``, ``_max_error`` [rad], ``_rms_torque``
  [N m], per joint, the ratios to the baseline), each row holds ``<law>_drift`` (the largest
  loop gap the run left before a projection [m], ``info["drift_m"]``) and ``<law>_status``
  (``"ok"`` or ``"failed: ..."``: a type-II singularity met, a loop that would not close, a
  drift above the bound); the row's ``status`` names every law that failed;
* the nominal mechanism is run too, as the row of index -1 (:attr:`Campaign.nominal`, in
  ``summary.json``): its numbers are those of the study's nominal run
  (:func:`rrr_pin.campaign.closed_chain_study.run_chain_study` with the same duration and rate).

Before each run a law's model has its loop-closure seed reset to ``home`` at ``r(0)`` (as the
study does), so a row depends on its own plant only: the rows are identical whatever the
number of workers, the chunks, or an interruption and resume.

Options of a serial campaign that do not apply to closed chains are refused by name: a
joint-limit margin, the ``codegen`` engine, plant effects on the ``compiled`` engine (``auto``
runs them in Python), the serial arms' uncertainty sets.
"""

from __future__ import annotations

import hashlib
import logging
from concurrent.futures import Executor
from dataclasses import asdict, dataclass

from ..control.closed_chain import CHAIN_LAWS, make_chain_law, reset_closure
from ..control.references import Reference
from ..model.closed_chain import load_closed_chain
from ..model.mechanisms import DeltaParams, FiveBarParams
from ..model.uncertainty import MechanismUncertainty, sample_mechanism
from ..robust.loopshaping import design
from ..sim.closed_chain import simulate_closed_chain
from .closed_chain_study import FAILURES, chain_reference
from .montecarlo import OUTPUTS, Campaign, CampaignSettings, run_samples
from .runner import check_laws, error_ratios, run_metrics
from .store import CampaignStore

__all__ = ["ChainCampaignJob", "run_chain_campaign", "chain_sample_row", "chain_laws",
           "check_chain_settings", "chain_store_settings", "open_chain_store",
           "NOMINAL_INDEX"]

logger = logging.getLogger(__name__)

#: Index of the nominal plant's row (the samples are 0, 1, ...).
NOMINAL_INDEX = -1



def chain_laws(names, chain, *, K=None, lam_fl: float = 100.0, lam_hinf: float = 45.0,
               torque_limit=None) -> list:
    """Build built-in laws of a closed chain by name, in the order given.

    Each law gets its own nominal model (its loop-closure seed follows its own runs), as in
    :func:`rrr_pin.campaign.closed_chain_study.run_chain_study`; each is
    :func:`rrr_pin.control.closed_chain.make_chain_law` of its name.

    Parameters
    ----------
    names : str or sequence of str
        Keys of :data:`rrr_pin.control.closed_chain.CHAIN_LAWS`, e.g. ``"fl,hinf,pd"``.
    chain : ClosedChain
        The nominal mechanism (a built-in parameter set).
    K : control LTI, optional
        Controller of the H-infinity laws; default ``design(lam=lam_hinf, n=chain.nq).K_reduced``.
    lam_fl, lam_hinf : float
        FL bandwidths [rad/s] of ``"fl"`` and of the H-infinity laws.
    torque_limit : float or array-like, optional
        The limits [N m] ``"hinf_aw"`` knows (it requires them).

    Raises
    ------
    ValueError
        An empty, unknown or repeated name (naming it and the known ones).
    """
    if isinstance(names, str):
        names = [s.strip() for s in names.split(",")]
    names = list(names)
    unknown = [n for n in names if n not in CHAIN_LAWS]
    if not names or unknown:
        raise ValueError(f"controllers {', '.join(map(repr, unknown or names))}: not "
                         f"implemented on closed chains; expected comma-separated names from "
                         f"{', '.join(CHAIN_LAWS)}")
    if K is None and any(n in ("hinf", "hinf_aw") for n in names):
        K = design(lam=lam_hinf, n=chain.nq).K_reduced
    laws = [make_chain_law(name, load_closed_chain(chain.params, gravity=chain.gravity), K=K,
                           lam_fl=lam_fl, lam_hinf=lam_hinf, torque_limit=torque_limit)
            for name in names]
    return check_laws(laws, chain.nq)


def check_chain_settings(chain, settings: CampaignSettings) -> None:
    """Refuse, by name, settings a closed-chain campaign does not implement.

    Raises
    ------
    ValueError
        A ``limit_margin``, the ``codegen`` engine, the ``compiled`` engine with active plant
        effects (it has none), a nominal loaded from an MJCF file (no parameter set to perturb).
    TypeError
        ``settings.tolerances`` not a :class:`~rrr_pin.model.uncertainty.MechanismUncertainty`.
    """
    if not isinstance(chain.params, (FiveBarParams, DeltaParams)):
        raise ValueError(f"{chain.name}: a closed-chain campaign perturbs a built-in parameter "
                         f"set (FiveBarParams or DeltaParams); this chain came from "
                         f"{chain.source!r} and has none")
    if not isinstance(settings.tolerances, MechanismUncertainty):
        raise TypeError(f"tolerances must be a MechanismUncertainty for a closed chain (e.g. "
                        f"MechanismTolerances()), got {type(settings.tolerances).__name__}: "
                        f"Tolerances and IdentifiedUncertainty perturb serial arms' URDF")
    run = settings.run
    unsupported = [what for what, given in (
        ("plant effects with engine 'compiled' (it has none; auto runs them in Python)",
         run.engine == "compiled" and run.effects is not None and run.effects.active),
        ("limit_margin", run.limit_margin != 0.0),
        (f"engine {run.engine!r}", run.engine not in ("auto", "python", "compiled"))) if given]
    if unsupported:
        raise ValueError(f"{chain.name} (a closed chain): the campaign does not implement "
                         f"{', '.join(unsupported)} (engines auto, python or compiled on the "
                         f"constraint dynamics, plant effects in Python, no joint-limit "
                         f"check)")


@dataclass(frozen=True)
class ChainCampaignJob:
    """What every sample of a closed-chain campaign shares (sent to the workers).

    Attributes
    ----------
    settings : CampaignSettings
    laws : tuple of ControlLaw or SampledLaw
        Laws on the actuated coordinates, each with a ``nominal`` ClosedChain or not.
    reference : Reference
        Actuated reference [rad].
    params : FiveBarParams or DeltaParams
        The nominal mechanism the plants are drawn around.
    gravity : float
        Gravity of the plants [m/s^2].
    joint_names : tuple of str
        Actuated joints.
    """

    settings: CampaignSettings
    laws: tuple
    reference: Reference
    params: FiveBarParams | DeltaParams
    gravity: float
    joint_names: tuple

    def rows(self, indices) -> list[dict]:
        """Rows of samples ``indices`` (-1: the nominal), in order (:func:`chain_sample_row`)."""
        return [chain_sample_row(self, k) for k in indices]


def _plant(job: ChainCampaignJob, k: int):
    """Sample ``k``'s mechanism (the nominal for -1), its parameters record."""
    if k == NOMINAL_INDEX:
        params, parameters = job.params, {"params": asdict(job.params), "factors": {}}
    else:
        params, factors = sample_mechanism(job.params, job.settings.seed, k,
                                           job.settings.tolerances)
        parameters = {"params": asdict(params), "factors": factors}
    return load_closed_chain(params, gravity=job.gravity), parameters


def chain_sample_row(job: ChainCampaignJob, k: int) -> dict:
    """Draw sample ``k`` (-1: the nominal), run every law on it and reduce it to one row."""
    plant, parameters = _plant(job, k)
    run = job.settings.run
    row = {"index": k, "seed": None if k == NOMINAL_INDEX else [job.settings.seed, k],
           "status": "ok", "parameters": parameters}
    figures, failed = {}, []
    for law in job.laws:
        reset_closure(law, job.reference)
        try:
            traj = simulate_closed_chain(plant, law, job.reference, run.duration,
                                         rate=run.rate, dt=run.dt, method=run.method,
                                         q0=run.q0, qd0=run.qd0, engine=run.engine,
                                         effects=run.effects)
        except FAILURES as exc:
            row[f"{law.name}_status"] = f"failed: {type(exc).__name__}: {exc}"
            failed.append(f"{law.name}: {type(exc).__name__}: {exc}")
            continue
        figures[law.name] = run_metrics(traj, job.joint_names)
        row.update({f"{law.name}_{key}": v for key, v in figures[law.name].items()})
        row[f"{law.name}_drift"] = float(traj.info["drift_m"])
        row[f"{law.name}_status"] = "ok"
    if failed:
        row["status"] = "failed: " + "; ".join(failed)
    undefined = []
    for name, r in error_ratios(figures, job.settings.baseline).items():
        for key in ("error_ratio", "torque_ratio"):
            if r[key] is not None:  # an undefined ratio is left out, its reason stated
                row[f"{key}_{name}"] = r[key]
        undefined += r.get("undefined", [])
    if undefined:
        row["undefined"] = "; ".join(undefined)
    return row


def run_chain_campaign(chain, laws, settings: CampaignSettings, *,
                       reference: Reference | None = None, jobs: int | None = None,
                       scheduler: str | None = None, executor: Executor | None = None,
                       chunk: int | None = None, progress=None,
                       store: CampaignStore | None = None) -> Campaign:
    """Run every law on the nominal mechanism and ``settings.samples`` uncertain ones.

    Parameters
    ----------
    chain : ClosedChain
        Nominal mechanism, loaded from a built-in parameter set
        (``rrr_pin.load_robot("fivebar")``, ``load_closed_chain(FiveBarParams(...))``).
    laws : sequence of ControlLaw or SampledLaw
        On the actuated coordinates: :func:`chain_laws` or your own; picklable; the baseline
        among them.
    settings : CampaignSettings
        ``tolerances`` a :class:`~rrr_pin.model.uncertainty.MechanismUncertainty` (e.g.
        ``MechanismTolerances()``); ``run``: duration [s] (for the default reference, its
        period too), ``rate`` [Hz] or None (continuous laws), ``dt``, ``method``, ``q0``,
        ``qd0``; the rest is refused (:func:`check_chain_settings`).
    reference : Reference, optional
        Actuated reference; default :func:`~rrr_pin.campaign.closed_chain_study.chain_reference`
        of ``chain`` over ``settings.run.duration``.
    jobs, scheduler, executor, chunk, progress, store
        As in :func:`rrr_pin.campaign.montecarlo.run_campaign`; ``progress(done, total)``
        counts the nominal plant too (``total = samples + 1``), and ``store`` is opened with
        :func:`open_chain_store`.

    Returns
    -------
    Campaign
        ``rows``: the uncertain plants; ``nominal``: the nominal plant's row; ``per_law``:
        ``("drift", "status")``.

    Raises
    ------
    CampaignInterrupted, WorkersLost, SchedulerUnreachable
        As :func:`~rrr_pin.campaign.montecarlo.run_campaign`.
    """
    check_chain_settings(chain, settings)
    laws = check_laws(laws, chain.nq, settings.baseline)
    reference = (chain_reference(chain, settings.run.duration) if reference is None
                 else reference)
    job = ChainCampaignJob(settings=settings, laws=tuple(laws), reference=reference,
                           params=chain.params, gravity=chain.gravity,
                           joint_names=tuple(chain.joint_names))
    samples = int(settings.samples)
    # One plant per task by default: a run costs about 1.5 s per simulated second on the
    # Python engine (5-bar, 1 kHz; 0.03-0.05 s compiled), above a task's set-up.
    rows = run_samples(job, [NOMINAL_INDEX, *range(samples)], total=samples + 1,
                       name=chain.name, jobs=jobs, scheduler=scheduler, executor=executor,
                       chunk=chunk, store=store, progress=progress, max_chunk=1)
    nominal = next((r for r in rows if r["index"] == NOMINAL_INDEX), None)
    return Campaign(robot=chain.name, joint_names=list(chain.joint_names),
                    laws=[law.describe() for law in laws],
                    rows=[r for r in rows if r["index"] != NOMINAL_INDEX],
                    settings={**settings.to_dict(), "reference": reference.to_dict()},
                    nominal=nominal, per_law=("drift", "status"))


def chain_store_settings(chain, laws, settings: CampaignSettings, reference) -> dict:
    """Everything that changes a row of a closed-chain campaign, JSON-ready (resume checks)."""
    return {"robot": chain.name, "mjcf_sha256": hashlib.sha256(chain.mjcf.encode()).hexdigest(),
            "gravity": chain.gravity, "controllers": [law.describe() for law in laws],
            **settings.to_dict(), "reference": reference.to_dict()}


def open_chain_store(out, chain, laws, settings: CampaignSettings, reference, *,
                     resume: bool = False, overwrite: bool = False) -> CampaignStore:
    """Open the store of a closed-chain campaign in ``out`` before any work.

    As :func:`rrr_pin.campaign.montecarlo.open_store` (same store, same outputs), with
    :func:`chain_store_settings`.
    """
    return CampaignStore.open(out, settings=chain_store_settings(chain, laws, settings,
                                                                 reference),
                              resume=resume, overwrite=overwrite, outputs=OUTPUTS)
