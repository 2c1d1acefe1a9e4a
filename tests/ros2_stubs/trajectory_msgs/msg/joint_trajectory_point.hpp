// STUB of trajectory_msgs/msg/JointTrajectoryPoint for tests (tests/ros2_stubs/README.md).
#pragma once

#include <vector>

#include "rclcpp/rclcpp.hpp"

namespace trajectory_msgs
{
namespace msg
{
struct JointTrajectoryPoint
{
  std::vector<double> positions, velocities, accelerations, effort;
  rclcpp::Duration time_from_start{0, 0};
};
}  // namespace msg
}  // namespace trajectory_msgs
