"""The live view in a real headless browser (Debian's chromium through chromium-driver,
driven by selenium): a ``handrig demo --view`` run's page draws the hand and moves it,
its relax button relaxes the rig, its e-stop button ends the run with torque off.

Skips only when chromium or its driver is not installed (``make browser-deps``; CI
installs them). ``HANDRIG_VIEW_SCREENSHOT=FILE.png`` also writes the page's picture
for the docs (docs/view.png is made this way).
"""

from __future__ import annotations

import io
import json
import os
import queue
import re
import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

CHROMIUM = shutil.which("chromium")
DRIVER = shutil.which("chromedriver")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(CHROMIUM is None or DRIVER is None,
                       reason="Debian's chromium and chromium-driver are not installed: "
                       "run `make browser-deps` as root (CI does)"),
]
FRAMES = 20000  # 100 s at 200 Hz: the test ends the run itself
SKELETON_RGB = (60, 200, 255)


def chromium(tmp: Path) -> Any:
    """Headless Debian chromium with WebGL on SwiftShader (no GPU, no display)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
                "--window-size=1200,900", f"--user-data-dir={tmp}"):
        opts.add_argument(arg)
    return webdriver.Chrome(options=opts, service=Service(executable_path=str(DRIVER)))


ROOT = Path(__file__).resolve().parents[4]


class ViewRun:
    """``handrig COMMAND ... --view 127.0.0.1:0 --json`` in a subprocess; its view URL
    from the line it prints at the start."""

    def __init__(self, *argv: str) -> None:
        env = {**os.environ, "MUJOCO_GL": "egl"}
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "handrig.cli", *argv, "--view", "127.0.0.1:0", "--json"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        self.lines: queue.Queue[str] = queue.Queue()
        self.stderr: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()
        self.url = self._wait_url()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.stderr.append(line)
            self.lines.put(line)

    def _wait_url(self) -> str:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=1)
            except queue.Empty:
                if self.proc.poll() is not None:
                    break
                continue
            found = re.search(r"view: (http://\S+)", line)
            if found:
                return found.group(1)
        raise AssertionError("no view URL printed:\n" + "".join(self.stderr))

    def summary(self, timeout_s: float = 60) -> dict[str, Any]:
        try:
            out, _ = self.proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:  # say what the run said before it hung
            self.kill()
            raise AssertionError(f"the run did not end within {timeout_s:g} s; its last "
                                 "lines:\n" + "".join(self.stderr[-30:])) from None
        return json.loads(out.strip().splitlines()[-1])

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


def wait_for(check: Any, timeout_s: float, what: str) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}")


def shot_after_moving(element: Any, moved: Any, timeout_s: float = 10.0) -> np.ndarray:
    """Screenshots of ``element`` every 0.2 s until ``moved(shot)`` (the hand has moved
    since the first shot) or ``timeout_s``; the last shot, for the test to check (it
    fails there when nothing moved)."""
    deadline = time.monotonic() + timeout_s
    while True:
        time.sleep(0.2)
        shot = pixels(element.screenshot_as_png)
        if moved(shot) or time.monotonic() > deadline:
            return shot


def pixels(png: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(np.int16)


def save_small(png: bytes, path: str, width: int = 900) -> None:
    """The page's picture for the docs: ``width`` pixels wide, 128 colours."""
    from PIL import Image

    image = Image.open(io.BytesIO(png)).convert("RGB")
    image = image.resize((width, round(image.height * width / image.width)), Image.LANCZOS)
    image.quantize(128).save(path, optimize=True)


def skin(rgb: np.ndarray) -> np.ndarray:
    """The puppet's skin colour (rgba 0.85 0.68 0.58, lit): warm, red over green over blue."""
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (r > 110) & (r > g + 12) & (g > b + 4) & (r - b > 30)


@pytest.fixture
def demo() -> Iterator[ViewRun]:
    run = ViewRun("demo", "--frames", str(FRAMES))
    try:
        yield run
    finally:
        run.kill()


def test_page_draws_and_moves_the_hand_relaxes_and_estops(demo: ViewRun, tmp_path: Path
                                                          ) -> None:
    from selenium.webdriver.common.by import By

    browser = chromium(tmp_path / "profile")
    shooting = bool(os.environ.get("HANDRIG_VIEW_SCREENSHOT"))
    try:
        # the docs' picture at the full rate; the test itself as a page without a GPU draws
        browser.get(with_full(demo.url) if shooting else demo.url)
        wait_for(lambda: browser.execute_script("return window.handrigView.framesDrawn()") > 5,
                 90, "the page to draw frames")
        view = browser.execute_script("return window.handrigView")
        assert view["softwareGL"] is True  # headless chromium: SwiftShader
        if not shooting:  # so it spares the CPU: at most 15 draws a second
            assert (view["pixelRatio"], view["maxDrawHz"]) == (1, 15)
            fps = browser.find_element(By.ID, "viewfps")  # written once a second
            wait_for(lambda: "add ?full to the URL" in fps.text, 10, "the page's note on its rate")
        puppet = browser.find_element(By.ID, "puppet")
        skeleton_view = browser.find_element(By.ID, "skeleton")
        first = pixels(puppet.screenshot_as_png)
        second = shot_after_moving(  # a moment later: the hand moved (checked below)
            puppet, lambda shot: (skin(first) != skin(shot)).mean() > 0.002)
        bones = pixels(skeleton_view.screenshot_as_png)
        if os.environ.get("HANDRIG_VIEW_SCREENSHOT"):
            save_small(browser.get_screenshot_as_png(), os.environ["HANDRIG_VIEW_SCREENSHOT"])

        # the hand is drawn in the model's view, in its colour, away from the edges
        h, w = first.shape[:2]
        for shot in (first, second):
            mask = skin(shot)
            assert mask.mean() > 0.01, f"only {mask.mean():.2%} of the view is the hand's colour"
            ys, xs = np.nonzero(mask)
            assert 0.1 * w < xs.mean() < 0.9 * w and 0.1 * h < ys.mean() < 0.9 * h
        # ... and it moved between the two moments
        changed = skin(first) != skin(second)
        assert changed.mean() > 0.002, f"the hand moved over only {changed.mean():.3%}"
        # the skeleton's view draws bones in their colour, not the puppet's skin
        near = np.abs(bones - np.array(SKELETON_RGB)).max(axis=-1) < 60
        assert near.sum() > 50 and skin(bones).mean() < 0.001
        # the model is one mesh (one draw call), and its ghost one more when drawn: not a
        # mesh per geom (the puppet hand has 34), each a draw call that software WebGL pays for
        assert 1 <= browser.execute_script("return window.handrigView.modelDrawCalls()") <= 2
        # the tables are filled from the telemetry
        assert browser.find_element(By.ID, "servos").find_elements(By.CSS_SELECTOR, "tbody tr")
        assert browser.find_element(By.ID, "glove").find_elements(By.CSS_SELECTOR, "tbody tr")

        mode = browser.find_element(By.ID, "mode")
        before = mode.text
        browser.find_element(By.ID, "relax").click()
        wait_for(lambda: mode.text == "relaxing", 10, f"the mode to change from {before!r}")
        time.sleep(0.5)
        browser.find_element(By.ID, "estop").click()  # acts on pointerdown
        summary = demo.summary(timeout_s=60)
    finally:
        browser.quit()
    events = "\n".join(summary["events"])
    assert "relaxed until it is pressed again" in events  # the relax button's mode change
    assert summary["estop"] is True and summary["torque_off"] is True
    assert summary["stop_reason"] == "e-stop button (view)"
    assert "e-stop button (view): torque off now" in events
    assert summary["frames"] < FRAMES


def test_two_hand_page_draws_and_moves_both_hands_relaxes_and_estops_both(tmp_path: Path
                                                                         ) -> None:
    """``handrig demo --rig puppet_two_hands --view``: a glove and a loop per hand. The
    page draws both hands of the puppet (the right on the right) and both skeletons,
    both move; the relax button relaxes both hands, the e-stop ends both with torque
    off on every servo."""
    from selenium.webdriver.common.by import By

    run = ViewRun("demo", "--rig", "puppet_two_hands", "--frames", str(FRAMES))
    browser = chromium(tmp_path / "profile")
    shooting = bool(os.environ.get("HANDRIG_VIEW_TWO_HANDS_SCREENSHOT"))
    try:
        browser.get(with_full(run.url) if shooting else run.url)  # the docs' picture: 30/s
        wait_for(lambda: browser.execute_script("return window.handrigView.framesDrawn()") > 5,
                 90, "the page to draw frames")
        puppet = browser.find_element(By.ID, "puppet")
        first = pixels(puppet.screenshot_as_png)
        w = first.shape[1]
        halves = (("left", slice(0, w // 2)), ("right", slice(w // 2, w)))
        second = shot_after_moving(  # a moment later: both hands moved (checked below)
            puppet, lambda shot: all((skin(first[:, half]) != skin(shot[:, half])).mean()
                                     > 0.001 for _, half in halves))
        bones = pixels(browser.find_element(By.ID, "skeleton").screenshot_as_png)
        if os.environ.get("HANDRIG_VIEW_TWO_HANDS_SCREENSHOT"):
            save_small(browser.get_screenshot_as_png(),
                       os.environ["HANDRIG_VIEW_TWO_HANDS_SCREENSHOT"])

        # the right hand is drawn on the right of the view, the left on the left
        xs = {h: browser.execute_script(f"return window.handrigView.handScreenX('{h}')")
              for h in ("ri", "le")}
        assert xs["le"] < 0.0 < xs["ri"], xs
        # a mesh per hand and per hand's ghost at most (docs/view.md)
        assert 2 <= browser.execute_script("return window.handrigView.modelDrawCalls()") <= 4
        # a hand in each half of the model's view, each moved between the two moments
        for name, half in halves:
            for shot in (first, second):
                share = skin(shot[:, half]).mean()
                assert share > 0.01, f"only {share:.2%} of the {name} half is the hand's colour"
            moved = (skin(first[:, half]) != skin(second[:, half])).mean()
            assert moved > 0.001, f"the {name} hand moved over only {moved:.3%}"
        # a skeleton in each half of the skeleton's view
        near = np.abs(bones - np.array(SKELETON_RGB)).max(axis=-1) < 60
        bw = bones.shape[1]
        assert near[:, :bw // 2].sum() > 50 and near[:, bw // 2:].sum() > 50
        # the tables: each hand's loop figures, its glove, every servo grouped by hand
        assert [c.text for c in browser.find_elements(By.CSS_SELECTOR, "#loop thead th")
                ][1:] == ["right", "left"]
        assert len(browser.find_element(By.ID, "rate").find_element(By.XPATH, "..")
                   .find_elements(By.TAG_NAME, "td")) == 2
        heads = [r.text for r in browser.find_elements(By.CSS_SELECTOR, "#servos tr.hand")]
        assert heads == ["right hand", "left hand"]
        joints = [r.find_elements(By.TAG_NAME, "td")[1].text for r in
                  browser.find_elements(By.CSS_SELECTOR, "#servos tbody tr:not(.hand)")]
        assert len(joints) == 40 and all(j.startswith("ri") for j in joints[:20])
        assert all(j.startswith("le") for j in joints[20:])
        gloves = [r.text for r in browser.find_elements(By.CSS_SELECTOR, "#glove tr.hand")]
        assert gloves == ["right glove", "left glove"]

        mode = browser.find_element(By.ID, "mode")
        browser.find_element(By.ID, "relax").click()
        wait_for(lambda: mode.text == "right relaxing · left relaxing", 10,
                 f"both hands to relax (the page says {mode.text!r})")
        time.sleep(0.5)
        browser.find_element(By.ID, "estop").click()  # acts on pointerdown
        summary = run.summary(timeout_s=60)
    finally:
        browser.quit()
        run.kill()
    assert summary["torque_off"] is True  # every servo of both hands
    for hand in ("right", "left"):
        s = summary["hands"][hand]
        events = "\n".join(s["events"])
        assert "relaxed until it is pressed again" in events, (hand, events)
        assert s["estop"] is True and s["stop_reason"] == "e-stop button (view)", hand
        assert "e-stop button (view): torque off now" in events, (hand, events)
        assert s["frames"] < FRAMES and s["torque_off"] is True


def with_full(url: str) -> str:
    """The page's URL asking for the full rate where WebGL is software."""
    return url + ("&" if "?" in url else "?") + "full"


def test_two_browsers_and_one_that_leaves(demo: ViewRun, tmp_path: Path) -> None:
    browsers = [chromium(tmp_path / f"profile{i}") for i in range(2)]
    try:
        browsers[0].get(demo.url)
        browsers[1].get(with_full(demo.url))  # ?full: the full rate in software too
        for b in browsers:
            wait_for(lambda b=b: b.execute_script("return window.handrigView.framesDrawn()") > 3,
                     90, "both pages to draw")
        full = browsers[1].execute_script("return window.handrigView")
        assert (full["pixelRatio"], full["maxDrawHz"]) == (1, 30)
        browsers.pop().quit()  # one leaves without a word
        stay = browsers[0]
        drawn = stay.execute_script("return window.handrigView.framesDrawn()")
        wait_for(lambda: stay.execute_script("return window.handrigView.framesDrawn()")
                 > drawn + 10, 30, "the other page to go on")
        from selenium.webdriver.common.by import By

        stay.find_element(By.ID, "stop").click()
        summary = demo.summary(timeout_s=60)
    finally:
        for b in browsers:
            b.quit()
    assert summary["estop"] is False and summary["torque_off"] is True
    assert summary["frames"] < FRAMES


def test_play_shows_the_recording_and_its_stop_button_ends_it(tmp_path: Path) -> None:
    from selenium.webdriver.common.by import By

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sink:  # the VMC receiver
        sink.bind(("127.0.0.1", 0))
        run = ViewRun("play", str(ROOT / "data" / "mocap" / "pn_gestures_reference.bvh"),
                      "--loop", "--vmc", f"127.0.0.1:{sink.getsockname()[1]}")
        browser = chromium(tmp_path / "profile")
        try:
            browser.get(run.url)
            wait_for(lambda: browser.execute_script("return window.handrigView.framesDrawn()")
                     > 5, 90, "the page to draw frames")
            assert "playing" in browser.find_element(By.ID, "mode").text
            assert not browser.find_element(By.ID, "estop").is_enabled()  # no rig, no e-stop
            shot = pixels(browser.find_element(By.ID, "puppet").screenshot_as_png)
            assert skin(shot).mean() > 0.01  # both hands of the human-hand model
            browser.find_element(By.ID, "stop").click()
            summary = run.summary(timeout_s=30)
        finally:
            browser.quit()
            run.kill()
    assert summary["bundles_sent"] > 0 and summary["interrupted"] is False


def test_page_without_webgl_says_so_and_its_tables_still_work(tmp_path: Path) -> None:
    """A browser without WebGL gets a message where the views would be, not a blank
    canvas, and the figures from the telemetry."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By

    from handrig.app.parts import build_parts
    from handrig.app.view import build_server
    from handrig.loop.telemetry import LoopSnapshot
    from handrig.pose.pipeline import POSE_NAMES

    cfg = build_parts(None).rig_config
    n = len(cfg.servos)
    snap = LoopSnapshot(
        t_s=1.0, seq=1, mode="running", mode_reason="", rate_hz=200.0, latency_p50_us=150.0,
        latency_p99_us=300.0, frames_lost=0, cycles=200, overruns=0,
        pose_deg=(10.0,) * len(POSE_NAMES), curve_names=POSE_NAMES,
        servo_ids=tuple(s.id for s in cfg.servos), servo_joints=tuple(s.joint for s in cfg.servos),
        goals_deg=(5.0,) * n, positions_deg=(4.0,) * n, temperatures_c=(31.0,) * n,
        hardware_errors=(0,) * n, stale=(False,) * n)
    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-webgl",
                "--disable-3d-apis", "--window-size=1200,900", f"--user-data-dir={tmp_path}"):
        opts.add_argument(arg)
    with build_server("127.0.0.1:0", cfg) as server:
        server.attach(lambda: snap)
        browser = webdriver.Chrome(options=opts, service=Service(executable_path=str(DRIVER)))
        try:
            browser.get(server.url)
            puppet = browser.find_element(By.ID, "puppet")
            wait_for(lambda: "cannot draw the 3D view" in puppet.text, 30, "the no-WebGL message")
            assert not browser.find_elements(By.CSS_SELECTOR, "canvas")
            wait_for(lambda: browser.find_element(By.ID, "mode").text == "running", 30,
                     "the mode from the telemetry")
            wait_for(lambda: len(browser.find_elements(By.CSS_SELECTOR, "#servos tbody tr")) == n,
                     30, "a row per servo")
        finally:
            browser.quit()
