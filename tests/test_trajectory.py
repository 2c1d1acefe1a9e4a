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
