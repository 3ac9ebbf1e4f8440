"""lipsync edit's server API, without a browser (Starlette TestClient and a real uvicorn)."""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time

import cv2
import httpx
import numpy as np
import pytest
import yaml
from starlette.testclient import TestClient

import synthetic
from lipsync.banks.bank import Bank
from lipsync.editor import Editor, make_app
from lipsync.morphing.render import Renderer
from lipsync.morphing.store import FlowStore
from lipsync.web import Session, start_in_thread


@pytest.fixture(scope="module")
def template_bank(tmp_path_factory):
    d = synthetic.write_bank(tmp_path_factory.mktemp("template") / "bank")
    text = (d / "bank.yaml").read_text()
    (d / "bank.yaml").write_text("# my synthetic face\n# second comment line\n" + text)
    return d


@pytest.fixture
def bank_dir(tmp_path, template_bank):
    d = shutil.copytree(template_bank, tmp_path / "bank")
    (tmp_path / "secret.txt").write_text("top secret")
    return d


@pytest.fixture
def editor(bank_dir):
    ed = Editor(bank_dir)
    yield ed
    ed.close()


@pytest.fixture
def session():
    s = Session.open()
    yield s
    s.close()


@pytest.fixture
def client(editor, session):
    c = TestClient(make_app(editor, session), base_url=session.origin)
    c.headers["X-Lipsync-Token"] = session.token
    return c


def decode(png: bytes) -> np.ndarray:
    return cv2.cvtColor(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def moved_doc(client, dx=2.0):
    doc = client.get("/api/bank").json()["doc"]
    lines = doc["visemes"]["O"]["lines"]
    # a symmetric edit (the pair moves mirrored), so the axis stays and only O's pairs change
    lines["upper_l"][1][0] -= dx
    lines["upper_r"][1][0] += dx
    return doc


def folder_state(d):
    return {p.name: p.read_bytes() for p in sorted(d.iterdir()) if p.is_file()}


def test_bank_info(client, bank_dir):
    info = client.get("/api/bank").json()
    assert info["shape"] == [160, 192] and info["axis"] == 95.5
    assert info["names"] == ["X", "A", "O", "E"]
    assert info["doc"] == yaml.safe_load((bank_dir / "bank.yaml").read_text())
    assert info["header"] == ["# my synthetic face", "# second comment line"]


def test_token_host_and_origin(client, session, bank_dir):
    before = folder_state(bank_dir)
    no_token = TestClient(client.app, base_url=session.origin)
    assert no_token.get("/api/bank").status_code == 403
    assert no_token.get("/api/bank?token=" + "x" * len(session.token)).status_code == 403
    assert no_token.get("/").status_code == 200  # the page itself carries no data
    assert client.get("/api/bank", headers={"host": "attacker.example:80"}).status_code == 403
    doc = moved_doc(client)
    r = client.post("/api/save", json={"doc": doc}, headers={"origin": "http://attacker.example"})
    assert r.status_code == 403
    r = client.post("/api/save", json={"doc": doc}, headers={"origin": "null"})
    assert r.status_code == 403
    assert folder_state(bank_dir) == before


@pytest.mark.parametrize("name", ["../secret.txt", "..%2Fsecret.txt", "%2e%2e/secret.txt", "link.png",
                                  "bank.yaml", "nope.png", "/etc/passwd", "%2Fetc%2Fpasswd"])
def test_only_bank_images_are_readable(client, bank_dir, name):
    os.symlink(bank_dir.parent / "secret.txt", bank_dir / "link.png")
    r = client.get("/api/image/" + name)
    assert r.status_code == 404
    assert b"top secret" not in r.content and b"visemes" not in r.content


def test_image_served(client, bank_dir):
    r = client.get("/api/image/O.png")
    assert r.status_code == 200 and r.headers["content-type"] == "image/png"
    assert r.content == (bank_dir / "O.png").read_bytes()


@pytest.mark.parametrize("body, status", [
    (b"not json", 400),
    (b"[1, 2]", 400),
    (b'{"doc": 5}', 400),
    (b'{"nodoc": {}}', 400),
    (b"[" * 100000, 400),  # deep nesting: RecursionError in the JSON parser
])
def test_invalid_payloads_refused_and_nothing_written(client, bank_dir, body, status):
    before = folder_state(bank_dir)
    for url in ("/api/save", "/api/draft"):
        r = client.post(url, content=body, headers={"content-type": "application/json"})
        assert r.status_code == status, (url, r.text)
        assert r.json()["ok"] is False
    assert folder_state(bank_dir) == before
    assert client.get("/api/status").status_code == 200  # still serving


def test_oversize_body_refused(client, bank_dir):
    before = folder_state(bank_dir)
    r = client.post("/api/save", content=b"{" + b" " * (3 << 20) + b"}")
    assert r.status_code == 413
    assert folder_state(bank_dir) == before


@pytest.mark.parametrize("mutate, viseme, feature, pattern", [
    (lambda d: d["visemes"]["A"]["lines"].pop("nose"), "A", None, r"viseme 'A': missing line 'nose'"),
    (lambda d: d["visemes"]["E"]["lines"].update(nose=[[5, 5], [5, 5]]), "E", "nose", "zero-length"),
    (lambda d: d["visemes"]["O"]["lines"].update(width=[[1, float("nan")], [5, 5]]), None, None, "finite"),
    (lambda d: d["visemes"]["O"].update(image="../secret.txt"), "O", None, "leads outside the bank folder"),
    (lambda d: d["visemes"]["O"]["lines"].update(width={"bezier": [[1, 1], [2, 2]]}), "O", "width", "bezier"),
    (lambda d: d.update(rest="Q"), None, None, "rest viseme 'Q'"),
    (lambda d: d["visemes"]["O"]["lines"].update(width="wide"), "O", "width", "expected"),
])
def test_save_with_an_error_writes_nothing_and_names_the_place(client, bank_dir, mutate, viseme, feature, pattern):
    before = folder_state(bank_dir)
    doc = client.get("/api/bank").json()["doc"]
    mutate(doc)
    body = json.dumps({"doc": doc}, allow_nan=True)
    for url in ("/api/save", "/api/draft"):
        r = client.post(url, content=body, headers={"content-type": "application/json"})
        assert r.status_code == 422, r.text
        err = r.json()["error"]
        assert re.search(pattern, err["message"]), err
        assert err["viseme"] == viseme and err["feature"] == feature
    assert folder_state(bank_dir) == before


def test_save_writes_exactly_the_edit_and_keeps_comments(client, bank_dir, editor):
    original = (bank_dir / "bank.yaml").read_text()
    others = {k: v for k, v in folder_state(bank_dir).items() if k != "bank.yaml"}
    doc = moved_doc(client, dx=2.5)
    r = client.post("/api/save", json={"doc": doc})
    assert r.status_code == 200 and r.json()["ok"]
    text = (bank_dir / "bank.yaml").read_text()
    assert text.startswith("# my synthetic face\n# second comment line\n")
    saved = yaml.safe_load(text)
    assert saved == doc
    old = yaml.safe_load(original)
    diffs = [(v, n) for v in old["visemes"] for n in old["visemes"][v]["lines"]
             if old["visemes"][v]["lines"][n] != saved["visemes"][v]["lines"][n]]
    assert diffs == [("O", "upper_l"), ("O", "upper_r")]
    x_old = old["visemes"]["O"]["lines"]["upper_l"][1][0]
    assert saved["visemes"]["O"]["lines"]["upper_l"][1][0] == pytest.approx(x_old - 2.5)
    assert list(saved) == list(old) and list(saved["visemes"]) == list(old["visemes"])
    assert {k: v for k, v in folder_state(bank_dir).items() if k != "bank.yaml"} == others
    assert Bank.load(bank_dir).lines["O"].shape == Bank.load(bank_dir).lines["X"].shape


def test_preview_follows_the_draft_and_matches_the_renderer(client, editor, bank_dir, tmp_path):
    assert editor.worker.wait_idle(60)
    r0 = client.get("/api/preview?from=X&to=O&alpha=0.5")
    assert r0.status_code == 200 and r0.headers["x-lipsync-method"] == "flow"
    before = decode(r0.content)
    doc = moved_doc(client, dx=6.0)
    v = client.post("/api/draft", json={"doc": doc}).json()["version"]
    status = client.get("/api/status").json()
    assert status["version"] == v
    # only the edited viseme's pairs need new flows: O with X, A and E
    assert status["flows"]["total"] == 3
    assert editor.worker.wait_idle(60)
    r1 = client.get("/api/preview?from=X&to=O&alpha=0.5")
    assert r1.headers["x-lipsync-method"] == "flow" and int(r1.headers["x-lipsync-version"]) == v
    after = decode(r1.content)
    assert np.abs(after.astype(int) - before).max() > 20  # the moved lines changed the frame
    # the same frame as the real renderer gives for the saved bank, computed independently
    client.post("/api/save", json={"doc": doc})
    want = Renderer(Bank.load(bank_dir), method="flow", store=FlowStore(tmp_path / "fresh")).render("X", "O", 0.5)
    assert np.abs(after.astype(int) - want).max() <= 1
    # the ends are the images themselves
    a0 = decode(client.get("/api/preview?from=X&to=O&alpha=0").content)
    assert np.array_equal(a0, Bank.load(bank_dir).images["X"])


def test_beier_neely_while_flows_are_missing(bank_dir, session, tmp_path):
    ed = Editor(bank_dir, store=FlowStore(tmp_path / "store"))
    try:
        ed.worker.stop()  # no background flows: the preview must not wait for them
        c = TestClient(make_app(ed, session), base_url=session.origin)
        c.headers["X-Lipsync-Token"] = session.token
        r = c.get("/api/preview?from=X&to=E&alpha=0.25")
        assert r.headers["x-lipsync-method"] == "beier-neely"
        want = Renderer(Bank.load(bank_dir), method="beier-neely", store=FlowStore(tmp_path / "s2")).render("X", "E", 0.25)
        assert np.abs(decode(r.content).astype(int) - want).max() <= 1
    finally:
        ed.close()


@pytest.mark.parametrize("query", ["from=X&to=Z&alpha=0.5", "from=X&to=O&alpha=2", "from=X&to=O&alpha=nan",
                                   "from=X&to=O&alpha=abc", "to=O"])
def test_preview_bad_queries(client, query):
    r = client.get("/api/preview?" + query)
    assert r.status_code == 400 and r.json()["ok"] is False


def test_real_server_on_loopback(editor, session, bank_dir):
    running = start_in_thread(make_app(editor, session), session)
    try:
        h = {"X-Lipsync-Token": session.token}
        assert httpx.get(session.url("/api/bank")).status_code == 200
        assert httpx.get(f"{session.origin}/api/bank").status_code == 403
        r = httpx.get(f"{session.origin}/api/bank", headers={**h, "Host": "rebound.example:%d" % session.port})
        assert r.status_code == 403
        page = httpx.get(f"{session.origin}/")
        assert page.status_code == 200 and "editor.js" in page.text
        assert "script-src 'self'" in page.headers["content-security-policy"]
        assert httpx.get(f"{session.origin}/static/editor.js").status_code == 200
        # httpx folds the "..": either way nothing outside static/ is served
        assert httpx.get(f"{session.origin}/static/../server.py").status_code in (403, 404)
        assert httpx.get(session.url("/static/%2e%2e/server.py")).status_code == 404
    finally:
        running.stop()


def test_cli_prints_url_with_token(bank_dir):
    proc = subprocess.Popen([sys.executable, "-m", "lipsync", "edit", str(bank_dir)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        url = None
        deadline = time.monotonic() + 60
        while url is None and time.monotonic() < deadline:
            line = proc.stdout.readline()
            m = re.search(r"(http://127\.0\.0\.1:\d+/\?token=\S+)", line)
            url = m.group(1) if m else None
        assert url, proc.stderr.read()
        base = url.split("?")[0].rstrip("/")
        token = url.split("token=")[1]
        for _ in range(100):
            try:
                r = httpx.get(base + "/api/bank", headers={"X-Lipsync-Token": token})
                break
            except httpx.ConnectError:
                time.sleep(0.05)
        assert r.status_code == 200 and r.json()["names"] == ["X", "A", "O", "E"]
        assert httpx.get(base + "/api/bank").status_code == 403
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=20)


def test_cli_bad_bank_exit_2(tmp_path, capsys):
    from lipsync.cli import main

    assert main(["edit", str(tmp_path)]) == 2
    assert "bank.yaml" in capsys.readouterr().err


def test_cli_taken_port_exit_2(bank_dir, capsys):
    from lipsync.cli import main

    taken = Session.open()
    try:
        assert main(["edit", str(bank_dir), "--port", str(taken.port)]) == 2
        assert f"cannot listen on 127.0.0.1:{taken.port}" in capsys.readouterr().err
    finally:
        taken.close()


def test_page_works_offline():
    # Everything the page loads comes from this server: no CDN, no other host, no build output.
    from lipsync.editor.server import STATIC

    files = sorted(STATIC.iterdir())
    assert {p.name for p in files} == {"index.html", "editor.js", "editor.css"}
    for p in files:
        text = p.read_text()
        urls = re.findall(r"(?:https?:)?//[A-Za-z0-9.-]+\.[A-Za-z]{2,}[^\s\"')]*", text)
        assert urls == ["http://www.w3.org/2000/svg"] * len(urls), (p.name, urls)  # the SVG namespace only
    html = (STATIC / "index.html").read_text()
    assert re.findall(r'(?:src|href)="([^"]+)"', html) == ["/static/editor.css", "/static/editor.js"]


def test_save_refuses_to_clobber_a_file_changed_on_disk(client, bank_dir):
    changed = (bank_dir / "bank.yaml").read_text().replace("name: synthetic", "name: changed-by-hand")
    (bank_dir / "bank.yaml").write_text(changed)
    r = client.post("/api/save", json={"doc": moved_doc(client)})
    assert r.status_code == 409 and "changed by someone else" in r.json()["error"]["message"]
    assert (bank_dir / "bank.yaml").read_text() == changed


def test_abandoned_draft_flows_are_removed_on_close(bank_dir, tmp_path):
    store = FlowStore(tmp_path / "store")
    other = store.pair_path("0" * 64)  # an entry the editor did not write (another bank's, say)
    other.parent.mkdir(parents=True)
    other.write_bytes(b"not ours")
    ed = Editor(bank_dir, store=store)
    assert ed.worker.wait_idle(60)
    base = ed.doc
    import copy

    for dx in (1.0, 2.0):  # two drafts that are never saved
        doc = copy.deepcopy(base)
        doc["visemes"]["O"]["lines"]["upper_l"][1][0] -= dx
        doc["visemes"]["O"]["lines"]["upper_r"][1][0] += dx
        ed.propose(doc)
        assert ed.worker.wait_idle(60)
    saved = copy.deepcopy(base)
    saved["visemes"]["E"]["lines"]["upper_l"][1][0] -= 1.5
    saved["visemes"]["E"]["lines"]["upper_r"][1][0] += 1.5
    ed.save(saved)
    assert ed.worker.wait_idle(60)
    ed.close()
    bank = Bank.load(bank_dir)
    from lipsync.editor.server import normalise_axis
    from lipsync.morphing.preprocess import all_pairs

    wanted = {store.pair_path(store.pair_key(bank, a, b, normalise_axis(bank))) for a, b in all_pairs(bank.names)}
    flows = set(store.pair_path("x").parent.glob("*" + store.pair_path("x").suffix))
    # the saved bank's six pairs stay, and the entry the editor did not write; the drafts'
    # flows and those of the version the save replaced are gone
    assert flows == wanted | {other}
    assert other.read_bytes() == b"not ours"


def test_browser_tests_say_why_they_skip():
    from lipsync.editor.browser import missing

    assert "chromium-driver" in missing(chromium="/bin/sh", chromedriver="/nonexistent/chromedriver")
    assert "Debian package chromium;" in missing(chromium="/nonexistent/chromium")


@pytest.mark.parametrize("doc", [
    {"name": "t", "rest": "X", "visemes": {"X": 5}},                      # the case (was a 500)
    {"name": "t", "rest": "X", "visemes": {"X": [1, 2]}},
    {"name": "t", "rest": "X", "visemes": {"X": None, "A": "a.png"}},
    {"name": "t", "rest": "X", "visemes": {"X": {"image": "X.png", "lines": 3}}},
    {"name": "t", "rest": "X", "visemes": {"X": {"image": "X.png", "lines": {"a": float("nan")}}}},
    {"name": ["t"], "rest": {"X": 1}, "visemes": []},
])
def test_malformed_documents_get_422_with_a_message(client, bank_dir, doc):
    before = folder_state(bank_dir)
    for route in ("/api/draft", "/api/save"):
        r = client.post(route, content=json.dumps({"doc": doc}))
        assert r.status_code == 422, (route, r.status_code, r.text[:300])
        assert r.json()["ok"] is False and r.json()["error"]["message"]
    assert folder_state(bank_dir) == before
