"""`export --command`: the drive's torque convention (issue 47, item 1) and armature (issue 44).

Each convention's exported C torque equals the Python law's minus the terms it names, computed
here independently (Pinocchio's ``computeGeneralizedGravity`` and the friction model written
out), at random states; the safe torque of a fault follows the convention. The RRR's exports
carry generated dynamics and are compiled directly with the system C compiler (well under a
second each); an export on an arm with armature goes through Pinocchio's C++ (CMake, slow).
"""

from __future__ import annotations

import ctypes
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin import export as export_law
from rrr_pin import exported_law, load_robot
from rrr_pin.cli import main
from rrr_pin.control.catalog import make_law
from rrr_pin.control.friction import JointFriction
from rrr_pin.deploy.command import COMMANDS, check_command
from rrr_pin.deploy.writer import prepare_export
from rrr_pin.validation import FieldError

CC = shutil.which("cc")
RATE = 1000.0
WARN = ["-Wall", "-Wextra", "-Werror"]
FRICTION = JointFriction(viscous=(0.3, 0.2, 0.1), coulomb=(0.5, 0.4, 0.2),
                         coulomb_velocity=0.05, source="test")

#: (law name, friction compensated, command) exported and compiled; every convention each
#: law can honour.
CASES = [("fl", False, "full"), ("fl", False, "no-gravity"),
         ("hinf", False, "no-gravity"), ("pd", False, "no-gravity"),
         ("hinf_aw", False, "no-gravity"),
         ("fl", True, "no-gravity"), ("fl", True, "no-gravity-no-friction"),
         ("hinf", True, "no-gravity-no-friction")]


def _object(folder: Path, f: str) -> str:
    obj = folder / (f + ".o")
    subprocess.run([CC, "-std=c99", "-pedantic", *WARN, "-O1", "-fPIC", "-c", str(folder / f),
                    "-o", str(obj)], check=True, capture_output=True, text=True)
    return str(obj)


def _compile(folder: Path, dynamics: list) -> Path:
    """The folder's controller.c linked with the RRR's dynamics objects (the same generated
    C in every RRR export, compiled once: the largest file)."""
    if not dynamics:
        dynamics += [_object(folder, f) for f in ("dynamics.c", "codegen_rrr.c")]
    lib = folder / "libdirect.so"
    subprocess.run([CC, "-shared", "-o", str(lib), _object(folder, "controller.c"), *dynamics,
                    "-lm"], check=True)
    return lib


def _law(name, friction, robot, paper):
    kwargs = {"friction": FRICTION} if friction else {}
    if name in ("hinf", "hinf_aw"):
        kwargs["K"] = paper.K_reduced  # the paper's design, lam = 45 rad/s (session fixture)
    return make_law(name, robot, **kwargs)


@pytest.fixture(scope="module")
def compiled(tmp_path_factory, rrr, paper):
    """Every case of :data:`CASES` on the RRR at 1 kHz, compiled directly."""
    if CC is None:
        pytest.skip("no C compiler")
    out, dynamics = {}, []
    for name, friction, command in CASES:
        folder = tmp_path_factory.mktemp(f"{name}-{friction}-{command}")
        ex = export_law(_law(name, friction, rrr, paper), rrr, RATE, folder, command=command,
                        overwrite=True)
        out[name, friction, command] = ex, exported_law(folder, _compile(folder, dynamics))
    return out


def _removed(robot, command, q, qd, friction):
    """The terms ``command`` names, written out here (not by rrr_pin.deploy.command)."""
    conv = COMMANDS[command]
    out = np.zeros(robot.nq)
    if conv.removes_gravity:
        out += pin.computeGeneralizedGravity(robot.model, robot.model.createData(), q)
    if conv.removes_friction and friction:
        fv, fc = np.array(FRICTION.viscous), np.array(FRICTION.coulomb)
        out += fv * qd + fc * np.tanh(qd / FRICTION.coulomb_velocity)
    return out


@pytest.mark.parametrize("case", CASES, ids=["-".join(map(str, c)) for c in CASES])
def test_command_is_the_law_minus_the_named_terms(compiled, rrr, case):
    ex, c_law = compiled[case]
    name, friction, command = case
    rng = np.random.default_rng(47)
    x_py = ex.law.initial_state()
    x_c = c_law.initial_state()
    for k in range(20):  # random states, the law's state carried through the steps
        # states a tracking law meets: errors of centiradians, speeds of 1 rad/s (random
        # errors of radians would ask for 1e5 N m, where one rounding exceeds 1e-12)
        q, qd, rdd = (rng.uniform(-1.5, 1.5, rrr.nq) for _ in range(3))
        r, rd = q + rng.uniform(-0.02, 0.02, rrr.nq), qd + rng.uniform(-0.05, 0.05, rrr.nq)
        tau_py, x_py = ex.law.step(k / RATE, q, qd, r, rd, rdd, x_py)
        tau_c, x_c = c_law.step(k / RATE, q, qd, r, rd, rdd, x_c)
        expected = tau_py - _removed(rrr, command, q, qd, friction)
        # the C law reproduces the Python law to rounding (test_export.py), and removing a term
        # adds one rounding: 1e-12 relative (hinf's high-frequency gain on random errors asks
        # for 1e4 N m, where one rounding is 2e-12 N m), 1e-12 N m absolute near zero
        assert_allclose(tau_c, expected, rtol=1e-12, atol=1e-12)
        assert_allclose(x_c, x_py, rtol=0, atol=1e-12)  # the law's state is the full torque's
    assert ex.record["command"]["name"] == command


@pytest.mark.parametrize("command", ["full", "no-gravity"])
def test_safe_torque_follows_the_convention(compiled, rrr, command):
    ex, c_law = compiled["fl", False, command]
    fn = c_law._lib.ctrl_safe_torque
    fn.argtypes = [ctypes.POINTER(ctypes.c_double)] * 2
    q = np.random.default_rng(3).uniform(-1, 1, rrr.nq)
    tau = np.full(rrr.nq, np.nan)
    fn(q.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
       tau.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
    G = pin.computeGeneralizedGravity(rrr.model, rrr.model.createData(), q)
    # full: gravity compensation of the nominal model (generated C vs Pinocchio: rounding);
    # no-gravity: the drive holds the arm, the safe command is exactly zero
    assert_allclose(tau, G if command == "full" else np.zeros(rrr.nq), rtol=0, atol=1e-12)


def test_conventions_the_law_cannot_honour(rrr):
    fl = make_law("fl", rrr)
    with pytest.raises(FieldError, match=r"command = 'no-gravity-no-friction'.*compensates no "
                                         r"friction"):
        prepare_export(fl, rrr, RATE, command="no-gravity-no-friction")
    with pytest.raises(FieldError, match=r"command = 'torque'.*not a torque convention"):
        prepare_export(fl, rrr, RATE, command="torque")
    flat = load_robot("rrr")
    flat.model.gravity.linear[:] = 0.0  # an arm moving in a horizontal plane
    with pytest.raises(FieldError, match=r"command = 'no-gravity'.*has no gravity"):
        check_command("no-gravity", make_law("fl", flat).sampled(RATE).compiled_form())


def test_cli_command_recorded_and_refused(tmp_path, capsys):
    out = tmp_path / "ng"
    assert main(["export", "--law", "pd", "--rate", "1000", "--command", "no-gravity",
                 "--out", str(out)]) == 0
    record = json.loads((out / "controller.json").read_text())
    assert record["command"]["name"] == "no-gravity" and record["command"]["removes_gravity"]
    assert '#define CTRL_COMMAND "no-gravity"' in (out / "controller.h").read_text()
    capsys.readouterr()
    assert main(["export", "--law", "fl", "--rate", "1000", "--command",
                 "no-gravity-no-friction", "--out", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err
    assert "--command" in err and "compensates no friction" in err and "Traceback" not in err


def test_dyngen_dynamics_carry_the_armature(tmp_path, rrr):
    """A chain of revolute joints exports generated C (no Pinocchio) with its armature.

    The RRR with an armature is no longer the model codegen_rrr.c was generated for (its
    fingerprint differs), so the export carries rrr_pin.sim.dyngen's C with the armature in its
    parameters; its torque equals the Python law's, whose M is Pinocchio's CRBA plus
    diag(armature), under ``no-gravity``.
    """
    if CC is None:
        pytest.skip("no C compiler")
    robot = load_robot("rrr")
    robot.model.armature[:] = (0.2, 0.1, 0.05)  # [kg m^2], larger than the links' own
    law = make_law("fl", robot)
    ex = export_law(law, robot, RATE, tmp_path / "arm", command="no-gravity")
    assert ex.dynamics == "dyngen"
    assert ex.record["model"]["parameters"]["armature"] == [0.2, 0.1, 0.05]
    objs = []
    for f in ("controller.c", "dynamics.c", "dyn_model.c"):
        obj = tmp_path / "arm" / (f + ".o")
        subprocess.run([CC, "-std=c99", "-pedantic", *WARN, "-Wno-unknown-pragmas",
                        "-ffp-contract=off", "-O0", "-fPIC", "-c", str(tmp_path / "arm" / f),
                        "-o", str(obj)], check=True, capture_output=True, text=True)
        objs.append(str(obj))
    lib = tmp_path / "arm" / "lib.so"
    subprocess.run([CC, "-shared", "-o", str(lib), *objs, "-lm"], check=True)
    c_law = exported_law(tmp_path / "arm", lib)
    rng = np.random.default_rng(44)
    data = robot.model.createData()
    for _ in range(10):
        q, qd, rdd = (rng.uniform(-1.5, 1.5, 3) for _ in range(3))
        r, rd = q + rng.uniform(-0.02, 0.02, 3), qd + rng.uniform(-0.05, 0.05, 3)
        tau_c, _ = c_law.step(0.0, q, qd, r, rd, rdd, np.zeros(0))
        # independent: FL's torque written out with CRBA + diag(armature) and RNEA - G
        M = pin.crba(robot.model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        assert_allclose(np.diag(M) - np.diag(pin.crba(load_robot("rrr").model,
                                                      load_robot("rrr").model.createData(), q)),
                        robot.model.armature, rtol=0, atol=1e-12)  # Pinocchio adds it
        lam = law.lam
        taubar = rdd + 2 * lam * (rd - qd) + lam ** 2 * (r - q)
        c_term = (pin.rnea(robot.model, data, q, qd, np.zeros(3))
                  - pin.computeGeneralizedGravity(robot.model, data, q))
        # two dynamics algorithms (generated recursion vs Pinocchio), torques of tens of N m:
        # rounding of a few 1e-15 relative
        assert_allclose(tau_c, M @ taubar + c_term, rtol=1e-12, atol=1e-12)
