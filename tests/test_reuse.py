"""Reuse of a run's preparation across runs (rrr_pin.sim.reuse.reuse_preparation).

A campaign samples the reference and discretizes the laws once per chunk instead of once per
run; the runs must not change by a single bit. The reference here is the same run made with no
reuse at all (each run prepares itself, the code path before the cache existed).
"""

import numpy as np
import pytest

import rrr_pin
from rrr_pin.campaign.runner import RunSettings, make_laws, run_laws
from rrr_pin.control.references import QuinticReference, default_reference
from rrr_pin.model.dynamics import robot_from_xml
from rrr_pin.model.uncertainty import sample_plant
from rrr_pin.sim import reuse
from rrr_pin.sim.extension import available
from rrr_pin.sim.simulation import reuse_preparation, simulate

DURATION = 0.3  # s: long enough for the H-inf state and the FL loop to move the plant


@pytest.fixture(scope="module")
def setup():
    robot = rrr_pin.load_robot("rrr")
    plants = [robot_from_xml(sample_plant(rrr_pin.paper_params(), 0, k).urdf)
              for k in range(2)]
    laws = make_laws("fl,hinf,pd", robot)
    refs = [default_reference(robot),
            QuinticReference(start=[0.2, -0.5, 0.8], goal=[0.9, 0.3, -0.2], move_time=0.2)]
    return robot, plants, laws, refs


def _same(a, b):
    for key in ("t", "q", "qd", "r", "tau"):
        # bit for bit: the cache must hand out exactly what a run computes for itself
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key), err_msg=key)


@pytest.mark.parametrize("engine", ["python", "compiled"])
@pytest.mark.parametrize("rate", [1000.0, None])
def test_runs_inside_reuse_equal_separate_runs(setup, engine, rate):
    _, plants, laws, refs = setup
    if engine == "compiled" and not available():
        pytest.skip("compiled extension not built")
    cases = [(p, law, ref) for p in plants for law in laws for ref in refs]
    alone = [simulate(p, law, ref, DURATION, rate=rate, engine=engine) for p, law, ref in cases]
    with reuse_preparation():
        shared = [simulate(p, law, ref, DURATION, rate=rate, engine=engine)
                  for p, law, ref in cases]
        # the cached reference and law forms exist only inside the block
        assert reuse._REUSE
    assert reuse._REUSE is None
    for a, b in zip(alone, shared, strict=True):
        _same(a, b)


def test_reused_reference_arrays_are_independent(setup):
    robot, plants, laws, refs = setup
    with reuse_preparation():
        first = simulate(plants[0], laws[0], refs[0], DURATION, rate=1000.0)
        first.r[:] = np.nan  # a caller scribbling on its trajectory
        second = simulate(plants[0], laws[0], refs[0], DURATION, rate=1000.0)
    _same(second, simulate(plants[0], laws[0], refs[0], DURATION, rate=1000.0))


def test_reuse_is_reentrant_and_run_laws_unchanged(setup):
    _, plants, laws, refs = setup
    settings = RunSettings(duration=DURATION, rate=500.0)
    outside = run_laws(plants[1], laws, refs[1], settings)
    with reuse_preparation():
        with reuse_preparation():
            pass
        assert reuse._REUSE is not None  # the inner block did not drop the cache
        inside = run_laws(plants[1], laws, refs[1], settings)
    for name in outside:
        _same(outside[name], inside[name])


def test_limits_still_checked_inside_reuse(setup):
    robot, plants, laws, _ = setup
    far = QuinticReference(start=[0.0, 0.0, 0.0], goal=[10.0, 0.0, 0.0], move_time=0.2)
    with reuse_preparation(), pytest.raises(ValueError, match="limits"):
        simulate(plants[0], laws[0], far, DURATION, rate=1000.0)


def test_robot_pickles_small_and_computes_the_same():
    """A campaign sends its laws' nominal Robot with every task: model only, not workspaces."""
    import pickle

    robot = rrr_pin.load_robot("ur5")
    blob = pickle.dumps(robot)
    # pin.Data of UR5 alone pickles to ~90 kB; the model and URDF text to ~25 kB
    assert len(blob) < 60_000
    back = pickle.loads(blob)
    rng = np.random.default_rng(3)
    q, qd, tau = rng.uniform(-1, 1, (3, robot.nq))
    # independent reference: the original object's own Pinocchio calls, bit for bit
    np.testing.assert_array_equal(back.M(q), robot.M(q))
    np.testing.assert_array_equal(back.V(q, qd), robot.V(q, qd))
    np.testing.assert_array_equal(back.G(q), robot.G(q))
    np.testing.assert_array_equal(back.forward_dynamics(q, qd, tau),
                                  robot.forward_dynamics(q, qd, tau))
    assert (back.name, back.source, back.urdf, back.locked, back.gravity) == (
        robot.name, robot.source, robot.urdf, robot.locked, robot.gravity)
    np.testing.assert_array_equal(back.upper, robot.upper)
    assert back.data is not robot.data


def test_lasting_preparation_goes_to_the_kept_dictionary(setup):
    # A campaign's job keeps its laws' sampled forms and its reference's samples across its
    # chunks (keep=...); what belongs to one plant stays in the block and goes with it.
    _, plants, laws, refs = setup
    kept: dict = {}
    with reuse_preparation(keep=kept):
        first = simulate(plants[0], laws[0], refs[0], DURATION, rate=1000.0)
        block = dict(reuse._REUSE)
    kinds = {key[1][0] for key in kept}
    assert "sampled" in kinds and kinds <= {"sampled", "limits"}
    assert all(obj in (laws[0], refs[0]) for obj, _ in kept.values())
    assert not any(key in block for key in kept)
    assert reuse._REUSE is None and reuse._LASTING is None
    with reuse_preparation(keep=kept):  # a later chunk: the same forms, the same numbers
        again = simulate(plants[0], laws[0], refs[0], DURATION, rate=1000.0)
        assert not reuse._REUSE  # nothing made again
    _same(first, again)


def test_a_batch_prepares_each_plant_as_simulate_does(setup):
    # simulate_batch prepares the runs after the first from it (only what depends on the
    # plant again): a plant whose own joint limits exclude the shared reference is refused
    # with the message simulate gives it alone, and the others run as they do alone.
    from dataclasses import replace

    from rrr_pin.model.dynamics import load_robot
    from rrr_pin.sim.simulation import simulate_batch

    robot, plants, laws, refs = setup
    params = robot.params
    tight = params.with_links([replace(params.links[0], upper=-2.9), *params.links[1:]])
    narrow = load_robot(tight)
    ref = refs[0]
    with pytest.raises(ValueError) as alone:
        simulate(narrow, laws[0], ref, DURATION, rate=1000.0)
    assert "joint 'joint1'" in str(alone.value) and "outside its limits" in str(alone.value)
    with pytest.raises(ValueError) as batched:
        simulate_batch([plants[0], narrow], laws[0], ref, DURATION, rate=1000.0)
    assert str(batched.value) == str(alone.value)
    for a, b in zip(simulate_batch(plants, laws[0], ref, DURATION, rate=1000.0, engine="compiled"),
                    [simulate(p, laws[0], ref, DURATION, rate=1000.0, engine="compiled")
                     for p in plants], strict=True):
        _same(a, b)
