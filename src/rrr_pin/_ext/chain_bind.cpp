// Python bindings of the compiled closed-chain engine (chain.hpp), added to rrr_pin.sim._rollout
// by module.cpp (private; use rrr_pin.sim.chain_compiled).
#include <cstdint>
#include <string>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>

#include "chain.hpp"

namespace nb = nanobind;

namespace rrr_pin
{
  void bind_chain(nb::module_ & mod)
  {
    nb::class_<ChainModel>(mod, "ChainModel", "A closed chain: tree, loop anchors, coordinates.")
      .def(nb::init<const std::string &, const IVec &, const IVec &, const Mat &, const Mat &,
                    const IVec &, const IVec &, const IVec &, const Vec &>(),
           nb::arg("serialized"), nb::arg("joint_a"), nb::arg("joint_b"), nb::arg("anchor_a"),
           nb::arg("anchor_b"), nb::arg("rows"), nb::arg("act"), nb::arg("pas"),
           nb::arg("home"))
      .def_prop_ro("nv", &ChainModel::nv)
      .def(
        "terms",
        [](const ChainModel & cm, const Vec & q, const Vec & qd) {
          // M (full), nle, J, phi, gamma at (q, qd): the engine's own kinematics, for tests.
          if (q.size() != cm.nv() || qd.size() != cm.nv())
            throw std::invalid_argument("q and qd must have nv entries");
          ChainWork w(cm);
          Mat M = pinocchio::crba(cm.tree.model, w.data, CRef(q));
          M.triangularView<Eigen::StrictlyLower>() = M.transpose();
          Vec nle = pinocchio::nonLinearEffects(cm.tree.model, w.data, CRef(q), CRef(qd));
          w.jacobian(q);
          Mat J = w.J;
          Vec phi = w.phi;
          w.gamma(q, qd);
          return nb::make_tuple(M, nle, J, phi, Vec(w.g));
        },
        nb::arg("q"), nb::arg("qd"), "(M, nle, J, phi, gamma) at (q, qd).")
      .def(
        "acceleration",
        [](const ChainModel & cm, const Vec & q, const Vec & qd, const Vec & u) {
          if (q.size() != cm.nv() || qd.size() != cm.nv() || u.size() != cm.nv())
            throw std::invalid_argument("q, qd and u must have nv entries");
          ChainWork w(cm);
          return Vec(w.acceleration(q, qd, u));
        },
        nb::arg("q"), nb::arg("qd"), nb::arg("u"), "Exact constrained qdd at (q, qd, u).");

    nb::class_<ChainFLLaw>(mod, "ChainFLLaw", "FL on a closed chain's reduced model (ChainFLForm).")
      .def(nb::init<>())
      .def_rw("lam", &ChainFLLaw::lam)
      .def_rw("A", &ChainFLLaw::A)
      .def_rw("B", &ChainFLLaw::B)
      .def_rw("C", &ChainFLLaw::C)
      .def_rw("D", &ChainFLLaw::D);

    nb::class_<ChainInputs>(mod, "ChainInputs", "A validated closed-chain run.")
      .def(nb::init<>())
      .def_rw("R", &ChainInputs::R)
      .def_rw("RD", &ChainInputs::RD)
      .def_rw("RDD", &ChainInputs::RDD)
      .def_rw("q0", &ChainInputs::q0)
      .def_rw("qd0", &ChainInputs::qd0)
      .def_rw("x0", &ChainInputs::x0)
      .def_rw("h", &ChainInputs::h)
      .def_rw("substeps", &ChainInputs::substeps)
      .def_rw("n_steps", &ChainInputs::n_steps)
      .def_rw("closure_tol", &ChainInputs::closure_tol)
      .def_rw("max_iter", &ChainInputs::max_iter)
      .def_rw("cond_limit", &ChainInputs::cond_limit)
      .def_rw("drift_bound", &ChainInputs::drift_bound);

    nb::class_<ChainResult>(mod, "ChainResult", "What a closed-chain run returns.")
      .def_ro("Q", &ChainResult::Q)
      .def_ro("QD", &ChainResult::QD)
      .def_ro("TAU", &ChainResult::TAU)
      .def_ro("drift", &ChainResult::drift)
      .def_ro("drift_v", &ChainResult::drift_v)
      .def_ro("q", &ChainResult::q)
      .def_ro("qd", &ChainResult::qd)
      .def_ro("status", &ChainResult::status)
      .def_ro("step", &ChainResult::step)
      .def_ro("value", &ChainResult::value)
      .def_ro("seed", &ChainResult::seed);

    mod.def("chain_rollout", &chain_rollout, nb::arg("plant"), nb::arg("nominal"),
            nb::arg("law"), nb::arg("inputs"), nb::call_guard<nb::gil_scoped_release>(),
            "Run FL on a closed chain's constrained dynamics; returns a ChainResult.");
    mod.def("chain_check_reference", &chain_check_reference, nb::arg("chain"), nb::arg("R"),
            nb::arg("seed"), nb::arg("tol"), nb::arg("max_iter"), nb::arg("cond_limit"),
            nb::call_guard<nb::gil_scoped_release>(),
            "Close the loop along R: (status, index, cond) (check_chain_reference's test).");
    mod.def("chain_kkt_timing", &chain_kkt_timing, nb::arg("plant"), nb::arg("q"), nb::arg("qd"),
            nb::arg("u"), nb::arg("calls"), nb::call_guard<nb::gil_scoped_release>(),
            "Wall time [s] of `calls` exact-KKT accelerations.");
  }
} // namespace rrr_pin
