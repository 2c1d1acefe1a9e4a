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

import re

import numpy as np

from ..outputs import writing
from ..validation import FieldError
from .sources import _num, render
from .writer import ExportError

__all__ = ["ros2_package", "write_ros2_package", "check_ros2", "check_ros2_name",
           "package_name", "PLACEHOLDER_MAINTAINER", "PERIOD_TOLERANCE"]

#: package.xml's maintainer when the exporter gave none: an address that cannot exist
#: (``.invalid``, RFC 2606); the package's CMake refuses a release with it.
PLACEHOLDER_MAINTAINER = ("rrr-pin export (placeholder: export --maintainer 'Name <email>')",
                          "maintainer@rrr-pin.invalid")

#: C++ keywords, which a package name (the plugin's namespace) cannot be.
_CXX_KEYWORDS = frozenset(
    "alignas alignof and and_eq asm auto bitand bitor bool break case catch char char8_t "
    "char16_t char32_t class compl concept const consteval constexpr constinit const_cast "
    "continue co_await co_return co_yield decltype default delete do double dynamic_cast else "
    "enum explicit export extern false float for friend goto if inline int long mutable "
    "namespace new noexcept not not_eq nullptr operator or or_eq private protected public "
    "register reinterpret_cast requires return short signed sizeof static static_assert "
    "static_cast struct switch template this thread_local throw true try typedef typeid "
    "typename union unsigned using virtual void volatile wchar_t while xor xor_eq".split())

#: A valid ROS 2 package name (REP 144): a lowercase letter, then lowercase letters, digits
#: and single underscores, not ending with one.
_ROS_NAME = re.compile(r"[a-z](?:[a-z0-9]|_(?!_))*[a-z0-9]")


def check_ros2_name(name: str) -> str:
    """Return ``name`` if it is a valid ROS 2 package name and C++ namespace, else refuse it.

    Raises
    ------
    FieldError
        Not REP 144's form (``[a-z][a-z0-9_]*``, no double or trailing underscore, at least two
        characters), or a C++ keyword (the package name is the plugin's namespace).
    """
    if not isinstance(name, str) or not _ROS_NAME.fullmatch(name):
        raise FieldError("ros2_name", f"{{name}} = {name!r} is not a ROS 2 package name (REP "
                                      f"144: a lowercase letter, then lowercase letters, digits "
                                      f"and single underscores, not ending with one; e.g. "
                                      f"ur5_hinf_controller)")
    if name in _CXX_KEYWORDS:
        raise FieldError("ros2_name", f"{{name}} = {name!r} is a C++ keyword; the package name "
                                      f"is the plugin's namespace")
    return name


def package_name(arm: str, law: str) -> str:
    """Return the default package name ``<arm>_<law>_controller``, made a valid ROS name.

    Letters are lowered, any other character becomes one underscore, and a name that does not
    start with a letter gets ``arm_`` in front (``"UR5e-left"``, ``"hinf"`` ->
    ``"ur5e_left_hinf_controller"``).
    """
    text = re.sub(r"[^a-z0-9]+", "_", f"{arm}_{law}_controller".lower()).strip("_")
    text = re.sub(r"_+", "_", text)
    if not text[:1].isalpha():
        text = "arm_" + text
    return check_ros2_name(text)


def _maintainer(maintainer: str | None) -> tuple[str, str, bool]:
    """``(name, email, placeholder)`` from ``"Name <email>"`` (None: the placeholder)."""
    if maintainer is None:
        return (*PLACEHOLDER_MAINTAINER, True)
    hit = re.fullmatch(r"\s*([^<>&\"]+?)\s*<([^<>@\s&\"]+@[^<>@\s&\"]+\.[^<>@\s&\"]+)>\s*",
                       maintainer)
    if not hit or not maintainer.isascii():
        raise FieldError("maintainer", f"{{name}} = {maintainer!r}: expected 'Name <email>' "
                                       f"(ASCII), e.g. 'Ada Lovelace <ada@example.org>'")
    return hit.group(1), hit.group(2), False

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


def ros2_package(prepared, robot, *, name: str | None = None,
                 maintainer: str | None = None) -> dict[str, str]:
    """Return the package's files (relative path -> text) for an :class:`~.writer.Export`.

    Parameters
    ----------
    prepared : Export
        The export (:func:`rrr_pin.deploy.writer.prepare_export`) the package runs.
    robot : Robot
        Its arm (joint names, position and effort limits).
    name : str, optional
        The package's name, also the plugin's namespace (``<name>/ExportedLawController``);
        default :func:`package_name` of the arm and the law, ``<arm>_<law>_controller``, so that
        two exports share a workspace. Checked by :func:`check_ros2_name`.
    maintainer : str, optional
        ``"Name <email>"`` for package.xml; default :data:`PLACEHOLDER_MAINTAINER`, which the
        package's CMake refuses to release.

    Returns
    -------
    dict
        ``"ros2/package.xml"``, ... -> text (ASCII), in a fixed order.

    Raises
    ------
    ExportError
        As :func:`check_ros2`.
    FieldError
        A ``name`` that is not a ROS package name, a ``maintainer`` not ``"Name <email>"``.
    """
    check_ros2(prepared)
    package = (package_name(robot.name, prepared.law.name) if name is None
               else check_ros2_name(name))
    who, email, placeholder = _maintainer(maintainer)
    command = prepared.command.name if prepared.command is not None else "full"
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
    # Pinocchio dynamics link libpinocchio: a rosdep key (ros-$ROS_DISTRO-pinocchio); the
    # generated dynamics need the C library only
    extra = ("  <depend>pinocchio</depend>\n" if prepared.dynamics == "pinocchio" else "")
    common = {"package": package}
    values = dict(rate=_num(rate), update_rate=int(round(rate)), joints=_yaml_list(joints),
                  tol=_num(PERIOD_TOLERANCE), limit=_yaml_list(_num(v) for v in limit),
                  lower=_yaml_list(_num(v) for v in lower),
                  upper=_yaml_list(_num(v) for v in upper), gains=gain_yaml,
                  law=repr(prepared.law.name), kind=form.kind, command=command)
    files = {
        "ros2/package.xml": render("ros2/package.xml", **common, maintainer=_xml(who),
                                   email=_xml(email), extra_depends=extra, command=command),
        "ros2/CMakeLists.txt": render("ros2/CMakeLists.txt", **common,
                                      maintainer_placeholder="ON" if placeholder else "OFF"),
        f"ros2/{package}.xml": render("ros2/plugin.xml", **common),
        f"ros2/config/{package}.yaml": render("ros2/controller.yaml", **common, **values),
        f"ros2/include/{package}/exported_law_params.hpp": render(
            "ros2/exported_law_params.hpp", **common, gains=gain_decl,
            tol=_num(PERIOD_TOLERANCE), limit=", ".join(map(_num, limit)),
            lower=", ".join(map(_num, lower)), upper=", ".join(map(_num, upper))),
        f"ros2/include/{package}/exported_law_controller.hpp": render(
            "ros2/exported_law_controller.hpp", **common),
        "ros2/src/exported_law_controller.cpp": render("ros2/exported_law_controller.cpp",
                                                       **common),
        f"ros2/launch/{package}.launch.py": render("ros2/launch.py.in", **common,
                                                   joints=", ".join(joints)),
        "ros2/config/ros2_control.xml": render("ros2/ros2_control.xml", **common,
                                               command=command, joint_blocks="".join(
                                                   _JOINT_BLOCK.format(name=_xml(j))
                                                   for j in joints)),
    }
    return files


#: One joint of the <ros2_control> block (config/ros2_control.xml).
_JOINT_BLOCK = """  <joint name="{name}">
    <command_interface name="effort"/>
    <state_interface name="position"/>
    <state_interface name="velocity"/>
  </joint>
"""


def _xml(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def write_ros2_package(prepared, robot, folder, *, name: str | None = None,
                       maintainer: str | None = None) -> list:
    """Write :func:`ros2_package` under ``folder`` (the export's folder); return the paths."""
    from pathlib import Path

    out = []
    for rel, text in ros2_package(prepared, robot, name=name,
                                  maintainer=maintainer).items():
        path = Path(folder) / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        with writing(path):
            path.write_bytes(text.encode("ascii"))
        out.append(path)
    return out


