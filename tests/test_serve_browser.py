"""The demo page of lipsync serve in Debian's headless Chromium (selenium + /usr/bin/chromedriver).

Skipped, with the reason, where chromium or chromedriver is not installed.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import pytest

from lipsync.live import LOOKAHEAD_S

CHROMIUM = Path("/usr/bin/chromium")
DRIVER = Path("/usr/bin/chromedriver")

pytestmark = pytest.mark.skipif(not (CHROMIUM.exists() and DRIVER.exists()),
                                reason="Debian chromium and chromium-driver are not installed")


def chromium(extra=()):
    """Headless Chromium through chromedriver with a fresh profile; yields the driver, then
    quits it and removes the profile (``extra``: more command-line flags)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="lipsync-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 f"--user-data-dir={profile}", "--window-size=800,900", *extra):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(str(DRIVER)), options=options)
    yield driver
    driver.quit()
    shutil.rmtree(profile, ignore_errors=True)


@pytest.fixture(scope="module")
def browser():
    yield from chromium()


@pytest.fixture(scope="module")
def server():
    from test_serve import Running

    running = Running()
    yield running
    running.stop()


STATUS = "return document.getElementById('status').textContent"
CANVAS_SUM = """
const c = document.getElementById('head');
const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
let s = 0;
for (let i = 0; i < d.length; i += 4) s += d[i] + 2 * d[i + 1] + 3 * d[i + 2];
return [c.width, c.height, s];
"""


def _wait(driver, script, timeout=20.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = driver.execute_script(script)
        if value:
            return value
        time.sleep(0.05)
    status = driver.execute_script(STATUS)
    raise AssertionError(f"timed out waiting for: {script} (status: {status})")


def test_demo_page_plays_and_draws_the_live_head(browser, server):
    browser.get(server.url("/"))
    _wait(browser, "return document.getElementById('status').textContent.startsWith('ready')")
    # the resting face is drawn once on connect
    _wait(browser, "return window.lipsyncDemo.frames >= 1")
    width, height, rest = browser.execute_script(CANVAS_SUM)
    assert (width, height) == (512, 512) and rest > 0
    browser.find_element("id", "play").click()
    sums, numbers = [], []
    t0 = time.monotonic()
    # sample the canvas until the page says the sentence is done (a loaded machine may
    # start the audio late), at most 30 s
    while time.monotonic() - t0 < 30.0:
        sums.append(browser.execute_script(CANVAS_SUM)[2])
        numbers.append(browser.execute_script("return window.lipsyncDemo.lastN"))
        if browser.execute_script(STATUS).startswith("done"):
            break
        time.sleep(0.1)
    stats = browser.execute_script("return window.lipsyncDemo")
    status = browser.execute_script(STATUS)
    print(f"\ndemo page: {stats['frames']} frames, {stats['final']} final, status {status!r}")
    assert stats["errors"] == 0, status
    assert stats["frames"] >= 30, (stats, status)       # ~25 fps for the 3 s sentence
    # events are pushed 1 s ahead of the audio, more than the look-ahead: frames arrive final,
    # except the resting face before any push and the last look-ahead of the sentence (no
    # data follows it, so it could still change)
    end = 2.97
    assert all(n == 0 or n / 25 > end - LOOKAHEAD_S for n in stats["provisional"]), stats["provisional"]
    assert stats["final"] >= 40
    assert len(set(sums)) >= 5                           # the canvas changes as the head talks
    assert max(numbers) >= 60                            # the frames followed the clock to the end
    assert numbers == sorted(numbers) or numbers[-1] >= 60
    server_status = server.status()
    assert server_status["frames"] >= stats["frames"] and server_status["errors"] == 0
