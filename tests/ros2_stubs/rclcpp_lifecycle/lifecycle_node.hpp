// STUB of rclcpp_lifecycle::LifecycleNode for tests (tests/ros2_stubs/README.md): not ROS 2.
#pragma once

#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "rclcpp/rclcpp.hpp"
#include "rclcpp_lifecycle/state.hpp"

namespace rclcpp_lifecycle
{
class LifecycleNode
{
public:
  explicit LifecycleNode(std::string name) : logger_(name), name_(std::move(name)) {}
  rclcpp::Logger get_logger() const { return logger_; }
  const char * get_name() const { return name_.c_str(); }

  bool has_parameter(const std::string & name) const { return params_.count(name) > 0; }
  /// Declares name; an override (the YAML's value) wins over the default, as in rclcpp.
  template <class T>
  T declare_parameter(const std::string & name, const T & default_value)
  {
    if (has_parameter(name)) throw std::runtime_error("parameter already declared: " + name);
    auto o = overrides_.find(name);
    params_[name] = o != overrides_.end() ? o->second : rclcpp::ParameterValue(default_value);
    return params_[name].template get<T>();
  }
  rclcpp::Parameter get_parameter(const std::string & name) const
  {
    auto p = params_.find(name);
    if (p == params_.end()) throw std::runtime_error("parameter not declared: " + name);
    return rclcpp::Parameter(name, p->second);
  }
  template <class MessageT, class Callback>
  typename rclcpp::Subscription<MessageT>::SharedPtr create_subscription(
    const std::string & topic, const rclcpp::QoS &, Callback && callback)
  {
    auto s = std::make_shared<rclcpp::Subscription<MessageT>>(topic, callback);
    subscriptions_.push_back(s);
    return s;
  }
  /// STUB only: the values the launch file's YAML gives (parameter overrides).
  void set_override(const std::string & name, const rclcpp::ParameterValue & v) { overrides_[name] = v; }
  std::vector<std::shared_ptr<void>> subscriptions_;

private:
  rclcpp::Logger logger_;
  std::string name_;
  std::map<std::string, rclcpp::ParameterValue> params_, overrides_;
};
}  // namespace rclcpp_lifecycle
