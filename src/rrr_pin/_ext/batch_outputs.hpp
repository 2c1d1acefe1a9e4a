// Outputs of the batched rollouts (batch.cpp, its private part): per plant its status and either
// its trajectory (BatchOutputs) or the figures of a campaign's row, reduced in the loop
// (FigureOutputs, numpy's reduction bit for bit: PairwiseSum).
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "batch.hpp"
#include "rk4.hpp"
#include "terms.hpp"

namespace rrr_pin
{
  namespace batch_outputs
  {
    using BState = LaneState;

    /// Per-plant status: running, or where and why it stopped.
    struct BatchStatus
    {
      Eigen::VectorXi bad_step, bad_joint, reason;
      std::vector<char> alive;
      int n_alive;

      explicit BatchStatus(int B)
      : bad_step(Eigen::VectorXi::Constant(B, -1))
      , bad_joint(Eigen::VectorXi::Constant(B, -1))
      , reason(Eigen::VectorXi::Constant(B, kOk))
      , alive(B, 1)
      , n_alive(B)
      {
      }

      void kill(int b, std::int64_t step, int joint, int why)
      {
        alive[b] = 0;
        --n_alive;
        bad_step[b] = static_cast<int>(step);
        bad_joint[b] = joint;
        reason[b] = why;
      }
    };

    /// rollout.cpp's divergence test of plant b after a step: kOk, or why (joint: where).
    inline int diverged(const BState & y, int b, int B, int n, const RowMat & lower,
                 const RowMat & upper, double vlim, int & joint)
    {
      int why = kOk;
      for (int j = 0; j < n && why == kOk; ++j)
        if (!std::isfinite(y.q[j * B + b]) || !std::isfinite(y.qd[j * B + b]))
          joint = j, why = kNonFinite;
      for (int j = 0; j < n && why == kOk; ++j)
        if (std::abs(y.qd[j * B + b]) > vlim)
          joint = j, why = kSpeed;
      for (int j = 0; j < n && why == kOk; ++j)
        if (y.q[j * B + b] < lower(b, j) || y.q[j * B + b] > upper(b, j))
          joint = j, why = kLimits;
      return why;
    }

    /// Per-plant outputs and status.
    struct BatchOutputs : BatchStatus
    {
      int B, n;
      std::int64_t N;
      RowMat Q, QD, TAU;

      BatchOutputs(int B_, int n_, std::int64_t N_)
      : BatchStatus(B_)
      , B(B_)
      , n(n_)
      , N(N_)
      , Q(RowMat::Constant(B_ * (N_ + 1), n_, std::numeric_limits<double>::quiet_NaN()))
      , QD(Q)
      , TAU(Q)
      {
      }

      std::int64_t row(int b, std::int64_t k) const { return b * (N + 1) + k; }

      void put(RowMat & out, int b, std::int64_t k, const Lanes & v) const
      {
        for (int j = 0; j < n; ++j)
          out(row(b, k), j) = v[j * B + b];
      }

      /// Record the states after step k; the plants that diverge are stopped.
      void record(std::int64_t k, const BState & y, const RowMat & lower, const RowMat & upper,
                  double vlim, std::vector<int> & stopped)
      {
        for (int b = 0; b < B; ++b)
        {
          if (!alive[b])
            continue;
          put(Q, b, k + 1, y.q);
          put(QD, b, k + 1, y.qd);
          int joint = -1;
          const int why = diverged(y, b, B, n, lower, upper, vlim, joint);
          if (why != kOk)
          {
            kill(b, k + 1, joint, why);
            stopped.push_back(b);
          }
        }
      }

      BatchResult result()
      {
        return {std::move(Q), std::move(QD), std::move(TAU), bad_step, bad_joint, reason};
      }

      void start(int b, const BState & y)
      {
        put(Q, b, 0, y.q);
        put(QD, b, 0, y.qd);
      }

      void torque(int b, std::int64_t k, const Lanes & tau) { put(TAU, b, k, tau); }

      /// The torque held on the last interval is also the one "at" the final sample.
      void hold_last_torque()
      {
        for (int b = 0; b < B; ++b)
          if (bad_step[b] < 0)
            TAU.row(row(b, N)) = TAU.row(row(b, N - 1));
      }
    };

    /// numpy's sum of a float64 array (``np.add.reduce`` of a contiguous row: ``0.0 +``
    /// pairwise_sum, numpy/_core/src/umath/loops_utils.h.src), fed one value at a time in the
    /// row's order: the same tree of additions, so the same number, bit for bit.
    /// Hand-written: numpy has no streaming form, and storing the row would cost the memory
    /// traffic the reduction exists to save.
    class PairwiseSum
    {
    public:
      /// The tree of a row of L values: its leaves (blocks of at most 128 values) in order,
      /// and after each leaf the number of pending additions of two partial sums.
      struct Plan
      {
        std::vector<std::int64_t> leaf;
        std::vector<int> merges;

        explicit Plan(std::int64_t L) { build(L); }

        void build(std::int64_t n)
        {
          if (n <= 128)
          {
            leaf.push_back(n);
            merges.push_back(0);
            return;
          }
          std::int64_t n2 = n / 2;
          n2 -= n2 % 8;
          build(n2);
          build(n - n2);
          ++merges.back();
        }
      };

      explicit PairwiseSum(std::shared_ptr<const Plan> plan) : plan_(std::move(plan)) {}

      void add(double a)
      {
        const std::int64_t n = plan_->leaf[i_];
        if (n < 8)
          res_ += a;
        else if (p_ < 8)
          r_[p_] = a;
        else if (p_ < n - n % 8)
          r_[p_ % 8] += a;
        else
        {
          if (p_ == n - n % 8)
            res_ = tree();
          res_ += a;
        }
        if (++p_ == n)
          close(n);
      }

      /// The sum of the row (all L values added).
      double value() const { return 0.0 + (stack_.empty() ? 0.0 : stack_.back()); }

    private:
      std::shared_ptr<const Plan> plan_;
      std::size_t i_ = 0;    // current leaf
      std::int64_t p_ = 0;   // position in it
      double r_[8] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
      double res_ = -0.0;
      std::vector<double> stack_;

      double tree() const
      {
        return ((r_[0] + r_[1]) + (r_[2] + r_[3])) + ((r_[4] + r_[5]) + (r_[6] + r_[7]));
      }

      void close(std::int64_t n)
      {
        stack_.push_back(n >= 8 && n % 8 == 0 ? tree() : res_);
        for (int m = 0; m < plan_->merges[i_]; ++m)
        {
          const double right = stack_.back();
          stack_.pop_back();
          stack_.back() = stack_.back() + right;
        }
        ++i_;
        p_ = 0;
        res_ = -0.0;
      }
    };

    /// Per-plant outputs reduced in the loop to the figures a campaign's row holds
    /// (rrr_pin.sim.trajectory.tracking_figures_batch, bit for bit): no trajectory stored.
    /// F row b: RMS error, max |error| [rad], RMS torque [N m], RMS error per joint [rad].
    /// Q, QD: the last state recorded (at divergence: the state that diverged); TAU: the first
    /// torque (a law's non-finite first torque is reported from it).
    struct FigureOutputs : BatchStatus
    {
      int B, n;
      std::int64_t N;
      const RowMat & R;
      std::int64_t rstride;  // row of the reference at sample k: k * rstride
      std::shared_ptr<const PairwiseSum::Plan> plan;
      std::vector<PairwiseSum> e2, t2;
      Lanes joint2, peak;
      RowMat Q, QD, TAU, F;

      FigureOutputs(int B_, int n_, std::int64_t N_, const RolloutInputs & in)
      : BatchStatus(B_)
      , B(B_)
      , n(n_)
      , N(N_)
      , R(in.R)
      , rstride(in.sampled ? 1 : 2)
      , plan(std::make_shared<const PairwiseSum::Plan>((N_ + 1) * n_))
      , e2(B_, PairwiseSum(plan))
      , t2(B_, PairwiseSum(plan))
      , joint2(static_cast<std::size_t>(B_) * n_, 0.0)
      , peak(B_, 0.0)
      , Q(RowMat::Constant(B_, n_, std::numeric_limits<double>::quiet_NaN()))
      , QD(Q)
      , TAU(Q)
      , F(RowMat::Constant(B_, 3 + n_, std::numeric_limits<double>::quiet_NaN()))
      {
      }

      void state(int b, std::int64_t k, const BState & y)
      {
        for (int j = 0; j < n; ++j)
        {
          const double q = y.q[j * B + b];
          Q(b, j) = q;
          QD(b, j) = y.qd[j * B + b];
          const double e = R(k * rstride, j) - q;
          const double ee = e * e;  // rounded, as numpy's E * E (no fused multiply-add)
          e2[b].add(ee);
          joint2[b * n + j] += ee;
          peak[b] = std::max(peak[b], std::abs(e));
        }
      }

      void start(int b, const BState & y) { state(b, 0, y); }

      void torque(int b, std::int64_t k, const Lanes & tau)
      {
        for (int j = 0; j < n; ++j)
        {
          const double t = tau[j * B + b];
          if (k == 0)
            TAU(b, j) = t;
          t2[b].add(t * t);
        }
      }

      void hold_last_torque()
      {
        for (int b = 0; b < B; ++b)
          if (bad_step[b] < 0)
            for (int j = 0; j < n; ++j)
              t2[b].add(last_[b * n + j] * last_[b * n + j]);
      }

      void record(std::int64_t k, const BState & y, const RowMat & lower, const RowMat & upper,
                  double vlim, std::vector<int> & stopped)
      {
        for (int b = 0; b < B; ++b)
        {
          if (!alive[b])
            continue;
          int joint = -1;
          const int why = diverged(y, b, B, n, lower, upper, vlim, joint);
          if (why != kOk)
          {
            for (int j = 0; j < n; ++j)
              Q(b, j) = y.q[j * B + b], QD(b, j) = y.qd[j * B + b];
            kill(b, k + 1, joint, why);
            stopped.push_back(b);
          }
          else
            state(b, k + 1, y);
        }
      }

      FigureResult result()
      {
        const double count = static_cast<double>((N + 1) * n);
        const double samples = static_cast<double>(N + 1);
        for (int b = 0; b < B; ++b)
        {
          if (bad_step[b] >= 0)
            continue;
          F(b, 0) = std::sqrt(e2[b].value() / count);
          F(b, 1) = peak[b];
          F(b, 2) = std::sqrt(t2[b].value() / count);
          for (int j = 0; j < n; ++j)
            F(b, 3 + j) = std::sqrt(joint2[b * n + j] / samples);
        }
        return {std::move(F), std::move(Q), std::move(QD), std::move(TAU), bad_step, bad_joint,
                reason};
      }

      /// Keep the torque of step k for the final sample (hold_last_torque).
      void keep(const Lanes & tau)
      {
        last_.assign(tau.begin(), tau.end());
        for (int b = 0; b < B; ++b)  // plant-major, as hold_last_torque reads it
          for (int j = 0; j < n; ++j)
            last_[b * n + j] = tau[j * B + b];
      }

    private:
      Lanes last_;
    };

    template<class Out>
    Out make_outputs(int B, int n, std::int64_t N, const RolloutInputs & in);

    template<>
    inline BatchOutputs make_outputs<BatchOutputs>(int B, int n, std::int64_t N, const RolloutInputs &)
    {
      return BatchOutputs(B, n, N);
    }

    template<>
    inline FigureOutputs make_outputs<FigureOutputs>(int B, int n, std::int64_t N,
                                              const RolloutInputs & in)
    {
      return FigureOutputs(B, n, N, in);
    }

    /// The torque of the last control step, kept by outputs that reduce (FigureOutputs).
    inline void keep_torque(BatchOutputs &, const Lanes &) {}
    inline void keep_torque(FigureOutputs & out, const Lanes & tau) { out.keep(tau); }
  } // namespace batch_outputs
} // namespace rrr_pin
