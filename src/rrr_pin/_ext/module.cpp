// Python bindings of the compiled rollout: rrr_pin.sim._rollout (private; use
// rrr_pin.sim.compiled). Parameters travel as objects whose fields Python sets by name: a law
// (FLLaw, FLAWLaw or PDLaw, one per compiled form), RolloutInputs and Effects.
#include <cstdint>
#include <string>

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
  void bind_chain(nb::module_ & mod);  // chain_bind.cpp
}

namespace
{
  /// Bind rollout() and floor_timing() for one law (overloads, selected by the law's type).
  template<class Law>
  nb::class_<Law> def_law(nb::module_ & mod, const char * name, const char * doc)
  {
    nb::class_<Law> cls(mod, name, doc);
    cls.def(nb::init<>());
    mod.def(
      "rollout", &rollout<Law>, nb::arg("plant"), nb::arg("nominal"), nb::arg("law"),
      nb::arg("inputs"), nb::arg("effects").none() = nb::none(),
      nb::call_guard<nb::gil_scoped_release>(),
      "Run the closed loop; returns (q, qd, tau, bad_step, bad_joint, reason).");
    mod.def(
      "floor_timing",
      [](const CompiledModel & plant, const CompiledModel & nominal, const Law &, bool sampled,
         int substeps, std::int64_t n_steps) {
        return floor_timing<Law>(plant, nominal, sampled, substeps, n_steps);
      },
      nb::arg("plant"), nb::arg("nominal"), nb::arg("law"), nb::arg("sampled"),
      nb::arg("substeps"), nb::arg("n_steps"), nb::call_guard<nb::gil_scoped_release>(),
      "Wall time [s] of the bare dynamics calls of a rollout of this law.");
    return cls;
  }
} // namespace

NB_MODULE(_rollout, mod)
{
  mod.doc() = "Compiled closed-loop rollout on Pinocchio (private; use rrr_pin.sim.compiled).";

  nb::class_<CompiledModel>(mod, "CompiledModel")
    .def(
      nb::init<const std::string &>(), nb::arg("serialized"),
      "Load a model from pinocchio.Model.saveToString() text.")
    .def_prop_ro("nq", &CompiledModel::nq)
    .def("save", &CompiledModel::save, "The model re-serialized with saveToString().")
    .def(
      "use_codegen", &CompiledModel::use_codegen, nb::arg("name"),
      "Use generated dynamics `name` instead of Pinocchio (caller checks the fingerprint).")
    .def_prop_ro("codegen", &CompiledModel::codegen);

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

  nb::class_<Effects>(mod, "Effects", "Plant effects (rrr_pin.control.effects.Resolved); all off.")
    .def(nb::init<>())
    .def_rw("delay_steps", &Effects::delay_steps)
    .def_rw("wa", &Effects::wa)
    .def_rw("limit", &Effects::limit)
    .def_rw("Fv", &Effects::Fv)
    .def_rw("Fc", &Effects::Fc)
    .def_rw("veps", &Effects::veps)
    .def_rw("noise_q", &Effects::noise_q)
    .def_rw("noise_qd", &Effects::noise_qd)
    .def_rw("quantum", &Effects::quantum)
    .def_rw("Bm", &Effects::Bm)
    .def_rw("Kf", &Effects::Kf)
    .def_rw("Df", &Effects::Df);

  def_law<FLLaw>(mod, "FLLaw", "Feedback linearization + linear controller (FLForm).")
    .def_rw("lam", &FLLaw::lam)
    .def_rw("A", &FLLaw::A)
    .def_rw("B", &FLLaw::B)
    .def_rw("C", &FLLaw::C)
    .def_rw("D", &FLLaw::D);
  def_law<FLAWLaw>(mod, "FLAWLaw", "FLLaw clipped, K conditioned on the clip (FLAWForm).")
    .def_rw("lam", &FLAWLaw::lam)
    .def_rw("A", &FLAWLaw::A)
    .def_rw("B", &FLAWLaw::B)
    .def_rw("C", &FLAWLaw::C)
    .def_rw("D", &FLAWLaw::D)
    .def_rw("L", &FLAWLaw::L)
    .def_rw("limit", &FLAWLaw::limit);
  def_law<PDLaw>(mod, "PDLaw", "PD + gravity compensation (PDForm).")
    .def_rw("Kp", &PDLaw::Kp)
    .def_rw("Kd", &PDLaw::Kd);

  mod.def("codegen_models", []() {
    nb::dict d;
    d["rrr"] = nb::make_tuple(
      std::string(rrr_cg_fingerprint), std::string(rrr_cg_urdf_sha256),
      std::string(rrr_cg_gravity));
    return d;
  }, "Generated models: name -> (fingerprint, URDF sha256, gravity text).");

  bind_batch(mod);
  bind_chain(mod);

  mod.def("pinocchio_version", []() { return std::string(PINOCCHIO_VERSION); });
  mod.def("eigen_version", []() {
    return std::to_string(EIGEN_WORLD_VERSION) + "." + std::to_string(EIGEN_MAJOR_VERSION) + "."
           + std::to_string(EIGEN_MINOR_VERSION);
  });
}
