"""rrr_pin.export: the built-in laws as C code, checked against the Python laws (issue 19).

The default run compiles ONE folder (H-infinity + FL on the RRR, generated dynamics) with the
system C compiler, directly (about 1 s); the CMake builds of every built-in law on the RRR and
on UR5 (Pinocchio C++, about a minute each) are marked slow.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin import (
    ControlLaw,
    QuinticReference,
    Robot,
    exported_law,
    fl_controller,
    hinf_fl_controller,
    load_robot,
    ncfsyn,
    pd_controller,
    sample_plants,
    simulate,
)
from rrr_pin import export as export_law
from rrr_pin.cli import main
from rrr_pin.deploy.loaded import build
from rrr_pin.deploy.writer import ExportError, prepare_export
from rrr_pin.model.dynamics import robot_from_xml
from rrr_pin.model.robots import nominal_params
from rrr_pin.outputs import OutputNotEmpty
from rrr_pin.robust.loopshaping import fl_plant, lag_weight
from rrr_pin.validation import FieldError

CC = shutil.which("cc")
CXX = shutil.which("c++")
RATE = 1000.0
WARN = ["-Wall", "-Wextra", "-Werror"]


def _compile_shared(folder: Path) -> Path:
    """The folder's C sources as objects (C99, no warning allowed) and a shared library."""
    objs = []
    for f in ("controller.c", "dynamics.c", "codegen_rrr.c"):
        obj = folder / (f + ".o")
        subprocess.run([CC, "-std=c99", "-pedantic", *WARN, "-O2", "-fPIC", "-c",
                        str(folder / f), "-o", str(obj)], check=True, capture_output=True,
                       text=True)
        objs.append(str(obj))
    lib = folder / "libdirect.so"
    subprocess.run([CC, "-shared", "-o", str(lib), *objs, "-lm"], check=True)
    return lib


def _uncertain(robot, seed: int):
    """One uncertain plant of ``robot`` (20 % inertias, 5 % lengths), as a Robot."""
    params = nominal_params(robot)  # the RRR's DH set (fast); other arms: their URDF
    source = params if params is not None else robot.urdf
    return robot_from_xml(sample_plants(source, 1, seed)[0].urdf, name="uncertain")


def _reference(robot):
    q0 = np.clip(robot.neutral(), robot.lower, robot.upper)
    return QuinticReference(q0, q0 + 0.3, 0.5)


def _random_steps(twin, c_law, count: int, seed: int, normwise: bool = False):
    """Worst relative difference of tau and x_next between the Python and the C step.

    Entry by entry, or ``normwise`` (max |a - b| / max |a| per vector: hinf_aw's state update
    ``A x + B e + L dy`` cancels, so its small entries carry the round-off of the large ones).
    """
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(count):
        q, qd, r, rd, rdd = (rng.uniform(-3.0, 3.0, twin.n) for _ in range(5))
        x = rng.standard_normal(twin.nx)
        tau_py, x_py = twin.step(0.0, q, qd, r, rd, rdd, x)
        tau_c, x_c = c_law.step(0.0, q, qd, r, rd, rdd, x)
        for a, b in ((tau_py, tau_c), (x_py, x_c)):
            if a.size:
                scale = np.abs(a).max() if normwise else np.abs(a)
                worst = max(worst, float(np.max(np.abs(a - b) / scale)))
    return worst


@pytest.fixture(scope="module")
def rrr():
    return load_robot("rrr")


@pytest.fixture(scope="module")
def hinf_rrr(rrr, tmp_path_factory):
    """The paper's H-infinity + FL on the RRR at 1 kHz, exported and compiled directly."""
    if CC is None:
        pytest.skip("no C compiler")
    folder = tmp_path_factory.mktemp("export") / "hinf"
    ex = export_law("hinf", rrr, RATE, folder)
    return ex, folder, _compile_shared(folder)


def test_rrr_export_compiles_and_steps_as_python(hinf_rrr):
    ex, folder, lib = hinf_rrr
    assert ex.dynamics == "generated" and ex.law.nx == 6
    c_law = exported_law(folder, lib)
    # 2000 random states, references and law states: the C transcription against the Python
    # law (CRBA/NLE by Pinocchio in Python, generated code in C): round-off, well inside 1e-12
    assert _random_steps(ex.law, c_law, 2000, seed=19) <= 1e-12


def test_rrr_closed_loop_equals_python(hinf_rrr, rrr):
    """Nominal plant and one uncertain plant: same trajectory as the Python law to 1e-12 rad."""
    ex, folder, lib = hinf_rrr
    c_law = exported_law(folder, lib)
    ref = _reference(rrr)
    plants = [rrr, _uncertain(rrr, 3)]
    for plant in plants:
        a = simulate(plant, ex.law, ref, 0.5)
        b = simulate(plant, c_law, ref, 0.5)
        assert b.info["engine"] == "python"
        assert_allclose(b.q, a.q, rtol=0, atol=1e-12)


def test_export_is_deterministic(rrr, tmp_path):
    a = export_law("fl", rrr, RATE, tmp_path / "a")
    b = export_law("fl", rrr, RATE, tmp_path / "b")
    assert list(a.files) == list(b.files)
    for name in a.files:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


def test_controller_json_records_the_design(hinf_rrr):
    import json

    ex, folder, _ = hinf_rrr
    record = json.loads((folder / "controller.json").read_text())
    form = ex.form
    assert_allclose(np.array(record["law"]["A"]), form.A, rtol=0, atol=0)  # repr round-trips
    assert record["law"]["Ts"] == 1.0 / RATE and record["law"]["method"] == "tustin"
    assert record["rate_hz"] == RATE and record["law"]["lam"] == 45.0
    assert record["design"]["gamma"] > 1.0 and record["design"]["emax"] > 0.0
    assert record["model"]["fingerprint"] == ex.record["model"]["fingerprint"]


# --- bad input -----------------------------------------------------------------------------

def test_continuous_law_without_rate(rrr):
    with pytest.raises(FieldError, match="law 'fl' is continuous-time.*give rate"):
        prepare_export(fl_controller(rrr), rrr, None)


@pytest.fixture(scope="module")
def hinf_quick(rrr):
    """H-infinity + FL with the full-order synthesis of one joint (no reduction: fast)."""
    return hinf_fl_controller(rrr, ncfsyn(fl_plant(45.0, 1), lag_weight()).K)


def test_prewarp_above_nyquist(rrr, hinf_quick):
    with pytest.raises(FieldError, match=r"prewarp = 400 rad/s is at or above the Nyquist "
                                         r"frequency pi \* rate = 314.159"):
        prepare_export(hinf_quick, rrr, 100.0, prewarp=400.0)


def test_prewarp_below_nyquist_is_used(rrr, hinf_quick):
    """The prewarped Tustin map of python-control, recorded (scipy's gbt as reference)."""
    import scipy.signal

    ex = prepare_export(hinf_quick, rrr, 100.0, prewarp=200.0)
    assert ex.record["law"]["prewarp_rad_s"] == 200.0
    A, B, C, D = hinf_quick.continuous_matrices()
    # prewarped bilinear = plain bilinear at the stretched period 2 tan(w Ts / 2) / w
    Ts = 0.01
    Tw = 2.0 * np.tan(200.0 * Ts / 2.0) / 200.0
    Ad, *_ = scipy.signal.cont2discrete((A, B, C, D), Tw, method="bilinear")
    assert_allclose(ex.form.A, Ad, rtol=1e-10, atol=1e-12)


def test_k_unstable_after_discretization(rrr, hinf_quick):
    with pytest.raises(FieldError, match=r"discretized by 'euler' at rate = 20 Hz is unstable"):
        prepare_export(hinf_quick, rrr, 20.0, method="euler")


def test_non_empty_out_without_overwrite(rrr, tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(OutputNotEmpty, match="is not empty"):
        export_law("pd", rrr, RATE, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_user_law_refused_with_what_to_declare(rrr):
    class Mine(ControlLaw):
        name, n = "mine", 3

        def torque(self, t, q, qd, r, rd, rdd, x):
            return -q

    with pytest.raises(ExportError, match="must declare, by compiled_form\\(\\), an FLForm"):
        prepare_export(Mine(), rrr, RATE)


def test_law_of_another_model_refused(rrr):
    other = _uncertain(rrr, 1)
    with pytest.raises(ExportError, match="build the law on the robot it is exported for"):
        prepare_export(pd_controller(other), rrr, RATE)


def test_unexpressible_joint(rrr):
    model = pin.Model()
    model.addJoint(0, pin.JointModelTranslation(), pin.SE3.Identity(), "slide3")
    robot = Robot(model, model.createData(), "slide3", "<test>", "")
    with pytest.raises(ExportError, match="joint 'slide3' is a JointModelTranslation"):
        prepare_export("pd", robot, RATE)


def test_cli_export_and_refusals(tmp_path, capsys):
    out = tmp_path / "c"
    assert main(["export", "--law", "pd", "--out", str(out)]) == 2
    assert "give --rate" in capsys.readouterr().err
    assert main(["export", "--law", "pd", "--rate", "500", "--out", str(out)]) == 0
    assert "#define CTRL_RATE_HZ 500.0" in (out / "controller.h").read_text()
    assert main(["export", "--law", "pd", "--rate", "500", "--out", str(out)]) == 2
    assert "pass --overwrite" in capsys.readouterr().err
    assert main(["export", "--law", "fl", "--rate", "500", "--out", str(out),
                 "--overwrite"]) == 0
    (tmp_path / "file").write_text("x")
    assert main(["export", "--law", "pd", "--rate", "500", "--out", str(tmp_path / "file")]) == 2
    assert "exists and is not a folder" in capsys.readouterr().err
    urdf = tmp_path / "planar.urdf"
    text = (Path(__file__).resolve().parents[1] / "urdf" / "rrr.urdf").read_text()
    urdf.write_text(text.replace('type="revolute"', 'type="planar"', 1))
    assert main(["export", "--robot", str(urdf), "--law", "pd", "--rate", "500", "--out",
                 str(tmp_path / "d")]) == 2
    assert "revolute and prismatic joints only" in capsys.readouterr().err


def test_continuous_joint_exports_as_one_angle(tmp_path):
    """A URDF ``continuous`` joint: Pinocchio's own parser gives it (cos, sin), nq 2 and nv 1;
    the loader makes it an unbounded revolute (one angle), which the C API expresses. The
    loaded model's M and h equal Pinocchio's native (cos, sin) model at random states
    (round-off: 1e-12), and the exported C law steps as the Python law (1e-12)."""
    if CC is None:
        pytest.skip("no C compiler")
    text = (Path(__file__).resolve().parents[1] / "urdf" / "rrr.urdf").read_text()
    urdf = tmp_path / "rrr_continuous.urdf"
    urdf.write_text(text.replace('type="revolute"', 'type="continuous"', 1))
    robot = load_robot(str(urdf))
    assert (robot.nq, robot.model.nv) == (3, 3) and np.isinf(robot.upper[0])
    native = pin.buildModelFromXML(urdf.read_text())
    assert (native.nq, native.nv) == (4, 3)  # JointModelRUBZ: (cos q1, sin q1)
    native.gravity = robot.model.gravity  # the loader sets standard gravity, 9.80665
    nd, rng = native.createData(), np.random.default_rng(31)
    for _ in range(20):
        q, qd = rng.uniform(-4.0, 4.0, 3), rng.uniform(-3.0, 3.0, 3)
        qn = np.concatenate([[np.cos(q[0]), np.sin(q[0])], q[1:]])
        M, h = robot.terms(q, qd)
        assert_allclose(M, pin.crba(native, nd, qn), rtol=0, atol=1e-12)
        assert_allclose(h, pin.rnea(native, nd, qn, qd, np.zeros(3)), rtol=0, atol=1e-12)
    ex = export_law("fl", robot, RATE, tmp_path / "fl")
    c_law = exported_law(tmp_path / "fl", _compile_shared(tmp_path / "fl"))
    assert _random_steps(ex.law, c_law, 200, seed=31) <= 1e-12
    # a model that keeps the (cos, sin) pair is refused by name, not exported
    kept = Robot(native, native.createData(), "native", str(urdf), urdf.read_text())
    with pytest.raises(ExportError, match="nq = 4 != nv = 3"):
        prepare_export("pd", kept, RATE)


# --- slow: CMake builds of every built-in law, RRR and UR5 ----------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("robot_name", ["rrr", "ur5"])
@pytest.mark.parametrize("law", ["fl", "hinf", "hinf_aw", "pd"])
def test_cmake_build_every_law(robot_name, law, tmp_path):
    """CMake build without warnings; steps and closed loops (nominal, uncertain) as Python."""
    if shutil.which("cmake") is None:
        pytest.skip("no cmake")
    robot = load_robot(robot_name)
    # UR5 on the Pinocchio C++ path (its chain exports generated C by default: test_ros2_package)
    ex = export_law(law, robot, RATE, tmp_path / law,
                    dynamics="pinocchio" if robot_name == "ur5" else "auto")
    lib = build(tmp_path / law)
    compile_log = (lib.parent / "build.log").read_text().split(" --build ", 1)[1]
    assert "warning" not in compile_log.lower()  # the compilers' -Wall -Wextra
    c_law = exported_law(tmp_path / law, lib)
    assert _random_steps(ex.law, c_law, 2000, seed=7, normwise=law == "hinf_aw") <= 1e-12
    ref = _reference(robot)
    for plant in (robot, _uncertain(robot, 5)):
        a = simulate(plant, ex.law, ref, 0.3)
        b = simulate(plant, c_law, ref, 0.3)
        assert_allclose(b.q, a.q, rtol=0, atol=1e-12)
    main_exe = tmp_path / law / "build" / "ctrl_main"
    assert "holding q0" in subprocess.run([str(main_exe)], check=True, capture_output=True,
                                          text=True).stdout


def test_discrete_k_exported_as_given(rrr, hinf_quick):
    import control

    Kd = control.c2d(hinf_quick.K[0, 0], 1.0 / 500.0, "zoh")
    law = hinf_fl_controller(rrr, Kd)
    ex = prepare_export(law, rrr, None)
    assert ex.rate == 500.0 and ex.record["law"]["K_source"] == "discrete K as given"
    assert ex.record["law"]["method"] is None
    # the SISO K copied on the diagonal, as given (scipy's block_diag as the reference)
    import scipy.linalg

    assert_allclose(ex.form.A, scipy.linalg.block_diag(*[np.asarray(Kd.A)] * 3), rtol=0, atol=0)
    with pytest.raises(FieldError, match="law 'hinf' is sampled at 500 Hz; rate = 1000.0"):
        prepare_export(law, rrr, 1000.0)


def test_exported_law_needs_a_built_library(rrr, tmp_path):
    export_law("pd", rrr, RATE, tmp_path / "pd")
    with pytest.raises(FileNotFoundError, match="build the folder first.*cmake -S"):
        exported_law(tmp_path / "pd")
    with pytest.raises(FileNotFoundError, match="holds no controller.json"):
        exported_law(tmp_path)


def test_ctrl_step_refuses_a_nan_input(hinf_rrr):
    ex, folder, lib = hinf_rrr
    c_law = exported_law(folder, lib)
    x = np.arange(c_law.nx, dtype=float)
    q = np.array([0.1, np.nan, 0.2])
    tau, x_next = c_law.step(0.0, q, np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), x)
    assert np.all(np.isnan(tau))  # CTRL_EINPUT: nothing computed
    assert_allclose(x_next, x, rtol=0, atol=0)  # the state is left untouched


# --- hinf_aw (issue 20: "exportable where the export issue applies") ------------------------

#: The torque limits of issue 20, about 10 % below the paper's reference peak [N m].
AW_LIMIT = (150.0, 270.0, 45.0)


def test_antiwindup_export_steps_and_runs_as_python(rrr, tmp_path):
    """hinf_aw exported: the clip and Hanus's correction in C equal the Python law's step."""
    if CC is None:
        pytest.skip("no C compiler")
    from rrr_pin.control.effects import PlantEffects
    from rrr_pin.control.laws import FLAWForm, hinf_aw_controller
    from rrr_pin.robust.loopshaping import design

    law = hinf_aw_controller(rrr, design(lam=45.0, n=3).K_reduced, torque_limit=AW_LIMIT)
    ex = export_law(law, rrr, RATE, tmp_path / "aw")
    assert type(ex.form) is FLAWForm and ex.record["law"]["kind"] == "fl_aw"
    assert ex.record["law"]["torque_limit_Nm"] == list(AW_LIMIT)
    lib = _compile_shared(tmp_path / "aw")  # -std=c99 -pedantic -Wall -Wextra -Werror
    c_law = exported_law(tmp_path / "aw", lib)
    # random states in +-3 rad(/s): nearly every step clips, so the LU solve and the
    # correction L (y_hat - y) are exercised; C (Gaussian elimination, generated dynamics)
    # against numpy.linalg.solve on Pinocchio's CRBA: round-off only
    rng = np.random.default_rng(23)
    clipped = 0
    for _ in range(2000):
        q, qd, r, rd, rdd = (rng.uniform(-3.0, 3.0, 3) for _ in range(5))
        x = rng.standard_normal(ex.law.nx)
        tau_py, x_py = ex.law.step(0.0, q, qd, r, rd, rdd, x)
        tau_c, x_c = c_law.step(0.0, q, qd, r, rd, rdd, x)
        clipped += bool(np.any(np.abs(tau_py) == np.asarray(AW_LIMIT)))
        assert_allclose(tau_c, tau_py, rtol=1e-12, atol=0)
        assert_allclose(x_c, x_py, rtol=1e-12, atol=1e-12 * np.abs(x_py).max())
    assert clipped > 1500
    # closed loop under the same limits on the plant: the C law runs as the Python law
    ref = _reference(rrr)
    fx = PlantEffects(torque_limit=AW_LIMIT)
    a = simulate(rrr, ex.law, ref, 0.5, effects=fx)
    b = simulate(rrr, c_law, ref, 0.5, effects=fx)
    assert_allclose(b.q, a.q, rtol=0, atol=1e-12)


def test_antiwindup_export_refuses_a_prewarp(rrr):
    from rrr_pin.control.laws import hinf_aw_controller
    from rrr_pin.robust.loopshaping import design

    law = hinf_aw_controller(rrr, design(lam=45.0, n=3).K_reduced, torque_limit=AW_LIMIT)
    with pytest.raises(FieldError, match="prewarp.*TrackingController"):
        prepare_export(law, rrr, RATE, prewarp=100.0)


def test_cli_export_refuses_a_rate_its_sampled_loop_cannot_hold(tmp_path, capsys, rrr):
    # Before: `export --law fl --rate 1` wrote the folder without a word (issue 31).
    from rrr_pin.control.catalog import make_law
    from rrr_pin.control.references import study_reference
    from rrr_pin.sim.simulation import simulate
    from rrr_pin.sim.trajectory import SimulationDiverged

    assert main(["export", "--law", "fl", "--rate", "1", "--out", str(tmp_path / "e")]) == 2
    err = capsys.readouterr().err
    assert "--rate 1 Hz: the sampled loop of 'fl' is unstable there" in err
    assert "it is stable from about 100 Hz" in err
    assert not (tmp_path / "e" / "controller.c").exists()
    # independent of the linear loop: the nonlinear simulation of the nominal arm diverges
    # below the stated rate and tracks above it
    law = make_law("fl", rrr)
    ref = study_reference(rrr, 1.0)
    with pytest.raises(SimulationDiverged):
        simulate(rrr, law, ref, 1.0, rate=90.0, engine="python")
    assert np.max(np.abs(simulate(rrr, law, ref, 1.0, rate=110.0).error)) < 0.1
