"""Generated dynamics at first use (rrr_pin.sim.dyncache): built, cached, refused by name.

References: Pinocchio's CRBA, nonLinearEffects, computeGeneralizedGravity and ABA on the same
numbers (an independent implementation), and the compiled engine (Pinocchio's dynamics in the
same loop) for the campaign rows.
"""

import json
import re

import pytest

from rrr_pin.campaign import montecarlo as mc
from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.control.references import study_reference
from rrr_pin.model.dynamics import robot_from_xml
from rrr_pin.model.uncertainty import Tolerances
from rrr_pin.sim import batched, dyncache, dyngen
from rrr_pin.sim.extension import EXTENSION, available
from rrr_pin.sim.simulation import simulate_batch

pytestmark = pytest.mark.skipif(not available(), reason="compiled extension not built")

RATE = 1000.0  # [Hz]


def _arm(axes, name):
    """URDF text of a chain of revolute joints about ``axes`` (e.g. "xy"), 0.4 m links."""
    vec = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}
    links = ['<link name="base"/>']
    for j, a in enumerate(axes, 1):
        parent = "base" if j == 1 else f"l{j - 1}"
        z = "0.1" if j == 1 else "0.4"
        links.append(
            f'<joint name="j{j}" type="revolute"><parent link="{parent}"/>'
            f'<child link="l{j}"/><origin xyz="0.05 0 {z}" rpy="0.1 0.2 0.3"/>'
            f'<axis xyz="{vec[a]}"/><limit lower="-3" upper="3" effort="100" velocity="10"/>'
            f'</joint><link name="l{j}"><inertial><origin xyz="0.02 0.01 0.2" rpy="0 0 0"/>'
            f'<mass value="{2.0 + j}"/><inertia ixx="0.05" ixy="0.001" ixz="0" iyy="0.04" '
            f'iyz="0.002" izz="0.03"/></inertial></link>')
    return f'<robot name="{name}">{"".join(links)}</robot>'


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A fresh cache folder, and this process's memory of structures forgotten."""
    monkeypatch.setenv("RRR_PIN_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(dyncache, "_LOADED", {})
    return tmp_path / "cache" / "dyn"


# Structure built successfully in these tests; the failure tests use another one (RY, RZ),
# never registered in this process, so that its refusals are not masked by a loaded entry.
GOOD = _arm("xy", "arm_xy")
BAD = _arm("yz", "arm_yz")


def test_structure_generated_at_first_use_equals_pinocchio(cache, generated_matches_pinocchio):
    robot = robot_from_xml(GOOD)
    st = dyngen.structure(robot.model)
    assert st not in {s for s, _, _ in EXTENSION.batch_models().values()}  # not compiled in
    name = dyncache.load(robot.model)  # built into this test's empty cache
    assert name in EXTENSION.batch_loaded()
    assert batched.generated_structure(robot.model) is not None  # what the engine finds
    folder, _ = dyncache.entry(st)
    meta = json.loads((folder / "entry.json").read_text())
    assert meta["structure"] == st and meta["generator_version"] == dyncache.GENERATOR_VERSION
    assert meta["build_s"] > 0.0
    generated_matches_pinocchio(name, robot.model, 33, 6)


def test_campaign_on_a_structure_generated_at_first_use_equals_compiled(cache):
    robot = robot_from_xml(GOOD)
    laws = make_laws("fl,pd", robot)
    settings = mc.CampaignSettings(samples=3, seed=2, tolerances=Tolerances(),
                                   run=RunSettings(duration=0.1, rate=RATE))
    fast = mc.run_campaign(robot, laws, settings, jobs=1).rows
    slow = mc.run_campaign(robot, laws, settings.__class__(
        samples=3, seed=2, tolerances=Tolerances(),
        run=RunSettings(duration=0.1, rate=RATE, engine="compiled")), jobs=1).rows
    for a, c in zip(fast, slow, strict=True):
        assert a["fl_engine"] == "codegen" and c["fl_engine"] == "compiled"
        for key, value in c.items():
            if key.endswith(("_rms_error", "_max_error")) or "_rms_error_" in key:
                # 1e-12 rad, the pinned tolerance of the batched engine (tests/test_batched.py)
                assert abs(a[key] - value) <= 1e-12, key


@pytest.mark.slow  # a second C compile of a structure (8 s); the first-use build is tested above
def test_entry_of_another_generator_version_is_rebuilt(cache, monkeypatch):
    robot = robot_from_xml(GOOD)
    st = dyngen.structure(robot.model)
    dyncache.load(robot.model)
    folder, _ = dyncache.entry(st)
    # A folder whose entry names another generator version is rebuilt, never reused.
    meta = json.loads((folder / "entry.json").read_text())
    (folder / "entry.json").write_text(json.dumps({**meta, "generator_version": "0" * 16}))
    (folder / "dyn.so").unlink()  # a new file: the loaded one stays mapped as it was
    (folder / "dyn.so").write_bytes(b"stale")
    monkeypatch.setattr(dyncache, "_LOADED", {})
    dyncache.load(robot.model)
    assert json.loads((folder / "entry.json").read_text())["generator_version"] == \
        dyncache.GENERATOR_VERSION
    assert (folder / "dyn.so").read_bytes()[:4] == b"\x7fELF"
    # Another generator version keys another folder: the old entry is not looked at.
    monkeypatch.setattr(dyncache, "GENERATOR_VERSION", "f" * 16)
    monkeypatch.setattr(dyncache, "_LOADED", {})
    other, _ = dyncache.entry(st)
    assert other != folder
    dyncache.load(robot.model)
    assert json.loads((other / "entry.json").read_text())["generator_version"] == "f" * 16


def _fallback(match):
    """A campaign-style batch on BAD runs on the compiled engine, saying why (``match``)."""
    robot = robot_from_xml(BAD)
    law = make_laws("fl", robot)[0]
    ref = study_reference(robot, 0.02)
    (traj,) = simulate_batch([robot], law, ref, 0.02, rate=RATE)
    assert traj.info["engine"] == "compiled"
    assert "not codegen for the batch" in traj.info["engine_note"]
    assert match in traj.info["engine_note"]
    with pytest.raises(batched.StructureMismatch, match=re.escape(match)):
        simulate_batch([robot], law, ref, 0.02, rate=RATE, engine="codegen")


def test_a_corrupted_entry_is_named_and_the_compiled_engine_runs(cache):
    st = dyngen.structure(robot_from_xml(BAD).model)
    folder, name = dyncache.entry(st)
    folder.mkdir(parents=True)
    (folder / "entry.json").write_text(json.dumps({
        "structure": st, "name": name, "generator_version": dyncache.GENERATOR_VERSION}))
    (folder / "dyn.so").write_bytes(b"not a shared object")
    _fallback("is corrupted")


def test_an_unwritable_cache_folder_is_named(cache, tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("a file, not a folder")
    monkeypatch.setenv("RRR_PIN_CACHE", str(blocker))
    _fallback("cannot be written")


@pytest.mark.parametrize("compiler, match", [("false", "failed (exit 1)"),
                                             ("/nonexistent/cc", "no C compiler")],
                         ids=["failing", "missing"])
def test_a_failing_or_missing_compiler_is_named(cache, monkeypatch, compiler, match):
    monkeypatch.setattr(dyncache, "COMPILER", compiler)
    _fallback(match)
