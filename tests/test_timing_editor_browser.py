"""lipsync edit-timeline in real headless Chromium: drag a word boundary, retype a word, save, compare.

A GRID sentence (tests/data/grid-s1-audio/bram2n, CC BY 4.0: "bin red at m two now") opened
from its own word alignment at 50 fps. Skipped (with the reason) when Debian's
chromium/chromium-driver are absent; `make test-browser` installs them and runs this file.
"""

import base64
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from lipsync import read_timeline
from lipsync.readers.papagayo import read_words
from lipsync.timing_editor import TimingEditor
from lipsync.timing_editor.browser import chromium, missing, timing_page, wait

pytestmark = pytest.mark.skipif(missing() is not None, reason=f"no headless Chromium: {missing()}")

DATA = Path(__file__).parent / "data" / "grid-s1-audio"
AUDIO, ALIGN = DATA / "bram2n.flac", DATA / "bram2n.align"
FPS = 50.0


@pytest.fixture(scope="module")
def driver():
    with chromium(1300, 700) as d:
        yield d


def rows(tl):
    return [{"start": s.start, "end": s.end, "label": s.label} for s in tl]


def at(driver, t, row):
    """Offsets from the canvas centre of time ``t`` in ``row`` (what ActionChains takes)."""
    canvas = driver.find_element("id", "timeline")
    x = driver.execute_script("return window.lipsyncTiming.xOf(arguments[0])", t)
    y = driver.execute_script("return window.lipsyncTiming.rowY(arguments[0])", row)
    return canvas, int(round(x - canvas.size["width"] / 2)), int(round(y - canvas.size["height"] / 2))


def settled(driver, version):
    wait(driver, f"window.lipsyncTiming.version > {version} && !window.lipsyncTiming.busy", what="the edit")


def shown_frame(driver):
    """The PNG the mouth <img> shows, as the page holds it (its blob), decoded."""
    url = driver.execute_async_script(
        "const done = arguments[0], r = new FileReader(); r.onload = () => done(r.result);"
        "r.readAsDataURL(window.lipsyncTiming.shownBlob);")
    b64 = url.split(",", 1)[1]
    png = np.frombuffer(base64.b64decode(b64), np.uint8)
    return cv2.cvtColor(cv2.imdecode(png, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def test_drag_retype_save_preview(tmp_path, driver):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    editor = TimingEditor(AUDIO, timeline=ALIGN, fps=FPS, out=tmp_path / "out" / "bram2n")
    start = editor.get()
    assert [w["label"] for w in start["words"]] == ["bin", "red", "at", "m", "two", "now"]
    two, now = start["words"][4], start["words"][5]
    assert two["end"] == now["start"] == 1.52
    with timing_page(editor, driver) as session:
        S = "window.lipsyncTiming"
        print(f"page ready in {driver.execute_script(f'return {S}.readyMs'):.0f} ms")
        # 1. drag the two|now boundary 100 ms to the left with the mouse (the phone edge follows)
        canvas, x, y = at(driver, 1.52, "words")
        px_per_s = driver.execute_script(f"return {S}.pxPerS")
        version = driver.execute_script(f"return {S}.version")
        d = int(round(0.1 * px_per_s))
        ActionChains(driver).move_to_element_with_offset(canvas, x, y).click_and_hold() \
            .move_by_offset(-5, 0).move_by_offset(5 - d, 0) \
            .release().perform()
        settled(driver, version)
        assert driver.execute_script(f"return {S}.doc.words[4].end") == 1.42
        # the arrow keys nudge the selected boundary by a frame (and back)
        version = driver.execute_script(f"return {S}.version")
        driver.find_element("tag name", "body").send_keys(Keys.ARROW_RIGHT)
        settled(driver, version)
        assert driver.execute_script(f"return {S}.doc.words[4].end") == 1.44
        version = driver.execute_script(f"return {S}.version")
        driver.find_element("tag name", "body").send_keys(Keys.ARROW_LEFT)
        settled(driver, version)
        assert driver.execute_script(f"return {S}.doc.words[4].end") == 1.42

        # 2. retype "at" as "in": click the word, type, Enter
        at_word = start["words"][2]
        canvas, x, y = at(driver, (at_word["start"] + at_word["end"]) / 2, "words")
        ActionChains(driver).move_to_element_with_offset(canvas, x, y).click().perform()
        label = driver.find_element("id", "label")
        assert label.get_attribute("value") == "at"
        version = driver.execute_script(f"return {S}.version")
        label.clear()
        label.send_keys("in", Keys.ENTER)
        settled(driver, version)

        # 3. save as TextGrid and .pgo (and the viseme tier as Rhubarb TSV) with the page's buttons
        for fmt in ("textgrid", "pgo", "rhubarb-tsv"):
            driver.execute_script(f"document.getElementById('format').value = '{fmt}'")
            driver.find_element("id", "save").click()
            wait(driver, f"{S}.saved['{fmt}']", what=f"the {fmt} save")
        paths = driver.execute_script(f"return {S}.saved")
        final = json.loads(json.dumps(driver.execute_script(f"return {S}.doc")))
        assert final == editor.get()

        # 4. scrub to a time in the moved stretch: the mouth shown is lipsync render's frame
        t = 1.47
        canvas, x, y = at(driver, t, "wave")
        ActionChains(driver).move_to_element_with_offset(canvas, x, y).click().perform()
        cursor = driver.execute_script(f"return {S}.cursor")
        index = int(np.floor(cursor * FPS + 1e-9))
        wait(driver, f"document.getElementById('mouth').dataset.frame === '{index}' && "
                     f"document.getElementById('mouth').dataset.version === String({S}.version)", what="the frame")
        shown = shown_frame(driver)

        # split the phone under the cursor (S), merge it back (M), undo and redo, make a viseme a rest
        body = driver.find_element("tag name", "body")
        n_phones = len(final["phones"])
        canvas, x, y = at(driver, cursor, "phones")
        ActionChains(driver).move_to_element_with_offset(canvas, x, y).click().perform()
        for key, count in (("s", n_phones + 1), ("m", n_phones)):
            version = driver.execute_script(f"return {S}.version")
            body.send_keys(key)
            settled(driver, version)
            assert len(driver.execute_script(f"return {S}.doc.phones")) == count, key
        assert editor.get() == final  # merged back: the same timeline
        for keys, count in (((Keys.CONTROL, "z"), n_phones + 1), ((Keys.CONTROL, "y"), n_phones)):
            version = driver.execute_script(f"return {S}.version")
            ActionChains(driver).key_down(keys[0]).send_keys(keys[1]).key_up(keys[0]).perform()
            settled(driver, version)
            assert len(editor.get()["phones"]) == count, keys
        canvas, x, y = at(driver, cursor, "visemes")
        ActionChains(driver).move_to_element_with_offset(canvas, x, y).click().perform()
        version = driver.execute_script(f"return {S}.version")
        body.send_keys(Keys.DELETE)
        settled(driver, version)
        vis = [v for v in editor.get()["visemes"] if v["start"] <= cursor < v["end"]]
        assert vis[0]["label"] == editor.bank.rest
        version = driver.execute_script(f"return {S}.version")
        ActionChains(driver).key_down(Keys.CONTROL).send_keys("z").key_up(Keys.CONTROL).perform()
        settled(driver, version)
        assert editor.get() == final

    # the saved files carry exactly those edits, and nothing else changed
    expect_words = json.loads(json.dumps(start["words"]))
    expect_words[4]["end"] = expect_words[5]["start"] = 1.42
    expect_words[2]["label"] = "in"
    assert rows(read_timeline(paths["textgrid"], tier="words")) == expect_words == final["words"]
    assert rows(read_words(paths["pgo"])) == expect_words
    phones = rows(read_timeline(paths["textgrid"]))
    assert phones == rows(read_timeline(paths["pgo"])) == final["phones"]
    w = expect_words[2]
    assert [p["label"] for p in phones if w["start"] <= p["start"] and p["end"] <= w["end"]] == ["IH", "N"]
    outside = [p for p in phones if not (w["start"] <= p["start"] and p["end"] <= w["end"])]
    before = [dict(p) for p in start["phones"] if not (w["start"] <= p["start"] and p["end"] <= w["end"])]
    for p in before:  # UW | N moved with the word boundary
        p["end"] = 1.42 if p["end"] == 1.52 else p["end"]
        p["start"] = 1.42 if p["start"] == 1.52 else p["start"]
    assert outside == before
    # reopening the saved files gives back the edited timeline
    for fmt in ("textgrid", "pgo"):
        assert TimingEditor(AUDIO, timeline=paths[fmt], fps=FPS, out=tmp_path / "x").get() == final, fmt

    # lipsync render of the edited timeline as saved (the TextGrid's phones, and the viseme tier
    # as Rhubarb cues), frame by frame as PNGs: the frame the page showed is render's
    for fmt in ("textgrid", "rhubarb-tsv"):
        frames = tmp_path / f"frames-{fmt}"
        r = subprocess.run([sys.executable, "-m", "lipsync", "render", paths[fmt], "-o", f"{frames}/",
                            "--fps", str(FPS), "--quiet"], capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        rendered = cv2.cvtColor(cv2.imread(str(sorted(frames.iterdir())[index])), cv2.COLOR_BGR2RGB)
        np.testing.assert_array_equal(shown, rendered, err_msg=fmt)
    # and the moved boundary shows: the unedited timeline's frame there is another
    original = TimingEditor(AUDIO, timeline=ALIGN, fps=FPS, out=tmp_path / "y").frame(index / FPS)
    assert np.abs(original.astype(int) - rendered.astype(int)).max() > 40


def test_space_plays_a_looped_selection_with_the_mouth(tmp_path, driver):
    import time

    editor = TimingEditor(AUDIO, timeline=ALIGN, fps=FPS, out=tmp_path / "out")
    with timing_page(editor, driver):
        S = "window.lipsyncTiming"
        canvas, x0, y = at(driver, 1.0, "wave")
        _, x1, _ = at(driver, 1.4, "wave")
        from selenium.webdriver.common.action_chains import ActionChains
        from selenium.webdriver.common.keys import Keys

        # zoom in around the cursor (+), scroll with the bar, fit the whole recording again
        fit = driver.execute_script(f"return {S}.pxPerS")
        width = driver.execute_script("return document.getElementById('timeline').clientWidth")
        assert fit == pytest.approx(width / editor.context.duration)
        driver.find_element("tag name", "body").send_keys("+")
        assert driver.execute_script(f"return {S}.pxPerS") == pytest.approx(1.5 * fit)
        driver.execute_script("const s = document.getElementById('scroll'); s.value = 1000;"
                              "s.dispatchEvent(new Event('input'))")
        span = width / (1.5 * fit)
        assert driver.execute_script(f"return {S}.t0") == pytest.approx(editor.context.duration - span)
        driver.find_element("id", "zoom-fit").click()
        assert driver.execute_script(f"return [{S}.t0, {S}.pxPerS]") == [0, pytest.approx(fit)]
        canvas, x0, y = at(driver, 1.0, "wave")
        _, x1, _ = at(driver, 1.4, "wave")

        # shift-drag on the waveform selects the loop (snapped to frames), then tick loop
        ActionChains(driver).move_to_element_with_offset(canvas, x0, y).key_down(Keys.SHIFT).click_and_hold() \
            .move_by_offset(x1 - x0, 0).release().key_up(Keys.SHIFT).perform()
        assert driver.execute_script(f"return {S}.loopSel") == [1.0, 1.4]
        driver.find_element("id", "loop").click()
        body = driver.find_element("tag name", "body")
        body.send_keys(" ")
        wait(driver, f"{S}.playing", what="playback")
        cursors, frames = [], set()
        deadline = time.monotonic() + 2.5
        while time.monotonic() < deadline:
            cursors.append(driver.execute_script(f"return {S}.cursor"))
            frames.add(driver.execute_script("return document.getElementById('mouth').dataset.frame"))
            time.sleep(0.03)
        body.send_keys(" ")
        wait(driver, f"!{S}.playing", what="pause")
    # the cursor stayed in the loop (a frame of slack for the clock's step) and went round it
    assert min(cursors) >= 1.0 and max(cursors) <= 1.4 + 0.1
    assert any(b < a - 0.2 for a, b in zip(cursors, cursors[1:])), "never wrapped around"
    # the mouth followed: several of the loop's frames were shown
    shown = {int(f) for f in frames if f is not None}
    assert len(shown & set(range(int(1.0 * FPS), int(1.4 * FPS) + 1))) >= 5, shown
