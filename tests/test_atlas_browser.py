"""The atlas player page in real headless Chromium: the frames it draws are lipsync's frames.

The page (lipsync/atlas/static/player.js) loads an atlas, its frames.json and the speech
from a static server on 127.0.0.1 and draws ``cells[frames[floor(t * fps)]]`` on a canvas.
Read back from the canvas, each drawn frame is compared with ``Animator.frame_at(t)`` (the
frame ``lipsync render`` writes): equal where the frame shows a viseme, and within the
atlas' quantisation where it is a morph. Skipped, with the reason, without Debian's chromium.
"""

from __future__ import annotations

import base64
import json
import shutil
import threading
import time
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import cv2
import numpy as np
import pytest

from lipsync import Animator, Bank
from lipsync._data import default_bank_dir
from lipsync.atlas import load_atlas
from lipsync.cli import main
from lipsync.editor.browser import chromium, missing, wait

pytestmark = pytest.mark.skipif(missing() is not None, reason=f"no headless Chromium: {missing()}")

ROOT = Path(__file__).parent.parent
HELLO = ROOT / "samples" / "hello.phn"
FPS = 25
N = 3


class _Quiet(SimpleHTTPRequestHandler):
    def log_message(self, *args):  # no request log on the test output
        pass


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A folder with the atlas, frames.json, the speech and the player, served on 127.0.0.1."""
    d = tmp_path_factory.mktemp("site")
    assert main(["atlas", str(default_bank_dir()), "-o", str(d / "mouth.png"), "-n", str(N), "--player", "-q",
                 str(HELLO)]) == 0
    assert main(["cues", str(HELLO), "--format", "atlas", "--atlas", str(d / "mouth.json"), "--fps", str(FPS),
                 "-o", str(d / "frames.json"), "-q"]) == 0
    shutil.copy(ROOT / "samples" / "hello.wav", d / "hello.wav")
    server = ThreadingHTTPServer(("127.0.0.1", 0), partial(_Quiet, directory=str(d)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield d, f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


@pytest.fixture(scope="module")
def page(site):
    d, url = site
    with chromium(800, 800) as driver:
        driver.get(f"{url}/player.html?atlas=mouth.json&frames=frames.json&audio=hello.wav")
        wait(driver, "window.lipsyncAtlasPlayer.ready || window.lipsyncAtlasPlayer.errors > 0", what="the player")
        assert driver.execute_script("return window.lipsyncAtlasPlayer.errors") == 0, \
            driver.find_element("id", "status").text
        yield driver, d


def canvas_at(driver, t: float):
    """What the page draws at time t: RGBA read back from its canvas (a PNG data URL)."""
    url = driver.execute_script("window.lipsyncAtlasPlayer.drawAt(arguments[0]);"
                                "return document.getElementById('view').toDataURL('image/png');", t)
    data = base64.b64decode(url.split(",", 1)[1])
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    return cv2.cvtColor(img, cv2.COLOR_BGRA2RGBA)


def test_drawn_frames_match_lipsyncs_frames_within_the_quantisation(page):
    driver, d = page
    atlas = load_atlas(d / "mouth.json")
    frames = json.loads((d / "frames.json").read_text())["frames"]
    anim = Animator(Bank.load(default_bank_dir()), HELLO, fps=FPS)
    assert driver.execute_script("return document.getElementById('view').width") == 512
    pairs = atlas.pair_cells()
    rx, ry, rw, rh = atlas.region
    box = (slice(ry, ry + rh), slice(rx, rx + rw))  # errors are means over the mouth region

    def cell_frame(i):
        c = atlas.cells[i]
        return anim.renderer.render(c.from_viseme, c.to_viseme, c.alpha).astype(int)

    errors, cut_errors, morphs = [], [], 0
    for n, spec in enumerate(anim.specs):
        t = (n + 0.5) / FPS
        drawn = canvas_at(driver, t)
        assert (drawn[..., 3] == 255).all()
        drawn = drawn[..., :3].astype(int)
        truth = anim.frame_at(t).astype(int)
        # the page drew exactly the cell frames.json names for this time
        assert np.array_equal(drawn, cell_frame(frames[n])), n
        err = np.abs(drawn - truth)[box].mean()
        if spec.is_still:
            assert err == 0, (n, spec)
            continue
        morphs += 1
        # the bound from the alpha step: the largest change one step between neighbouring
        # cells of this pair makes (the frame is at most half a step from the cell drawn),
        # plus one grey level for storing B->A as A->B at 1 - alpha
        key = (spec.from_viseme, spec.to_viseme)
        chain = pairs.get(key) or pairs[key[::-1]]
        step = max(np.abs(cell_frame(i) - cell_frame(j))[box].mean() for (_, i), (_, j) in zip(chain, chain[1:]))
        assert err <= step + 1.0, (n, spec, err, step)
        errors.append(err)
        # what a cue-file player (hard cuts to the nearer viseme) would show instead
        nearer = spec.from_viseme if spec.alpha < 0.5 else spec.to_viseme
        cut_errors.append(np.abs(anim.renderer.render(nearer, nearer, 0.0).astype(int) - truth)[box].mean())
    assert morphs >= 20
    print(f"\natlas player: {morphs} morph frames, mean abs error over the mouth region "
          f"{np.mean(errors):.2f} grey levels (hard cuts to the nearer viseme: {np.mean(cut_errors):.2f}); "
          f"max {np.max(errors):.2f}")
    assert np.mean(errors) < 0.5 * np.mean(cut_errors)


def test_playback_follows_the_audio_clock(page):
    driver, d = page
    frames = json.loads((d / "frames.json").read_text())["frames"]
    driver.execute_script("window.lipsyncAtlasPlayer.log.length = 0; document.getElementById('audio').currentTime = 0;")
    driver.find_element("id", "play").click()
    wait(driver, "document.getElementById('audio').currentTime > 1.2", timeout=30, what="the sound to play 1.2 s")
    driver.find_element("id", "play").click()  # pause
    paused_at = driver.execute_script("return document.getElementById('audio').currentTime")
    time.sleep(0.3)  # a few animation frames after the pause
    state = driver.execute_script("return window.lipsyncAtlasPlayer")
    log = state["log"]
    assert len(log) >= 10, log
    times = [t for t, _, _ in log]
    assert times == sorted(times) and times[-1] - times[0] > 1.0
    for t, n, cell in log:
        assert n == min(int(np.floor(t * FPS + 1e-9)), len(frames) - 1) and cell == frames[n]
    assert len({n for _, n, _ in log}) >= 10  # it moved through the frames as the sound played
    assert state["lastTime"] == pytest.approx(paused_at, abs=1e-6)
    assert state["errors"] == 0
