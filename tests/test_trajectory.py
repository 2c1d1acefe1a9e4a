"""Trajectory files: save -> load round trips in every format, and refusals."""

import csv
import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.control.laws import fl_controller
from rrr_pin.control.references import default_reference
from rrr_pin.sim.simulation import simulate
from rrr_pin.sim.trajectory import FORMATS, Trajectory, TrajectoryFileError

ARRAYS = ("t", "q", "qd", "r", "tau")


@pytest.fixture(scope="module")
def simulated(rrr):
    robot = rrr
    return simulate(robot, fl_controller(robot), default_reference(robot), 0.05, dt=1e-3,
                    rate=1000.0, engine="python")


def _by_hand():
    """Two joints, one prismatic, a name with a comma and a space, seeded random values."""
    rng = np.random.default_rng(7)
    N = 9
    return Trajectory(t=np.linspace(0.0, 0.8, N), q=rng.normal(size=(N, 2)),
                      qd=rng.normal(size=(N, 2)) * 1e-17, r=rng.normal(size=(N, 2)) * 1e12,
                      tau=rng.normal(size=(N, 2)), controller="mine", plant="bench",
                      info={"dt": np.float64(1e-3), "grid": (1, 2), "limit": np.inf},
                      joint_names=["shoulder, left", "slide z"], joint_units=["rad", "m"])


@pytest.mark.parametrize("suffix", FORMATS, ids=[s[1:] for s in FORMATS])
@pytest.mark.parametrize("make", ["simulated", "by_hand"])
def test_round_trip_is_exact(tmp_path, suffix, make, simulated):
    traj = simulated if make == "simulated" else _by_hand()
    path = traj.save(tmp_path / f"run{suffix}")
    back = Trajectory.load(path)
    for key in ARRAYS:
        # rtol = atol = 0: every format keeps float64 bit for bit (CSV writes repr(float), the
        # shortest text that parses back to the same double).
        assert_allclose(getattr(back, key), getattr(traj, key), rtol=0, atol=0)
        assert getattr(back, key).shape == np.shape(getattr(traj, key))
    assert (back.controller, back.plant) == (traj.controller, traj.plant)
    assert back.joint_names == traj.joint_names
    assert back.joint_units == traj.joint_units
    # info is stored as JSON: compare with its JSON image (tuples -> lists, numpy -> float)
    assert back.info == json.loads(json.dumps(traj.info, default=float))


def test_simulated_trajectory_names_its_joints(simulated, rrr):
    assert simulated.joint_names == rrr.joint_names
    assert simulated.joint_units == ["rad"] * rrr.nq


def test_csv_layout_has_units_and_metadata(tmp_path):
    path = _by_hand().save(tmp_path / "run.csv")
    lines = path.read_text().splitlines()
    preamble = [line for line in lines if line.startswith("# ")]
    meta = {k: json.loads(v) for k, _, v in (line[2:].partition(": ") for line in preamble)}
    assert meta["format"] == "rrr-pin trajectory" and meta["version"] == 1
    assert meta["units"]["tau"] == ["N m", "N"]
    header = next(csv.reader([lines[len(preamble)]]))
    assert header == ["t [s]", "q_shoulder, left [rad]", "q_slide z [m]",
                      "qd_shoulder, left [rad/s]", "qd_slide z [m/s]",
                      "r_shoulder, left [rad]", "r_slide z [m]",
                      "tau_shoulder, left [N m]", "tau_slide z [N]"]


def test_parquet_schema_carries_units(tmp_path):
    import pyarrow.parquet as pq

    schema = pq.read_schema(_by_hand().save(tmp_path / "run.parquet"))
    assert schema.field("tau_slide z [N]").metadata == {b"unit": b"N"}
    assert json.loads(schema.metadata[b"rrr_pin"])["joint_names"][1] == "slide z"


def test_npz_reads_without_pickle(tmp_path):
    path = _by_hand().save(tmp_path / "run.npz")
    with np.load(path, allow_pickle=False) as data:
        assert json.loads(data["metadata"].item())["controller"] == "mine"


@pytest.mark.parametrize("name", ["run.h5", "run.txt", "run"])
def test_unknown_suffix_is_refused(tmp_path, name):
    with pytest.raises(ValueError, match=r"unknown trajectory format.*\.csv, \.npz, \.parquet"):
        _by_hand().save(tmp_path / name)
    with pytest.raises(ValueError, match="unknown trajectory format"):
        Trajectory.load(tmp_path / name)


def test_foreign_files_are_refused(tmp_path):
    plain = tmp_path / "plain.csv"
    plain.write_text("a,b\n1,2\n")
    with pytest.raises(TrajectoryFileError, match="not an rrr-pin trajectory"):
        Trajectory.load(plain)
    npz = tmp_path / "plain.npz"
    np.savez(npz, t=np.zeros(3))
    with pytest.raises(TrajectoryFileError, match="no 'metadata' entry"):
        Trajectory.load(npz)
    newer = tmp_path / "newer.csv"
    _by_hand().save(newer)
    newer.write_text(newer.read_text().replace("# version: 1", "# version: 2"))
    with pytest.raises(TrajectoryFileError, match="version 2"):
        Trajectory.load(newer)
    with pytest.raises(FileNotFoundError, match="not found"):
        Trajectory.load(tmp_path / "absent.npz")


def test_truncated_csv_row_is_refused(tmp_path):
    path = _by_hand().save(tmp_path / "run.csv")
    text = path.read_text().rstrip("\n")
    path.write_text(text[:text.rfind(",")] + "\n")  # drop the last value of the last row
    with pytest.raises(TrajectoryFileError, match=str(path.name)):
        Trajectory.load(path)


def _reordered(order):
    """``_by_hand()`` with its rows taken in ``order`` (time and every array alike)."""
    traj = _by_hand()
    return Trajectory(**{k: getattr(traj, k)[order] for k in ARRAYS},
                      controller=traj.controller, plant=traj.plant, info=traj.info,
                      joint_names=traj.joint_names, joint_units=traj.joint_units)


@pytest.mark.parametrize("suffix", FORMATS, ids=[s[1:] for s in FORMATS])
@pytest.mark.parametrize("order, why", [
    (np.arange(9)[::-1], r"runs backwards at rows 0 and 1"),
    (np.array([0, 1, 2, 4, 3, 5, 6, 7, 8]), r"decreases \(rows out of order\?\) at rows 3 and 4"),
    (np.array([0, 1, 2, 3, 3, 5, 6, 7, 8]), r"repeats at rows 3 and 4"),
], ids=["backwards", "swapped", "repeated"])
def test_time_out_of_order_is_refused(tmp_path, suffix, order, why):
    path = _reordered(order).save(tmp_path / f"run{suffix}")
    with pytest.raises(TrajectoryFileError, match=rf"run\{suffix}: time t {why}"):
        Trajectory.load(path)


def test_non_finite_time_is_refused(tmp_path):
    traj = _by_hand()
    traj.t = traj.t.copy()
    traj.t[2] = np.nan
    path = traj.save(tmp_path / "run.npz")
    with pytest.raises(TrajectoryFileError, match=r"run\.npz: t\[2\] = nan s is not finite"):
        Trajectory.load(path)


@pytest.mark.parametrize("suffix", FORMATS, ids=[s[1:] for s in FORMATS])
def test_non_finite_samples_are_refused(tmp_path, suffix):
    # issue 50's probe: a .mat whose q held inf was accepted; a run that diverges raises
    # instead of saving, so a saved run with NaN or inf is damaged or edited.
    traj = _by_hand()
    traj.q = traj.q.copy()
    traj.q[3, 1] = np.inf
    path = traj.save(tmp_path / f"run{suffix}")
    with pytest.raises(TrajectoryFileError, match=rf"run\{suffix}: q\[3, 1\] = inf is not "
                                                  rf"finite \(t = "):
        Trajectory.load(path)


@pytest.mark.parametrize("suffix", FORMATS, ids=[s[1:] for s in FORMATS])
def test_damaged_files_are_refused_by_name(tmp_path, suffix):
    binary = tmp_path / f"binary{suffix}"
    binary.write_bytes(bytes(range(256)) * 4)  # not UTF-8, not a zip, not Parquet
    with pytest.raises(TrajectoryFileError, match=rf"binary\{suffix}: not a"):
        Trajectory.load(binary)
    whole = _by_hand().save(tmp_path / f"whole{suffix}").read_bytes()
    cut = tmp_path / f"cut{suffix}"
    cut.write_bytes(whole[:len(whole) // 2])
    damaged = {".csv": r"cut\.csv, line \d+: [1-8] values, the header has 9 \(a truncated",
               ".npz": r"cut\.npz: a truncated or damaged \.npz archive",
               ".parquet": r"cut\.parquet: not a readable Parquet file \(truncated",
               ".mat": r"cut\.mat: not a readable MAT file \(truncated"}[suffix]
    with pytest.raises(TrajectoryFileError, match=damaged):
        Trajectory.load(cut)
    folder = tmp_path / f"folder{suffix}"
    folder.mkdir()
    with pytest.raises(TrajectoryFileError, match=rf"folder\{suffix}: is a directory"):
        Trajectory.load(folder)


def test_mat_file_holds_matlab_variables(tmp_path):
    # What a MATLAB user gets from load('run.mat'): t as a column, q..tau as N x n, the
    # metadata as JSON text; read here with scipy.io.loadmat directly, not Trajectory.load.
    import scipy.io

    traj = _by_hand()
    data = scipy.io.loadmat(traj.save(tmp_path / "run.mat"))
    assert data["t"].shape == (9, 1)
    assert_allclose(data["t"][:, 0], traj.t, rtol=0, atol=0)
    for key in ("q", "qd", "r", "tau"):
        assert_allclose(data[key], getattr(traj, key), rtol=0, atol=0)
    meta = json.loads(str(data["metadata"][0]))
    assert meta["joint_names"] == ["shoulder, left", "slide z"]
    assert meta["units"]["tau"] == ["N m", "N"]


def test_repr_is_a_summary_not_the_arrays(simulated):
    text = repr(simulated)
    assert text.startswith("Trajectory(plant='rrr', controller='fl', ")
    assert f"{len(simulated.t)} samples over 0.05 s, 3 joints" in text
    assert f"max |error| {np.max(np.abs(simulated.error)):.4g}" in text
    assert "\n" not in text and "array(" not in text and len(text) < 200
