"""lipsync edit in real headless Chromium: drag a point, move the alpha slider, save.

Skipped (with the reason) when Debian's chromium/chromium-driver are absent; `make
test-browser` installs them and runs this file.
"""

import shutil

import numpy as np
import pytest
import yaml

import synthetic
from lipsync.editor.browser import chromium, editor_page, missing, wait

pytestmark = pytest.mark.skipif(missing() is not None, reason=f"no headless Chromium: {missing()}")


@pytest.fixture(scope="module")
def template_bank(tmp_path_factory):
    return synthetic.write_bank(tmp_path_factory.mktemp("template") / "bank")


@pytest.fixture(scope="module")
def driver():
    with chromium(1200, 800) as d:
        yield d


def click(driver, css):
    """Click an element, finding it again if a redraw replaced it meanwhile."""
    from selenium.common.exceptions import StaleElementReferenceException

    for _ in range(20):
        try:
            return driver.find_element("css selector", css).click()
        except StaleElementReferenceException:
            continue
    raise AssertionError(f"{css} kept going stale")


def view_box(driver):
    return [float(x) for x in driver.execute_script(
        "return document.getElementById('canvas').getAttribute('viewBox')").split()]


def preview_pixels(driver):
    """The preview <img> as shown, decoded from an element screenshot."""
    import cv2

    png = driver.find_element("id", "preview").screenshot_as_png
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR).astype(int)


def test_drag_slider_save(tmp_path, template_bank, driver):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    bank = shutil.copytree(template_bank, tmp_path / "bank")
    before = yaml.safe_load((bank / "bank.yaml").read_text())
    with editor_page(bank, driver, store=tmp_path / "store") as (editor, session):
        assert editor.worker.wait_idle(60)
        click(driver, ".thumb[data-viseme='O']")
        driver.find_element("id", "to").send_keys("O")
        wait(driver, "document.getElementById('preview').dataset.method === 'flow' && "
                     "!window.lipsyncEditor.previewBusy", what="a flow preview")
        shown = preview_pixels(driver)

        # drag the end of upper_l by (30, 12) screen pixels
        handle = driver.find_element("css selector", "#canvas-lines circle[data-feature='upper_l'][data-k='1']")
        scale = driver.execute_script("return document.getElementById('canvas').getScreenCTM().a")
        version = driver.execute_script("return window.lipsyncEditor.version")
        ActionChains(driver).click_and_hold(handle).move_by_offset(30, 12).release().perform()
        wait(driver, f"window.lipsyncEditor.version > {version} && window.lipsyncEditor.pendingSince === null",
             what="the draft preview")
        dragged = preview_pixels(driver)
        assert np.abs(dragged - shown).max() > 20, "the preview did not follow the drag"

        # the alpha slider: 0.5 -> 0.7 by four arrow steps of 0.05
        slider = driver.find_element("id", "alpha")
        slider.click()  # the middle of the track: 0.5
        driver.execute_script("arguments[0].value = 0.5; arguments[0].dispatchEvent(new Event('input'))", slider)
        wait(driver, "document.getElementById('preview').dataset.alpha === '0.5' && !window.lipsyncEditor.previewBusy")
        at_half = preview_pixels(driver)
        slider.send_keys(Keys.ARROW_RIGHT * 4)
        wait(driver, "document.getElementById('preview').dataset.alpha === '0.7' && !window.lipsyncEditor.previewBusy",
             what="the preview at alpha 0.7")
        assert driver.find_element("id", "alpha-value").text == "0.70"
        assert np.abs(preview_pixels(driver) - at_half).max() > 20, "the preview did not follow the slider"

        driver.find_element("id", "save").click()
        wait(driver, "document.getElementById('message').textContent.startsWith('saved')", what="the save")
        wait(driver, "window.lipsyncEditor.saveToPreviewMs !== null", what="the preview after saving")
        ms = driver.execute_script("return window.lipsyncEditor.saveToPreviewMs")
        print(f"save -> updated preview in headless Chromium: {ms:.0f} ms")

    after = yaml.safe_load((bank / "bank.yaml").read_text())
    p_old = before["visemes"]["O"]["lines"]["upper_l"][1]
    p_new = after["visemes"]["O"]["lines"]["upper_l"][1]
    # the page keeps 1/10 px; a screen pixel is 1/scale image pixels
    assert p_new[0] == pytest.approx(p_old[0] + 30 / scale, abs=0.11)
    assert p_new[1] == pytest.approx(p_old[1] + 12 / scale, abs=0.11)
    # symmetry: true, so the partner moved mirrored about the axis x = 95.5
    assert after["visemes"]["O"]["lines"]["upper_r"][1] == pytest.approx([2 * 95.5 - p_new[0], p_new[1]], abs=1e-6)
    # and nothing else changed
    for v in before["visemes"]:
        for n in before["visemes"][v]["lines"]:
            if (v, n) not in (("O", "upper_l"), ("O", "upper_r")):
                assert after["visemes"][v]["lines"][n] == before["visemes"][v]["lines"][n], (v, n)
    assert after["visemes"]["O"]["lines"]["upper_l"][0] == before["visemes"]["O"]["lines"]["upper_l"][0]
    assert {k: after[k] for k in after if k != "visemes"} == {k: before[k] for k in before if k != "visemes"}


def test_undo_redo_add_rename_delete(tmp_path, template_bank, driver):
    bank = shutil.copytree(template_bank, tmp_path / "bank")
    before = yaml.safe_load((bank / "bank.yaml").read_text())
    from selenium.webdriver.common.action_chains import ActionChains

    with editor_page(bank, driver, store=tmp_path / "store") as (editor, _):
        # zoom and pan change the view box only
        canvas = driver.find_element("id", "canvas")
        vb = view_box(driver)
        assert vb == [0, 0, 192, 160]
        driver.find_element("id", "zoom-in").click()
        zoomed = view_box(driver)
        assert zoomed[2:] == pytest.approx([192 / 1.25, 160 / 1.25])
        assert zoomed[0] + zoomed[2] / 2 == pytest.approx(96) and zoomed[1] + zoomed[3] / 2 == pytest.approx(80)
        ActionChains(driver).move_to_element_with_offset(canvas, -canvas.size["width"] // 2 + 3, 0) \
            .click_and_hold().move_by_offset(40, 0).release().perform()
        panned = view_box(driver)
        assert panned[0] < zoomed[0] and panned[1:] == pytest.approx(zoomed[1:])
        driver.find_element("id", "zoom-fit").click()
        assert view_box(driver) == [0, 0, 192, 160]
        assert editor.worker.wait_idle(60)
        wait(driver, "document.getElementById('preview-status').textContent.includes('flows 6/6') || "
                     "document.getElementById('preview-status').textContent.includes('flows ready')",
             what="flow progress shown")
        # an unpaired line across the axis (the brow) mirrors its other end; nose (on the axis) does not
        brow0 = driver.execute_script("const S = window.lipsyncEditor; return S.doc.visemes[S.current].lines.brow")
        nose0 = driver.execute_script("const S = window.lipsyncEditor; return S.doc.visemes[S.current].lines.nose")
        scale = driver.execute_script("return document.getElementById('canvas').getScreenCTM().a")
        for feature, dx, dy in (("brow", -10, 6), ("nose", 0, -8)):
            handle = driver.find_element("css selector", f"#canvas-lines circle[data-feature='{feature}'][data-k='0']")
            ActionChains(driver).click_and_hold(handle).move_by_offset(dx, dy).release().perform()
        brow = driver.execute_script("const S = window.lipsyncEditor; return S.doc.visemes[S.current].lines.brow")
        nose = driver.execute_script("const S = window.lipsyncEditor; return S.doc.visemes[S.current].lines.nose")
        assert brow[0] == pytest.approx([brow0[0][0] - 10 / scale, brow0[0][1] + 6 / scale], abs=0.11)
        assert brow[1] == pytest.approx([2 * 95.5 - brow[0][0], brow[0][1]], abs=1e-6)
        assert nose[1] == nose0[1] and nose[0][1] == pytest.approx(nose0[0][1] - 8 / scale, abs=0.11)
        driver.find_element("id", "undo").click()
        driver.find_element("id", "undo").click()
        assert driver.execute_script("return window.lipsyncEditor.doc.visemes") == before["visemes"]
        box = driver.find_element("id", "line-name")
        box.clear()
        box.send_keys("mouth_l")
        driver.find_element("id", "add").click()
        names = driver.execute_script("return Object.keys(window.lipsyncEditor.doc.visemes.E.lines)")
        assert names[-2:] == ["mouth_l", "mouth_r"]  # the partner comes too (symmetry: true)
        box.clear()
        box.send_keys("jaw_l")
        driver.find_element("id", "rename").click()
        names = driver.execute_script("return Object.keys(window.lipsyncEditor.doc.visemes.X.lines)")
        assert names[-2:] == ["jaw_l", "jaw_r"]
        click(driver, "#features li[data-feature='nose']")
        driver.find_element("id", "delete").click()
        assert "nose" not in driver.execute_script("return Object.keys(window.lipsyncEditor.doc.visemes.A.lines)")
        for _ in range(3):
            driver.find_element("id", "undo").click()
        assert driver.execute_script("return window.lipsyncEditor.doc.visemes") == before["visemes"]
        driver.find_element("id", "redo").click()
        names = driver.execute_script("return Object.keys(window.lipsyncEditor.doc.visemes.O.lines)")
        assert names[-2:] == ["mouth_l", "mouth_r"]
        # a Bézier pair, saved: the bank loads it as curves of 8 segments
        box.clear()
        box.send_keys("arc_r")
        driver.find_element("id", "new-kind").send_keys("Bézier")
        driver.find_element("id", "add").click()
        arc = driver.execute_script("return window.lipsyncEditor.doc.visemes.A.lines.arc_l")
        assert len(arc["bezier"]) == 4
        # play runs the preview through several alphas, then stops
        count = driver.execute_script("return window.lipsyncEditor.previewCount")
        driver.find_element("id", "play").click()
        wait(driver, f"window.lipsyncEditor.previewCount >= {count + 3}", what="playing")
        driver.find_element("id", "play").click()
        assert driver.find_element("id", "play").text == "Play"
        driver.find_element("id", "save").click()
        wait(driver, "document.getElementById('message').textContent.startsWith('saved')", what="the save")
        from lipsync.banks.bank import Bank
        saved = Bank.load(bank)
        assert [n for n in saved.line_names if n.startswith("arc_l")] == [f"arc_l#{i}" for i in range(8)]
        assert saved.features["O"]["arc_r"].kind == "bezier"
        before = yaml.safe_load((bank / "bank.yaml").read_text())
        # copy X's lines onto the shown viseme
        click(driver, ".thumb[data-viseme='E']")
        driver.find_element("id", "copy-from").send_keys("X")
        driver.find_element("id", "copy").click()
        doc = driver.execute_script("return window.lipsyncEditor.doc.visemes")
        assert doc["E"]["lines"] == doc["X"]["lines"]
        # an invalid edit is reported beside its line and not saved
        driver.execute_script("window.lipsyncEditor.doc.visemes.A.lines.width = [[10, 10], [10, 10]];")
        driver.find_element("id", "save").click()
        err = wait(driver, "document.querySelector(\"#features li[data-feature='width'] .error\")"
                           "?.textContent", what="the error beside the line")
        assert "zero-length" in err and err.startswith("A:")
    assert yaml.safe_load((bank / "bank.yaml").read_text()) == before
