// A plant as the compiled engine takes it: the kinematic tree, its loop closures and the split
// of its coordinates into actuated and passive ones (rrr_pin.model.plant.TreeDescription). A
// serial arm is a tree with no loop (every coordinate actuated); a closed chain the same tree
// with loop closures, whose kinematics (the anchor gaps phi, their Jacobian J = [J_a J_p] and
// gamma = Jdot qd), Newton closure, S = [I; -J_p^-1 J_a] and exact KKT dynamics are Closure's.
//
// The KKT system of the constrained dynamics is solved exactly on the independent rows of J
// (Schur complement of M), where the Python engine calls Pinocchio's proximal
// constraintDynamics, which converges to that solution (to about 6e-11 rad/s^2 at mu = 1e-4).
// The dynamics are Pinocchio's own C++ algorithms (CRBA, nonLinearEffects, RNEA, joint
// Jacobians, second-order forward kinematics) on the deserialized model, so every joint type
// Pinocchio has (the 5-bar's unaligned revolutes, the Delta's composite joints) and every
// perturbed parameter set run alike; the loop-closure kinematics are written here from
// Pinocchio's joint placements, velocities and accelerations.
#pragma once

#include <cstdint>
#include <string>
#include <tuple>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include "model.hpp"

namespace rrr_pin
{
  /// The tree, its loop closures and the coordinate split (TreeDescription). Read-only once
  /// built, so one instance may serve concurrent rollouts.
  struct Tree
  {
    CompiledModel tree;
    IVec joint_a, joint_b;  // per loop: the joint carrying each anchor point (0: the ground)
    Mat anchor_a, anchor_b; // (3, L): the anchor points in their joint's frame [m]
    IVec rows;              // independent rows of the stacked gaps (3 L), one per passive coord.
    IVec act, pas;          // velocity indices of the actuated and passive coordinates
    Vec home;               // a closed configuration (the Newton seed of a law's first closure)
    double closure_tol;     // Newton stops at this residual [m]
    int max_iter;           // Newton iterations before the loop counts as not closing
    double cond_limit;      // largest cond(J_p) accepted (type-II singularity above it)
    double drift_bound;     // largest gap [m] one RK4 step may leave before its projection

    /// From pinocchio.Model.saveToString() text; loop_joints (L, 2), loop_anchors (2 L, 3)
    /// (rows 2 k and 2 k + 1: the anchor points of loop k's two sides).
    Tree(const std::string & serialized, const IVec & act, const IVec & pas,
         const Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor> & loop_joints,
         const RowMat & loop_anchors, const IVec & rows, const Vec & home, double closure_tol,
         int max_iter, double cond_limit, double drift_bound);
    int nv() const { return tree.model.nv; }
    int na() const { return static_cast<int>(act.size()); }
    int loops() const { return static_cast<int>(joint_a.size()); }
  };

  /// Kinematics and dynamics of a Tree's loop closure, with its own workspace (one per thread).
  class Closure
  {
  public:
    explicit Closure(const Tree & tree);

    /// J (rows, nv) and phi (rows) at q: one computeJointJacobians.
    void jacobian(const Vec & q);
    /// J and phi from the placements and joint Jacobians already in data.
    void points();
    /// gamma = Jdot qd (rows) at (q, qd): second-order kinematics with qdd = 0.
    void gamma(const Vec & q, const Vec & qd);
    /// gamma from the placements, velocities and zero-qdd accelerations already in data.
    void gamma_points();
    /// cond(J_p) of the last jacobian() (2-norm; inf if singular).
    double cond() const;
    /// Newton on the passive coordinates of q (actuated parts kept) to the tree's tolerance;
    /// J, phi at the solution. Returns 0, or 1 (cond above the limit, cond_out set), 2 (no
    /// convergence). fresh: J and phi are already those of q (the first iteration skips
    /// jacobian(q)).
    int close(Vec & q, double & cond_out, bool fresh = false);
    /// S = [I; -J_p^-1 J_a] of the last jacobian() into S (nv, na).
    void S_of(Mat & S);
    /// Full constrained accelerations at (q, qd) with generalized force u: the exact KKT.
    const Vec & acceleration(const Vec & q, const Vec & qd, const Vec & u);

    const Tree & cm;
    Data data;
    Mat J, Jfull, Jj, Jp, Ja, M;
    Vec phi, gap, g, qdd;

  private:
    void point(int joint, const Eigen::Ref<const Eigen::Vector3d> & t, Eigen::Vector3d & p) const;
    Mat MiJt, A;
    Vec b, f, zero;
    Eigen::LLT<Mat> llt_M, llt_A;
  };

  /// max |v_i|, NaN if any entry is NaN (as numpy's max of abs).
  double maxabs(const Vec & v);

  /// The reference check of rrr_pin.model.closed_chain.check_chain_reference on actuated samples
  /// R (N, na), Newton from the tree's home then from each solution: (status, sample index of
  /// a stop or of the worst cond(J_p), worst cond(J_p)); status 0, or 1 at a sample where the
  /// loop does not close, cond(J_p) exceeds the limit, or det J_p changed sign since the
  /// previous sample. A tree with no loop passes with (0, 0, 1).
  std::tuple<int, std::int64_t, double> check_reference(const Tree & tree, const RowMat & R);
} // namespace rrr_pin
