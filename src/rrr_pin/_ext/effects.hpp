// Plant effects of a sampled rollout (rrr_pin.control.effects), one field per effect as in
// rrr_pin.control.effects.Resolved (rrr_pin.sim.compiled copies them by name). Default-constructed,
// every effect is off (empty vectors, zero-row noise, wa = quantum = 0, no delay): the ideal loop.
//
// Order in the loop, operation for operation as rrr_pin.sim.python_engine._effects:
// sensor (noise, quantization) -> law -> saturation -> delay (delay_steps plant sub-steps) ->
// first-order actuator (wa > 0) -> flexible joint (Kf non-empty) -> plant with friction (Fv
// non-empty). The drive train acts on the actuated coordinates (the n measured ones); a closed
// chain's passive coordinates stay ideal. A new effect: a field here, its check, its step below
// and the Python step.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "model.hpp"
#include "rk4.hpp"

namespace rrr_pin
{
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

    bool saturates() const { return limit.size() > 0; }
    bool rubs() const { return Fv.size() > 0; }
    bool flexes() const { return Kf.size() > 0; }
    bool lags() const { return wa > 0.0; }

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

    /// Sensor at control step k: qm = Q(q + n_q), qdm = qd + n_qd.
    void sense(std::int64_t k, const Vec & q, const Vec & qd, Vec & qm, Vec & qdm) const
    {
      qm = q;
      qdm = qd;
      if (noise_q.rows() > 0)
        qm = qm + noise_q.row(k).transpose();
      if (quantum > 0.0)
        for (Eigen::Index j = 0; j < qm.size(); ++j)
          qm[j] = quantum * std::nearbyint(qm[j] / quantum);
      if (noise_qd.rows() > 0)
        qdm = qdm + noise_qd.row(k).transpose();
    }

    /// Saturation: tau = clip(tau, -limit, limit).
    void saturate(Vec & tau) const
    {
      if (saturates())
        for (Eigen::Index j = 0; j < tau.size(); ++j)
          tau[j] = std::min(std::max(tau[j], -limit[j]), limit[j]);
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

    /// Plant state at t = 0, at rest on the first command tau_0: a = tau_0, and a flexible
    /// joint's spring carrying it, th = q + tau_0 / K, thd = qd (q, qd: the actuated
    /// coordinates of y).
    void start(const Vec & tau0, const Vec & q, const Vec & qd, State & y) const
    {
      if (lags())
        y.a = tau0;
      if (flexes())
      {
        y.th = q + tau0.cwiseQuotient(Kf);
        y.thd = qd;
      }
    }

    /// Torque on the actuated joints, tj [N m], for command u at plant state y whose actuated
    /// coordinates are (q, qd); fills the slopes of the actuator (k.a) and of the motor (k.th,
    /// k.thd). tm, fr: scratch (n,).
    void joint_torque(const Vec & q, const Vec & qd, const State & y, const Vec & u, State & k,
                      Vec & tj, Vec & tm, Vec & fr) const
    {
      tm = lags() ? y.a : u;
      if (flexes())
      {
        tj = Kf.cwiseProduct(y.th - q) + Df.cwiseProduct(y.thd - qd);
        k.th = y.thd;
        k.thd = (tm - tj).cwiseQuotient(Bm);
      }
      else
        tj = tm;
      if (rubs())
      {
        for (Eigen::Index j = 0; j < tj.size(); ++j)
          fr[j] = Fv[j] * qd[j] + Fc[j] * std::tanh(qd[j] / veps);
        tj = tj - fr;
      }
      if (lags())
        k.a = wa * (u - y.a);
    }
  };
} // namespace rrr_pin
