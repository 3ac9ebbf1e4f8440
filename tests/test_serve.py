"""lipsync serve against real clients: uvicorn on 127.0.0.1 (a free port), httpx and websockets.

Frames are checked against the LiveAnimator's own (decoded JPEG, so within JPEG's error),
render jobs against the decoded mp4; the soak tests (200 malformed messages, 20 sessions at
once) count threads, sessions and resident memory before and after.
"""

from __future__ import annotations

import asyncio
import gc
import json
import os
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import cv2
import httpx
import numpy as np
import pytest
import websockets

from lipsync import Bank, read_timeline
from lipsync._data import default_bank_dir
from lipsync.live import LiveAnimator
from lipsync.server import WS_MAX_MESSAGE, LiveServer, ServeConfig
from lipsync.server.protocol import HEADER
from lipsync.server.session import LiveSession
from lipsync.web import Session, start_in_thread

ROOT = Path(__file__).resolve().parents[1]
HELLO = ROOT / "samples" / "hello.phn"


class Running:
    def __init__(self, **config):
        self.session = Session.open("127.0.0.1", 0)
        self.server = LiveServer(ServeConfig(**config), session=self.session)
        self.handle = start_in_thread(self.server.app, self.session, ws_max_size=WS_MAX_MESSAGE)
        self.origin = self.session.origin
        self.ws_url = self.session.url("/ws/live").replace("http://", "ws://")

    def url(self, path):
        return self.session.url(path)

    def status(self):
        return httpx.get(self.url("/api/status")).json()

    def stop(self):
        self.handle.stop()
        self.server.close()
        self.session.close()


@pytest.fixture(scope="module")
def srv():
    running = Running(max_sessions=20, idle_timeout=30)
    yield running
    running.stop()


def hello_events():
    return [{"start": s.start, "end": s.end, "label": s.label, "kind": "phoneme"} for s in read_timeline(HELLO)]


def rss_mb() -> float:
    """Resident memory in MB after glibc hands back what it holds free.

    Freed memory stays in glibc's per-thread arenas (its mmap threshold rises after frame-
    sized buffers are freed, so later ones come from the heap) and RSS then swings by
    ~16 MB between identical rounds; malloc_trim returns it, so what is left is live.
    """
    import ctypes
    import ctypes.util

    try:
        ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc: RSS as it is
        pass
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


async def _connect(srv, **kw):
    return await websockets.connect(srv.ws_url, origin=srv.origin, max_size=2**24, **kw)


async def _frames(ws, count, timeout=20.0):
    """Receive until ``count`` frames came; return them as (n, flags, t, rgb) and the texts."""
    frames, texts = [], []
    deadline = time.monotonic() + timeout
    while len(frames) < count:
        msg = await asyncio.wait_for(ws.recv(), max(0.1, deadline - time.monotonic()))
        if isinstance(msg, bytes):
            n, flags, t = HEADER.unpack(msg[:HEADER.size])
            bgr = cv2.imdecode(np.frombuffer(msg[HEADER.size:], np.uint8), cv2.IMREAD_COLOR)
            frames.append((n, flags, t, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)))
        else:
            texts.append(json.loads(msg))
    return frames, texts


# ---------------------------------------------------------------------------- guard


def test_binds_loopback_and_refuses_foreign_host_origin_and_missing_token(srv):
    assert srv.session.host == "127.0.0.1"
    assert httpx.get(srv.origin + "/api/status").status_code == 403                      # no token
    assert httpx.get(srv.url("/api/status"), headers={"Host": "evil.example"}).status_code == 403
    assert httpx.get(srv.url("/api/status"), headers={"Origin": "http://evil.example"}).status_code == 403
    assert httpx.get(srv.url("/api/status")).status_code == 200
    page = httpx.get(srv.origin + "/")  # the page itself is public; it reads the token from its URL
    assert page.status_code == 200 and "live.js" in page.text

    async def handshake(url, origin):
        try:
            async with websockets.connect(url, origin=origin):
                return "open"
        except websockets.exceptions.InvalidStatus as exc:
            return exc.response.status_code

    assert asyncio.run(handshake(srv.ws_url, "http://evil.example")) == 403
    assert asyncio.run(handshake(srv.ws_url.split("?")[0], srv.origin)) == 403
    assert asyncio.run(handshake(srv.ws_url, srv.origin)) == "open"


# ---------------------------------------------------------------------------- live


def test_live_frames_follow_the_clock_and_match_the_live_animator(srv):
    bank = Bank.load(default_bank_dir())
    reference = LiveAnimator(bank, fps=25, prepare=False)
    reference.push(read_timeline(HELLO))

    async def run():
        async with await _connect(srv) as ws:
            ready = json.loads(await ws.recv())
            assert ready["type"] == "ready" and (ready["width"], ready["height"]) == (512, 512)
            await ws.send(json.dumps({"type": "push", "events": hello_events()}))
            await ws.send(json.dumps({"type": "clock", "t": 0.4}))
            t0 = time.monotonic()
            frames, texts = await _frames(ws, 12)
            return frames, texts, time.monotonic() - t0

    frames, texts, elapsed = asyncio.run(run())
    assert not [t for t in texts if t["type"] == "error"]
    numbers = [n for n, *_ in frames]
    assert numbers == sorted(numbers) and numbers[0] == 10          # clock 0.4 s = frame 10
    assert numbers[-1] <= 10 + round((elapsed + 0.1) * 25)           # never ahead of the clock
    assert all(flags & 1 for _, flags, _, _ in frames)               # all pushed: final
    for n, _, t, rgb in frames:
        assert t == pytest.approx(n / 25)
        # the server's JPEG is the LiveAnimator's frame n encoded at quality 80, byte for byte
        ok, jpeg = cv2.imencode(".jpg", cv2.cvtColor(reference.frame(n), cv2.COLOR_RGB2BGR),
                                [cv2.IMWRITE_JPEG_QUALITY, 80])
        want = cv2.cvtColor(cv2.imdecode(jpeg, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        assert np.array_equal(rgb, want), n
    # the frames move: the head is talking
    assert max(np.abs(frames[0][3].astype(int) - f[3]).mean() for f in frames) > 0.5


def test_webp_and_config_and_stop(srv):
    async def run():
        async with await _connect(srv) as ws:
            await ws.recv()
            await ws.send(json.dumps({"type": "config", "format": "webp", "fps": 30}))
            cfg = json.loads(await ws.recv())
            await ws.send(json.dumps({"type": "push", "start": 0, "end": 1, "label": "AA"}))
            await ws.send(json.dumps({"type": "clock", "t": 0.5}))
            msg = await ws.recv()
            await ws.send(json.dumps({"type": "stop"}))
            await ws.send(json.dumps({"type": "ping"}))
            after = []
            try:
                while True:
                    after.append(await asyncio.wait_for(ws.recv(), 0.5))
            except asyncio.TimeoutError:
                pass
            return cfg, msg, after

    cfg, msg, after = asyncio.run(run())
    assert cfg == {"type": "config", "fps": 30.0, "format": "webp", "quality": 80}
    n, _, t = HEADER.unpack(msg[:HEADER.size])
    assert n == 15 and msg[HEADER.size:][:4] == b"RIFF" and msg[HEADER.size + 8:][:4] == b"WEBP"
    # after stop: at most the frame already in flight, then only the pong
    assert [m for m in after if isinstance(m, str)] == ['{"type":"pong"}']
    assert sum(isinstance(m, bytes) for m in after) <= 1


MALFORMED = [
    "", "nonsense", "[]", "42", "null", '{"type": 5}', '{"type": "dance"}', '{"no": "type"}',
    '{"type": "clock"}', '{"type": "clock", "t": "soon"}', '{"type": "clock", "t": -1}', '{"type": "clock", "t": 1e308}',
    '{"type": "clock", "t": true}', '{"type": "push"}', '{"type": "push", "start": 0, "end": 1}',
    '{"type": "push", "start": 0, "end": 1, "label": 7}', '{"type": "push", "start": 1, "end": 0, "label": "AA"}',
    '{"type": "push", "start": 0, "end": 1, "label": "' + "x" * 100 + '"}',
    '{"type": "push", "start": 0, "end": 99999, "label": "AA"}', '{"type": "push", "events": []}',
    '{"type": "push", "events": 5}', '{"type": "push", "events": [1, 2]}',
    '{"type": "push", "start": 0, "end": 1, "label": "AA", "kind": "colour"}',
    '{"type": "push", "start": 0, "end": 1, "label": "zz", "kind": "viseme"}',
    '{"type": "config", "fps": 1000}', '{"type": "config", "format": "gif"}', '{"type": "config", "quality": 5}',
    "[" * 5000 + "]" * 5000, '{"type": "clock", "t": NaN}', '{"type": "push", "start": Infinity, "end": 1, "label": "M"}',
]


def test_200_malformed_messages_each_get_an_error_and_the_session_and_server_carry_on(srv):
    before = srv.status()

    async def run():
        async with await _connect(srv) as ws, await _connect(srv) as other:
            await ws.recv()
            await other.recv()
            await ws.send(json.dumps({"type": "push", "start": 0, "end": 0.5, "label": "AA"}))
            replies = []
            for i in range(200):
                bad = MALFORMED[i % len(MALFORMED)] if i % 7 else b"\x00binary"
                await ws.send(bad)
                replies.append(json.loads(await asyncio.wait_for(ws.recv(), 5)))
            # the session still works: an out-of-order push was refused, a good one is taken
            await ws.send(json.dumps({"type": "push", "start": 0.5, "end": 1.0, "label": "M"}))
            await ws.send(json.dumps({"type": "clock", "t": 0.8}))
            frames, texts = await _frames(ws, 2)
            # and the other session was not disturbed
            await other.send(json.dumps({"type": "clock", "t": 0.0}))
            other_frames, _ = await _frames(other, 1)
            return replies, frames, texts, other_frames

    replies, frames, texts, other_frames = asyncio.run(run())
    assert len(replies) == 200 and all(r["type"] == "error" and r["error"] for r in replies)
    assert not [t for t in texts if t["type"] == "error"]
    assert frames[0][0] == 20 and other_frames[0][0] == 0
    after = srv.status()
    assert after["errors"] - before["errors"] == 200
    assert after["sessions"] == 0 or _settle(srv)


def _settle(srv, timeout=5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if srv.status()["sessions"] == 0:
            return True
        time.sleep(0.05)
    return False


def _fixed_mmap_threshold(nbytes: int = 256 << 10) -> None:
    """Serve blocks of ``nbytes`` or more from mmap from now on (returned to the system when
    freed), whatever glibc's dynamic threshold has grown to: earlier tests in a whole-suite
    run free arrays of tens of MB, which raises it so far that frame-sized buffers come from
    the heap, where fragmentation left RSS 16-30 MB up between identical rounds."""
    import ctypes
    import ctypes.util

    try:
        ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt(-3, nbytes)  # M_MMAP_THRESHOLD
    except (OSError, AttributeError):  # not glibc
        pass


def test_20_concurrent_sessions_then_nothing_leaked():
    """Twenty sessions at once, a 21st refused, twice over: nothing per session is kept.

    Measured in a fresh interpreter: inside a whole-suite process (about 1 GB after the
    earlier tests) glibc's heap moved RSS by 10-30 MB between identical rounds however the
    allocator was tuned (1 clean-clone run in 3 failed), which says nothing about this
    server; alone, the same rounds measured -2..+6 MB.
    """
    out = subprocess.run([sys.executable, "-c", "import test_serve; test_serve._leak_check_alone()"],
                         cwd=Path(__file__).parent, capture_output=True, text=True, timeout=600)
    print(out.stdout)
    assert out.returncode == 0, out.stdout + out.stderr


def _leak_check_alone() -> None:
    running = Running(max_sessions=20, idle_timeout=30)
    try:
        _leak_check(running)
    finally:
        running.stop()


def _leak_check(srv) -> None:
    _fixed_mmap_threshold()
    events = hello_events()

    async def one(k, release):
        async with await _connect(srv) as ws:
            await ws.recv()
            await ws.send(json.dumps({"type": "push", "events": events}))
            await ws.send(json.dumps({"type": "clock", "t": 0.04 * k}))
            frames, texts = await _frames(ws, 3, timeout=60)
            await release.wait()  # all 20 stay open until the 21st has been refused
            return frames[0][0], [t for t in texts if t["type"] == "error"]

    async def refused():
        async with await _connect(srv) as ws:
            msg = json.loads(await ws.recv())
            try:
                await asyncio.wait_for(ws.recv(), 5)
            except websockets.exceptions.ConnectionClosed as exc:
                return msg, exc.rcvd.code if exc.rcvd else None

    async def round_(extra: bool):
        async with await _connect(srv) as holder:  # noqa: F841 - part of the 20
            await holder.recv()
            release = asyncio.Event()
            tasks = [asyncio.create_task(one(k, release)) for k in range(19)]
            deadline = time.monotonic() + 60
            while len(srv.server.sessions) < 20 and time.monotonic() < deadline:
                await asyncio.sleep(0.05)  # all 20 open before the 21st knocks
            assert len(srv.server.sessions) == 20
            over = await refused() if extra else None
            release.set()
            return await asyncio.gather(*tasks), over

    # Warm-up: every renderer of the pool gets the pair states this speech uses (each a few
    # MB, kept for reuse: not a leak), and one round sizes the session machinery.
    reference = LiveAnimator(Bank.load(default_bank_dir()), fps=25, prepare=False)
    reference.push(read_timeline(HELLO))
    pairs = {(s.from_viseme, s.to_viseme) for s in map(reference.spec, range(80)) if s.shown is None}
    srv.server.pool.warm(sorted(pairs))
    del reference
    # One-time allocations (the event loop's buffers, the pool's scratch, the refusal path of
    # a 21st session: up to ~11 MB in all) land in the first few rounds; over ten rounds after
    # them RSS stayed flat to 0.1 MB. A leak would grow every round, so four warm-up rounds.
    for extra in (True, False, False, False):
        asyncio.run(round_(extra))
    assert _settle(srv)
    gc.collect()
    threads0, rss0 = threading.active_count(), rss_mb()
    results, over = asyncio.run(round_(True))
    for k, (first, errors) in enumerate(results):
        assert not errors and first >= k  # each session on its own clock
    assert over[0]["type"] == "error" and "limit" in over[0]["error"] and over[1] == 1013
    assert _settle(srv)
    results2, _ = asyncio.run(round_(False))
    assert _settle(srv)
    gc.collect()
    threads1, rss1 = threading.active_count(), rss_mb()
    status = srv.status()
    alive = [o for o in gc.get_objects() if isinstance(o, (LiveAnimator, LiveSession))]
    assert not alive
    print(f"\n20 sessions x 2 rounds: threads {threads0} -> {threads1}, RSS {rss0:.0f} -> {rss1:.0f} MB, "
          f"sessions open {status['sessions']}, refused {status['refused_sessions']}")
    assert status["sessions"] == 0 and threads1 <= threads0
    # two more rounds of 20 sessions: nothing per session is kept (40 sessions under 12 MB:
    # any leak of 0.3 MB a session, less than one kept 512x512 frame, fails; measured -2..+6)
    assert rss1 - rss0 < 12


def test_idle_session_is_closed():
    running = Running(idle_timeout=0.5)
    try:
        async def run():
            async with await _connect(running) as ws:
                await ws.recv()
                msg = json.loads(await asyncio.wait_for(ws.recv(), 5))
                with pytest.raises(websockets.exceptions.ConnectionClosed):
                    await asyncio.wait_for(ws.recv(), 5)
                return msg

        msg = asyncio.run(run())
        assert msg["type"] == "error" and "idle" in msg["error"]
        assert _settle(running)
    finally:
        running.stop()


# ---------------------------------------------------------------------------- render jobs


def _wait_job(srv, job, timeout=120):
    deadline = time.monotonic() + timeout
    seen = []
    while time.monotonic() < deadline:
        state = httpx.get(srv.url(f"/api/jobs/{job}")).json()
        seen.append(state["progress"])
        if state["state"] in ("done", "error"):
            return state, seen
        time.sleep(0.05)
    raise AssertionError("job did not finish")


def test_render_job_gives_the_mp4_of_the_timeline(srv, tmp_path):
    r = httpx.post(srv.url("/api/render") + "&name=hello.phn", content=HELLO.read_bytes())
    assert r.status_code == 202
    state, progress = _wait_job(srv, r.json()["job"])
    assert state["state"] == "done" and state["frames"] == 75 and progress == sorted(progress)
    video = httpx.get(srv.url(state["video"]))
    assert video.status_code == 200 and video.headers["content-type"] == "video/mp4"
    out = tmp_path / "hello.mp4"
    out.write_bytes(video.content)
    cap = cv2.VideoCapture(str(out))
    n = 0
    while cap.read()[0]:
        n += 1
    assert n == 75 and cap.get(cv2.CAP_PROP_FRAME_WIDTH) == 512


def test_bad_uploads_are_answered_and_server_files_stay_private(srv):
    r = httpx.post(srv.url("/api/render") + "&name=broken.phn", content=b"0 100 aa\n50 20 bb\n")
    state, _ = _wait_job(srv, r.json()["job"])
    assert state["state"] == "error" and "broken.phn" in state["error"] and "lipsync-serve" not in state["error"]
    assert httpx.post(srv.url("/api/render") + "&name=a.phn&format=nope", content=b"x").status_code == 400
    assert httpx.post(srv.url("/api/render") + "&name=a.phn", content=b"").status_code == 400
    assert httpx.post(srv.url("/api/render") + "&name=a.phn&fps=abc", content=b"0 1 a").status_code == 400
    assert httpx.get(srv.url("/api/jobs/../../etc/passwd")).status_code == 404
    assert httpx.get(srv.url("/api/jobs/0123456789abcdef/video")).status_code == 404
    assert httpx.get(srv.url("/static/../__init__.py")).status_code == 404
    assert httpx.get(srv.url("/api/status")).status_code == 200


def test_upload_over_the_limit_is_refused():
    running = Running(max_upload=4096)
    try:
        r = httpx.post(running.url("/api/render") + "&name=a.phn", content=b"0 1 a\n" * 2000)
        assert r.status_code == 413
        assert httpx.get(running.url("/api/status")).status_code == 200
    finally:
        running.stop()


# ---------------------------------------------------------------------------- CLI


def test_cli_serve_prints_its_url_and_serves_on_loopback():
    proc = subprocess.Popen([sys.executable, "-m", "lipsync", "serve", "--port", "0", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("lipsync serve: open http://127.0.0.1:")
        url = line.split()[-1]
        status = httpx.get(url.replace("/?token", "/api/status?token"), timeout=10)
        assert status.status_code == 200 and status.json()["sessions"] == 0
    finally:
        proc.terminate()
        proc.wait(10)


def test_render_job_from_audio_and_text_gives_video_with_the_speech(srv, tmp_path):
    import imageio_ffmpeg
    from urllib.parse import quote

    text = (ROOT / "samples" / "hello.lab").read_text()
    r = httpx.post(srv.url("/api/render") + "&name=hello.wav&text=" + quote(text),
                   content=(ROOT / "samples" / "hello.wav").read_bytes())
    assert r.status_code == 202
    state, _ = _wait_job(srv, r.json()["job"])
    assert state["state"] == "done", state
    out = tmp_path / "speech.mp4"
    out.write_bytes(httpx.get(srv.url(state["video"])).content)
    probe = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(out)],
                           capture_output=True, text=True).stderr
    assert "Video: h264" in probe and "Audio: aac" in probe  # the upload is the soundtrack
    cap = cv2.VideoCapture(str(out))
    frames = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame.astype(np.int16))
    assert len(frames) == 75  # 2.97 s of audio at 25 fps
    # the aligned speech moves the mouth: frames in the middle differ from the first (rest)
    assert max(np.abs(f - frames[0]).mean() for f in frames[20:60]) > 1.0


# ---------------------------------------------------------------------------- numeric options (issue 19, item 3)

@pytest.mark.parametrize("option, value", [
    ("--max-upload-mb", "nan"), ("--max-upload-mb", "inf"), ("--max-upload-mb", "-1"), ("--max-upload-mb", "1e30"),
    ("--idle-timeout", "nan"), ("--idle-timeout", "inf"), ("--idle-timeout", "0"), ("--idle-timeout", "-5"),
    ("--max-sessions", "0"), ("--workers", "0"), ("--workers", "-3"), ("--quality", "1000"), ("--port", "70000"),
])
def test_every_numeric_option_is_checked_before_serving(capsys, option, value):
    from lipsync.cli import main

    assert main(["serve", "--port", "0", option, value]) == 2
    err = capsys.readouterr().err
    assert f"{option} must be" in err and "Traceback" not in err and "open http" not in err, err


def test_serve_config_refuses_non_finite_numbers():
    from lipsync.errors import InputError

    for bad in (dict(idle_timeout=float("nan")), dict(idle_timeout=float("inf")), dict(max_upload=10**12),
                dict(max_sessions=1.5), dict(workers=0), dict(fps=0.0), dict(fps=26.0), dict(quality=5)):
        with pytest.raises(InputError):
            ServeConfig(**bad)


def test_render_query_fps_is_checked_as_the_cli_checks_it(srv):
    for fps in ("0", "-25", "nan", "inf", "121", "1e308", "abc", ""):
        r = httpx.post(srv.url("/api/render") + f"&name=hello.phn&fps={fps}", content=HELLO.read_bytes())
        assert r.status_code == 400 and "frame rate" in r.json()["error"], (fps, r.text)
    r = httpx.post(srv.url("/api/render") + "&name=hello.phn&fps=10", content=HELLO.read_bytes())
    assert r.status_code == 202
    state, _ = _wait_job(srv, r.json()["job"])
    assert state["state"] == "done" and state["frames"] == 30  # 3 s at 10 fps, not at the default 25
