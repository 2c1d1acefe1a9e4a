// CompiledModel: loading and saving (see model.hpp).
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
} // namespace rrr_pin
