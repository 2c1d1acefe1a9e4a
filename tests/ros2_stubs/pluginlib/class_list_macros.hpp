// STUB of pluginlib's export macro for tests (tests/ros2_stubs/README.md): not ROS 2. It
// registers a factory under the class's name, which the test instantiates by that name.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <string>

namespace rrr_pin_stub
{
template <class Base>
std::map<std::string, std::function<std::shared_ptr<Base>()>> & registry()
{
  static std::map<std::string, std::function<std::shared_ptr<Base>()>> r;
  return r;
}
template <class Derived, class Base>
struct Registrar
{
  explicit Registrar(const char * name)
  {
    registry<Base>()[name] = [] { return std::make_shared<Derived>(); };
  }
};
}  // namespace rrr_pin_stub

#define RRR_PIN_STUB_CAT2(a, b) a##b
#define RRR_PIN_STUB_CAT(a, b) RRR_PIN_STUB_CAT2(a, b)
#define PLUGINLIB_EXPORT_CLASS(Derived, Base)                              \
  namespace                                                                \
  {                                                                        \
  const rrr_pin_stub::Registrar<Derived, Base> RRR_PIN_STUB_CAT(           \
    rrr_pin_stub_registrar_, __LINE__)(#Derived);                          \
  }
