import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.control.paths import circle_from_start


@pytest.mark.parametrize("normal", [(0, 0, 1), (0, 0, -2.5), (1, 0, 0), (1, 1, 1), (0.95, 0.1, 0)],
                         ids=["z", "minus-z-scaled", "x", "diagonal", "near-x"])
def test_circle_starts_at_p0_in_the_plane_of_normal(normal):
    p0 = np.array([0.3, -0.2, 1.1])
    path = circle_from_start(p0, 0.05, normal)
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    # Independent checks on the geometry, to round-off (1e-12 m on values ~1 m):
    assert_allclose(path.point(np.array([0.0]))[0], p0, rtol=0, atol=1e-12)  # starts at p0
    pts = path.point(np.linspace(0.0, 1.0, 17))
    assert_allclose(np.linalg.norm(pts - path.center, axis=1), 0.05, rtol=1e-12)  # radius
    assert_allclose((pts - path.center) @ n, 0.0, atol=1e-12)  # in the plane normal to n
    assert_allclose(pts[-1], p0, rtol=0, atol=1e-12)  # one full turn


def test_circle_start_direction_is_x_projected_unless_normal_is_near_x():
    assert_allclose(circle_from_start([0, 0, 0], 1.0).start_dir, [1.0, 0.0, 0.0])
    # Within acos(0.9) ~ 26 deg of x the projection of x would be short: y is projected.
    assert_allclose(circle_from_start([0, 0, 0], 1.0, (1, 0, 0)).start_dir, [0.0, 1.0, 0.0])


@pytest.mark.parametrize("kwargs,message", [
    ({"radius": 0.0}, r"radius must be a finite number > 0 \[m\], got 0.0"),
    ({"radius": float("nan")}, "radius must be a finite number > 0"),
    ({"normal": (0, 0, 0)}, "normal must be a non-zero vector"),
    ({"normal": (0, 1)}, r"Expected normal of shape \(3,\), got \(2,\)"),
    ({"p0": (0, 0, np.inf)}, "p0 must be finite"),
], ids=["radius-zero", "radius-nan", "normal-zero", "normal-size", "p0-inf"])
def test_circle_refuses_bad_input(kwargs, message):
    args = {"p0": (0.0, 0.0, 1.0), "radius": 0.1, **kwargs}
    with pytest.raises(ValueError, match=message):
        circle_from_start(**args)


# --- the default start of a task-space motion (rrr_pin.control.paths.task_start) -------------

def _fd_conditioning(robot, frame, q, h=1e-6):
    # A second algorithm: the position Jacobian by central differences of forward kinematics
    # (Robot.frame_placement), not Pinocchio's analytic frame Jacobian.
    J = np.empty((3, robot.nq))
    for j in range(robot.nq):
        dq = np.zeros(robot.nq)
        dq[j] = h
        J[:, j] = (robot.frame_placement(q + dq, frame)[:3, 3]
                   - robot.frame_placement(q - dq, frame)[:3, 3]) / (2 * h)
    s = np.linalg.svd(J, compute_uv=False)[:min(3, robot.nq)]
    return s[0] / s[-1] if s[-1] > 0 else np.inf


def test_position_conditioning_matches_finite_differences(rrr):
    from rrr_pin.control.paths import position_conditioning

    rng = np.random.default_rng(3)
    for q in rng.uniform(-2.0, 2.0, size=(5, 3)):
        # central differences of step 1e-6 rad: truncation ~1e-12, round-off ~1e-10 relative
        assert_allclose(position_conditioning(rrr, "ee", q), _fd_conditioning(rrr, "ee", q),
                        rtol=1e-6)


def test_task_start_bends_the_stretched_rrr_and_keeps_a_good_neutral(rrr, ur5):
    from rrr_pin.control.paths import COND_MAX, position_conditioning, task_start

    # The paper's RRR at zero is stretched (l2 and l3 aligned): the origin of 'ee' cannot move
    # along the arm, the position Jacobian has rank 2 (its smallest singular value is 0).
    assert np.isinf(position_conditioning(rrr, "ee", np.zeros(3)))
    q = task_start(rrr, "ee")
    assert _fd_conditioning(rrr, "ee", q) <= COND_MAX
    # the documented order: no smaller one-joint offset on the 0.05 rad grid is good enough
    offset = np.abs(q).max()
    for m in range(1, int(round(offset / 0.05))):
        for j in range(3):
            for sign in (1, -1):
                p = np.zeros(3)
                p[j] = sign * m * 0.05
                assert _fd_conditioning(rrr, "ee", p) > COND_MAX
    assert np.count_nonzero(q) == 1
    assert_allclose(task_start(ur5, "tool0"), np.clip(ur5.neutral(), ur5.lower, ur5.upper),
                    rtol=0, atol=0)


def test_task_start_refuses_when_no_one_joint_move_helps(rrr):
    from rrr_pin.control.paths import task_start

    with pytest.raises(ValueError, match=r"badly conditioned .* give the start configuration "
                                         r"\(--home"):
        task_start(rrr, "ee", cond_max=1.0001)
    with pytest.raises(ValueError, match="frame 'nosuch' is not in robot"):
        task_start(rrr, "nosuch")


def test_default_circle_runs_from_the_default_home_and_is_judged_in_task_space(rrr):
    # The circle the CLI's --reference circle --radius 0.1 builds without --home: before, the
    # stretched neutral arm made the IK fail at path point 5.
    from rrr_pin.control.references import TaskSpaceReference
    from rrr_pin.control.specs import ReferenceSpec

    ref = ReferenceSpec(kind="circle", radius=0.1).build(rrr, 2.0)
    assert isinstance(ref, TaskSpaceReference)
    p0 = rrr.frame_placement(ref.positions([0.0])[0], "ee")[:3, 3]
    # the target follows the quintic law over one turn: start, opposite point at T/2 (s = 1/2,
    # angle pi: centre - r u), start again at T; closed forms of the circle, to round-off
    T = ref.move_time
    assert_allclose(ref.target([0.0, T])[0], ref.target([0.0, T])[1], atol=1e-12)
    assert_allclose(ref.target([T / 2])[0], ref.path.center - 0.1 * ref.path.start_dir,
                    atol=1e-12)
    assert_allclose(ref.target([0.0])[0], p0, atol=1e-6)  # the IK tolerance on the first knot
    # The reference's own joint spline, judged against the path: within the deviation that
    # task_space_reference measured between knots (and the 1e-6 m IK tolerance at knots).
    t = np.linspace(0.0, T, 401)
    e = ref.tracking_error(rrr, t, ref.positions(t))
    assert np.linalg.norm(e, axis=1).max() <= ref.fk_error_m + 1e-6
    assert ref.to_dict()["task_space"]["frame"] == "ee"
    with pytest.raises(ValueError, match=r"q must have shape \(401, 3\)"):
        ref.tracking_error(rrr, t, ref.positions(t)[:, :2])


def test_study_reports_the_cartesian_error_of_a_task_space_reference(rrr, tmp_path):
    from rrr_pin.campaign.runner import RunSettings, make_laws
    from rrr_pin.campaign.study import StudyConfig, run_study
    from rrr_pin.control.specs import ReferenceSpec
    from rrr_pin.model.dynamics import robot_from_xml
    from rrr_pin.report.plotting import plot_task_space
    from rrr_pin.report.results import results_markdown

    ref = ReferenceSpec(kind="circle", radius=0.1, move_time=0.5).build(rrr, 0.6)
    laws = make_laws(["fl"], rrr)
    result = run_study(rrr, laws, reference=ref, config=StudyConfig(
        run=RunSettings(duration=0.6), samples=1, jobs=1))
    ts = result.task_space
    # Independently: the frame by Robot.frame_placement against the circle's own point()
    traj = result.nominal["fl"]
    s = np.clip(traj.t / 0.5, 0, 1)
    s = s**3 * (10 - 15 * s + 6 * s * s)  # the quintic time law, re-derived here
    want = ref.path.point(s)
    got = np.array([rrr.frame_placement(q, "ee")[:3, 3] for q in traj.q])
    d = np.linalg.norm(got - want, axis=1)
    assert_allclose(ts["nominal"]["fl"]["rms_error_m"], np.sqrt(np.mean(d * d)), rtol=1e-9)
    plant = robot_from_xml(result.plants[0].plant.urdf, check=False)
    q1 = result.samples[0]["trajectories"]["fl"].q
    d1 = np.linalg.norm(np.array([plant.frame_placement(q, "ee")[:3, 3] for q in q1]) - want,
                        axis=1)
    assert_allclose(ts["uncertain"]["fl"]["max_error_m"], d1.max(), rtol=1e-9)
    assert "task_space" in result.to_json() and "errors" not in result.to_json()["task_space"]
    assert "## Task space: error of frame `ee`" in results_markdown(result)
    fig = plot_task_space(result)
    assert [ax.get_ylabel() for ax in fig.axes] == ["y [m]", "Cartesian error |p(q) - p*(t)| [mm]"]


@pytest.mark.parametrize("scale", [1e-200, 1e300], ids=["tiny", "huge"])
def test_a_normal_of_any_length_gives_the_circle_of_its_direction(scale):
    # A tiny normal gave "center must be finite" (n @ n underflowed to 0, then 0/0); a huge
    # one overflowed. The circle depends on the direction only: the unit normal's circle.
    p0 = np.array([0.3, -0.2, 1.1])
    normal = np.array([0.0, 0.6, 0.8])
    got = circle_from_start(p0, 0.05, scale * normal)
    want = circle_from_start(p0, 0.05, normal)
    s = np.linspace(0.0, 1.0, 9)
    assert_allclose(got.point(s), want.point(s), rtol=0, atol=1e-15)  # round-off of ~1 m
    assert_allclose(got.normal, normal, rtol=0, atol=1e-15)
