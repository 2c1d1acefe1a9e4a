// Plant effects of a sampled rollout (rrr_pin.control.effects), one field per effect as in
// rrr_pin.control.effects.Resolved (rrr_pin.sim.compiled copies them by name). Default-constructed,
// every effect is off (empty vectors, zero-row noise, wa = quantum = 0, no delay): the ideal loop.
//
// Order in the loop, operation for operation as rrr_pin.sim.python_engine._effects:
// sensor (noise, quantization) -> law -> saturation -> delay (delay_steps plant sub-steps) ->
// first-order actuator (wa > 0) -> flexible joint (Kf non-empty) -> plant with friction (Fv
// non-empty). The drive train acts on the actuated coordinates (the n measured ones); a closed
// chain's passive coordinates stay ideal. Each effect is written once, per joint (sensed_q,
// sensed_qd, saturated, joint_torque_at, start_at): the compiled rollout applies it to a
// plant's vectors (sense, saturate, joint_torque, start), the batched lanes of batch.cpp to each
// (joint, plant) entry, so every effect is batched. A new effect: a field here, its check, its
// step below and the Python step.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <tuple>

#include "model.hpp"
#include "rk4.hpp"

namespace rrr_pin
{
  /// A field of a parameter struct (a law of law.hpp, the Effects here): its name, as in the
  /// Python record it is copied from, and its member. The bindings are made from these lists.
  template<class Member>
  struct Field
  {
    const char * name;
    Member member;
  };

  template<class Member>
  constexpr Field<Member> field(const char * name, Member member)
  {
    return {name, member};
  }

  struct Effects
  {
    std::int64_t delay_steps = 0;  // transport delay [plant sub-steps]
    double wa = 0.0;               // actuator bandwidth [rad/s]; 0 = ideal actuator
    Vec limit;                     // (n,) saturation [N m]; empty = none
    Vec Fv, Fc;                    // (n,) viscous [N m s/rad], Coulomb [N m]; empty = none
    double veps = 1.0;             // Coulomb smoothing speed [rad/s]
    RowMat noise_q, noise_qd;      // (N, n) sensor noise [rad], [rad/s]; 0 rows = none
    double quantum = 0.0;          // encoder step [rad]; 0 = exact
    Vec Bm, Kf, Df;                // (n,) motor inertia, stiffness, damping; empty = rigid

    /// The fields, once (name as in rrr_pin.control.effects.Resolved, member): the bindings
    /// are made from this list.
    static constexpr auto fields()
    {
      return std::make_tuple(
        field("delay_steps", &Effects::delay_steps), field("wa", &Effects::wa),
        field("limit", &Effects::limit), field("Fv", &Effects::Fv), field("Fc", &Effects::Fc),
        field("veps", &Effects::veps), field("noise_q", &Effects::noise_q),
        field("noise_qd", &Effects::noise_qd), field("quantum", &Effects::quantum),
        field("Bm", &Effects::Bm), field("Kf", &Effects::Kf), field("Df", &Effects::Df));
    }

    bool saturates() const { return limit.size() > 0; }
    bool rubs() const { return Fv.size() > 0; }
    bool flexes() const { return Kf.size() > 0; }
    bool lags() const { return wa > 0.0; }
    /// Whether the drive train is not ideal (the command reaches the joints through
    /// joint_torque_at): a new drive-train effect is added here, not in the loops.
    bool drives() const { return lags() || rubs() || flexes(); }

    void check(Eigen::Index n, std::int64_t n_steps) const
    {
      if (delay_steps < 0)
        throw std::invalid_argument("delay_steps >= 0 is required");
      if (
        (saturates() && limit.size() != n) || (rubs() && (Fv.size() != n || Fc.size() != n))
        || (flexes() && (Kf.size() != n || Bm.size() != n || Df.size() != n))
        || (noise_q.rows() > 0 && (noise_q.rows() != n_steps || noise_q.cols() != n))
        || (noise_qd.rows() > 0 && (noise_qd.rows() != n_steps || noise_qd.cols() != n)))
        throw std::invalid_argument("effect arrays have the wrong shape");
    }

    /// Sensor of joint j at control step k: qm_j = Q(q_j + n_q[k, j]) [rad].
    double sensed_q(std::int64_t k, Eigen::Index j, double q) const
    {
      double v = q;
      if (noise_q.rows() > 0)
        v = v + noise_q(k, j);
      if (quantum > 0.0)
        v = quantum * std::nearbyint(v / quantum);
      return v;
    }

    /// Sensor of joint j at control step k: qdm_j = qd_j + n_qd[k, j] [rad/s].
    double sensed_qd(std::int64_t k, Eigen::Index j, double qd) const
    {
      return noise_qd.rows() > 0 ? qd + noise_qd(k, j) : qd;
    }

    /// Whether the sensor changes what the law reads.
    bool senses() const { return noise_q.rows() > 0 || noise_qd.rows() > 0 || quantum > 0.0; }

    /// Sensor at control step k: qm = Q(q + n_q), qdm = qd + n_qd.
    void sense(std::int64_t k, const Vec & q, const Vec & qd, Vec & qm, Vec & qdm) const
    {
      qm.resize(q.size());
      qdm.resize(qd.size());
      for (Eigen::Index j = 0; j < q.size(); ++j)
      {
        qm[j] = sensed_q(k, j, q[j]);
        qdm[j] = sensed_qd(k, j, qd[j]);
      }
    }

    /// Saturation of joint j: clip(tau_j, -limit_j, limit_j) (Eigen's cwiseMax(-limit)
    /// .cwiseMin(limit): std::max, then std::min); tau_j itself without a limit.
    double saturated(Eigen::Index j, double tau) const
    {
      return saturates() ? std::min(std::max(tau, -limit[j]), limit[j]) : tau;
    }

    /// Saturation: tau = clip(tau, -limit, limit).
    void saturate(Vec & tau) const
    {
      if (saturates())
        for (Eigen::Index j = 0; j < tau.size(); ++j)
          tau[j] = saturated(j, tau[j]);
    }

    /// Row of the command history U the joints receive at plant sub-step s of control step k.
    std::int64_t delayed_row(std::int64_t k, int s, int substeps) const
    {
      const std::int64_t j = k * substeps + s - delay_steps;
      return j >= 0 ? j / substeps : 0;
    }

    /// Parts of the plant state the effects add: actuator output a, motor (th, thd).
    Parts parts() const
    {
      Parts p;
      p.a = lags();
      p.th = flexes();
      return p;
    }

    /// Joint j at t = 0, at rest on its first command tau0: a = tau0, and a flexible joint's
    /// spring carrying it, th = q + tau0 / K, thd = qd (a, th, thd left as they are for the
    /// parts the effects do not add).
    void start_at(Eigen::Index j, double tau0, double q, double qd, double & a, double & th,
                  double & thd) const
    {
      if (lags())
        a = tau0;
      if (flexes())
      {
        th = q + tau0 / Kf[j];
        thd = qd;
      }
    }

    /// Plant state at t = 0, at rest on the first command tau_0 (start_at per joint; q, qd: the
    /// actuated coordinates of y).
    void start(const Vec & tau0, const Vec & q, const Vec & qd, State & y) const
    {
      const Eigen::Index n = tau0.size();
      if (lags())
        y.a.resize(n);
      if (flexes())
      {
        y.th.resize(n);
        y.thd.resize(n);
      }
      double unused = 0.0;
      for (Eigen::Index j = 0; j < n; ++j)
        start_at(j, tau0[j], q[j], qd[j], lags() ? y.a[j] : unused, flexes() ? y.th[j] : unused,
                 flexes() ? y.thd[j] : unused);
    }

    /// Torque on joint j [N m] for command u at actuator output a, motor (th, thd) and joint
    /// (q, qd): the actuator's output (or u), through the flexible joint's spring, less the
    /// friction; the slopes of the actuator (ka) and of the motor (kth, kthd) where the effects
    /// add them.
    double joint_torque_at(Eigen::Index j, double q, double qd, double a, double th, double thd,
                           double u, double & ka, double & kth, double & kthd) const
    {
      const double tm = lags() ? a : u;
      double t = tm;
      if (flexes())
      {
        t = Kf[j] * (th - q) + Df[j] * (thd - qd);
        kth = thd;
        kthd = (tm - t) / Bm[j];
      }
      if (rubs())
        t = t - (Fv[j] * qd + Fc[j] * std::tanh(qd / veps));
      if (lags())
        ka = wa * (u - a);
      return t;
    }

    /// Torque on the actuated joints, tj [N m], for command u at plant state y whose actuated
    /// coordinates are (q, qd) (joint_torque_at per joint); fills the slopes of the actuator
    /// (k.a) and of the motor (k.th, k.thd).
    void joint_torque(const Vec & q, const Vec & qd, const State & y, const Vec & u, State & k,
                      Vec & tj) const
    {
      const Eigen::Index n = u.size();
      tj.resize(n);
      if (lags())
        k.a.resize(n);
      if (flexes())
      {
        k.th.resize(n);
        k.thd.resize(n);
      }
      double ka = 0.0, kth = 0.0, kthd = 0.0;
      for (Eigen::Index j = 0; j < n; ++j)
      {
        tj[j] = joint_torque_at(j, q[j], qd[j], lags() ? y.a[j] : 0.0,
                                flexes() ? y.th[j] : 0.0, flexes() ? y.thd[j] : 0.0, u[j], ka,
                                kth, kthd);
        if (lags())
          k.a[j] = ka;
        if (flexes())
        {
          k.th[j] = kth;
          k.thd[j] = kthd;
        }
      }
    }
  };
} // namespace rrr_pin
