// Compiled closed-loop rollout: the plant integrated with Pinocchio's ABA (or the generated
// dynamics) and a compiled law (law.hpp), all in one C++ loop with no return to Python per step.
// Python entry point: rrr_pin.sim.compiled.run_compiled; bindings in module.cpp.
//
// The algorithm is the Python reference engine's (rrr_pin.sim.simulation: _python_sampled,
// _python_effects and _python_continuous), operation for operation; tests/test_engines.py pins
// the two together. The reference arrives sampled on the grid where the law is evaluated (one
// row per control instant for sampled laws, per half RK4 step for continuous laws), so any
// reference runs here.
#pragma once

#include <cstdint>
#include <tuple>

#include "effects.hpp"
#include "law.hpp"
#include "model.hpp"

namespace rrr_pin
{
  /// Everything a rollout needs besides the models, the law and the effects
  /// (rrr_pin.sim.trajectory.Run, set field by field from Python).
  struct RolloutInputs
  {
    bool sampled = true;        // sampled law (zero-order hold) or continuous law
    RowMat R, RD, RDD;          // reference [rad, rad/s, rad/s^2], (N + 1, n) sampled,
                                // (2 N + 1, n) continuous (every half step)
    Vec q0, qd0, x0;            // initial state (n,), (n,), law state (nx,)
    Vec lower, upper;           // joint limits [rad] (n,), margin included
    double vlim = 0.0;          // speed limit [rad/s]
    double h = 0.0;             // RK4 step [s]
    int substeps = 1;           // RK4 steps per control period (sampled)
    std::int64_t n_steps = 0;   // N control periods (sampled) or RK4 steps (continuous)
  };

  /// Throw std::invalid_argument unless `in` fits n joints and a law of nx states: the law
  /// state, the step counts and the reference arrays (every engine's rollout checks these).
  void check_inputs(const RolloutInputs & in, Eigen::Index n, Eigen::Index nx);

  /// Divergence reasons, mirrored in rrr_pin.sim.trajectory.REASONS (same order of tests as
  /// rrr_pin.sim.trajectory.diverged_joint: non-finite, then speed, then limits). kLawTorque:
  /// the law's torque (before any saturation) is NaN or inf; bad_step is then the step whose law
  /// evaluation (sampled: at its start; continuous: at one of its RK4 stages) returned it.
  enum Reason : int
  {
    kOk = -1,
    kNonFinite = 0,
    kSpeed = 1,
    kLimits = 2,
    kLawTorque = 3,
  };

  /// (q, qd, tau) of shape (N + 1, n), NaN after a divergence; bad_step (-1: none), bad_joint,
  /// reason.
  using RolloutResult = std::tuple<RowMat, RowMat, RowMat, std::int64_t, int, int>;

  /// Run `law` on `plant` (fx: plant effects, sampled runs only; null = ideal plant).
  template<class Law>
  RolloutResult rollout(
    const CompiledModel & plant, const CompiledModel & nominal, const Law & law,
    const RolloutInputs & in, const Effects * fx);

  /// Wall time [s] of the dynamics calls one rollout of a `Law` makes, with trivial glue:
  /// sampled, per control step: the law's calls (FLLaw: CRBA + nonLinearEffects; PDLaw: gravity)
  /// on the nominal model and 4 substeps ABA on the plant; continuous, per RK4 step: 4 x (the
  /// law's calls + one ABA).
  template<class Law>
  double floor_timing(
    const CompiledModel & plant, const CompiledModel & nominal, bool sampled, int substeps,
    std::int64_t n_steps);

  extern template RolloutResult rollout<FLLaw>(
    const CompiledModel &, const CompiledModel &, const FLLaw &, const RolloutInputs &,
    const Effects *);
  extern template RolloutResult rollout<FLAWLaw>(
    const CompiledModel &, const CompiledModel &, const FLAWLaw &, const RolloutInputs &,
    const Effects *);
  extern template RolloutResult rollout<PDLaw>(
    const CompiledModel &, const CompiledModel &, const PDLaw &, const RolloutInputs &,
    const Effects *);
  extern template double floor_timing<FLLaw>(
    const CompiledModel &, const CompiledModel &, bool, int, std::int64_t);
  extern template double floor_timing<FLAWLaw>(
    const CompiledModel &, const CompiledModel &, bool, int, std::int64_t);
  extern template double floor_timing<PDLaw>(
    const CompiledModel &, const CompiledModel &, bool, int, std::int64_t);
} // namespace rrr_pin
