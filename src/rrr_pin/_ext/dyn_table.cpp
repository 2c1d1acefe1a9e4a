// The generated structures (batch.hpp's DynFunctions): those compiled in (dyn_<name>.c of
// generated/, rrr_pin.sim.dyngen), and those registered at run time (rrr_pin.sim.dyncache).
// Apart from the lane loops of batch.cpp, which look a structure up by name here.
#include <deque>
#include <iterator>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

#include "batch.hpp"

extern "C" {
#define RRR_DYN_DECLARE(name)                                                                  \
  extern const char name##_dyn_structure[];                                                    \
  extern const char name##_dyn_fd[];                                                           \
  extern const int name##_dyn_nq;                                                              \
  extern const int name##_dyn_np;                                                              \
  extern const int name##_dyn_nd;                                                              \
  void name##_pre(int, const double *, double *);                                              \
  void name##_crba(int, const double *, const double *, double *);                             \
  void name##_nle(int, const double *, const double *, const double *, double *);              \
  void name##_gravity(int, const double *, const double *, double *);                          \
  void name##_fd(int, const double *, const double *, const double *, const double *, double *); \
  void name##_fd_other(int, const double *, const double *, const double *, const double *,    \
                       double *);                                                              \
  void name##_id(int, const double *, const double *, const double *, const double *, double *);
RRR_DYN_DECLARE(rrr)
RRR_DYN_DECLARE(ur5)
RRR_DYN_DECLARE(panda)
#undef RRR_DYN_DECLARE
}

namespace rrr_pin
{
  namespace
  {
#define RRR_DYN_ENTRY(name)                                                                    \
  DynFunctions{#name,          name##_dyn_structure, name##_dyn_fd, name##_dyn_nq,              \
               name##_dyn_np,  name##_dyn_nd,        name##_pre,    name##_crba,                \
               name##_nle,     name##_gravity,       name##_fd,     name##_fd_other,            \
               name##_id}
    const DynFunctions kTable[] = {RRR_DYN_ENTRY(rrr), RRR_DYN_ENTRY(ur5), RRR_DYN_ENTRY(panda)};
#undef RRR_DYN_ENTRY
  } // namespace

  namespace
  {
    /// Structures loaded at run time (dyn_register), with the strings their entries point to.
    /// A deque never moves its elements, so a reference handed out stays valid.
    struct Loaded
    {
      std::mutex lock;
      std::deque<std::string> strings;
      std::deque<DynFunctions> table;
    };

    Loaded & loaded()
    {
      static Loaded l;
      return l;
    }
  } // namespace

  const DynFunctions * dyn_table(int & count)
  {
    count = static_cast<int>(sizeof(kTable) / sizeof(kTable[0]));
    return kTable;
  }

  std::vector<DynFunctions> dyn_all()
  {
    std::vector<DynFunctions> out(std::begin(kTable), std::end(kTable));
    Loaded & l = loaded();
    std::lock_guard<std::mutex> guard(l.lock);
    out.insert(out.end(), l.table.begin(), l.table.end());
    return out;
  }

  void dyn_register(const std::string & name, const std::string & structure,
                    const std::string & fd_algorithm, int nq, int np, int nd, std::uintptr_t pre,
                    std::uintptr_t crba, std::uintptr_t nle, std::uintptr_t gravity,
                    std::uintptr_t fd, std::uintptr_t fd_other, std::uintptr_t id)
  {
    if (nq < 1 || np != 3 + 23 * nq || nd < 1 || !pre || !crba || !nle || !gravity || !fd
        || !fd_other || !id)
      throw std::invalid_argument(
        "dyn_register: nq >= 1, np = 3 + 23 nq, nd >= 1 and seven functions");
    if (fd_algorithm != "ldlt" && fd_algorithm != "aba")
      throw std::invalid_argument("dyn_register: fd_algorithm must be 'ldlt' or 'aba'");
    Loaded & l = loaded();
    std::lock_guard<std::mutex> guard(l.lock);
    for (const DynFunctions & f : kTable)
      if (name == f.name)
        throw std::invalid_argument("dyn_register: '" + name + "' is compiled in");
    for (const DynFunctions & f : l.table)
      if (name == f.name)
        throw std::invalid_argument("dyn_register: '" + name + "' is registered already");
    l.strings.push_back(name);
    const char * n = l.strings.back().c_str();
    l.strings.push_back(structure);
    const char * st = l.strings.back().c_str();
    l.strings.push_back(fd_algorithm);
    const char * alg = l.strings.back().c_str();
    using Fd = void (*)(int, const double *, const double *, const double *, const double *,
                        double *);
    l.table.push_back(DynFunctions{
      n, st, alg, nq, np, nd, reinterpret_cast<void (*)(int, const double *, double *)>(pre),
      reinterpret_cast<void (*)(int, const double *, const double *, double *)>(crba),
      reinterpret_cast<void (*)(int, const double *, const double *, const double *, double *)>(
        nle),
      reinterpret_cast<void (*)(int, const double *, const double *, double *)>(gravity),
      reinterpret_cast<Fd>(fd), reinterpret_cast<Fd>(fd_other), reinterpret_cast<Fd>(id)});
  }

  const DynFunctions & dyn_by_name(const std::string & name)
  {
    std::string known;
    for (const DynFunctions & f : kTable)
    {
      if (name == f.name)
        return f;
      known += (known.empty() ? "" : ", ") + std::string(f.name);
    }
    Loaded & l = loaded();
    std::lock_guard<std::mutex> guard(l.lock);
    for (const DynFunctions & f : l.table)
    {
      if (name == f.name)
        return f;
      known += ", " + std::string(f.name);
    }
    throw std::invalid_argument("no generated dynamics named '" + name + "' (known: " + known
                                + ")");
  }
} // namespace rrr_pin
