// STUB of controller_interface for tests (tests/ros2_stubs/README.md): not ROS 2.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "hardware_interface/loaned_command_interface.hpp"
#include "hardware_interface/loaned_state_interface.hpp"
#include "rclcpp/rclcpp.hpp"
#include "rclcpp_lifecycle/lifecycle_node.hpp"
#include "rclcpp_lifecycle/state.hpp"

namespace controller_interface
{
using CallbackReturn = rclcpp_lifecycle::node_interfaces::LifecycleNodeInterface::CallbackReturn;

enum class return_type : std::uint8_t { OK = 0, ERROR = 1 };
enum class interface_configuration_type : std::uint8_t { ALL = 0, INDIVIDUAL = 1, NONE = 2 };

struct InterfaceConfiguration
{
  interface_configuration_type type;
  std::vector<std::string> names = {};
};

class ControllerInterfaceBase : public rclcpp_lifecycle::node_interfaces::LifecycleNodeInterface
{
public:
  ControllerInterfaceBase() = default;
  ~ControllerInterfaceBase() override = default;
  virtual InterfaceConfiguration command_interface_configuration() const = 0;
  virtual InterfaceConfiguration state_interface_configuration() const = 0;
  virtual void assign_interfaces(
    std::vector<hardware_interface::LoanedCommandInterface> && command_interfaces,
    std::vector<hardware_interface::LoanedStateInterface> && state_interfaces)
  {
    command_interfaces_ = std::move(command_interfaces);
    state_interfaces_ = std::move(state_interfaces);
  }
  virtual void release_interfaces()
  {
    command_interfaces_.clear();
    state_interfaces_.clear();
  }
  virtual CallbackReturn on_init() = 0;
  virtual return_type update(const rclcpp::Time & time, const rclcpp::Duration & period) = 0;
  std::shared_ptr<rclcpp_lifecycle::LifecycleNode> get_node() { return node_; }
  unsigned int get_update_rate() const { return update_rate_; }
  std::shared_ptr<const rclcpp_lifecycle::LifecycleNode> get_node() const { return node_; }
  template <typename ParameterT>
  auto auto_declare(const std::string & name, const ParameterT & default_value)
  {
    if (!node_->has_parameter(name)) return node_->declare_parameter<ParameterT>(name, default_value);
    return node_->get_parameter(name).get_value<ParameterT>();
  }
  /// STUB of init(controller_name, urdf, cm_update_rate, namespace, node_options): makes the
  /// node with the YAML's values as overrides, records the update rate, calls on_init().
  CallbackReturn init(const std::string & controller_name,
                      const std::vector<std::pair<std::string, rclcpp::ParameterValue>> & overrides,
                      unsigned int cm_update_rate)
  {
    update_rate_ = cm_update_rate;
    node_ = std::make_shared<rclcpp_lifecycle::LifecycleNode>(controller_name);
    for (const auto & o : overrides) node_->set_override(o.first, o.second);
    return on_init();
  }

protected:
  std::vector<hardware_interface::LoanedCommandInterface> command_interfaces_;
  std::vector<hardware_interface::LoanedStateInterface> state_interfaces_;

private:
  std::shared_ptr<rclcpp_lifecycle::LifecycleNode> node_;
  unsigned int update_rate_ = 0;
};

class ControllerInterface : public ControllerInterfaceBase
{
public:
  ControllerInterface() = default;
  bool is_chainable() const { return false; }
};
}  // namespace controller_interface
