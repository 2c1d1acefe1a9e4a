// CompiledModel: loading, saving and switching to generated dynamics (see model.hpp).
#include "model.hpp"

#include <pinocchio/serialization.hpp>

namespace rrr_pin
{
  CompiledModel::CompiledModel(const std::string & serialized)
  {
    model.loadFromString(serialized);
  }

  std::string CompiledModel::save() const
  {
    return model.saveToString();
  }

  void CompiledModel::use_codegen(const std::string & name)
  {
    if (name != "rrr")
      throw std::invalid_argument("no generated dynamics named '" + name + "' (known: rrr)");
    if (model.nq != kRrrCodegen.nq || model.nv != kRrrCodegen.nq)
      throw std::invalid_argument("model size differs from the generated dynamics'");
    cg = &kRrrCodegen;
  }
} // namespace rrr_pin
