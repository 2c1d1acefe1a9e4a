"""What only a closed chain's study and report have; the behaviour every plant shares is tested
over plant kinds in the layer's own file (test_study, test_montecarlo, test_report_html, ...).

Here: the mechanism drawn with its passive joints closing the loop, the Delta's platform on
its adept cycle (in the 3D scene and in ``task_path.png``), a reference or a track the
mechanism cannot follow refused with its time, a user's own mechanism (a parameter set) and an
MJCF file as inputs.

Independent references: the keyframes read back from the page (the MeshCat commands, msgpack
in base64) against Pinocchio's forward kinematics of a model built afresh from the MJCF; the
Delta's platform against the adept cycle's task-space definition (``adept_point``) and the
closed-form kinematics (``delta_fk``); the 5-bar's workspace boundary from its closed-form
elbows (the loop closes while the elbows are at most ``2 l2`` apart). The browser test (slow:
~30 s on the shared machine) opens a study's page in headless Chromium, as the serial
report's, and finds the mechanism where its closed-form kinematics puts it.
"""

import base64
import re
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.campaign.study import StudyConfig, run_study
from rrr_pin.control.laws import fl_controller
from rrr_pin.control.references import default_reference, study_reference
from rrr_pin.model.closed_chain import LoopClosureError
from rrr_pin.model.dynamics import load_robot
from rrr_pin.model.mechanisms import (
    FiveBarParams,
    adept_point,
    delta_elbows,
    delta_fk,
    fivebar_elbows,
    fivebar_fk,
)
from rrr_pin.model.uncertainty import Tolerances
from rrr_pin.report.plotting import plot_task_path
from rrr_pin.report.results import write_results, write_study_report
from rrr_pin.report.viewer import (
    CAMERA_FOV,
    Scene,
    Track,
    camera_view,
    full_configurations,
    scene_document,
    task_path_points,
)
from rrr_pin.sim.simulation import simulate
from rrr_pin.sim.trajectory import SimulationDiverged

FPS = 10.0


def _commands(document: str) -> list[dict]:
    import umsgpack

    body = re.search(r"var commands = \[(.*?)\];", document, re.S).group(1)
    return [umsgpack.unpackb(base64.b64decode(c)) for c in re.findall(r'"([^"]*)"', body)]


def _keyframes(document: str) -> dict:
    """``{(arm, joint): (frames, positions (K, 3), quaternions xyzw (K, 4))}`` of a scene."""
    (anim,) = [c for c in _commands(document) if c["type"] == "set_animation"]
    out = {}
    for a in anim["animations"]:
        _, _, _, arm, joint = a["path"].split("/")
        tracks = {tr["name"]: tr["keys"] for tr in a["clip"]["tracks"]}
        frames = [k["time"] for k in tracks[".position"]]
        out[arm, int(joint[len("joint"):])] = (
            np.array(frames), np.array([k["value"] for k in tracks[".position"]]),
            np.array([k["value"] for k in tracks[".quaternion"]]))
    return out


def _fresh_model(chain):
    """Model and loop closures read afresh from the chain's MJCF (no ClosedChain involved)."""
    with tempfile.NamedTemporaryFile("w", suffix=".xml", delete=False) as fh:
        fh.write(chain.source_text()[0])
    try:
        model, constraints = pin.buildModelAndLegacyConstraintsFromMJCF(fh.name)
    finally:
        Path(fh.name).unlink()
    return model, list(constraints)


def _reference_q(chain, duration, times):
    ref = study_reference(chain, duration)
    return np.array([ref(t)[0] for t in times])


# --- the mechanism drawn -----------------------------------------------------------------------

@pytest.mark.parametrize("plant", ["fivebar", "delta"], indirect=True)
def test_keyframes_close_the_loop(plant):
    nominal = plant
    ghost, _ = nominal.perturbed(np.random.default_rng(3), Tolerances())
    duration = 1.0
    t = np.arange(int(duration * FPS) + 1) / FPS  # the viewer's frame times, exactly
    qa = _reference_q(nominal, duration, t)
    scene = Scene(nominal.name, nominal, [Track("nominal", t, qa),
                                          Track("ghost", t, qa, opacity=0.35, robot=ghost)])
    keys = _keyframes(scene_document(scene, fps=FPS))
    for arm, chain in (("nominal", nominal), ("ghost", ghost)):
        # The drawn configurations, through Pinocchio's FK of a model built afresh: the two
        # anchors of each loop coincide (Newton stops at 1e-12 m; 1e-9 leaves rounding room).
        q = full_configurations(chain, qa)
        model, constraints = _fresh_model(chain)
        data = model.createData()
        for k, qk in enumerate(q):
            pin.forwardKinematics(model, data, qk)
            for c in constraints:
                a = data.oMi[c.joint1_id] * c.joint1_placement
                b = data.oMi[c.joint2_id] * c.joint2_placement
                assert_allclose(a.translation, b.translation, rtol=0, atol=1e-9)
            # ... and they are the page's keyframes: every animated joint's placement, packed
            # in single precision (~1e-7 m on a metre; 1e-6 bounds it).
            for (which, j), (frames, pos, quat) in keys.items():
                if which != arm:
                    continue
                np.testing.assert_array_equal(frames, np.arange(len(t)))
                assert_allclose(pos[k], data.oMi[j].translation, rtol=0, atol=1e-6)
                R = pin.Quaternion(*np.roll(quat[k], 1)).normalized().matrix()  # w, x, y, z
                assert_allclose(R, data.oMi[j].rotation, rtol=0, atol=1e-6)
        # The loop closes in the page's own (single-precision) poses too.
        for c in constraints:
            ends = []
            for joint, place in ((c.joint1_id, c.joint1_placement),
                                 (c.joint2_id, c.joint2_placement)):
                _, pos, quat = keys[arm, joint]
                R = [pin.Quaternion(*np.roll(v, 1)).normalized().matrix() for v in quat]
                ends.append(np.array([Rk @ place.translation + p
                                      for Rk, p in zip(R, pos, strict=True)]))
            assert_allclose(ends[0], ends[1], rtol=0, atol=1e-6)
    # Every joint moves, passive ones included: each animated node leaves its first pose.
    for (arm, j), (_, pos, quat) in keys.items():
        assert np.abs(quat - quat[0]).max() + np.abs(pos - pos[0]).max() > 1e-3, (arm, j)


def test_delta_platform_follows_the_adept_cycle(delta):
    period = 2.0
    t = np.arange(int(period * FPS) + 1) / FPS
    scene = Scene("delta", delta, [Track("nominal", t, _reference_q(delta, period, t))])
    keys = _keyframes(scene_document(scene, fps=FPS))
    platform = delta.model.getJointId("Composite_px")  # the platform's three slides
    frames, pos, _ = keys["nominal", platform]
    # The task-space definition of the cycle; the reference is its inverse kinematics every
    # 5 ms joined by a C2 spline (error ~1e-9 m here), the page packs single precision
    # (~1e-7 m): 1e-6 m, against a 305 mm stroke.
    assert_allclose(pos, adept_point(delta.params, frames / FPS, period), rtol=0, atol=1e-6)
    assert np.ptp(pos[:, 0]) > 0.3  # it did cross


def test_task_path_figure_draws_the_cycle_and_the_platform(delta):
    # task_path.png of a Delta study: the adept cycle in grey, and the platform of the
    # nominal run by the closed-form kinematics, in the plane the cycle spans (x and z) [mm].
    duration = 0.5
    result = run_study(delta, make_laws("fl", delta), config=StudyConfig(
        samples=0, run=RunSettings(duration=duration, rate=1000.0)))
    ax = plot_task_path(result, delta).axes[0]
    path, traj = ax.lines[0], result.nominal["fl"]
    cycle = 1e3 * adept_point(delta.params, np.linspace(0.0, duration, 401), duration)
    # the plotted floats are the arrays given: round-off of the world mapping only
    assert_allclose(np.column_stack(path.get_data()), cycle[:, [0, 2]], rtol=0, atol=1e-9)
    platform = 1e3 * np.array([delta_fk(delta.params, q) for q in traj.q])
    assert_allclose(np.column_stack(ax.lines[1].get_data()), platform[:, [0, 2]], rtol=0,
                    atol=1e-9)
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x [mm]", "z [mm]")


# --- what the mechanism cannot follow, refused with its time ----------------------------------

def test_a_track_that_cannot_close_is_refused_with_its_time(fivebar):
    qa = np.array([fivebar.neutral(), fivebar.neutral(), [np.pi, 0.0]])  # elbows 0.58 m apart
    scene = Scene("fivebar", fivebar, [Track("nominal", [0.0, 0.1, 0.2], qa)])
    with pytest.raises(LoopClosureError, match=r"track 'nominal': cannot draw 'fivebar' at "
                                               r"t = 0.2 s: fivebar: the loop does not close"):
        scene_document(scene, fps=FPS)


def test_a_track_through_a_singularity_is_refused_with_its_time(fivebar):
    a = np.arccos(0.34 / 0.46)  # symmetric elbows 2 l2 = 0.46 m apart: distal links aligned
    qa = np.array([fivebar.neutral(), [np.pi - a, a]])
    scene = Scene("fivebar", fivebar, [Track("nominal", [0.0, 0.1], qa)])
    # Newton either reaches the stretched pose (cond(J_p) above the limit) or stalls at it
    with pytest.raises(ValueError, match=r"track 'nominal': cannot draw 'fivebar' at t = 0.1 s: "
                                         r"fivebar: (type-II|the loop does not close)"):
        scene_document(scene, fps=FPS)


def test_a_reference_the_mechanism_cannot_follow_is_refused_with_its_time(fivebar):
    # The arm's sinusoid (0.5 rad about home) takes the 5-bar's elbows more than 2 l2 apart:
    # the nominal run stops where the reference leaves the workspace, naming that time.
    ref = default_reference(fivebar)
    with pytest.raises(SimulationDiverged, match=r"law 'fl' diverged on the nominal plant: "
                                                 r"LoopClosureError: reference at t = ") as info:
        run_study(fivebar, make_laws("fl", fivebar),
                  config=StudyConfig(samples=0, run=RunSettings(duration=0.5)), reference=ref)
    stopped = float(re.search(r"reference at t = ([0-9.]+) s", str(info.value)).group(1))
    # the first time the closed-form elbows are 2 l2 apart, on a 0.1 ms grid
    P = fivebar.params
    t = np.arange(0.0, 0.5, 1e-4)
    gap = [np.linalg.norm(np.subtract(*fivebar_elbows(P, r))) for r in ref.sample(t)[0]]
    first = t[np.argmax(np.array(gap) > 2 * P.l2)]
    # the run reads the reference at the RK4 stages of its 1 ms steps: within one step after
    assert first - 1e-4 <= stopped <= first + 1e-3


# --- a mechanism of your own, and an MJCF file ------------------------------------------------

def test_a_users_own_mechanism_is_an_input(tmp_path):
    # Your own 5-bar (longer, heavier distal links): the study runs it and draws its plants
    # from its own parameter set; its nominal run is the same simulation written out by hand;
    # its report and plants are written for it.
    mine = FiveBarParams(l2=0.25, m2=0.4, name="mybar")
    plant = load_robot(mine)
    run = RunSettings(duration=0.05, rate=1000.0)
    result = run_study(plant, make_laws("fl", plant), config=StudyConfig(samples=1, run=run))
    assert result.robot == "mybar" and result.nominal["fl"].plant == "mybar"
    assert result.samples[0]["status"] == "ok"
    assert result.plants[0].plant.params.l2 != mine.l2  # drawn around the user's set
    by_hand = simulate(load_robot(mine), fl_controller(load_robot(mine)),
                       study_reference(load_robot(mine), 0.05), 0.05, rate=1000.0)
    # the same run on fresh objects (the law's Newton seed reset at the start): equal
    assert_allclose(result.nominal["fl"].q, by_hand.q, rtol=0, atol=0)
    write_results(result, tmp_path)
    assert "# Closed-loop study on `mybar`" in (tmp_path / "results.md").read_text()
    written = tmp_path / "plants" / "mybar_000.xml"
    assert written.read_text() == result.plants[0].plant.source_text()[0]
    assert load_robot(written).nq == 2  # the written MJCF loads back
    assert write_study_report(result, tmp_path, [], None, plant) == tmp_path / "report.html"


def test_an_mjcf_file_runs_its_nominal_plant_and_refuses_uncertain_ones(fivebar, tmp_path):
    # An MJCF file as it is: no parameter set, so no task path of its own and nothing to
    # perturb; given a reference, its nominal study runs, and uncertain plants are refused.
    path = tmp_path / "mine.xml"
    path.write_text(fivebar.source_text()[0])
    plant = load_robot(path)
    assert plant.params is None and plant.task_path(1.0) is None
    ref = study_reference(fivebar, 0.05)  # the built-in's path, the same mechanism
    run = RunSettings(duration=0.05, rate=1000.0)
    result = run_study(plant, make_laws("fl", plant), config=StudyConfig(samples=0, run=run),
                       reference=ref)
    assert result.nominal["fl"].info["drift_m"] <= result.nominal["fl"].info["drift_bound_m"]
    with pytest.raises(ValueError, match="mine: an MJCF file without a parameter set cannot "
                                         "be perturbed"):
        run_study(plant, make_laws("fl", plant), config=StudyConfig(samples=1, run=run),
                  reference=ref)


# --- a real browser ---------------------------------------------------------------------------

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")


def _project(points, eye, target, width, height):
    """Pixel (column, row) of world points [m] through three.js's pinhole camera."""
    f = (target - eye) / np.linalg.norm(target - eye)
    r = np.cross(f, [0.0, 0.0, 1.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    d = np.asarray(points) - eye
    x, y, z = d @ r, d @ u, d @ f
    tan = np.tan(np.radians(CAMERA_FOV / 2))
    ndc_x, ndc_y = x / (z * tan * width / height), y / (z * tan)
    return np.column_stack([(ndc_x + 1) / 2 * width, (1 - ndc_y) / 2 * height])


def _draw_at(driver, seconds):
    driver.execute_script(
        "viewer.animator.pause(); viewer.animator.seek(arguments[0]); viewer.set_dirty();"
        "window.__drawn = false; requestAnimationFrame(() => requestAnimationFrame(() => "
        "{ window.__drawn = true; }));", seconds)
    end = time.monotonic() + 60
    while not driver.execute_script("return window.__drawn === true;"):
        assert time.monotonic() < end, "no frame drawn"
        time.sleep(0.1)


@pytest.mark.slow
@pytest.mark.parametrize("plant", ["fivebar", "delta"], indirect=True)
def test_report_renders_in_headless_chromium(plant, tmp_path):
    """The nominal mechanism is drawn where its closed-form kinematics puts it."""
    if CHROMIUM is None or CHROMEDRIVER is None:
        pytest.skip("Chromium is missing: apt-get install chromium chromium-driver")
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    duration = 1.0
    result = run_study(plant, make_laws("fl,hinf", plant),
                       config=StudyConfig(samples=0, run=RunSettings(duration=duration)))
    page = write_study_report(result, tmp_path, [], None, plant)
    traj = result.nominal["fl"]
    # the page's first scene, as the report makes it: its camera
    points_path, label = task_path_points(plant, duration)
    scene = Scene(f"{result.label('fl')}: nominal and uncertain plants", plant,
                  [Track("nominal plant", traj.t, traj.q)], path=points_path, path_label=label)
    eye, target = camera_view(scene)
    seconds = 0.5
    qa = np.array([np.interp(seconds, traj.t, traj.q[:, j]) for j in range(traj.q.shape[1])])
    params = plant.params
    if plant.name == "fivebar":  # midpoints of the two distal links, from the closed form
        tip = fivebar_fk(params, qa)
        points = [np.array([(e[0] + tip[0]) / 2, 0.0, (e[1] + tip[1]) / 2])
                  for e in fivebar_elbows(params, qa)]
    else:  # the platform's centre and the forearms' midpoints
        p = delta_fk(params, qa)
        points = [p] + [(e + p) / 2 for e in delta_elbows(params, qa)]
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                "--force-device-scale-factor=1", "--window-size=1000,800"):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    try:
        driver.get(page.resolve().as_uri())
        frame = driver.find_elements("css selector", "figure.rrr-scene iframe")[0]
        driver.execute_script("arguments[0].scrollIntoView();", frame)
        driver.switch_to.frame(frame)
        end = time.monotonic() + 90
        while not driver.execute_script(
                "return document.body.getAttribute('data-scene-ready') === '1';"):
            assert time.monotonic() < end, "the scene never became ready"
            time.sleep(0.2)
        driver.execute_script("viewer.gui.close();")
        width, height = driver.execute_script("return [window.innerWidth, window.innerHeight];")
        shots = []
        for visible in ("true", "false"):
            driver.execute_script(f"viewer.set_property(['meshcat', 'arms', 'nominal_plant'], "
                                  f"'visible', {visible});")
            _draw_at(driver, seconds)
            driver.switch_to.default_content()
            shots.append(frame.screenshot_as_png)
            driver.switch_to.frame(frame)
        logs = driver.get_log("browser")
    finally:
        driver.quit()
    import io

    import matplotlib.pyplot as plt

    a, b = ((plt.imread(io.BytesIO(png), format="png")[..., :3] * 255).astype(int)
            for png in shots)
    diff = np.abs(a - b).max(axis=2)
    border = 1  # the iframe's CSS border
    for col, row in _project(points, eye, target, width, height):
        c, r = int(round(col)) + border, int(round(row)) + border
        window = diff[r - 3:r + 4, c - 3:c + 4]
        assert window.size and window.max() > 40, (
            f"t = {seconds} s: nothing drawn at pixel ({c}, {r}) where the closed-form "
            f"kinematics puts the {plant.name} (largest change "
            f"{window.max() if window.size else None})")
    assert diff[5:40, 5:40].max() < 10  # far from it, nothing changes
    assert [e for e in logs if e["level"] == "SEVERE"] == []
