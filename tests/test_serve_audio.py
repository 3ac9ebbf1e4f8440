"""lipsync serve's audio sessions: binary 16-bit PCM in, frames out as the audio reaches them.

The frames' specs (``config: specs``) are checked against ``LiveAnimator.feed_audio`` of the
same samples (what ``lipsync render --live`` shows); the limits (a message too long, odd
bytes, a rate not offered, audio before its rate, audio faster than real time, too many
sessions) each get an error and the server carries on.
"""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path

import numpy as np
import pytest

from lipsync.pipeline.liveclip import live_specs
from lipsync.server.protocol import HEADER, MAX_AUDIO_MESSAGE_S
from lipsync.speech.audio import load_audio

from test_serve import Running, _connect, _settle

ROOT = Path(__file__).resolve().parents[1]
HELLO_WAV = ROOT / "samples" / "hello.wav"


@pytest.fixture(scope="module")
def srv():
    running = Running(max_sessions=3, idle_timeout=30)
    yield running
    running.stop()


async def _stream(ws, pcm, rate, chunk_s=0.02, pace=0.5):
    """Send ``pcm`` in chunks, at most ``pace`` s ahead of real time; collect what comes back."""
    got = {"specs": {}, "frames": [], "errors": []}

    async def reader():
        while True:
            msg = await ws.recv()
            if isinstance(msg, bytes):
                got["frames"].append(HEADER.unpack(msg[:HEADER.size]))
            else:
                m = json.loads(msg)
                if m["type"] == "spec":
                    got["specs"][m["n"]] = (m["from"], m["to"], m["alpha"])
                elif m["type"] == "error":
                    got["errors"].append(m["error"])

    task = asyncio.create_task(reader())
    step = int(rate * chunk_s)
    t0 = time.monotonic()
    for i in range(0, len(pcm), step):
        ahead = i / rate - (time.monotonic() - t0)
        if ahead > pace:
            await asyncio.sleep(ahead - pace)
        await ws.send(pcm[i:i + step].astype("<i2").tobytes())
    await asyncio.sleep(1.0)
    task.cancel()
    return got


def test_audio_session_sends_the_frames_render_live_shows(srv):
    pcm = load_audio(HELLO_WAV)
    expected = live_specs(pcm, srv.server.bank)

    async def run():
        async with await _connect(srv) as ws:
            ready = json.loads(await ws.recv())
            await ws.send(json.dumps({"type": "config", "audio_rate": 16000, "specs": True}))
            config = json.loads(await ws.recv())
            got = await _stream(ws, pcm, 16000)
            return ready, config, got

    ready, config, got = asyncio.run(run())
    assert ready["audio_lookahead"] == 0.2 and config["audio_rate"] == 16000
    assert got["errors"] == []
    # every frame the audio reached (n / 25 + 0.2 <= 2.96 s) was sent, in order, unless the
    # sender fell behind on a loaded machine and skipped (then most still came)
    due = int((len(pcm) // 320 * 0.02 - 0.2) * 25) + 1
    numbers = [n for n, _, _ in got["frames"]]
    assert numbers == sorted(numbers) and numbers[-1] == due - 1 and len(numbers) >= 0.8 * due
    assert all(flags & 1 for _, flags, _ in got["frames"])       # fixed when sent
    for n, (a, b, alpha) in got["specs"].items():
        s = expected[n]
        assert (a, b) == (s.from_viseme, s.to_viseme) and alpha == pytest.approx(s.alpha, abs=1e-6), n
    shown = {expected[n].shown for n in got["specs"]}
    assert len(shown - {None}) >= 4                                # the mouth moved through shapes


def test_audio_limits_each_get_an_error_and_the_session_carries_on(srv):
    before = srv.status()

    async def run():
        errors = []
        async with await _connect(srv) as ws:
            await ws.recv()

            async def expect_error(message):
                await ws.send(message)
                reply = await asyncio.wait_for(ws.recv(), 10)
                while isinstance(reply, bytes):          # frames of the audio sent before
                    reply = await asyncio.wait_for(ws.recv(), 10)
                errors.append(json.loads(reply))

            await expect_error(np.zeros(320, "<i2").tobytes())                      # no rate yet
            await expect_error(json.dumps({"type": "config", "audio_rate": 12345}))  # a rate not offered
            await expect_error(json.dumps({"type": "config", "lookahead": 5000}))
            await ws.send(json.dumps({"type": "config", "audio_rate": 8000}))
            assert json.loads(await ws.recv())["audio_rate"] == 8000
            await expect_error(b"\x01\x02\x03")                                     # odd bytes
            await expect_error(np.zeros(int(8000 * MAX_AUDIO_MESSAGE_S) + 1, "<i2").tobytes())  # too long
            await expect_error(b"\x00")                                             # one byte
            for _ in range(6):          # 6 s at once: what runs over 2 s ahead of real time is refused
                await ws.send(np.zeros(8000, "<i2").tobytes())
            await ws.send(json.dumps({"type": "config", "audio_rate": 16000}))    # rate fixed now
            # the session still works: it answers, and frames of the silence came
            await ws.send(json.dumps({"type": "ping"}))
            kinds = []
            deadline = time.monotonic() + 20
            while "pong" not in kinds and time.monotonic() < deadline:
                msg = await asyncio.wait_for(ws.recv(), 20)
                if isinstance(msg, bytes):
                    kinds.append("frame")
                else:
                    m = json.loads(msg)
                    kinds.append(m["type"])
                    if m["type"] == "error":
                        errors.append(m)
        return errors, kinds

    errors, kinds = asyncio.run(run())
    text = " | ".join(e["error"] for e in errors)
    ahead = text.count("ahead of real time")
    assert 1 <= ahead <= 4, text
    assert [e["type"] for e in errors] == ["error"] * len(errors) and len(errors) == 7 + ahead, errors
    for part in ("audio_rate", "lookahead", "not whole 16-bit samples", "over 1 s", "ahead of real time",
                 "before the first audio"):
        assert part in text, part
    assert "pong" in kinds and "frame" in kinds
    assert srv.status()["errors"] - before["errors"] == len(errors)
    assert _settle(srv)


def test_too_many_audio_sessions_are_refused_and_the_rest_keep_streaming(srv):
    async def run():
        socks = [await _connect(srv) for _ in range(3)]
        for ws in socks:
            assert json.loads(await ws.recv())["type"] == "ready"
        extra = await _connect(srv)
        refused = json.loads(await extra.recv())
        ws = socks[0]
        await ws.send(json.dumps({"type": "config", "audio_rate": 16000}))
        await ws.recv()
        await ws.send(np.zeros(16000, "<i2").tobytes())   # one second at once: frames 0-20 due
        last = -1
        while last < 20:
            msg = await asyncio.wait_for(ws.recv(), 20)
            if isinstance(msg, bytes):
                last = HEADER.unpack(msg[:HEADER.size])[0]
        for s in socks + [extra]:
            await s.close()
        return refused, last

    refused, last = asyncio.run(run())
    assert refused["type"] == "error" and "limit" in refused["error"]
    assert last == 20          # a burst: the sender skips to the newest frame due
    assert _settle(srv)
