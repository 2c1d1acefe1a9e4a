// The engine face of a plant (rrr_pin.model.plant.Plant): what the compiled rollout integrates,
// one class per kind, on the plant's full state (q, qd) (every coordinate of the tree):
//
//   acceleration(q, qd, tau): the forward dynamics under actuator torques tau (n actuated);
//   measure(q, qd, ...):      the actuated coordinates (what the encoders read);
//   settle(q, qd):            after every RK4 step.
//
//   ArmPlant:   a serial tree. Pinocchio's ABA; every coordinate is measured; nothing settles.
//   ChainPlant: a closed chain. The exact KKT constrained dynamics of Closure (tau on the
//               actuated coordinates, zero on the passive ones); settle is ChainSettler's step
//               (rrr_pin.model.closed_chain): the drift check against the tree's bound, the
//               projection (Newton on the passive coordinates, then qd_p = -J_p^-1 J_a qd_a),
//               the drift records and the type-II checks (cond(J_p) above the limit, a sign
//               change of det J_p).
#pragma once

#include "terms.hpp"

namespace rrr_pin
{
  /// The actuated coordinates of a full state (references to it, or to a gathered copy).
  struct Measured
  {
    const Vec & q;
    const Vec & qd;
  };

  /// A serial tree under ABA.
  class ArmPlant
  {
  public:
    static constexpr bool settles = false;

    ArmPlant(const Tree & tree, const Vec &)
    : w(tree.tree)
    {
    }

    const Vec & acceleration(const Vec & q, const Vec & qd, const Vec & tau)
    {
      return aba(w, q, qd, tau);
    }

    /// Every coordinate is actuated: the state itself (qa, qda unused).
    Measured measure(const Vec & q, const Vec & qd, Vec &, Vec &) const { return {q, qd}; }

    int settle(Vec &, Vec &) { return kOk; }

    double drift = 0.0, drift_v = 0.0, value = 0.0;

  private:
    Workspace w;
  };

  /// A closed chain under its exact KKT dynamics, projected onto its loop after every step.
  class ChainPlant
  {
  public:
    static constexpr bool settles = true;

    /// q0: the closed initial configuration (det J_p there: the branch to stay on).
    ChainPlant(const Tree & tree, const Vec & q0)
    : w(tree)
    , u(Vec::Zero(tree.nv()))
    , qc(tree.nv())
    , qda(tree.na())
    {
      w.jacobian(q0);
      sign = w.Jp.determinant();
    }

    const Vec & acceleration(const Vec & q, const Vec & qd, const Vec & tau)
    {
      const IVec & act = w.cm.act;
      for (Eigen::Index i = 0; i < act.size(); ++i)
        u[act[i]] = tau[i];
      return w.acceleration(q, qd, u);
    }

    /// The actuated coordinates, gathered into qa, qda.
    Measured measure(const Vec & q, const Vec & qd, Vec & qa, Vec & qda_) const
    {
      const IVec & act = w.cm.act;
      for (Eigen::Index i = 0; i < act.size(); ++i)
      {
        qa[i] = q[act[i]];
        qda_[i] = qd[act[i]];
      }
      return {qa, qda_};
    }

    /// After a step: drift check, projection, drift records, det J_p sign; kOk or the stop
    /// (value: the gap [m] or cond(J_p); q, qd left as the step ended, or projected).
    int settle(Vec & q, Vec & qd)
    {
      const Tree & cm = w.cm;
      w.jacobian(q);  // phi at q, and Newton's first J
      const double gap = maxabs(w.phi);
      if (!(gap <= cm.drift_bound))
      {
        value = gap;
        return kDrift;
      }
      drift = drift > gap ? drift : gap;  // Python's max(drift, gap)
      qc = q;
      double cond = 0.0;
      const int st = w.close(qc, cond, true);
      if (st)
      {
        value = cond;
        return st == 1 ? kPlantSingular : kPlantNoClose;
      }
      for (Eigen::Index i = 0; i < cm.act.size(); ++i)
        qda[i] = qd[cm.act[i]];
      qdp = -w.Jp.partialPivLu().solve(w.Ja * qda);
      const double dv = maxabs(w.J * qd);  // J at the projected q, the unprojected qd
      drift_v = drift_v > dv ? drift_v : dv;
      const double det = w.Jp.determinant();
      q = qc;
      for (Eigen::Index i = 0; i < cm.pas.size(); ++i)
        qd[cm.pas[i]] = qdp[i];
      if (det * sign < 0.0)
      {
        value = w.cond();
        return kPlantCrossed;
      }
      sign = det;
      return kOk;
    }

    /// Largest gap [m] a step left, largest |J qd| [m/s] before a projection; the value [m] or
    /// cond(J_p) of a stop.
    double drift = 0.0, drift_v = 0.0, value = 0.0;

  private:
    Closure w;
    Vec u, qc, qda, qdp;
    double sign = 0.0;
  };
} // namespace rrr_pin
