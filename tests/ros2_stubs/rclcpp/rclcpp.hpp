// STUB of rclcpp for tests (tests/ros2_stubs/README.md): not ROS 2.
#pragma once

#include <cstdint>
#include <cstdio>
#include <functional>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace rclcpp
{
class Time
{
public:
  Time() = default;
  explicit Time(std::int64_t nanoseconds) : ns_(nanoseconds) {}
  double seconds() const { return static_cast<double>(ns_) * 1e-9; }
  std::int64_t nanoseconds() const { return ns_; }

private:
  std::int64_t ns_ = 0;
};

class Duration
{
public:
  Duration(std::int32_t seconds, std::uint32_t nanoseconds)
  : ns_(static_cast<std::int64_t>(seconds) * 1000000000LL + nanoseconds) {}
  static Duration from_nanoseconds(std::int64_t ns) { Duration d(0, 0); d.ns_ = ns; return d; }
  static Duration from_seconds(double s)
  {
    return from_nanoseconds(static_cast<std::int64_t>(s * 1e9));
  }
  double seconds() const { return static_cast<double>(ns_) * 1e-9; }
  std::int64_t nanoseconds() const { return ns_; }

private:
  std::int64_t ns_ = 0;
};

class Logger
{
public:
  explicit Logger(std::string name = "") : name_(std::move(name)) {}
  const char * get_name() const { return name_.c_str(); }

private:
  std::string name_;
};
inline Logger get_logger(const std::string & name) { return Logger(name); }

enum class ParameterType { NOT_SET, BOOL, DOUBLE, STRING, DOUBLE_ARRAY, STRING_ARRAY };

class ParameterValue
{
public:
  ParameterValue() = default;
  explicit ParameterValue(double v) : type_(ParameterType::DOUBLE), d_(v) {}
  explicit ParameterValue(const std::string & v) : type_(ParameterType::STRING), s_(v) {}
  explicit ParameterValue(const char * v) : type_(ParameterType::STRING), s_(v) {}
  explicit ParameterValue(const std::vector<double> & v) : type_(ParameterType::DOUBLE_ARRAY), da_(v) {}
  explicit ParameterValue(const std::vector<std::string> & v)
  : type_(ParameterType::STRING_ARRAY), sa_(v) {}
  ParameterType get_type() const { return type_; }
  template <class T> T get() const;

private:
  void want(ParameterType t) const
  {
    if (type_ != t) throw std::runtime_error("parameter of another type");  // rclcpp throws too
  }
  ParameterType type_ = ParameterType::NOT_SET;
  double d_ = 0.0;
  std::string s_;
  std::vector<double> da_;
  std::vector<std::string> sa_;
  friend class Parameter;
};
template <> inline double ParameterValue::get<double>() const { want(ParameterType::DOUBLE); return d_; }
template <> inline std::string ParameterValue::get<std::string>() const { want(ParameterType::STRING); return s_; }
template <> inline std::vector<double> ParameterValue::get<std::vector<double>>() const
{
  want(ParameterType::DOUBLE_ARRAY);
  return da_;
}
template <> inline std::vector<std::string> ParameterValue::get<std::vector<std::string>>() const
{
  want(ParameterType::STRING_ARRAY);
  return sa_;
}

class Parameter
{
public:
  Parameter() = default;
  Parameter(std::string name, ParameterValue value) : name_(std::move(name)), value_(std::move(value)) {}
  double as_double() const { return value_.get<double>(); }
  std::string as_string() const { return value_.get<std::string>(); }
  std::vector<double> as_double_array() const { return value_.get<std::vector<double>>(); }
  std::vector<std::string> as_string_array() const { return value_.get<std::vector<std::string>>(); }
  template <class T> T get_value() const { return value_.get<T>(); }
  const ParameterValue & get_parameter_value() const { return value_; }

private:
  std::string name_;
  ParameterValue value_;
};

class QoS
{
public:
  explicit QoS(std::size_t depth) : depth_(depth) {}
  std::size_t depth() const { return depth_; }

private:
  std::size_t depth_;
};
class SystemDefaultsQoS : public QoS
{
public:
  SystemDefaultsQoS() : QoS(10) {}
};

template <class MessageT>
class Subscription
{
public:
  using SharedPtr = std::shared_ptr<Subscription>;
  using Callback = std::function<void(std::shared_ptr<MessageT>)>;
  Subscription(std::string topic, Callback cb) : topic_(std::move(topic)), callback_(std::move(cb)) {}
  const char * get_topic_name() const { return topic_.c_str(); }
  /// STUB only: what the executor does when a message arrives.
  void deliver(const MessageT & msg) { callback_(std::make_shared<MessageT>(msg)); }

private:
  std::string topic_;
  Callback callback_;
};
}  // namespace rclcpp

#define RRR_PIN_STUB_LOG(level, logger, ...)                          \
  do {                                                                \
    std::fprintf(stderr, "[%s] [%s]: ", level, (logger).get_name());  \
    std::fprintf(stderr, __VA_ARGS__);                                \
    std::fprintf(stderr, "\n");                                       \
  } while (0)
#define RCLCPP_ERROR(logger, ...) RRR_PIN_STUB_LOG("ERROR", logger, __VA_ARGS__)
#define RCLCPP_WARN(logger, ...) RRR_PIN_STUB_LOG("WARN", logger, __VA_ARGS__)
#define RCLCPP_INFO(logger, ...) RRR_PIN_STUB_LOG("INFO", logger, __VA_ARGS__)
