"""Screenshot of a ``report.html``'s 3D animation in headless Chromium (the README's picture).
===========================================================================================

The README's ``docs/figures/report.png`` is made from the default study, so that it shows
what ``rrr-pin reproduce`` writes::

    rrr-pin reproduce --out results
    python scripts/report_screenshot.py results/report.html docs/figures/report.png

It opens the report from disk, scrolls scene ``--scene`` (0-based, in the page's order) into
view, waits until MeshCat has drawn it, pauses the animation at ``--time`` seconds with the
controls open, and saves the page's viewport (``--width`` x ``--height`` pixels).

Needs, besides the project: Chromium and its WebDriver (Debian/Ubuntu:
``apt-get install chromium chromium-driver``; ``--chromium`` and ``--chromedriver`` name other
binaries) and selenium (in the ``test`` extra: ``pip install '.[test]'``). No network is used.
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path


def _wait(driver, script: str, timeout: float) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if driver.execute_script(script):
            return
        time.sleep(0.2)
    raise RuntimeError(f"timed out after {timeout:g} s waiting for: {script}")


def screenshot(report: Path, out: Path, scene: int = 1, seconds: float = 3.0,
               width: int = 1200, height: int = 680, chromium: str | None = None,
               chromedriver: str | None = None, timeout: float = 120.0) -> Path:
    """Save a screenshot of scene ``scene`` of ``report`` paused at ``seconds`` to ``out``."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                "--force-device-scale-factor=1", f"--window-size={width},{height}"):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(chromedriver), options=options)
    try:  # the page's viewport, exactly (--window-size also counts the window's frame)
        driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {
            "width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})
        driver.get(report.resolve().as_uri())
        frames = driver.find_elements("css selector", "figure.rrr-scene iframe")
        if not 0 <= scene < len(frames):
            raise ValueError(f"--scene {scene}: {report} has {len(frames)} scenes "
                             f"(0 to {len(frames) - 1})")
        frame = frames[scene]
        driver.execute_script("arguments[0].closest('figure').scrollIntoView({block: 'start'});",
                              frame)
        driver.switch_to.frame(frame)
        _wait(driver, "return document.body.getAttribute('data-scene-ready') === '1';",
              timeout)
        driver.execute_script(
            "viewer.animator.pause(); viewer.animator.seek(arguments[0]);"
            "viewer.animator.display_progress(arguments[0]); viewer.set_dirty();"
            "window.__drawn = false; requestAnimationFrame(() => requestAnimationFrame(() => "
            "{ window.__drawn = true; }));", seconds)
        _wait(driver, "return window.__drawn === true;", timeout)
        driver.switch_to.default_content()
        out.parent.mkdir(parents=True, exist_ok=True)
        if not driver.save_screenshot(str(out)):
            raise RuntimeError(f"Chromium could not write {out}")
    finally:
        driver.quit()
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("report", type=Path, help="a report.html (e.g. results/report.html)")
    parser.add_argument("out", type=Path, help="PNG to write (e.g. docs/figures/report.png)")
    parser.add_argument("--scene", type=int, default=1,
                        help="which 3D scene, 0-based (1: the second, H-inf + FL in a study)")
    parser.add_argument("--time", type=float, default=3.0,
                        help="instant of the animation shown [s] (3.0)")
    parser.add_argument("--width", type=int, default=1200, help="viewport width [px] (1200)")
    parser.add_argument("--height", type=int, default=680, help="viewport height [px] (680)")
    parser.add_argument("--chromium", default=shutil.which("chromium")
                        or shutil.which("chromium-browser"), help="Chromium binary")
    parser.add_argument("--chromedriver", default=shutil.which("chromedriver"),
                        help="ChromeDriver binary (Debian's chromium-driver)")
    args = parser.parse_args(argv)
    if not args.report.is_file():
        parser.error(f"{args.report}: no such file (write it with `rrr-pin reproduce`)")
    if args.chromium is None or args.chromedriver is None:
        parser.error("Chromium and ChromeDriver are needed (Debian/Ubuntu: apt-get install "
                     "chromium chromium-driver), or name them with --chromium/--chromedriver")
    try:
        import selenium  # noqa: F401
    except ImportError:
        parser.error("selenium is needed: pip install '.[test]' (or pip install selenium)")
    path = screenshot(args.report, args.out, args.scene, args.time, args.width, args.height,
                      args.chromium, args.chromedriver)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
