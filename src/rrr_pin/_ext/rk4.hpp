// Classical RK4, the one integrator of every compiled loop, as in the Python engine
// (rrr_pin.sim.python_engine): k1 = f(y), k2 = f(y + h/2 k1), k3 = f(y + h/2 k2),
// k4 = f(y + h k3), y += h/6 (k1 + 2 (k2 + k3) + k4), component by component.
//
// Written once over the parts of a state, for two layouts of the numbers: one plant (Eigen
// vectors: the rollout of rollout.cpp, serial arm or closed chain) and B plants side by side
// (Lanes, entry j of plant b at [j * B + b]: the batched rollout of batch.cpp). The two
// element-wise kernels below are the only code that differs; both compute, entry by entry,
// out = y + c k and y + h/6 (k1 + 2 (k2 + k3) + k4) in that order, so a plant's numbers are the
// same bits in either layout.
#pragma once

#include <cstddef>
#include <vector>

#include "model.hpp"

namespace rrr_pin
{
  /// B plants' entries side by side (structure-of-arrays).
  using Lanes = std::vector<double>;

  /// What is integrated: the plant (q, qd: every coordinate, [rad, m], [rad/s, m/s]) always; a
  /// continuous law's state x, the actuator output a [N m] and the motor side (th [rad],
  /// thd [rad/s]) when the run has them. A slope (time derivative) has the same layout: q holds
  /// qd, qd holds qdd, th holds thd, ...
  template<class V>
  struct BasicState
  {
    V q, qd, x, a, th, thd;
  };

  using State = BasicState<Vec>;
  using LaneState = BasicState<Lanes>;

  /// The optional parts of a State a run carries.
  struct Parts
  {
    bool x = false, a = false, th = false;
  };

  /// Stage points and slopes of one RK4 step.
  template<class V>
  struct RK4Work
  {
    BasicState<V> ys, k1, k2, k3, k4;
  };

  using RK4 = RK4Work<Vec>;

  // The element-wise kernels of each layout.
  inline void axpy(const Vec & y, double c, const Vec & k, Vec & out)
  {
    out = y + c * k;
  }

  inline void axpy(const Lanes & y, double c, const Lanes & k, Lanes & out)
  {
    for (std::size_t i = 0; i < y.size(); ++i)
      out[i] = y[i] + c * k[i];
  }

  inline void combine(
    Vec & y, double h6, const Vec & k1, const Vec & k2, const Vec & k3, const Vec & k4)
  {
    y += h6 * (k1 + 2.0 * (k2 + k3) + k4);
  }

  inline void combine(
    Lanes & y, double h6, const Lanes & k1, const Lanes & k2, const Lanes & k3,
    const Lanes & k4)
  {
    for (std::size_t i = 0; i < y.size(); ++i)
      y[i] += h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
  }

  /// Call f(&BasicState<V>::part) for every part the run carries (qd before q).
  template<class V, class F>
  void each_part(const Parts & p, F && f)
  {
    using S = BasicState<V>;
    f(&S::qd);
    f(&S::q);
    if (p.x)
      f(&S::x);
    if (p.a)
      f(&S::a);
    if (p.th)
    {
      f(&S::th);
      f(&S::thd);
    }
  }

  /// One RK4 stage: the point ys = y + c k and the system's slope there, into `out`. `point`
  /// says where the stage lies in the step (0: start, 1: middle, 2: end) for a system that
  /// samples its input there (a continuous law's reference).
  template<class System, class V>
  void stage(
    System & sys, const BasicState<V> & y, const BasicState<V> & k, double c, int point,
    BasicState<V> & ys, BasicState<V> & out)
  {
    each_part<V>(sys.parts, [&](auto part) { axpy(y.*part, c, k.*part, ys.*part); });
    sys.slope(ys, point, out);
  }

  /// The rest of an RK4 step of h from y, with w.k1 = the slope at y already computed.
  template<class System, class V>
  void rk4_rest(System & sys, BasicState<V> & y, double h, RK4Work<V> & w)
  {
    const double h2 = 0.5 * h, h6 = h / 6.0;
    stage(sys, y, w.k1, h2, 1, w.ys, w.k2);
    stage(sys, y, w.k2, h2, 1, w.ys, w.k3);
    stage(sys, y, w.k3, h, 2, w.ys, w.k4);
    each_part<V>(sys.parts, [&](auto part) {
      combine(y.*part, h6, w.k1.*part, w.k2.*part, w.k3.*part, w.k4.*part);
    });
  }

  /// One RK4 step of h from y.
  template<class System, class V>
  void rk4_step(System & sys, BasicState<V> & y, double h, RK4Work<V> & w)
  {
    sys.slope(y, 0, w.k1);
    rk4_rest(sys, y, h, w);
  }
} // namespace rrr_pin
