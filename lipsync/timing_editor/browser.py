"""Driving the timing editor in headless Chromium (browser tests, the benchmark, the docs screenshot).

Reuses :mod:`lipsync.editor.browser`'s Chromium (Debian's ``chromium`` + ``chromium-driver``,
a fresh profile, nothing but 127.0.0.1).

``python -m lipsync.timing_editor.browser AUDIO TIMELINE OUT.png`` writes a screenshot of the
page editing AUDIO from TIMELINE (saves go to a temporary folder): ``make docs-images`` makes
docs/timing-editor.png so.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

from ..editor.browser import chromium, missing, wait

__all__ = ["timing_page", "screenshot", "chromium", "missing", "wait"]


@contextmanager
def timing_page(editor, driver, *, timeout: float = 60.0):
    """Serve ``editor`` (a :class:`~lipsync.timing_editor.TimingEditor`) on 127.0.0.1 and open it
    in ``driver``; yields the session once the page shows the timeline and its first frame."""
    from ..web import Session, start_in_thread
    from .server import make_app

    session = Session.open()
    running = start_in_thread(make_app(editor, session), session)
    try:
        driver.get(session.url("/"))
        wait(driver, "document.body.dataset.ready === '1'", timeout, what="the timing editor page")
        yield session
    finally:
        running.stop()
        session.close()


def screenshot(audio, timeline, out, *, width: int = 1400, height: int = 600) -> None:
    """A PNG of the page on ``audio`` with ``timeline``: zoomed on the speech, a word selected,
    the cursor inside it and its mouth frame shown."""
    from .server import TimingEditor

    tmp = Path(tempfile.mkdtemp(prefix="lipsync-timing-shot-"))
    try:
        editor = TimingEditor(audio, timeline=timeline, out=tmp / "out")
        with chromium(width, height) as driver, timing_page(editor, driver):
            words = editor.get()["words"]
            w = words[len(words) // 2]
            driver.execute_script(
                "const S = window.lipsyncTiming; S.pxPerS = arguments[2];"
                "S.t0 = Math.max(0, arguments[0] - 0.6); document.getElementById('zoom-in').click();"
                "S.pxPerS = arguments[2]; S.t0 = Math.max(0, arguments[0] - 0.6);"
                "S.edge = null; S.loopSel = [arguments[0], arguments[1]];", w["start"], w["end"], 700)
            # select the word through a real click on its middle
            import time

            from selenium.webdriver.common.action_chains import ActionChains

            canvas = driver.find_element("id", "timeline")
            x = driver.execute_script("return window.lipsyncTiming.xOf(arguments[0])", (w["start"] + w["end"]) / 2)
            y = driver.execute_script("return window.lipsyncTiming.rowY('words')")
            ActionChains(driver).move_to_element_with_offset(canvas, int(x - canvas.size["width"] / 2),
                                                             int(y - canvas.size["height"] / 2)).click().perform()
            wait(driver, "document.getElementById('mouth').dataset.frame == "
                         "String(Math.floor(window.lipsyncTiming.cursor * window.lipsyncTiming.info.fps + 1e-9))",
                 30, "the mouth at the cursor")
            time.sleep(0.3)
            import cv2
            import numpy as np

            png = driver.get_screenshot_as_png()
        from ..encode.preview import save_png

        img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
        save_png(out, cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":  # pragma: no cover
    if len(sys.argv) != 4:
        sys.exit("usage: python -m lipsync.timing_editor.browser AUDIO TIMELINE OUT.png")
    why = missing()
    if why:
        sys.exit(f"cannot take the screenshot: {why}")
    screenshot(sys.argv[1], sys.argv[2], sys.argv[3])
    print(f"wrote {sys.argv[3]}")
