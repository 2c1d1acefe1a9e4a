// STUB of hardware_interface for tests (tests/ros2_stubs/README.md): not ROS 2.
#pragma once

#include <optional>
#include <string>
#include <utility>

namespace hardware_interface
{
class LoanedCommandInterface
{
public:
  /// STUB only: the hardware's command the interface writes.
  LoanedCommandInterface(std::string name, double * value) : name_(std::move(name)), value_(value) {}
  LoanedCommandInterface(const LoanedCommandInterface &) = delete;
  LoanedCommandInterface(LoanedCommandInterface &&) = default;
#ifdef RRR_PIN_STUB_HUMBLE
  const std::string get_name() const { return name_; }  // Humble: by value
  void set_value(double val) { *value_ = val; }
  double get_value() const { return *value_; }
#else
  const std::string & get_name() const { return name_; }
  template <typename T>
  [[nodiscard]] bool set_value(const T & value, unsigned int max_tries = 10)
  {
    (void)max_tries;
    *value_ = value;
    return true;
  }
  template <typename T = double>
  [[nodiscard]] std::optional<T> get_optional(unsigned int max_tries = 10) const
  {
    (void)max_tries;
    return *value_;
  }
#endif

private:
  std::string name_;
  double * value_;
};
}  // namespace hardware_interface
