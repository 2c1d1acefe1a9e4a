"""Tests of rrr_pin.control.specs: a ReferenceSpec builds the reference its options name."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.control.paths import circle_from_start
from rrr_pin.control.references import (
    LinePath,
    QuinticReference,
    default_reference,
    task_space_reference,
)
from rrr_pin.control.specs import KINDS, ReferenceSpec

T = np.linspace(0.0, 2.0, 41)


def _same(a, b):
    # the spec must build exactly the reference the direct call builds (same code, same numbers)
    for x, y in zip(a.sample(T), b.sample(T), strict=True):
        assert_allclose(x, y, rtol=0, atol=0)


def test_sine_is_the_default_reference(rrr):
    _same(ReferenceSpec().build(rrr, 4.0), default_reference(rrr))
    home = (0.1, 0.5, -0.4)
    _same(ReferenceSpec(amp=0.2, freq=1.0, home=home).build(rrr, 4.0),
          default_reference(rrr, amp=0.2, freq=1.0, home=np.array(home)))


def test_quintic_defaults_to_half_the_run(rrr):
    start = np.clip(rrr.neutral(), rrr.lower, rrr.upper)
    got = ReferenceSpec(kind="quintic", to=(0.3, -0.2, 0.4)).build(rrr, 3.0)
    _same(got, QuinticReference(start, np.array([0.3, -0.2, 0.4]), 1.5))


def test_line_and_circle_start_where_the_frame_is(rrr):
    home = np.array([0.2, 0.6, -1.0])
    frame = rrr.model.frames[len(rrr.model.frames) - 1].name
    p0 = rrr.frame_placement(home, frame)[:3, 3]
    got = ReferenceSpec(kind="line", home=tuple(home), end=tuple(p0 + [0.05, 0.0, 0.0]),
                        move_time=1.0).build(rrr, 2.0)
    _same(got, task_space_reference(rrr, frame, LinePath(p0, p0 + [0.05, 0.0, 0.0]), 1.0,
                                    q_start=home))
    got = ReferenceSpec(kind="circle", home=tuple(home), radius=0.05).build(rrr, 2.0)
    _same(got, task_space_reference(rrr, frame, circle_from_start(p0, 0.05), 1.0,
                                    q_start=home))


@pytest.mark.parametrize("normal", [(0.0, 0.0, 1e-200), (0.0, 0.0, 1e300)],
                         ids=["tiny", "huge"])
def test_a_circle_normal_of_any_length_is_its_direction(rrr, normal):
    # They gave "center must be finite, got [nan, nan, nan]" (n @ n under- or overflowed).
    home = np.array([0.2, 0.6, -1.0])
    got = ReferenceSpec(kind="circle", home=tuple(home), radius=0.05, normal=normal)
    want = ReferenceSpec(kind="circle", home=tuple(home), radius=0.05, normal=(0.0, 0.0, 1.0))
    _same(got.build(rrr, 2.0), want.build(rrr, 2.0))


def option(field):
    return "--" + field.replace("_", "-")


@pytest.mark.parametrize("spec, message", [
    (ReferenceSpec(kind="zigzag"), "--reference 'zigzag' is unknown; known: study, sine"),
    (ReferenceSpec(kind="spline"), "--reference spline needs --csv PATH"),
    (ReferenceSpec(kind="quintic"), "--reference quintic needs --to"),
    (ReferenceSpec(kind="quintic", to=(0, 0, 0), move_time=0.0),
     "--move-time must be a finite number > 0, got 0.0"),
    (ReferenceSpec(kind="circle", radius=-0.1), "--radius must be a finite number > 0, got -0.1"),
    (ReferenceSpec(home=(0.0, 0.0)), r"Expected --home of shape (3,), got (2,)"),
    (ReferenceSpec(amp=float("nan")), "--amp must be a finite number >= 0, got nan"),
], ids=["kind", "csv", "to", "move-time", "radius", "home", "amp"])
def test_refusals_name_the_option_as_the_caller_spells_it(rrr, spec, message):
    with pytest.raises(ValueError) as info:
        spec.build(rrr, 4.0, label=option)
    assert message in str(info.value)


def test_default_label_is_the_field_name(rrr):
    with pytest.raises(ValueError, match="move_time must be a finite number > 0, got -1"):
        ReferenceSpec(kind="quintic", to=(0, 0, 0), move_time=-1).build(rrr, 4.0)


def test_every_kind_is_documented():
    assert set(KINDS) == {"study", "sine", "quintic", "spline", "line", "circle"}
    assert all(isinstance(v, str) and v for v in KINDS.values())


@pytest.mark.parametrize("amp", [10.0, 3.0], ids=["amp-10", "amp-3"])
def test_an_amplitude_the_limits_cannot_hold_is_refused_not_reduced(rrr, amp):
    # The RRR's joints span [-pi, pi]: about the default home (10 % to spare) the largest
    # amplitude is 2 pi / 2.2 = 2.856 rad. Issue 24: --amp 10 ran at 2.83 rad (45 % of the range).
    with pytest.raises(ValueError, match=rf"^--amp = {amp:g} rad is too large for joint "
                                         rf"'joint1' \(limits \[-3.142, 3.142\] rad\): the "
                                         rf"largest amplitude they allow about the default "
                                         rf"home \(range / 2.2\) is {2 * np.pi / 2.2:.4g} rad"):
        ReferenceSpec(amp=amp).build(rrr, 4.0, label=option)


def test_an_amplitude_beyond_the_limits_about_a_given_home_is_refused(rrr):
    # joint1 at 3 rad with amp 2: spans [1, 5] rad, beyond pi; the amplitude is not reduced.
    with pytest.raises(ValueError, match=r"reference for joint 'joint1' spans \[1, 5\] rad"):
        ReferenceSpec(amp=2.0, home=(3.0, 0.0, 0.0)).build(rrr, 4.0, label=option)


def test_the_largest_amplitude_is_accepted_as_given(rrr):
    amp = 2.0 * np.pi / 2.2 * (1 - 1e-12)
    ref = default_reference(rrr, amp=amp)
    assert_allclose(ref.amp, amp, rtol=0, atol=0)  # not reduced


@pytest.mark.parametrize("kind", [k for k in KINDS if k != "study"])
def test_an_option_the_kind_does_not_read_is_refused(rrr, kind):
    # issue 50's probe: --radius, --move-time, --csv ... without their --reference kind were
    # ignored without a word. Every option another kind reads is refused by this one.
    defaults = ReferenceSpec()
    others = {"amp": 0.3, "freq": 1.0, "to": (0.1, 0.2, 0.3), "move_time": 1.0, "csv": "w.csv",
              "frame": "tool", "end": (0.1, 0.1, 0.1), "radius": 0.1, "normal": (1.0, 0.0, 0.0)}
    for key, value in others.items():
        spec = ReferenceSpec(kind=kind, **{key: value})
        if key in spec._reads():
            continue
        assert getattr(defaults, key) != value
        with pytest.raises(ValueError, match=rf"^--{key.replace('_', '-')} is not read by "
                                             rf"--reference {kind}: "):
            spec.build(rrr, 2.0, label=option)
