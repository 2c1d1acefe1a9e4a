r"""The record ``identification.json``: its check, and the uncertain plants drawn from it."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...validation import check_probability
from ..plant import UncertaintySet
from .consistency import (
    parameter_weights,
    plausible_set,
    pseudo_inertia_lmis,
    urdf_with_parameters,
)
from .regressors import (
    BaseParameters,
    IdentificationError,
    base_parameters,
    body_links,
    joint_kinematics,
)

__all__ = ["RECORD_KEYS", "check_identification_record", "IdentifiedUncertainty"]


#: Keys of ``identification.json`` that :class:`IdentifiedUncertainty` reads.
RECORD_KEYS = ("joints", "links", "kinematics", "base", "base_count", "estimate", "cov",
               "standard_consistent", "consistency")


def check_identification_record(record: dict, path) -> None:
    """Refuse an ``identification.json`` that :class:`IdentifiedUncertainty` cannot draw from.

    Raises
    ------
    IdentificationError
        Naming the file and the key: missing keys; base names, ``K`` rows, ``estimate`` and
        ``base_count`` of different lengths; a covariance of the wrong shape, not finite, not
        symmetric or not positive definite.
    """
    missing = [k for k in RECORD_KEYS if k not in record]
    if not missing and isinstance(record["base"], dict):
        missing = [f"base.{k}" for k in ("names", "expressions", "standard", "independent",
                                         "K") if k not in record["base"]]
    if not missing and "pseudo_inertia_margins" not in (record["consistency"] or {}):
        missing = ["consistency.pseudo_inertia_margins"]
    if missing:
        raise IdentificationError(f"identification {str(path)!r}: missing keys {missing} (not "
                                  f"written by `rrr-pin identify`, or edited)")
    try:
        p = int(record["base_count"])
        K = np.asarray(record["base"]["K"], dtype=float)
        est = np.asarray(record["estimate"], dtype=float)
        cov = np.asarray(record["cov"], dtype=float)
    except (TypeError, ValueError) as exc:
        raise IdentificationError(f"identification {str(path)!r}: not numbers: {exc}") from None
    sizes = {"base_count": p, "base.names": len(record["base"]["names"]),
             "base.K rows": K.shape[0] if K.ndim == 2 else -1, "estimate": est.size}
    if len(set(sizes.values())) != 1 or est.ndim != 1:
        raise IdentificationError(f"identification {str(path)!r}: the number of base "
                                  f"parameters disagrees: {sizes}")
    if cov.shape != (p, p):
        raise IdentificationError(f"identification {str(path)!r}: 'cov' has shape "
                                  f"{cov.shape}, expected ({p}, {p}) for {p} base parameters")
    if not np.all(np.isfinite(cov)) or not np.all(np.isfinite(est)):
        raise IdentificationError(f"identification {str(path)!r}: 'cov' or 'estimate' holds a "
                                  f"value that is not finite")
    if not np.allclose(cov, cov.T, rtol=1e-9, atol=0.0):
        raise IdentificationError(f"identification {str(path)!r}: 'cov' is not symmetric")
    try:
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise IdentificationError(f"identification {str(path)!r}: 'cov' is not positive "
                                  f"definite (smallest eigenvalue "
                                  f"{np.linalg.eigvalsh(cov).min():.3g})") from None
    f = record.get("friction_estimate") or []
    if f and record.get("cov_all") is not None:
        try:
            cov_all = np.asarray(record["cov_all"], dtype=float)
            f = np.asarray(f, dtype=float)
        except (TypeError, ValueError) as exc:
            raise IdentificationError(f"identification {str(path)!r}: 'cov_all' or "
                                      f"'friction_estimate' not numbers: {exc}") from None
        P = p + f.size + len(record.get("armature_columns") or [])
        if f.size != 3 * len(record["joints"]) or cov_all.shape != (P, P):
            raise IdentificationError(
                f"identification {str(path)!r}: 'friction_estimate' has {f.size} values "
                f"(3 per joint of {len(record['joints'])}) and 'cov_all' shape "
                f"{cov_all.shape}, expected ({P}, {P})")
        try:
            if not np.all(np.isfinite(cov_all)) or not np.all(np.isfinite(f)):
                raise np.linalg.LinAlgError
            np.linalg.cholesky(0.5 * (cov_all + cov_all.T))
        except np.linalg.LinAlgError:
            raise IdentificationError(f"identification {str(path)!r}: 'cov_all' is not "
                                      f"finite and positive definite") from None


# --- the uncertainty set of an identification -------------------------------------------------

@dataclass(frozen=True)
class IdentifiedUncertainty(UncertaintySet):
    r"""Uncertain plants drawn from an identification's distribution (``identification.json``).

    Each plant: base parameters ``theta ~ N(theta_c, cov)`` kept only inside the
    ``confidence`` ellipsoid ``(theta - theta_c)^T cov^{-1} (theta - theta_c) <=
    chi2_p(confidence)`` (a draw outside is redrawn), centred on ``theta_c``, the base
    parameters of the identified URDF (the study's nominal; equal to the estimate when that is
    consistent, else the nearest consistent point, :func:`consistent_parameters`), with the
    estimate's covariance ``cov``, then the standard parameters with exactly
    those base parameters nearest to the identified ones under ``J_b >= eps_b 1`` (an SDP); a
    draw with no consistent arm is rejected and redrawn (at most :attr:`MAX_DRAWS` draws per
    plant). So the plants follow the identified distribution conditioned on physical
    consistency (within the confidence region): where the estimate lies near the boundary of
    the consistent set (thin links), many draws are rejected, none is moved. The kinematics
    stay the nominal's. Each plant records how many draws were rejected.

    When the identification has friction (``identify --friction``), base and friction
    parameters are drawn together, from their joint covariance (``cov_all``) in its
    ``confidence`` ellipsoid (of ``p + 3 nq`` dimensions), around the consistent base
    parameters and the friction estimate; a viscous or Coulomb coefficient (or an armature)
    drawn below zero is folded back (``|x|``: the folded normal of a coefficient known to be
    >= 0, which an estimate near 0 calls for; issue 46: rejecting such draws left none on a
    real log), counted in ``rejected["friction_folded"]``; the plant is kept. Each plant's
    URDF carries its drawn friction as ``<dynamics damping friction>`` (simulated with
    ``PlantEffects(viscous="urdf", coulomb="urdf")``, CLI
    ``--friction urdf``); the offsets are drawn but neither simulated nor written.

    Parameters
    ----------
    path : str
        The ``identification.json`` read (recorded with its SHA-256).
    confidence : float, default 0.95
        Of the ellipsoid the plants are drawn in, in (0, 1).
    draws : {"reject", "project"}, default "reject"
        ``"reject"``: the above (inconsistent draws redrawn, none moved). ``"project"``: a
        draw with no consistent arm is moved to the nearest consistent one (in the metric of
        the estimate's covariance, :func:`consistent_parameters` with the identification's
        mass band), a friction coefficient below 0 folded back as in "reject"; each plant
        records how far it was moved (``projected_mahalanobis``). For a real log whose
        estimate lies outside the consistent set (``identify --keep-inconsistent``), where
        almost every draw is inconsistent and rejection finds no plant.
    """

    MAX_DRAWS = 1000
    DRAWS = ("reject", "project")

    path: str
    confidence: float = 0.95
    draws: str = "reject"
    record: dict = field(default=None, repr=False, compare=False)
    sha256: str = field(default="", compare=True)

    def __post_init__(self) -> None:
        c = check_probability("confidence", self.confidence)
        if not 0.0 < c < 1.0:
            raise ValueError(f"confidence must be in (0, 1), got {c!r}")
        object.__setattr__(self, "confidence", c)
        if self.draws not in self.DRAWS:
            raise ValueError(f"draws must be one of {', '.join(self.DRAWS)}, got "
                             f"{self.draws!r}")
        if self.record is None:
            try:
                raw = Path(self.path).read_bytes()
                record = json.loads(raw)
            except (OSError, ValueError) as exc:
                raise IdentificationError(f"cannot read identification {self.path!r}: "
                                          f"{exc}") from None
            if not isinstance(record, dict) or record.get("format") != "rrr-pin-identification":
                raise IdentificationError(f"{self.path!r} is not an identification.json of "
                                          f"`rrr-pin identify` (no format "
                                          f"'rrr-pin-identification')")
            check_identification_record(record, self.path)
            object.__setattr__(self, "record", record)
            object.__setattr__(self, "sha256", hashlib.sha256(raw).hexdigest())

    @property
    def base(self) -> BaseParameters:
        """The base parameters identified."""
        return BaseParameters.from_dict(self.record["base"])

    def check_robot(self, robot) -> None:
        """Refuse a nominal whose joints or kinematics are not the identification's.

        Raises
        ------
        IdentificationError
            Naming the joints or the first joint whose placement differs (beyond 1e-9).
        """
        rec = self.record
        if list(robot.joint_names) != rec["joints"]:
            raise IdentificationError(f"{self.path}: identified joints {rec['joints']} are not "
                                      f"the robot {robot.name!r}'s {robot.joint_names}")
        for mine, theirs in zip(joint_kinematics(robot), rec["kinematics"], strict=True):
            if mine["type"] != theirs["type"] or not np.allclose(
                    mine["placement"], theirs["placement"], rtol=0.0, atol=1e-9):
                raise IdentificationError(
                    f"{self.path}: joint {mine['joint']!r} of {robot.name!r} is not placed as "
                    f"in the identified arm (kinematics differ); use the URDF identified "
                    f"({rec.get('urdf', 'identified.urdf')}) or the one it was identified on")
        if len(rec["base"]["K"][0]) != 10 * robot.nq:
            raise IdentificationError(f"{self.path}: its base parameters combine "
                                      f"{len(rec['base']['K'][0])} standard parameters; the "
                                      f"robot {robot.name!r} has {10 * robot.nq} (10 per body)")
        if body_links(robot) != rec["links"]:
            raise IdentificationError(f"{self.path}: body links {rec['links']} are not the "
                                      f"robot's {body_links(robot)}")
        own, theirs = list(base_parameters(robot).names), list(rec["base"]["names"])
        if own != theirs:
            raise IdentificationError(f"{self.path}: {len(theirs)} base parameters identified, "
                                      f"the robot {robot.name!r} has {len(own)} (or named "
                                      f"otherwise: {sorted(set(theirs) ^ set(own))[:4]})")

    def describe(self) -> str:
        """One line for reports."""
        return (f"identified distribution ({Path(self.path).name}, {self.record['base_count']} "
                f"base parameters, {self.confidence:.0%} confidence region"
                + (", inconsistent draws projected)" if self.draws == "project" else ")"))

    def to_dict(self) -> dict:
        """JSON-ready: what the plants are drawn from."""
        return {"kind": "identified", "identification": str(self.path),
                "identification_sha256": self.sha256, "confidence": self.confidence,
                "base_count": self.record["base_count"], "draws": self.draws}

    def _problem(self):
        cached = getattr(self, "_cache", None)
        if cached is not None:
            return cached
        import cvxpy as cp

        base, phi_id = self.base, np.asarray(self.record["standard_consistent"], float)
        theta = cp.Parameter(base.p)
        phi = cp.Variable(len(phi_id))
        margins = np.asarray(self.record["consistency"]["pseudo_inertia_margins"], float)
        problem = cp.Problem(
            cp.Minimize(cp.sum_squares(cp.multiply(parameter_weights(phi_id), phi - phi_id))),
            [base.K @ phi == theta] + pseudo_inertia_lmis(phi, len(phi_id) // 10, margins)
            + plausible_set(phi, self._phi0(), **self._bands()))
        cached = (problem, theta, phi)
        object.__setattr__(self, "_cache", cached)
        return cached

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k != "_cache"}

    def __setstate__(self, state):
        self.__dict__.update(state)

    def as_settings(self) -> dict:
        """Return what the outputs record: ``{"uncertainty": "identified", ...to_dict()}``."""
        return {"uncertainty": "identified", **{k: v for k, v in self.to_dict().items()
                                                if k != "kind"}}

    def arm(self, source, rng: np.random.Generator, *, skip_joints=(), name=None
            ) -> tuple[str, dict]:
        """:meth:`draw` on the arm's URDF (kinematics nominal): ``(URDF, {"identified": ...})``."""
        from ..urdf import urdf_from_params

        text = str(source) if isinstance(source, str) else urdf_from_params(source)
        urdf, drawn = self.draw(text, rng)
        return urdf, {"identified": drawn}

    def _bands(self) -> dict:
        """Return the plausibility bands the identification applied (its record)."""
        c = self.record.get("consistency") or {}
        return {"mass_band": c.get("mass_band"), "inertia_band": c.get("inertia_band")}

    def _phi0(self) -> np.ndarray:
        """Return the nominal standard parameters the bands are around."""
        return np.asarray(self.record.get("standard_nominal")
                          or self.record["standard_consistent"], float)

    def _project(self, urdf: str, theta, friction):
        """Nearest consistent arm to base parameters ``theta``: ``(URDF, phi, distance)``.

        The distance is the move's Mahalanobis norm in the estimate's covariance; ``(None,
        None, None)`` when no consistent arm is found.
        """
        from .consistency import consistent_parameters

        rec = self.record
        cov = np.asarray(rec["cov"], float)
        w, V = np.linalg.eigh(0.5 * (cov + cov.T))
        A = (V / np.sqrt(np.maximum(w, 1e-15 * w.max()))).T  # A^T A = cov^-1
        try:
            phi, info = consistent_parameters(self.base, theta, A, self._phi0(),
                                              **self._bands())
            text = urdf_with_parameters(urdf, rec["links"], phi, friction=friction)
        except (IdentificationError, ValueError):
            return None, None, None
        return text, phi, float(info["distance_returned_rms_Nm"])

    def draw(self, urdf: str, rng: np.random.Generator) -> tuple[str, dict]:
        """One plant: its URDF text and ``{"base", "standard", "friction", "rejected": {...}}``.

        Raises
        ------
        IdentificationError
            No consistent plant in :attr:`MAX_DRAWS` draws.
        """
        from scipy.stats import chi2

        rec = self.record
        mean = np.asarray(rec["base_consistent"], float)
        cov = np.asarray(rec["cov"], float)
        p = len(mean)
        f_mean = np.asarray(rec.get("friction_estimate") or [], float)
        kept = np.asarray(rec.get("armature_columns") or [], dtype=int)
        a_est = np.asarray(rec.get("armature_estimate") or [], float)
        a_mean = a_est[kept] if kept.size else np.zeros(0)
        if f_mean.size and rec.get("cov_all") is not None:
            mean = np.concatenate([mean, f_mean, a_mean])
            cov = np.asarray(rec["cov_all"], float)
        else:
            f_mean = a_mean = np.zeros(0)
        nf = f_mean.size
        L = np.linalg.cholesky(cov)
        limit = chi2.ppf(self.confidence, len(mean))
        problem, theta, phi = self._problem()
        outside = inconsistent = negative = 0
        for _ in range(self.MAX_DRAWS):
            z = rng.standard_normal(len(mean))
            if z @ z > limit:
                outside += 1
                continue
            x = mean + L @ z
            friction = None
            drawn_armature = None
            if a_mean.size:  # folded at 0 (see the class docstring)
                drawn_armature = np.where(a_est > 0.0, a_est, 0.0)
                drawn_armature[kept] = x[p + nf:]
                negative += int(np.sum(drawn_armature < 0.0))
                drawn_armature = np.abs(drawn_armature)
            if f_mean.size:  # folded at 0: a coefficient known to be >= 0
                f = x[p:p + nf].reshape(-1, 3)
                negative += int(np.sum(f[:, :2] < 0.0))
                f = np.column_stack([np.abs(f[:, :2]), f[:, 2]])
                friction = {j: {"viscous_Nms_rad": float(fj[0]), "coulomb_Nm": float(fj[1]),
                                "offset_Nm": float(fj[2])}
                            for j, fj in zip(rec["joints"], f, strict=True)}
            theta.value = x[:p]
            try:
                problem.solve(solver="CLARABEL", warm_start=False)
                ok = problem.status == "optimal"
            except Exception:  # cvxpy.SolverError: a rejected draw
                ok = False
            if ok:
                try:
                    text = urdf_with_parameters(urdf, rec["links"], phi.value,
                                                friction=friction)
                except ValueError:  # not physical after all (round-off): rejected
                    ok = False
            moved = None
            if not ok and self.draws == "project":
                text, phi_value, moved = self._project(urdf, x[:p], friction)
                ok = text is not None
            else:
                phi_value = phi.value
            if not ok:
                inconsistent += 1
                continue
            rejected = {"outside_confidence": outside, "inconsistent": inconsistent}
            if f_mean.size:
                rejected["friction_folded"] = negative
            if self.draws == "project":
                rejected["projected"] = moved is not None
                rejected["projected_mahalanobis"] = moved
            return text, {"base": x[:p].tolist(), "standard": np.asarray(phi_value).tolist(),
                          "friction": friction, "rejected": rejected,
                          **({"armature": drawn_armature.tolist()}
                             if drawn_armature is not None else {})}
        raise IdentificationError(
            f"{self.path}: no physically consistent plant in {self.MAX_DRAWS} draws "
            f"({outside} outside the {self.confidence:.0%} region, {inconsistent} with no "
            f"consistent arm); the identified covariance is too wide for this arm: draw with "
            f"--uncertainty-draws project (each draw moved to the nearest consistent arm)")
