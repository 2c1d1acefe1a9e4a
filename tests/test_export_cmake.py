"""Exported folders build with CMake alone and inside a user's project (issue 35).

Both ways a user builds an export: ``cmake -S folder -B build && cmake --build build``, and
``add_subdirectory(folder)`` from their own CMakeLists.txt. Run with ``PATH=/usr/bin:/bin``:
no activated virtual environment, no ``CMAKE_PREFIX_PATH``, so the folder must find the
Pinocchio of the install that exported it by itself (``RRR_PIN_PYTHON``, recorded at export).
Default run: the RRR (plain C) built both ways, and UR5 configured and generated under
``add_subdirectory`` (where "Target coal::coal not found" used to stop it). Slow: UR5 and Panda
(Pinocchio C++, tens of seconds each) built both ways, and their programs run.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rrr_pin import export as export_law
from rrr_pin import load_robot

_VENV_CMAKE = Path(sys.executable).parent / "cmake"
CMAKE = str(_VENV_CMAKE) if _VENV_CMAKE.is_file() else shutil.which("cmake")
pytestmark = pytest.mark.skipif(CMAKE is None or shutil.which("cc", path="/usr/bin:/bin") is None,
                                reason="no cmake or C compiler")

#: A user's program: one ctrl_step at the reference, its torque printed.
APP = r"""#include <stdio.h>
#include "controller.h"
int main(void)
{
    const double q[CTRL_NQ] = {0.0}, zero[CTRL_NQ] = {0.0};
    double tau[CTRL_NQ];
    ctrl_state s;
    int i, rc;
    ctrl_reset(&s);
    rc = ctrl_step(&s, q, zero, q, zero, zero, tau);
    for (i = 0; i < CTRL_NQ; ++i) printf("%.17g\n", tau[i]);
    return rc;
}
"""


def _cmake(*args, cwd=None):
    env = {**os.environ, "PATH": "/usr/bin:/bin"}  # as a user with no activated venv
    env.pop("CMAKE_PREFIX_PATH", None)
    env.pop("VIRTUAL_ENV", None)
    done = subprocess.run([CMAKE, *map(str, args)], capture_output=True, text=True, env=env,
                          cwd=cwd, check=False, timeout=1800)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return done.stdout


def _user_project(tmp_path: Path, folder: Path, cxx: bool) -> Path:
    """A user's CMake project that pulls the export in by add_subdirectory."""
    user = tmp_path / "user"
    user.mkdir()
    (user / "app.c").write_text(APP)
    (user / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.21)\n"
        f"project(user LANGUAGES C{' CXX' if cxx else ''})\n"
        f'add_subdirectory("{folder.as_posix()}" rrr_pin_ctrl)\n'
        "add_executable(app app.c)\n"
        "target_link_libraries(app PRIVATE rrr_pin_ctrl)\n"
        + ("set_target_properties(app PROPERTIES LINKER_LANGUAGE CXX)\n" if cxx else ""))
    return user


def _torque_at_rest(ex, robot) -> np.ndarray:
    n = robot.nq
    z = np.zeros(n)
    return ex.law.step(0.0, z, z, z, z, z, ex.law.initial_state())[0]


def _build_both_ways(robot_name: str, law: str, tmp_path: Path):
    robot = load_robot(robot_name)
    folder = tmp_path / "export"
    # the Pinocchio C++ path (a chain of RX/RY/RZ joints exports generated C by default)
    ex = export_law(law, robot, 1000.0, folder,
                    dynamics="generated" if robot_name == "rrr" else "pinocchio")
    _cmake("-S", folder, "-B", tmp_path / "plain")
    _cmake("--build", tmp_path / "plain")
    assert "holding q0" in subprocess.run([str(tmp_path / "plain" / "ctrl_main")],
                                          capture_output=True, text=True, check=True).stdout
    user = _user_project(tmp_path, folder, cxx=ex.dynamics == "pinocchio")
    _cmake("-S", user, "-B", tmp_path / "ub")
    _cmake("--build", tmp_path / "ub", "--target", "app")
    out = subprocess.run([str(tmp_path / "ub" / "app")], capture_output=True, text=True,
                         check=True).stdout
    tau = np.array([float(v) for v in out.split()])
    # the C law in the user's program against its Python twin: round-off
    np.testing.assert_allclose(tau, _torque_at_rest(ex, robot), rtol=1e-12, atol=1e-9)


def test_rrr_builds_alone_and_by_add_subdirectory(tmp_path):
    _build_both_ways("rrr", "hinf", tmp_path)


def test_ur5_configures_by_add_subdirectory_without_a_venv(tmp_path):
    """The Pinocchio CMake package found by the export's own CMakeLists, targets made global."""
    robot = load_robot("ur5")
    folder = tmp_path / "export"
    export_law("fl", robot, 1000.0, folder, dynamics="pinocchio")  # the Pinocchio C++ path
    text = (folder / "CMakeLists.txt").read_text()
    assert f'set(RRR_PIN_PYTHON "{Path(sys.executable).as_posix()}"' in text
    user = _user_project(tmp_path, folder, cxx=True)
    log = _cmake("-S", user, "-B", tmp_path / "ub")  # generate fails on a local coal::coal
    assert "rrr_pin_ctrl: cmeel prefix of" in log and "Generating done" in log


@pytest.mark.slow
@pytest.mark.parametrize("robot_name", ["ur5", "panda"])
def test_pinocchio_arms_build_both_ways(robot_name, tmp_path):
    _build_both_ways(robot_name, "fl", tmp_path)
