// Batched rollouts: B plants of one generated structure (dyn_*.c, rrr_pin.sim.dyngen) integrated
// together, structure-of-arrays (entry j of plant b at [j * B + b]), each plant with its own
// parameter vector, law state and divergence. Python entry point: rrr_pin.sim.batched.
//
// The loop is the compiled engine's (rollout.cpp: ideal sampled plant, or a continuous law
// integrated with the arm), operation for operation per plant; only the dynamics calls are the
// generated ones, on all B plants at once. A plant that diverges (same tests, same order as
// rollout.cpp) is recorded and then carried along on its initial state, unrecorded, so it
// touches no other plant's numbers: no operation crosses plants.
#pragma once

#include <cstdint>
#include <string>
#include <tuple>
#include <vector>

#include "effects.hpp"
#include "law.hpp"
#include "rollout.hpp"

namespace rrr_pin
{
  /// Generated dynamics of one structure (a dyn_<name>.c file). `pre` turns parameter vectors
  /// (np entries) into derived vectors (nd entries: the parameter-only expressions, once per
  /// plant); the other functions take derived vectors. `fd` is the forward-dynamics algorithm
  /// of fewer operations (`fd_algorithm`, "ldlt" or "aba"), `fd_other` the other one (for the
  /// structures compiled in; one registered at run time passes `fd` again).
  struct DynFunctions
  {
    const char * name;
    const char * structure;
    const char * fd_algorithm;
    int nq, np, nd;
    void (*pre)(int, const double *, double *);
    void (*crba)(int, const double *, const double *, double *);
    void (*nle)(int, const double *, const double *, const double *, double *);
    void (*gravity)(int, const double *, const double *, double *);
    void (*fd)(int, const double *, const double *, const double *, const double *, double *);
    void (*fd_other)(int, const double *, const double *, const double *, const double *,
                     double *);
    /// Inverse dynamics M(q) a + nle(q, v) (armature included), the FL law's torque.
    void (*id)(int, const double *, const double *, const double *, const double *, double *);
  };

  /// The generated structures compiled in, and their count.
  const DynFunctions * dyn_table(int & count);
  /// Every generated structure: compiled in, then those registered at run time.
  std::vector<DynFunctions> dyn_all();
  /// Register a structure's functions loaded at run time (rrr_pin.sim.dyncache: a shared
  /// object compiled from the generator's C), by address; names are unique.
  void dyn_register(const std::string & name, const std::string & structure,
                    const std::string & fd_algorithm, int nq, int np, int nd, std::uintptr_t pre,
                    std::uintptr_t crba, std::uintptr_t nle, std::uintptr_t gravity,
                    std::uintptr_t fd, std::uintptr_t fd_other, std::uintptr_t id);
  /// The generated structure named `name` (throws std::invalid_argument naming the known ones).
  const DynFunctions & dyn_by_name(const std::string & name);

  /// Batch bound (dyn_common.h RRR_DYN_BMAX).
  constexpr int kBatchMax = 16;

  /// (Q, QD, TAU) of shape (B (N + 1), n), plant b in rows b (N + 1) ...; NaN after each
  /// plant's divergence; bad_step (B,) (-1: none), bad_joint (B,), reason (B,).
  using BatchResult = std::tuple<RowMat, RowMat, RowMat, Eigen::VectorXi, Eigen::VectorXi,
                                 Eigen::VectorXi>;

  /// Run `law` on B plants (parameter rows of `plant`, (B, np)) with the law's model
  /// `nominal` (np,); `in` as for rollout() (q0, qd0, x0 shared), limits per plant (B, n).
  /// (F, Q, QD, TAU0, bad_step, bad_joint, reason) of batch_figures: per plant its figures
  /// (B, 3 + nq: RMS error, max |error|, RMS torque, RMS error per joint), its last state
  /// recorded (the diverging one) and its first torque.
  using FigureResult = std::tuple<RowMat, RowMat, RowMat, RowMat, Eigen::VectorXi,
                                  Eigen::VectorXi, Eigen::VectorXi>;

  /// batch_rollout reduced in the loop to the figures of a campaign's row
  /// (rrr_pin.sim.trajectory.tracking_figures_batch of the same run, bit for bit).
  template<class Law>
  FigureResult batch_figures(
    const std::string & name, const RowMat & plant, const Vec & nominal, const Law & law,
    const RolloutInputs & in, const RowMat & lower, const RowMat & upper,
    const Effects * fx = nullptr);

  template<class Law>
  BatchResult batch_rollout(
    const std::string & name, const RowMat & plant, const Vec & nominal, const Law & law,
    const RolloutInputs & in, const RowMat & lower, const RowMat & upper,
    const Effects * fx = nullptr);

  /// Wall time [s] of the bare generated dynamics calls of B plant-rollouts of a `Law`
  /// (the calls floor_timing() times, on all B plants per call).
  template<class Law>
  double batch_floor_timing(
    const std::string & name, const RowMat & plant, const Vec & nominal, bool sampled,
    int substeps, std::int64_t n_steps);

#define RRR_PIN_BATCH_LAW(Law, prefix)                                                           \
  prefix template BatchResult batch_rollout<Law>(                                                \
    const std::string &, const RowMat &, const Vec &, const Law &, const RolloutInputs &,        \
    const RowMat &, const RowMat &, const Effects *);                                            \
  prefix template FigureResult batch_figures<Law>(                                               \
    const std::string &, const RowMat &, const Vec &, const Law &, const RolloutInputs &,        \
    const RowMat &, const RowMat &, const Effects *);                                            \
  prefix template double batch_floor_timing<Law>(                                                \
    const std::string &, const RowMat &, const Vec &, bool, int, std::int64_t);
#define RRR_PIN_BATCH_EXTERN(Law) RRR_PIN_BATCH_LAW(Law, extern)
  RRR_PIN_LAWS(RRR_PIN_BATCH_EXTERN)
#undef RRR_PIN_BATCH_EXTERN
} // namespace rrr_pin
