// Python bindings of the compiled rollout: rrr_pin.sim._rollout (private; use
// rrr_pin.sim.compiled). Parameters travel as objects whose fields Python sets by name: a plant's
// Tree (rrr_pin.model.plant.TreeDescription), a law (one class per law of RRR_PIN_LAWS, law.hpp,
// named as its compiled form's `cpp`, its fields bound from the law's own list), RolloutInputs
// and Effects. LAWS: the names of the laws, in the list's order.
#include <cstdint>
#include <string>
#include <tuple>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>

#include "rollout.hpp"

namespace nb = nanobind;
using namespace rrr_pin;

namespace rrr_pin
{
  void bind_batch(nb::module_ & mod);  // batch_bind.cpp
}

namespace
{
  using LoopJoints = Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor>;

  /// Bind one law: its class (Law::name, Law::doc, a read-write attribute per Law::fields()),
  /// rollout() and floor_timing() (overloads, selected by the law's type).
  template<class Law>
  void def_law(nb::module_ & mod)
  {
    nb::class_<Law> cls(mod, Law::name, Law::doc);
    cls.def(nb::init<>());
    std::apply([&cls](auto... f) { (cls.def_rw(f.name, f.member), ...); }, Law::fields());
    mod.def(
      "rollout", &rollout<Law>, nb::arg("plant"), nb::arg("nominal"), nb::arg("law"),
      nb::arg("inputs"), nb::arg("effects").none() = nb::none(),
      nb::call_guard<nb::gil_scoped_release>(), "Run the closed loop; returns a RolloutResult.");
    mod.def(
      "floor_timing",
      [](const Tree & plant, const Tree & nominal, const Law &, bool sampled, int substeps,
         std::int64_t n_steps) {
        return floor_timing<Law>(plant, nominal, sampled, substeps, n_steps);
      },
      nb::arg("plant"), nb::arg("nominal"), nb::arg("law"), nb::arg("sampled"),
      nb::arg("substeps"), nb::arg("n_steps"), nb::call_guard<nb::gil_scoped_release>(),
      "Wall time [s] of the bare dynamics calls of a rollout of this law (serial trees).");
  }
} // namespace

NB_MODULE(_rollout, mod)
{
  mod.doc() = "Compiled closed-loop rollout on Pinocchio (private; use rrr_pin.sim.compiled).";

  nb::class_<Tree>(mod, "Tree", "A plant's tree, loop closures and coordinate split.")
    .def(
      nb::init<const std::string &, const IVec &, const IVec &, const LoopJoints &,
               const RowMat &, const IVec &, const Vec &, double, int, double, double>(),
      nb::arg("serialized"), nb::arg("actuated"), nb::arg("passive"), nb::arg("loop_joints"),
      nb::arg("loop_anchors"), nb::arg("rows"), nb::arg("home"), nb::arg("closure_tol"),
      nb::arg("max_iter"), nb::arg("cond_limit"), nb::arg("drift_bound"),
      "From pinocchio.Model.saveToString() text and a TreeDescription's arrays (loop_anchors "
      "(2 L, 3)).")
    .def_prop_ro("nv", &Tree::nv)
    .def_prop_ro("na", &Tree::na)
    .def_prop_ro("loops", &Tree::loops, "Number of loop closures (0: a serial tree).")
    .def(
      "save", [](const Tree & t) { return t.tree.save(); },
      "The model re-serialized with saveToString().")
    .def(
      "acceleration", &plant_acceleration, nb::arg("q"), nb::arg("qd"), nb::arg("tau"),
      "The plant's full qdd at (q, qd) under actuator torques tau (ABA or exact KKT).")
    .def(
      "closure_terms",
      [](const Tree & t, const Vec & q, const Vec & qd) {
        // M (full), nle, J, phi, gamma at (q, qd): the engine's own kinematics, for tests.
        if (q.size() != t.nv() || qd.size() != t.nv())
          throw std::invalid_argument("q and qd must have nv entries");
        Closure w(t);
        Mat M = pinocchio::crba(t.tree.model, w.data, CRef(q));
        M.triangularView<Eigen::StrictlyLower>() = M.transpose();
        Vec nle = pinocchio::nonLinearEffects(t.tree.model, w.data, CRef(q), CRef(qd));
        w.jacobian(q);
        Mat J = w.J;
        Vec phi = w.phi;
        w.gamma(q, qd);
        return nb::make_tuple(M, nle, J, phi, Vec(w.g));
      },
      nb::arg("q"), nb::arg("qd"), "(M, nle, J, phi, gamma) at (q, qd).");

  nb::class_<RolloutInputs>(mod, "RolloutInputs", "A validated run (rrr_pin.sim.trajectory.Run).")
    .def(nb::init<>())
    .def_rw("sampled", &RolloutInputs::sampled)
    .def_rw("R", &RolloutInputs::R)
    .def_rw("RD", &RolloutInputs::RD)
    .def_rw("RDD", &RolloutInputs::RDD)
    .def_rw("q0", &RolloutInputs::q0)
    .def_rw("qd0", &RolloutInputs::qd0)
    .def_rw("x0", &RolloutInputs::x0)
    .def_rw("lower", &RolloutInputs::lower)
    .def_rw("upper", &RolloutInputs::upper)
    .def_rw("vlim", &RolloutInputs::vlim)
    .def_rw("h", &RolloutInputs::h)
    .def_rw("substeps", &RolloutInputs::substeps)
    .def_rw("n_steps", &RolloutInputs::n_steps);

  nb::class_<RolloutResult>(mod, "RolloutResult", "What a rollout returns (rollout.hpp).")
    .def_ro("Q", &RolloutResult::Q)
    .def_ro("QD", &RolloutResult::QD)
    .def_ro("TAU", &RolloutResult::TAU)
    .def_ro("step", &RolloutResult::step)
    .def_ro("joint", &RolloutResult::joint)
    .def_ro("reason", &RolloutResult::reason)
    .def_ro("value", &RolloutResult::value)
    .def_ro("drift", &RolloutResult::drift)
    .def_ro("drift_v", &RolloutResult::drift_v)
    .def_ro("q", &RolloutResult::q)
    .def_ro("qd", &RolloutResult::qd)
    .def_ro("law_q", &RolloutResult::law_q)
    .def_ro("seed", &RolloutResult::seed);

  nb::class_<Effects> effects(mod, "Effects",
                              "Plant effects (rrr_pin.control.effects.Resolved); all off.");
  effects.def(nb::init<>());
  std::apply([&effects](auto... f) { (effects.def_rw(f.name, f.member), ...); },
             Effects::fields());

#define RRR_PIN_BIND_LAW(Law) def_law<Law>(mod);
  RRR_PIN_LAWS(RRR_PIN_BIND_LAW)
#undef RRR_PIN_BIND_LAW
#define RRR_PIN_LAW_NAME(Law) Law::name,
  const char * laws[] = {RRR_PIN_LAWS(RRR_PIN_LAW_NAME)};
#undef RRR_PIN_LAW_NAME
  nb::list names;
  for (const char * name : laws)
    names.append(name);
  mod.attr("LAWS") = nb::tuple(names);

  mod.def("check_reference", &check_reference, nb::arg("plant"), nb::arg("R"),
          nb::call_guard<nb::gil_scoped_release>(),
          "Close the loop along R from home: (status, index, cond) (check_chain_reference's "
          "test; a serial tree passes).");
  mod.def("acceleration_timing", &acceleration_timing, nb::arg("plant"), nb::arg("q"),
          nb::arg("qd"), nb::arg("tau"), nb::arg("calls"),
          nb::call_guard<nb::gil_scoped_release>(),
          "Wall time [s] of `calls` plant accelerations (ABA or exact KKT).");

  bind_batch(mod);

  mod.def("pinocchio_version", []() { return std::string(PINOCCHIO_VERSION); });
  mod.def("eigen_version", []() {
    return std::to_string(EIGEN_WORLD_VERSION) + "." + std::to_string(EIGEN_MAJOR_VERSION) + "."
           + std::to_string(EIGEN_MINOR_VERSION);
  });
}
