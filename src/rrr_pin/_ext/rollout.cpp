// The loops of a compiled rollout (see rollout.hpp): a sampled law on the ideal plant or with
// the plant effects of effects.hpp (one template, two instances), and a continuous law
// integrated with the arm. Both take
// their RK4 stages from rk4.hpp.
#include "rollout.hpp"

#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <type_traits>

#include "rk4.hpp"

namespace rrr_pin
{
  void check_inputs(const RolloutInputs & in, Eigen::Index n, Eigen::Index nx)
  {
    if (in.x0.size() != nx)
      throw std::invalid_argument("x0 must have the law's nx entries");
    if (in.substeps < 1 || in.n_steps < 1 || !(in.h > 0.0))
      throw std::invalid_argument("substeps >= 1, n_steps >= 1 and h > 0 are required");
    const std::int64_t rows = in.sampled ? in.n_steps + 1 : 2 * in.n_steps + 1;
    if (
      in.R.rows() != rows || in.RD.rows() != rows || in.RDD.rows() != rows || in.R.cols() != n
      || in.RD.cols() != n || in.RDD.cols() != n)
      throw std::invalid_argument("reference arrays have the wrong shape");
  }

  namespace
  {
    struct Divergence
    {
      int joint = -1;
      int reason = kOk;
    };

    Divergence diverged(
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

    /// Index of the first NaN or inf entry of a torque, or -1.
    int first_nonfinite(const Vec & tau)
    {
      for (Eigen::Index j = 0; j < tau.size(); ++j)
        if (!std::isfinite(tau[j]))
          return static_cast<int>(j);
      return -1;
    }

    void check_inputs(
      const CompiledModel & plant, const CompiledModel & nominal, Eigen::Index nx,
      const RolloutInputs & in)
    {
      const Eigen::Index n = plant.model.nq;
      if (nominal.model.nq != n)
        throw std::invalid_argument("plant and nominal models differ in nq");
      check_inputs(in, n, nx);
      if (
        in.q0.size() != n || in.qd0.size() != n || in.lower.size() != n || in.upper.size() != n)
        throw std::invalid_argument("state and limit vectors must have nq entries");
    }

    /// The sampled plant: the arm driven by the command u (held on the sub-step) through the
    /// actuator, the flexible joint and the friction of the effects.
    struct SampledPlant
    {
      Workspace arm;
      const Effects & fx;
      Parts parts;
      Vec u, tj, tm, fr;

      SampledPlant(const CompiledModel & model, const Effects & effects)
      : arm(model)
      , fx(effects)
      , parts(effects.parts())
      , u(model.model.nq)
      , tj(model.model.nq)
      , tm(model.model.nq)
      , fr(model.model.nq)
      {
      }

      void slope(const State & y, int, State & k)
      {
        k.q = y.qd;
        fx.joint_torque(y, u, k, tj, tm, fr);
        k.qd = aba(arm, y.q, y.qd, tj);
      }
    };

    /// The ideal sampled plant: the arm alone, driven by the held command u. The effects loop's
    /// SampledPlant with every effect off computes the same numbers; this one skips its copies.
    struct IdealPlant
    {
      Workspace arm;
      Parts parts;
      Vec u;

      explicit IdealPlant(const CompiledModel & model)
      : arm(model)
      , u(model.model.nq)
      {
      }

      void slope(const State & y, int, State & k)
      {
        k.q = y.qd;
        k.qd = aba(arm, y.q, y.qd, u);
      }
    };

    /// A continuous law and the arm, integrated together; the law at every RK4 stage, on the
    /// reference row of the stage's half step.
    template<class Eval>
    struct ContinuousLoop
    {
      Workspace arm;
      Eval & law;
      const RolloutInputs & in;
      Parts parts;
      std::int64_t k = 0;          // RK4 step
      const Vec * tau = nullptr;   // torque of the last slope
      int bad_joint = -1;          // first joint of a NaN or inf torque of the law, or -1

      void slope(const State & y, int point, State & d)
      {
        const std::int64_t i = 2 * k + point;
        tau = &law.torque(y.q, y.qd, in.R.row(i), in.RD.row(i), in.RDD.row(i), y.x);
        if (bad_joint < 0)
          bad_joint = first_nonfinite(*tau);
        if (parts.x)
          law.state_map(y.x, d.x);
        d.q = y.qd;
        d.qd = aba(arm, y.q, y.qd, *tau);
      }
    };

    struct Outputs
    {
      RowMat Q, QD, TAU;
      std::int64_t bad_step = -1;
      Divergence bad;

      Outputs(std::int64_t n_steps, Eigen::Index n)
      : Q(RowMat::Constant(n_steps + 1, n, std::numeric_limits<double>::quiet_NaN()))
      , QD(RowMat::Constant(n_steps + 1, n, std::numeric_limits<double>::quiet_NaN()))
      , TAU(RowMat::Constant(n_steps + 1, n, std::numeric_limits<double>::quiet_NaN()))
      {
      }

      /// Record the state after step k; false (and the divergence kept) if it diverged.
      bool record(std::int64_t k, const State & y, const RolloutInputs & in)
      {
        Q.row(k + 1) = y.q.transpose();
        QD.row(k + 1) = y.qd.transpose();
        bad = diverged(y.q, y.qd, in.lower, in.upper, in.vlim);
        if (bad.reason == kOk)
          return true;
        bad_step = k + 1;
        return false;
      }

      /// Stop at step k: the law returned a NaN or inf torque for joint j.
      void law_failed(std::int64_t k, int j)
      {
        bad_step = k;
        bad = {j, kLawTorque};
      }

      RolloutResult result()
      {
        return {std::move(Q), std::move(QD), std::move(TAU), bad_step, bad.joint, bad.reason};
      }
    };

    /// Sampled law: sensor -> law -> saturation -> delay -> plant (effects.hpp), S RK4 sub-steps
    /// of h per control period, the command held. Ideal = true: no effects (the same operations
    /// on the same numbers, without the sensor, saturation, delay-line and actuator copies).
    template<class Law, bool Ideal>
    RolloutResult sampled_loop(
      const CompiledModel & plant_model, const CompiledModel & nominal_model, const Law & law,
      const RolloutInputs & in, const Effects & fx)
    {
      const Eigen::Index n = plant_model.model.nq, m = law.nx();
      const std::int64_t N = in.n_steps;
      Outputs out(N, n);
      std::conditional_t<Ideal, IdealPlant, SampledPlant> plant = [&] {
        if constexpr (Ideal)
          return IdealPlant(plant_model);
        else
          return SampledPlant(plant_model, fx);
      }();
      typename Law::Eval eval(law, nominal_model);
      State y;
      y.q = in.q0;
      y.qd = in.qd0;
      Vec x = in.x0, xn(m), tau(n), qm(n), qdm(n);
      RK4 w;
      out.Q.row(0) = y.q.transpose();
      out.QD.row(0) = y.qd.transpose();
      for (std::int64_t k = 0; k < N; ++k)
      {
        if constexpr (Ideal)
          tau = eval.torque(y.q, y.qd, in.R.row(k), in.RD.row(k), in.RDD.row(k), x);
        else
        {
          fx.sense(k, y.q, y.qd, qm, qdm);
          tau = eval.torque(qm, qdm, in.R.row(k), in.RD.row(k), in.RDD.row(k), x);
        }
        if (m > 0)
        {
          eval.state_map(x, xn);
          x.swap(xn);
        }
        if (const int j = first_nonfinite(tau); j >= 0)  // the law's own output
        {
          out.TAU.row(k) = tau.transpose();
          out.law_failed(k, j);
          break;
        }
        if constexpr (!Ideal)
          fx.saturate(tau);
        if constexpr (Ideal)
        {
          out.TAU.row(k) = tau.transpose();
          plant.u = tau;
          for (int s = 0; s < in.substeps; ++s)
            rk4_step(plant, y, in.h, w);
        }
        else
        {
          out.TAU.row(k) = tau.transpose();  // also the delay line: row j = command j
          if (k == 0)
            fx.start(tau, y);
          for (int s = 0; s < in.substeps; ++s)
          {
            plant.u = out.TAU.row(fx.delayed_row(k, s, in.substeps)).transpose();
            rk4_step(plant, y, in.h, w);
          }
        }
        if (!out.record(k, y, in))
          break;
      }
      // The torque held on the last interval is also the one "at" the final sample.
      if (out.bad_step < 0)
        out.TAU.row(N) = out.TAU.row(N - 1);
      return out.result();
    }

    /// Continuous law: (q, qd, x) integrated together by RK4 steps of h.
    template<class Law>
    RolloutResult continuous_loop(
      const CompiledModel & plant_model, const CompiledModel & nominal_model, const Law & law,
      const RolloutInputs & in)
    {
      const Eigen::Index n = plant_model.model.nq;
      const std::int64_t N = in.n_steps;
      Outputs out(N, n);
      typename Law::Eval eval(law, nominal_model);
      ContinuousLoop<typename Law::Eval> loop{Workspace(plant_model), eval, in, Parts{}};
      loop.parts.x = law.nx() > 0;
      State y;
      y.q = in.q0;
      y.qd = in.qd0;
      y.x = in.x0;
      RK4 w;
      out.Q.row(0) = y.q.transpose();
      out.QD.row(0) = y.qd.transpose();
      for (std::int64_t k = 0;; ++k)
      {
        loop.k = k;
        loop.slope(y, 0, w.k1);
        out.TAU.row(k) = loop.tau->transpose();
        if (k < N)
          rk4_rest(loop, y, in.h, w);
        if (loop.bad_joint >= 0)
        {
          out.law_failed(k, loop.bad_joint);
          break;
        }
        if (k == N || !out.record(k, y, in))
          break;
      }
      return out.result();
    }
  } // namespace

  template<class Law>
  RolloutResult rollout(
    const CompiledModel & plant, const CompiledModel & nominal, const Law & law,
    const RolloutInputs & in, const Effects * fx)
  {
    const Eigen::Index n = plant.model.nq;
    if (!in.sampled && fx)
      throw std::invalid_argument("plant effects need a sampled law");
    check_inputs(plant, nominal, law.nx(), in);
    law.check(n);
    if (!in.sampled)
      return continuous_loop(plant, nominal, law, in);
    if (!fx)
      return sampled_loop<Law, true>(plant, nominal, law, in, Effects{});
    fx->check(n, in.n_steps);
    return sampled_loop<Law, false>(plant, nominal, law, in, *fx);
  }

  template<class Law>
  double floor_timing(
    const CompiledModel & plant_model, const CompiledModel & nominal_model, bool sampled,
    int substeps, std::int64_t n_steps)
  {
    if (nominal_model.model.nq != plant_model.model.nq)
      throw std::invalid_argument("plant and nominal models differ in nq");
    if (substeps < 1 || n_steps < 0)
      throw std::invalid_argument("substeps must be >= 1 and n_steps >= 0");
    Workspace plant(plant_model), nominal(nominal_model);
    const Eigen::Index n = plant.model.nq;
    Vec q = Vec::Constant(n, 0.3), qd = Vec::Constant(n, 0.1), tau = Vec::Zero(n);
    double sink = 0.0;
    const auto t0 = std::chrono::steady_clock::now();
    for (std::int64_t k = 0; k < n_steps; ++k)
    {
      if (sampled)
      {
        Law::model_calls(nominal, q, qd, tau, sink);
        for (int s = 0; s < 4 * substeps; ++s)
          sink += aba(plant, q, qd, tau)[0];
      }
      else
        for (int s = 0; s < 4; ++s)
        {
          Law::model_calls(nominal, q, qd, tau, sink);
          sink += aba(plant, q, qd, tau)[0];
        }
    }
    const auto t1 = std::chrono::steady_clock::now();
    if (!std::isfinite(sink))
      throw std::runtime_error("floor_timing: non-finite result");
    return std::chrono::duration<double>(t1 - t0).count();
  }

  template RolloutResult rollout<FLLaw>(
    const CompiledModel &, const CompiledModel &, const FLLaw &, const RolloutInputs &,
    const Effects *);
  template RolloutResult rollout<FLAWLaw>(
    const CompiledModel &, const CompiledModel &, const FLAWLaw &, const RolloutInputs &,
    const Effects *);
  template RolloutResult rollout<PDLaw>(
    const CompiledModel &, const CompiledModel &, const PDLaw &, const RolloutInputs &,
    const Effects *);
  template double floor_timing<FLLaw>(
    const CompiledModel &, const CompiledModel &, bool, int, std::int64_t);
  template double floor_timing<FLAWLaw>(
    const CompiledModel &, const CompiledModel &, bool, int, std::int64_t);
  template double floor_timing<PDLaw>(
    const CompiledModel &, const CompiledModel &, bool, int, std::int64_t);
} // namespace rrr_pin
