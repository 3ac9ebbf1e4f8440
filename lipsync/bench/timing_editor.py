"""Speed figure of ``lipsync edit-timeline`` (registered in :data:`lipsync.bench.FIGURES` as ``timing-editor``).

A 60 s recording made of 20 GRID sentences of speaker s1 (``lipsync.bench.grid``) one after
another, with their transcript, as an animator opens it:

* ``open (align 60 s)``: from ``TimingEditor(AUDIO, text=...)`` to the aligned, mapped
  timeline (decode, align, map) — the ratio is to the recording's length (real-time factor);
* ``first paint``: headless Chromium from loading the page to it showing the waveform, the
  three tiers and the first mouth frame (``body[data-ready]``), served by the real app on
  uvicorn (skipped without Chromium);
* ``/api/frame`` p50 and p95 over HTTP, each request a frame not asked before (no cache) at
  a random time, the timeline edited once first (so the animator is rebuilt) — the ratio is
  to the frame period at 25 fps (under 1: frames come faster than playback needs them);
* the frames served per second with the page's 3 requests in flight, as a ratio to 25 fps
  (over 1: uncached playback keeps up).
"""

from __future__ import annotations

import random
import time
from typing import List

import numpy as np

from . import FIGURES, Context

#: Sentences joined: 20 GRID sentences of ~3 s make a minute.
SENTENCES = 20
#: Frame requests the page keeps in flight while playing (timing.js MAX_INFLIGHT).
INFLIGHT = 3


def _minute(ctx: Context):
    """A ~60 s WAV of GRID sentences and its transcript."""
    import wave

    from ..speech.audio import load_audio
    from . import grid

    names = grid.clips()[:SENTENCES]
    pcm = np.concatenate([load_audio(grid.video(n)) for n in names])
    path = ctx.tmp / "timing-minute.wav"
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(16000)
        w.writeframes(pcm.astype("<i2").tobytes())
    return path, " ".join(grid.transcript(n) for n in names), len(pcm) / 16000


@FIGURES.decorator("timing-editor")
def timing_editor_figure(ctx: Context, rows: List[dict]) -> None:
    import httpx

    from ..timing_editor import TimingEditor, make_app
    from ..web import Session, start_in_thread

    audio, text, seconds = _minute(ctx)
    t0 = time.perf_counter()
    editor = TimingEditor(audio, text=text, out=ctx.tmp / "timing-out")
    opened = time.perf_counter() - t0
    rows.append({"figure": "timing-editor", "measure": f"open a {seconds:.0f} s recording with --text (aligned)",
                 "ms": round(opened * 1e3), "ratio": round(opened / seconds, 3), "n": len(editor.get()["words"])})

    session = Session.open()
    running = start_in_thread(make_app(editor, session), session)
    try:
        paint = _first_paint(session)
        if paint is not None:
            rows.append({"figure": "timing-editor", "measure": "page load -> first paint (tiers + mouth)",
                         "ms": round(paint * 1e3), "ratio": "", "n": 1})
        client = httpx.Client(base_url=session.origin, headers={"X-Lipsync-Token": session.token}, timeout=120)
        doc = client.get("/api/timeline").json()
        doc["visemes"] = None
        assert client.put("/api/timeline", json=doc).status_code == 200  # a new version: no warm animator
        n = 20 if ctx.quick else 100
        fps = editor.context.fps
        frames = random.Random(0).sample(range(int(seconds * fps) - 1), n)
        times = []
        for i in frames:
            t = time.perf_counter()
            r = client.get(f"/api/frame?t={i / fps}")
            times.append(time.perf_counter() - t)
            assert r.status_code == 200
        # the page keeps MAX_INFLIGHT requests going while playing: frames served per second so
        from concurrent.futures import ThreadPoolExecutor

        ahead = random.Random(1).sample(sorted(set(range(int(seconds * fps) - 1)) - set(frames)), n)
        with ThreadPoolExecutor(INFLIGHT) as pool:
            t = time.perf_counter()
            codes = list(pool.map(lambda i: client.get(f"/api/frame?t={i / fps}").status_code, ahead))
            served = n / (time.perf_counter() - t)
        assert set(codes) == {200}
    finally:
        running.stop()
        session.close()
    rows.append({"figure": "timing-editor", "measure": f"/api/frame throughput, {INFLIGHT} in flight (as the page plays)",
                 "ms": round(1e3 / served, 1), "ratio": round(served / fps, 2), "n": n})
    ms = np.array(times) * 1e3
    period = 1e3 / fps
    for q in (50, 95):
        value = float(np.percentile(ms, q))
        rows.append({"figure": "timing-editor", "measure": f"/api/frame p{q} (uncached, 512x512 PNG, over HTTP)",
                     "ms": round(value, 1), "ratio": round(value / period, 2), "n": n})


def _first_paint(session):
    """Seconds from asking Chromium for the page to the page being ready; None without Chromium."""
    from ..editor.browser import chromium, missing, wait

    if missing() is not None:
        return None
    with chromium(1400, 700) as driver:
        t = time.perf_counter()
        driver.get(session.url("/"))
        wait(driver, "document.body.dataset.ready === '1'", 120, "the timing editor page")
        return time.perf_counter() - t
