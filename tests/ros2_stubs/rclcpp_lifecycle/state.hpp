// STUB of rclcpp_lifecycle for tests (tests/ros2_stubs/README.md): not ROS 2.
#pragma once

#include <cstdint>
#include <string>

namespace rclcpp_lifecycle
{
class State
{
public:
  State() = default;
  State(std::uint8_t id, std::string label) : id_(id), label_(std::move(label)) {}
  std::uint8_t id() const { return id_; }
  const std::string & label() const { return label_; }

private:
  std::uint8_t id_ = 0;
  std::string label_ = "unknown";
};

namespace node_interfaces
{
class LifecycleNodeInterface
{
public:
  enum class CallbackReturn : std::uint8_t { SUCCESS = 97, FAILURE = 98, ERROR = 99 };
  virtual ~LifecycleNodeInterface() = default;
  virtual CallbackReturn on_configure(const State &) { return CallbackReturn::SUCCESS; }
  virtual CallbackReturn on_cleanup(const State &) { return CallbackReturn::SUCCESS; }
  virtual CallbackReturn on_shutdown(const State &) { return CallbackReturn::SUCCESS; }
  virtual CallbackReturn on_activate(const State &) { return CallbackReturn::SUCCESS; }
  virtual CallbackReturn on_deactivate(const State &) { return CallbackReturn::SUCCESS; }
  virtual CallbackReturn on_error(const State &) { return CallbackReturn::SUCCESS; }
};
}  // namespace node_interfaces
}  // namespace rclcpp_lifecycle
