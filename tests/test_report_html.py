"""rrr_pin.report.html: one self-contained report.html, its size bound, and a real browser.

The browser test opens the report from disk in headless Chromium (Debian's ``chromium`` and
``chromium-driver``, driven by selenium), waits for the MeshCat scene, and checks that the
nominal arm is drawn where DH forward kinematics (``rrr_pin.model.dh``, independent of Pinocchio and
of the viewer) projected through the scene's camera puts it, at two instants of the animation,
and that the console shows no error. The README's screenshot is made by
``scripts/report_screenshot.py`` from the default study's report.
"""

import base64
import io
import json
import math
import re
import shutil
import time

import matplotlib.pyplot as plt
import numpy as np
import pytest

from rrr_pin.model.dh import forward_kinematics, paper_params
from rrr_pin.model.dynamics import load_robot
from rrr_pin.outputs import OutputNotWritable, check_writable
from rrr_pin.report.html import REPORT_MAX_BYTES, report_html, write_report_html
from rrr_pin.report.viewer import CAMERA_FOV, Scene, Track, camera_view

TABLE_MD = """| Controller | RMS error [rad] |
|---|---|
| FL alone | 1.5e-4 |
| H-inf + FL <b>x</b> | 6.4e-6 |
"""
DESIGN = {"gamma_min": 2.1436, "K": {"gain": 47.4011, "zeros": [-134.752, -12.1674],
                                     "poles": [-513.371, -0.19]},
          "margins": {"robust_stability_dB": 10.5, "robust_performance": False},
          "emax": float("nan")}


def _q(t, phase=0.0):
    return 0.5 * np.sin(np.pi * t[:, None] + 2 * np.pi * np.arange(3) / 3 + phase)


def _ghost_offsets(k):
    # Each uncertain plant drifts away from the nominal arm (growing with time).
    return np.array([0.25, -0.2, 0.15]) * (1 + k) / 3


def _scene(robot, title="H-inf + FL", ghosts=3, duration=2.0, dt=1e-3):
    t = np.arange(0.0, duration + dt / 2, dt)
    tracks = [Track("nominal", t, _q(t))]
    tracks += [Track(f"plant {k}", t, _q(t) + _ghost_offsets(k) * (t / duration)[:, None],
                     opacity=0.35) for k in range(ghosts)]
    return Scene(title, robot, tracks)


@pytest.fixture(scope="module")
def figure(tmp_path_factory):
    path = tmp_path_factory.mktemp("fig") / "error.png"
    fig, ax = plt.subplots(figsize=(4, 3))
    t = np.linspace(0, 4, 100)
    ax.plot(t, 1e-4 * np.sin(np.pi * t), label="joint 1")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("tracking error [rad]")
    ax.legend()
    fig.savefig(path, dpi=60)
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------------
# The page itself.


def test_report_is_self_contained(rrr, figure, tmp_path):
    path = write_report_html(tmp_path / "out" / "report.html", title="RRR study",
                             tables=[("Results", TABLE_MD)], figures=[figure], design=DESIGN,
                             scenes=[_scene(rrr, duration=0.5)])
    text = path.read_text(encoding="utf-8")
    # no external resource: every script inline, every image a data: URI
    assert not re.search(r"<script[^>]*\bsrc=", text, re.I)
    assert not re.search(r"""(src|href)=["']?(https?:)?//""", text, re.I)
    assert "url(http" not in text
    images = re.findall(r'<img [^>]*src="([^"]*)"', text)
    assert len(images) == 1 and images[0].startswith("data:image/png;base64,")
    # the inlined figure is the file, byte for byte (decoded independently)
    assert base64.b64decode(images[0].split(",", 1)[1]) == figure.read_bytes()
    assert text.count('<figure class="rrr-scene"') == 1


def test_tables_markdown_and_html(rrr):
    page = report_html(title="t", tables=[("md", TABLE_MD),
                                          ("raw", "<table><tr><td>as is</td></tr></table>")])
    assert "<th>Controller</th>" in page and "<td>1.5e-4</td>" in page
    assert "&lt;b&gt;x&lt;/b&gt;" in page  # raw HTML inside Markdown is escaped
    assert "<table><tr><td>as is</td></tr></table>" in page
    with pytest.raises(TypeError, match=r"tables\[0\]"):
        report_html(title="t", tables=[("only a caption",)])


def test_design_summary_readable():
    page = report_html(title="t", design=DESIGN)
    for text in ("gamma_min", "2.1436", "47.4011", "-134.752, -12.1674", "robust_performance",
                 "<td>no</td>", "<td>NaN</td>"):
        assert text in page, text
    with pytest.raises(TypeError, match="design"):
        report_html(title="t", design=[1, 2])


def test_missing_figure(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothere.png"):
        report_html(title="t", figures=[tmp_path / "nothere.png"])


def test_check_writable(tmp_path):
    assert check_writable(tmp_path / "a" / "b") == (tmp_path / "a" / "b").resolve()
    assert (tmp_path / "a" / "b").is_dir() and not any((tmp_path / "a" / "b").iterdir())
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    with pytest.raises(OutputNotWritable, match="file.txt.*not a folder"):
        check_writable(blocker)
    with pytest.raises(OutputNotWritable, match=r"file.txt/sub.*not writable"):
        check_writable(blocker / "sub")


def test_size_bound_two_controllers_eleven_arms(rrr, figure):
    # The bound: 10 s at 30 frames/s with 11 arms, here for two controllers.
    scenes = [_scene(rrr, "FL alone", ghosts=10, duration=10.0),
              _scene(rrr, "H-inf + FL", ghosts=10, duration=10.0)]
    page = report_html(title="t", tables=[("Results", TABLE_MD)], figures=[figure],
                       design=DESIGN, scenes=scenes)
    size = len(page.encode("utf-8"))
    assert size <= REPORT_MAX_BYTES
    # a tighter budget decimates frames and is kept too
    small = report_html(title="t", scenes=scenes, max_bytes=4_000_000)
    assert len(small.encode("utf-8")) <= 4_000_000
    # a budget no scene fits (the viewer script alone is 0.85 MB): the page is still made,
    # and says which scenes are not drawn (before issue 31: ViewerSizeError after the study)
    tiny = report_html(title="t", scenes=scenes, max_bytes=1_500_000)
    assert tiny.count("not drawn, as even one arm exceeds the page's size budget") == 2
    assert len(tiny.encode("utf-8")) <= 1_500_000


# ---------------------------------------------------------------------------------------------
# A real browser.

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")


def _browser(width=1200, height=900):
    if CHROMIUM is None or CHROMEDRIVER is None:
        pytest.skip("Chromium is missing: install Debian's chromium and chromium-driver "
                    "(apt-get install chromium chromium-driver) to run the browser test")
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed "
                                    "(pip install '.[test]')")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                "--force-device-scale-factor=1", f"--window-size={width},{height}"):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)


def _wait(driver, script, timeout=60.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if driver.execute_script(script):
            return
        time.sleep(0.2)
    raise AssertionError(f"timed out waiting for: {script}")


def _pixels(png: bytes) -> np.ndarray:
    return (plt.imread(io.BytesIO(png), format="png")[..., :3] * 255).astype(int)


def _project(points, eye, target, width, height):
    """Pixel (column, row) of world points [m] through a pinhole camera (three.js's)."""
    f = (target - eye) / np.linalg.norm(target - eye)
    r = np.cross(f, [0.0, 0.0, 1.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    d = np.asarray(points) - eye
    x, y, z = d @ r, d @ u, d @ f
    tan = math.tan(math.radians(CAMERA_FOV / 2))
    ndc_x, ndc_y = x / (z * tan * width / height), y / (z * tan)
    return np.column_stack([(ndc_x + 1) / 2 * width, (1 - ndc_y) / 2 * height])


def _frame_state(driver, seconds):
    """Pause the animation at ``seconds`` and wait for two rendered frames."""
    driver.execute_script(
        "viewer.animator.pause(); viewer.animator.seek(arguments[0]); viewer.set_dirty();"
        "window.__drawn = false; requestAnimationFrame(() => requestAnimationFrame(() => "
        "{ window.__drawn = true; }));", seconds)
    _wait(driver, "return window.__drawn === true;")


def test_report_renders_in_headless_chromium(rrr, figure, tmp_path):
    scene = _scene(rrr)
    path = write_report_html(tmp_path / "report.html", title="RRR: H-infinity + FL study",
                             tables=[("Results", TABLE_MD)], figures=[figure],
                             design=DESIGN, scenes=[scene])
    driver = _browser()
    try:
        driver.get(path.resolve().as_uri())
        frame = driver.find_element("css selector", "figure.rrr-scene iframe")
        driver.execute_script("arguments[0].scrollIntoView();", frame)
        driver.switch_to.frame(frame)
        _wait(driver, "return document.body.getAttribute('data-scene-ready') === '1';")
        time.sleep(1.0)  # let it play a moment
        driver.execute_script("viewer.gui.close();")
        width, height = driver.execute_script(
            "return [window.innerWidth, window.innerHeight];")
        eye, target = camera_view(scene)
        params = paper_params()
        for seconds in (0.5, 1.25):  # two poses: the arm moves
            _frame_state(driver, seconds)
            driver.switch_to.default_content()
            with_arm = _pixels(frame.screenshot_as_png)
            driver.switch_to.frame(frame)
            driver.execute_script("viewer.set_property(['meshcat', 'arms', 'nominal'], "
                                  "'visible', false);")
            _frame_state(driver, seconds)
            driver.switch_to.default_content()
            without_arm = _pixels(frame.screenshot_as_png)
            driver.switch_to.frame(frame)
            driver.execute_script("viewer.set_property(['meshcat', 'arms', 'nominal'], "
                                  "'visible', true);")
            # The nominal arm at this instant, from DH kinematics: midpoints of links 2, 3.
            q = _q(np.array([seconds]))[0]
            o = [T[:3, 3] for T in forward_kinematics(params, q)]
            points = [(o[1] + o[2]) / 2, (o[2] + o[3]) / 2, o[1] + 0.25 * (o[2] - o[1])]
            diff = np.abs(with_arm - without_arm).max(axis=2)
            border = 1  # the iframe's CSS border
            for col, row in _project(points, eye, target, width, height):
                c, r = int(round(col)) + border, int(round(row)) + border
                window = diff[r - 3:r + 4, c - 3:c + 4]
                assert window.size and window.max() > 40, (
                    f"t={seconds} s: no arm drawn at pixel ({c}, {r}) where DH kinematics "
                    f"puts it (largest change {window.max() if window.size else None})")
            # far from the arm (a corner of the canvas) nothing changes
            assert diff[5:40, 5:40].max() < 10
        logs = driver.get_log("browser")
    finally:
        driver.quit()
    errors = [entry for entry in logs if entry["level"] == "SEVERE"]
    assert errors == [], errors


# --- the study's and the campaign's report.html, and the report layer's text ----------------


@pytest.fixture(scope="module")
def small_study(plant):
    from rrr_pin.campaign.runner import RunSettings, make_laws
    from rrr_pin.campaign.study import StudyConfig, run_study

    laws = make_laws("fl,pd", plant)
    run = RunSettings(duration=0.2, rate=1000.0)
    return run_study(plant, laws, config=StudyConfig(run=run, samples=2, jobs=1))


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_study_report_draws_the_studys_own_plants(small_study, plant, tmp_path, monkeypatch):
    # 2 laws x 2 plants: the scenes draw the study's plant objects (each uncertain plant with
    # its own perturbed dimensions), none rebuilt from a description (URDF or MJCF).
    import rrr_pin.model.closed_chain as closed_chain
    import rrr_pin.model.dynamics as dynamics
    import rrr_pin.report.results as results

    monkeypatch.setattr(dynamics, "robot_from_xml", None)  # a rebuild would fail here
    monkeypatch.setattr(closed_chain, "_from_mjcf", None)
    drawn = []
    real = results.Track

    def track(*args, **kwargs):
        drawn.append(kwargs.get("robot"))
        return real(*args, **kwargs)

    monkeypatch.setattr(results, "Track", track)
    path = results.write_study_report(small_study, tmp_path, [], {"gamma": 2.1}, plant)
    assert path == tmp_path / "report.html"
    ghosts = [p.plant for p in small_study.plants]
    assert [r for r in drawn if r is not None] == ghosts * 2  # each law's scene, same objects
    text = path.read_text()
    assert text.count("uncertain plant 1</span>") == 2  # a ghost in each law's scene
    assert f"rrr-pin study on {plant.name}" in text


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_study_report_skips_a_failed_run(small_study, plant, tmp_path):
    # A run that ended on an uncertain plant has no trajectory: that law's scene draws the
    # others only.
    import copy
    import dataclasses

    from rrr_pin.report.results import write_study_report

    samples = copy.copy(small_study.samples)
    samples[1] = {**samples[1], "status": "diverged: pd: test",
                  "trajectories": {"fl": samples[1]["trajectories"]["fl"]},
                  "metrics": {"fl": samples[1]["metrics"]["fl"]}}
    failed = dataclasses.replace(small_study, samples=samples)
    text = write_study_report(failed, tmp_path, [], None, plant).read_text()
    assert text.count("uncertain plant 0</span>") == 2  # in both laws' scenes
    assert text.count("uncertain plant 1</span>") == 1  # FL's scene only


@pytest.mark.parametrize("reproduced, plant", [("rrr", "rrr"), ("fivebar", "fivebar")],
                         indirect=True, ids=["rrr", "fivebar"])
def test_study_report_is_self_contained_and_covers_every_law(reproduced, plant):
    # The shared `rrr-pin reproduce` run's page.
    out = reproduced.out
    text = (out / "report.html").read_text(encoding="utf-8")
    # no external resource: every script inline, every image a data: URI
    assert not re.search(r"<script[^>]*\bsrc=", text, re.I)
    assert not re.search(r"""(src|href)=["']?(https?:)?//""", text, re.I)
    assert "url(http" not in text
    images = re.findall(r'<img [^>]*src="([^"]*)"', text)
    pngs = sorted(out.glob("*.png"))
    assert len(images) == len(pngs) and all(i.startswith("data:image/png;base64,")
                                            for i in images)
    inlined = {base64.b64decode(i.split(",", 1)[1]) for i in images}
    assert inlined == {p.read_bytes() for p in pngs}  # each figure, byte for byte
    # one scene per law, the nominal and its uncertain plants in each
    assert text.count('<figure class="rrr-scene"') == 2
    for label in ("FL alone", "H-infinity + FL"):
        assert f"<b>{label}: nominal and uncertain plants</b>" in text
    assert text.count("uncertain plant 0</span>") == text.count("uncertain plant 1</span>") == 2
    # a plant with a task path has it drawn in each scene, the others none
    found = plant.task_points(0.3)
    if found is None:
        assert "(reference)</span>" not in text
    else:
        assert text.count(f" {found[1]}</span>") == 2  # e.g. the 5-bar's tip circle
    # the tables: results.md's, with the settings and the reference
    assert "| Uncertain plants: RMS error FL alone / H-inf+FL" not in text  # as HTML, not md
    assert "<td>Uncertain plants: RMS error FL alone / H-inf+FL [-] (Fig. 6c)</td>" in text
    # issue 50: every failed design check in the headline, before the tables. The paper's
    # design misses its robust performance barrier (sec. 4.1: the RPB and RSB intersect), so
    # the page lists it first, with the margin results.json records.
    design = json.loads((out / "results.json").read_text())["design"]
    assert design["robust_performance"]["ok"] is False
    head = text.index("Design checks not passed")
    assert head < text.index("Study tables")
    margin = design["robust_performance"]["margin_db"]
    assert "robust_performance: ok = no (worst_frequency = " in text[head:]
    assert f"margin_db = {margin:.3g})" in text[head:text.index("Study tables")]


@pytest.mark.parametrize("where", ["example-robot-data", "copied"])
def test_study_report_warns_of_missing_meshes_once(where, tmp_path):
    # UR5 from example-robot-data: the plants' package:// meshes resolve where the nominal's
    # do (before: one 1.3 kB warning per plant and law). A copy of its URDF outside the
    # package: the meshes are missing for the nominal and every plant, warned about once.
    import warnings

    from rrr_pin.campaign.runner import RunSettings, make_laws
    from rrr_pin.campaign.study import StudyConfig, run_study
    from rrr_pin.model.robots import erd_urdf_path
    from rrr_pin.report.geometry import MissingMeshWarning
    from rrr_pin.report.results import write_study_report

    source = "ur5"
    if where == "copied":
        source = tmp_path / "ur5.urdf"
        source.write_text(erd_urdf_path("ur5").read_text())
    robot = load_robot(source)
    run = RunSettings(duration=0.02, engine="python")
    study = run_study(robot, make_laws("fl,pd", robot),
                      config=StudyConfig(run=run, samples=2, jobs=1))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        write_study_report(study, tmp_path, [], None, robot)
    meshes = [w for w in caught if issubclass(w.category, MissingMeshWarning)]
    assert len(meshes) == (0 if where == "example-robot-data" else 1)
    if meshes:
        assert len(meshes[0].message.missing) == 14  # 7 visual + 7 collision meshes of the UR5


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_study_summary_lines(small_study):
    from rrr_pin.report.results import summary_lines

    s = small_study.to_json()["summary"]
    lines = summary_lines(small_study, s)
    assert lines[0] == "nominal max |e| [rad]: " + ", ".join(
        f"{k} {v:.3g}" for k, v in s["nominal_max_error"].items())
    ratio = s["error_ratio_uncertain"]["pd"]
    assert lines[1].startswith(f"uncertain (2 plants): RMS error fl / pd = {ratio:.3g} ")
    assert len(lines) == 2  # no certificate, nothing diverged


@pytest.fixture(scope="module")
def small_campaign(rrr):
    import rrr_pin.campaign.montecarlo as mc
    from rrr_pin.campaign.runner import RunSettings, make_laws

    settings = mc.CampaignSettings(samples=3, run=RunSettings(duration=0.2, rate=1000.0,
                                                            engine="python"))
    return mc.run_campaign(rrr, make_laws("fl,pd", rrr), settings, jobs=1)


def test_campaign_report_and_summary_lines(small_campaign, tmp_path):
    from rrr_pin.campaign.montecarlo import campaign_summary
    from rrr_pin.report.campaign import summary_lines, write_campaign_report

    s = campaign_summary(small_campaign)
    path = write_campaign_report(small_campaign, s, tmp_path)
    text = path.read_text()
    assert path == tmp_path / "report.html" and "<img" not in text  # no montecarlo.png here
    m = s["pd_rms_torque"]  # in the page's table, not in the terminal's
    assert (f"<td>pd_rms_torque</td>\n<td>N m</td>\n<td>{m['median']:.4g}</td>" in text)
    lines = summary_lines(small_campaign, s)
    assert lines[0] == "every controller ran on 3, a run diverged on 0"
    assert lines[1] == "per law: fl ran on 3, pd ran on 3"  # issue 50: the status per law
    # the engines that ran the rows, as the rows record them
    ran = {law: {r[f"{law}_engine"] for r in small_campaign.rows} for law in ("fl", "pd")}
    assert lines[2] == "engines that ran: " + "; ".join(
        f"{law} {e.pop()} 3" for law, e in ran.items())
    share = 100 * s["fraction_better"]["pd"]
    assert lines[3] == f"pd better than fl on {share:.1f} % of the plants"
    assert lines[4].split() == ["metric", "median", "p95", "worst"]
    assert [line.split()[0] for line in lines[5:]] == [
        "fl_rms_error", "fl_max_error", "error_ratio_pd", "torque_ratio_pd", "pd_rms_error",
        "pd_max_error"]


def test_failed_checks_lists_every_false_verdict_with_its_path():
    from rrr_pin.report.results import failed_checks

    record = {"gamma": 2.1, "robust_stability": {"ok": True, "margin_db": 1.0},
              "robust_performance": {"ok": False, "margin_db": -10.63},
              "reduction": {"inner": {"guaranteed": False, "b": 0.4}},
              "certificate": {"certified": True}}
    assert failed_checks(record) == ["robust_performance: ok = no (margin_db = -10.6)",
                                     "reduction.inner: guaranteed = no (b = 0.4)"]
    assert failed_checks({"robust_stability": {"ok": True}}) == [] == failed_checks(None)


def test_design_summary_and_lines_agree():
    from rrr_pin.report.design import design_lines, design_summary, study_design
    from rrr_pin.robust.loopshaping import design

    d = design(lam=45.0, n=2)
    out = design_summary(d)
    lines = design_lines(d)
    assert lines[1] == (f"gamma_min = {out['gamma_min']:.4f}   gamma = {out['gamma']:.4f}   "
                        f"emax = 1/gamma = {out['emax']:.4f}")
    assert lines[2] == f"full-order K: gain {out['K_full']['gain']:.6g}"
    assert lines[-1].startswith("robust performance: ")
    recorded = study_design(d, full_order=True)
    assert recorded["K_used"] == "full" and recorded["K"] == out["K_full"]
    assert study_design(d)["K"] == out["K_reduced"]


def test_stress_lines_show_missing_values_as_dashes():
    from rrr_pin.report.stress import stress_lines

    result = {"robot": "rrr", "what": "actuator transport delay tau_d", "unit": "s",
              "budget_rad": 0.05, "settings": {"rate_hz": 1000.0}, "elapsed_s": 1.23,
              "rows": [{"controller": "fl", "predicted": 0.005972, "simulated": None,
                        "agreement": None, "guaranteed": 0.001062}]}
    lines = stress_lines(result)
    assert lines[0] == ("rrr: actuator transport delay tau_d [s], budget 0.05 rad RMS, "
                        "1000 Hz, 1.2 s")
    assert lines[2].split() == ["fl", "0.005972", "-", "-", "0.001062"]


def test_comparison_lines_fail_on_nan_and_above_rtol():
    # A NaN difference is a failure, never "ok" (NaN <= rtol is False).
    from rrr_pin.report.dynamics import comparison_lines

    result = {"M": {"abs": 1e-12, "scale": 2.0, "rel": 5e-13},
              "V": {"abs": 1e-6, "scale": 1.0, "rel": 1e-6},
              "G": {"abs": math.nan, "scale": 9.8, "rel": math.nan}}
    lines, failed = comparison_lines(result, 1e-9)
    assert failed == ["V", "G"]
    assert [line.split()[-1] for line in lines[1:4]] == ["ok", "FAIL", "FAIL"]
    assert lines[-1] == "FAIL: V, G differ by more than rtol = 1e-09"
    assert comparison_lines({"M": result["M"]}, 1e-9)[0][-1] == (
        "OK: all relative differences <= rtol = 1e-09")
