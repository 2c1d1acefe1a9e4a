// Compiled closed-chain engine (issue 22): a parallel mechanism's full constrained dynamics and
// the reduced-model FL law (ChainFLForm) in one C++ loop. Python entry point:
// rrr_pin.sim.chain_compiled.run_chain_compiled; bindings in chain_bind.cpp.
//
// The algorithm is the Python reference engine's (rrr_pin.sim.closed_chain, sampled law),
// operation for operation, with one difference of method: the KKT system of the constrained
// dynamics is solved exactly on the independent rows of J (Schur complement of M) where the
// Python engine calls Pinocchio's proximal constraintDynamics, which converges to that solution
// (to about 6e-11 rad/s^2 at mu = 1e-4). The dynamics are Pinocchio's own C++ algorithms (CRBA,
// nonLinearEffects, RNEA, joint Jacobians, second-order forward kinematics) on the deserialized
// model, so every joint type Pinocchio has (the 5-bar's unaligned revolutes, the Delta's
// composite joints) and every perturbed parameter set run alike.
#pragma once

#include <cstdint>
#include <tuple>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/SVD>

#include "model.hpp"

namespace rrr_pin
{
  using IVec = Eigen::VectorXi;

  /// A closed chain: the tree, its loop-closure anchor points and the coordinate split
  /// (rrr_pin.model.closed_chain.ClosedChain). Read-only once built.
  struct ChainModel
  {
    CompiledModel tree;
    IVec joint_a, joint_b;  // per closure: the joint carrying each anchor point
    Mat anchor_a, anchor_b; // (3, nc): the anchor points in their joint's frame [m]
    IVec rows;              // independent rows of the stacked gaps (3 nc), one per passive coordinate
    IVec act, pas;          // velocity indices of the actuated and passive coordinates
    Vec home;               // a closed configuration (the law's first Newton seed)

    ChainModel(const std::string & serialized, const IVec & joint_a, const IVec & joint_b,
               const Mat & anchor_a, const Mat & anchor_b, const IVec & rows, const IVec & act,
               const IVec & pas, const Vec & home);
    int nv() const { return tree.model.nv; }
    int na() const { return static_cast<int>(act.size()); }
  };

  /// Status of a closure or of a run (mirrored in rrr_pin.sim.chain_compiled.STATUS).
  enum ChainStatus : int
  {
    kChainOk = 0,
    kChainDrift = 1,          // a step left a gap above the drift bound (ConstraintDrift)
    kChainPlantSingular = 2,  // the plant's projection met cond(J_p) > limit
    kChainPlantNoClose = 3,   // the plant's projection did not converge (LoopClosureError)
    kChainPlantCrossed = 4,   // det J_p changed sign over a step
    kChainLawSingular = 5,    // the law's loop closure met cond(J_p) > limit
    kChainLawNoClose = 6,     // the law's loop closure did not converge
  };

  /// Kinematics and dynamics of one ChainModel with its own workspace (one per thread).
  class ChainWork
  {
  public:
    explicit ChainWork(const ChainModel & cm);

    /// J (rows, nv) and phi (rows) at q: one computeJointJacobians.
    void jacobian(const Vec & q);
    /// J and phi from the placements and joint Jacobians already in data.
    void points();
    /// phi at q (forward kinematics of positions only).
    void residual(const Vec & q);
    /// gamma = Jdot qd (rows) at (q, qd): second-order kinematics with qdd = 0.
    void gamma(const Vec & q, const Vec & qd);
    /// gamma from the placements, velocities and zero-qdd accelerations already in data.
    void gamma_points();
    /// cond(J_p) of the last jacobian() (2-norm; inf if singular).
    double cond() const;
    /// Newton on the passive coordinates of q (actuated parts kept) to tol; J, phi at the
    /// solution. Returns kChainOk, or 1 (cond above the limit, cond_out set), 2 (no convergence).
    /// fresh: J and phi are already those of q (the first iteration skips jacobian(q)).
    int close(Vec & q, double tol, int max_iter, double cond_limit, double & cond_out,
              bool fresh = false);
    /// S = [I; -J_p^-1 J_a] of the last jacobian() into S (nv, na).
    void S_of(Mat & S);
    /// Full constrained accelerations at (q, qd) with generalized force u: the exact KKT.
    const Vec & acceleration(const Vec & q, const Vec & qd, const Vec & u);

    const ChainModel & cm;
    Data data;
    Mat J, Jfull, Jj, Jp, Ja, M, S;
    Vec phi, gap, g, qdd;

  private:
    void point(int joint, const Eigen::Ref<const Eigen::Vector3d> & t, Eigen::Vector3d & p) const;
    Mat MiJt, A;
    Vec b, f, zero;
    Eigen::LLT<Mat> llt_M, llt_A;
  };

  /// The law of ChainFLForm: FL (and H-infinity + FL) on the law's own closed chain's reduced
  /// model, its passive coordinates by Newton seeded from its previous sample.
  struct ChainFLLaw
  {
    double lam = 0.0;  // [rad/s]
    Mat A, B, C, D;    // discrete K on e: (m, m), (m, n), (n, m), (n, n); m = 0 for FL alone
  };

  /// Everything a closed-chain run needs besides the models and the law (set by name).
  struct ChainInputs
  {
    RowMat R, RD, RDD;         // actuated reference (N + 1, na) [rad, rad/s, rad/s^2]
    Vec q0, qd0, x0;           // full closed initial state (nv,), (nv,); law state (m,)
    double h = 0.0;            // RK4 step [s]
    int substeps = 1;          // RK4 steps per control period
    std::int64_t n_steps = 0;  // control periods N
    double closure_tol = 0.0;  // CLOSURE_TOL [m]
    int max_iter = 30;         // Newton iterations of a closure
    double cond_limit = 0.0;   // COND_LIMIT
    double drift_bound = 0.0;  // DRIFT_BOUND [m]
  };

  /// The run: actuated (q, qd, tau) (N + 1, na) up to the stop, drift records, final state;
  /// on a stop, its status, step and the state Python re-derives the exact error from.
  struct ChainResult
  {
    RowMat Q, QD, TAU;
    double drift = 0.0, drift_v = 0.0;
    Vec q, qd;              // final full state (or the plant's state at the stop)
    int status = kChainOk;
    std::int64_t step = -1; // control step of the stop
    double value = 0.0;     // the gap [m] (drift) or cond(J_p) of the stop
    Vec seed;               // the law's Newton seed at a law stop (full nominal configuration)
  };

  ChainResult chain_rollout(const ChainModel & plant, const ChainModel & nominal,
                            const ChainFLLaw & law, const ChainInputs & in);

  /// The reference check of rrr_pin.sim.closed_chain.check_chain_reference on actuated samples R
  /// (N, na), Newton from `seed` then from each solution: (status, sample index of a stop or of
  /// the worst cond(J_p), worst cond(J_p)); status 0, or 1 at a sample where the loop does not
  /// close, cond(J_p) exceeds the limit, or det J_p changed sign since the previous sample.
  std::tuple<int, std::int64_t, double> chain_check_reference(
    const ChainModel & cm, const RowMat & R, const Vec & seed, double tol, int max_iter,
    double cond_limit);

  /// Wall time [s] of `calls` exact-KKT accelerations on `plant` at (q, qd, u) (the compiled
  /// engine's share of a run's plant work, for the benchmark).
  double chain_kkt_timing(const ChainModel & plant, const Vec & q, const Vec & qd, const Vec & u,
                          std::int64_t calls);
} // namespace rrr_pin
