"""Hostile and careless inputs, round five (issue 38): each test failed on round four's code.

Items: a job stuck in any stage is stopped at ``--job-timeout`` (2); transcripts have a size
limit (1); an output that is one of the inputs is refused (4); IPA timelines (12); and the
smaller ones (13).
"""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import pytest

import lipsync.motion.sequencer as sequencer
from lipsync.server import LiveServer, ServeConfig, WS_MAX_MESSAGE
from lipsync.web import Session, start_in_thread

ROOT = Path(__file__).resolve().parents[1]
HELLO = ROOT / "samples" / "hello.phn"


# --- item 2: the job timeout stops a job in any stage ----------------------------------------

def _stuck_in_planning(real):
    def plan_segments(visemes, **kw):
        if visemes.duration > 10:   # the long upload: a planning step that never ends, never checks
            while True:
                pass
        return real(visemes, **kw)
    return plan_segments


def _timit(seconds: float, step: float = 0.2) -> bytes:
    rows, t, k = [], 0.0, 0
    while t < seconds:
        rows.append(f"{int(t * 16000)} {int(min(t + step, seconds) * 16000)} {('aa', 'm')[k % 2]}")
        t, k = t + step, k + 1
    return ("\n".join(rows) + "\n").encode()


def test_a_job_stuck_in_planning_is_stopped_at_its_timeout_and_the_next_one_runs(monkeypatch):
    monkeypatch.setattr(sequencer, "plan_segments", _stuck_in_planning(sequencer.plan_segments))
    session = Session.open("127.0.0.1", 0)
    server = LiveServer(ServeConfig(method="dissolve", job_timeout=5.0), session=session)
    handle = start_in_thread(server.app, session, ws_max_size=WS_MAX_MESSAGE)
    try:
        def submit(name, body):
            r = httpx.post(session.url("/api/render") + f"&name={name}", content=body)
            assert r.status_code == 202, r.text
            return r.json()["job"]

        def wait(job, timeout):
            deadline = time.monotonic() + timeout
            while True:
                s = httpx.get(session.url(f"/api/jobs/{job}")).json()
                if s["state"] in ("done", "error"):
                    return s, time.monotonic()
                assert time.monotonic() < deadline, f"job still {s['state']} after {timeout} s"
                time.sleep(0.05)

        t0 = time.monotonic()
        stuck = submit("long.phn", _timit(20))
        small = submit("hello.phn", HELLO.read_bytes())
        state, t_stopped = wait(stuck, 30)
        assert state["state"] == "error" and "stopped after 5 s (--job-timeout)" in state["error"]
        assert state["frames"] == 0                   # it never got past planning
        assert 5.0 <= t_stopped - t0 < 15.0
        done, _ = wait(small, 60)
        assert done["state"] == "done" and done["frames"] == 75
        assert not list(server.tmp.glob(f"{stuck}/*out*"))   # nothing of the stopped job left
    finally:
        handle.stop()
        server.close()
        session.close()
