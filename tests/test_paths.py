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
