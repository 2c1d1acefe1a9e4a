// Generate plain C functions (CppADCodeGen) for CRBA (full M, column-major), nonLinearEffects,
// ABA and RNEA(q, v, a) of one URDF model with gravity G m/s^2 along -z.
// Usage: gen URDF PREFIX GRAVITY OUT.inc   (driven by scripts/codegen.py; see docs/codegen.md)
#include <pinocchio/codegen/cppadcg.hpp>  // must precede the other Pinocchio headers
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody.hpp>
#include <pinocchio/parsers/urdf.hpp>

#include <chrono>
#include <fstream>
#include <functional>
#include <iomanip>
#include <iostream>
#include <sstream>

using CGD = CppAD::cg::CG<double>;
using ADCG = CppAD::AD<CGD>;
using ADModel = pinocchio::ModelTpl<ADCG>;
using ADData = pinocchio::DataTpl<ADCG>;
using ADVec = Eigen::Matrix<ADCG, Eigen::Dynamic, 1>;

static std::string generate(
  const std::string & fname, Eigen::Index nx, Eigen::Index ny,
  const std::function<void(const ADVec &, ADVec &)> & body, size_t & nops)
{
  ADVec X(nx), Y(ny);
  X.setZero();
  CppAD::Independent(X);
  body(X, Y);
  CppAD::ADFun<CGD> fun(X, Y);
  fun.optimize("no_compare_op");

  CppAD::cg::CodeHandler<double> handler;
  CppAD::vector<CGD> ind(static_cast<size_t>(nx));
  handler.makeVariables(ind);
  CppAD::vector<CGD> dep = fun.Forward(0, ind);
  CppAD::cg::LanguageC<double> lang("double");
  lang.setParameterPrecision(17);
  CppAD::cg::LangCDefaultVariableNameGenerator<double> names; // x, y, v
  std::ostringstream code;
  handler.generateCode(code, lang, dep, names);
  nops = handler.getTemporaryVariableCount();
  std::ostringstream out;
  out << "static void " << fname << "(const double * __restrict x, double * __restrict y) {\n";
  if (handler.getTemporaryVariableCount() > 0)
    out << "  double v[" << handler.getTemporaryVariableCount() << "];\n";
  if (handler.getTemporaryArraySize() > 0)
    out << "  double array[" << handler.getTemporaryArraySize() << "];\n";
  out << code.str() << "}\n";
  return out.str();
}

int main(int argc, char ** argv)
{
  if (argc != 5)
  {
    std::cerr << "usage: gen URDF PREFIX GRAVITY OUT\n";
    return 2;
  }
  const auto t0 = std::chrono::steady_clock::now();
  pinocchio::Model model;
  pinocchio::urdf::buildModel(argv[1], model);
  const double g = std::stod(argv[3]);
  model.gravity.setZero();
  model.gravity.linear()[2] = -g;
  const std::string p = argv[2];
  const Eigen::Index nq = model.nq, nv = model.nv;
  ADModel adm = model.cast<ADCG>();
  ADData add(adm);
  std::ostringstream all;
  all << std::setprecision(17) << "// gravity " << g << " m/s^2 along -z\n#define " << p << "_NQ " << nq << "\n";
  size_t nt;
  all << generate(p + "_crba", nq, nv * nv, [&](const ADVec & X, ADVec & Y) {
    pinocchio::crba(adm, add, X);
    for (Eigen::Index j = 0; j < nv; ++j)
      for (Eigen::Index i = 0; i < nv; ++i)
        Y[j * nv + i] = (i <= j) ? add.M(i, j) : add.M(j, i);
  }, nt);
  std::cerr << p << " crba temporaries " << nt << "\n";
  all << generate(p + "_nle", nq + nv, nv, [&](const ADVec & X, ADVec & Y) {
    Y = pinocchio::nonLinearEffects(adm, add, X.head(nq), X.segment(nq, nv));
  }, nt);
  std::cerr << p << " nle temporaries " << nt << "\n";
  all << generate(p + "_aba", nq + 2 * nv, nv, [&](const ADVec & X, ADVec & Y) {
    Y = pinocchio::aba(adm, add, X.head(nq), X.segment(nq, nv), X.segment(nq + nv, nv));
  }, nt);
  std::cerr << p << " aba temporaries " << nt << "\n";
  all << generate(p + "_rnea", nq + 2 * nv, nv, [&](const ADVec & X, ADVec & Y) {
    Y = pinocchio::rnea(adm, add, X.head(nq), X.segment(nq, nv), X.segment(nq + nv, nv));
  }, nt);
  std::cerr << p << " rnea temporaries " << nt << "\n";
  std::ofstream(argv[4]) << all.str();
  const auto t1 = std::chrono::steady_clock::now();
  std::cerr << p << " generation (tape + C source) " << std::chrono::duration<double>(t1 - t0).count()
            << " s\n";
  return 0;
}
