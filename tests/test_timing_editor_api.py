"""lipsync edit-timeline's API without a browser: GET, PUT, frames, saves, reloads, refusals.

The recording is GRID's bram2n (tests/data/grid-s1-audio, CC BY 4.0) with its own word
alignment (.align), so no aligner runs here.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from starlette.testclient import TestClient

from lipsync import read_timeline
from lipsync.errors import InputError
from lipsync.motion.timeline import Segment, Timeline
from lipsync.readers.papagayo import read_words
from lipsync.timing_editor import TimingEditor, make_app
from lipsync.timing_editor import model as model_mod
from lipsync.timing_editor import server as server_mod
from lipsync.web import Session

DATA = Path(__file__).parent / "data" / "grid-s1-audio"
AUDIO, ALIGN = DATA / "bram2n.flac", DATA / "bram2n.align"
FPS = 25.0


@pytest.fixture
def editor(tmp_path):
    return TimingEditor(AUDIO, timeline=ALIGN, out=tmp_path / "out" / "bram2n", fps=FPS)


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


def rows(tl):
    return [{"start": s.start, "end": s.end, "label": s.label} for s in tl]


def merged(segs):
    out = []
    for s in segs:
        if out and out[-1]["label"] == s["label"] and out[-1]["end"] == s["start"]:
            out[-1] = dict(out[-1], end=s["end"])
        else:
            out.append(s)
    return out


def grid_words():
    """The .align file's words in seconds, written out here from its units (1/25000 s)."""
    out = []
    for line in ALIGN.read_text().split("\n"):
        parts = line.split()
        if len(parts) == 3 and parts[2] != "sil":
            out.append((int(parts[0]) / 25000, int(parts[1]) / 25000, parts[2]))
    return out


def test_get_is_the_files_words_on_the_frame_grid(client):
    doc = client.get("/api/timeline").json()
    assert set(doc) == {"words", "phones", "visemes"}
    want = [(round(a * FPS) / FPS, round(b * FPS) / FPS, w) for a, b, w in grid_words()]
    assert [(w["start"], w["end"], w["label"]) for w in doc["words"]] == want
    # every phone lies inside a word, and the viseme tier covers the recording with no gap
    for p in doc["phones"]:
        assert any(w["start"] <= p["start"] and p["end"] <= w["end"] for w in doc["words"]), p
    vis = doc["visemes"]
    assert vis[0]["start"] == 0 and all(a["end"] == b["start"] for a, b in zip(vis, vis[1:]))
    info = client.get("/api/info").json()
    assert vis[-1]["end"] == info["duration"] and info["fps"] == FPS
    assert info["frames"] == int(np.ceil(info["duration"] * FPS))  # as lipsync render makes them
    for tier in (doc["words"], doc["phones"]):
        for s in tier:
            assert s["start"] * FPS == pytest.approx(round(s["start"] * FPS), abs=1e-9)


def edited(doc, old=1.52, new=1.44):
    """The 'two' | 'now' boundary 80 ms earlier; the phone edge under it follows (UW | N)."""
    doc = json.loads(json.dumps(doc))
    for tier in ("words", "phones"):
        for s in doc[tier]:
            for key in ("start", "end"):
                if s[key] == old:
                    s[key] = new
    doc["visemes"] = None  # derived again from the phones
    return doc


def test_put_frame_save_reload(client, editor, tmp_path):
    from lipsync.pipeline.animator import Animator

    before = client.get("/api/timeline").json()
    doc = edited(before)
    r = client.put("/api/timeline", json=doc)
    assert r.status_code == 200, r.text
    stored = r.json()
    assert client.get("/api/timeline").json() == stored
    assert [w["label"] for w in stored["words"]] == [w["label"] for w in before["words"]]
    assert stored["words"][4]["end"] == 1.44 and stored["words"][5]["start"] == 1.44
    assert [p["label"] for p in stored["phones"] if p["start"] == 1.44] == ["N"]
    assert stored["visemes"] != before["visemes"]
    # retype "at" as "in": its phones from the lexicon (CMUdict: IH N), spread over the word
    r = client.post("/api/retype", json={"index": 2, "label": "in"})
    assert r.status_code == 200, r.text
    stored = r.json()
    w = stored["words"][2]
    inside = [p for p in stored["phones"] if w["start"] <= p["start"] and p["end"] <= w["end"]]
    assert w["label"] == "in" and [p["label"] for p in inside] == ["IH", "N"]
    assert inside[0]["start"] == w["start"] and inside[-1]["end"] == w["end"]

    # the preview frame = an independent Animator over the stored viseme tier
    vis = Timeline(tuple(Segment(s["start"], s["end"], s["label"]) for s in stored["visemes"]), kind="viseme",
                   stated_end=editor.context.duration)
    anim = Animator(editor.bank, vis, fps=FPS)
    for t in (0.0, 1.1, 1.23, 1.46, 2.0):
        got = decode(client.get(f"/api/frame?t={t}").content)
        np.testing.assert_array_equal(got, anim.frame(int(np.floor(t * FPS + 1e-9))), err_msg=f"t={t}")

    # save each format; each reads back as exactly the edited timeline
    paths = {}
    for fmt in ("textgrid", "pgo", "rhubarb-tsv", "rhubarb-json", "moho"):
        r = client.post(f"/api/save?format={fmt}")
        assert r.status_code == 200, r.text
        paths[fmt] = r.json()["path"]
    assert sorted(os.listdir(tmp_path / "out")) == ["bram2n.TextGrid", "bram2n.dat", "bram2n.json", "bram2n.pgo",
                                                    "bram2n.tsv"]
    assert rows(read_timeline(paths["textgrid"], tier="words")) == stored["words"]
    assert rows(read_timeline(paths["textgrid"])) == stored["phones"]
    assert rows(read_timeline(paths["pgo"])) == stored["phones"]
    assert rows(read_words(paths["pgo"])) == stored["words"]
    # Papagayo opens the sound relative to the project
    assert Path(paths["pgo"]).read_text().split("\n")[1] == os.path.relpath(AUDIO.resolve(), tmp_path / "out")
    assert rows(read_timeline(paths["rhubarb-tsv"])) == stored["visemes"]
    assert rows(read_timeline(paths["rhubarb-json"])) == stored["visemes"]
    moho = editor.map.aliases  # the map's Preston Blair names, back to its own
    back = {aliases[0]: v for v, aliases in moho.items() if aliases}
    # a Moho file's last key is "rest from here on": the reader shows it for one frame
    end = stored["visemes"][-1]["end"]
    moho_rows = merged([dict(r, label=back.get(r["label"], r["label"]))
                        for r in rows(read_timeline(paths["moho"], fps=FPS))])
    # Moho holds whole frames: a diphthong's mid-frame split moves by half a frame at most
    # (and it keys a shape once where two phones in a row show it)
    assert [r["label"] for r in moho_rows] == [r["label"] for r in merged(stored["visemes"])]
    for got, want in zip(moho_rows, merged(stored["visemes"])):
        assert abs(got["start"] - want["start"]) <= 0.5 / FPS + 1e-9
    assert moho_rows[-1]["end"] >= end

    # reopening any saved file in the editor gives the same timeline
    for fmt, path in paths.items():
        if fmt == "moho":
            continue  # whole frames (above)
        again = TimingEditor(AUDIO, timeline=path, fps=FPS, out=tmp_path / "again").get()
        tiers = ("words", "phones", "visemes") if fmt in ("textgrid", "pgo") else ("visemes",)
        for tier in tiers:
            assert again[tier] == stored[tier], (fmt, tier)

    # lipsync render of the saved TextGrid (the phones) and of the saved viseme track: every
    # frame is the preview's (PNG folders)
    for fmt in ("textgrid", "rhubarb-tsv"):
        frames = tmp_path / f"frames-{fmt}"
        r = subprocess.run([sys.executable, "-m", "lipsync", "render", paths[fmt], "-o", f"{frames}/",
                            "--fps", str(FPS), "--quiet"], capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        pngs = sorted(frames.iterdir())
        assert len(pngs) == client.get("/api/info").json()["frames"]
        for i, png in enumerate(pngs):
            rendered = cv2.cvtColor(cv2.imread(str(png), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
            shown = decode(client.get(f"/api/frame?t={i / FPS}").content)
            np.testing.assert_array_equal(shown, rendered, err_msg=f"{fmt} frame {i}")


def test_save_keeps_the_previous_file(client, tmp_path):
    first = client.post("/api/save?format=textgrid").json()["path"]
    old = Path(first).read_bytes()
    doc = client.get("/api/timeline").json()
    doc["words"][0]["label"] = "bins"
    assert client.put("/api/timeline", json=doc).status_code == 200
    assert client.post("/api/save?format=textgrid").json()["path"] == first
    assert Path(first + ".bak").read_bytes() == old
    assert read_timeline(first, tier="words")[0].label == "bins"
    assert sorted(os.listdir(tmp_path / "out")) == ["bram2n.TextGrid", "bram2n.TextGrid.bak"]


def test_a_failed_save_leaves_the_file_and_nothing_else(client, editor, tmp_path):
    path = client.post("/api/save?format=pgo").json()["path"]
    old = Path(path).read_bytes()
    doc = client.get("/api/timeline").json()
    doc["words"][0]["label"] = "two words"  # a Papagayo word is one token
    assert client.put("/api/timeline", json=doc).status_code == 200
    r = client.post("/api/save?format=pgo")
    assert r.status_code == 400 and "one token" in r.json()["error"]
    assert Path(path).read_bytes() == old
    assert sorted(os.listdir(tmp_path / "out")) == ["bram2n.pgo"]


def bad_docs(doc):
    def change(fn):
        d = json.loads(json.dumps(doc))
        fn(d)
        return d

    w = doc["words"]
    return [
        ("overlap", change(lambda d: d["words"][1].update(start=w[0]["end"] - 0.08)), "overlaps"),
        ("negative", change(lambda d: d["words"][0].update(start=-0.04)), "negative"),
        ("empty", change(lambda d: d["words"][0].update(end=w[0]["start"])), "at or before"),
        ("unknown phone", change(lambda d: d["phones"][0].update(label="QQ")), "unknown phone"),
        ("unknown viseme", change(lambda d: d["visemes"][1].update(label="Z9")), "not in the bank"),
        ("past the end", change(lambda d: d["words"][-1].update(end=99.0)), "after the recording"),
        ("not a number", change(lambda d: d["words"][0].update(start="0.5")), "finite number"),
        ("infinite", change(lambda d: d["phones"][0].update(end=float("inf"))), "finite number"),
        ("label type", change(lambda d: d["words"][0].update(label=7)), "label"),
        ("long label", change(lambda d: d["words"][0].update(label="a" * 101)), "label"),
        ("missing key", change(lambda d: d["words"][0].pop("end")), "start, end and label"),
        ("extra tier", change(lambda d: d.update(mouths=[])), "unknown keys"),
        ("tier type", change(lambda d: d.update(words={})), "must be a list"),
    ]


def test_bad_timelines_are_400_and_change_nothing(client):
    doc = client.get("/api/timeline").json()
    for name, bad, reason in bad_docs(doc):
        r = client.put("/api/timeline", content=json.dumps(bad, allow_nan=True))
        assert r.status_code == 400, name
        assert reason in r.json()["error"], (name, r.json())
        assert client.get("/api/timeline").json() == doc, name
    many = {"words": [{"start": 0, "end": 0.04, "label": "a"}] * (model_mod.MAX_SEGMENTS + 1), "phones": []}
    r = client.put("/api/timeline", json=many)
    assert r.status_code == 400 and "over the limit" in r.json()["error"]
    for body in (b"not json", b"[1, 2]", b"null"):
        r = client.put("/api/timeline", content=body)
        assert r.status_code == 400 and "error" in r.json()
    for body, reason in (({"index": 99, "label": "x"}, "no word 99"), ({"index": 0, "label": "..."}, "no sounds"),
                         ({"index": "0", "label": "x"}, "expected"),
                         ({"index": 0, "label": "supercalifragilistic"}, "widen the word")):
        r = client.post("/api/retype", json=body)
        assert r.status_code == 400 and reason in r.json()["error"], (body, r.json())
    for q in ("", "?t=abc", "?t=nan", "?t=-1", "?t=1e9", "?t=inf"):
        r = client.get("/api/frame" + q)
        assert r.status_code == 400 and "t must" in r.json()["error"], q
    r = client.post("/api/save?format=docx")
    assert r.status_code == 400 and "format must be one of" in r.json()["error"]
    assert client.get("/api/timeline").json() == doc


def test_saving_over_an_input_is_refused(tmp_path, session):
    tg = tmp_path / "in.TextGrid"
    ed0 = TimingEditor(AUDIO, timeline=ALIGN, out=tmp_path / "in", fps=FPS)
    ed0.save("textgrid")
    before = tg.read_bytes()
    ed = TimingEditor(AUDIO, timeline=tg, out=tmp_path / "in", fps=FPS)
    c = TestClient(make_app(ed, session), base_url=session.origin, headers={"X-Lipsync-Token": session.token})
    r = c.post("/api/save?format=textgrid")
    assert r.status_code == 400 and "input" in r.json()["error"]
    assert tg.read_bytes() == before and not (tmp_path / "in.TextGrid.bak").exists()


def test_bad_inputs_to_the_editor(tmp_path, monkeypatch):
    not_audio = tmp_path / "notes.wav"
    not_audio.write_text("these are not samples")
    with pytest.raises(InputError, match="notes.wav"):
        TimingEditor(not_audio, timeline=ALIGN)
    overlapping = tmp_path / "bad.align"
    overlapping.write_text("0 13000 sil\n13000 19250 bin\n15000 24750 red\n")
    with pytest.raises(InputError, match="bad.align"):
        TimingEditor(AUDIO, timeline=overlapping)
    unknown = tmp_path / "cues.txt"  # Audacity labels with a phone no map knows
    unknown.write_text("0.5\t0.7\tQQ\n0.7\t0.9\tAA\n")
    with pytest.raises(InputError, match=r"cues\.txt.*unknown phone label\(s\): QQ"):
        TimingEditor(AUDIO, timeline=unknown)
    # the length bound (an hour; lowered here so a 3 s file is "too long")
    monkeypatch.setattr(server_mod, "MAX_AUDIO_S", 2.0)
    with pytest.raises(InputError, match="longer than the editor's limit"):
        TimingEditor(AUDIO, timeline=ALIGN)


def test_cli_exit_2_names_the_file(tmp_path):
    not_audio = tmp_path / "notes.mp3"
    not_audio.write_bytes(b"\x00" * 200)
    r = subprocess.run([sys.executable, "-m", "lipsync", "edit-timeline", str(not_audio), "--timeline", str(ALIGN)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "notes.mp3" in r.stderr and "Traceback" not in r.stderr


def test_guard_refusals(editor, session):
    app = make_app(editor, session)
    c = TestClient(app, base_url=session.origin)
    assert c.get("/api/timeline").status_code == 403  # no token
    assert c.get("/api/timeline", headers={"X-Lipsync-Token": "wrong"}).status_code == 403
    assert c.get(session.url("/api/timeline")).status_code == 200  # token as the query parameter
    ok = {"X-Lipsync-Token": session.token}
    assert c.get("/api/timeline", headers={**ok, "Host": "evil.example"}).status_code == 403
    assert c.put("/api/timeline", headers={**ok, "Origin": "http://evil.example"}, content=b"{}").status_code == 403
    assert c.post("/api/save?format=textgrid", headers={**ok, "Origin": "http://evil.example"}).status_code == 403
    big = b"[" + b"0," * (server_mod.MAX_BODY // 2) + b"0]"
    assert c.put("/api/timeline", headers=ok, content=big).status_code == 413
    assert c.get("/", headers={}).status_code == 200  # the page itself is public (it holds no data)
    assert session.host == "127.0.0.1"


def test_page_assets_and_audio(client, editor):
    assert "timing.js" in client.get("/").text
    peaks = client.get("/api/peaks").json()
    assert peaks["rate"] == 200 and len(peaks["min"]) == len(peaks["max"]) == int(editor.context.duration * 200)
    pcm = editor.pcm.astype(np.int32)
    k = int(np.argmax(peaks["max"]))  # the loudest block: its extreme, scaled to 127
    assert peaks["max"][k] == pcm[k * 80:(k + 1) * 80].max() * 127 // 32767
    wav = client.get("/api/audio")
    assert wav.headers["content-type"] == "audio/wav"
    np.testing.assert_array_equal(np.frombuffer(wav.content[44:], "<i2"), editor.pcm)


def test_module_examples_run():
    import doctest

    import lipsync.readers.papagayo
    import lipsync.writers.papagayo

    for module in (model_mod, server_mod, lipsync.writers.papagayo, lipsync.readers.papagayo):
        result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
        assert result.failed == 0 and result.attempted > 0, module.__name__


def test_render_writes_the_video_with_the_previewed_frames(client, tmp_path):
    r = client.post("/api/render")
    assert r.status_code == 200, r.text
    path = r.json()["path"]
    assert path == str(tmp_path / "out" / "bram2n.mp4")
    cap = cv2.VideoCapture(path)
    frames = []
    while True:
        ok, bgr = cap.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
    n = client.get("/api/info").json()["frames"]
    assert len(frames) == n
    rest = decode(client.get("/api/frame?t=0").content).astype(int)
    for i in (0, 30, 40, n - 1):  # H.264 is lossy: close, not equal
        shown = decode(client.get(f"/api/frame?t={i / FPS}").content).astype(int)
        assert np.abs(frames[i].astype(int) - shown).mean() < 3, i
        if i in (30, 40):  # speech: where the preview's mouth is not the rest's, the video shows it too
            mouth = np.abs(shown - rest).max(axis=2) > 40
            assert mouth.sum() > 500
            own = np.abs(frames[i].astype(int) - shown)[mouth].mean()
            assert own < np.abs(frames[i].astype(int) - rest)[mouth].mean() / 4, i
    assert os.listdir(tmp_path / "out") == ["bram2n.mp4"]


def test_a_changed_phone_changes_its_viseme(client):
    doc = client.get("/api/timeline").json()
    b = doc["phones"][0]
    assert (b["label"], b["start"], b["end"]) == ("B", 0.52, 0.6)  # "bin" begins with closed lips
    assert [v["label"] for v in doc["visemes"] if v["start"] == 0.52] == ["A"]
    doc["phones"][0]["label"] = "AA"  # the map (english-to-rhubarb): AA -> D, wide open
    doc["visemes"] = None
    stored = client.put("/api/timeline", json=doc).json()
    assert [(v["label"], v["end"]) for v in stored["visemes"] if v["start"] == 0.52] == [("D", 0.6)]
    # a viseme changed by hand is kept as given (and its segment keeps its times)
    stored["visemes"] = [dict(v, label="G") if v["start"] == 0.52 else v for v in stored["visemes"]]
    again = client.put("/api/timeline", json=stored).json()
    assert again == stored


def test_retyping_in_another_language_uses_its_letters_to_sounds(tmp_path):
    from lipsync.phonetics.g2p import espeak_available

    if not espeak_available():
        pytest.skip("espeak-ng (the languages extra) is not installed")
    # Spanish "sol": espeak-ng's IPA s, o, l, spread over the word
    ed = TimingEditor(AUDIO, timeline=ALIGN, fps=FPS, out=tmp_path / "o", lang="es")
    doc = ed.retype(0, "sol")
    w = doc["words"][0]
    inside = [p["label"] for p in doc["phones"] if w["start"] <= p["start"] and p["end"] <= w["end"]]
    assert w["label"] == "sol" and inside == ["s", "o", "l"]


def test_where_saves_go(tmp_path):
    def target(out, ext):
        return TimingEditor(AUDIO, timeline=ALIGN, out=out).target(ext)

    assert target(None, ".pgo") == str(DATA.resolve() / "bram2n.edited.pgo")  # beside the audio
    assert target(tmp_path, ".tsv") == str(tmp_path / "bram2n.edited.tsv")  # into a folder
    assert target(tmp_path / "fixed.mp4", ".TextGrid") == str(tmp_path / "fixed.TextGrid")
    assert target(tmp_path / "fixed.mp4", ".mp4") == str(tmp_path / "fixed.mp4")
    assert target(tmp_path / "take2", ".dat") == str(tmp_path / "take2.dat")
