"""Live sessions of a bank with mouth samples select them within the look-ahead (issue 35 item 4).

``visemes/grid-s1`` keeps the lower face of every frame of its ten sentences as samples.
The phones of its first sentence are read from the samples table itself (each sample's
phone, frame by frame: the sentence's own alignment), so the sentence can be pushed to a
LiveAnimator as a TTS engine would push it:

* pushed whole before the first frame (a look-ahead covering the utterance), the session
  fixes exactly the samples the offline render selects, and its frames are the offline
  render's pixels;
* pushed phone by phone with frames taken 120 ms behind the data, the plan is remade as
  phones arrive, yet every frame shows what was fixed for it when it was first shown (the
  path is never retracted), and each frame is the composite of its fixed sample (the
  offline frame_plan over the fixed path, pasted by the offline compositor onto the plate);
* ``samples="off"`` (and bank.yaml's ``enabled: false``) is today's live morph: the offline
  Animator's old-morph frames for the same pushed timeline, and ``render --live --samples off``;
* a ``lipsync serve`` audio session on the bank sends the sample frames.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import wave
from pathlib import Path

import cv2
import numpy as np
import pytest

from lipsync import Animator, Bank
from lipsync._data import default_bank_dir
from lipsync.live import LiveAnimator
from lipsync.live.audio import RATE
from lipsync.live.samples import shared_samples
from lipsync.motion.timeline import Segment, Timeline
from lipsync.samples import load_samples
from lipsync.selection import frame_plan
from lipsync.speech.audio import load_audio

from live_session import audio_session

ROOT = Path(__file__).resolve().parents[1]
GRID_BANK = default_bank_dir().parent / "grid-s1"
AUDIO = ROOT / "tests" / "data" / "grid-s1-audio"


@pytest.fixture(scope="module")
def bank():
    return Bank.load(GRID_BANK)


@pytest.fixture(scope="module")
def sentence(bank):
    """The bank's first sentence as a phone timeline, from the samples' own phones (25 fps)."""
    s = load_samples(bank)
    rows = np.nonzero(s.table["clip"] == 0)[0]
    fps = float(s.table["fps"][0])
    segs = []
    for f, lab in zip(s.table["frame"][rows].tolist(), s.labels[rows].tolist()):
        if segs and segs[-1][2] == lab and abs(segs[-1][1] - f / fps) < 1e-9:
            segs[-1] = (segs[-1][0], (f + 1) / fps, lab)
        else:
            segs.append((f / fps, (f + 1) / fps, lab))
    tl = Timeline(tuple(Segment(a, e, lab) for a, e, lab in segs if lab != "sil"), kind="phoneme",
                  stated_end=len(rows) / fps)
    return tl, rows


def _composite(live, n, shows):
    """Frame ``n`` made independently of the session: the plate frame of its clock and the
    offline compositor's render of ``shows`` (src, dst, alpha)."""
    plate, line = live.plate, live._plate_line
    j = plate.index(n, live.fps, line)
    out = plate.frames[j].copy()
    comp = live.samples.shared.compositor
    return comp.render(*shows, out, plate.poses[j], prepared=comp.plate.prepare(plate.poses[j], out.shape))


def test_a_session_given_the_whole_sentence_chooses_the_offline_path(bank, sentence):
    tl, rows = sentence
    anim = Animator(bank, tl, fps=25, samples="on", plate_start=0.0)
    offline = anim.sample_path.selection.samples
    assert len(anim) == len(rows) == 75
    live = LiveAnimator(bank, fps=25, prepare=False)
    assert live.samples is not None                   # on by default for a bank with samples
    live.push(tl)
    got = [live.sample(n) for n in range(len(anim))]
    assert got == offline.tolist()
    assert live.samples.selection.windows == 1        # one plan: the whole utterance, as offline
    # not a trivial path: runs of real footage, and joins between them
    assert len(set(got)) > 20 and (np.diff(offline) == 1).mean() > 0.5 and (np.diff(offline) != 1).sum() >= 3
    for n in range(len(anim)):
        assert np.array_equal(live.frame(n), anim.frame(n)), n
    # the viseme the sequencer shows is unchanged by samples
    assert [live.spec(n) for n in range(len(anim))] == anim.specs


def test_with_a_short_lookahead_the_path_is_continuous_and_frames_are_their_samples(bank, sentence):
    tl, _ = sentence
    lag = 0.12                                         # frames taken 120 ms behind the data
    live = LiveAnimator(bank, fps=25, prepare=False)
    shown, fixed = {}, {}
    n = 0
    for seg in tl.segments:
        live.push(float(seg.start), float(seg.end), str(seg.label), kind="phoneme")
        while n / 25 + lag <= seg.end + 1e-9:
            shown[n] = live.frame(n).copy()
            fixed[n] = live.sample(n)
            n += 1
    total = 75
    for k in range(n, total):
        shown[k] = live.frame(k).copy()
        fixed[k] = live.sample(k)
    sel = live.samples.selection
    assert sel.windows > 10                            # the plan was remade as phones came
    path = np.array(sel.path[:total])
    assert path.tolist() == [fixed[k] for k in range(total)]   # nothing retracted
    # what each frame shows is the offline frame_plan over the fixed path
    src, dst, alpha = frame_plan(path, live.samples.shared.selector.succ, np.array(sel.exact[:total]))
    assert (live.samples.shared.selector.succ[path[:-1]] != path[1:]).sum() >= 3      # joins
    for k in range(total):
        want = _composite(live, k, (int(src[k]), int(dst[k]), float(alpha[k])))
        assert np.array_equal(shown[k], want), k
        assert np.array_equal(live.frame(k), shown[k]), k       # shown again: the same frame
    # with this little look-ahead the path still follows the real opening's course: its
    # samples' openings correlate with the offline path's
    offline = Animator(bank, tl, fps=25, samples="on", plate_start=0.0).sample_path.selection.samples
    opening = live.samples.shared.samples.opening
    assert np.corrcoef(opening[path], opening[offline])[0, 1] > 0.7


def test_samples_off_is_the_live_morph_of_today(bank, sentence):
    tl, _ = sentence
    old = Animator(bank, tl, fps=25, samples="off", plate_start=0.0)
    for live in (LiveAnimator(bank, fps=25, prepare=False, samples="off"),
                 LiveAnimator(dataclasses.replace(bank, samples=dataclasses.replace(bank.samples, enabled=False)),
                              fps=25, prepare=False)):
        assert live.samples is None
        live.push(tl)
        for n in (0, 20, 33, 50, 74):
            assert np.array_equal(live.frame(n), old.frame(n)), n
    with pytest.raises(ValueError):
        live.sample(0)
    with pytest.raises(Exception, match="samples"):
        LiveAnimator(bank, fps=25, prepare=False, samples="maybe")
    # a drawn bank has none, whatever is asked
    assert LiveAnimator(default_bank_dir(), prepare=False, samples="on").samples is None
    assert shared_samples(bank, "off", None, None) is None


def _wav(path, pcm):
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1), w.setsampwidth(2), w.setframerate(RATE)
        w.writeframes(pcm.astype("<i2").tobytes())
    return path


def _session(bank, pcm, **options):
    return audio_session(bank, pcm, prepare=False, **options)


def test_render_live_writes_the_sessions_samples_and_off_its_morph(bank, tmp_path):
    pcm = load_audio(AUDIO / "bram2n.flac")[:int(1.2 * RATE)]
    wav = _wav(tmp_path / "one.wav", pcm)
    live, on = _session(bank, pcm)
    _, off = _session(bank, pcm, samples="off")
    assert sorted(on) == sorted(off) == list(range(30))
    # every frame fixed with its audio: a fixed frame's window starts at it and reaches
    # no further than the audio heard (the 200 ms look-ahead: 5 frames), until the end
    sel = live.samples.selection
    assert sel.windows >= 20 and sel.window_frames / sel.windows <= 8
    for opt, want in (("on", on), ("off", off)):
        out = tmp_path / opt
        r = subprocess.run([sys.executable, "-m", "lipsync", "render", str(wav), "--live", "--samples", opt,
                            "--bank", str(GRID_BANK), "-o", f"{out}/", "--quiet"], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        files = sorted(out.glob("*.png"))
        assert len(files) == 30
        for n, f in enumerate(files):
            assert np.array_equal(cv2.cvtColor(cv2.imread(str(f)), cv2.COLOR_BGR2RGB), want[n]), (opt, n)
    # samples and morph differ in the mouth only
    mesh = np.asarray(json.loads((GRID_BANK / "plate.json").read_text())["rest_mesh"], np.float64)
    nose = int(mesh[:, 1].min() + 0.5 * (mesh[:, 1].max() - mesh[:, 1].min()))
    diff = [np.abs(on[n].astype(int) - off[n]).mean(axis=2) for n in range(30)]
    assert np.mean([d[nose:].mean() for d in diff]) > 1.0
    assert max(d[:int(mesh[:, 1].min())].max() for d in diff) == 0


def test_a_serve_audio_session_on_a_sample_bank_sends_sample_frames(bank):
    import asyncio

    from lipsync.server.protocol import HEADER
    from test_serve import Running, _connect

    pcm = load_audio(AUDIO / "lgwg3s.flac")[:int(1.2 * RATE)]
    srv = Running(bank=str(GRID_BANK), max_sessions=2, idle_timeout=30)
    try:
        assert srv.server.samples is not None

        async def run():
            got = {}
            async with await _connect(srv) as ws:
                await ws.recv()
                await ws.send(json.dumps({"type": "config", "audio_rate": 16000, "plate_start": 0}))
                await ws.recv()
                for i in range(0, len(pcm), 8000):
                    await ws.send(pcm[i:i + 8000].astype("<i2").tobytes())
                await ws.send(json.dumps({"type": "end"}))
                while True:
                    msg = await asyncio.wait_for(ws.recv(), 30)
                    if isinstance(msg, bytes):
                        n = HEADER.unpack(msg[:HEADER.size])[0]
                        bgr = cv2.imdecode(np.frombuffer(msg[HEADER.size:], np.uint8), cv2.IMREAD_COLOR)
                        got[n] = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
                    else:
                        m = json.loads(msg)
                        assert m["type"] != "error", m
                        if m["type"] == "end":
                            return got

        got = asyncio.run(run())
    finally:
        srv.stop()
    _, on = _session(bank, pcm)
    _, off = _session(bank, pcm, samples="off")
    assert max(got) == 29
    assert max(np.abs(got[n].astype(int) - on[n]).mean() for n in got) < 2.5     # JPEG at quality 80
    # where samples and morph differ (the mouth), the frames sent are the samples'
    mouth = np.mean([np.abs(on[n].astype(int) - off[n]).max(axis=2) for n in got], axis=0) > 8
    assert mouth.sum() > 500
    near_on = np.mean([np.abs(got[n].astype(int) - on[n]).max(axis=2)[mouth].mean() for n in got])
    near_off = np.mean([np.abs(got[n].astype(int) - off[n]).max(axis=2)[mouth].mean() for n in got])
    assert near_off > 2 * near_on, (near_on, near_off)


def test_a_frame_far_past_the_data_is_rest_and_fixes_no_frames_on_the_way(bank, sentence):
    from lipsync.selection.select import CLOSED

    tl, _ = sentence
    live = LiveAnimator(bank, fps=25, prepare=False)
    live.push(tl)
    assert live.frame(10).shape == (222, 240, 3)
    live.frame_at(120.0)                        # a clock two minutes on: rest, at once
    sel = live.samples.selection
    assert sel.first == 3000 and len(sel.path) == 1 and sel.windows < 20
    k = live.sample(sel.first)
    s = live.samples.shared.samples
    assert s.opening[k] <= CLOSED and s.labels[k] == "sil"
    # a frame skipped over shows the morph's rest (it was never shown with a sample)
    old = Animator(bank, tl, fps=25, samples="off", plate_start=0.0)
    assert np.array_equal(live.frame(74), old.frame(74))


def test_dropping_phones_no_window_reaches_changes_no_sample(bank, sentence, monkeypatch):
    """A long session keeps only the phones its windows still reach: three sentences pushed
    phone by phone, frames taken 120 ms behind, fix the same samples whether old phones are
    dropped every few pushes or never."""
    import lipsync.live.animator as A

    tl, _ = sentence
    segs = [(float(s.start) + 3.0 * k, float(s.end) + 3.0 * k, str(s.label)) for k in range(3) for s in tl.segments]
    paths = []
    for keep in (4, 10 ** 9):
        monkeypatch.setattr(A, "_KEEP_PHONES", keep)
        live = LiveAnimator(bank, fps=25, prepare=False)
        n = 0
        for a, b, lab in segs:
            live.push(a, b, lab, kind="phoneme")
            while n / 25 + 0.12 <= b + 1e-9:
                live.sample(n)
                n += 1
        paths.append(live.samples.selection.path[:n])
        if keep == 4:
            assert len(live._phones) < len(segs) / 2        # old phones were dropped
    assert n > 150 and paths[0] == paths[1]
