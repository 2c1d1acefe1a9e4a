"""controller.json records the inertial parameters the exported dynamics carry (issue 35).

An identified (or any non-nominal) model travels with its export: the embedded dynamics use its
parameters, and controller.json lists them. Checked against the URDF text itself: each link's
``<mass>`` and ``<inertial><origin xyz>`` give m and m c (the child link's frame is the joint's).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
from numpy.testing import assert_allclose

from rrr_pin import load_robot, sample_plants
from rrr_pin.deploy.writer import prepare_export
from rrr_pin.model.dynamics import robot_from_xml
from rrr_pin.model.robots import nominal_params


def test_controller_json_records_the_model_parameters():
    nominal = load_robot("rrr")
    urdf = sample_plants(nominal_params(nominal), 1, 11)[0].urdf  # another model: "identified"
    robot = robot_from_xml(urdf, name="identified")
    ex = prepare_export("pd", robot, 1000.0)
    params = ex.record["model"]["parameters"]
    values = np.array(params["values"])
    assert values.shape == (3, 10) and params["friction_compensated"] is False
    root = ET.fromstring(urdf)
    links = {link.get("name"): link for link in root.iter("link")}
    moving = [jt for jt in root.iter("joint") if jt.get("type") in ("revolute", "continuous")]
    assert len(moving) == 3
    for j, joint in enumerate(moving):
        inertial = links[joint.find("child").get("link")].find("inertial")
        m = float(inertial.find("mass").get("value"))
        origin = inertial.find("origin")
        c = np.array([float(v) for v in origin.get("xyz").split()]) if origin is not None \
            else np.zeros(3)
        # the URDF's decimal text against Pinocchio's doubles: exact to the last digits
        assert_allclose(values[j, 0], m, rtol=1e-12)
        assert_allclose(values[j, 1:4], m * c, rtol=1e-12, atol=1e-12)
    assert not np.allclose(values, np.array(prepare_export("pd", nominal, 1000.0)
                                            .record["model"]["parameters"]["values"]))
