r"""A ros2_control controller package around an exported law: :func:`ros2_package`.

``rrr-pin export --ros2`` writes, beside the exported C folder, the package ``ros2/`` that a
ROS 2 user builds with colcon (``colcon build --paths <export>/ros2``):

- ``package.xml`` (ament_cmake; depends on controller_interface, hardware_interface,
  pluginlib, rclcpp, rclcpp_lifecycle, realtime_tools, trajectory_msgs),
- ``CMakeLists.txt``: the exported law by ``add_subdirectory(..)``, the plugin library, and
  ``pluginlib_export_plugin_description_file(controller_interface rrr_pin_controller.xml)``,
- ``rrr_pin_controller.xml``: the plugin description,
- ``config/rrr_pin_controller.yaml``: the controller's parameters (joints, rate, period band,
  torque and position limits, the law's gains, the fault torque),
- ``include/rrr_pin_controller/exported_law_controller.hpp``, ``src/exported_law_controller.cpp``:
  ``rrr_pin_controller::ExportedLawController``, a ``controller_interface::ControllerInterface``.

The controller's rules, stated once here and in the header:

- **Parameters are checked at configure** (``on_configure``): ``joints`` must be the exported
  joints in their order (a missing or extra joint is named), ``rate_hz`` and the controller
  manager's update rate the rate the law was discretized for, the gains (``lam``; ``kp``/``kd``
  of PD) those compiled in; otherwise the transition fails with the reason logged. Nothing
  else is computed than what was exported.
- **The reference** comes from the topic ``~/reference`` (``trajectory_msgs/JointTrajectoryPoint``:
  positions, and velocities and accelerations or none for zeros) through a
  ``realtime_tools::RealtimeBuffer`` (the subscriber writes, ``update`` reads without blocking).
  On activation the reference is the measured position, held.
- **The period** of each ``update`` must lie within ``period_tolerance`` (default 0.2: +-20 %)
  of ``1 / rate_hz``; inside the band the law computes with it: ``ctrl_step_dt`` discretizes
  K's continuous realization at that period by the export's method (a law without K does not
  depend on it), and the period used is recorded (``last_period()``). The first update after
  activation has no period measured: it computes with ``1 / rate_hz``. A law whose K the
  exported C cannot discretize per period (a discrete K as given, a method other than those of
  :data:`~rrr_pin.deploy.period.GBT_ALPHA`) is refused by :func:`check_ros2`.
- **Faults** (a period outside the band; a non-finite or out-of-limit state; a reference of the
  wrong size or non-finite; ``ctrl_step_dt`` refusing): the command becomes the **safe torque**,
  gravity compensation ``Ghat(q)`` of the nominal model (``fault_torque: gravity``, default) or
  zero (``fault_torque: zero``, also used when ``q`` itself is not finite); the fault is
  latched until the next activation, logged with its reason, and readable (``fault()``,
  ``fault_reason()``). ``update`` returns OK so that the safe torque is written every period:
  never the last torque held.
- **Torque limits** (``torque_limit``, per joint [N m]): the command is clipped to them; the
  clipped periods are counted (``clipped_periods()``).

The package is compiled by ``tests/test_ros2_package.py`` against the stub headers of
``tests/ros2_stubs/`` (not ROS 2 itself: not installable on the project's machines).
"""

from __future__ import annotations

import numpy as np

from ..outputs import writing
from .sources import _num
from .writer import ExportError

__all__ = ["ros2_package", "write_ros2_package", "check_ros2", "PACKAGE", "PERIOD_TOLERANCE"]

#: The package's name (and the plugin's namespace).
PACKAGE = "rrr_pin_controller"

#: Default relative band of an accepted period around ``1 / rate`` (+-20 %).
PERIOD_TOLERANCE = 0.2


def _yaml_list(values) -> str:
    return "[" + ", ".join(values) + "]"


def check_ros2(prepared) -> None:
    """Refuse an export whose law the controller cannot run over a measured period.

    The controller computes with the period it measures (``ctrl_step_dt``); a law with ``K``
    needs K's continuous realization and a method the C discretizes per period
    (:data:`~rrr_pin.deploy.period.GBT_ALPHA`).

    Raises
    ------
    ExportError
        A discrete ``K`` given as such, or a method (``zoh``, ...) that needs a matrix
        exponential per period; the message says what would do.
    """
    if prepared.form.kind == "pd" or not prepared.law.nx or prepared.continuous is not None:
        return
    raise ExportError(
        f"--ros2: law {prepared.law.name!r} can run its K at 1/rate only "
        f"({prepared.record['ctrl_step_dt']['period']}); the ros2_control controller computes "
        f"with the period it measures: export a continuous K with method tustin (the default)")


def ros2_package(prepared, robot) -> dict[str, str]:
    """Return the package's files (relative path -> text) for an :class:`~.writer.Export`.

    Parameters
    ----------
    prepared : Export
        The export (:func:`rrr_pin.deploy.writer.prepare_export`) the package runs.
    robot : Robot
        Its arm (joint names, position and effort limits).

    Returns
    -------
    dict
        ``"ros2/package.xml"``, ... -> text (ASCII), in a fixed order.

    Raises
    ------
    ExportError
        As :func:`check_ros2`.
    """
    check_ros2(prepared)
    form = prepared.form
    n = robot.nq
    joints = list(robot.joint_names)
    if form.kind == "fl_aw":
        limit = np.asarray(form.limit, dtype=float)
    else:
        limit = np.asarray(robot.model.effortLimit, dtype=float)
    lower, upper = np.asarray(robot.lower, float), np.asarray(robot.upper, float)
    if form.kind == "pd":
        gains = {"kp": np.asarray(form.Kp, float).ravel(), "kd": np.asarray(form.Kd, float).ravel()}
        gain_yaml = (f"    kp: {_yaml_list(_num(v) for v in gains['kp'])}  # row-major, "
                     f"compiled in: checked\n"
                     f"    kd: {_yaml_list(_num(v) for v in gains['kd'])}\n")
        gain_decl = (f"constexpr bool kIsPD = true;\nconstexpr bool kLamPerJoint = false;\n"
                     f"constexpr double kLam[1] = {{0.0}};\n"
                     f"constexpr double kKp[{n * n}] = {{{', '.join(map(_num, gains['kp']))}}};\n"
                     f"constexpr double kKd[{n * n}] = {{{', '.join(map(_num, gains['kd']))}}};\n")
    else:
        # lam: one number, or a list of one per joint (a double array parameter)
        per_joint = np.ndim(form.lam) > 0
        lams = [_num(v) for v in np.atleast_1d(form.lam)]
        lam_text = _yaml_list(lams) if per_joint else lams[0]
        gain_yaml = f"    lam: {lam_text}  # compiled in: checked\n"
        gain_decl = (f"constexpr bool kIsPD = false;\n"
                     f"constexpr bool kLamPerJoint = {'true' if per_joint else 'false'};\n"
                     f"constexpr double kLam[{len(lams)}] = {{{', '.join(lams)}}};\n"
                     f"constexpr double kKp[1] = {{0.0}};\nconstexpr double kKd[1] = {{0.0}};\n")
    rate = prepared.rate
    files = {
        "ros2/package.xml": _PACKAGE_XML,
        "ros2/CMakeLists.txt": _CMAKE,
        "ros2/rrr_pin_controller.xml": _PLUGIN_XML,
        "ros2/config/rrr_pin_controller.yaml": _YAML.format(
            rate=_num(rate), update_rate=int(round(rate)), joints=_yaml_list(joints),
            tol=_num(PERIOD_TOLERANCE), limit=_yaml_list(_num(v) for v in limit),
            lower=_yaml_list(_num(v) for v in lower), upper=_yaml_list(_num(v) for v in upper),
            gains=gain_yaml, law=prepared.law.name, kind=form.kind),
        "ros2/include/rrr_pin_controller/exported_law_params.hpp": _PARAMS_HPP.replace(
            "@GAINS@", gain_decl).replace("@TOL@", _num(PERIOD_TOLERANCE)).replace(
            "@LIMIT@", ", ".join(map(_num, limit))).replace(
            "@LOWER@", ", ".join(map(_num, lower))).replace(
            "@UPPER@", ", ".join(map(_num, upper))),
        "ros2/include/rrr_pin_controller/exported_law_controller.hpp": _HPP,
        "ros2/src/exported_law_controller.cpp": _CPP,
    }
    return files


def write_ros2_package(prepared, robot, folder) -> list:
    """Write :func:`ros2_package` under ``folder`` (the export's folder); return the paths."""
    from pathlib import Path

    out = []
    for name, text in ros2_package(prepared, robot).items():
        path = Path(folder) / name
        path.parent.mkdir(parents=True, exist_ok=True)
        with writing(path):
            path.write_bytes(text.encode("ascii"))
        out.append(path)
    return out


_BANNER = "GENERATED by `rrr-pin export --ros2` -- do not edit; export again."

_PACKAGE_XML = f"""<?xml version="1.0"?>
<!-- {_BANNER} -->
<?xml-model href="http://download.ros.org/schema/package_format3.xsd"
  schematypens="http://www.w3.org/2001/XMLSchema"?>
<package format="3">
  <name>{PACKAGE}</name>
  <version>0.1.0</version>
  <description>A law exported by rrr-pin (../controller.json), as a ros2_control controller
    plugin: effort commands from joint positions and velocities.</description>
  <maintainer email="user@example.com">rrr-pin user</maintainer>
  <license>BSD-3-Clause</license>

  <buildtool_depend>ament_cmake</buildtool_depend>

  <depend>controller_interface</depend>
  <depend>hardware_interface</depend>
  <depend>pluginlib</depend>
  <depend>rclcpp</depend>
  <depend>rclcpp_lifecycle</depend>
  <depend>realtime_tools</depend>
  <depend>trajectory_msgs</depend>

  <export>
    <build_type>ament_cmake</build_type>
  </export>
</package>
"""

_PLUGIN_XML = f"""<!-- {_BANNER} -->
<library path="{PACKAGE}">
  <class name="{PACKAGE}/ExportedLawController"
         type="{PACKAGE}::ExportedLawController"
         base_class_type="controller_interface::ControllerInterface">
    <description>The law exported by rrr-pin (see ../controller.json): effort commands from
      joint positions and velocities, the reference on ~/reference.</description>
  </class>
</library>
"""

_CMAKE = f"""# {_BANNER}
# The ros2_control controller plugin {PACKAGE}/ExportedLawController around the exported law
# of the parent folder (controller.h, ctrl_step_dt). Build: colcon build --paths <export>/ros2
cmake_minimum_required(VERSION 3.21)
project({PACKAGE} LANGUAGES C CXX)

if(CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang")
  add_compile_options(-Wall -Wextra)
endif()
set(CMAKE_CXX_STANDARD 17)
set(CMAKE_CXX_STANDARD_REQUIRED ON)

find_package(ament_cmake REQUIRED)
set(THIS_PACKAGE_DEPENDS controller_interface hardware_interface pluginlib rclcpp
    rclcpp_lifecycle realtime_tools trajectory_msgs)
foreach(dep IN ITEMS ${{THIS_PACKAGE_DEPENDS}})
  find_package(${{dep}} REQUIRED)
endforeach()

# The exported law (static library rrr_pin_ctrl, position-independent), from the parent folder.
get_filename_component(RRR_PIN_EXPORT "${{CMAKE_CURRENT_SOURCE_DIR}}/.." REALPATH)
add_subdirectory("${{RRR_PIN_EXPORT}}" rrr_pin_ctrl EXCLUDE_FROM_ALL)

add_library({PACKAGE} SHARED src/exported_law_controller.cpp)
target_include_directories({PACKAGE} PUBLIC
  $<BUILD_INTERFACE:${{CMAKE_CURRENT_SOURCE_DIR}}/include>
  $<INSTALL_INTERFACE:include/{PACKAGE}>)
target_link_libraries({PACKAGE} PRIVATE rrr_pin_ctrl)
# The plugin finds libpinocchio (Pinocchio dynamics) where it was linked from.
set_target_properties({PACKAGE} PROPERTIES INSTALL_RPATH_USE_LINK_PATH TRUE)
if(COMMAND ament_target_dependencies)
  ament_target_dependencies({PACKAGE} PUBLIC ${{THIS_PACKAGE_DEPENDS}})
endif()
pluginlib_export_plugin_description_file(controller_interface {PACKAGE}.xml)

install(DIRECTORY include/ DESTINATION include/{PACKAGE})
install(DIRECTORY config DESTINATION share/{PACKAGE})
install(TARGETS {PACKAGE} EXPORT export_{PACKAGE}
        ARCHIVE DESTINATION lib LIBRARY DESTINATION lib RUNTIME DESTINATION bin)
ament_export_targets(export_{PACKAGE} HAS_LIBRARY_TARGET)
ament_export_dependencies(${{THIS_PACKAGE_DEPENDS}})
ament_package()
"""

_YAML = """# """ + _BANNER + """
# Law {law!r} ({kind}) exported by rrr-pin, as a ros2_control controller. Load with the
# controller manager (its update_rate must be the law's rate):
#   ros2 control load_controller --set-state active rrr_pin_controller
controller_manager:
  ros__parameters:
    update_rate: {update_rate}  # [Hz]
    rrr_pin_controller:
      type: rrr_pin_controller/ExportedLawController

rrr_pin_controller:
  ros__parameters:
    joints: {joints}  # exactly the exported joints, in this order: checked
    rate_hz: {rate}  # the rate the law was discretized for: checked
    period_tolerance: {tol}  # an update period outside (1 +- this) / rate_hz is a fault
    torque_limit: {limit}  # [N m] per joint: the command is clipped
    position_lower: {lower}  # [rad] a measured position outside [lower, upper] is a fault
    position_upper: {upper}
    fault_torque: gravity  # the safe torque on a fault: gravity (Ghat(q)) or zero
    reference_topic: ~/reference  # trajectory_msgs/JointTrajectoryPoint
{gains}"""

_PARAMS_HPP = f"""// {_BANNER}
// The exported law's compiled-in gains and the defaults of the controller's parameters.
#pragma once

namespace {PACKAGE}
{{
namespace exported
{{
@GAINS@constexpr double kPeriodTolerance = @TOL@;
constexpr double kTorqueLimit[] = {{@LIMIT@}};
constexpr double kPositionLower[] = {{@LOWER@}};
constexpr double kPositionUpper[] = {{@UPPER@}};
}}  // namespace exported
}}  // namespace {PACKAGE}
"""

_HPP = f"""// {_BANNER}
// ExportedLawController: a controller_interface::ControllerInterface running ctrl_step_dt of
// the exported law (../../controller.h) once per update, over the period measured. Its rules
// (parameters checked at configure, the period band, the fault torque) are stated in the
// class comment.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "controller.h"
#include "controller_interface/controller_interface.hpp"
#include "rclcpp/rclcpp.hpp"
#include "rclcpp_lifecycle/state.hpp"
#include "realtime_tools/realtime_buffer.hpp"
#include "trajectory_msgs/msg/joint_trajectory_point.hpp"

namespace {PACKAGE}
{{
/// The faults that put the command on the safe torque (latched until the next activation).
enum class Fault : std::uint8_t
{{
  NONE = 0,
  PERIOD,           ///< an update period outside (1 +- period_tolerance) / rate_hz
  STATE,            ///< a measured position or velocity not finite, or a position out of limits
  REFERENCE_SIZE,   ///< a reference message with the wrong number of joints
  REFERENCE_VALUE,  ///< a reference message with a value not finite
  LAW               ///< ctrl_step_dt refused its inputs or produced a torque not finite
}};

/// A reference point written by the subscriber (non-real-time) and read by update().
struct Reference
{{
  std::array<double, CTRL_NQ> r{{}}, rd{{}}, rdd{{}};
  Fault fault = Fault::NONE;  ///< a bad message: the reason update() latches
  std::size_t sizes[3] = {{0, 0, 0}};  ///< the sizes the bad message had
}};

/// The exported law as a ros2_control effort controller.
///
/// Parameters (config/rrr_pin_controller.yaml), checked in on_configure: joints (exactly the
/// exported ones, in order), rate_hz (the law's), period_tolerance (0.2 = +-20 %),
/// torque_limit [N m], position_lower/upper [rad], fault_torque ("gravity" or "zero"), the
/// compiled-in gains (lam; kp, kd for PD), reference_topic.
/// update(): a period outside the band, a bad state or reference, or ctrl_step_dt refusing
/// latch a fault; the command is then the safe torque (gravity compensation Ghat(q), or zero
/// when q is not finite or fault_torque is "zero") every period until deactivation. Inside
/// the band the law runs over the period measured (ctrl_step_dt: K discretized at it,
/// CTRL_STEP_DT), the first update after activation over 1 / rate_hz.
class ExportedLawController : public controller_interface::ControllerInterface
{{
public:
  ExportedLawController();

  controller_interface::CallbackReturn on_init() override;
  controller_interface::InterfaceConfiguration command_interface_configuration() const override;
  controller_interface::InterfaceConfiguration state_interface_configuration() const override;
  controller_interface::CallbackReturn on_configure(
    const rclcpp_lifecycle::State & previous_state) override;
  controller_interface::CallbackReturn on_activate(
    const rclcpp_lifecycle::State & previous_state) override;
  controller_interface::CallbackReturn on_deactivate(
    const rclcpp_lifecycle::State & previous_state) override;
  controller_interface::return_type update(
    const rclcpp::Time & time, const rclcpp::Duration & period) override;

  /// What the subscriber does with a message (public so that a test can feed it directly).
  void set_reference(const trajectory_msgs::msg::JointTrajectoryPoint & msg);

  Fault fault() const {{ return fault_; }}
  /// The latched fault's reason (empty when none).
  std::string fault_reason() const {{ return std::string(reason_); }}
  /// The period [s] the last update computed with (measured; nominal on the first update).
  double last_period() const {{ return last_period_; }}
  std::uint64_t clipped_periods() const {{ return clipped_; }}

private:
#if defined(__GNUC__)
  __attribute__((format(printf, 3, 4)))
#endif
  void latch(Fault f, const char * fmt, ...);
  void safe_torque(const double q[CTRL_NQ], double tau[CTRL_NQ]) const;
  bool write_command(const double tau[CTRL_NQ]);

  std::vector<std::string> joints_;
  double rate_hz_ = CTRL_RATE_HZ;
  double tolerance_ = 0.0;
  bool gravity_on_fault_ = true;
  std::array<double, CTRL_NQ> limit_{{}}, lower_{{}}, upper_{{}};
  realtime_tools::RealtimeBuffer<Reference> reference_;
  rclcpp::Subscription<trajectory_msgs::msg::JointTrajectoryPoint>::SharedPtr subscription_;
  ctrl_state state_{{}};
  Fault fault_ = Fault::NONE;
  char reason_[160] = {{0}};
  double last_period_ = 0.0;
  bool first_update_ = true;
  std::uint64_t clipped_ = 0;
}};
}}  // namespace {PACKAGE}
"""

_CPP = f"""// {_BANNER}
#include "rrr_pin_controller/exported_law_controller.hpp"

#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <memory>
#include <limits>
#include <optional>
#include <type_traits>
#include <utility>

#include "dynamics.h"
#include "rrr_pin_controller/exported_law_params.hpp"

namespace {PACKAGE}
{{
namespace
{{
using controller_interface::CallbackReturn;

// A loaned interface's value: get_optional() where the interface has it (Jazzy and later),
// get_value() otherwise (Humble); NaN when the value could not be read (then a STATE fault).
template <class I>
auto read_value(const I & i, int) -> decltype(i.get_optional(), double())
{{
  const auto v = i.get_optional();
  return v.has_value() ? *v : std::numeric_limits<double>::quiet_NaN();
}}
template <class I>
double read_value(const I & i, long)
{{
  return i.get_value();
}}

// set_value() returns whether the value was written in newer ros2_control, nothing in Humble.
template <class I>
bool write_value(I & i, double v)
{{
  if constexpr (std::is_same_v<decltype(i.set_value(v)), bool>) {{
    return i.set_value(v);
  }} else {{
    i.set_value(v);
    return true;
  }}
}}

bool same_doubles(const std::vector<double> & a, const double * b, std::size_t n)
{{
  if (a.size() != n) return false;
  for (std::size_t i = 0; i < n; ++i)
    if (a[i] != b[i]) return false;
  return true;
}}
}}  // namespace

ExportedLawController::ExportedLawController() : controller_interface::ControllerInterface() {{}}

CallbackReturn ExportedLawController::on_init()
{{
  static const char * const names[CTRL_NQ] = CTRL_JOINT_NAMES;
  const std::vector<std::string> exported(names, names + CTRL_NQ);
  const std::vector<double> limit(exported::kTorqueLimit, exported::kTorqueLimit + CTRL_NQ);
  const std::vector<double> lower(exported::kPositionLower, exported::kPositionLower + CTRL_NQ);
  const std::vector<double> upper(exported::kPositionUpper, exported::kPositionUpper + CTRL_NQ);
  auto_declare<std::vector<std::string>>("joints", exported);
  auto_declare<double>("rate_hz", CTRL_RATE_HZ);
  auto_declare<double>("period_tolerance", exported::kPeriodTolerance);
  auto_declare<std::vector<double>>("torque_limit", limit);
  auto_declare<std::vector<double>>("position_lower", lower);
  auto_declare<std::vector<double>>("position_upper", upper);
  auto_declare<std::string>("fault_torque", "gravity");
  auto_declare<std::string>("reference_topic", "~/reference");
  if (exported::kIsPD) {{
    auto_declare<std::vector<double>>(
      "kp", std::vector<double>(exported::kKp, exported::kKp + CTRL_NQ * CTRL_NQ));
    auto_declare<std::vector<double>>(
      "kd", std::vector<double>(exported::kKd, exported::kKd + CTRL_NQ * CTRL_NQ));
  }} else {{
    if (exported::kLamPerJoint) {{
      auto_declare<std::vector<double>>(
        "lam", std::vector<double>(exported::kLam, exported::kLam + CTRL_NQ));
    }} else {{
      auto_declare<double>("lam", exported::kLam[0]);
    }}
  }}
  joints_ = exported;
  return CallbackReturn::SUCCESS;
}}

controller_interface::InterfaceConfiguration
ExportedLawController::command_interface_configuration() const
{{
  controller_interface::InterfaceConfiguration c;
  c.type = controller_interface::interface_configuration_type::INDIVIDUAL;
  for (const auto & j : joints_) c.names.push_back(j + "/effort");
  return c;
}}

controller_interface::InterfaceConfiguration
ExportedLawController::state_interface_configuration() const
{{
  controller_interface::InterfaceConfiguration c;
  c.type = controller_interface::interface_configuration_type::INDIVIDUAL;
  for (const auto & j : joints_) c.names.push_back(j + "/position");
  for (const auto & j : joints_) c.names.push_back(j + "/velocity");
  return c;
}}

CallbackReturn ExportedLawController::on_configure(const rclcpp_lifecycle::State &)
{{
  auto node = get_node();
  auto logger = node->get_logger();
  static const char * const names[CTRL_NQ] = CTRL_JOINT_NAMES;
  const auto joints = node->get_parameter("joints").as_string_array();
  for (int i = 0; i < CTRL_NQ; ++i) {{
    bool found = false;
    for (const auto & j : joints) found = found || j == names[i];
    if (!found) {{
      RCLCPP_ERROR(logger, "parameter joints: exported joint '%s' is missing", names[i]);
      return CallbackReturn::ERROR;
    }}
  }}
  for (const auto & j : joints) {{
    bool known = false;
    for (int i = 0; i < CTRL_NQ; ++i) known = known || j == names[i];
    if (!known) {{
      RCLCPP_ERROR(logger, "parameter joints: '%s' is not an exported joint (the law runs %d "
                   "joints)", j.c_str(), CTRL_NQ);
      return CallbackReturn::ERROR;
    }}
  }}
  if (joints.size() != static_cast<std::size_t>(CTRL_NQ)) {{
    RCLCPP_ERROR(logger, "parameter joints: %zu entries, the law runs %d joints (a joint "
                 "repeated)", joints.size(), CTRL_NQ);
    return CallbackReturn::ERROR;
  }}
  for (int i = 0; i < CTRL_NQ; ++i) {{
    if (joints[i] != names[i]) {{
      RCLCPP_ERROR(logger, "parameter joints: entry %d is '%s', the exported order has '%s'",
                   i, joints[i].c_str(), names[i]);
      return CallbackReturn::ERROR;
    }}
  }}
  rate_hz_ = node->get_parameter("rate_hz").as_double();
  if (rate_hz_ != CTRL_RATE_HZ) {{
    RCLCPP_ERROR(logger, "parameter rate_hz = %g Hz: the law was discretized for %g Hz; export "
                 "it again at that rate", rate_hz_, CTRL_RATE_HZ);
    return CallbackReturn::ERROR;
  }}
  if (get_update_rate() != 0 && static_cast<double>(get_update_rate()) != rate_hz_) {{
    RCLCPP_ERROR(logger, "the controller manager updates this controller at %u Hz; the law was "
                 "discretized for %g Hz: set update_rate to it", get_update_rate(), rate_hz_);
    return CallbackReturn::ERROR;
  }}
  tolerance_ = node->get_parameter("period_tolerance").as_double();
  if (!(tolerance_ > 0.0 && tolerance_ < 1.0)) {{
    RCLCPP_ERROR(logger, "parameter period_tolerance = %g: must be in (0, 1)", tolerance_);
    return CallbackReturn::ERROR;
  }}
  const char * arrays[3] = {{"torque_limit", "position_lower", "position_upper"}};
  std::array<double, CTRL_NQ> * targets[3] = {{&limit_, &lower_, &upper_}};
  for (int a = 0; a < 3; ++a) {{
    const auto v = node->get_parameter(arrays[a]).as_double_array();
    if (v.size() != static_cast<std::size_t>(CTRL_NQ)) {{
      RCLCPP_ERROR(logger, "parameter %s: %zu entries, expected %d (one per joint)", arrays[a],
                   v.size(), CTRL_NQ);
      return CallbackReturn::ERROR;
    }}
    for (int i = 0; i < CTRL_NQ; ++i) (*targets[a])[i] = v[i];
  }}
  for (int i = 0; i < CTRL_NQ; ++i) {{
    if (!(limit_[i] > 0.0) || !(lower_[i] < upper_[i])) {{
      RCLCPP_ERROR(logger, "joint '%s': torque_limit %g must be > 0 and position_lower %g < "
                   "position_upper %g", names[i], limit_[i], lower_[i], upper_[i]);
      return CallbackReturn::ERROR;
    }}
  }}
  const auto fault_torque = node->get_parameter("fault_torque").as_string();
  if (fault_torque != "gravity" && fault_torque != "zero") {{
    RCLCPP_ERROR(logger, "parameter fault_torque = '%s': 'gravity' or 'zero'",
                 fault_torque.c_str());
    return CallbackReturn::ERROR;
  }}
  gravity_on_fault_ = fault_torque == "gravity";
  if (exported::kIsPD) {{
    if (!same_doubles(node->get_parameter("kp").as_double_array(), exported::kKp,
                      CTRL_NQ * CTRL_NQ)
        || !same_doubles(node->get_parameter("kd").as_double_array(), exported::kKd,
                         CTRL_NQ * CTRL_NQ)) {{
      RCLCPP_ERROR(logger, "parameters kp, kd differ from the gains compiled into the exported "
                   "law; export the law again with the gains wanted");
      return CallbackReturn::ERROR;
    }}
  }} else if (exported::kLamPerJoint) {{
    if (!same_doubles(node->get_parameter("lam").as_double_array(), exported::kLam, CTRL_NQ)) {{
      RCLCPP_ERROR(logger, "parameter lam differs from the per-joint lam compiled into the "
                   "exported law; export the law again with the gains wanted");
      return CallbackReturn::ERROR;
    }}
  }} else if (node->get_parameter("lam").as_double() != exported::kLam[0]) {{
    RCLCPP_ERROR(logger, "parameter lam = %g differs from the lam = %g compiled into the "
                 "exported law; export the law again with the gain wanted",
                 node->get_parameter("lam").as_double(), exported::kLam[0]);
    return CallbackReturn::ERROR;
  }}
  subscription_ = node->create_subscription<trajectory_msgs::msg::JointTrajectoryPoint>(
    node->get_parameter("reference_topic").as_string(), rclcpp::SystemDefaultsQoS(),
    [this](const std::shared_ptr<trajectory_msgs::msg::JointTrajectoryPoint> msg) {{
      set_reference(*msg);
    }});
  return CallbackReturn::SUCCESS;
}}

void ExportedLawController::set_reference(const trajectory_msgs::msg::JointTrajectoryPoint & msg)
{{
  Reference ref;
  const std::size_t n = CTRL_NQ;
  ref.sizes[0] = msg.positions.size();
  ref.sizes[1] = msg.velocities.size();
  ref.sizes[2] = msg.accelerations.size();
  if (ref.sizes[0] != n || (ref.sizes[1] != n && ref.sizes[1] != 0)
      || (ref.sizes[2] != n && ref.sizes[2] != 0)) {{
    ref.fault = Fault::REFERENCE_SIZE;
  }} else {{
    for (std::size_t i = 0; i < n; ++i) {{
      ref.r[i] = msg.positions[i];
      ref.rd[i] = ref.sizes[1] ? msg.velocities[i] : 0.0;
      ref.rdd[i] = ref.sizes[2] ? msg.accelerations[i] : 0.0;
      if (!std::isfinite(ref.r[i]) || !std::isfinite(ref.rd[i]) || !std::isfinite(ref.rdd[i]))
        ref.fault = Fault::REFERENCE_VALUE;
    }}
  }}
  reference_.writeFromNonRT(ref);
}}

CallbackReturn ExportedLawController::on_activate(const rclcpp_lifecycle::State &)
{{
  // the interfaces are loaned in the order of the configurations above
  if (state_interfaces_.size() != 2 * CTRL_NQ || command_interfaces_.size() != CTRL_NQ) {{
    RCLCPP_ERROR(get_node()->get_logger(), "expected %d state and %d command interfaces, got "
                 "%zu and %zu", 2 * CTRL_NQ, CTRL_NQ, state_interfaces_.size(),
                 command_interfaces_.size());
    return CallbackReturn::ERROR;
  }}
  for (int i = 0; i < CTRL_NQ; ++i) {{
    if (state_interfaces_[i].get_name() != joints_[i] + "/position"
        || state_interfaces_[CTRL_NQ + i].get_name() != joints_[i] + "/velocity"
        || command_interfaces_[i].get_name() != joints_[i] + "/effort") {{
      RCLCPP_ERROR(get_node()->get_logger(), "interfaces of joint '%s' not in the configured "
                   "order", joints_[i].c_str());
      return CallbackReturn::ERROR;
    }}
  }}
  ctrl_reset(&state_);  // the law's state; Pinocchio's workspace of this thread
  Reference hold;  // hold the measured position until a reference arrives
  for (int i = 0; i < CTRL_NQ; ++i) hold.r[i] = read_value(state_interfaces_[i], 0);
  reference_.initRT(hold);
  fault_ = Fault::NONE;
  reason_[0] = '\\0';
  first_update_ = true;
  clipped_ = 0;
  return CallbackReturn::SUCCESS;
}}

CallbackReturn ExportedLawController::on_deactivate(const rclcpp_lifecycle::State &)
{{
  // leave the drives a defined command: zero effort (the hardware's own brake/hold rules next)
  for (auto & c : command_interfaces_) (void)write_value(c, 0.0);
  return CallbackReturn::SUCCESS;
}}

void ExportedLawController::latch(Fault f, const char * fmt, ...)
{{
  if (fault_ != Fault::NONE) return;  // the first reason is kept
  fault_ = f;
  std::va_list args;
  va_start(args, fmt);
  std::vsnprintf(reason_, sizeof reason_, fmt, args);
  va_end(args);
  RCLCPP_ERROR(get_node()->get_logger(), "fault, safe torque (%s) from now on: %s",
               gravity_on_fault_ ? "gravity compensation" : "zero", reason_);
}}

void ExportedLawController::safe_torque(const double q[CTRL_NQ], double tau[CTRL_NQ]) const
{{
  bool finite = true;
  for (int i = 0; i < CTRL_NQ; ++i) finite = finite && std::isfinite(q[i]);
  if (gravity_on_fault_ && finite) {{
    ctrl_dyn_gravity(q, tau);
  }} else {{
    for (int i = 0; i < CTRL_NQ; ++i) tau[i] = 0.0;
  }}
  for (int i = 0; i < CTRL_NQ; ++i) {{
    if (!std::isfinite(tau[i])) tau[i] = 0.0;
  }}
}}

bool ExportedLawController::write_command(const double tau[CTRL_NQ])
{{
  bool ok = true;
  for (int i = 0; i < CTRL_NQ; ++i) ok = write_value(command_interfaces_[i], tau[i]) && ok;
  return ok;
}}

controller_interface::return_type ExportedLawController::update(
  const rclcpp::Time &, const rclcpp::Duration & period)
{{
  double q[CTRL_NQ], qd[CTRL_NQ], tau[CTRL_NQ];
  for (int i = 0; i < CTRL_NQ; ++i) {{
    q[i] = read_value(state_interfaces_[i], 0);
    qd[i] = read_value(state_interfaces_[CTRL_NQ + i], 0);
  }}
  const double Ts = 1.0 / rate_hz_;  // == CTRL_PERIOD (rate_hz checked at configure)
  // the first update after activation has no previous one to measure a period from: it
  // computes with the nominal period; every later one with the period measured
  const double dt = first_update_ ? Ts : period.seconds();
  if (!first_update_ && !(std::fabs(dt - Ts) <= tolerance_ * Ts)) {{
    latch(Fault::PERIOD, "update period %.6g s outside the band %.6g s +- %.3g %%", dt, Ts,
          100.0 * tolerance_);
  }}
  first_update_ = false;
  last_period_ = dt;
  for (int i = 0; i < CTRL_NQ && fault_ == Fault::NONE; ++i) {{
    if (!std::isfinite(q[i]) || !std::isfinite(qd[i])) {{
      latch(Fault::STATE, "joint '%s': state q = %g, qd = %g not finite", joints_[i].c_str(),
            q[i], qd[i]);
    }} else if (q[i] < lower_[i] || q[i] > upper_[i]) {{
      latch(Fault::STATE, "joint '%s': position %g rad outside its limits [%g, %g]",
            joints_[i].c_str(), q[i], lower_[i], upper_[i]);
    }}
  }}
  const Reference * ref = reference_.readFromRT();
  if (fault_ == Fault::NONE && ref->fault == Fault::REFERENCE_SIZE) {{
    latch(Fault::REFERENCE_SIZE, "reference of the wrong size: positions %zu, velocities %zu, "
          "accelerations %zu; expected %d each (or 0 velocities, 0 accelerations)",
          ref->sizes[0], ref->sizes[1], ref->sizes[2], CTRL_NQ);
  }} else if (fault_ == Fault::NONE && ref->fault == Fault::REFERENCE_VALUE) {{
    latch(Fault::REFERENCE_VALUE, "reference with a value not finite");
  }}
  if (fault_ == Fault::NONE) {{
    // the law over the period measured (CTRL_STEP_DT: K discretized at dt)
    const int rc = ctrl_step_dt(&state_, q, qd, ref->r.data(), ref->rd.data(), ref->rdd.data(),
                                tau, dt);
    if (rc != CTRL_OK) {{
      latch(Fault::LAW, "ctrl_step_dt returned %d (1: an input not finite, 2: a torque not "
            "finite, 3: a period it cannot run)", rc);
    }}
  }}
  if (fault_ != Fault::NONE) {{
    safe_torque(q, tau);
  }}
  bool clipped = false;
  for (int i = 0; i < CTRL_NQ; ++i) {{
    if (tau[i] > limit_[i]) {{
      tau[i] = limit_[i];
      clipped = true;
    }} else if (tau[i] < -limit_[i]) {{
      tau[i] = -limit_[i];
      clipped = true;
    }}
  }}
  clipped_ += clipped;
  if (!write_command(tau)) {{
    RCLCPP_ERROR(get_node()->get_logger(), "a command interface refused its value");
    return controller_interface::return_type::ERROR;
  }}
  return controller_interface::return_type::OK;
}}
}}  // namespace {PACKAGE}

#include "pluginlib/class_list_macros.hpp"

PLUGINLIB_EXPORT_CLASS({PACKAGE}::ExportedLawController, controller_interface::ControllerInterface)
"""
