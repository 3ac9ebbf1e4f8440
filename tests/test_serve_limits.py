"""``lipsync serve``'s render queue under abuse (issue 32, item 4).

* a 15-byte upload claiming ten hours fails at once (``--max-clip-seconds``), and the next
  job runs;
* a job over ``--job-timeout`` is stopped, so the one queued behind it starts and finishes;
* SIGTERM while a long job renders stops the server within a couple of seconds, with its
  job folder (uploads, partial outputs) removed and no ffmpeg left running.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx

from lipsync.server import LiveServer, ServeConfig, WS_MAX_MESSAGE
from lipsync.web import Session, start_in_thread

ROOT = Path(__file__).resolve().parents[1]
HELLO = ROOT / "samples" / "hello.phn"


def _timit(seconds: float, step: float = 0.2) -> bytes:
    """A TIMIT .phn timeline alternating two phones every ``step`` s for ``seconds``."""
    rows, t, k = [], 0.0, 0
    while t < seconds:
        rows.append(f"{int(t * 16000)} {int(min(t + step, seconds) * 16000)} {('aa', 'm')[k % 2]}")
        t, k = t + step, k + 1
    return ("\n".join(rows) + "\n").encode()


class Server:
    def __init__(self, **config):
        self.session = Session.open("127.0.0.1", 0)
        self.server = LiveServer(ServeConfig(method="dissolve", **config), session=self.session)
        self.handle = start_in_thread(self.server.app, self.session, ws_max_size=WS_MAX_MESSAGE)

    def submit(self, name: str, body: bytes) -> str:
        r = httpx.post(self.session.url("/api/render") + f"&name={name}", content=body)
        assert r.status_code == 202, r.text
        return r.json()["job"]

    def state(self, job: str) -> dict:
        return httpx.get(self.session.url(f"/api/jobs/{job}")).json()

    def wait(self, job: str, timeout: float = 60) -> dict:
        deadline = time.monotonic() + timeout
        while True:
            s = self.state(job)
            if s["state"] in ("done", "error"):
                return s
            assert time.monotonic() < deadline, f"job still {s['state']} after {timeout} s"
            time.sleep(0.02)

    def stop(self):
        self.handle.stop()
        self.server.close()
        self.session.close()


def test_a_tiny_upload_of_a_ten_hour_timeline_fails_at_once_and_the_queue_moves_on():
    srv = Server()
    try:
        ten_hours = b"0 576000000 aa\n"  # TIMIT samples at 16 kHz: 36000 s in 15 bytes
        assert len(ten_hours) == 15
        huge = srv.submit("ten-hours.phn", ten_hours)
        small = srv.submit("hello.phn", HELLO.read_bytes())
        state = srv.wait(huge, timeout=10)
        assert state["state"] == "error" and state["frames"] == 0
        assert "ten-hours.phn: lasts 36000 s; this server renders at most 600 s per job" in state["error"]
        assert srv.wait(small)["state"] == "done"
    finally:
        srv.stop()


def test_a_job_over_its_time_is_stopped_and_the_next_one_runs():
    srv = Server(job_timeout=3.0)   # a worker process per job: a 3 s clip takes ~1 s on a loaded machine
    try:
        long_job = srv.submit("long.phn", _timit(500))     # 12,500 frames: far more than 3 s of work
        small = srv.submit("hello.phn", HELLO.read_bytes())
        state = srv.wait(long_job)
        assert state["state"] == "error" and "stopped after 3 s (--job-timeout)" in state["error"]
        assert 0 < state["frames"] < 12500
        done = srv.wait(small)
        assert done["state"] == "done" and done["frames"] == 75
        assert not list(srv.server.tmp.glob(f"{long_job}/.*partial*"))   # the stopped job's partial removed
    finally:
        srv.stop()


def _ffmpeg_children(pid: int):
    # the job's ffmpeg is a child of the job's worker process, itself a child of serve's
    out = subprocess.run(["ps", "-o", "pid=,ppid=,comm=", "-e"], capture_output=True, text=True).stdout
    rows = [line.split() for line in out.splitlines()]
    family = {str(pid)} | {r[0] for r in rows if r[1] == str(pid)}
    return [" ".join(r) for r in rows if "ffmpeg" in r[2] and r[1] in family]


def test_sigterm_stops_serve_within_seconds_while_a_job_renders(tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    p = subprocess.Popen([sys.executable, "-m", "lipsync", "serve", "--port", "0", "--method", "dissolve"],
                         env=dict(os.environ, TMPDIR=str(tmp)), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    try:
        url = p.stdout.readline().split()[-1]
        base, query = url.split("?")
        base = base.rstrip("/")
        r = httpx.post(f"{base}/api/render?{query}&name=long.phn", content=_timit(590))
        job = r.json()["job"]
        deadline = time.monotonic() + 60
        while httpx.get(f"{base}/api/jobs/{job}?{query}").json()["frames"] < 25:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        ffmpeg = _ffmpeg_children(p.pid)
        assert ffmpeg  # the job's encoder is running
        t0 = time.monotonic()
        p.send_signal(signal.SIGTERM)
        p.communicate(timeout=30)
        took = time.monotonic() - t0
    finally:
        if p.poll() is None:
            p.kill()
    print(f"SIGTERM to exit while rendering: {took:.2f} s")
    assert p.returncode == 0 and took < 5.0
    assert list(tmp.iterdir()) == []           # job folder, upload and partial mp4 removed
    pid = int(ffmpeg[0].split()[0])
    # killed with the job's worker; reaped by init (it is the worker's child), or a zombie until then
    deadline = time.monotonic() + 3.0
    while time.monotonic() < deadline:
        stat = subprocess.run(["ps", "-o", "stat=", "-p", str(pid)], capture_output=True, text=True).stdout.strip()
        if not stat or stat.startswith("Z"):
            break
        time.sleep(0.05)
    assert not stat or stat.startswith("Z")  # ffmpeg gone


def test_audio_over_the_limit_is_measured_by_decoding_and_refused_before_aligning():
    srv = Server(max_clip_seconds=2.0)
    try:
        job = srv.submit("hello.wav", (ROOT / "samples" / "hello.wav").read_bytes())   # 2.97 s of speech
        state = srv.wait(job, timeout=20)
        assert state["state"] == "error" and state["frames"] == 0
        assert "hello.wav: lasts more than 2 s; this server renders at most 2 s per job" in state["error"]
    finally:
        srv.stop()


def _gone(pid: int, within: float) -> bool:
    """Whether ``pid`` has exited (or is a zombie awaiting its reaper) within ``within`` s."""
    deadline = time.monotonic() + within
    while True:
        stat = subprocess.run(["ps", "-o", "stat=", "-p", str(pid)], capture_output=True, text=True).stdout.strip()
        if not stat or stat.startswith("Z"):
            return True
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)


def test_a_job_worker_dies_with_a_killed_server(tmp_path):
    # The job's worker sits in a process group of its own (so the job timeout can kill its
    # ffmpeg with it); a server killed with SIGKILL must not leave it rendering on.
    p = subprocess.Popen([sys.executable, "-m", "lipsync", "serve", "--port", "0", "--method", "dissolve"],
                         env=dict(os.environ, TMPDIR=str(tmp_path)), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        url = p.stdout.readline().split()[-1]
        base, query = url.split("?")
        base = base.rstrip("/")
        job = httpx.post(f"{base}/api/render?{query}&name=long.phn", content=_timit(590)).json()["job"]
        deadline = time.monotonic() + 60
        while httpx.get(f"{base}/api/jobs/{job}?{query}").json()["frames"] < 25:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        ffmpeg = _ffmpeg_children(p.pid)
        assert ffmpeg
        out = subprocess.run(["ps", "-o", "pid=,ppid=", "-e"], capture_output=True, text=True).stdout
        workers = [int(r.split()[0]) for r in out.splitlines() if r.split()[1] == str(p.pid)]
        assert workers   # the job's worker process, a child of serve
        p.kill()
        p.wait(timeout=10)
    finally:
        if p.poll() is None:
            p.kill()
    assert all(_gone(pid, 5.0) for pid in workers), "a job worker outlived its killed server"
    assert _gone(int(ffmpeg[0].split()[0]), 5.0), "the job's ffmpeg outlived its killed server"
