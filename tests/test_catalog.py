"""The registry of built-in laws (rrr_pin.control.catalog): light to import, one name -> factory."""

import subprocess
import sys

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.campaign.runner import make_laws
from rrr_pin.control.catalog import BUILTIN_LAWS, LAWS, make_law
from rrr_pin.control.laws import (
    AntiWindupTracking,
    FLAWForm,
    FLForm,
    PDForm,
    PDGravity,
    SampledLaw,
    TrackingController,
    TwoDOFController,
    TwoDOFForm,
)

# The paper's eq. (18), typed from the paper (a test input, not from rrr_pin.robust).
K18 = control.tf([47.40, 47.40 * (134.75 + 12.17), 47.40 * 134.75 * 12.17],
                 [1.0, 513.37 + 0.19, 513.37 * 0.19])


#: What each built-in name builds, and the compiled form it declares (None: Python only).
BUILT = {"fl": (TrackingController, FLForm), "hinf": (TrackingController, FLForm),
         "pd": (PDGravity, PDForm), "hinf_aw": (AntiWindupTracking, FLAWForm),
         "hinf2dof": (TwoDOFController, TwoDOFForm)}


def test_catalog_imports_no_numerical_library():
    # The CLI's help lists the laws from here; it must answer without loading any of these.
    code = ("import sys, rrr_pin.control.catalog as c; assert c.BUILTIN_LAWS; "
            "print(sorted(m for m in ('numpy', 'pinocchio', 'control', 'scipy') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_descriptions_are_the_registry_s():
    assert BUILTIN_LAWS == {name: law.description for name, law in LAWS.items()}
    assert list(LAWS) == ["fl", "hinf", "pd", "hinf_aw", "hinf2dof"]


def test_each_name_builds_its_law(rrr):
    fl = make_law("fl", rrr, lam_fl=80.0)
    assert type(fl) is TrackingController and fl.lam == 80.0 and fl.nx == 0
    hinf = make_law("hinf", rrr, K=K18, lam_hinf=45.0)
    assert type(hinf) is TrackingController and hinf.lam == 45.0
    # K18 (2 states) copied on the diagonal of 3 joints; its DC gain from the paper's
    # polynomials: 47.40 * 134.75 * 12.17 / (513.37 * 0.19). 1e-12: one state-space solve.
    A, B, C, D = hinf.continuous_matrices()
    assert A.shape == (6, 6)
    dc = C @ np.linalg.solve(-A, B) + D
    assert_allclose(dc, 47.40 * 134.75 * 12.17 / (513.37 * 0.19) * np.eye(3), rtol=1e-12,
                    atol=1e-9)
    pd = make_law("pd", rrr)
    assert type(pd) is PDGravity


def test_make_laws_goes_through_the_registry(rrr):
    laws = make_laws("pd,fl", rrr, lam_fl=70.0)
    assert [law.name for law in laws] == ["pd", "fl"] and laws[1].lam == 70.0


@pytest.mark.parametrize("name", ["lqr", "", 3], ids=["unknown", "empty", "not-a-string"])
def test_an_unknown_name_lists_the_builtins(rrr, name):
    with pytest.raises(ValueError, match=r"unknown controller .*; built-in controllers: fl \("):
        make_law(name, rrr)


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
@pytest.mark.parametrize("name", list(LAWS))
def test_every_builtin_builds_on_every_kind_of_plant_and_samples(plant, name):
    # One law per name for any plant (a built-in added to the registry is checked on every
    # kind here); its compiled form is the law's own declaration, whatever the plant (which
    # engine runs it is the engine's decision).
    assert set(BUILT) == set(LAWS)
    cls, form = BUILT[name]
    law = make_law(name, plant, K=K18, torque_limit=50.0)
    assert type(law) is cls and law.n == plant.nq
    assert type(law.compiled_form()) is form
    digital = law.sampled(1000.0)
    assert isinstance(digital, SampledLaw) and digital.rate == 1000.0
    rng = np.random.default_rng(1)
    q = plant.neutral() + rng.uniform(-0.05, 0.05, plant.nq)
    plant.reset(q)
    qd = rng.standard_normal(plant.nq)
    r, rd, rdd = q + 0.01, qd + 0.1, rng.standard_normal(plant.nq)
    x = np.zeros(law.nx)
    if law.nx == 0:
        # A static law read at the sample is the continuous law: the same operations.
        assert_allclose(digital.step(0.0, q, qd, r, rd, rdd, x)[0],
                        law.torque(0.0, q, qd, r, rd, rdd, x), rtol=0, atol=0)
