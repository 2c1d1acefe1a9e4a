// Compiled closed-loop rollout: plant integration with Pinocchio's ABA and the built-in control
// laws that declare a compiled form (rrr_pin.controllers.CompiledForm), all in one C++ loop (no
// return to Python per step). Python entry point: rrr_pin.compiled.run_compiled.
//
// The algorithm is the Python reference engine's (rrr_pin.simulation._python_sampled and
// _python_continuous), operation for operation; tests/test_engines.py pins the two together.
// Laws implemented here, exactly as in rrr_pin.controllers:
//   kFL: taubar = rdd + 2 lam (rd - qd) + lam^2 (e + y), y = C x + D e,
//        tau = Mhat(q) taubar + nle_hat(q, qd); state: xdot = A x + B e (continuous) or
//        x+ = A x + B e after the output (sampled, A..D already discrete).
//   kPD: tau = Kp e + Kd (rd - qd) + Ghat(q); no state.
// The reference arrives sampled on the grid where the law is evaluated (one row per control
// instant for sampled laws, per half RK4 step for continuous laws), so any reference runs here.
//
// ABI: this file is compiled against the Pinocchio headers of the `libpinocchio` wheel and links
// its shared libraries, whose SONAME carries no version. The package pins one exact `pin`
// version at build and run time, and rrr_pin.compiled compares `pinocchio_version()` with the
// imported pinocchio before the first call.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <tuple>

// The wheel's libraries are built for baseline x86-64 (16-byte Eigen alignment). Code built with
// other alignment settings (e.g. -march=native -> 32 bytes) passes misaligned objects to them
// and crashes at the first call; CMakeLists.txt sets these, this guard catches a bypass.
#if !defined(EIGEN_MAX_ALIGN_BYTES) || EIGEN_MAX_ALIGN_BYTES != 16
  #error "rrr_pin._rollout must be compiled with EIGEN_MAX_ALIGN_BYTES=16 (see CMakeLists.txt)"
#endif

#include <Eigen/Core>

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody.hpp>
#include <pinocchio/serialization.hpp>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>

namespace nb = nanobind;

namespace
{
  using Model = pinocchio::Model;
  using Data = pinocchio::Data;
  using Vec = Eigen::VectorXd;
  using Mat = Eigen::MatrixXd;
  using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  using CRowMat = nb::DRef<const RowMat>;
  // Eigen::Ref arguments select the explicit template instantiations compiled into
  // libpinocchio_default (the same code the Python bindings call).
  using CRef = Eigen::Ref<const Vec>;

  /// A deserialized pinocchio::Model; read-only once loaded (each call makes its own Data), so
  /// one instance may serve concurrent rollouts.
  struct CompiledModel
  {
    Model model;

    explicit CompiledModel(const std::string & serialized)
    {
      model.loadFromString(serialized);
    }

    int nq() const
    {
      return model.nq;
    }

    std::string save() const
    {
      return model.saveToString();
    }
  };

  /// A model with its workspace, for one call.
  struct Workspace
  {
    const Model & model;
    Data data;

    explicit Workspace(const CompiledModel & m)
    : model(m.model)
    , data(m.model)
    {
    }
  };

  inline const Vec & aba(Workspace & w, const Vec & q, const Vec & v, const Vec & tau)
  {
    return pinocchio::aba(w.model, w.data, CRef(q), CRef(v), CRef(tau));
  }

  inline const Mat & crba(Workspace & w, const Vec & q)
  {
    return pinocchio::crba(w.model, w.data, CRef(q));
  }

  inline const Vec & nle(Workspace & w, const Vec & q, const Vec & v)
  {
    return pinocchio::nonLinearEffects(w.model, w.data, CRef(q), CRef(v));
  }

  inline const Vec & gravity(Workspace & w, const Vec & q)
  {
    return pinocchio::computeGeneralizedGravity(w.model, w.data, CRef(q));
  }

  /// Law kinds, mirrored in rrr_pin.compiled.
  enum Kind : int
  {
    kFL = 0,
    kPD = 1,
  };

  /// Divergence reasons, mirrored in rrr_pin.compiled (same order of tests as
  /// rrr_pin.simulation.diverged_joint: non-finite, then speed, then limits).
  enum Reason : int
  {
    kOk = -1,
    kNonFinite = 0,
    kSpeed = 1,
    kLimits = 2,
  };

  struct Divergence
  {
    int joint = -1;
    int reason = kOk;
  };

  inline Divergence diverged(
    const Vec & q, const Vec & qd, const Vec & lower, const Vec & upper, double vlim)
  {
    const Eigen::Index n = q.size();
    for (Eigen::Index j = 0; j < n; ++j)
      if (!std::isfinite(q[j]) || !std::isfinite(qd[j]))
        return {static_cast<int>(j), kNonFinite};
    for (Eigen::Index j = 0; j < n; ++j)
      if (std::abs(qd[j]) > vlim)
        return {static_cast<int>(j), kSpeed};
    for (Eigen::Index j = 0; j < n; ++j)
      if (q[j] < lower[j] || q[j] > upper[j])
        return {static_cast<int>(j), kLimits};
    return {};
  }

  /// The law of a compiled form, evaluated on the nominal model.
  struct Law
  {
    int kind;
    Workspace nominal;
    double lam;
    const Mat &A, &B, &C, &D, &Kp, &Kd;
    Eigen::Index n, m;
    Vec e, y, taubar, tau;
    Mat M;

    Law(
      int kind_, const CompiledModel & nominal_model, double lam_, const Mat & A_,
      const Mat & B_, const Mat & C_, const Mat & D_, const Mat & Kp_, const Mat & Kd_)
    : kind(kind_)
    , nominal(nominal_model)
    , lam(lam_)
    , A(A_)
    , B(B_)
    , C(C_)
    , D(D_)
    , Kp(Kp_)
    , Kd(Kd_)
    , n(nominal_model.model.nq)
    , m(A_.rows())
    , e(n)
    , y(n)
    , taubar(n)
    , tau(n)
    , M(n, n)
    {
    }

    /// Torque at (q, qd) for reference row (r, rd, rdd) and law state x; leaves e in `e`.
    template<typename R1, typename R2, typename R3>
    const Vec & torque(
      const Vec & q, const Vec & qd, const R1 & r, const R2 & rd, const R3 & rdd, const Vec & x)
    {
      e = r.transpose() - q;
      if (kind == kFL)
      {
        y.noalias() = D * e;
        if (m > 0)
          y.noalias() += C * x;
        taubar = rdd.transpose() + 2.0 * lam * (rd.transpose() - qd) + lam * lam * (e + y);
        // Feedback linearization, eq. (8), with the nominal model; crba fills the upper
        // triangle.
        M = crba(nominal, q);
        M.triangularView<Eigen::StrictlyLower>() = M.transpose();
        tau.noalias() = M * taubar;
        tau += nle(nominal, q, qd);
      }
      else
      {
        tau.noalias() = Kp * e;
        tau.noalias() += Kd * (rd.transpose() - qd);
        tau += gravity(nominal, q);
      }
      return tau;
    }

    /// x+ = A x + B e (sampled) or xdot = A x + B e (continuous), with `e` of the last torque().
    void state_map(const Vec & x, Vec & out) const
    {
      out.noalias() = A * x;
      out.noalias() += B * e;
    }
  };

  using RolloutResult = std::tuple<RowMat, RowMat, RowMat, std::int64_t, int, int>;

  RolloutResult rollout(
    const CompiledModel & plant_model,
    const CompiledModel & nominal_model,
    int kind,
    bool sampled,
    double lam,
    const Mat & A,
    const Mat & B,
    const Mat & C,
    const Mat & D,
    const Mat & Kp,
    const Mat & Kd,
    CRowMat R,
    CRowMat RD,
    CRowMat RDD,
    const Vec & q0,
    const Vec & qd0,
    const Vec & x0,
    const Vec & lower,
    const Vec & upper,
    double vlim,
    double h,
    int substeps,
    std::int64_t n_steps)
  {
    const Eigen::Index n = plant_model.model.nq;
    const Eigen::Index m = A.rows();
    if (nominal_model.model.nq != n)
      throw std::invalid_argument("plant and nominal models differ in nq");
    if (kind != kFL && kind != kPD)
      throw std::invalid_argument("unknown law kind");
    if (
      A.cols() != m || B.rows() != m || B.cols() != n || C.rows() != n || C.cols() != m
      || D.rows() != n || D.cols() != n || x0.size() != m)
      throw std::invalid_argument("controller matrices have inconsistent shapes");
    if (kind == kPD && (Kp.rows() != n || Kp.cols() != n || Kd.rows() != n || Kd.cols() != n))
      throw std::invalid_argument("Kp and Kd must be nq x nq");
    if (substeps < 1 || n_steps < 1 || !(h > 0.0))
      throw std::invalid_argument("substeps >= 1, n_steps >= 1 and h > 0 are required");
    const std::int64_t rows = sampled ? n_steps + 1 : 2 * n_steps + 1;
    if (
      R.rows() != rows || RD.rows() != rows || RDD.rows() != rows || R.cols() != n
      || RD.cols() != n || RDD.cols() != n)
      throw std::invalid_argument("reference arrays have the wrong shape");
    if (q0.size() != n || qd0.size() != n || lower.size() != n || upper.size() != n)
      throw std::invalid_argument("state and limit vectors must have nq entries");

    const double nan = std::numeric_limits<double>::quiet_NaN();
    RowMat Q = RowMat::Constant(n_steps + 1, n, nan);
    RowMat QD = RowMat::Constant(n_steps + 1, n, nan);
    RowMat TAU = RowMat::Constant(n_steps + 1, n, nan);
    std::int64_t bad_step = -1;
    Divergence bad;

    {
      nb::gil_scoped_release release;

      Workspace plant(plant_model);
      Law law(kind, nominal_model, lam, A, B, C, D, Kp, Kd);
      Vec q = q0, qd = qd0, x = x0, xn(m), tau(n);
      Vec a1(n), a2(n), a3(n), a4(n), v2(n), v3(n), v4(n), qs(n);
      Vec x1(m), x2(m), x3(m), x4(m), xs(m);
      const double h2 = 0.5 * h, h6 = h / 6.0;
      Q.row(0) = q.transpose();
      QD.row(0) = qd.transpose();

      if (sampled)
      {
        for (std::int64_t k = 0; k < n_steps; ++k)
        {
          tau = law.torque(q, qd, R.row(k), RD.row(k), RDD.row(k), x);
          if (m > 0)
          {
            law.state_map(x, xn);
            x.swap(xn);
          }
          TAU.row(k) = tau.transpose();
          // Plant: S classical RK4 steps of h on (q, qd), tau held.
          for (int s = 0; s < substeps; ++s)
          {
            a1 = aba(plant, q, qd, tau);
            v2 = qd + h2 * a1;
            qs = q + h2 * qd;
            a2 = aba(plant, qs, v2, tau);
            v3 = qd + h2 * a2;
            qs = q + h2 * v2;
            a3 = aba(plant, qs, v3, tau);
            v4 = qd + h * a3;
            qs = q + h * v3;
            a4 = aba(plant, qs, v4, tau);
            q += h6 * (qd + 2.0 * (v2 + v3) + v4);
            qd += h6 * (a1 + 2.0 * (a2 + a3) + a4);
          }
          Q.row(k + 1) = q.transpose();
          QD.row(k + 1) = qd.transpose();
          bad = diverged(q, qd, lower, upper, vlim);
          if (bad.reason != kOk)
          {
            bad_step = k + 1;
            break;
          }
        }
        if (bad_step < 0)
          TAU.row(n_steps) = TAU.row(n_steps - 1);
      }
      else
      {
        // Continuous-time law: (q, qd, x) integrated together, the law at every RK4 stage.
        for (std::int64_t k = 0;; ++k)
        {
          const std::int64_t i = 2 * k;
          tau = law.torque(q, qd, R.row(i), RD.row(i), RDD.row(i), x);
          if (m > 0)
            law.state_map(x, x1);
          a1 = aba(plant, q, qd, tau);
          TAU.row(k) = tau.transpose();
          if (k == n_steps)
            break;
          v2 = qd + h2 * a1;
          qs = q + h2 * qd;
          if (m > 0)
            xs = x + h2 * x1;
          a2 = aba(plant, qs, v2, law.torque(qs, v2, R.row(i + 1), RD.row(i + 1), RDD.row(i + 1), xs));
          if (m > 0)
            law.state_map(xs, x2);
          v3 = qd + h2 * a2;
          qs = q + h2 * v2;
          if (m > 0)
            xs = x + h2 * x2;
          a3 = aba(plant, qs, v3, law.torque(qs, v3, R.row(i + 1), RD.row(i + 1), RDD.row(i + 1), xs));
          if (m > 0)
            law.state_map(xs, x3);
          v4 = qd + h * a3;
          qs = q + h * v3;
          if (m > 0)
            xs = x + h * x3;
          a4 = aba(plant, qs, v4, law.torque(qs, v4, R.row(i + 2), RD.row(i + 2), RDD.row(i + 2), xs));
          if (m > 0)
            law.state_map(xs, x4);
          q += h6 * (qd + 2.0 * (v2 + v3) + v4);
          qd += h6 * (a1 + 2.0 * (a2 + a3) + a4);
          if (m > 0)
            x += h6 * (x1 + 2.0 * (x2 + x3) + x4);
          Q.row(k + 1) = q.transpose();
          QD.row(k + 1) = qd.transpose();
          bad = diverged(q, qd, lower, upper, vlim);
          if (bad.reason != kOk)
          {
            bad_step = k + 1;
            break;
          }
        }
      }
    }
    return {std::move(Q), std::move(QD), std::move(TAU), bad_step, bad.joint, bad.reason};
  }

  /// Sampled rollout with plant effects (rrr_pin.effects), operation for operation as
  /// rrr_pin.simulation._python_effects: sensor (noise, quantization) -> law -> saturation ->
  /// delay (delay_steps plant sub-steps) -> first-order actuator (wa > 0) -> flexible joint
  /// (Kf non-empty) -> arm with friction (Fv non-empty). Empty vectors / zero-row matrices
  /// switch an effect off. The ideal loop stays in rollout() above, untouched.
  RolloutResult rollout_effects(
    const CompiledModel & plant_model,
    const CompiledModel & nominal_model,
    int kind,
    double lam,
    const Mat & A,
    const Mat & B,
    const Mat & C,
    const Mat & D,
    const Mat & Kp,
    const Mat & Kd,
    CRowMat R,
    CRowMat RD,
    CRowMat RDD,
    const Vec & q0,
    const Vec & qd0,
    const Vec & x0,
    const Vec & lower,
    const Vec & upper,
    double vlim,
    double h,
    int substeps,
    std::int64_t n_steps,
    std::int64_t delay_steps,
    double wa,
    const Vec & limit,
    const Vec & Fv,
    const Vec & Fc,
    double veps,
    CRowMat noise_q,
    CRowMat noise_qd,
    double quantum,
    const Vec & Bm,
    const Vec & Kf,
    const Vec & Df)
  {
    const Eigen::Index n = plant_model.model.nq;
    const Eigen::Index m = A.rows();
    if (nominal_model.model.nq != n)
      throw std::invalid_argument("plant and nominal models differ in nq");
    if (kind != kFL && kind != kPD)
      throw std::invalid_argument("unknown law kind");
    if (
      A.cols() != m || B.rows() != m || B.cols() != n || C.rows() != n || C.cols() != m
      || D.rows() != n || D.cols() != n || x0.size() != m)
      throw std::invalid_argument("controller matrices have inconsistent shapes");
    if (kind == kPD && (Kp.rows() != n || Kp.cols() != n || Kd.rows() != n || Kd.cols() != n))
      throw std::invalid_argument("Kp and Kd must be nq x nq");
    if (substeps < 1 || n_steps < 1 || !(h > 0.0) || delay_steps < 0)
      throw std::invalid_argument("substeps >= 1, n_steps >= 1, h > 0, delay_steps >= 0");
    const std::int64_t rows = n_steps + 1;
    if (
      R.rows() != rows || RD.rows() != rows || RDD.rows() != rows || R.cols() != n
      || RD.cols() != n || RDD.cols() != n)
      throw std::invalid_argument("reference arrays have the wrong shape");
    if (q0.size() != n || qd0.size() != n || lower.size() != n || upper.size() != n)
      throw std::invalid_argument("state and limit vectors must have nq entries");
    const bool sat = limit.size() > 0, fric = Fv.size() > 0, flex = Kf.size() > 0;
    const bool has_nq = noise_q.rows() > 0, has_nqd = noise_qd.rows() > 0, act = wa > 0.0;
    if (
      (sat && limit.size() != n) || (fric && Fc.size() != n) || (fric && Fv.size() != n)
      || (flex && (Kf.size() != n || Bm.size() != n || Df.size() != n))
      || (has_nq && (noise_q.rows() != n_steps || noise_q.cols() != n))
      || (has_nqd && (noise_qd.rows() != n_steps || noise_qd.cols() != n)))
      throw std::invalid_argument("effect arrays have the wrong shape");

    const double nan = std::numeric_limits<double>::quiet_NaN();
    RowMat Q = RowMat::Constant(n_steps + 1, n, nan);
    RowMat QD = RowMat::Constant(n_steps + 1, n, nan);
    RowMat TAU = RowMat::Constant(n_steps + 1, n, nan);
    RowMat U(n_steps, n);
    std::int64_t bad_step = -1;
    Divergence bad;

    {
      nb::gil_scoped_release release;

      Workspace plant(plant_model);
      Law law(kind, nominal_model, lam, A, B, C, D, Kp, Kd);
      Vec q = q0, qd = qd0, x = x0, xn(m), tau(n), qm(n), qdm(n), u(n);
      Vec a1(n), a2(n), a3(n), a4(n), v2(n), v3(n), v4(n), qs(n);
      Vec act_s(n), b1(n), b2(n), b3(n), b4(n), a = Vec::Zero(n);
      Vec th = Vec::Zero(n), thd = Vec::Zero(n), th_s(n), w2(n), w3(n), w4(n);
      Vec c1(n), c2(n), c3(n), c4(n), tj(n), tm(n);
      const double h2 = 0.5 * h, h6 = h / 6.0;

      // Link acceleration `acc`, actuator derivative `ad`, motor acceleration `thdd`.
      auto f = [&](const Vec & qq, const Vec & vv, const Vec & aa, const Vec & tt,
                   const Vec & ww, Vec & acc, Vec & ad, Vec & thdd) {
        tm = act ? aa : u;
        if (flex)
        {
          tj = Kf.cwiseProduct(tt - qq) + Df.cwiseProduct(ww - vv);
          thdd = (tm - tj).cwiseQuotient(Bm);
        }
        else
          tj = tm;
        if (fric)
        {
          Vec fr(n);
          for (Eigen::Index j = 0; j < n; ++j)
            fr[j] = Fv[j] * vv[j] + Fc[j] * std::tanh(vv[j] / veps);
          tj = tj - fr;
        }
        if (act)
          ad = wa * (u - aa);
        acc = aba(plant, qq, vv, tj);
      };

      Q.row(0) = q.transpose();
      QD.row(0) = qd.transpose();
      for (std::int64_t k = 0; k < n_steps; ++k)
      {
        qm = q;
        qdm = qd;
        if (has_nq)
          qm = qm + noise_q.row(k).transpose();
        if (quantum > 0.0)
          for (Eigen::Index j = 0; j < n; ++j)
            qm[j] = quantum * std::nearbyint(qm[j] / quantum);
        if (has_nqd)
          qdm = qdm + noise_qd.row(k).transpose();
        tau = law.torque(qm, qdm, R.row(k), RD.row(k), RDD.row(k), x);
        if (m > 0)
        {
          law.state_map(x, xn);
          x.swap(xn);
        }
        if (sat)
          for (Eigen::Index j = 0; j < n; ++j)
            tau[j] = std::min(std::max(tau[j], -limit[j]), limit[j]);
        U.row(k) = tau.transpose();
        TAU.row(k) = tau.transpose();
        if (k == 0)
        {
          if (act)
            a = tau;
          if (flex)
          {
            th = q + tau.cwiseQuotient(Kf);
            thd = qd;
          }
        }
        for (int s = 0; s < substeps; ++s)
        {
          const std::int64_t j = k * substeps + s - delay_steps;
          u = U.row(j >= 0 ? j / substeps : 0).transpose();
          f(q, qd, a, th, thd, a1, b1, c1);
          v2 = qd + h2 * a1;
          if (act)
            act_s = a + h2 * b1;
          if (flex)
          {
            th_s = th + h2 * thd;
            w2 = thd + h2 * c1;
          }
          qs = q + h2 * qd;
          f(qs, v2, act_s, th_s, w2, a2, b2, c2);
          v3 = qd + h2 * a2;
          if (act)
            act_s = a + h2 * b2;
          if (flex)
          {
            th_s = th + h2 * w2;
            w3 = thd + h2 * c2;
          }
          qs = q + h2 * v2;
          f(qs, v3, act_s, th_s, w3, a3, b3, c3);
          v4 = qd + h * a3;
          if (act)
            act_s = a + h * b3;
          if (flex)
          {
            th_s = th + h * w3;
            w4 = thd + h * c3;
          }
          qs = q + h * v3;
          f(qs, v4, act_s, th_s, w4, a4, b4, c4);
          q += h6 * (qd + 2.0 * (v2 + v3) + v4);
          qd += h6 * (a1 + 2.0 * (a2 + a3) + a4);
          if (act)
            a += h6 * (b1 + 2.0 * (b2 + b3) + b4);
          if (flex)
          {
            th += h6 * (thd + 2.0 * (w2 + w3) + w4);
            thd += h6 * (c1 + 2.0 * (c2 + c3) + c4);
          }
        }
        Q.row(k + 1) = q.transpose();
        QD.row(k + 1) = qd.transpose();
        bad = diverged(q, qd, lower, upper, vlim);
        if (bad.reason != kOk)
        {
          bad_step = k + 1;
          break;
        }
      }
      if (bad_step < 0)
        TAU.row(n_steps) = TAU.row(n_steps - 1);
    }
    return {std::move(Q), std::move(QD), std::move(TAU), bad_step, bad.joint, bad.reason};
  }

  /// Wall time [s] of the Pinocchio calls one rollout of a law needs, with trivial glue:
  /// sampled, per control step: the law's calls (kFL: CRBA + nonLinearEffects; kPD: gravity) on
  /// the nominal model and 4*S ABA on the plant; continuous, per RK4 step: 4 x (the law's calls
  /// + one ABA).
  double floor_timing(
    const CompiledModel & plant_model,
    const CompiledModel & nominal_model,
    int kind,
    bool sampled,
    int substeps,
    std::int64_t n_steps)
  {
    if (nominal_model.model.nq != plant_model.model.nq)
      throw std::invalid_argument("plant and nominal models differ in nq");
    if (substeps < 1 || n_steps < 0)
      throw std::invalid_argument("substeps must be >= 1 and n_steps >= 0");
    nb::gil_scoped_release release;
    Workspace plant(plant_model), nominal(nominal_model);
    const Eigen::Index n = plant.model.nq;
    Vec q = Vec::Constant(n, 0.3), qd = Vec::Constant(n, 0.1), tau = Vec::Zero(n);
    double sink = 0.0;
    auto law = [&]() {
      if (kind == kFL)
      {
        sink += crba(nominal, q)(0, 0);
        tau = nle(nominal, q, qd);
      }
      else
        tau = gravity(nominal, q);
    };
    const auto t0 = std::chrono::steady_clock::now();
    for (std::int64_t k = 0; k < n_steps; ++k)
    {
      if (sampled)
      {
        law();
        for (int s = 0; s < 4 * substeps; ++s)
          sink += aba(plant, q, qd, tau)[0];
      }
      else
        for (int s = 0; s < 4; ++s)
        {
          law();
          sink += aba(plant, q, qd, tau)[0];
        }
    }
    const auto t1 = std::chrono::steady_clock::now();
    if (!std::isfinite(sink))
      throw std::runtime_error("floor_timing: non-finite result");
    return std::chrono::duration<double>(t1 - t0).count();
  }

} // namespace

NB_MODULE(_rollout, mod)
{
  mod.doc() = "Compiled closed-loop rollout on Pinocchio (private; use rrr_pin.compiled).";

  nb::class_<CompiledModel>(mod, "CompiledModel")
    .def(
      nb::init<const std::string &>(), nb::arg("serialized"),
      "Load a model from pinocchio.Model.saveToString() text.")
    .def_prop_ro("nq", &CompiledModel::nq)
    .def("save", &CompiledModel::save, "The model re-serialized with saveToString().");

  mod.def(
    "rollout", &rollout, nb::arg("plant"), nb::arg("nominal"), nb::arg("kind"),
    nb::arg("sampled"), nb::arg("lam"), nb::arg("A"), nb::arg("B"), nb::arg("C"), nb::arg("D"),
    nb::arg("Kp"), nb::arg("Kd"), nb::arg("R"), nb::arg("RD"), nb::arg("RDD"), nb::arg("q0"),
    nb::arg("qd0"), nb::arg("x0"), nb::arg("lower"), nb::arg("upper"), nb::arg("vlim"),
    nb::arg("h"), nb::arg("substeps"), nb::arg("n_steps"),
    "Run the closed loop; returns (q, qd, tau, bad_step, bad_joint, reason).");

  mod.def(
    "rollout_effects", &rollout_effects, nb::arg("plant"), nb::arg("nominal"), nb::arg("kind"),
    nb::arg("lam"), nb::arg("A"), nb::arg("B"), nb::arg("C"), nb::arg("D"), nb::arg("Kp"),
    nb::arg("Kd"), nb::arg("R"), nb::arg("RD"), nb::arg("RDD"), nb::arg("q0"), nb::arg("qd0"),
    nb::arg("x0"), nb::arg("lower"), nb::arg("upper"), nb::arg("vlim"), nb::arg("h"),
    nb::arg("substeps"), nb::arg("n_steps"), nb::arg("delay_steps"), nb::arg("wa"),
    nb::arg("limit"), nb::arg("Fv"), nb::arg("Fc"), nb::arg("veps"), nb::arg("noise_q"),
    nb::arg("noise_qd"), nb::arg("quantum"), nb::arg("Bm"), nb::arg("Kf"), nb::arg("Df"),
    "Sampled closed loop with plant effects; returns (q, qd, tau, bad_step, bad_joint, reason).");

  mod.def(
    "floor_timing", &floor_timing, nb::arg("plant"), nb::arg("nominal"), nb::arg("kind"),
    nb::arg("sampled"), nb::arg("substeps"), nb::arg("n_steps"),
    "Wall time [s] of the bare Pinocchio calls of a rollout.");

  mod.def("pinocchio_version", []() { return std::string(PINOCCHIO_VERSION); });
  mod.def("eigen_version", []() {
    return std::to_string(EIGEN_WORLD_VERSION) + "." + std::to_string(EIGEN_MAJOR_VERSION) + "."
           + std::to_string(EIGEN_MINOR_VERSION);
  });
}
