"""rrr_pin.report.closed_chain's report.html and the viewer's closed-chain scenes.

The keyframes are read back from the page (the MeshCat commands, msgpack in base64) and
checked against computations that do not go through the viewer: the loop's two anchor points
from Pinocchio's forward kinematics of a model built afresh from the MJCF, and the Delta's
platform against the adept cycle's task-space definition (``adept_point``). The browser test
(slow: ~30 s on the shared machine) opens the page in headless Chromium, as the serial report's.
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

from rrr_pin.campaign.closed_chain_study import (
    ChainStudyConfig,
    ChainStudyResult,
    adept_point,
    chain_reference,
)
from rrr_pin.model.closed_chain import LoopClosureError, load_closed_chain
from rrr_pin.model.mechanisms import (
    delta_elbows,
    delta_fk,
    fivebar_elbows,
    fivebar_fk,
    mechanism_params,
    perturb_mechanism,
)
from rrr_pin.report.closed_chain import chain_scenes, plant_params, write_chain_study
from rrr_pin.report.viewer import (
    CAMERA_FOV,
    Scene,
    Track,
    camera_view,
    full_configurations,
    scene_document,
)
from rrr_pin.sim.trajectory import Trajectory

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
        fh.write(chain.mjcf)
    try:
        model, constraints = pin.buildModelAndLegacyConstraintsFromMJCF(fh.name)
    finally:
        Path(fh.name).unlink()
    return model, list(constraints)


def _reference_q(chain, duration, times):
    ref = chain_reference(chain, duration)
    return np.array([ref(t)[0] for t in times])


@pytest.mark.parametrize("name", ["fivebar", "delta"])
def test_keyframes_close_the_loop(name):
    nominal = load_closed_chain(name)
    params, _ = perturb_mechanism(nominal.params, np.random.default_rng(3))
    ghost = load_closed_chain(params)
    duration = 1.0
    t = np.arange(int(duration * FPS) + 1) / FPS  # the viewer's frame times, exactly
    qa = _reference_q(nominal, duration, t)
    scene = Scene(name, nominal, [Track("nominal", t, qa),
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
                np.testing.assert_allclose(a.translation, b.translation, rtol=0, atol=1e-9)
            # ... and they are the page's keyframes: every animated joint's placement, packed
            # in single precision (~1e-7 m on a metre; 1e-6 bounds it).
            for (which, j), (frames, pos, quat) in keys.items():
                if which != arm:
                    continue
                np.testing.assert_array_equal(frames, np.arange(len(t)))
                np.testing.assert_allclose(pos[k], data.oMi[j].translation, rtol=0, atol=1e-6)
                R = pin.Quaternion(*np.roll(quat[k], 1)).normalized().matrix()  # w, x, y, z
                np.testing.assert_allclose(R, data.oMi[j].rotation, rtol=0, atol=1e-6)
        # The loop closes in the page's own (single-precision) poses too.
        for c in constraints:
            ends = []
            for joint, place in ((c.joint1_id, c.joint1_placement),
                                 (c.joint2_id, c.joint2_placement)):
                _, pos, quat = keys[arm, joint]
                R = [pin.Quaternion(*np.roll(v, 1)).normalized().matrix() for v in quat]
                ends.append(np.array([Rk @ place.translation + p
                                      for Rk, p in zip(R, pos, strict=True)]))
            np.testing.assert_allclose(ends[0], ends[1], rtol=0, atol=1e-6)
    # Every joint moves, passive ones included: each animated node leaves its first pose.
    for (arm, j), (_, pos, quat) in keys.items():
        assert np.abs(quat - quat[0]).max() + np.abs(pos - pos[0]).max() > 1e-3, (arm, j)


def test_delta_platform_follows_the_adept_cycle():
    chain = load_closed_chain("delta")
    period = 2.0
    t = np.arange(int(period * FPS) + 1) / FPS
    scene = Scene("delta", chain, [Track("nominal", t, _reference_q(chain, period, t))])
    keys = _keyframes(scene_document(scene, fps=FPS))
    platform = chain.model.getJointId("Composite_px")  # the platform's three slides
    frames, pos, _ = keys["nominal", platform]
    # The task-space definition of the cycle; the reference is its inverse kinematics every
    # 5 ms joined by a C2 spline (error ~1e-9 m here), the page packs single precision
    # (~1e-7 m): 1e-6 m, against a 305 mm stroke.
    np.testing.assert_allclose(pos, adept_point(chain.params, frames / FPS, period),
                               rtol=0, atol=1e-6)
    assert np.ptp(pos[:, 0]) > 0.3  # it did cross


def test_a_track_that_cannot_close_is_refused_with_its_time():
    chain = load_closed_chain("fivebar")
    qa = np.array([chain.neutral(), chain.neutral(), [np.pi, 0.0]])  # elbows 0.58 m apart
    scene = Scene("fivebar", chain, [Track("nominal", [0.0, 0.1, 0.2], qa)])
    with pytest.raises(LoopClosureError, match=r"track 'nominal': cannot draw the closed "
                                               r"chain 'fivebar' at t = 0.2 s: .*does not "
                                               r"close"):
        scene_document(scene, fps=FPS)


def test_plant_params_rebuild_the_perturbed_plant_exactly():
    nominal = mechanism_params("delta")
    params, factors = perturb_mechanism(nominal, np.random.default_rng(7))
    assert plant_params(nominal, factors) == params


def _fake_result(name, names, samples=1, duration=0.5, seed=0):
    """A study result from the reference itself (no simulation): the report layer's input."""
    nominal = load_closed_chain(name)
    t = np.linspace(0.0, duration, int(duration * 100) + 1)
    r = _reference_q(nominal, duration, t)
    rng = np.random.default_rng(seed)
    metrics, trajectories = [], []
    for i in range(samples + 1):
        factors = {} if i == 0 else perturb_mechanism(nominal.params, rng)[1]
        row = {"plant": "nominal" if i == 0 else f"sample{i - 1:03d}", "factors": factors}
        runs = {}
        for k, law in enumerate(names):
            q = r + 1e-4 * (i + k) * np.sin(2 * np.pi * t)[:, None]
            runs[law] = Trajectory(t=t, q=q, qd=np.zeros_like(q), r=r, tau=np.ones_like(q),
                                   controller=law, plant=row["plant"],
                                   info={"engine": "python", "drift_m": 1e-13 * (1 + k),
                                         "drift_bound_m": 1e-6},
                                   joint_names=nominal.joint_names)
            row[law] = {"rms_error_rad": 1e-4 * (i + k), "max_error_rad": 2e-4 * (i + k),
                        "rms_tau_Nm": 1.0, "drift_m": 1e-13 * (1 + k), "status": "ok"}
        metrics.append(row)
        trajectories.append(runs)
    return ChainStudyResult(
        config=ChainStudyConfig(mechanism=name, samples=samples, seed=seed,
                                duration=duration),
        names=list(names), labels=[f"law {n}" for n in names], metrics=metrics,
        trajectories=trajectories, reference="the mechanism's reference",
        claims=[{"claim": "a claim", "value": 1.5, "holds": True}])


def test_report_is_self_contained_and_covers_every_law(tmp_path):
    result = _fake_result("fivebar", ["fl", "hinf", "pd"], duration=0.3)
    paths = write_chain_study(result, tmp_path)
    assert paths[-1] == tmp_path / "report.html"
    text = paths[-1].read_text(encoding="utf-8")
    # no external resource: every script inline, every image a data: URI
    assert not re.search(r"<script[^>]*\bsrc=", text, re.I)
    assert not re.search(r"""(src|href)=["']?(https?:)?//""", text, re.I)
    assert "url(http" not in text
    images = re.findall(r'<img [^>]*src="([^"]*)"', text)
    assert len(images) == 2 and all(i.startswith("data:image/png;base64,") for i in images)
    assert base64.b64decode(images[0].split(",", 1)[1]) == (tmp_path /
                                                            "fig5_nominal.png").read_bytes()
    # one scene per law, nominal and its uncertain plant in each
    assert text.count('<figure class="rrr-scene"') == 3
    for label in ("law fl", "law hinf", "law pd"):
        assert f"<b>{label}: nominal and uncertain plants</b>" in text
    assert text.count("uncertain plant 0</span>") == 3
    assert text.count("tip circle (reference)</span>") == 3  # the reference's path, drawn
    # the claims, every law's columns, the settings with the drift and the reference
    assert "RMS error pd [rad]" in text and "a claim" in text
    assert "max_drift_m" in text and "drift_bound_m" in text
    assert "the mechanism&#x27;s reference" in text or "the mechanism's reference" in text


def test_scenes_skip_a_failed_run():
    result = _fake_result("fivebar", ["fl", "hinf"])
    result.trajectories[1]["hinf"] = None
    result.metrics[1]["hinf"]["status"] = "failed: test"
    fl, hinf = chain_scenes(result)
    assert [tr.label for tr in fl.tracks] == ["nominal plant", "uncertain plant 0"]
    assert [tr.label for tr in hinf.tracks] == ["nominal plant"]
    # the uncertain plant is drawn with its own perturbed lengths
    assert fl.tracks[1].robot.params == plant_params(mechanism_params("fivebar"),
                                                     result.metrics[1]["factors"])


# --- a real browser -------------------------------------------------------------------------

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
@pytest.mark.parametrize("name", ["fivebar", "delta"])
def test_report_renders_in_headless_chromium(name, tmp_path):
    """The nominal mechanism is drawn where its closed-form kinematics puts it."""
    if CHROMIUM is None or CHROMEDRIVER is None:
        pytest.skip("Chromium is missing: apt-get install chromium chromium-driver")
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    result = _fake_result(name, ["fl", "hinf"], samples=0, duration=1.0)
    path = write_chain_study(result, tmp_path)[-1]
    scene = chain_scenes(result)[0]
    eye, target = camera_view(scene)
    seconds = 0.5
    traj = result.trajectories[0]["fl"]
    qa = np.array([np.interp(seconds, traj.t, traj.q[:, j]) for j in range(traj.q.shape[1])])
    params = mechanism_params(name)
    if name == "fivebar":  # midpoints of the two distal links, from the closed form
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
        driver.get(path.resolve().as_uri())
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
            f"kinematics puts the {name} (largest change {window.max() if window.size else None})")
    assert diff[5:40, 5:40].max() < 10  # far from it, nothing changes
    assert [e for e in logs if e["level"] == "SEVERE"] == []

def test_scene_path_is_checked():
    chain = load_closed_chain("fivebar")
    track = Track("nominal", [0.0], [chain.neutral()])
    with pytest.raises(ValueError, match=r"expected path of shape \(K, 3\) with K >= 2, got "
                                         r"\(4, 2\)"):
        Scene("fivebar", chain, [track], path=np.zeros((4, 2)))
    with pytest.raises(ValueError, match="path must be finite"):
        Scene("fivebar", chain, [track], path=[[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])


def test_claims_table_shows_a_failed_runs_nan_drift():
    from rrr_pin.report.closed_chain import claims_table

    result = _fake_result("fivebar", ["fl", "hinf"], samples=0)
    result.metrics[0]["hinf"].update(drift_m=float("nan"), status="failed: test")
    row = [line for line in claims_table(result).splitlines() if line.startswith("| nominal")]
    # max(1e-13, nan) would be 1e-13: the failed run's NaN must not be hidden
    assert row[0].endswith("| nan |")
    assert "- nominal hinf: failed: test" in claims_table(result)


def test_a_track_through_a_singularity_is_refused_with_its_time():
    chain = load_closed_chain("fivebar")
    a = np.arccos(0.34 / 0.46)  # symmetric elbows 2 l2 = 0.46 m apart: distal links aligned
    qa = np.array([chain.neutral(), [np.pi - a, a]])
    scene = Scene("fivebar", chain, [Track("nominal", [0.0, 0.1], qa)])
    # Newton either reaches the stretched pose (cond(J_p) above the limit) or stalls at it
    with pytest.raises(ValueError, match=r"track 'nominal': cannot draw the closed chain "
                                         r"'fivebar' at t = 0.1 s: fivebar: (type-II|the loop "
                                         r"does not close)"):
        scene_document(scene, fps=FPS)
