// The loops of a compiled rollout (see rollout.hpp), each written once over the plant (plant.hpp)
// and the law's model (terms.hpp): a sampled law on the ideal plant or with the plant effects of
// effects.hpp (one template, two instances), and a continuous law integrated with the plant. All
// take their RK4 steps from rk4.hpp.
#include "rollout.hpp"

#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "plant.hpp"
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

    void check_models(
      const Tree & plant, const Tree & nominal, Eigen::Index nx, const RolloutInputs & in)
    {
      const Eigen::Index n = plant.na();
      if (nominal.na() != n)
        throw std::invalid_argument("plant and nominal models differ in actuated coordinates");
      check_inputs(in, n, nx);
      if (in.q0.size() != plant.nv() || in.qd0.size() != plant.nv())
        throw std::invalid_argument("q0 and qd0 must be the plant's full state (nv entries)");
      if (in.lower.size() != n || in.upper.size() != n)
        throw std::invalid_argument("limit vectors must have one entry per actuated coordinate");
    }

    /// What a law's model keeps of its stop: nothing for a serial tree (it never stops).
    void keep_stop(const ArmTerms &, RolloutResult &) {}

    /// A closed chain's: the actuated q of the closure, its Newton seed and cond(J_p).
    void keep_stop(const ChainTerms & terms, RolloutResult & out)
    {
      out.law_q = terms.law_q;
      out.seed = terms.seed;
      out.value = terms.value;
    }

    /// The sampled plant: driven by the command u (held on the sub-step), directly (Ideal) or
    /// through the actuator, the flexible joint and the friction of the effects, on its
    /// actuated coordinates.
    template<class Plant, bool Ideal>
    struct Driven
    {
      Plant & plant;
      const Effects & fx;
      Parts parts;
      Vec u, tj, qa, qda;

      Driven(Plant & p, const Effects & effects, Eigen::Index n)
      : plant(p)
      , fx(effects)
      , parts(effects.parts())
      , u(n)
      , tj(n)
      , qa(n)
      , qda(n)
      {
      }

      void slope(const State & y, int, State & k)
      {
        k.q = y.qd;
        if constexpr (Ideal)
          k.qd = plant.acceleration(y.q, y.qd, u);
        else
        {
          const Measured m = plant.measure(y.q, y.qd, qa, qda);
          fx.joint_torque(m.q, m.qd, y, u, k, tj);
          k.qd = plant.acceleration(y.q, y.qd, tj);
        }
      }
    };

    /// A continuous law and the plant, integrated together; the law at every RK4 stage, on the
    /// reference row of the stage's half step.
    template<class Plant, class Eval>
    struct ContinuousLoop
    {
      Plant & plant;
      Eval & law;
      const RolloutInputs & in;
      RolloutResult & out;
      Parts parts;
      Vec qa, qda;
      std::int64_t k = 0;          // RK4 step
      const Vec * tau = nullptr;   // torque of the last slope
      int bad_joint = -1;          // first joint of a NaN or inf torque of the law, or -1
      int law_stop = kOk;          // the first stop of the law's model, or kOk

      void slope(const State & y, int point, State & d)
      {
        const std::int64_t i = 2 * k + point;
        const Measured m = plant.measure(y.q, y.qd, qa, qda);
        const int st = law.torque(m.q, m.qd, in.R.row(i), in.RD.row(i), in.RDD.row(i), y.x);
        if (st != kOk && law_stop == kOk)
        {
          law_stop = st;
          keep_stop(law.terms, out);
        }
        tau = &law.tau();
        if (bad_joint < 0)
          bad_joint = first_nonfinite(*tau);
        if (parts.x)
          law.state_map(y.x, d.x);
        d.q = y.qd;
        d.qd = plant.acceleration(y.q, y.qd, *tau);
      }
    };

    struct Outputs
    {
      RolloutResult r;

      Outputs(std::int64_t n_steps, Eigen::Index n)
      {
        const double nan = std::numeric_limits<double>::quiet_NaN();
        r.Q = RowMat::Constant(n_steps + 1, n, nan);
        r.QD = RowMat::Constant(n_steps + 1, n, nan);
        r.TAU = RowMat::Constant(n_steps + 1, n, nan);
      }

      /// Record the measured state after step k; false (and the divergence kept) if it diverged.
      bool record(std::int64_t k, const Measured & m, const RolloutInputs & in)
      {
        r.Q.row(k + 1) = m.q.transpose();
        r.QD.row(k + 1) = m.qd.transpose();
        const Divergence bad = diverged(m.q, m.qd, in.lower, in.upper, in.vlim);
        if (bad.reason == kOk)
          return true;
        r.step = k + 1;
        r.joint = bad.joint;
        r.reason = bad.reason;
        return false;
      }

      /// Stop at step k: the law returned a NaN or inf torque for joint j.
      void law_failed(std::int64_t k, int j)
      {
        r.step = k;
        r.joint = j;
        r.reason = kLawTorque;
      }

      /// Stop at step k for `reason` (a plant's settle or a law's model).
      void stop(std::int64_t k, int reason)
      {
        r.step = k;
        r.reason = reason;
      }

      /// The result, with the plant's records and its final (or stopped) state.
      template<class Plant>
      RolloutResult finish(const Plant & plant, const State & y)
      {
        r.drift = plant.drift;
        r.drift_v = plant.drift_v;
        if (r.reason >= kDrift && r.reason <= kPlantCrossed)
          r.value = plant.value;
        r.q = y.q;
        r.qd = y.qd;
        return std::move(r);
      }
    };

    /// Sampled law: sensor -> law -> saturation -> delay -> plant (effects.hpp), S RK4 sub-steps
    /// of h per control period, the command held, the plant settled after each. Ideal = true: no
    /// effects (the same operations on the same numbers, without the sensor, saturation,
    /// delay-line and actuator copies).
    template<class Plant, class Terms, class Law, bool Ideal>
    RolloutResult sampled_loop(
      const Tree & plant_tree, const Tree & nominal, const Law & law, const RolloutInputs & in,
      const Effects & fx)
    {
      const Eigen::Index n = plant_tree.na(), m = law.nx();
      const std::int64_t N = in.n_steps;
      Outputs out(N, n);
      Plant plant(plant_tree, in.q0);
      Driven<Plant, Ideal> sys(plant, fx, n);
      typename Law::template Eval<Terms> eval(law, nominal);
      State y;
      y.q = in.q0;
      y.qd = in.qd0;
      Vec x = in.x0, xn(m), tau(n), qm(n), qdm(n), qa(n), qda(n);
      RK4 w;
      {
        const Measured m0 = plant.measure(y.q, y.qd, qa, qda);
        out.r.Q.row(0) = m0.q.transpose();
        out.r.QD.row(0) = m0.qd.transpose();
      }
      for (std::int64_t k = 0; k < N; ++k)
      {
        const Measured ms = plant.measure(y.q, y.qd, qa, qda);
        int st;
        if constexpr (Ideal)
          st = eval.torque(ms.q, ms.qd, in.R.row(k), in.RD.row(k), in.RDD.row(k), x);
        else
        {
          fx.sense(k, ms.q, ms.qd, qm, qdm);
          st = eval.torque(qm, qdm, in.R.row(k), in.RD.row(k), in.RDD.row(k), x);
        }
        if (st != kOk)  // the law's model could not be evaluated there
        {
          out.stop(k, st);
          keep_stop(eval.terms, out.r);
          break;
        }
        tau = eval.tau();
        if (m > 0)
        {
          eval.state_map(x, xn);
          x.swap(xn);
        }
        // The law's own output. With the effects (a saturation could clip an inf, a delay hold
        // a NaN back) and on a plant that does not settle, it stops here; a settling plant's
        // Python loop meets it in the settle first (the step's gap is NaN), so it is kept for
        // after the step.
        const int bad = first_nonfinite(tau);
        if (bad >= 0 && !(Ideal && Plant::settles))
        {
          out.r.TAU.row(k) = tau.transpose();
          out.law_failed(k, bad);
          break;
        }
        if constexpr (!Ideal)
          fx.saturate(tau);
        out.r.TAU.row(k) = tau.transpose();  // also the delay line: row j = command j
        if constexpr (Ideal)
          sys.u = tau;
        else if (k == 0)
          fx.start(tau, ms.q, ms.qd, y);
        for (int s = 0; s < in.substeps; ++s)
        {
          if constexpr (!Ideal)
            sys.u = out.r.TAU.row(fx.delayed_row(k, s, in.substeps)).transpose();
          rk4_step(sys, y, in.h, w);
          st = plant.settle(y.q, y.qd);
          if (st != kOk)
            break;
        }
        if (st != kOk)
        {
          out.stop(k, st);
          break;
        }
        if (bad >= 0)
        {
          out.law_failed(k, bad);
          break;
        }
        if (!out.record(k, plant.measure(y.q, y.qd, qa, qda), in))
          break;
      }
      // The torque held on the last interval is also the one "at" the final sample.
      if (out.r.step < 0)
        out.r.TAU.row(N) = out.r.TAU.row(N - 1);
      return out.finish(plant, y);
    }

    /// Continuous law: (q, qd, x) integrated together by RK4 steps of h, the plant settled after
    /// each.
    template<class Plant, class Terms, class Law>
    RolloutResult continuous_loop(
      const Tree & plant_tree, const Tree & nominal, const Law & law, const RolloutInputs & in)
    {
      const Eigen::Index n = plant_tree.na();
      const std::int64_t N = in.n_steps;
      Outputs out(N, n);
      Plant plant(plant_tree, in.q0);
      using Eval = typename Law::template Eval<Terms>;
      Eval eval(law, nominal);
      ContinuousLoop<Plant, Eval> loop{plant, eval, in, out.r, Parts{}, Vec(n), Vec(n)};
      loop.parts.x = law.nx() > 0;
      State y;
      y.q = in.q0;
      y.qd = in.qd0;
      y.x = in.x0;
      RK4 w;
      Vec qa(n), qda(n);
      {
        const Measured m0 = plant.measure(y.q, y.qd, qa, qda);
        out.r.Q.row(0) = m0.q.transpose();
        out.r.QD.row(0) = m0.qd.transpose();
      }
      for (std::int64_t k = 0;; ++k)
      {
        loop.k = k;
        loop.slope(y, 0, w.k1);
        out.r.TAU.row(k) = loop.tau->transpose();
        if (k < N)
          rk4_rest(loop, y, in.h, w);
        if (loop.law_stop != kOk)
        {
          out.stop(k, loop.law_stop);
          break;
        }
        if (k < N)
          if (const int st = plant.settle(y.q, y.qd); st != kOk)
          {
            out.stop(k, st);
            break;
          }
        if (loop.bad_joint >= 0)
        {
          out.law_failed(k, loop.bad_joint);
          break;
        }
        if (k == N || !out.record(k, plant.measure(y.q, y.qd, qa, qda), in))
          break;
      }
      return out.finish(plant, y);
    }

    template<class Plant, class Terms, class Law>
    RolloutResult run(
      const Tree & plant, const Tree & nominal, const Law & law, const RolloutInputs & in,
      const Effects * fx)
    {
      if (!in.sampled)
        return continuous_loop<Plant, Terms>(plant, nominal, law, in);
      if (!fx)
        return sampled_loop<Plant, Terms, Law, true>(plant, nominal, law, in, Effects{});
      return sampled_loop<Plant, Terms, Law, false>(plant, nominal, law, in, *fx);
    }
  } // namespace

  template<class Law>
  RolloutResult rollout(
    const Tree & plant, const Tree & nominal, const Law & law, const RolloutInputs & in,
    const Effects * fx)
  {
    const Eigen::Index n = plant.na();
    if (!in.sampled && fx)
      throw std::invalid_argument("plant effects need a sampled law");
    check_models(plant, nominal, law.nx(), in);
    law.check(n);
    if (fx)
      fx->check(n, in.n_steps);
    // The plant's kind and its law model's, each from its own description (loops or none).
    if (plant.loops() > 0)
      return nominal.loops() > 0 ? run<ChainPlant, ChainTerms>(plant, nominal, law, in, fx)
                                 : run<ChainPlant, ArmTerms>(plant, nominal, law, in, fx);
    return nominal.loops() > 0 ? run<ArmPlant, ChainTerms>(plant, nominal, law, in, fx)
                               : run<ArmPlant, ArmTerms>(plant, nominal, law, in, fx);
  }

  template<class Law>
  double floor_timing(
    const Tree & plant_tree, const Tree & nominal_tree, bool sampled, int substeps,
    std::int64_t n_steps)
  {
    if (plant_tree.loops() > 0 || nominal_tree.loops() > 0)
      throw std::invalid_argument("floor_timing times serial trees (ABA, CRBA); a closed chain's "
                                  "plant calls are timed by acceleration_timing");
    if (nominal_tree.na() != plant_tree.na())
      throw std::invalid_argument("plant and nominal models differ in nq");
    if (substeps < 1 || n_steps < 0)
      throw std::invalid_argument("substeps must be >= 1 and n_steps >= 0");
    Workspace plant(plant_tree.tree), nominal(nominal_tree.tree);
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

  namespace
  {
    template<class Plant>
    double time_accelerations(const Tree & tree, const Vec & q, const Vec & qd, const Vec & tau,
                              std::int64_t calls)
    {
      Plant plant(tree, q);
      double sink = 0.0;
      const auto t0 = std::chrono::steady_clock::now();
      for (std::int64_t i = 0; i < calls; ++i)
        sink += plant.acceleration(q, qd, tau)[0];
      const auto t1 = std::chrono::steady_clock::now();
      if (std::isnan(sink))
        return std::numeric_limits<double>::quiet_NaN();
      return std::chrono::duration<double>(t1 - t0).count();
    }

    void check_state(const Tree & tree, const Vec & q, const Vec & qd, const Vec & tau)
    {
      if (q.size() != tree.nv() || qd.size() != tree.nv() || tau.size() != tree.na())
        throw std::invalid_argument("q and qd must have nv entries, tau one per actuated "
                                    "coordinate");
    }
  } // namespace

  double acceleration_timing(const Tree & tree, const Vec & q, const Vec & qd, const Vec & tau,
                             std::int64_t calls)
  {
    check_state(tree, q, qd, tau);
    return tree.loops() > 0 ? time_accelerations<ChainPlant>(tree, q, qd, tau, calls)
                            : time_accelerations<ArmPlant>(tree, q, qd, tau, calls);
  }

  Vec plant_acceleration(const Tree & tree, const Vec & q, const Vec & qd, const Vec & tau)
  {
    check_state(tree, q, qd, tau);
    if (tree.loops() > 0)
    {
      ChainPlant plant(tree, q);
      return plant.acceleration(q, qd, tau);
    }
    ArmPlant plant(tree, q);
    return plant.acceleration(q, qd, tau);
  }

#define RRR_PIN_ROLLOUT_INSTANCE(Law) RRR_PIN_ROLLOUT_LAW(Law, )
  RRR_PIN_LAWS(RRR_PIN_ROLLOUT_INSTANCE)
#undef RRR_PIN_ROLLOUT_INSTANCE
} // namespace rrr_pin
