import dataclasses
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.model.dh import ArmParams, DHLink, dh_transform, forward_kinematics, paper_params


def test_paper_tables():
    p = paper_params()
    # Values typed from the paper's Table 2.
    assert_allclose(p.m, [20.0, 20.0, 5.0])
    assert_allclose(p.l, [1.0, 1.0, 1.0])
    assert_allclose(p.lg, [0.75, 0.75, 0.5])
    assert_allclose(p.J, [[1.6667, 1.6667, 0.0], [0.0, 1.6667, 1.6667], [0.0, 0.4167, 0.4167]])
    assert p.g == 9.8
    # Table 1: (a, alpha, d).
    assert [(lk.a, lk.alpha, lk.d) for lk in p.links] == [
        (0.0, math.pi / 2, 1.0), (1.0, 0.0, 0.0), (1.0, 0.0, 0.0)]


def test_json_round_trip(tmp_path):
    p = paper_params()
    path = tmp_path / "p.json"
    p.save(path)
    assert ArmParams.load(path) == p


BAD = [
    ("mass", -1.0, r"mass must be a finite number > 0 \[kg\], got -1\.0"),
    ("mass", float("nan"), r"mass must be a finite number > 0 \[kg\], got nan"),
    ("lg", 1.5, "lg must lie in"),
    ("lg", -0.1, "lg must lie in"),
    ("J", (-1.0, 1.0, 1.0), r"Jx must be a finite number >= 0 \[kg m\^2\], got -1\.0"),
    ("effort", 0.0, r"effort must be a finite number > 0 \[N m\], got 0\.0"),
    ("velocity", True, r"velocity must be a finite number > 0 \[rad/s\], got True"),
    ("J", (0.0, 1.0, 3.0), "Jz = 3.0 violates the triangle inequality"),
    ("a", float("inf"), "a must be finite"),
]


@pytest.mark.parametrize("field,value,message", BAD, ids=[f"{b[0]}={b[1]}" for b in BAD])
def test_validation_names_field(field, value, message):
    link = paper_params().links[1]
    with pytest.raises(ValueError, match=message):
        dataclasses.replace(link, **{field: value})


def test_zero_length_rejected():
    with pytest.raises(ValueError, match="link length"):
        DHLink(a=0.0, alpha=0.0, d=0.0, mass=1.0, lg=0.0, J=(1.0, 1.0, 1.0))


def test_load_rejects_unknown_keys(tmp_path):
    path = tmp_path / "p.json"
    path.write_text('{"links": [], "colour": 1}')
    with pytest.raises(ValueError, match="unknown parameter keys"):
        ArmParams.load(path)


def test_dh_transform_is_product_of_elementary_motions():
    # Independent construction: Rz(theta) Tz(d) Tx(a) Rx(alpha) as four 4x4 matrices.
    rng = np.random.default_rng(0)
    theta, d, a, alpha = rng.uniform(-3, 3, 4)

    def rz(t):
        c, s = np.cos(t), np.sin(t)
        return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])

    def rx(t):
        c, s = np.cos(t), np.sin(t)
        return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])

    def tr(x, y, z):
        T = np.eye(4)
        T[:3, 3] = (x, y, z)
        return T

    expected = rz(theta) @ tr(0, 0, d) @ tr(a, 0, 0) @ rx(alpha)
    assert_allclose(dh_transform(theta, d, a, alpha), expected, atol=1e-15)


def test_tip_position_closed_form():
    # The RRR tip, by hand: joint 1 turns the vertical plane, joints 2-3 move in it.
    rng = np.random.default_rng(1)
    for q in rng.uniform(-np.pi, np.pi, (20, 3)):
        reach = np.cos(q[1]) + np.cos(q[1] + q[2])
        height = 1.0 + np.sin(q[1]) + np.sin(q[1] + q[2])
        tip = forward_kinematics(paper_params(), q)[-1][:3, 3]
        assert_allclose(tip, [reach * np.cos(q[0]), reach * np.sin(q[0]), height], atol=1e-14)


def test_load_refuses_a_folder_as_a_folder(tmp_path):
    # It said "parameter file not found" (the folder exists).
    (tmp_path / "p.json").mkdir()
    with pytest.raises(ValueError, match=r"p.json: is a directory; a parameter set is a JSON "
                                         r"file"):
        ArmParams.load(tmp_path / "p.json")


def test_a_scaled_link_is_the_validated_link():
    # DHLink.scaled skips the checks because they hold by construction: the same link through
    # the checked constructor is equal field by field (and is not refused), over random draws
    # of the paper's links at a 90 % tolerance.
    from dataclasses import asdict, replace

    from rrr_pin.model.uncertainty import perturb_inertia

    rng = np.random.default_rng(7)
    for link in paper_params().links:
        for _ in range(200):
            f_m, f_l = rng.uniform(0.1, 1.9, 2)
            J = tuple(np.diag(perturb_inertia(np.diag(link.J), rng.uniform(0.1, 1.9, 3))).tolist())
            fast = link.scaled(f_m, J, f_l)
            checked = replace(link, mass=link.mass * f_m, J=J, a=link.a * f_l,
                              d=link.d * f_l, lg=link.lg * f_l)
            assert asdict(fast) == asdict(checked)
