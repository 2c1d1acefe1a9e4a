"""Operation counts of the generated dynamics (rrr_pin.sim.dyngen) and the per-structure choice.

References: a count derived by hand for one revolute joint, the operations of the committed C
text itself (counted from the file, apart from the generator's own bookkeeping), and
Pinocchio's ABA for a structure whose forward dynamics the generator writes as an ABA.
"""

import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from rrr_pin.model.dynamics import load_robot
from rrr_pin.sim import dyncache, dyngen
from rrr_pin.sim.batched import GENERATED
from rrr_pin.sim.extension import EXTENSION, available

GEN = Path(__file__).resolve().parents[1] / "src" / "rrr_pin" / "_ext" / "generated"


def _chain(n, seed=0):
    """An n-joint chain of revolute joints about z, y, x in turn, random placements."""
    rng = np.random.default_rng(seed)
    model, parent = pin.Model(), 0
    kinds = (pin.JointModelRZ, pin.JointModelRY, pin.JointModelRX)
    for j in range(n):
        placement = pin.SE3(pin.exp3(rng.normal(size=3)), rng.uniform(-0.3, 0.3, 3))
        parent = model.addJoint(parent, kinds[j % 3](), placement, f"j{j}")
        model.appendBodyToJoint(parent, pin.Inertia.Random(), pin.SE3.Identity())
    return model


def test_one_joint_gravity_count_derived_by_hand():
    # G of one joint about z: R = Rp R_z(q), columns 0 and 1 needed (6 entries, 2 mul + 1 add
    # each: 12 mul, 6 add); a = R^T (-g), x and y (2 dots: 6 mul, 4 add); f = m a, x and y
    # (2 mul); tau = (c x f)_z (2 mul, 1 add): 22 mul, 11 add, nothing else needs q.
    c = dyngen.operation_counts(_chain(1))["gravity"]
    assert (c["mul"], c["add"], c["div"]) == (22, 11, 0)
    # M of one joint is Io_zz + armature: parameters only, nothing left per call.
    assert dyngen.operation_counts(_chain(1))["crba"]["total"] == 0


def _c_ops(text, name, fn):
    """+, -, *, / of the statements of function ``name_fn`` in a generated C file."""
    body = text.split(f"void {name}_{fn}(int B,")[1].split("\n}\n")[0]
    statements = re.findall(r"^      (?:const double \w+|out\[[^\]]+\]) = (.*);$", body, re.M)
    return sum(s.count(op) for s in statements for op in (" + ", " - ", " * ", " / "))


@pytest.mark.parametrize("name", list(GENERATED))
def test_counts_are_the_committed_c(name):
    source, lock = GENERATED[name]
    model = load_robot(source, lock=dict(lock)).model
    counts = dyngen.operation_counts(model)
    text = (GEN / f"dyn_{name}.c").read_text()
    chosen = dyngen.fd_algorithm(counts)
    other = "aba" if chosen == "ldlt" else "ldlt"
    for fn, key in (("crba", "crba"), ("nle", "nle"), ("gravity", "gravity"),
                    ("fd", chosen), ("fd_other", other), ("pre", "pre")):
        assert _c_ops(text, name, fn) == counts[key]["total"], fn
    assert f'{name}_dyn_fd[] = "{chosen}"' in text
    # Hoisting removes work from every call and adds none.
    before = dyngen.operation_counts(model, hoisted=False)
    for key in ("crba", "nle", "gravity", "ldlt", "aba"):
        assert counts[key]["total"] <= before[key]["total"], key
    assert counts["ldlt"]["total"] < before["ldlt"]["total"]


def test_the_forward_dynamics_of_fewer_operations_is_chosen():
    # 3 to 7 joints: CRBA + L D L^T is cheaper (O(n^2) + O(n^3) small); from 10 joints on the
    # O(n) ABA is.
    for n, expected in ((3, "ldlt"), (7, "ldlt"), (12, "aba")):
        counts = dyngen.operation_counts(_chain(n))
        assert dyngen.fd_algorithm(counts) == expected, n
        chosen = counts[expected]["total"]
        assert chosen == min(counts["ldlt"]["total"], counts["aba"]["total"])


@pytest.mark.skipif(not available(), reason="compiled extension not built")
@pytest.mark.parametrize("name", list(GENERATED))
def test_the_extension_records_the_chosen_algorithm(name):
    source, lock = GENERATED[name]
    model = load_robot(source, lock=dict(lock)).model
    assert EXTENSION.batch_fd_algorithm(name) == dyngen.fd_algorithm(
        dyngen.operation_counts(model))


@pytest.mark.slow
@pytest.mark.skipif(not available(), reason="compiled extension not built")
def test_a_structure_whose_forward_dynamics_is_an_aba_equals_pinocchio(
        tmp_path, monkeypatch, generated_matches_pinocchio):
    # 10 joints: the ABA is chosen; built at first use (about a minute of compiling).
    monkeypatch.setenv("RRR_PIN_CACHE", str(tmp_path))
    monkeypatch.setattr(dyncache, "_LOADED", {})
    model = _chain(10, seed=4)
    name = dyncache.load(model)
    assert EXTENSION.batch_fd_algorithm(name) == "aba"
    generated_matches_pinocchio(name, model, 5, 4)


@pytest.mark.slow  # two C builds of the generated code (7 s); make test-slow runs it
@pytest.mark.skipif(not available(), reason="compiled extension not built")
def test_hoisting_changes_no_bit(tmp_path, monkeypatch):
    # A 2-joint structure generated with and without hoisting (everything at every call, as
    # generator version 1 did), each built into the cache under its own key: the same
    # expressions in the same order, so the same bits.
    monkeypatch.setenv("RRR_PIN_CACHE", str(tmp_path))
    model = _chain(2, seed=3)
    generate, names = dyngen.generate, {}
    for hoisted in (True, False):
        monkeypatch.setattr(dyncache, "_LOADED", {})
        monkeypatch.setattr(dyncache, "GENERATOR_VERSION", f"test-hoisted-{hoisted}")
        monkeypatch.setattr(dyngen, "generate",
                            lambda *a, h=hoisted, **k: generate(*a, **k, hoisted=h))
        names[hoisted] = dyncache.load(model)
        text = (dyncache.entry(dyngen.structure(model))[0] / "dyn.c").read_text()
        assert ("const double h" in text) == hoisted
    rng = np.random.default_rng(7)
    # Any numbers (the arithmetic is compared, not the physics).
    P = np.stack([dyngen.parameters(model)] * 5) * rng.uniform(0.9, 1.1, (5, 49))
    q, v, tau = (rng.uniform(-3.0, 3.0, (5, 2)) for _ in range(3))
    for a, b in zip(EXTENSION.batch_dynamics(names[True], P, q, v, tau),
                    EXTENSION.batch_dynamics(names[False], P, q, v, tau), strict=True):
        np.testing.assert_array_equal(a, b)  # bit for bit
