"""The end of a live audio stream (issue 36 item 5): ``LiveAnimator.finish_audio()`` and the
WebSocket ``{"type": "end"}`` message deliver every remaining frame.

A stream's frames are those ``feed_audio`` made due plus those ``finish_audio`` returns; their
count must be the offline render's for the same audio (``Animator.from_audio``, what
``lipsync render AUDIO`` renders: ``ceil(duration * fps)``), whatever the rate and chunking,
and the last look-ahead's frames must show the speech that reaches the end of the audio.
"""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path

import numpy as np
import pytest

from lipsync import Animator, Bank
from lipsync._data import default_bank_dir
from lipsync.errors import InputError
from lipsync.live import LiveAnimator
from lipsync.live.audio import RATE
from lipsync.pipeline.liveclip import live_shapes, live_specs
from lipsync.server.protocol import HEADER, ProtocolError, parse
from lipsync.speech.audio import load_audio

from test_serve import Running, _connect

ROOT = Path(__file__).resolve().parents[1]
AUDIO = ROOT / "tests" / "data" / "grid-s1-audio"


@pytest.fixture(scope="module")
def bank():
    return Bank.load(default_bank_dir())


@pytest.fixture(scope="module")
def clip():
    """A GRID sentence cut in the middle of its last word ("... please" of lray6p is at
    1.90-2.35 s in GRID's alignment): speech runs to the last sample."""
    pcm = load_audio(AUDIO / "lray6p.flac")
    return pcm[:int(2.13 * RATE) + 37]          # not a whole block: 2.130 s + 37 samples


def _write_wav(path, pcm, rate=RATE):
    import wave

    with wave.open(str(path), "wb") as w:
        w.setnchannels(1), w.setsampwidth(2), w.setframerate(rate)
        w.writeframes(pcm.astype("<i2").tobytes())
    return path


def _stream(bank, pcm, rate, chunks):
    live = LiveAnimator(bank, fps=25, prepare=False)
    fed, i = [], 0
    for size in chunks:
        fed += live.feed_audio(pcm[i:i + size], rate)
        i += size
        if i >= len(pcm):
            break
    return live, fed, live.finish_audio()


def test_a_fed_stream_has_the_offline_renders_frames_last_ones_included(bank, clip, tmp_path):
    wav = _write_wav(tmp_path / "cut.wav", clip)
    offline = Animator.from_audio(bank, wav, "lay red at y six")        # what `lipsync render` renders
    assert len(offline) == int(np.ceil(len(clip) / RATE * 25)) == 54
    live, fed, last = _stream(bank, clip, RATE, [320] * 1000)
    assert fed == list(range(len(fed))) and last == list(range(len(fed), len(offline)))
    assert len(fed) + len(last) == len(offline) and live.frames_total == len(offline)
    # the look-ahead (200 ms = 5 frames) and the unfinished last block: 5-6 frames came only now
    assert 5 <= len(last) <= 6
    # ... and they show the last word's sounds, not rest; they equal render --live's frames
    specs = live_specs(clip, bank)
    assert len(specs) == len(offline)
    assert [live.spec(n) for n in last] == specs[last[0]:]
    assert any((live.spec(n).from_viseme, live.spec(n).to_viseme) != ("X", "X") for n in last)
    assert live.finish_audio() == []                  # once only
    with pytest.raises(InputError, match="has ended"):
        live.feed_audio(np.zeros(320, np.int16))


@pytest.mark.parametrize("rate", [16000, 44100])
def test_any_rate_and_chunking_gives_the_same_frame_count(bank, clip, rate):
    pcm = clip
    if rate != RATE:       # the clip brought to 44.1 kHz by linear interpolation (any audio at that rate)
        t = np.arange(int(len(clip) * rate / RATE)) * RATE / rate
        pcm = np.round(np.interp(t, np.arange(len(clip)), clip.astype(np.float64))).astype(np.int16)
    want = int(np.ceil(len(pcm) / rate * 25 - 1e-9))
    rng = np.random.default_rng(rate)
    live, fed, last = _stream(bank, pcm, rate, rng.integers(1, 3000, 2000))
    assert fed + last == list(range(want))


def test_cues_live_covers_the_whole_audio(clip, tmp_path):
    import subprocess
    import sys

    wav = _write_wav(tmp_path / "cut.wav", clip)
    r = subprocess.run([sys.executable, "-m", "lipsync", "cues", str(wav), "--live", "-o", str(tmp_path / "c.tsv"),
                        "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    rows = [line.split("\t") for line in (tmp_path / "c.tsv").read_text().splitlines()]
    # Rhubarb TSV ends with the rest cue at the end of the last frame: 54 frames = 2.16 s
    assert rows[-1] == ["2.160", "X"]
    # mouth shapes within the last look-ahead (the last 200 ms: speech runs to the end)
    assert any(v != "X" for t, v in rows[:-1] if float(t) >= 2.16 - 0.2)


# ---------------------------------------------------------------------------- WebSocket

def test_end_message_parses_and_bad_ones_are_refused():
    assert type(parse('{"type": "end"}')).__name__ == "End"
    for bad in ('{"type": "end", "t": 2.5}', '{"type": "end", "frames": 3, "x": 1}'):
        with pytest.raises(ProtocolError, match="end: takes no fields"):
            parse(bad)


@pytest.fixture(scope="module")
def srv():
    running = Running(max_sessions=4, idle_timeout=30)
    yield running
    running.stop()


def test_end_sends_every_remaining_frame_then_says_so(srv, clip):
    expected = live_specs(clip, srv.server.bank)
    cues = live_shapes(clip, srv.server.bank)

    async def run():
        async with await _connect(srv) as ws:
            await ws.recv()
            await ws.send(json.dumps({"type": "end"}))                     # no audio yet
            errors = [json.loads(await ws.recv())]
            await ws.send(json.dumps({"type": "config", "audio_rate": 16000, "specs": True}))
            assert json.loads(await ws.recv())["type"] == "config"
            t0 = time.monotonic()
            for i in range(0, len(clip), 320):                              # in real time
                wait = i / RATE - (time.monotonic() - t0) - 0.1
                if wait > 0:
                    await asyncio.sleep(wait)
                await ws.send(clip[i:i + 320].astype("<i2").tobytes())
            await ws.send(json.dumps({"type": "end", "at": 1}))            # a field: refused, carries on
            await ws.send(json.dumps({"type": "end"}))
            frames, specs, end = [], {}, None
            while end is None:
                msg = await asyncio.wait_for(ws.recv(), 20)
                if isinstance(msg, bytes):
                    frames.append(HEADER.unpack(msg[:HEADER.size])[0])
                    continue
                m = json.loads(msg)
                if m["type"] == "spec":
                    specs[m["n"]] = (m["from"], m["to"], m["alpha"], m["cue"])
                elif m["type"] == "error":
                    errors.append(m)
                elif m["type"] == "end":
                    end = m
            await ws.send(json.dumps({"type": "end"}))                     # twice
            errors.append(json.loads(await ws.recv()))
            await ws.send(np.zeros(320, "<i2").tobytes())                  # audio after the end
            errors.append(json.loads(await ws.recv()))
            await ws.send(json.dumps({"type": "ping"}))
            pong = json.loads(await ws.recv())
            return frames, specs, end, errors, pong

    frames, specs, end, errors, pong = asyncio.run(run())
    assert end == {"type": "end", "frames": len(expected)} and len(expected) == 54
    # every frame, in order, the last look-ahead's included (the sender skips only when it
    # falls behind the audio; the end's frames are never skipped)
    assert frames[-1] == len(expected) - 1 and frames == sorted(set(frames))
    assert frames[-6:] == list(range(len(expected) - 6, len(expected)))
    for n in frames[-6:]:
        s = expected[n]
        assert specs[n][:2] == (s.from_viseme, s.to_viseme) and specs[n][2] == pytest.approx(s.alpha, abs=1e-6)
        assert specs[n][3] == cues[n]
    texts = [e["error"] for e in errors]
    assert [e["type"] for e in errors] == ["error"] * 4, errors
    assert "no audio has been streamed" in texts[0]
    assert "takes no fields" in texts[1]
    assert "already ended" in texts[2]
    assert "has ended" in texts[3]
    assert pong == {"type": "pong"}


def test_the_live_modules_examples_run():
    """The docstring examples of the modules this round changed (finish_audio, cue, close,
    shared_plate, the end message) run and give what they show."""
    import doctest
    import importlib

    for name in ("lipsync.live.animator", "lipsync.live.causal", "lipsync.live.pool", "lipsync.live.audio",
                 "lipsync.pipeline.liveclip", "lipsync.server.protocol"):
        result = doctest.testmod(importlib.import_module(name))
        assert result.failed == 0 and result.attempted > 0, name
