// The control laws the compiled engine implements, one struct of parameters per compiled form of
// rrr_pin.control.laws (FLForm -> FLLaw, FLAWForm -> FLAWLaw, PDForm -> PDLaw,
// TwoDOFForm -> TwoDOFLaw;
// rrr_pin.sim.compiled maps one to the other by type and copies the fields by name). Each law's
// Eval<Terms> evaluates it on the law's model, operation for operation as the Python laws do;
// Terms (terms.hpp) is where M, h and G come from: a serial tree's (ArmTerms) or a closed
// chain's reduced model (ChainTerms), as the Python laws read nominal.terms() and nominal.G():
//
//   FLLaw: taubar = rdd + 2 lam (rd - qd) + lam^2 (e + y), y = C x + D e, elementwise with
//          lam one value per joint (a shared lam arrives as nq equal entries),
//          tau = Mhat(q) taubar + h_hat(q, qd)                                         eq. (8)
//          state: xdot = A x + B e (continuous) or x+ = A x + B e after the output (sampled,
//          A..D already discrete).
//   FLAWLaw: FLLaw's tau clipped, tau_s = clip(tau, -limit, limit); K conditioned on it (Hanus):
//          x+ (or xdot) = A x + B e + L dy, dy_j = (Mhat^-1 (tau_s - tau))_j / lam_j^2, L = B D^-1, the
//          last term only at evaluations where a joint clips (FLAWForm).
//   PDLaw: tau = Kp e + Kd (rd - qd) + Ghat(q); no state.
//   TwoDOFLaw: tauhat = q + C x + D v, v = [e; qd], taubar = lam^2 (tauhat - q) - 2 lam qd,
//          elementwise, tau = Mhat(q) taubar + h_hat(q, qd) (TwoDOFController, the 2-DOF
//          H-infinity law: no rd, rdd feed-forward); state: xdot = A x + B v or x+ = A x + B v
//          after the output (sampled).
//
// torque() returns kOk or the stop of the law's model (a closed chain's loop that does not close
// there); the torque is then tau().
//
// Each law names itself (name: its class in rrr_pin.sim._rollout and the `cpp` of its compiled
// form in rrr_pin.control.laws.forms), says what it is (doc) and lists its fields once
// (fields(): name and member, in the compiled form's spelling), from which the bindings are
// made. RRR_PIN_LAWS at the end is the one list of laws: the bindings, the rollout, the batch
// and its bindings expand it, so a law added there is bound, instantiated and batched.
#pragma once

#include <tuple>

#include <Eigen/LU>

#include "effects.hpp"  // Field, field()
#include "terms.hpp"

namespace rrr_pin
{
  /// Eq. (8) with the law's model: tau = Mhat(q) taubar + h_hat(q, qd) (FLLaw, TwoDOFLaw), or
  /// the stop of a model whose loop does not close at q.
  template<class Terms>
  int model_torque(Terms & terms, const Vec & q, const Vec & qd, const Vec & taubar, Vec & tau)
  {
    if (const int st = terms.terms(q, qd); st != kOk)
      return st;
    tau.noalias() = terms.M() * taubar;
    tau += terms.h();
    return kOk;
  }

  /// Feedback linearization with a linear controller (A, B, C, D) on e = r - q (FLForm).
  struct FLLaw
  {
    Vec lam;         // (n,) [rad/s], per joint
    Mat A, B, C, D;  // (m, m), (m, n), (n, m), (n, n); m = 0 for FL alone

    static constexpr const char * name = "FLLaw";
    static constexpr const char * doc = "Feedback linearization + linear controller (FLForm).";
    static constexpr auto fields()
    {
      return std::make_tuple(field("lam", &FLLaw::lam), field("A", &FLLaw::A),
                             field("B", &FLLaw::B), field("C", &FLLaw::C), field("D", &FLLaw::D));
    }

    Eigen::Index nx() const { return A.rows(); }

    void check(Eigen::Index n) const
    {
      const Eigen::Index m = A.rows();
      if (
        A.cols() != m || B.rows() != m || B.cols() != n || C.rows() != n || C.cols() != m
        || D.rows() != n || D.cols() != n)
        throw std::invalid_argument("controller matrices have inconsistent shapes");
      if (lam.size() != n)
        throw std::invalid_argument("lam must have one entry per joint");
    }

    /// The nominal-model calls one torque() makes on a serial tree (for floor_timing).
    static void model_calls(Workspace & nominal, const Vec & q, const Vec & qd, Vec & tau,
                            double & sink)
    {
      sink += crba(nominal, q)(0, 0);
      tau = nle(nominal, q, qd);
    }

    template<class Terms>
    class Eval
    {
    public:
      Eval(const FLLaw & law, const Tree & nominal)
      : terms(nominal)
      , p(law)
      , m(law.nx())
      , e(nominal.na())
      , y(e.size())
      , taubar(e.size())
      , tau_(e.size())
      {
      }

      /// Torque at (q, qd) for reference row (r, rd, rdd) and law state x; keeps e.
      template<typename R1, typename R2, typename R3>
      int torque(
        const Vec & q, const Vec & qd, const R1 & r, const R2 & rd, const R3 & rdd, const Vec & x)
      {
        e = r.transpose() - q;
        y.noalias() = p.D * e;
        if (m > 0)
          y.noalias() += p.C * x;
        // per joint: (2 lam_j) (rd_j - qd_j) and (lam_j lam_j) (e_j + y_j), the Python law's
        // operations in its order
        const auto lam = p.lam.array();
        taubar = (rdd.transpose().array() + (2.0 * lam) * (rd.transpose() - qd).array()
                  + (lam * lam) * (e + y).array()).matrix();
        return model_torque(terms, q, qd, taubar, tau_);
      }

      const Vec & tau() const { return tau_; }

      /// x+ = A x + B e (sampled) or xdot = A x + B e (continuous), e of the last torque().
      void state_map(const Vec & x, Vec & out) const
      {
        out.noalias() = p.A * x;
        out.noalias() += p.B * e;
      }

      /// Mhat(q) of the last torque() (symmetric).
      const Mat & inertia() const { return terms.M(); }

      Terms terms;

    private:
      const FLLaw & p;
      Eigen::Index m;
      Vec e, y, taubar, tau_;
    };
  };

  /// FLLaw with its torque clipped and K self-conditioned on the clipped torque (FLAWForm).
  struct FLAWLaw : FLLaw
  {
    Mat L;      // (m, n) conditioning gain B D^-1
    Vec limit;  // (n,) torque limits [N m]

    static constexpr const char * name = "FLAWLaw";
    static constexpr const char * doc = "FLLaw clipped, K conditioned on the clip (FLAWForm).";
    static constexpr auto fields()
    {
      return std::tuple_cat(FLLaw::fields(), std::make_tuple(field("L", &FLAWLaw::L),
                                                             field("limit", &FLAWLaw::limit)));
    }

    void check(Eigen::Index n) const
    {
      FLLaw::check(n);
      if (L.rows() != A.rows() || L.cols() != n || limit.size() != n)
        throw std::invalid_argument("L must be m x nq and limit of size nq");
    }

    template<class Terms>
    class Eval
    {
    public:
      Eval(const FLAWLaw & law, const Tree & nominal)
      : fl(law, nominal)
      , terms(fl.terms)
      , p(law)
      , tau_(nominal.na())
      , dy(nominal.na())
      {
      }

      /// FLLaw's torque clipped to the limits; keeps the correction dy if a joint clipped.
      template<typename R1, typename R2, typename R3>
      int torque(
        const Vec & q, const Vec & qd, const R1 & r, const R2 & rd, const R3 & rdd, const Vec & x)
      {
        if (const int st = fl.torque(q, qd, r, rd, rdd, x); st != kOk)
          return st;
        const Vec & raw = fl.tau();
        tau_ = raw.cwiseMax(-p.limit).cwiseMin(p.limit);
        clipped = tau_ != raw;
        if (clipped)
          dy = (fl.inertia().partialPivLu().solve(tau_ - raw).array()
                / (p.lam.array() * p.lam.array())).matrix();
        return kOk;
      }

      const Vec & tau() const { return tau_; }

      /// FLLaw's state map, plus L dy after a torque() that clipped.
      void state_map(const Vec & x, Vec & out) const
      {
        fl.state_map(x, out);
        if (clipped)
          out.noalias() += p.L * dy;
      }

    private:
      typename FLLaw::template Eval<Terms> fl;

    public:
      Terms & terms;

    private:
      const FLAWLaw & p;
      Vec tau_, dy;
      bool clipped = false;
    };
  };

  /// Feedback linearization with a two-degrees-of-freedom controller on v = [e; qd]
  /// (TwoDOFForm).
  struct TwoDOFLaw
  {
    Vec lam;         // (n,) [rad/s], per joint
    Mat A, B, C, D;  // (m, m), (m, 2n), (n, m), (n, 2n)

    static constexpr const char * name = "TwoDOFLaw";
    static constexpr const char * doc = "FL + 2-DOF controller on [e; qd] (TwoDOFForm).";
    static constexpr auto fields()
    {
      return std::make_tuple(field("lam", &TwoDOFLaw::lam), field("A", &TwoDOFLaw::A),
                             field("B", &TwoDOFLaw::B), field("C", &TwoDOFLaw::C),
                             field("D", &TwoDOFLaw::D));
    }

    Eigen::Index nx() const { return A.rows(); }

    void check(Eigen::Index n) const
    {
      const Eigen::Index m = A.rows();
      if (
        A.cols() != m || B.rows() != m || B.cols() != 2 * n || C.rows() != n || C.cols() != m
        || D.rows() != n || D.cols() != 2 * n)
        throw std::invalid_argument("2-DOF controller matrices have inconsistent shapes");
      if (lam.size() != n)
        throw std::invalid_argument("lam must have one entry per joint");
    }

    /// FLLaw's nominal-model calls (CRBA and nonLinearEffects).
    static void model_calls(Workspace & nominal, const Vec & q, const Vec & qd, Vec & tau,
                            double & sink)
    {
      FLLaw::model_calls(nominal, q, qd, tau, sink);
    }

    template<class Terms>
    class Eval
    {
    public:
      Eval(const TwoDOFLaw & law, const Tree & nominal)
      : terms(nominal)
      , p(law)
      , m(law.nx())
      , n(nominal.na())
      , v(2 * n)
      , tauhat(n)
      , taubar(n)
      , tau_(n)
      {
      }

      /// Torque at (q, qd) for reference row r and law state x (rd, rdd unread); keeps v.
      template<typename R1, typename R2, typename R3>
      int torque(
        const Vec & q, const Vec & qd, const R1 & r, const R2 &, const R3 &, const Vec & x)
      {
        v.head(n) = r.transpose() - q;
        v.tail(n) = qd;
        // tauhat = q + C x + D v, the Python law's sums in its order
        tauhat = q;
        if (m > 0)
          tauhat.noalias() += p.C * x;
        tauhat.noalias() += p.D * v;
        // per joint: (lam_j lam_j) (tauhat_j - q_j) - (2 lam_j) qd_j
        const auto lam = p.lam.array();
        taubar = ((lam * lam) * (tauhat - q).array() - (2.0 * lam) * qd.array()).matrix();
        return model_torque(terms, q, qd, taubar, tau_);
      }

      const Vec & tau() const { return tau_; }

      /// x+ = A x + B v (sampled) or xdot = A x + B v (continuous), v of the last torque().
      void state_map(const Vec & x, Vec & out) const
      {
        out.noalias() = p.A * x;
        out.noalias() += p.B * v;
      }

      Terms terms;

    private:
      const TwoDOFLaw & p;
      Eigen::Index m, n;
      Vec v, tauhat, taubar, tau_;
    };
  };

  /// PD + gravity compensation (PDForm).
  struct PDLaw
  {
    Mat Kp, Kd;  // (n, n) [N m/rad], [N m s/rad]

    static constexpr const char * name = "PDLaw";
    static constexpr const char * doc = "PD + gravity compensation (PDForm).";
    static constexpr auto fields()
    {
      return std::make_tuple(field("Kp", &PDLaw::Kp), field("Kd", &PDLaw::Kd));
    }

    Eigen::Index nx() const { return 0; }

    void check(Eigen::Index n) const
    {
      if (Kp.rows() != n || Kp.cols() != n || Kd.rows() != n || Kd.cols() != n)
        throw std::invalid_argument("Kp and Kd must be nq x nq");
    }

    static void model_calls(Workspace & nominal, const Vec & q, const Vec &, Vec & tau,
                            double &)
    {
      tau = gravity(nominal, q);
    }

    template<class Terms>
    class Eval
    {
    public:
      Eval(const PDLaw & law, const Tree & nominal)
      : terms(nominal)
      , p(law)
      , e(nominal.na())
      , tau_(e.size())
      {
      }

      template<typename R1, typename R2, typename R3>
      int torque(
        const Vec & q, const Vec & qd, const R1 & r, const R2 & rd, const R3 &, const Vec &)
      {
        e = r.transpose() - q;
        tau_.noalias() = p.Kp * e;
        tau_.noalias() += p.Kd * (rd.transpose() - qd);
        if (const int st = terms.gravity(q); st != kOk)
          return st;
        tau_ += terms.G();
        return kOk;
      }

      const Vec & tau() const { return tau_; }

      /// A static law has no state (the loops never call this with nx = 0).
      void state_map(const Vec &, Vec &) const {}

      Terms terms;

    private:
      const PDLaw & p;
      Vec e, tau_;
    };
  };
} // namespace rrr_pin

/// The compiled laws, once: X(Law) for each. Expanded by the bindings (module.cpp), the rollout's
/// instantiations (rollout.hpp), the batch's (batch.hpp) and its bindings (batch_bind.cpp).
#define RRR_PIN_LAWS(X) X(FLLaw) X(FLAWLaw) X(PDLaw) X(TwoDOFLaw)
