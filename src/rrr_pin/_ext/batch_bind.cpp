// Python bindings of the batched rollouts (batch.hpp), added to rrr_pin.sim._rollout by
// module.cpp (private; use rrr_pin.sim.batched).
#include <cstdint>
#include <stdexcept>
#include <string>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>

#include <vector>

#include "batch.hpp"

namespace nb = nanobind;

namespace rrr_pin
{
  namespace
  {
    template<class Law>
    void def_batch_law(nb::module_ & mod)
    {
      mod.def(
        "batch_rollout", &batch_rollout<Law>, nb::arg("name"), nb::arg("plant"),
        nb::arg("nominal"), nb::arg("law"), nb::arg("inputs"), nb::arg("lower"),
        nb::arg("upper"), nb::arg("effects").none() = nb::none(),
        nb::call_guard<nb::gil_scoped_release>(),
        "Run the closed loop on B plants; returns (Q, QD, TAU, bad_step, bad_joint, reason).");
      mod.def(
        "batch_figures", &batch_figures<Law>, nb::arg("name"), nb::arg("plant"),
        nb::arg("nominal"), nb::arg("law"), nb::arg("inputs"), nb::arg("lower"),
        nb::arg("upper"), nb::arg("effects").none() = nb::none(),
        nb::call_guard<nb::gil_scoped_release>(),
        "batch_rollout reduced to each plant's figures in the loop; returns (F, Q, QD, TAU0, "
        "bad_step, bad_joint, reason).");
      mod.def(
        "batch_floor_timing",
        [](const std::string & name, const RowMat & plant, const Vec & nominal, const Law &,
           bool sampled, int substeps, std::int64_t n_steps) {
          return batch_floor_timing<Law>(name, plant, nominal, sampled, substeps, n_steps);
        },
        nb::arg("name"), nb::arg("plant"), nb::arg("nominal"), nb::arg("law"),
        nb::arg("sampled"), nb::arg("substeps"), nb::arg("n_steps"),
        nb::call_guard<nb::gil_scoped_release>(),
        "Wall time [s] of the bare generated dynamics calls of B plant-rollouts of this law.");
    }
  } // namespace

  void bind_batch(nb::module_ & mod)
  {
#define RRR_PIN_BIND_BATCH_LAW(Law) def_batch_law<Law>(mod);
    RRR_PIN_LAWS(RRR_PIN_BIND_BATCH_LAW)
#undef RRR_PIN_BIND_BATCH_LAW
    mod.def("batch_models", []() {
      nb::dict d;
      int count = 0;
      const DynFunctions * table = dyn_table(count);
      for (int i = 0; i < count; ++i)
        d[table[i].name] = nb::make_tuple(std::string(table[i].structure), table[i].nq,
                                          table[i].np);
      return d;
    }, "Generated structures compiled in: name -> (structure, nq, number of parameters).");
    mod.def("batch_loaded", []() {
      nb::dict d;
      int count = 0;
      dyn_table(count);
      const std::vector<DynFunctions> all = dyn_all();
      for (std::size_t i = static_cast<std::size_t>(count); i < all.size(); ++i)
        d[all[i].name] = nb::make_tuple(std::string(all[i].structure), all[i].nq, all[i].np);
      return d;
    }, "Generated structures registered at run time: name -> (structure, nq, np).");
    mod.def("batch_register", &dyn_register, nb::arg("name"), nb::arg("structure"),
            nb::arg("fd_algorithm"), nb::arg("nq"), nb::arg("np"), nb::arg("nd"),
            nb::arg("pre"), nb::arg("crba"), nb::arg("nle"), nb::arg("gravity"), nb::arg("fd"),
            nb::arg("fd_other"), nb::arg("id"),
            "Register generated functions loaded at run time, by address (rrr_pin.sim.dyncache).");
    mod.def(
      "batch_fd_algorithm",
      [](const std::string & name) { return std::string(dyn_by_name(name).fd_algorithm); },
      nb::arg("name"),
      "The forward-dynamics algorithm of a generated structure's fd: 'ldlt' or 'aba'.");
    mod.def("c_compiler", []() { return std::string(RRR_C_COMPILER); },
            "The C compiler that built the extension's generated dynamics (CMAKE_C_COMPILER).");
    mod.def("c_flags", []() { return std::string(RRR_C_FLAGS); },
            "Its flags for the generated dynamics.");
    mod.def("batch_max", []() { return kBatchMax; });
    mod.def(
      "batch_dynamics",
      [](const std::string & name, const RowMat & P, const RowMat & q, const RowMat & v,
         const RowMat & tau) {
        const DynFunctions & f = dyn_by_name(name);
        const Eigen::Index B = P.rows(), n = f.nq;
        if (B < 1 || B > kBatchMax || P.cols() != f.np)
          throw std::invalid_argument("P must be (B, np) with 1 <= B <= 16");
        for (const RowMat * a : {&q, &v, &tau})
          if (a->rows() != B || a->cols() != n)
            throw std::invalid_argument("q, v and tau must be (B, nq)");
        // Structure-of-arrays: transposed, row-major (entry k of plant b at [k * B + b]).
        const RowMat Ps = P.transpose(), qs = q.transpose(), vs = v.transpose(),
                     ts = tau.transpose();
        RowMat Ds(f.nd, B), M(n * n, B), nle(n, B), g(n, B), qdd(n, B), qdd2(n, B), id(n, B);
        const int b = static_cast<int>(B);
        f.pre(b, Ps.data(), Ds.data());
        f.crba(b, Ds.data(), qs.data(), M.data());
        f.nle(b, Ds.data(), qs.data(), vs.data(), nle.data());
        f.gravity(b, Ds.data(), qs.data(), g.data());
        f.fd(b, Ds.data(), qs.data(), vs.data(), ts.data(), qdd.data());
        f.fd_other(b, Ds.data(), qs.data(), vs.data(), ts.data(), qdd2.data());
        f.id(b, Ds.data(), qs.data(), vs.data(), ts.data(), id.data());  // tau read as a
        return nb::make_tuple(RowMat(M.transpose()), RowMat(nle.transpose()),
                              RowMat(g.transpose()), RowMat(qdd.transpose()),
                              RowMat(qdd2.transpose()), RowMat(id.transpose()));
      },
      nb::arg("name"), nb::arg("P"), nb::arg("q"), nb::arg("v"), nb::arg("tau"),
      "Generated M (B, n n, row-major), nonLinearEffects, G, forward dynamics (B, n) by the "
      "chosen algorithm (batch_fd_algorithm) and by the other one (a structure built at first "
      "use: the chosen one again), and the inverse dynamics M a + nle with tau read as a.");
  }
} // namespace rrr_pin
