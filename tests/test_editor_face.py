"""The editor's "Place from face": the API (TestClient) and the button in headless Chromium.

The banks are real GRID frames (tests/data/grid-s1, CC BY 4.0: see SOURCE.md there). The
expected lines are independent of the editor: what ``lipsync init`` places from the same
images (itself checked against the face mesh's points in test_init.py).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from starlette.testclient import TestClient

from lipsync.videobank.photos import init_bank
from lipsync.editor import Editor, make_app
from lipsync.face.lines import FACE_WARP
from lipsync.face.video import read_video
from lipsync.web import Session

GRID = Path(__file__).parent / "data" / "grid-s1"


@pytest.fixture(scope="module")
def face_images(tmp_path_factory):
    frames = list(read_video(GRID / "lwae8n.mpg"))
    d = tmp_path_factory.mktemp("faces")
    for v, i in (("X", 50), ("D", 29), ("F", 16)):
        cv2.imwrite(str(d / f"{v}.png"), cv2.cvtColor(frames[i], cv2.COLOR_RGB2BGR))
    return d


def _bank(tmp_path, face_images, lines):
    d = shutil.copytree(face_images, tmp_path / "bank")
    # the photos as they are: placing lines from the face on each picture must give what init
    # placed (one-face pictures take the plate's lines above the nose, which the editor
    # cannot see in a single picture)
    init_bank(d, lines=lines, keep_photos=True)
    return d


@pytest.fixture
def api():
    made = []

    def open_(bank_dir):
        ed = Editor(bank_dir, store=None)
        s = Session.open()
        c = TestClient(make_app(ed, s), base_url=s.origin)
        c.headers["X-Lipsync-Token"] = s.token
        made.append((ed, s))
        return ed, c

    yield open_
    for ed, s in made:
        ed.close()
        s.close()


def _doc(bank_dir):
    return yaml.safe_load((bank_dir / "bank.yaml").read_text())


def test_place_one_viseme_from_its_face(tmp_path, face_images, api):
    bank = _bank(tmp_path, face_images, "face")
    placed = _doc(bank)
    ed, c = api(bank)
    doc = c.get("/api/bank").json()["doc"]
    # the user dragged D's inner lower lip away; placing D from the face puts it back
    doc["visemes"]["D"]["lines"]["lip_inner_lower_l"]["polyline"][0] = [10.0, 10.0]
    doc["visemes"]["X"]["lines"]["brow_l"]["polyline"][0] = [20.0, 20.0]
    r = c.post("/api/face", json={"doc": doc, "visemes": ["D"]})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["sources"] == {"D": "face"} and body["axis"] is None
    assert body["doc"]["visemes"]["D"]["lines"] == placed["visemes"]["D"]["lines"]
    # only D was placed: X keeps the user's edit
    assert body["doc"]["visemes"]["X"]["lines"]["brow_l"]["polyline"][0] == [20.0, 20.0]
    # the placed document is a valid draft
    assert c.post("/api/draft", json={"doc": body["doc"]}).json()["ok"]


def test_place_all_turns_template_lines_into_face_lines(tmp_path, face_images, api):
    bank = _bank(tmp_path, face_images, "template")
    expected = _doc(_bank(tmp_path / "other", face_images, "face"))
    ed, c = api(bank)
    doc = c.get("/api/bank").json()["doc"]
    assert "upper_outer_l" in doc["visemes"]["X"]["lines"]
    # one viseme alone cannot switch to face lines: every viseme needs the same names
    r = c.post("/api/face", json={"doc": doc, "visemes": ["D"]})
    assert r.status_code == 422 and "all visemes" in r.json()["error"]["message"]
    r = c.post("/api/face", json={"doc": doc, "visemes": "all"})
    assert r.status_code == 200, r.text
    new = r.json()["doc"]
    for v in "XDF":
        assert new["visemes"][v]["lines"] == expected["visemes"][v]["lines"]
    assert new["warp"] == {"a": FACE_WARP.a, "b": FACE_WARP.b, "p": FACE_WARP.p}
    assert new["symmetry"] is False
    assert c.post("/api/save", json={"doc": new}).json()["ok"]
    assert _doc(bank)["visemes"]["D"]["lines"] == expected["visemes"]["D"]["lines"]


def test_place_from_face_refuses_what_it_cannot_do(tmp_path, api):
    bank = tmp_path / "plain"  # flat pictures: no face
    bank.mkdir()
    for v, grey in (("X", 90), ("A", 160)):
        cv2.imwrite(str(bank / f"{v}.png"), np.full((300, 400, 3), grey, np.uint8))
    init_bank(bank)
    ed, c = api(bank)
    doc = c.get("/api/bank").json()["doc"]
    r = c.post("/api/face", json={"doc": doc, "visemes": "all"})
    assert r.status_code == 422 and "no face found in any of the bank's images" in r.json()["error"]["message"]
    for bad in ("some", 5, [], ["nope"], [3]):
        r = c.post("/api/face", json={"doc": doc, "visemes": bad})
        assert r.status_code == 422, bad
    broken = dict(doc, rest="nope")
    assert c.post("/api/face", json={"doc": broken, "visemes": "all"}).status_code == 422
    assert c.post("/api/face", content=b"not json").status_code == 400


def test_place_from_face_button_in_chromium(tmp_path, face_images):
    from lipsync.editor.browser import chromium, editor_page, missing, wait

    if missing() is not None:
        pytest.skip(f"no headless Chromium: {missing()}")
    bank = _bank(tmp_path, face_images, "template")
    expected = _doc(_bank(tmp_path / "other", face_images, "face"))
    with chromium(1200, 800) as driver:
        with editor_page(bank, driver, store=tmp_path / "store") as (editor, session):
            driver.find_element("id", "face-scope").send_keys("all")
            version = driver.execute_script("return window.lipsyncEditor.version")
            driver.find_element("id", "face").click()
            wait(driver, "document.getElementById('message').textContent.startsWith('lines placed')",
                 what="lines placed from the face")
            wait(driver, f"window.lipsyncEditor.version > {version} && window.lipsyncEditor.pendingSince === null",
                 what="the draft of the placed lines")
            page = driver.execute_script("return window.lipsyncEditor.doc")
            for v in "XDF":
                assert page["visemes"][v]["lines"] == expected["visemes"][v]["lines"]
            # the canvas draws the new lines
            n = driver.execute_script("return document.querySelectorAll('#canvas-lines [data-feature=\"jaw_l\"]').length")
            assert n > 0
            # undo brings the template's lines (and warp) back
            driver.find_element("id", "undo").click()
            page = driver.execute_script("return window.lipsyncEditor.doc")
            assert "upper_outer_l" in page["visemes"]["X"]["lines"] and page["warp"]["b"] == 4.0
