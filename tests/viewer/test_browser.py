"""``latentrl view`` and ``latentrl play`` in headless Chromium: the body is drawn, a floor click steers it.

Runs Debian's ``chromium`` + ``chromium-driver`` through Selenium (no browser download) with software
WebGL (SwiftShader). Skips, naming what is missing, where Chromium, its driver, Selenium or Viser is
not installed. ``LATENTRL_VIEWER_SHOTS=DIR`` keeps the screenshots (docs/viewer_play.png and
docs/viewer_scene.png are made this way; docs/viewer_view.png is the same page on an evaluation folder).
"""

import contextlib
import io
import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.browser

ROOT = Path(__file__).resolve().parents[2]
POLICY = ROOT / "policies" / "reach_walk_default.pt"
CHROMIUM = os.environ.get("LATENTRL_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = os.environ.get("LATENTRL_CHROMEDRIVER") or shutil.which("chromedriver")
SHOTS = os.environ.get("LATENTRL_VIEWER_SHOTS")
WINDOW = (1200, 720) if SHOTS else (880, 520)  # software WebGL: small is fast
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--hide-scrollbars")


@pytest.fixture(scope="module")
def browser():
    pytest.importorskip("viser", reason="the viewer extra is not installed (pip install -e '.[viewer]')")
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed (pip install -e '.[dev]')")
    if not CHROMIUM or not CHROMEDRIVER:
        pytest.skip("no chromium/chromedriver on PATH (Debian: apt-get install chromium chromium-driver)")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--window-size={WINDOW[0]},{WINDOW[1]}")
    profile = tempfile.mkdtemp(prefix="latentrl-chromium-")
    options.add_argument(f"--user-data-dir={profile}")
    try:
        driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    except Exception as exc:  # a driver that does not match the browser, a broken install, ...
        pytest.skip(f"chromium did not start: {str(exc).splitlines()[0][:200]}")
    driver.set_page_load_timeout(60)
    driver.set_script_timeout(60)
    yield driver
    driver.quit()
    shutil.rmtree(profile, ignore_errors=True)


@contextlib.contextmanager
def serve(*args):
    """Run ``latentrl ARGS --port 0``; yield (url, output lines); Ctrl-C it afterwards and require exit 0."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")}
    proc = subprocess.Popen([sys.executable, "-m", "latentrl.app.cli", *args, "--port", "0"], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env)
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in proc.stdout], daemon=True).start()
    try:
        first = wait_line(lines, "open http", 90)
        yield re.search(r"http://\S+", first).group(0), lines
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()
    assert proc.returncode == 0, f"{args[0]} did not stop cleanly on Ctrl-C (exit {proc.returncode})"


def wait_line(lines: queue.Queue, needle: str, timeout: float) -> str:
    end, seen = time.monotonic() + timeout, []
    while time.monotonic() < end:
        try:
            line = lines.get(timeout=0.2)
        except queue.Empty:
            continue
        seen.append(line)
        if needle in line:
            return line
    raise AssertionError(f"no line with {needle!r} within {timeout} s; output:\n{''.join(seen)}")


def page_text(driver) -> str:
    return driver.execute_script("return document.body.innerText")


def open_page(driver, url: str, ready: str) -> None:
    driver.get(url)
    end = time.monotonic() + 60
    while ready not in page_text(driver):
        assert time.monotonic() < end, f"page never showed {ready!r}:\n{page_text(driver)}"
        time.sleep(0.3)
    # the "software WebGL" notice: close it, as a user would (it would cover part of the screenshots)
    driver.execute_script("document.querySelectorAll('[class*=Notification-closeButton]').forEach(b => b.click())")


def screenshot(driver) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(driver.get_screenshot_as_png())).convert("RGB")).astype(np.int16)


def still_screenshot(driver, timeout: float = 20.0) -> np.ndarray:
    """A screenshot once two in a row (0.5 s apart) agree: the canvas has faded in and nothing moves."""
    last, end = screenshot(driver), time.monotonic() + timeout
    while time.monotonic() < end:
        time.sleep(0.5)
        shot = screenshot(driver)
        if np.abs(shot - last).max(axis=-1).__gt__(40).sum() < 20:
            return shot
        last = shot
    return last


def click_control(driver, label: str, kind: str) -> None:
    """Click the GUI checkbox labelled ``label`` (kind 'checkbox') or the button reading ``label``."""
    from selenium.webdriver.common.by import By

    if kind == "button":
        element = driver.find_element(By.XPATH, f"//button[normalize-space()='{label}']")
    else:
        # the GUI label's own input: a scene-tree entry may read the same (the "/body" node)
        target = driver.find_element(By.XPATH, f"//label[normalize-space(text())='{label}']").get_attribute("for")
        element = driver.find_element(By.ID, target)
    driver.execute_script("arguments[0].click()", element)


def panel_left(driver) -> int:
    """x of the GUI panel's left edge in screenshot pixels (the scene is what lies left of it)."""
    from selenium.webdriver.common.by import By

    label = driver.find_element(By.XPATH, "//*[normalize-space(text())='skeleton']")
    return int(label.rect["x"] - 20)


def assert_body_drawn(driver, name: str) -> np.ndarray:
    """Screenshot with and without the capsule body: they must differ in the scene, in the sides' hues.

    The body is lit, so its pixels are shades of the side colours: blue (left) or orange (right) hues (one side
    may hide behind the other).
    """
    with_body = still_screenshot(driver)
    click_control(driver, "body", "checkbox")
    without = still_screenshot(driver)
    click_control(driver, "body", "checkbox")
    scene = slice(0, panel_left(driver))
    changed = np.abs(with_body - without)[:, scene].max(axis=-1) > 40
    assert changed.sum() > 300, f"{name}: hiding the body changed only {changed.sum()} pixels"
    ys, xs = np.nonzero(changed)
    r, g, b = with_body[:, scene][changed].T
    blue, orange = (b > r + 40) & (b > g), (r > b + 60) & (r > g)
    assert blue.sum() + orange.sum() > 150, f"{name}: the body shows {blue.sum()} blue, {orange.sum()} orange"
    print(f"{name}: body covers {changed.sum()} pixels in x {xs.min()}..{xs.max()}, y {ys.min()}..{ys.max()}")
    return with_body


def keep(driver, name: str) -> None:
    if SHOTS:
        Path(SHOTS).mkdir(parents=True, exist_ok=True)
        driver.save_screenshot(str(Path(SHOTS) / name))


def test_view_draws_a_sampled_motion(browser, tmp_path):
    from latentrl.app.cli import main

    motion = tmp_path / "walk.npz"
    assert main(["motion", "sample", "--text", "walk", "--text", "turn left", "--seconds", "4", "--out",
                 str(motion)]) == 0
    with serve("view", str(motion)) as (url, _):
        open_page(browser, url, "frame ")
        click_control(browser, "Pause", "button")
        assert_body_drawn(browser, "view")
        still_screenshot(browser)
        keep(browser, "viewer_view.png")


def test_view_draws_the_scene_of_a_motion(browser, tmp_path):
    """A motion carrying a scene: its objects are drawn (the green seat's pixels show in the scene)."""
    from latentrl.render import save_motion_npz
    from latentrl.scenes import Box, Cylinder, Scene, Seat, Stairs, scene_to_json
    from tests.viewer.conftest import walking

    scene = Scene((Stairs((1.4, 0.2), 90.0, 1.0, 0.15, 0.3, 4), Box((-1.2, 1.0), (0.6, 0.6, 1.0), 20.0),
                   Cylinder((-0.8, 2.8), 0.25, 1.2), Seat((0.2, 3.2), (0.6, 0.6), 0.45, -90.0)))
    motion = save_motion_npz(tmp_path / "walk.npz", walking(50), texts=["walk"] * 50, scene=scene_to_json(scene))
    with serve("view", str(motion)) as (url, _):
        open_page(browser, url, "frame ")
        click_control(browser, "Pause", "button")
        shot = still_screenshot(browser)
        r, g, b = shot[:, : panel_left(browser)].reshape(-1, 3).T
        green = (g > r + 20) & (g > b + 25)
        assert green.sum() > 150, f"the seat is not drawn: {green.sum()} green pixels"  # ~260 in the small window
        keep(browser, "viewer_scene.png")


def status(driver) -> dict[str, np.ndarray]:
    text = page_text(driver)
    found = {k: re.search(rf"{k}: \(([-\d.]+), ([-\d.]+)\)", text) for k in ("pelvis", "goal")}
    return {k: np.array([float(m.group(1)), float(m.group(2))]) for k, m in found.items() if m}


def test_play_walks_to_a_floor_click(browser):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    with serve("play", str(POLICY)) as (url, lines):
        open_page(browser, url, "click on the floor to set a goal")
        assert_body_drawn(browser, "play")
        start = status(browser)["pelvis"]
        canvas = browser.find_element(By.TAG_NAME, "canvas")
        w, h = canvas.size["width"], canvas.size["height"]
        ActionChains(browser).move_to_element_with_offset(canvas, int(-0.12 * w), int(0.1 * h)).click().perform()
        line = wait_line(lines, "latentrl play: goal", 20)
        goal = np.array([float(v) for v in re.search(r"goal \(([-\d.]+), ([-\d.]+)\)", line).groups()])
        before = np.linalg.norm(goal - start)
        assert 0.8 < before < 10, f"the click landed {before:.2f} m from the body: {line}"
        try:
            wait_line(lines, "latentrl play: reached", 40)
        except AssertionError:
            pass  # a slow machine: judge by how far it got
        now = status(browser)
        assert np.allclose(now["goal"], goal, atol=0.01), (now, goal)
        after = np.linalg.norm(goal - now["pelvis"])
        assert after < before - 0.5, f"pelvis {now['pelvis']} did not approach the goal {goal} ({before:.2f} m before)"
        from selenium.webdriver.common.keys import Keys

        before_drop = still_screenshot(browser)
        # left of the body, below it (the panel covers the canvas's right side in the small window)
        ActionChains(browser).move_to_element_with_offset(canvas, int(-0.3 * w), int(0.2 * h)) \
            .key_down(Keys.CONTROL).click().key_up(Keys.CONTROL).perform()
        try:
            wait_line(lines, "latentrl play: box dropped at", 20)  # a ctrl-click drops a box, sets no goal
        except AssertionError as exc:
            raise AssertionError(f"{exc}\npage:\n{page_text(browser)}") from None
        assert np.allclose(status(browser)["goal"], goal, atol=0.01)
        after_drop = still_screenshot(browser)
        scene = slice(0, panel_left(browser))
        changed = np.abs(after_drop - before_drop)[:, scene].max(axis=-1) > 40
        r, g, b = after_drop[:, scene][changed].T
        box = ((r > g + 40) & (g > b + 20)).sum()  # the dropped box's orange-brown, lit
        assert box > 800, f"the dropped box is not drawn: {box} box-coloured pixels changed"
        print(f"play: the dropped box changed {box} pixels")
        keep(browser, "viewer_play.png")


PWN = "<img src=x onerror=window.__pwned=1><script>window.__pwned=2</script>"
"""A prompt, a report's policy path and an episode's end that would run a script if shown as HTML."""


def test_view_shows_hostile_strings_as_text(browser, tmp_path):
    import json

    from latentrl.render import save_motion_npz
    from tests.viewer.conftest import walking, write_eval

    folder = write_eval(tmp_path / "eval")
    report = json.loads((folder / "report.json").read_text())
    report["policy"]["path"] = f"runs/{PWN}/final.pt"
    first = report["suites"]["demo"]["paths"][0]["episodes"][0]
    first["end"], first["success"] = PWN, False
    (folder / "report.json").write_text(json.dumps(report))
    save_motion_npz(folder / first["motion"], walking(50), texts=[PWN] * 50)
    with serve("view", str(folder)) as (url, _):
        open_page(browser, url, "frame ")
        end = time.monotonic() + 20
        while (shown := page_text(browser).count(PWN)) < 3 and time.monotonic() < end:
            time.sleep(0.3)  # summary, metrics table (end) and status line (prompt)
        injected = browser.execute_script(
            "return [document.querySelectorAll('img[src=\"x\"], [onerror]').length,"
            " [...document.scripts].filter(s => s.textContent.includes('__pwned')).length, window.__pwned || 0]")
        assert injected == [0, 0, 0], f"[img elements, script elements, script ran]: {injected}"
        assert shown >= 3, f"the strings did not show as text:\n{page_text(browser)}"


def test_play_steers_a_joystick_policy_by_the_keyboard(browser):
    """The shipped joystick policy: A and the left arrow, pressed in the page, turn the command; the body walks."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    with serve("play", "joystick_walk_default") as (url, lines):
        open_page(browser, url, "arrows or WASD")
        start = status(browser)["pelvis"]
        ActionChains(browser).send_keys("a").perform()
        wait_text(browser, "heading 15°")
        ActionChains(browser).send_keys(Keys.ARROW_LEFT).perform()
        wait_text(browser, "heading 30°")
        end = time.monotonic() + 40
        while np.linalg.norm(status(browser)["pelvis"] - start) < 0.5:
            assert time.monotonic() < end, f"the body did not walk: {page_text(browser)}"
            time.sleep(0.5)


def wait_text(driver, needle: str, timeout: float = 20.0) -> None:
    end = time.monotonic() + timeout
    while needle not in page_text(driver):
        assert time.monotonic() < end, f"page never showed {needle!r}:\n{page_text(driver)}"
        time.sleep(0.2)


def test_play_lands_a_clicked_pelvis_goal_of_the_reach_joint_policy(browser):
    """``latentrl play reach_joint_default``: a floor click gives the pelvis a goal in 2 s; refined, it lands."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    with serve("play", "reach_joint_default", "--deterministic") as (url, lines):
        open_page(browser, url, "a goal for the joint picked below")
        assert "refinement: on (32 steps)" in page_text(browser)
        canvas = browser.find_element(By.TAG_NAME, "canvas")
        w, h = canvas.size["width"], canvas.size["height"]
        # near the middle: a spot about 1-2 m ahead of the start pose (the camera looks past it)
        ActionChains(browser).move_to_element_with_offset(canvas, int(0.0 * w), int(0.04 * h)).click().perform()
        line = wait_line(lines, "latentrl play: pelvis goal (", 20)
        assert "2 s from now" in line, line
        print(line.strip())
        landed = wait_line(lines, "latentrl play: pelvis goal", 120)  # 8 refined steps: slow motion on a CPU
        error = float(re.search(r"goal ([\d.]+) cm off", landed).group(1))
        assert error < 10.0, landed
        print(f"play (ReachJoint): {landed.strip()}")
        keep(browser, "viewer_play_joint.png")
