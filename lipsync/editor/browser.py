"""Driving the editor in real headless Chromium (browser tests and the README screenshot).

Debian's ``chromium`` and ``chromium-driver`` (``/usr/bin/chromium``, ``/usr/bin/chromedriver``)
driven by selenium, with a fresh profile and no network features, so a run touches nothing
but 127.0.0.1.

``python -m lipsync.editor.browser BANK OUT.png`` writes a screenshot of the editor on a
copy of BANK (the bank itself is not touched): ``make docs-images`` makes docs/editor.png so.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Optional

CHROMIUM = os.environ.get("LIPSYNC_CHROMIUM", "/usr/bin/chromium")
CHROMEDRIVER = os.environ.get("LIPSYNC_CHROMEDRIVER", "/usr/bin/chromedriver")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--force-device-scale-factor=1")


def missing(chromium: Optional[str] = None, chromedriver: Optional[str] = None) -> Optional[str]:
    """Why a browser cannot be started here (None when it can).

    Examples
    --------
    >>> missing("/nonexistent/chromium")
    '/nonexistent/chromium not found (Debian package chromium; `make test-browser` installs it)'
    """
    for path, package in ((chromium or CHROMIUM, "chromium"), (chromedriver or CHROMEDRIVER, "chromium-driver")):
        if not os.access(path, os.X_OK):
            return f"{path} not found (Debian package {package}; `make test-browser` installs it)"
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed (pip install -e '.[test]')"
    return None


@contextmanager
def chromium(width: int = 1400, height: int = 860):
    """A selenium WebDriver of headless Chromium with a fresh profile; quit on exit.

    Examples
    --------
    >>> if missing() is None:  # doctest: +SKIP
    ...     with chromium() as driver:
    ...         driver.get("about:blank")
    """
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="lipsync-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={profile}")
    options.add_argument(f"--window-size={width},{height}")
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def wait(driver, script: str, timeout: float = 30.0, what: str = ""):
    """Poll a JS expression until it is truthy; returns its value."""
    deadline = time.monotonic() + timeout
    while True:
        value = driver.execute_script("return " + script)
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out waiting for {what or script}")
        time.sleep(0.05)


@contextmanager
def editor_page(bank_dir, driver, *, store=None):
    """Serve ``bank_dir`` with the editor on 127.0.0.1 and open it in ``driver``.

    Yields ``(editor, session)`` once the page has loaded the bank and shown a preview.
    """
    from ..morphing.store import FlowStore
    from ..web import Session, start_in_thread
    from .server import Editor, make_app

    editor = Editor(bank_dir, store=FlowStore(store) if store else None)
    session = Session.open()
    running = start_in_thread(make_app(editor, session), session)
    try:
        driver.get(session.url("/"))
        wait(driver, "document.body.dataset.ready === '1' && window.lipsyncEditor.previewCount > 0",
             what="the editor page")
        yield editor, session
    finally:
        running.stop()
        editor.close()
        session.close()


def screenshot(bank_dir, out, *, viseme: str = "D", alpha: float = 0.5, select: str = "upper_outer_l") -> None:
    """A PNG of the editor on a copy of ``bank_dir``: ``viseme`` shown, the rest→viseme
    preview at ``alpha`` rendered with flows, one line selected."""
    from ..encode.preview import save_png

    tmp = Path(tempfile.mkdtemp(prefix="lipsync-shot-"))
    try:
        bank = shutil.copytree(bank_dir, tmp / Path(bank_dir).resolve().name,
                               ignore=shutil.ignore_patterns(".lipsync"))
        with chromium() as driver, editor_page(bank, driver, store=tmp / "store") as (editor, _):
            driver.execute_script(
                "document.querySelector(`.thumb[data-viseme='${arguments[0]}']`).click();", viseme)
            driver.execute_script(
                "document.querySelector(`#features li[data-feature='${arguments[0]}']`).click();", select)
            driver.execute_script("const a = document.getElementById('alpha'); a.value = arguments[0];"
                                  "a.dispatchEvent(new Event('input'));", alpha)
            editor.worker.wait_idle(600)
            wait(driver, "window.lipsyncEditor.lastMethod === 'flow' && "
                         f"document.getElementById('preview').dataset.alpha === '{alpha}'", 60, "a flow preview")
            time.sleep(1.0)  # one status poll, so the progress bar shows the finished state
            import cv2
            import numpy as np

            png = driver.get_screenshot_as_png()
        img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
        save_png(out, cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":  # pragma: no cover
    if len(sys.argv) != 3:
        sys.exit("usage: python -m lipsync.editor.browser BANK OUT.png")
    why = missing()
    if why:
        sys.exit(f"cannot take the screenshot: {why}")
    screenshot(sys.argv[1], sys.argv[2])
    print(f"wrote {sys.argv[2]}")
