"""`rrr-pin export --ros2`: the ros2_control package, compiled against tests/ros2_stubs (issue 35).

ROS 2 is not installable on the project's machines: the package's C++ is compiled with
``-Wall -Wextra -Werror`` against stub headers with the real API's names and signatures
(tests/ros2_stubs/README.md says what they leave out), twice: with the accessors of Jazzy and
later (``get_optional``, ``[[nodiscard]] bool set_value``) and with Humble's. A driver plays the
controller manager (tests/ros2_stubs/drive_controller.cpp): init with the YAML's parameters,
configure, activate, update with a given period, the reference through the subscription.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml
from numpy.testing import assert_allclose

from rrr_pin import export as export_law
from rrr_pin import exported_law, load_robot
from rrr_pin.cli import main
from rrr_pin.deploy.ros2 import PERIOD_TOLERANCE, write_ros2_package

CC = shutil.which("cc")
CXX = shutil.which("c++")
STUBS = Path(__file__).resolve().parent / "ros2_stubs"
WARN = ["-Wall", "-Wextra", "-Werror"]
RATE = 1000.0
TS = 1.0 / RATE

#: The package name by default: <arm>_<law>_controller.
PKG = "rrr_hinf_controller"

#: The fault codes of <package>::Fault.
NONE, PERIOD, STATE, REF_SIZE, REF_VALUE = 0, 1, 2, 3, 4


@pytest.fixture(scope="module")
def package(tmp_path_factory):
    """The paper's H-infinity + FL on the RRR at 1 kHz with its ros2 package, compiled."""
    if CC is None or CXX is None:
        pytest.skip("no C/C++ compiler")
    robot = load_robot("rrr")
    folder = tmp_path_factory.mktemp("ros2") / "hinf"
    ex = export_law("hinf", robot, RATE, folder)
    write_ros2_package(ex, robot, folder)
    objs = []
    for f in ("controller.c", "dynamics.c", "codegen_rrr.c"):
        obj = folder / (f + ".o")
        subprocess.run([CC, "-std=c99", *WARN, "-O2", "-fPIC", "-c", str(folder / f), "-o",
                        str(obj)], check=True, capture_output=True, text=True)
        objs.append(str(obj))
    lib = folder / "libdirect.so"
    subprocess.run([CC, "-shared", "-o", str(lib), *objs, "-lm"], check=True)
    drivers = {}
    for api, flags in (("jazzy", []), ("humble", ["-DRRR_PIN_STUB_HUMBLE"])):
        exe = folder / f"drive_{api}"
        done = subprocess.run(
            [CXX, "-std=c++17", *WARN, *flags, f"-DRRR_PIN_PACKAGE={PKG}", "-O1", f"-I{STUBS}",
             f"-I{folder}",
             f"-I{folder / 'ros2' / 'include'}",
             str(folder / "ros2" / "src" / "exported_law_controller.cpp"),
             str(STUBS / "drive_controller.cpp"), *objs, "-o", str(exe), "-lm"],
            capture_output=True, text=True, check=False)
        assert done.returncode == 0, done.stderr  # no warning allowed either (-Werror)
        drivers[api] = exe
    return ex, robot, folder, lib, drivers


def _params(folder: Path, **changes) -> list[str]:
    """The YAML's controller parameters as driver lines, with ``changes``."""
    (path,) = (folder / "ros2" / "config").glob("*_controller.yaml")
    doc = yaml.safe_load(path.read_text())
    params = dict(doc[path.stem]["ros__parameters"], **changes)
    lines = []
    for name, v in params.items():
        if v is None:
            continue
        if isinstance(v, list) and v and isinstance(v[0], str):
            lines.append(f"param {name} sa {len(v)} {' '.join(v)}")
        elif isinstance(v, list):
            lines.append(f"param {name} da {len(v)} {' '.join(repr(float(x)) for x in v)}")
        elif isinstance(v, str):
            lines.append(f"param {name} s {v}")
        else:
            lines.append(f"param {name} d {float(v)!r}")
    return lines


def _drive(exe: Path, lines: list[str]):
    done = subprocess.run([str(exe)], input="\n".join(lines) + "\n", capture_output=True,
                          text=True, check=True, timeout=60)
    return done.stdout.splitlines(), done.stderr


def _vec(v) -> str:
    return " ".join(repr(float(x)) for x in v)


def _updates(out: list[str]):
    """(tau rows, fault codes, periods used) of the driver's ``update`` answers."""
    rows = [line.split() for line in out if line.startswith("update ")]
    assert all(r[1] == "OK" for r in rows)
    n = len(rows[0]) - 8  # "update OK" tau[n] "fault" code period clipped "allocations" k
    tau = np.array([[float(x) for x in r[2:2 + n]] for r in rows])
    fault = [int(r[3 + n]) for r in rows]
    period = np.array([float(r[4 + n]) for r in rows])
    # the stub counts C++ allocations during each update(): a real-time thread makes none
    assert all(r[6 + n] == "allocations" and r[7 + n] == "0" for r in rows), rows
    return tau, fault, period


def _started(folder, **changes) -> list[str]:
    q0 = np.array([0.1, -0.4, 0.7])
    return [*_params(folder, **changes), "init", "configure",
            f"activate {_vec(q0)} {_vec(np.zeros(3))}"]


def test_package_files(package):
    ex, robot, folder, _, _ = package
    xml = (folder / "ros2" / "package.xml").read_text()
    assert f"<name>{PKG}</name>" in xml and "<depend>realtime_tools</depend>" in xml
    # generated dynamics: no Pinocchio to depend on; a placeholder maintainer that cannot exist
    assert "<depend>pinocchio</depend>" not in xml and "@rrr-pin.invalid" in xml
    cmake = (folder / "ros2" / "CMakeLists.txt").read_text()
    assert f"pluginlib_export_plugin_description_file(controller_interface {PKG}.xml)" in cmake
    assert "RPATH" not in cmake and "if(ON)\n  if(RRR_PIN_RELEASE)" in cmake
    plugin = (folder / "ros2" / f"{PKG}.xml").read_text()
    assert f'type="{PKG}::ExportedLawController"' in plugin
    assert 'base_class_type="controller_interface::ControllerInterface"' in plugin
    doc = yaml.safe_load((folder / "ros2" / "config" / f"{PKG}.yaml").read_text())
    assert doc["controller_manager"]["ros__parameters"]["update_rate"] == 1000
    p = doc[PKG]["ros__parameters"]
    assert p["command"] == "full"
    assert p["joints"] == list(robot.joint_names) and p["rate_hz"] == RATE
    assert p["period_tolerance"] == PERIOD_TOLERANCE and p["lam"] == ex.form.lam
    assert p["torque_limit"] == robot.model.effortLimit.tolist()


@pytest.mark.parametrize("api, count", [("jazzy", 2000), ("humble", 200)])
def test_update_equals_the_c_and_python_law(package, api, count):
    """Random steps through the controller: ctrl_step's torques and the Python law's."""
    ex, robot, folder, lib, drivers = package
    rng = np.random.default_rng(35)
    lines = _started(folder, torque_limit=[1e12] * 3)  # no clip: the law's own torque
    steps = []
    for _ in range(count):
        q, qd, r, rd, rdd = (rng.uniform(-3.0, 3.0, 3) for _ in range(5))
        steps.append((q, qd, r, rd, rdd))
        lines += [f"ref 3 {_vec(r)} 3 {_vec(rd)} 3 {_vec(rdd)}", f"update {TS!r} {_vec(q)} "
                  f"{_vec(qd)}"]
    out, err = _drive(drivers[api], lines)
    assert out[:3] == ["init SUCCESS", "configure SUCCESS", "activate SUCCESS"], err
    tau, fault, _ = _updates(out)
    assert set(fault) == {NONE}
    c_law = exported_law(folder, lib)
    x_py = ex.law.initial_state()
    x_c = c_law.initial_state()
    for k, (q, qd, r, rd, rdd) in enumerate(steps):
        tau_py, x_py = ex.law.step(k * TS, q, qd, r, rd, rdd, x_py)
        tau_c, x_c = c_law.step(k * TS, q, qd, r, rd, rdd, x_c)
        # the same compiled ctrl_step: the same bits
        assert_allclose(tau[k], tau_c, rtol=0, atol=0)
        # Python (Pinocchio CRBA/NLE, numpy) against the C (generated dynamics): round-off
        assert_allclose(tau[k], tau_py, rtol=1e-12, atol=0)


def test_jitter_inside_the_band_computes_with_the_period(package):
    """Periods inside +-20 %: the law runs over each period measured, nothing else changes.

    Each update equals ctrl_step_dt at the measured period (bit for bit) and the Python law
    with K discretized at that period by python-control's sample_system (1e-12), on the state
    chained from the previous periods; the first update after activation uses 1 / rate_hz.
    """
    import control

    from rrr_pin.control.laws import DiscreteTrackingController

    ex, robot, folder, lib, drivers = package
    c_law = exported_law(folder, lib)
    rng = np.random.default_rng(7)
    steps = [(rng.uniform(-1.0, 1.0, 3), rng.uniform(-1.0, 1.0, 3)) for _ in range(300)]
    r, rd, rdd = np.array([0.2, -0.3, 0.5]), np.array([0.1, 0.0, -0.1]), np.zeros(3)
    ref = f"ref 3 {_vec(r)} 3 {_vec(rd)} 3 {_vec(rdd)}"
    jitter = TS * (1.0 + rng.uniform(-0.199, 0.199, len(steps)))  # +-19.9 %: inside +-20 %
    jitter[5] = TS * 1.0011  # the period the previous class refused (1 us tolerance)
    jitter = np.round(jitter * 1e9) * 1e-9  # what a Duration holds (whole nanoseconds)
    runs = []
    for periods in (np.full(len(steps), TS), jitter):
        lines = [*_started(folder, torque_limit=[1e12] * 3), ref]  # no clip: the law's torque
        lines += [f"update {float(p)!r} {_vec(q)} {_vec(qd)}"
                  for p, (q, qd) in zip(periods, steps, strict=True)]
        runs.append(_updates(_drive(drivers["jazzy"], lines)[0]))
    (tau_a, fault_a, used_a), (tau_b, fault_b, used_b) = runs
    assert set(fault_a) == set(fault_b) == {NONE}
    # the period used: the one measured (to the nanosecond a Duration holds), but the first
    assert_allclose(used_b[1:], jitter[1:], rtol=0, atol=1e-15)
    assert used_b[0] == TS and np.all(used_a == TS)
    A, B, C, D = ex.continuous
    x_c = x_py = c_law.initial_state()
    for k, (q, qd) in enumerate(steps):
        tau_c, x_c, rc = c_law.step_dt(q, qd, r, rd, rdd, x_c, used_b[k])
        assert rc == 0
        assert_allclose(tau_b[k], tau_c, rtol=0, atol=0)  # the same compiled ctrl_step_dt
        Kd = control.sample_system(control.ss(A, B, C, D), used_b[k], method="tustin")
        law_k = DiscreteTrackingController(ex.law.nominal, ex.form.lam, Kd)
        tau_py, x_py = law_k.step(0.0, q, qd, r, rd, rdd, x_py)
        assert_allclose(tau_b[k], tau_py, rtol=1e-12, atol=0)
    # at the nominal period it is ctrl_step (the bit-for-bit test above); the first update
    # (nominal period, initial state) is the same in both runs, the later ones are not
    assert_allclose(tau_b[0], tau_a[0], rtol=0, atol=0)
    assert np.max(np.abs(tau_b[1:] - tau_a[1:])) > 1e-3  # [N m]: the period is used


def _gravity(robot, q):
    """Ghat(q) by Pinocchio (independent of the generated C the controller calls)."""
    return pin.computeGeneralizedGravity(robot.model, robot.model.createData(), q)


def _assert_latched_safe_torque(out, err, robot, q, code, reason):
    """Updates good, faulty, good: the fault ``code`` latches, the safe torque (gravity
    compensation, by Pinocchio) is written on the faulty update and after, the reason says so
    and nothing is logged from update(). Returns the three torques."""
    tau, fault, _ = _updates(out)
    assert fault == [NONE, code, code]  # latched: a good update does not clear it
    assert_allclose(tau[1], _gravity(robot, q), rtol=1e-12)
    assert_allclose(tau[2], _gravity(robot, q), rtol=1e-12)
    assert reason in next(line for line in out if line.startswith("reason "))
    assert err == ""  # nothing logged from update(), the real-time thread (issue 47)
    return tau


@pytest.mark.parametrize("period", [1.25e-3, 0.75e-3, 10e-3, 0.0, -1e-3],
                         ids=["25% long", "25% short", "10x", "zero", "negative"])
def test_period_outside_the_band_is_a_reported_fault(package, period):
    ex, robot, folder, _, drivers = package
    q = np.array([0.3, -0.5, 0.9])
    lines = [*_started(folder), f"update {TS!r} {_vec(q)} 0 0 0",
             f"update {period!r} {_vec(q)} 0 0 0", "reason", f"update {TS!r} {_vec(q)} 0 0 0"]
    out, err = _drive(drivers["jazzy"], lines)
    tau = _assert_latched_safe_torque(out, err, robot, q, PERIOD,
                                      f"update period {period:.6g} s outside the band 0.001 s "
                                      f"+- 20 %")
    assert not np.allclose(tau[0], tau[1])  # not the previous torque held


def test_fault_torque_zero(package):
    ex, robot, folder, _, drivers = package
    q = np.array([0.3, -0.5, 0.9])
    out, _ = _drive(drivers["jazzy"], [*_started(folder, fault_torque="zero"),
                                       f"update {TS!r} {_vec(q)} 0 0 0",
                                       f"update 0.002 {_vec(q)} 0 0 0"])
    tau, fault, _ = _updates(out)
    assert fault == [NONE, PERIOD] and np.all(tau[1] == 0.0)


@pytest.mark.parametrize("ref, sizes", [
    ("ref 2 0.1 0.2 0 0", "positions 2, velocities 0, accelerations 0"),
    ("ref 4 0.1 0.2 0.3 0.4 0 0", "positions 4, velocities 0, accelerations 0"),
    ("ref 3 0.1 0.2 0.3 2 0 0 0", "positions 3, velocities 2, accelerations 0"),
    ("ref 3 0.1 0.2 0.3 3 0 0 0 1 0", "positions 3, velocities 3, accelerations 1"),
], ids=["2 positions", "4 positions", "2 velocities", "1 acceleration"])
def test_reference_of_the_wrong_size_is_a_reported_fault(package, ref, sizes):
    ex, robot, folder, _, drivers = package
    q = np.array([0.3, -0.5, 0.9])
    out, err = _drive(drivers["jazzy"], [*_started(folder), "ref 3 0.6 0.1 0.2 0 0",
                                         f"update {TS!r} {_vec(q)} 0 0 0", ref,
                                         f"update {TS!r} {_vec(q)} 0 0 0", "reason",
                                         "ref 3 0.6 0.1 0.2 0 0",
                                         f"update {TS!r} {_vec(q)} 0 0 0"])
    tau = _assert_latched_safe_torque(out, err, robot, q, REF_SIZE,
                                      f"reason reference of the wrong size: {sizes}; expected "
                                      f"3 each")
    assert np.max(np.abs(tau[0] - tau[1])) > 1.0  # [N m]: not the last torque held


def test_reference_and_state_not_finite(package):
    ex, robot, folder, _, drivers = package
    q = np.array([0.3, -0.5, 0.9])
    out, _ = _drive(drivers["jazzy"], [*_started(folder), "ref 3 0.1 nan 0 0 0",
                                       f"update {TS!r} {_vec(q)} 0 0 0"])
    tau, fault, _ = _updates(out)
    assert fault == [REF_VALUE]
    out, _ = _drive(drivers["jazzy"], [*_started(folder),
                                       f"update {TS!r} 0.3 nan 0.9 0 0 0", "reason"])
    tau, fault, _ = _updates(out)
    assert fault == [STATE] and np.all(tau[0] == 0.0)  # q not finite: zero, not gravity
    assert "joint 'joint2': state q = nan" in out[-1]
    out, _ = _drive(drivers["jazzy"], [*_started(folder), f"update {TS!r} 0.3 3.5 0.9 0 0 0",
                                       "reason"])
    assert _updates(out)[1] == [STATE] and "position 3.5 rad outside its limits" in out[-1]


@pytest.mark.parametrize("changes, message", [
    ({"joints": ["joint1", "joint2"]}, "exported joint 'joint3' is missing"),
    ({"joints": ["joint1", "joint2", "joint3", "gripper"]},
     "'gripper' is not an exported joint (the law runs 3 joints)"),
    ({"joints": ["joint2", "joint1", "joint3"]},
     "entry 0 is 'joint2', the exported order has 'joint1'"),
    ({"rate_hz": 500.0}, "rate_hz = 500 Hz: the law was discretized for 1000 Hz"),
    ({"lam": 40.0}, "lam = 40 differs from the lam = 45 compiled into the exported law"),
    ({"period_tolerance": 1.5}, "period_tolerance = 1.5: must be in (0, 1)"),
    ({"torque_limit": [1.0, 2.0]}, "torque_limit: 2 entries, expected 3"),
    ({"fault_torque": "hold"}, "fault_torque = 'hold': 'gravity' or 'zero'"),
    ({"command": "no-gravity"}, "command = 'no-gravity': the law was exported for the torque "
                                "convention 'full'"),
], ids=["missing joint", "extra joint", "order", "rate", "gain", "band", "limits", "hold",
        "command"])
def test_bad_parameters_refused_at_configure(package, changes, message):
    ex, robot, folder, _, drivers = package
    out, err = _drive(drivers["jazzy"], [*_params(folder, **changes), "init", "configure"])
    assert out == ["init SUCCESS", "configure ERROR"]
    assert message in err


def test_controller_manager_at_another_rate_refused(package):
    ex, robot, folder, _, drivers = package
    out, err = _drive(drivers["jazzy"], [*_params(folder), "init 500", "configure"])
    assert out == ["init SUCCESS", "configure ERROR"]
    assert "updates this controller at 500 Hz; the law was discretized for 1000 Hz" in err


def test_torque_limit_clips_and_counts(package):
    ex, robot, folder, _, drivers = package
    q = np.array([0.3, -0.5, 0.9])
    out, _ = _drive(drivers["jazzy"], [*_started(folder, torque_limit=[5.0, 5.0, 5.0]),
                                       "ref 3 1 1 1 0 0", f"update {TS!r} {_vec(q)} 0 0 0"])
    row = next(line for line in out if line.startswith("update ")).split()
    assert [float(v) for v in row[2:5]] == [5.0, 5.0, 5.0] and row[-3] == "1"


def test_deactivate_writes_zero(package):
    ex, robot, folder, _, drivers = package
    out, _ = _drive(drivers["jazzy"], [*_started(folder), f"update {TS!r} 0.3 0.2 0.1 0 0 0",
                                       "deactivate"])
    assert out[-1] == "deactivate SUCCESS 0 0 0"


#: The packages the ros2/CMakeLists.txt finds, each given by a stub config (ros2_stubs/cmake).
STUB_PACKAGES = ("ament_cmake", "controller_interface", "hardware_interface", "pluginlib",
                 "rclcpp", "rclcpp_lifecycle", "realtime_tools", "trajectory_msgs")


def _build_package(folder: Path, tmp_path: Path, name: str = PKG, env=None) -> Path:
    """Configure and build ``folder/ros2`` with the stub packages; return the build folder."""
    cmake = shutil.which("cmake")
    if cmake is None:
        pytest.skip("no cmake")
    stubs = [f"-D{pkg}_DIR={STUBS / 'cmake'}" for pkg in STUB_PACKAGES]
    build = tmp_path / "build"
    log = subprocess.run([cmake, "-S", str(folder / "ros2"), "-B", str(build), *stubs,
                          "-DCMAKE_CXX_FLAGS=-Werror"], capture_output=True, text=True,
                         check=True, env=env).stdout
    assert f"STUB pluginlib: controller_interface plugins in {name}.xml" in log
    done = subprocess.run([cmake, "--build", str(build)], capture_output=True, text=True,
                          check=False, env=env)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert (build / f"lib{name}.so").is_file()
    assert not (build / "rrr_pin_ctrl" / "ctrl_main").exists()  # EXCLUDE_FROM_ALL: not built
    return build


def test_package_cmake_builds_the_plugin_against_stub_packages(package, tmp_path):
    """The package's own CMakeLists (add_subdirectory(..), pluginlib export, install) builds."""
    _build_package(package[2], tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("arm", ["ur5", "panda"])
def test_arm_package_builds_without_a_python_environment(tmp_path, arm):
    """UR5, Panda with --command no-gravity: the package builds with PATH=/usr/bin:/bin.

    No Python environment on PATH or the library path, the stub workspace's packages only; the
    plugin links no Pinocchio (the arm's dynamics are generated C) and carries no RPATH.
    """
    import os

    robot = load_robot(arm)
    folder = tmp_path / arm
    ex = export_law("fl", robot, RATE, folder, command="no-gravity")
    write_ros2_package(ex, robot, folder)
    name = f"{arm}_fl_controller"
    env = {"PATH": "/usr/bin:/bin", "HOME": os.environ.get("HOME", "/tmp")}
    build = _build_package(folder, tmp_path, name, env=env)
    lib = build / f"lib{name}.so"
    needed = subprocess.run(["ldd", str(lib)], capture_output=True, text=True, check=True,
                            env=env).stdout
    assert "pinocchio" not in needed and "not found" not in needed
    dynamic = subprocess.run(["readelf", "-d", str(lib)], capture_output=True, text=True,
                             check=True, env=env).stdout
    assert "RPATH" not in dynamic and "RUNPATH" not in dynamic
    doc = yaml.safe_load((folder / "ros2" / "config" / f"{name}.yaml").read_text())
    assert doc[name]["ros__parameters"]["command"] == "no-gravity"
    # the plugin's update() (stub driver) against the C law and the Python law minus G
    objs = []
    for f in ("controller.c", "dynamics.c", "dyn_model.c"):
        obj = folder / (f + ".o")
        subprocess.run([CC, "-std=c99", "-O1", "-fPIC", "-ffp-contract=off", "-c",
                        str(folder / f), "-o", str(obj)], check=True, env=env)
        objs.append(str(obj))
    exe = folder / "drive"
    subprocess.run([CXX, "-std=c++17", *WARN, f"-DRRR_PIN_PACKAGE={name}", "-O1",
                    f"-I{STUBS}", f"-I{folder}", f"-I{folder / 'ros2' / 'include'}",
                    str(folder / "ros2" / "src" / "exported_law_controller.cpp"),
                    str(STUBS / "drive_controller.cpp"), *objs, "-o", str(exe), "-lm"],
                   check=True, env=env)
    lib = folder / "libdirect.so"
    subprocess.run([CC, "-shared", "-o", str(lib), *objs, "-lm"], check=True, env=env)
    c_law = exported_law(folder, lib)
    rng = np.random.default_rng(47)
    q0 = np.clip(robot.neutral(), robot.lower + 0.1, robot.upper - 0.1)  # inside the limits
    q = q0 + rng.uniform(-0.05, 0.05, robot.nq)
    qd = rng.uniform(-0.5, 0.5, robot.nq)
    # no clipping: the law's own torque (the arm's effort limits would clip FL's at 0.05 rad)
    out, _ = _drive(exe, [*_params(folder, torque_limit=[1e12] * robot.nq), "init", "configure",
                          f"activate {_vec(q0)} {_vec(np.zeros(robot.nq))}",
                          f"update {TS!r} {_vec(q)} {_vec(qd)}"])
    tau, fault, _ = _updates(out)
    assert fault == [NONE]
    # the reference held at q0 (activation), zero velocity and acceleration
    zero = np.zeros(robot.nq)
    tau_c, _ = c_law.step(0.0, q, qd, q0, zero, zero, np.zeros(0))
    assert_allclose(tau[0], tau_c, rtol=0, atol=0)  # the plugin runs the C law, bit for bit
    tau_py, _ = ex.law.step(0.0, q, qd, q0, zero, zero, np.zeros(0))
    G = pin.computeGeneralizedGravity(robot.model, robot.model.createData(), q)
    # generated C vs Pinocchio, torques of tens of N m: round-off far below 1e-12 relative
    assert_allclose(tau[0], tau_py - G, rtol=1e-12, atol=1e-12)


def test_cli_export_ros2(tmp_path, capsys):
    out = tmp_path / "c"
    assert main(["export", "--law", "pd", "--rate", "500", "--out", str(out), "--ros2"]) == 0
    assert "colcon build --paths" in capsys.readouterr().out
    doc = yaml.safe_load((out / "ros2" / "config" / "rrr_pd_controller.yaml").read_text())
    p = doc["rrr_pd_controller"]["ros__parameters"]
    assert p["rate_hz"] == 500.0 and len(p["kp"]) == 9 and "lam" not in p


def test_a_law_that_cannot_run_over_a_measured_period_is_refused(tmp_path, capsys):
    """zoh (a matrix exponential per period) or a discrete K as given: refused before writing."""
    import control

    from rrr_pin.control.laws import DiscreteTrackingController
    from rrr_pin.deploy.ros2 import ros2_package
    from rrr_pin.deploy.writer import ExportError, prepare_export

    out = tmp_path / "z"
    assert main(["export", "--law", "hinf", "--rate", "1000", "--method", "zoh", "--out",
                 str(out), "--ros2"]) == 2
    err = capsys.readouterr().err
    assert "--ros2: law 'hinf' can run its K at 1/rate only" in err
    assert "method 'zoh' is not one the C discretizes per period" in err
    assert not (out / "controller.c").exists()
    robot = load_robot("rrr")
    Kd = control.sample_system(control.ss(-10.0, 1.0, 5.0, 2.0), TS, method="tustin")
    prepared = prepare_export(DiscreteTrackingController(robot, 45.0, Kd), robot)
    with pytest.raises(ExportError, match=r"K is discrete as given; dt other than CTRL_PERIOD"):
        ros2_package(prepared, robot)


#: The functions update() runs (the real-time thread): none may log or allocate.
REAL_TIME = ("update", "latch", "safe_torque", "write_command")

#: What logs or may allocate, as written in C++ source.
FORBIDDEN = ("RCLCPP_", "new ", "malloc", "std::string", "std::vector", "push_back",
             "emplace_back", "resize", "make_shared", "std::to_string", "get_logger")


def _body(text: str, name: str) -> str:
    """The body of ``ExportedLawController::name`` in the generated .cpp (braces matched)."""
    start = text.index(f"ExportedLawController::{name}(")
    i = text.index("{", text.index(")", start))
    depth = 0
    for j in range(i, len(text)):
        depth += {"{": 1, "}": -1}.get(text[j], 0)
        if depth == 0:
            return text[i:j + 1]
    raise AssertionError(f"unbalanced braces in {name}")


def test_update_neither_logs_nor_allocates(package):
    """Scan the real-time path's source (the allocation counter of the stub runs it too)."""
    folder = package[2]
    text = (folder / "ros2" / "src" / "exported_law_controller.cpp").read_text()
    for name in REAL_TIME:
        body = _body(text, name)
        found = [word for word in FORBIDDEN if word in body]
        assert not found, f"{name}() uses {found}"


@pytest.mark.parametrize("bad", ["Ur5_controller", "ur5__fl", "1arm", "ur5-fl", "ur5_", "a",
                                 "namespace"])
def test_a_package_name_that_is_not_a_ros_name_is_refused(package, tmp_path, capsys, bad):
    from rrr_pin.validation import FieldError

    ex, robot, _, _, _ = package
    with pytest.raises(FieldError, match=r"ros2_name = "):
        write_ros2_package(ex, robot, tmp_path, name=bad)
    assert main(["export", "--law", "pd", "--rate", "1000", "--ros2", "--ros2-name", bad,
                 "--out", str(tmp_path / "cli")]) == 2
    err = capsys.readouterr().err
    assert "--ros2-name" in err and "Traceback" not in err
    assert not (tmp_path / "cli" / "controller.c").exists()


def test_default_names_and_maintainer(package, tmp_path):
    from rrr_pin.deploy.ros2 import package_name, ros2_package
    from rrr_pin.validation import FieldError

    # two exports of one arm with two laws do not collide; any arm name becomes a ROS name
    assert package_name("ur5", "hinf") == "ur5_hinf_controller"
    assert package_name("UR5e-left", "hinf") == "ur5e_left_hinf_controller"
    assert package_name("7dof", "fl") == "arm_7dof_fl_controller"
    ex, robot, _, _, _ = package
    files = ros2_package(ex, robot, maintainer="Ada Lovelace <ada@example.org>")
    xml = files["ros2/package.xml"]
    assert '<maintainer email="ada@example.org">Ada Lovelace</maintainer>' in xml
    assert "if(OFF)" in files["ros2/CMakeLists.txt"]  # a real maintainer: releasable
    with pytest.raises(FieldError, match=r"maintainer = 'ada'"):
        ros2_package(ex, robot, maintainer="ada")


def test_cleanup_and_error_return_to_unconfigured(package):
    """on_cleanup drops the configuration (configure works again); on_error writes zero effort
    and says why, from a non-real-time transition."""
    ex, robot, folder, _, drivers = package
    q = np.array([0.1, -0.4, 0.7])
    lines = [*_started(folder), f"update {TS!r} {_vec(q)} 0 0 0", "deactivate", "cleanup",
             "configure", f"activate {_vec(q)} {_vec(np.zeros(3))}",
             f"update {TS!r} {_vec(q)} 0 0 0", f"update {1.5 * TS!r} {_vec(q)} 0 0 0",
             "error"]
    out, err = _drive(drivers["jazzy"], lines)
    assert "cleanup SUCCESS" in out and out.count("configure SUCCESS") == 2
    assert out[-1] == "error SUCCESS"
    assert "transition failed: zero effort" in err and "latched fault: update period" in err


def test_launch_file_and_ros2_control_block(package):
    """The example launch file is Python that compiles and names the package's own files; the
    <ros2_control> block gives each exported joint, in order, effort in, position and velocity
    out (what command_interface_configuration and state_interface_configuration ask for)."""
    import xml.etree.ElementTree as ET

    ex, robot, folder, _, _ = package
    launch = (folder / "ros2" / "launch" / f"{PKG}.launch.py").read_text()
    compile(launch, "launch.py", "exec")  # syntax only: launch_ros is not installed here
    assert f'FindPackageShare("{PKG}"), "config", "{PKG}.yaml"' in launch
    block = ET.parse(folder / "ros2" / "config" / "ros2_control.xml").getroot()
    joints = block.findall("joint")
    assert [j.get("name") for j in joints] == list(robot.joint_names)
    for j in joints:
        assert [c.get("name") for c in j.findall("command_interface")] == ["effort"]
        assert [c.get("name") for c in j.findall("state_interface")] == ["position", "velocity"]
    xml = (folder / "ros2" / "package.xml").read_text()
    assert "<exec_depend>controller_manager</exec_depend>" in xml
    for path in [*(folder / "ros2").glob("*.xml"), *(folder / "ros2" / "config").glob("*.xml")]:
        ET.parse(path)  # well-formed (a "--" inside a comment is not: it was, before)
