"""The ros2 package's calls against the real ros2_control and realtime_tools declarations.

``tests/ros2_stubs/api/declarations.txt`` holds, one line each, the declarations the exported
package relies on, copied from the public headers of ros2_control and realtime_tools on their
``humble`` and ``jazzy`` branches (commits named in the file; declarations only, no code).
Two checks, per distribution: every call the generated controller makes resolves to one of them
(Humble's ``get_value`` where Jazzy has ``get_optional``), and the stubs the package is compiled
against in tests/test_ros2_package.py declare each of them as written (with
``RRR_PIN_STUB_HUMBLE`` for Humble), so that compiling against the stubs means compiling against
these signatures.

Not checked here (stated in docs/guide/torque-controlled-arm.md): rclcpp, rclcpp_lifecycle (the
lifecycle callbacks' signatures), pluginlib and trajectory_msgs, whose headers were not taken;
and anything a real build would find beyond declarations (template instantiation, ABI, the
controller manager's behaviour).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from rrr_pin import export as export_law
from rrr_pin import load_robot
from rrr_pin.deploy.ros2 import ros2_package

STUBS = Path(__file__).resolve().parent / "ros2_stubs"

#: The real header -> the stub that stands for it.
STUB_OF = {
    "controller_interface_base.hpp": "controller_interface/controller_interface.hpp",
    "loaned_command_interface.hpp": "hardware_interface/loaned_command_interface.hpp",
    "loaned_state_interface.hpp": "hardware_interface/loaned_state_interface.hpp",
    "realtime_buffer.hpp": "realtime_tools/realtime_buffer.hpp",
}

#: What the generated .cpp calls (a pattern) -> the declaration, per distribution, that
#: provides it.
CALLS = {
    r"\.get_optional\(\)": {"jazzy": "[[nodiscard]] std::optional<T> get_optional("
                                     "unsigned int max_tries = 10) const",
                            "humble": "double get_value() const"},
    r"\.get_value\(\)": {"jazzy": "double get_value() const", "humble": "double get_value() const"},
    r"\.set_value\(": {"jazzy": "[[nodiscard]] bool set_value(const T & value, "
                                "unsigned int max_tries = 10)",
                       "humble": "void set_value(double val)"},
    r"\.get_name\(\)": {"jazzy": "const std::string & get_name() const",
                        "humble": "const std::string get_name() const"},
    r"auto_declare<": "auto auto_declare(const std::string & name, const ParameterT & "
                      "default_value)",
    r"get_node\(\)": "std::shared_ptr<rclcpp_lifecycle::LifecycleNode> get_node();",
    r"get_update_rate\(\)": "unsigned int get_update_rate() const;",
    r"\breadFromRT\(\)": "T * readFromRT()",
    r"\bwriteFromNonRT\(": "void writeFromNonRT(const T & data)",
    r"\binitRT\(": "void initRT(const T & data)",
    r"interface_configuration_type::INDIVIDUAL": "INDIVIDUAL = 1,",
    r"return_type::OK": "OK = 0,",
    r"return_type::ERROR": "ERROR = 1,",
    r"command_interfaces_": "std::vector<hardware_interface::LoanedCommandInterface> "
                            "command_interfaces_;",
    r"state_interfaces_": "std::vector<hardware_interface::LoanedStateInterface> "
                          "state_interfaces_;",
    r"\bupdate\(": "virtual return_type update(const rclcpp::Time & time, "
                   "const rclcpp::Duration & period) = 0;",
    r"command_interface_configuration\(\)": "virtual InterfaceConfiguration "
                                            "command_interface_configuration() const = 0;",
    r"on_init\(\)": "virtual CallbackReturn on_init() = 0;",
}


def _declarations() -> dict[str, list[tuple[str, str]]]:
    out = {"humble": [], "jazzy": []}
    for line in (STUBS / "api" / "declarations.txt").read_text().splitlines():
        if line.startswith("#") or not line.strip():
            continue
        distro, _, header, decl = (part.strip() for part in line.split(" | ", 3))
        out[distro].append((Path(header).name, decl))
    return out


def _stub_text(name: str, distro: str) -> str:
    """The stub header as the compiler sees it for ``distro`` (RRR_PIN_STUB_HUMBLE resolved),
    whitespace collapsed."""
    keep, stack = [], []
    for line in (STUBS / name).read_text().splitlines():
        s = line.strip()
        if s.startswith("#ifdef RRR_PIN_STUB_HUMBLE"):
            stack.append(distro == "humble")
        elif s.startswith("#ifndef RRR_PIN_STUB_HUMBLE"):
            stack.append(distro != "humble")
        elif s.startswith("#else") and stack:
            stack[-1] = not stack[-1]
        elif s.startswith("#endif") and stack:
            stack.pop()
        elif all(stack):
            keep.append(s)
    return re.sub(r"\s+", " ", " ".join(keep))


def _core(decl: str) -> str:
    """A declaration without what a definition may write otherwise (virtual, = 0, ;, ,)."""
    decl = re.sub(r"^virtual ", "", decl)
    decl = re.sub(r"^\[\[deprecated\([^]]*\)\]\] ", "", decl)
    return re.sub(r"( = 0)?[;,]$", "", decl)


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_stubs_declare_the_real_signatures(distro):
    decls = _declarations()[distro]
    assert len(decls) >= 20
    missing = [(h, d) for h, d in decls if _core(d) not in _stub_text(STUB_OF[h], distro)]
    assert not missing, f"{distro}: the stubs lack {missing}"


@pytest.mark.parametrize("distro", ["humble", "jazzy"])
def test_every_call_of_the_package_is_declared(distro, tmp_path):
    robot = load_robot("rrr")
    ex = export_law("fl", robot, 1000.0, tmp_path / "e")
    files = ros2_package(ex, robot)
    code = "".join(text for name, text in files.items() if name.endswith((".cpp", ".hpp")))
    declared = {d for _, d in _declarations()[distro]}
    used = [pattern for pattern in CALLS if re.search(pattern, code)]
    assert len(used) >= 15  # the table covers what the package calls
    for pattern in used:
        decl = CALLS[pattern]
        decl = decl[distro] if isinstance(decl, dict) else decl
        assert decl in declared, f"{distro}: {pattern} -> {decl!r} is not a real declaration"
