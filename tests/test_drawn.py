"""Uncertain arms drawn straight into their model (rrr_pin.model.drawn) against the text route.

The reference is independent code: the URDF text :meth:`Tolerances.arm` writes from the same
seeded draws (yourdfpy or the DH generator), read by urdfdom and Pinocchio's URDF reader.
"""

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from rrr_pin import Tolerances, load_robot
from rrr_pin.model.drawn import urdf_rotation
from rrr_pin.model.dynamics import DrawnArm, robot_from_xml
from rrr_pin.sim import dyngen

TOL = Tolerances()
PANDA_LOCK = {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0}


@pytest.fixture(scope="module")
def panda():
    return load_robot("panda", lock=PANDA_LOCK)


@pytest.fixture(scope="module")
def kinova():
    return load_robot("kinova")


def _text_route(nominal, seed):
    """The plant the URDF route makes of seed ``[0, k]``: its model and parameters record."""
    source = nominal.params if nominal.params is not None else nominal.urdf
    text, parameters = TOL.arm(source, np.random.default_rng(seed),
                               skip_joints=tuple(nominal.locked), name="s")
    plant = robot_from_xml(text, gravity=nominal.gravity, lock=dict(nominal.locked), name="s",
                           check=False)
    return text, plant, parameters


@pytest.mark.parametrize("arm", ["rrr", "ur5", "panda", "kinova"])
def test_drawn_equals_text_route(arm, request):
    """Every parameter of the drawn model equals the model read from the URDF text, bit for bit.

    RRR (DH parameters), UR5 (fixed joints), Panda (fingers locked: buildReducedModel),
    Kinova (origins at gimbal lock, whose rpy yourdfpy writes back changed).
    """
    nominal = request.getfixturevalue(arm)
    for k in range(4):
        drawn, parameters = nominal.perturbed(np.random.default_rng([7, k]), TOL, name="s")
        text, plant, expected = _text_route(nominal, [7, k])
        # the record adds the plant's joint coefficients (armature, damping, friction)
        assert parameters.pop("joint_dynamics") == drawn.joint_dynamics()
        assert isinstance(drawn, DrawnArm) and parameters == expected
        A, B = dyngen.parameters(drawn.model), dyngen.parameters(plant.model)
        np.testing.assert_array_equal(A, B)
        assert B.tolist() != dyngen.parameters(nominal.model).tolist()  # something was drawn
        for fa, fb in zip(drawn.model.frames, plant.model.frames, strict=True):
            assert fa.name == fb.name
            np.testing.assert_array_equal(fa.placement.homogeneous, fb.placement.homogeneous)
        # the limits, armature and friction are the nominal's
        np.testing.assert_array_equal(drawn.lower, plant.lower)
        np.testing.assert_array_equal(drawn.effort_limits(), plant.effort_limits())
        assert drawn.name == "s" and drawn.locked == plant.locked


def test_urdf_written_at_first_use(rrr):
    """The URDF of a drawn arm is written only when asked for, from the same draws."""
    drawn, _ = rrr.perturbed(np.random.default_rng([3, 1]), TOL, name="rrr_sample001")
    assert "_urdf" not in drawn.__dict__ or drawn.__dict__["_urdf"] is None
    text, _, _ = _text_route(rrr, [3, 1])
    assert drawn.urdf == text.replace('name="s"', 'name="rrr_sample001"')
    assert drawn.source_text() == (drawn.urdf, ".urdf")


def test_urdf_rotation_matches_pinocchio(ur5):
    """urdf_rotation of a joint's rpy equals the placement Pinocchio read from the text."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(ur5.urdf)
    checked = 0
    for j in root.findall("joint"):
        jid = ur5.model.getJointId(j.get("name"))
        if j.get("type") == "fixed" or ur5.model.parents[jid] == 0:
            continue  # the first joint sits after the fixed world joint: a product
        checked += 1
        rpy = [float(v) for v in j.find("origin").get("rpy").split()]
        np.testing.assert_array_equal(
            urdf_rotation(rpy),
            ur5.model.jointPlacements[jid].rotation)
    assert checked == 5
    # and against Pinocchio's own rpy map, to round-off (another algorithm)
    rpy = np.array([0.3, -1.2, 2.5])
    np.testing.assert_allclose(urdf_rotation(rpy), pin.rpy.rpyToMatrix(rpy), atol=1e-15)


def test_identified_set_keeps_the_text_route(rrr):
    """An uncertainty set without a direct route draws through the URDF text (draw_arm None)."""
    from rrr_pin.model.plant import UncertaintySet

    assert UncertaintySet().draw_arm(rrr, np.random.default_rng(0)) is None


def test_drawn_arm_pickles_with_its_urdf(ur5):
    """A drawn arm crossing a process boundary travels as its model and its (written) URDF."""
    import pickle

    drawn, _ = ur5.perturbed(np.random.default_rng([5, 2]), TOL, name="ur5_sample002")
    back = pickle.loads(pickle.dumps(drawn))
    np.testing.assert_array_equal(dyngen.parameters(back.model), dyngen.parameters(drawn.model))
    assert type(back) is DrawnArm and back.urdf == drawn.urdf
    text, plant, _ = _text_route(ur5, [5, 2])
    assert back.urdf == text  # a URDF arm's drawn text keeps the nominal's <robot name>


def test_a_subclass_with_its_own_arm_keeps_its_text_route(rrr):
    """Tolerances subclassed with another arm(): its plants are what its arm() writes."""
    from dataclasses import dataclass

    from rrr_pin.model.uncertainty import perturb_params
    from rrr_pin.model.urdf import urdf_from_params

    @dataclass(frozen=True)
    class Heavier(Tolerances):
        def arm(self, source, rng, *, skip_joints=(), name=None):
            params, factors = perturb_params(source, rng, self)
            links = [replace(link, mass=2.0 * link.mass) for link in params.links]
            return urdf_from_params(params.with_links(links)), {"factors": factors}

    drawn, _ = rrr.perturbed(np.random.default_rng([1, 0]), Heavier(), name="h")
    plain, _ = rrr.perturbed(np.random.default_rng([1, 0]), TOL, name="h")
    assert not isinstance(drawn, DrawnArm)
    np.testing.assert_allclose(drawn.model.inertias[1].mass, 2.0 * plain.model.inertias[1].mass,
                               rtol=1e-15)  # the subclass's own doubling, read from its text
