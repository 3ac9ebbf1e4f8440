"""Live sessions of a bank made from video show its idle plate (issue 36 item 2).

A LiveAnimator of ``visemes/grid-s1`` fed 10 s of real speech (three GRID sentences of the
same speaker, tests/data/grid-s1-audio) in 20 ms chunks, each frame rendered as it falls
due (as ``lipsync serve`` does), must give exactly the frames ``lipsync render --live``
writes for the same audio, and above the nose (which the mouth never touches) exactly the
plate's own frames at the session's clock: the speaker's blinks and head motion, frame by
frame. The plate is decoded once and shared by every animator of the bank.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from lipsync import Bank
from lipsync._data import default_bank_dir
from lipsync.bench.grid import above_nose_changes, above_nose_rows
from lipsync.live import LiveAnimator
from lipsync.live.audio import BLOCK, RATE
from lipsync.live.pool import shared_plate
from lipsync.speech.audio import load_audio

from live_session import audio_session

ROOT = Path(__file__).resolve().parents[1]
AUDIO = ROOT / "tests" / "data" / "grid-s1-audio"
GRID_BANK = default_bank_dir().parent / "grid-s1"
SECONDS = 10.0


@pytest.fixture(scope="module")
def bank():
    return Bank.load(GRID_BANK)


@pytest.fixture(scope="module")
def speech(tmp_path_factory):
    """10 s of the speaker: three sentences end to end, as a 16 kHz WAV and its samples."""
    pcm = np.concatenate([load_audio(AUDIO / f"{n}.flac") for n in ("bram2n", "lgwg3s", "lray6p", "lwwf8p")])
    pcm = pcm[:int(SECONDS * RATE)]
    assert len(pcm) == SECONDS * RATE
    wav = tmp_path_factory.mktemp("speech") / "speech.wav"
    import wave

    with wave.open(str(wav), "wb") as w:
        w.setnchannels(1), w.setsampwidth(2), w.setframerate(RATE)
        w.writeframes(pcm.astype("<i2").tobytes())
    return pcm, wav


def _blinks(frames, mesh) -> list:
    """Frames where an eyelid closes or opens: the mean grey of the box around both eyes
    (the rest mesh's eyelid points) jumps by more than 3 robust standard deviations of the
    clip's eye-box grey in one frame (a lid sweeps over the dark iris in 2-3 frames; the
    head's drift changes the box slowly)."""
    from lipsync.face import topology as T

    pts = mesh[list(T.EYE_UPPER_L + T.EYE_LOWER_L + T.EYE_UPPER_R + T.EYE_LOWER_R)]
    (x0, y0), (x1, y1) = pts.min(0).astype(int) - 2, pts.max(0).astype(int) + 3
    grey = np.array([cv2.cvtColor(f, cv2.COLOR_RGB2GRAY)[y0:y1, x0:x1].mean() for f in frames])
    sigma = 1.4826 * np.median(np.abs(grey - np.median(grey)))
    return [int(n) + 1 for n in np.nonzero(np.abs(np.diff(grey)) > 3 * sigma)[0]]


def _session_frames(bank, pcm, **options):
    return audio_session(bank, pcm, **options)


def test_a_live_session_shows_the_plate_and_equals_render_live(bank, speech, tmp_path):
    pcm, wav = speech
    live, frames = _session_frames(bank, pcm)
    assert sorted(frames) == list(range(250))          # 10 s at 25 fps, the last look-ahead's frames included
    r = subprocess.run([sys.executable, "-m", "lipsync", "render", str(wav), "--live", "--bank", str(GRID_BANK),
                        "-o", f"{tmp_path / 'frames'}/", "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    files = sorted((tmp_path / "frames").glob("*.png"))
    assert len(files) == 250
    for n, f in enumerate(files):
        rgb = cv2.cvtColor(cv2.imread(str(f), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        assert np.array_equal(rgb, frames[n]), n

    # above the nose: the plate's own pixels at the session's clock, so its motion and blinks
    plate = live.plate
    assert plate is not None and plate is shared_plate(bank)
    mesh = np.asarray(json.loads((GRID_BANK / "plate.json").read_text())["rest_mesh"], np.float64)
    rows = above_nose_rows(mesh) - 3     # the mask's feather stays below the nose's lower edge
    seq = [frames[n] for n in range(250)]
    ours = above_nose_changes(seq, rows)
    theirs = above_nose_changes([plate.frames[plate.index(n, 25.0)] for n in range(250)], rows)
    assert np.array_equal(ours, theirs)
    for n in (0, 77, 249):
        assert np.array_equal(frames[n][:rows], plate.frames[plate.index(n, 25.0)][:rows])
    # the plate moves in most frames, and the speaker blinks
    assert np.mean(ours > 0) > 0.9
    blinks = _blinks(seq, mesh)
    assert len(blinks) >= 1, blinks
    # the still pictures (the old live session) hardly move above the nose (the morph's
    # reach: a grey level on a few pixels) and never blink
    still = LiveAnimator(bank, fps=25, still=True, prepare=False)
    for i in range(0, 16000 * 2, BLOCK):
        still.feed_audio(pcm[i:i + BLOCK], RATE)
    assert still.plate is None
    assert above_nose_changes([still.frame(n) for n in range(25)], rows).max() < 0.05 * np.median(ours)


def test_the_plate_is_decoded_once_and_shared(bank):
    a = LiveAnimator(bank, fps=25, prepare=False)
    b = LiveAnimator(Bank.load(GRID_BANK), fps=30, prepare=False)
    assert a.plate is b.plate
    assert not a.plate.frames.flags.writeable           # shared pixels cannot be drawn on by mistake
    # a transparent or plate-less bank has none
    assert LiveAnimator(default_bank_dir(), prepare=False).plate is None


def test_a_serve_session_of_grid_s1_sends_the_plate_frames(speech):
    """`lipsync serve --bank visemes/grid-s1`: an audio session's JPEG frames are the
    LiveAnimator's plate frames (within JPEG's error), the last look-ahead's included."""
    import asyncio

    from lipsync.server.protocol import HEADER
    from test_serve import Running, _connect

    pcm = speech[0][:int(1.6 * RATE)]
    srv = Running(bank=str(GRID_BANK), max_sessions=2, idle_timeout=30)
    try:
        assert srv.server.plate is not None and srv.server.plate is shared_plate(srv.server.bank)

        async def run():
            got = {}
            async with await _connect(srv) as ws:
                await ws.recv()
                # the plate where render --live and a default LiveAnimator start (a session
                # otherwise starts at a place of its own: test_serve_sessions_start_apart)
                await ws.send(json.dumps({"type": "config", "audio_rate": 16000, "plate_start": 0}))
                await ws.recv()
                for i in range(0, len(pcm), 8000):          # half-second messages
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
    live = LiveAnimator(Bank.load(GRID_BANK), fps=25, prepare=False)
    for i in range(0, len(pcm), BLOCK):
        live.feed_audio(pcm[i:i + BLOCK], RATE)
    live.finish_audio()
    assert max(got) == 39                              # 1.6 s: frames 0-39, the last ones included
    for n, rgb in got.items():
        want = live.frame(n)
        assert np.abs(rgb.astype(int) - want).mean() < 2.5, n          # JPEG at quality 80
    # the plate's blink (plate frames 46-48 of the 75: output frames 46-48) is not in 1.6 s;
    # its motion is: consecutive frames differ above the nose as the plate's do
    mesh = np.asarray(json.loads((GRID_BANK / "plate.json").read_text())["rest_mesh"], np.float64)
    rows = above_nose_rows(mesh) - 3
    ns = sorted(got)[-10:]
    plate = live.plate
    theirs = above_nose_changes([plate.frames[plate.index(n, 25.0)] for n in ns], rows)
    ours = above_nose_changes([got[n] for n in ns], rows)
    assert np.corrcoef(ours, theirs)[0, 1] > 0.5 and theirs.mean() > 0.3


def test_a_session_started_elsewhere_on_the_plate_equals_render_live_there(bank, speech, tmp_path):
    """``LiveAnimator(plate_start=S)`` shows what ``render --live --plate-start S`` shows, and
    above the nose it is the plate's timeline from S, not from 0 (issue 36 item 3)."""
    pcm, wav = speech
    pcm = pcm[:RATE]                                   # 1 s: 25 frames
    live, frames = _session_frames(bank, pcm, plate_start=1.2)
    assert sorted(frames) == list(range(25))
    clip = tmp_path / "one.wav"
    import wave

    with wave.open(str(clip), "wb") as w:
        w.setnchannels(1), w.setsampwidth(2), w.setframerate(RATE)
        w.writeframes(pcm.astype("<i2").tobytes())
    r = subprocess.run([sys.executable, "-m", "lipsync", "render", str(clip), "--live", "--plate-start", "1.2",
                        "--bank", str(GRID_BANK), "-o", f"{tmp_path / 'frames'}/", "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    files = sorted((tmp_path / "frames").glob("*.png"))
    assert len(files) == 25
    for n, f in enumerate(files):
        assert np.array_equal(cv2.cvtColor(cv2.imread(str(f)), cv2.COLOR_BGR2RGB), frames[n]), n
    plate = live.plate
    mesh = np.asarray(json.loads((GRID_BANK / "plate.json").read_text())["rest_mesh"], np.float64)
    rows = above_nose_rows(mesh) - 3
    line = plate.timeline(1.2)
    assert line.frame(0) == 30 % len(plate)            # 1.2 s into the plate at its 25 fps
    for n in (0, 12, 24):
        assert np.array_equal(frames[n][:rows], plate.frames[plate.index(n, 25.0, line)][:rows])
        assert not np.array_equal(frames[n][:rows], plate.frames[plate.index(n, 25.0)][:rows])
    with pytest.raises(Exception, match="plate_start"):
        LiveAnimator(bank, fps=25, prepare=False, plate_start=-1.0)


def test_serve_sessions_start_apart_on_the_plate_unless_told():
    """Each `serve` session starts at a place of its own on the plate (two heads on one page
    do not blink in unison); config's plate_start sets it, within its bound."""
    import asyncio

    from test_serve import Running, _connect

    srv = Running(bank=str(GRID_BANK), max_sessions=8, idle_timeout=30)
    try:
        async def run():
            async with await _connect(srv) as ws:
                await ws.recv()
                await ws.send(json.dumps({"type": "config", "plate_start": 2.0}))
                reply = json.loads(await asyncio.wait_for(ws.recv(), 10))
                assert reply["type"] == "config", reply
                await ws.send(json.dumps({"type": "config", "plate_start": 1e9}))
                bad = json.loads(await asyncio.wait_for(ws.recv(), 10))
                assert bad["type"] == "error" and "plate_start" in bad["error"], bad
                await ws.send(json.dumps({"type": "ping"}))
                assert json.loads(await asyncio.wait_for(ws.recv(), 10))["type"] == "pong"  # still serving

        asyncio.run(run())
        from lipsync.server.session import LiveSession

        # a session is made per connection; only where it starts is looked at here
        sessions = [LiveSession(srv.server, websocket=None).plate_start for _ in range(8)]
    finally:
        srv.stop()
    plate_s = len(srv.server.plate) / srv.server.plate.fps
    assert all(0 <= s < plate_s for s in sessions)
    assert len(set(sessions)) > 1, sessions
