"""Speed figures of the live animator (registered in :data:`lipsync.bench.FIGURES`):

1. ``live_lookahead``: the data a frame needs past its time before it equals the offline
   frame -- the bound derived from the sequencer's constants (:data:`LOOKAHEAD_S`) beside
   the smallest lag (10 ms steps; 20 with --quick) that gives every frame of each real timeline exactly;
2. ``live_latency``: push -> frame available, wall time. Events of the MFA recording are
   pushed one at a time; after each push the newest frame it made final (time = data end
   - look-ahead) is rendered. Median, 95th percentile and maximum, at 512x512 and
   1280x720, with a cold renderer (each viseme pair met for the first time) and a warm one;
3. ``live_fps``: sustained frames per second per core: one thread, OpenCV limited to one
   thread, rendering every frame of the recording in clock order; also with JPEG encoding
   (what ``lipsync serve`` sends) and with the two-thread pool the server uses (frames per
   second for the whole machine).
"""

from __future__ import annotations

import statistics
import time
import warnings
from typing import List

import numpy as np

from . import FIGURES, Context


def _timeline(path):
    from ..readers import read_timeline

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_timeline(path)


def bench_lookahead(rows: List[dict], ctx: Context) -> None:
    from .._data import default_bank_dir
    from ..animator import Animator
    from ..bank import Bank
    from ..live import LOOKAHEAD_S, LiveAnimator, replay_specs

    bank = Bank.load(default_bank_dir())
    root = default_bank_dir().parents[1]
    files = [root / "samples" / "hello.phn", root / "samples" / "balloons.phn", ctx.mfa / "acoustic_corpus.TextGrid"]
    for path in files:
        if not path.exists():
            continue
        tl = _timeline(path)
        offline = Animator(bank, tl, fps=25).specs
        segs = LiveAnimator(bank, fps=25, prepare=False).resolve_timeline(tl)
        needed = 0.0
        step = 0.02 if ctx.quick else 0.01
        for lag in np.arange(0.0, LOOKAHEAD_S + 0.005, step):
            if replay_specs(LiveAnimator(bank, fps=25, prepare=False), segs, len(offline), lag) != offline:
                needed = float(lag) + step
        rows.append({"figure": "live_lookahead", "timeline": path.name, "frames": len(offline),
                     "bound_ms": round(LOOKAHEAD_S * 1000), "needed_ms": round(needed * 1000)})


def _segments(bank, ctx: Context):
    from ..live import LiveAnimator

    return LiveAnimator(bank, fps=25, prepare=False).resolve_timeline(_timeline(ctx.mfa / "acoustic_corpus.TextGrid"))


def bench_latency(rows: List[dict], ctx: Context, banks) -> None:
    import cv2

    from ..bank import Bank
    from ..live import LiveAnimator

    for label, path in banks.items():
        bank = Bank.load(path)
        segs = _segments(bank, ctx)
        limit = 80 if ctx.quick else len(segs)
        pool = None
        for run in ("cold", "warm"):
            # cold: a new renderer meets each viseme pair for the first time (its per-pair
            # state is built then); warm: a second session on the same renderer
            live = LiveAnimator(bank, fps=25, renderer=pool)
            pool = live.renderer
            out = np.empty(live.shape + (3,), np.uint8)
            push_ms, frame_ms, total_ms, jpeg_ms = [], [], [], []
            for seg in segs[:limit]:
                t0 = time.perf_counter()
                live.push(*seg, kind="viseme")
                t1 = time.perf_counter()
                t = live.final_until
                if t < 0:
                    continue
                live.frame_at(t, out=out)
                t2 = time.perf_counter()
                cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, 80])
                t3 = time.perf_counter()
                push_ms.append((t1 - t0) * 1e3)
                frame_ms.append((t2 - t1) * 1e3)
                total_ms.append((t2 - t0) * 1e3)
                jpeg_ms.append((t3 - t0) * 1e3)
            q = lambda xs, p: round(float(np.percentile(xs, p)), 2)  # noqa: E731
            rows.append({"figure": "live_latency", "size": label, "renderer": run, "pushes": len(total_ms),
                         "push_ms_median": round(statistics.median(push_ms), 3),
                         "frame_ms_median": round(statistics.median(frame_ms), 2),
                         "push_to_frame_ms_median": q(total_ms, 50), "push_to_frame_ms_p95": q(total_ms, 95),
                         "push_to_frame_ms_max": q(total_ms, 100), "push_to_jpeg_ms_median": q(jpeg_ms, 50),
                         "lookahead_ms": round(live.lookahead * 1000)})


def bench_fps(rows: List[dict], ctx: Context, banks) -> None:
    import threading

    import cv2

    from ..bank import Bank
    from ..live import LiveAnimator, RendererPool

    seconds = 4.0 if ctx.quick else 12.0
    for label, path in banks.items():
        bank = Bank.load(path)
        segs = [s for s in _segments(bank, ctx) if s[1] <= seconds]
        live = LiveAnimator(bank, fps=25)
        live.push(*segs[0], kind="viseme")
        for seg in segs[1:]:
            live.push(*seg, kind="viseme")
        n_frames = int(seconds * 25)
        out = np.empty(live.shape + (3,), np.uint8)
        live.frame(n_frames // 2, out=out)  # plan once
        for n in range(n_frames):            # warm: every pair state of this speech
            live.frame(n, out=out)
        threads = cv2.getNumThreads()
        cv2.setNumThreads(1)
        try:
            t = time.perf_counter()
            for n in range(n_frames):
                live.frame(n, out=out)
            render_s = time.perf_counter() - t
            t = time.perf_counter()
            for n in range(n_frames):
                live.frame(n, out=out)
                cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, 80])
            jpeg_s = time.perf_counter() - t
        finally:
            cv2.setNumThreads(threads)
        # The server's arrangement: a pool of renderers, one thread per core, OpenCV default.
        workers = 2
        pool = RendererPool(bank, size=workers)
        lives = []
        for _ in range(workers):
            other = LiveAnimator(bank, fps=25, renderer=pool, prepare=False)
            for seg in segs:
                other.push(*seg, kind="viseme")
            lives.append(other)
        pool.warm(sorted({(s.from_viseme, s.to_viseme) for s in map(live.spec, range(n_frames))
                          if s.shown is None}))

        def work(anim):
            buf = np.empty(anim.shape + (3,), np.uint8)
            for n in range(n_frames):
                anim.frame(n, out=buf)

        ths = [threading.Thread(target=work, args=(a,)) for a in lives]
        t = time.perf_counter()
        for th in ths:
            th.start()
        for th in ths:
            th.join()
        pool_s = time.perf_counter() - t
        rows.append({"figure": "live_fps", "size": label, "frames": n_frames,
                     "fps_per_core": round(n_frames / render_s, 1),
                     "fps_per_core_with_jpeg": round(n_frames / jpeg_s, 1),
                     "x_real_time_per_core": round(n_frames / render_s / 25, 2),
                     f"fps_{workers}_threads_pool": round(workers * n_frames / pool_s, 1),
                     "sessions_at_25fps": int(workers * n_frames / pool_s // 25)})


@FIGURES.decorator("live_lookahead")
def _lookahead(ctx: Context, rows: List[dict]) -> None:
    bench_lookahead(rows, ctx)


@FIGURES.decorator("live_latency")
def _latency(ctx: Context, rows: List[dict]) -> None:
    from .render import _toon_banks

    if (ctx.mfa / "acoustic_corpus.TextGrid").exists():
        bench_latency(rows, ctx, _toon_banks(ctx))


@FIGURES.decorator("live_fps")
def _fps(ctx: Context, rows: List[dict]) -> None:
    from .render import _toon_banks

    if (ctx.mfa / "acoustic_corpus.TextGrid").exists():
        bench_fps(rows, ctx, _toon_banks(ctx))
