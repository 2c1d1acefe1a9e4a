// Compiled closed-loop rollout: any plant (a serial tree under ABA or a closed chain under its
// exact KKT dynamics, plant.hpp) and a compiled law (law.hpp) on its model (a serial tree or a
// closed chain, terms.hpp), with the plant effects of effects.hpp, all in one C++ loop with no
// return to Python per step. Python entry point: rrr_pin.sim.compiled.run_compiled; bindings in
// module.cpp.
//
// The algorithm is the Python reference engine's (rrr_pin.sim.python_engine: _sampled, _effects
// and _continuous), operation for operation, written once over the plant: the plant's full
// state starts at Plant.start (given), every RK4 stage calls the plant's acceleration, every
// step ends with its settle, and the law reads the measured (actuated) coordinates.
// tests/test_engines.py pins the two engines together. The reference arrives sampled on the grid
// where the law is evaluated (one row per control instant for sampled laws, per half RK4 step
// for continuous laws), so any reference runs here.
#pragma once

#include <cstdint>
#include <tuple>

#include "effects.hpp"
#include "law.hpp"
#include "tree.hpp"

namespace rrr_pin
{
  /// Everything a rollout needs besides the plants, the law and the effects
  /// (rrr_pin.sim.trajectory.Run, set field by field from Python).
  struct RolloutInputs
  {
    bool sampled = true;        // sampled law (zero-order hold) or continuous law
    RowMat R, RD, RDD;          // reference [rad, rad/s, rad/s^2], (N + 1, n) sampled,
                                // (2 N + 1, n) continuous (every half step)
    Vec q0, qd0;                // the plant's full initial state (nv,), (nv,) (Plant.start)
    Vec x0;                     // the law's initial state (nx,)
    Vec lower, upper;           // limits of the measured coordinates [rad] (n,), margin included
    double vlim = 0.0;          // speed limit [rad/s]
    double h = 0.0;             // RK4 step [s]
    int substeps = 1;           // RK4 steps per control period (sampled)
    std::int64_t n_steps = 0;   // N control periods (sampled) or RK4 steps (continuous)
  };

  /// Throw std::invalid_argument unless `in` fits n measured joints and a law of nx states:
  /// the law state, the step counts and the reference arrays (every engine's rollout checks
  /// these).
  void check_inputs(const RolloutInputs & in, Eigen::Index n, Eigen::Index nx);

  /// A run: the measured (q, qd, tau) of shape (N + 1, n), NaN after a stop; the stop (step -1:
  /// none) and what Python re-derives its exception from.
  struct RolloutResult
  {
    RowMat Q, QD, TAU;
    std::int64_t step = -1;  // the stop's step
    int joint = -1;          // the joint of a divergence or of a law's non-finite torque
    int reason = kOk;        // Reason (terms.hpp)
    double value = 0.0;      // the gap [m] of a drift, cond(J_p) of a plant or law stop
    double drift = 0.0;      // largest gap [m] a step left (closed chain)
    double drift_v = 0.0;    // largest |J qd| [m/s] before a projection (closed chain)
    Vec q, qd;               // the plant's full state at the end, or at the stop
    Vec law_q, seed;         // a law stop: the actuated q it was evaluated at, its Newton seed
  };

  /// Run `law` on `plant` (fx: plant effects, sampled runs only; null = ideal plant). The plant
  /// and the law's model are each a serial tree or a closed chain (its loops say which).
  template<class Law>
  RolloutResult rollout(
    const Tree & plant, const Tree & nominal, const Law & law, const RolloutInputs & in,
    const Effects * fx);

  /// Wall time [s] of the dynamics calls one rollout of a `Law` on serial trees makes, with
  /// trivial glue: sampled, per control step: the law's calls (FLLaw: CRBA + nonLinearEffects;
  /// PDLaw: gravity) on the nominal model and 4 substeps ABA on the plant; continuous, per RK4
  /// step: 4 x (the law's calls + one ABA). A tree with loops is refused.
  template<class Law>
  double floor_timing(
    const Tree & plant, const Tree & nominal, bool sampled, int substeps, std::int64_t n_steps);

  /// Wall time [s] of `calls` plant accelerations at (q, qd) under actuator torques tau: ABA
  /// of a serial tree, the exact KKT of a closed chain.
  double acceleration_timing(const Tree & plant, const Vec & q, const Vec & qd, const Vec & tau,
                             std::int64_t calls);

  /// The plant's acceleration at (q, qd) under actuator torques tau (ABA or exact KKT).
  Vec plant_acceleration(const Tree & plant, const Vec & q, const Vec & qd, const Vec & tau);

#define RRR_PIN_ROLLOUT_LAW(Law, prefix)                                                         \
  prefix template RolloutResult rollout<Law>(                                                    \
    const Tree &, const Tree &, const Law &, const RolloutInputs &, const Effects *);            \
  prefix template double floor_timing<Law>(const Tree &, const Tree &, bool, int, std::int64_t);
#define RRR_PIN_ROLLOUT_EXTERN(Law) RRR_PIN_ROLLOUT_LAW(Law, extern)
  RRR_PIN_LAWS(RRR_PIN_ROLLOUT_EXTERN)
#undef RRR_PIN_ROLLOUT_EXTERN
} // namespace rrr_pin
