// The model of a compiled rollout: a deserialized pinocchio::Model and the four dynamics calls
// the loops make on it (Pinocchio's C++ algorithms).
//
// ABI: compiled against the Pinocchio headers of the `libpinocchio` wheel and linked to its
// shared libraries, whose SONAME carries no version. The package pins one exact `pin` version at
// build and run time, and rrr_pin.sim.extension compares `pinocchio_version()` with the imported
// pinocchio before the first call.
#pragma once

#include <stdexcept>
#include <string>

// The wheel's libraries are built for baseline x86-64 (16-byte Eigen alignment). Code built with
// other alignment settings (e.g. -march=native -> 32 bytes) passes misaligned objects to them
// and crashes at the first call; CMakeLists.txt sets these, this guard catches a bypass.
#if !defined(EIGEN_MAX_ALIGN_BYTES) || EIGEN_MAX_ALIGN_BYTES != 16
  #error "rrr_pin._rollout must be compiled with EIGEN_MAX_ALIGN_BYTES=16 (see CMakeLists.txt)"
#endif

#include <Eigen/Core>

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody.hpp>

namespace rrr_pin
{
  using Model = pinocchio::Model;
  using Data = pinocchio::Data;
  using Vec = Eigen::VectorXd;
  using Mat = Eigen::MatrixXd;
  using IVec = Eigen::VectorXi;
  using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  // Eigen::Ref arguments select the explicit template instantiations compiled into
  // libpinocchio_default (the same code the Python bindings call).
  using CRef = Eigen::Ref<const Vec>;

  /// A deserialized pinocchio::Model; read-only once loaded (each call makes its own Data), so
  /// one instance may serve concurrent rollouts.
  struct CompiledModel
  {
    Model model;

    explicit CompiledModel(const std::string & serialized);
    int nq() const { return model.nq; }
    std::string save() const;
  };

  /// A model with its workspace, for one call.
  struct Workspace
  {
    const Model & model;
    Data data;

    explicit Workspace(const CompiledModel & m)
    : model(m.model)
    , data(m.model)
    {
    }
  };

  /// Joint accelerations qdd = ABA(q, v, tau) [rad/s^2].
  inline const Vec & aba(Workspace & w, const Vec & q, const Vec & v, const Vec & tau)
  {
    return pinocchio::aba(w.model, w.data, CRef(q), CRef(v), CRef(tau));
  }

  /// Joint-space inertia M(q) [kg m^2] by CRBA (Pinocchio fills the upper triangle only).
  inline const Mat & crba(Workspace & w, const Vec & q)
  {
    return pinocchio::crba(w.model, w.data, CRef(q));
  }

  /// Coriolis, centrifugal and gravity torques V(q, v) + G(q) [N m].
  inline const Vec & nle(Workspace & w, const Vec & q, const Vec & v)
  {
    return pinocchio::nonLinearEffects(w.model, w.data, CRef(q), CRef(v));
  }

  /// Gravity torque G(q) [N m].
  inline const Vec & gravity(Workspace & w, const Vec & q)
  {
    return pinocchio::computeGeneralizedGravity(w.model, w.data, CRef(q));
  }
} // namespace rrr_pin
