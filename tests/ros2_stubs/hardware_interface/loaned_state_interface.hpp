// STUB of hardware_interface for tests (tests/ros2_stubs/README.md): not ROS 2.
// The accessors of Jazzy and later (get_optional, [[nodiscard]] bool set_value); with
// -DRRR_PIN_STUB_HUMBLE those of Humble (double get_value(), void set_value).
#pragma once

#include <optional>
#include <string>
#include <utility>

namespace hardware_interface
{
class LoanedStateInterface
{
public:
  /// STUB only: the hardware's value the interface reads (the controller manager's loan).
  LoanedStateInterface(std::string name, const double * value) : name_(std::move(name)), value_(value) {}
  LoanedStateInterface(const LoanedStateInterface &) = delete;
  LoanedStateInterface(LoanedStateInterface &&) = default;
#ifdef RRR_PIN_STUB_HUMBLE
  const std::string get_name() const { return name_; }  // Humble: by value
  double get_value() const { return *value_; }
#else
  const std::string & get_name() const { return name_; }
  [[deprecated("Jazzy: use get_optional")]] double get_value() const { return *value_; }
  template <typename T = double>
  [[nodiscard]] std::optional<T> get_optional(unsigned int max_tries = 10) const
  {
    (void)max_tries;
    return *value_;
  }
#endif

private:
  std::string name_;
  const double * value_;
};
}  // namespace hardware_interface
