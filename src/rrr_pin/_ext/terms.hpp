// Where a compiled law takes its model from (the plant protocol's nominal.terms(q, qd) and
// nominal.G(q), rrr_pin.model.plant): the two kinds of a law's model, one class each, both in
// actuated coordinates. The laws of law.hpp are templated on them.
//
//   ArmTerms:   a serial tree. M(q) by CRBA (its upper triangle mirrored), h = V + G by
//               nonLinearEffects, G by computeGeneralizedGravity. Never fails.
//   ChainTerms: a closed chain's reduced model (ClosedChain.reduced and .G): the passive
//               coordinates by Newton on the loop closure, seeded from the previous solution
//               (the first from the tree's home), then S = [I; -J_p^-1 J_a], qd = S qd_a,
//               s0 = [0; -J_p^-1 gamma], M_r = S^T (M S), h_r = S^T rnea(q, qd, s0),
//               G_r = S^T g(q). Fails (a status) where the loop does not close or J_p is
//               singular; the seed, the actuated q and cond(J_p) of the failure are kept.
#pragma once

#include <cstdint>

#include "tree.hpp"

namespace rrr_pin
{
  /// Stops of a run, mirrored in rrr_pin.sim.compiled (STOPS) and, for the first four, in
  /// rrr_pin.sim.trajectory.REASONS (same order of tests as diverged_joint: non-finite, then
  /// speed, then limits). kLawTorque: the law's torque (before any saturation) is NaN or inf;
  /// the stop's step is then the one whose law evaluation (sampled: at its start; continuous:
  /// at one of its RK4 stages) returned it.
  enum Reason : int
  {
    kOk = -1,
    kNonFinite = 0,
    kSpeed = 1,
    kLimits = 2,
    kLawTorque = 3,
    kDrift = 4,          // a step left a loop gap above the drift bound (ConstraintDrift)
    kPlantSingular = 5,  // the plant's projection met cond(J_p) > limit
    kPlantNoClose = 6,   // the plant's projection did not converge (LoopClosureError)
    kPlantCrossed = 7,   // det J_p changed sign over a step
    kLawSingular = 8,    // the law's loop closure met cond(J_p) > limit
    kLawNoClose = 9,     // the law's loop closure did not converge
  };

  /// A serial tree's M, h and G (never fails).
  class ArmTerms
  {
  public:
    explicit ArmTerms(const Tree & tree)
    : w(tree.tree)
    , M_(tree.na(), tree.na())
    {
    }

    /// M(q) [kg m^2] and h(q, qd) [N m]; returns kOk.
    int terms(const Vec & q, const Vec & qd)
    {
      M_ = crba(w, q);
      M_.triangularView<Eigen::StrictlyLower>() = M_.transpose();
      h_ = &nle(w, q, qd);
      return kOk;
    }

    /// G(q) [N m]; returns kOk.
    int gravity(const Vec & q)
    {
      G_ = &rrr_pin::gravity(w, q);
      return kOk;
    }

    const Mat & M() const { return M_; }
    const Vec & h() const { return *h_; }
    const Vec & G() const { return *G_; }

  private:
    Workspace w;
    Mat M_;
    const Vec * h_ = nullptr;
    const Vec * G_ = nullptr;
  };

  /// A closed chain's reduced M_r, h_r and G_r, with the law's own loop-closure Newton.
  class ChainTerms
  {
  public:
    explicit ChainTerms(const Tree & tree)
    : seed(tree.home)
    , law_q(tree.na())
    , w(tree)
    , qn(tree.home)
    , qdn(tree.nv())
    , s0(Vec::Zero(tree.nv()))
    {
    }

    /// M_r(q_a) [kg m^2] and h_r(q_a, qd_a) [N m]; returns kOk or a law stop.
    int terms(const Vec & qa, const Vec & qda)
    {
      if (const int st = close(qa); st != kOk)
        return st;
      w.S_of(S);
      qdn.noalias() = S * qda;
      w.gamma(qn, qdn);
      sp = -w.Jp.partialPivLu().solve(w.g);
      const Tree & cm = w.cm;
      for (Eigen::Index i = 0; i < cm.pas.size(); ++i)
        s0[cm.pas[i]] = sp[i];
      const Model & model = cm.tree.model;
      Mf = pinocchio::crba(model, w.data, CRef(qn));
      Mf.triangularView<Eigen::StrictlyLower>() = Mf.transpose();
      const Vec & hf = pinocchio::rnea(model, w.data, CRef(qn), CRef(qdn), CRef(s0));
      MS.noalias() = Mf * S;
      M_.noalias() = S.transpose() * MS;
      h_.noalias() = S.transpose() * hf;
      return kOk;
    }

    /// G_r(q_a) = S^T g(q) [N m]; returns kOk or a law stop.
    int gravity(const Vec & qa)
    {
      if (const int st = close(qa); st != kOk)
        return st;
      w.S_of(S);
      const Vec & g = pinocchio::computeGeneralizedGravity(w.cm.tree.model, w.data, CRef(qn));
      G_.noalias() = S.transpose() * g;
      return kOk;
    }

    const Mat & M() const { return M_; }
    const Vec & h() const { return h_; }
    const Vec & G() const { return G_; }

    /// At a stop: the full configuration Newton started from, the actuated q it was asked for
    /// and cond(J_p) there (inf where J_p was singular).
    Vec seed, law_q;
    double value = 0.0;

  private:
    /// The closed configuration at actuated qa, Newton from the last solution.
    int close(const Vec & qa)
    {
      const Tree & cm = w.cm;
      seed = qn;
      for (Eigen::Index i = 0; i < cm.act.size(); ++i)
        qn[cm.act[i]] = qa[i];
      const int st = w.close(qn, value);
      if (!st)
        return kOk;
      law_q = qa;
      qn = seed;  // the next call (none: the run stops) seeds from the last solution
      return st == 1 ? kLawSingular : kLawNoClose;
    }

    Closure w;
    Vec qn, qdn, s0, sp, h_, G_;
    Mat S, Mf, MS, M_;
  };
} // namespace rrr_pin
