// Classical RK4, one stage function for every loop of the compiled rollout, as in the Python
// engine (rrr_pin.sim.simulation): k1 = f(y), k2 = f(y + h/2 k1), k3 = f(y + h/2 k2),
// k4 = f(y + h k3), y += h/6 (k1 + 2 (k2 + k3) + k4), component by component.
#pragma once

#include "model.hpp"

namespace rrr_pin
{
  /// What is integrated: the arm (q [rad], qd [rad/s]) always; a continuous law's state x, the
  /// actuator output a [N m] and the motor side (th [rad], thd [rad/s]) when the run has them.
  /// A slope (time derivative) has the same layout: q holds qd, qd holds qdd, th holds thd, ...
  struct State
  {
    Vec q, qd, x, a, th, thd;
  };

  /// The optional parts of a State a run carries.
  struct Parts
  {
    bool x = false, a = false, th = false;
  };

  /// Stage points and slopes of one RK4 step.
  struct RK4
  {
    State ys, k1, k2, k3, k4;
  };

  /// One RK4 stage: the point ys = y + c k and the system's slope there, into `out`. `point`
  /// says where the stage lies in the step (0: start, 1: middle, 2: end) for a system that
  /// samples its input there (a continuous law's reference).
  template<class System>
  void stage(
    System & sys, const State & y, const State & k, double c, int point, State & ys, State & out)
  {
    const Parts & p = sys.parts;
    ys.qd = y.qd + c * k.qd;
    ys.q = y.q + c * k.q;
    if (p.x)
      ys.x = y.x + c * k.x;
    if (p.a)
      ys.a = y.a + c * k.a;
    if (p.th)
    {
      ys.th = y.th + c * k.th;
      ys.thd = y.thd + c * k.thd;
    }
    sys.slope(ys, point, out);
  }

  /// The rest of an RK4 step of h from y, with w.k1 = the slope at y already computed.
  template<class System>
  void rk4_rest(System & sys, State & y, double h, RK4 & w)
  {
    const double h2 = 0.5 * h, h6 = h / 6.0;
    stage(sys, y, w.k1, h2, 1, w.ys, w.k2);
    stage(sys, y, w.k2, h2, 1, w.ys, w.k3);
    stage(sys, y, w.k3, h, 2, w.ys, w.k4);
    const Parts & p = sys.parts;
    y.q += h6 * (w.k1.q + 2.0 * (w.k2.q + w.k3.q) + w.k4.q);
    y.qd += h6 * (w.k1.qd + 2.0 * (w.k2.qd + w.k3.qd) + w.k4.qd);
    if (p.x)
      y.x += h6 * (w.k1.x + 2.0 * (w.k2.x + w.k3.x) + w.k4.x);
    if (p.a)
      y.a += h6 * (w.k1.a + 2.0 * (w.k2.a + w.k3.a) + w.k4.a);
    if (p.th)
    {
      y.th += h6 * (w.k1.th + 2.0 * (w.k2.th + w.k3.th) + w.k4.th);
      y.thd += h6 * (w.k1.thd + 2.0 * (w.k2.thd + w.k3.thd) + w.k4.thd);
    }
  }

  /// One RK4 step of h from y.
  template<class System>
  void rk4_step(System & sys, State & y, double h, RK4 & w)
  {
    sys.slope(y, 0, w.k1);
    rk4_rest(sys, y, h, w);
  }
} // namespace rrr_pin
