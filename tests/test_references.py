import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin.control.laws import pd_controller
from rrr_pin.control.references import (
    CirclePath,
    IKError,
    LinePath,
    QuinticReference,
    Reference,
    SineReference,
    SplineReference,
    checked_sample,
    task_space_reference,
)
from rrr_pin.model.dynamics import load_robot
from rrr_pin.sim.simulation import simulate


def _central_differences(ref, t, h=1e-5):
    R_p, RD_p, _ = ref.sample(t + h)
    R_m, RD_m, _ = ref.sample(t - h)
    return (R_p - R_m) / (2 * h), (RD_p - RD_m) / (2 * h)


@pytest.mark.parametrize("ref", [
    SineReference(home=[0.1, -0.2], amp=[0.5, 0.3], freq=[0.5, 2.0], phase=[0.0, 1.0]),
    QuinticReference([0.0, 1.0], [1.0, -0.5], 1.5),
    SplineReference([0.0, 0.5, 1.2, 2.0], [[0, 0], [0.4, -0.2], [0.1, 0.3], [0.5, 0.5]]),
], ids=["sine", "quintic", "spline"])
def test_derivatives_by_finite_differences(ref):
    t = np.array([0.05, 0.37, 0.9, 1.31])
    _, rd, rdd = ref.sample(t)
    fd_rd, fd_rdd = _central_differences(ref, t)
    # central differences: error O(h^2 * third derivative) ~ 1e-10 * 1e3 ~ 1e-7
    assert_allclose(fd_rd, rd, atol=1e-6)
    assert_allclose(fd_rdd, rdd, atol=1e-5)
    # The scalar call agrees with the vectorized sample.
    for k, tk in enumerate(t):
        for a, b in zip(ref(tk), (x[k] for x in ref.sample(t)), strict=True):
            assert_allclose(a, b, rtol=1e-14, atol=1e-14)


def test_quintic_meets_its_boundary_conditions():
    start, goal, T = np.array([0.2, -1.0, 0.5]), np.array([1.0, 0.0, -0.5]), 2.0
    ref = QuinticReference(start, goal, T)
    R, RD, RDD = ref.sample([0.0, T, T + 1.0])
    assert_allclose(R[0], start, atol=1e-15)
    assert_allclose(R[1], goal, atol=1e-15)
    assert_allclose(R[2], goal, atol=1e-15)  # at rest on the goal afterwards
    assert_allclose(RD, 0.0, atol=1e-15)
    assert_allclose(RDD, 0.0, atol=1e-15)
    # Midpoint: by symmetry of the rest-to-rest quintic, half way at T/2 with the peak speed
    # 15/8 (goal - start)/T (the quintic's maximum of ds/dt).
    Rm, RDm, _ = ref.sample([T / 2])
    assert_allclose(Rm[0], (start + goal) / 2, atol=1e-14)
    assert_allclose(RDm[0], 15 / 8 * (goal - start) / T, rtol=1e-13)


def test_spline_through_waypoints_c2_and_at_rest():
    times = np.array([0.0, 0.4, 1.0, 1.5, 2.2])
    W = np.array([[0, 0], [0.3, -0.1], [0.1, 0.4], [-0.2, 0.2], [0.0, 0.1]])
    ref = SplineReference(times, W)
    R, RD, _ = ref.sample(times)
    assert_allclose(R, W, atol=1e-14)
    assert_allclose(RD[[0, -1]], 0.0, atol=1e-14)  # clamped ends
    # C2: acceleration continuous across every inner knot (left and right limits agree).
    eps = 1e-9
    for tk in times[1:-1]:
        a_left = ref.sample([tk - eps])[2][0]
        a_right = ref.sample([tk + eps])[2][0]
        assert_allclose(a_left, a_right, atol=1e-6)


def test_csv_reference(tmp_path, rrr):
    path = tmp_path / "wp.csv"
    path.write_text("time,joint1,joint2,joint3\n0,0,0,0\n1,0.2,0.1,-0.1\n2,0.3,0.0,0.2\n")
    ref = SplineReference.from_csv(path, rrr)
    assert ref.n == 3 and ref.duration == 2.0
    assert_allclose(ref.positions([1.0])[0], [0.2, 0.1, -0.1], atol=1e-14)


@pytest.mark.parametrize("text,message", [
    ("0,0,0,0\n1,0,0,0\n1,0.1,0,0\n", "strictly increasing: row 2 has t = 1 s"),
    ("0,0,0,0\n1,nan,0,0\n", "must be finite: row 1"),
    ("0,0,0\n1,0,0\n", "row 1: 3 columns, expected 4"),
    ("0,0,0,0\n1,0,0,3.5\n", "joint 'joint3' = 3.5 rad is outside its limits"),
    ("0,0,0,0\n1,a,0,0\n", "not a number"),
    ("0,0,0,0\n", "at least 2 rows"),
], ids=["time", "nan", "columns", "limits", "text", "one-row"])
def test_csv_bad_input(tmp_path, rrr, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        SplineReference.from_csv(path, rrr)


def _fk(robot, frame, q):
    fid = robot.model.getFrameId(frame)
    pin.framesForwardKinematics(robot.model, robot.data, q)
    return robot.data.oMf[fid].translation.copy()


@pytest.mark.parametrize("robot_name,frame", [("rrr", None), ("ur5", "tool0")])
@pytest.mark.parametrize("kind", ["line", "circle"])
def test_task_space_path_reproduced_by_forward_kinematics(robot_name, frame, kind):
    robot = load_robot(robot_name)
    frame = frame or robot.model.frames[len(robot.model.frames) - 1].name
    q_home = np.clip(robot.neutral() + 0.4, robot.lower, robot.upper)
    p0 = _fk(robot, frame, q_home)
    if kind == "line":
        path = LinePath(p0, p0 + [-0.1, 0.05, -0.08])
    else:
        path = CirclePath(p0 - [0.08, 0, 0], 0.08, normal=[0, 0, 1], start_dir=[1, 0, 0])
    T = 2.0
    ref = task_space_reference(robot, frame, path, T, q_start=q_home)
    # Independent check: FK of the joint reference at times off the IK knots against the path
    # point from the quintic time law s(t) = 10 u^3 - 15 u^4 + 6 u^5, u = t / T.
    t = np.random.default_rng(3).uniform(0, T, 25)
    u = t / T
    s = 10 * u**3 - 15 * u**4 + 6 * u**5
    want = path.point(s)
    got = np.array([_fk(robot, frame, q) for q in ref.positions(t)])
    assert_allclose(got, want, atol=1e-4)  # the spline between 200 Hz knots: ~1e-6 m measured


def test_unreachable_path_names_the_point(rrr):
    frame = rrr.model.frames[len(rrr.model.frames) - 1].name
    with pytest.raises(IKError, match=r"did not converge at path point \d+ .* residual"):
        task_space_reference(rrr, frame, LinePath([0.5, 0, 1.5], [5.0, 0, 1.5]), 1.0)


def test_unknown_frame(rrr):
    with pytest.raises(ValueError, match="frame 'nosuch' is not in robot"):
        task_space_reference(rrr, "nosuch", LinePath([0, 0, 1], [0, 0, 1.1]), 1.0)


# --- a user's reference that returns the wrong thing (issue 24) -------------------------------

class _Returns(Reference):
    """A user's reference whose ``__call__`` returns ``out(t)``."""

    def __init__(self, out, n=3):
        self.out, self.n = out, n

    def __call__(self, t):
        return self.out(t)


_Z = np.zeros(3)


@pytest.mark.parametrize("out, message", [
    (lambda t: 0.0, r"__call__\(0\) returned 0\.0 \(float\); expected a tuple \(r, rd, rdd\)"),
    (lambda t: None, r"__call__\(0\) returned None \(NoneType\)"),
    (lambda t: (_Z, _Z), r"__call__\(0\) returned \(array"),
    (lambda t: (np.zeros(4), np.zeros(4), np.zeros(4)),
     r"__call__\(0\) returned \(array.* of 3 arrays of shape \(3,\)"),
    (lambda t: (_Z + np.nan, _Z, _Z), r"r is nan \(not finite\) at t = 0 s for joint 0"),
    (lambda t: (_Z, _Z, _Z + (np.inf if t > 0.0105 else 0.0)),
     r"rdd is inf \(not finite\) at t = 0\.011 s for joint 0"),
], ids=["scalar", "None", "pair", "shape", "nan-r", "inf-rdd-later"])
def test_a_wrong_reference_is_refused_naming_it(out, message, rrr):
    # They gave a TypeError, an IndexError, numpy's "cannot reshape", or (a NaN rdd) nothing.
    with pytest.raises(ValueError, match=r"reference _Returns: " + message):
        simulate(rrr, pd_controller(rrr), _Returns(out), 0.05, engine="python")


def test_a_wrong_sample_override_is_refused_naming_it():
    class Flat(Reference):
        n = 3

        def __call__(self, t):
            return _Z, _Z, _Z

        def sample(self, t):
            return np.zeros((len(t), 2)), np.zeros((len(t), 3)), np.zeros((len(t), 3))

    t = np.linspace(0.0, 1.0, 5)
    with pytest.raises(ValueError, match=r"reference Flat: sample\(\) returned r of shape "
                                         r"\(5, 2\), expected \(5, 3\)"):
        checked_sample(Flat(), t)
    R, RD, RDD = checked_sample(_Returns(lambda s: (_Z + s, _Z + 1.0, _Z)), t)
    assert_allclose(R[:, 0], t, rtol=0, atol=0)  # exact: the values the reference returned
    assert_allclose(RD, 1.0, rtol=0, atol=0)
