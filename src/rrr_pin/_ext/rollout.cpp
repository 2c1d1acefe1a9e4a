// Compiled closed-loop rollout: plant integration with Pinocchio's ABA, feedback linearization
// with the nominal model's CRBA/RNEA, a discrete linear controller K and a sinusoidal reference,
// all in one C++ loop (no return to Python per step). Python entry point: rrr_pin.compiled.
//
// The algorithm is specified in rrr_pin/compiled.py (rollout_compiled); keep both in step.
//
// ABI: this file is compiled against the Pinocchio headers of the `libpinocchio` wheel and links
// its shared libraries, whose SONAME carries no version. The package pins one exact `pin`
// version at build and run time, and rrr_pin.compiled compares `pinocchio_version()` with the
// imported pinocchio before the first call.

#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <tuple>

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
#include <pinocchio/serialization.hpp>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>

namespace nb = nanobind;

namespace
{
  using Model = pinocchio::Model;
  using Data = pinocchio::Data;
  using Vec = Eigen::VectorXd;
  using Mat = Eigen::MatrixXd;
  using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  // Eigen::Ref arguments select the explicit template instantiations compiled into
  // libpinocchio_default (the same code the Python bindings call).
  using CRef = Eigen::Ref<const Vec>;

  /// A deserialized pinocchio::Model; read-only once loaded (each call makes its own Data), so
  /// one instance may serve concurrent rollouts.
  struct CompiledModel
  {
    Model model;

    explicit CompiledModel(const std::string & serialized)
    {
      model.loadFromString(serialized);
    }

    int nq() const
    {
      return model.nq;
    }

    std::string save() const
    {
      return model.saveToString();
    }
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

  inline const Vec & aba(Workspace & w, const Vec & q, const Vec & v, const Vec & tau)
  {
    return pinocchio::aba(w.model, w.data, CRef(q), CRef(v), CRef(tau));
  }

  inline const Mat & crba(Workspace & w, const Vec & q)
  {
    return pinocchio::crba(w.model, w.data, CRef(q));
  }

  inline const Vec & nle(Workspace & w, const Vec & q, const Vec & v)
  {
    return pinocchio::nonLinearEffects(w.model, w.data, CRef(q), CRef(v));
  }

  /// Index of the first joint whose q or qd is non-finite or exceeds `bound`, or -1.
  inline int bad_joint(const Vec & q, const Vec & qd, double bound)
  {
    for (Eigen::Index j = 0; j < q.size(); ++j)
      if (!(std::abs(q[j]) <= bound) || !(std::abs(qd[j]) <= bound)) // false for NaN
        return static_cast<int>(j);
    return -1;
  }

  /// Status codes, mirrored in rrr_pin.compiled.
  enum Status : int
  {
    kOk = 0,
    kDiverged = 1,
  };

  using RolloutResult = std::tuple<RowMat, RowMat, RowMat, RowMat, int, std::int64_t, int>;

  RolloutResult rollout(
    const CompiledModel & plant_model,
    const CompiledModel & nominal_model,
    double lam,
    const Mat & Ad,
    const Mat & Bd,
    const Mat & Cd,
    const Mat & Dd,
    const Vec & home,
    const Vec & amp,
    const Vec & omega,
    const Vec & phase,
    double Ts,
    int substeps,
    std::int64_t n_steps,
    double bound)
  {
    const Eigen::Index n = plant_model.model.nq;
    const Eigen::Index m = Ad.rows();
    if (nominal_model.model.nq != n)
      throw std::invalid_argument("plant and nominal models differ in nq");
    if (
      Ad.cols() != m || Bd.rows() != m || Bd.cols() != n || Cd.rows() != n || Cd.cols() != m
      || Dd.rows() != n || Dd.cols() != n)
      throw std::invalid_argument("controller matrices have inconsistent shapes");
    if (home.size() != n || amp.size() != n || omega.size() != n || phase.size() != n)
      throw std::invalid_argument("reference parameters must have nq entries");
    if (substeps < 1 || n_steps < 0)
      throw std::invalid_argument("substeps must be >= 1 and n_steps >= 0");

    const double nan = std::numeric_limits<double>::quiet_NaN();
    RowMat Q = RowMat::Constant(n_steps + 1, n, nan);
    RowMat QD = RowMat::Constant(n_steps + 1, n, nan);
    RowMat TAU = RowMat::Constant(n_steps, n, nan);
    RowMat E = RowMat::Constant(n_steps, n, nan);
    int status = kOk;
    std::int64_t bad_step = -1;
    int bad_j = -1;

    {
      nb::gil_scoped_release release;

      Workspace plant(plant_model), nominal(nominal_model);
      const double h = Ts / substeps;
      const double lam2 = lam * lam;
      Vec q(n), qd(n), r(n), rd(n), rdd(n), e(n), y(n), taubar(n), tau(n);
      Vec x = Vec::Zero(m), xn(m);
      Vec k1q(n), k1v(n), k2q(n), k2v(n), k3q(n), k3v(n), k4q(n), k4v(n), qs(n), vs(n);
      Mat M(n, n);

      auto reference = [&](double t) {
        for (Eigen::Index j = 0; j < n; ++j)
        {
          const double arg = omega[j] * t + phase[j];
          const double s = std::sin(arg), c = std::cos(arg);
          r[j] = home[j] + amp[j] * s;
          rd[j] = amp[j] * omega[j] * c;
          rdd[j] = -amp[j] * omega[j] * omega[j] * s;
        }
      };

      reference(0.0);
      q = r;
      qd = rd;
      Q.row(0) = q.transpose();
      QD.row(0) = qd.transpose();
      bad_j = bad_joint(q, qd, bound);
      if (bad_j >= 0)
      {
        status = kDiverged;
        bad_step = 0;
      }

      for (std::int64_t k = 0; k < n_steps && status == kOk; ++k)
      {
        reference(static_cast<double>(k) * Ts);
        e = r - q;
        // Controller: y with the old state, then the state update.
        y.noalias() = Dd * e;
        if (m > 0)
        {
          y.noalias() += Cd * x;
          xn.noalias() = Ad * x;
          xn.noalias() += Bd * e;
          x.swap(xn);
        }
        taubar = rdd + 2.0 * lam * (rd - qd) + lam2 * (e + y);
        // Feedback linearization, eq. (8), with the nominal model; crba fills the upper triangle.
        M = crba(nominal, q);
        M.triangularView<Eigen::StrictlyLower>() = M.transpose();
        tau.noalias() = M * taubar;
        tau += nle(nominal, q, qd);
        TAU.row(k) = tau.transpose();
        E.row(k) = e.transpose();

        // Plant: S classical RK4 steps of h on (q, qd), tau held.
        for (int s = 0; s < substeps; ++s)
        {
          k1q = qd;
          k1v = aba(plant, q, qd, tau);
          qs = q + 0.5 * h * k1q;
          vs = qd + 0.5 * h * k1v;
          k2q = vs;
          k2v = aba(plant, qs, vs, tau);
          qs = q + 0.5 * h * k2q;
          vs = qd + 0.5 * h * k2v;
          k3q = vs;
          k3v = aba(plant, qs, vs, tau);
          qs = q + h * k3q;
          vs = qd + h * k3v;
          k4q = vs;
          k4v = aba(plant, qs, vs, tau);
          q += (h / 6.0) * (k1q + 2.0 * k2q + 2.0 * k3q + k4q);
          qd += (h / 6.0) * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
        }
        Q.row(k + 1) = q.transpose();
        QD.row(k + 1) = qd.transpose();
        bad_j = bad_joint(q, qd, bound);
        if (bad_j >= 0)
        {
          status = kDiverged;
          bad_step = k + 1;
        }
      }
    }
    return {std::move(Q), std::move(QD), std::move(TAU), std::move(E), status, bad_step, bad_j};
  }

  /// Wall time [s] of the Pinocchio calls one rollout needs (per control step: 4*S ABA on the
  /// plant, one CRBA and one nonLinearEffects on the nominal model), with trivial glue.
  double floor_timing(
    const CompiledModel & plant_model,
    const CompiledModel & nominal_model,
    int substeps,
    std::int64_t n_steps)
  {
    if (nominal_model.model.nq != plant_model.model.nq)
      throw std::invalid_argument("plant and nominal models differ in nq");
    if (substeps < 1 || n_steps < 0)
      throw std::invalid_argument("substeps must be >= 1 and n_steps >= 0");
    nb::gil_scoped_release release;
    Workspace plant(plant_model), nominal(nominal_model);
    const Eigen::Index n = plant.model.nq;
    Vec q = Vec::Constant(n, 0.3), qd = Vec::Constant(n, 0.1), tau = Vec::Zero(n);
    double sink = 0.0;
    const auto t0 = std::chrono::steady_clock::now();
    for (std::int64_t k = 0; k < n_steps; ++k)
    {
      sink += crba(nominal, q)(0, 0);
      tau = nle(nominal, q, qd);
      for (int s = 0; s < 4 * substeps; ++s)
        sink += aba(plant, q, qd, tau)[0];
    }
    const auto t1 = std::chrono::steady_clock::now();
    if (!std::isfinite(sink))
      throw std::runtime_error("floor_timing: non-finite result");
    return std::chrono::duration<double>(t1 - t0).count();
  }

} // namespace

NB_MODULE(_rollout, mod)
{
  mod.doc() = "Compiled closed-loop rollout on Pinocchio (private; use rrr_pin.compiled).";

  nb::class_<CompiledModel>(mod, "CompiledModel")
    .def(
      nb::init<const std::string &>(), nb::arg("serialized"),
      "Load a model from pinocchio.Model.saveToString() text.")
    .def_prop_ro("nq", &CompiledModel::nq)
    .def("save", &CompiledModel::save, "The model re-serialized with saveToString().");

  mod.def(
    "rollout", &rollout, nb::arg("plant"), nb::arg("nominal"), nb::arg("lam"), nb::arg("Ad"),
    nb::arg("Bd"), nb::arg("Cd"), nb::arg("Dd"), nb::arg("home"), nb::arg("amp"),
    nb::arg("omega"), nb::arg("phase"), nb::arg("Ts"), nb::arg("substeps"), nb::arg("n_steps"),
    nb::arg("bound"), "Run the closed loop; returns (q, qd, tau, e, status, bad_step, bad_joint).");

  mod.def(
    "floor_timing", &floor_timing, nb::arg("plant"), nb::arg("nominal"), nb::arg("substeps"),
    nb::arg("n_steps"), "Wall time [s] of the bare Pinocchio calls of a rollout.");

  mod.def("pinocchio_version", []() { return std::string(PINOCCHIO_VERSION); });
  mod.def("eigen_version", []() {
    return std::to_string(EIGEN_WORLD_VERSION) + "." + std::to_string(EIGEN_MAJOR_VERSION) + "."
           + std::to_string(EIGEN_MINOR_VERSION);
  });
}
