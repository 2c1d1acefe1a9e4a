# STUB for tests (../README.md): not ROS 2.
include("${CMAKE_CURRENT_LIST_DIR}/rrr_pin_ros2_stubs.cmake")
