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

import os
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
    from ..pipeline.animator import Animator
    from ..banks.bank import Bank
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

    from ..banks.bank import Bank
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

    from ..banks.bank import Bank
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


# --- audio in (issue 30): lipsync.live.audio, LiveAnimator.feed_audio ------------------------
#
# ``python -m lipsync.bench --only live_audio_shapes --only live_audio_lips --only live_audio_speed
# --only live_audio_sessions --only live_events_delay`` (each runnable alone). Timings are wall
# and CPU time on whatever else the machine runs: compare the ratios printed side by side.

#: Look-aheads of the trade-off curve, seconds.
AUDIO_LOOKAHEADS = (0.0, 0.06, 0.1, 0.14, 0.2, 0.3, 0.4)


def _shape_track(specs) -> np.ndarray:
    """Each frame's nearer viseme (what a viewer reads as the mouth shape)."""
    return np.array([s.from_viseme if s.alpha < 0.5 else s.to_viseme for s in specs], dtype=object)


def _offline_loop_specs(bank, pcm, n: int, timing=None):
    """Offline without a transcript: the same phone loop and gate over the whole file, then
    the offline sequencer (:class:`lipsync.Animator`)."""
    from ..pipeline.animator import Animator
    from ..live.audio import offline_phones
    from ..motion.timeline import PHONEME, Segment, Timeline

    dur = len(pcm) / 16000
    runs = offline_phones(pcm)
    tl = Timeline(tuple(Segment(a / 100, b / 100, p) for a, b, p in runs), kind=PHONEME, stated_end=dur)
    return Animator(bank, tl, fps=25, timing=timing).specs[:n]


def _recordings(ctx: Context, count: int):
    """(name, 16 kHz samples, transcript-aligned phones) of the MFA recording and GRID clips."""
    from ..readers import read_timeline
    from ..speech.audio import load_audio
    from . import grid as G

    out = []
    wav = ctx.mfa / "acoustic_corpus.wav"
    if wav.is_file() and (ctx.mfa / "acoustic_corpus.TextGrid").is_file():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out.append(("mfa acoustic_corpus", load_audio(wav), read_timeline(ctx.mfa / "acoustic_corpus.TextGrid")))
    for c in [c for c in G.held_out() if G.video(c).is_file()][:count]:
        out.append((c, load_audio(G.video(c)), G.alignment_of(c).phones))
    return out


@FIGURES.decorator("live_audio_shapes")
def _audio_shapes(ctx: Context, rows: List[dict]) -> None:
    """Mouth shapes against the transcript-aligned track: live at each look-ahead and offline
    without a transcript (frames showing the same shape, toon bank, its timing)."""
    from .._data import default_bank_dir
    from ..pipeline.animator import Animator
    from ..banks.bank import Bank
    from ..pipeline.liveclip import live_specs

    bank = Bank.load(default_bank_dir())
    recs = _recordings(ctx, 6 if ctx.quick else 30)
    per = {"offline": [], **{L: [] for L in AUDIO_LOOKAHEADS}}
    vs_off = {L: [] for L in AUDIO_LOOKAHEADS}
    mfa = {}
    for name, pcm, phones in recs:
        n = int(np.ceil(len(pcm) / 16000 * 25))
        ref = _shape_track(Animator(bank, phones.replace(stated_end=max(len(pcm) / 16000, phones.duration)),
                                    fps=25).specs[:n])
        off = _shape_track(_offline_loop_specs(bank, pcm, n))
        score = {"offline": float(np.mean(off == ref))}
        for L in AUDIO_LOOKAHEADS:
            live = _shape_track(live_specs(pcm, bank, lookahead=L))
            score[L] = float(np.mean(live == ref))
            vs_off[L].append(float(np.mean(live == off)))
        if name.startswith("mfa"):
            mfa = score
        else:
            for k, v in score.items():
                per[k].append(v)
    grid_n = len(per["offline"])
    for L in AUDIO_LOOKAHEADS:
        row = {"figure": "live_audio_shapes", "look-ahead ms": round(L * 1000)}
        if grid_n:
            row.update({f"GRID ({grid_n}) live": round(statistics.mean(per[L]), 3),
                        "GRID offline (no transcript)": round(statistics.mean(per["offline"]), 3),
                        "GRID live - offline, points": round(100 * (statistics.mean(per[L]) - statistics.mean(per["offline"])), 1)})
        if mfa:
            row.update({"MFA live": round(mfa[L], 3), "MFA offline": round(mfa["offline"], 3),
                        "MFA live - offline, points": round(100 * (mfa[L] - mfa["offline"]), 1)})
        row["live = offline frames (all)"] = round(statistics.mean(vs_off[L]), 3)
        rows.append(row)


@FIGURES.decorator("live_audio_lips")
def _audio_lips(ctx: Context, rows: List[dict]) -> None:
    """Lip opening against the real speaker (GRID s1, held-out sentences) with the shipped
    visemes/grid-s1 bank (its own timing): live (140 and 200 ms) against offline without a
    transcript, and the transcript-aligned track for reference. r per clip, mean."""
    from .._data import default_bank_dir
    from ..pipeline.animator import Animator
    from ..banks.bank import Bank
    from ..motion.coarticulation import predicted
    from ..pipeline.liveclip import live_specs
    from ..speech.audio import load_audio
    from . import grid as G
    from .coarticulation import bank_values

    path = default_bank_dir().parent / "grid-s1"
    held = [c for c in G.held_out() if G.video(c).is_file()][:8 if ctx.quick else 30]
    if not (path / "bank.yaml").is_file() or not held:
        rows.append({"figure": "live_audio_lips", "case": "skipped: no visemes/grid-s1 or GRID clips"})
        return
    bank = Bank.load(path)
    values = bank_values(bank)
    r = {"live 140 ms": [], "live 200 ms": [], "offline, no transcript": [], "offline, transcript": []}
    for c in held:
        real = G.real_measures(c)["opening"]
        n = len(real)
        pcm = load_audio(G.video(c))
        aligned = G.alignment_of(c).phones
        specs = {"live 140 ms": live_specs(pcm, bank, lookahead=0.14)[:n],
                 "live 200 ms": live_specs(pcm, bank, lookahead=0.2)[:n],
                 "offline, no transcript": _offline_loop_specs(bank, pcm, n),
                 "offline, transcript": Animator(bank, aligned.replace(stated_end=max(n / 25, aligned.duration)),
                                                 fps=25).specs[:n]}
        for k, s in specs.items():
            m = min(len(s), n)
            r[k].append(G.correlation(predicted(s[:m], values), real[:m]))
    base = statistics.mean(r["offline, no transcript"])
    for k, v in r.items():
        rows.append({"figure": "live_audio_lips", "track": k, "clips": len(v),
                     "lip-opening r (mean)": round(statistics.mean(v), 3),
                     "minus offline no transcript": round(statistics.mean(v) - base, 3)})


def _session_costs(bank, pcm, *, render: bool, pool=None):
    """Feed ``pcm`` in 20 ms chunks as fast as possible; per chunk the wall time from its
    last sample to its frames being ready (fed, and rendered + JPEG-encoded when ``render``);
    and the CPU seconds of this thread."""
    import cv2

    from ..live import LiveAnimator

    live = LiveAnimator(bank, fps=25, renderer=pool, prepare=False)
    out = np.empty(live.shape + (live.renderer.channels,), np.uint8)
    live.feed_audio(np.zeros(0, np.int16), 16000)     # the recogniser loaded (a session's config)
    lat = []
    cpu = time.thread_time()
    for i in range(0, len(pcm), 320):
        t = time.perf_counter()
        for n in live.feed_audio(pcm[i:i + 320], 16000):
            if render:
                live.frame(n, out=out)
                cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, 80])
        lat.append(time.perf_counter() - t)
    return np.array(lat), time.thread_time() - cpu


@FIGURES.decorator("live_audio_speed")
def _audio_speed(ctx: Context, rows: List[dict]) -> None:
    """One audio session on one core: per-chunk latency and CPU per second of audio."""
    import cv2

    from .._data import default_bank_dir
    from ..banks.bank import Bank
    from ..live import AUDIO_LOOKAHEAD_S, LiveAnimator
    from ..speech.audio import load_audio

    wav = ctx.mfa / "acoustic_corpus.wav"
    if not wav.is_file():
        return
    pcm = load_audio(wav)
    if ctx.quick:
        pcm = pcm[:16000 * 8]
    seconds = len(pcm) / 16000
    bank = Bank.load(default_bank_dir())
    LiveAnimator(bank, fps=25)          # flows ready
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        for render in (False, True):
            lat, cpu = _session_costs(bank, pcm, render=render)
            per_s = cpu / seconds
            row = {"figure": "live_audio_speed", "work": "recognise + sequence" + (" + render 512px + JPEG" if render else ""),
                   "audio s": round(seconds, 1), "chunk p50 ms": round(1000 * float(np.percentile(lat, 50)), 2),
                   "chunk p95 ms": round(1000 * float(np.percentile(lat, 95)), 2),
                   "chunk max ms": round(1000 * float(lat.max()), 1),
                   "CPU s per s of audio": round(per_s, 3),
                   "end to end p95 ms (look-ahead + chunk + p95)": round(1000 * (AUDIO_LOOKAHEAD_S + 0.02)
                                                                         + 1000 * float(np.percentile(lat, 95)))}
            if render:
                row["sessions one core holds at 25 fps"] = int(1.0 / per_s)
            rows.append(row)
    finally:
        cv2.setNumThreads(threads)


#: A frame is on time when it is ready by its audio time plus the look-ahead plus this: the
#: 20 ms chunk its audio came in and one frame (40 ms at 25 fps) of the player's own timing,
#: which shows each frame at the first screen refresh after its time anyway.
DUE_MARGIN_S = 0.06


@FIGURES.decorator("live_audio_sessions")
def _audio_sessions(ctx: Context, rows: List[dict]) -> None:
    """8 audio sessions at once in real time (threads, as ``lipsync serve`` runs them; a pool
    of 2 renderers, warm), each frame rendered and JPEG-encoded: is every frame ready when due?
    The machine's load average is printed beside: other work on the cores delays frames."""
    import threading

    import cv2

    from .._data import default_bank_dir
    from ..banks.bank import Bank
    from ..live import AUDIO_LOOKAHEAD_S, LiveAnimator, RendererPool
    from ..speech.audio import load_audio
    from . import grid as G

    clips = [c for c in G.held_out() if G.video(c).is_file()][:8]
    if len(clips) < 8:
        rows.append({"figure": "live_audio_sessions", "case": "skipped: fewer than 8 GRID clips"})
        return
    bank = Bank.load(default_bank_dir())
    LiveAnimator(bank, fps=25)
    pool = RendererPool(bank, size=2)
    # a server that has run a while has met every viseme pair (a pair's first in-between
    # frame builds its state: ~100 ms, the live_latency figure's "cold" column)
    pool.warm([(a, b) for a in bank.names for b in bank.names if a != b])
    audio = [load_audio(G.video(c)) for c in clips]
    lives = [LiveAnimator(bank, fps=25, renderer=pool, prepare=False) for _ in clips]
    for live in lives:
        live.feed_audio(np.zeros(0, np.int16), 16000)
    late: List[float] = []
    frames = [0]
    lock = threading.Lock()
    start = time.perf_counter() + 0.5

    def session(live, pcm):
        out = np.empty(live.shape + (live.renderer.channels,), np.uint8)
        for k, i in enumerate(range(0, len(pcm), 320)):
            wait = start + (k + 1) * 0.02 - time.perf_counter()   # chunk k's last sample arrives
            if wait > 0:
                time.sleep(wait)
            for n in live.feed_audio(pcm[i:i + 320], 16000):
                live.frame(n, out=out)
                cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, 80])
                ready = time.perf_counter() - start
                with lock:
                    late.append(ready - (n / 25 + AUDIO_LOOKAHEAD_S + DUE_MARGIN_S))
                    frames[0] += 1

    cpu = time.process_time()
    ths = [threading.Thread(target=session, args=(lv, p)) for lv, p in zip(lives, audio)]
    for th in ths:
        th.start()
    for th in ths:
        th.join()
    cpu = time.process_time() - cpu
    late_a = np.array(late)
    rows.append({"figure": "live_audio_sessions", "sessions": len(lives), "renderers": pool.size,
                 "audio s each": round(statistics.mean(len(p) / 16000 for p in audio), 1), "frames": frames[0],
                 "on time": f"{int((late_a <= 0).sum())}/{len(late_a)}",
                 "ready after audio, p95 ms": round(1000 * float(np.percentile(late_a + DUE_MARGIN_S, 95)), 1),
                 "latest vs due ms": round(1000 * float(late_a.max()), 1),
                 "CPU s per s of audio (all)": round(cpu / sum(len(p) / 16000 for p in audio), 3),
                 "cores": os.cpu_count(), "load average (1 min)": round(os.getloadavg()[0], 1)})


def needed_delays(segments, n_frames: int, lookahead: float, events_at: str, fps: float = 25.0) -> np.ndarray:
    """Per frame, the least delay behind the newest event's arrival at which the frame is final
    (the data reaches ``lookahead`` past it) when each event arrives as its sound starts or ends.

    Examples
    --------
    >>> needed_delays([(0.0, 0.3, "A"), (0.3, 0.5, "B")], 3, 0.1, "end", fps=10).round(2).tolist()
    [0.3, 0.2, 0.1]
    """
    ends = np.array([e for _, e, _ in segments])
    arrive = np.array([s for s, _, _ in segments]) if events_at == "start" else ends
    out = np.full(n_frames, np.inf)
    for n in range(n_frames):
        t = n / fps
        ok = np.nonzero(ends >= t + lookahead - 1e-9)[0]
        if len(ok):
            out[n] = max(0.0, arrive[ok].min() - t) if events_at == "start" else arrive[ok[0]] - t
    return out


@FIGURES.decorator("live_events_delay")
def _events_delay(ctx: Context, rows: List[dict]) -> None:
    """The delay events need: at a phone's start the look-ahead is enough; at its end the data
    lags the clock by up to one event, so every frame is final only at the look-ahead plus the
    longest event. Measured with the live animator's own is_final (frames whose data never
    reaches the look-ahead past them, the last ones, left out)."""
    from .._data import default_bank_dir
    from ..banks.bank import Bank
    from ..live import LiveAnimator

    bank = Bank.load(default_bank_dir())
    root = default_bank_dir().parents[1]
    for path in (root / "samples" / "hello.phn", root / "samples" / "balloons.phn", ctx.mfa / "acoustic_corpus.TextGrid"):
        if not path.exists():
            continue
        live = LiveAnimator(bank, fps=25, prepare=False)
        segs = live.resolve_timeline(_timeline(path))
        end = segs[-1][1]
        n = int((end - live.lookahead) * 25)
        longest = max(e - s for s, e, _ in segs)
        row = {"figure": "live_events_delay", "timeline": path.name, "frames": n, "look-ahead ms": round(1000 * live.lookahead),
               "longest event ms": round(1000 * longest)}
        for at in ("start", "end"):
            need = needed_delays(segs, n, live.lookahead, at)
            row[f"at {at}: needed max ms"] = round(1000 * float(need.max()))
            row[f"at {at}: final at look-ahead"] = f"{int((need <= live.lookahead + 1e-9).sum())}/{n}"
        row["look-ahead + longest ms"] = round(1000 * (live.lookahead + longest))
        rows.append(row)


# --- live cues and the end of a stream (issue 36), serve's memory (issue 38) ------------------

#: Look-aheads of the live cue figure, seconds.
CUE_LOOKAHEADS = (0.06, 0.1, 0.2, 0.4)


def _cli_cue_frames(args, n: int, out: "os.PathLike[str]") -> np.ndarray:
    """``lipsync cues ARGS -o OUT.tsv`` run in this process; the cue shown at each of ``n``
    frame centres (25 fps) of the Rhubarb TSV it wrote."""
    import contextlib
    import io

    from ..cli import main

    with contextlib.redirect_stderr(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main(["cues", *map(str, args), "-o", str(out), "--quiet"])
    if rc != 0:
        raise RuntimeError(f"lipsync cues {' '.join(map(str, args))} exited {rc}")
    shown = np.full(n, "X", dtype=object)
    for line in open(out, encoding="utf-8"):
        parts = line.split()
        if len(parts) == 2:
            shown[max(int(np.ceil(float(parts[0]) * 25 - 0.5 - 1e-9)), 0):] = parts[1]
    return shown


def _wav(path, pcm) -> None:
    import wave

    with wave.open(str(path), "wb") as w:
        w.setnchannels(1), w.setsampwidth(2), w.setframerate(16000)
        w.writeframes(np.asarray(pcm).astype("<i2").tobytes())


@FIGURES.decorator("live_cues")
def _live_cues(ctx: Context, rows: List[dict]) -> None:
    """``lipsync cues AUDIO --live`` against the transcript-aligned cues (``lipsync cues AUDIO
    --text T``) on speech frames (frames whose aligned cue is not rest X), held-out GRID
    sentences (:func:`lipsync.bench.grid.held_out`; the choices were made on
    :data:`~lipsync.bench.grid.BANK_CLIPS`), per look-ahead: the shapes the session fixed
    (:meth:`lipsync.LiveAnimator.cue`, what cues --live writes) beside the nearer viseme of
    each rendered frame (what it wrote before), with the toon bank and with visemes/grid-s1
    (its dominance timing blends shapes), and offline without a transcript (``lipsync cues
    AUDIO``). Also each stream's frame count against the offline render's."""
    from .._data import default_bank_dir
    from ..banks.bank import Bank
    from ..phonetics.phonemes import DEFAULT_MAP, load_map, resolve_visemes
    from ..pipeline.liveclip import live_session
    from ..speech.audio import load_audio
    from . import grid as G

    clips = [c for c in G.held_out() if G.video(c).is_file()][:6 if ctx.quick else 30]
    banks = {"toon": Bank.load(default_bank_dir()), "grid-s1": Bank.load(default_bank_dir().parent / "grid-s1")}
    if not clips or banks["grid-s1"].plate is None:
        rows.append({"figure": "live_cues", "case": "skipped: no GRID clips"})
        return
    base = load_map(DEFAULT_MAP)
    to_map = {k: {b: m for m, b in resolve_visemes(base, bank.names)[0].items()} for k, bank in banks.items()}
    score = {"offline": []}
    counts_equal = 0
    for c in clips:
        pcm = load_audio(G.video(c))
        n = int(np.ceil(len(pcm) / 16000 * 25 - 1e-9))
        wav = ctx.tmp / f"{c}.wav"
        _wav(wav, pcm)
        ref = _cli_cue_frames([wav, "--text", G.transcript(c)], n, ctx.tmp / "ref.tsv")
        speech = ref != "X"
        agree = lambda track: float(np.mean(np.asarray(track, dtype=object)[speech] == ref[speech]))  # noqa: E731
        score["offline"].append(agree(_cli_cue_frames([wav], n, ctx.tmp / "off.tsv")))
        for L in CUE_LOOKAHEADS:
            for name, bank in banks.items():
                live, frames = live_session(pcm, bank, lookahead=L)
                counts_equal += frames == n
                m = to_map[name]
                cues = [m.get(live.cue(k), live.cue(k)) for k in range(n)]
                near = [m.get(v, v) for v in _shape_track([live.spec(k) for k in range(n)])]
                score.setdefault((L, name, "cue"), []).append(agree(cues))
                score.setdefault((L, name, "near"), []).append(agree(near))
    off = 100 * statistics.mean(score["offline"])
    for L in CUE_LOOKAHEADS:
        row = {"figure": "live_cues", "look-ahead ms": round(L * 1000), "held-out clips": len(clips),
               "offline, no transcript %": round(off, 1)}
        for name in banks:
            cue = 100 * statistics.mean(score[(L, name, "cue")])
            row[f"{name}: live cues %"] = round(cue, 1)
            row[f"{name}: minus offline, points"] = round(cue - off, 1)
            row[f"{name}: nearer viseme of the frame %"] = round(100 * statistics.mean(score[(L, name, "near")]), 1)
        rows.append(row)
    rows.append({"figure": "live_cues", "case": "streams whose frame count = the offline render's",
                 "count": f"{counts_equal}/{len(clips) * len(CUE_LOOKAHEADS) * len(banks)}"})


def _rss_of(pid: int) -> float:
    """Resident memory of process ``pid`` in MB (Linux ``/proc``)."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


async def _memory_round(ws_url: str, origin: str, sessions: int, pcm: np.ndarray, pid: int) -> float:
    """Open ``sessions`` audio sessions on a running server, stream ``pcm`` and end each;
    the server's resident MB with all of them open; then close them."""
    import asyncio
    import json

    import websockets

    socks = [await websockets.connect(ws_url, origin=origin, max_size=2**24) for _ in range(sessions)]
    try:
        for ws in socks:
            await ws.recv()                                        # ready
            await ws.send(json.dumps({"type": "config", "audio_rate": 16000}))

        async def until(ws, kind):
            while True:
                msg = await asyncio.wait_for(ws.recv(), 120)
                if isinstance(msg, str) and json.loads(msg)["type"] == kind:
                    return

        for ws in socks:
            await until(ws, "config")                              # the recogniser is loaded
            await ws.send(pcm.astype("<i2").tobytes())
            await ws.send(json.dumps({"type": "end"}))
        for ws in socks:
            await until(ws, "end")
        return _rss_of(pid)
    finally:
        for ws in socks:
            await ws.close()


@FIGURES.decorator("serve_memory")
def _serve_memory(ctx: Context, rows: List[dict]) -> None:
    """``lipsync serve``'s resident memory over three rounds of 32 audio sessions (each loads
    a recogniser, streams 1 s of speech and ends its stream), open and after all closed,
    against the server's memory before the first (issue 38 item 10)."""
    import asyncio
    import re
    import subprocess
    import sys

    import httpx

    from ..speech.audio import load_audio
    from . import grid as G

    sessions = 8 if ctx.quick else 32
    clip = [c for c in G.held_out() if G.video(c).is_file()][0]
    pcm = load_audio(G.video(clip))[:16000]
    proc = subprocess.Popen([sys.executable, "-m", "lipsync", "serve", "--port", "0", "--max-sessions",
                             str(sessions), "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        line = proc.stdout.readline()
        m = re.search(r"(http://127\.0\.0\.1:\d+)/\?token=(\S+)", line)
        if m is None:
            rows.append({"figure": "serve_memory", "case": f"skipped: serve printed {line.strip()[:80]!r}"})
            return
        origin, token = m.group(1), m.group(2)
        ws_url = origin.replace("http://", "ws://") + f"/ws/live?token={token}"

        def settle():
            for _ in range(200):
                if httpx.get(f"{origin}/api/status?token={token}").json()["sessions"] == 0:
                    break
                time.sleep(0.05)
            time.sleep(0.5)
            return _rss_of(proc.pid)

        start = settle()
        for k in range(3):
            open_mb = asyncio.run(_memory_round(ws_url, origin, sessions, pcm, proc.pid))
            closed = settle()
            rows.append({"figure": "serve_memory", "round": k + 1, "audio sessions": sessions,
                         "RSS before the first MB": round(start), "RSS all open MB": round(open_mb),
                         "RSS all closed MB": round(closed), "closed minus before MB": round(closed - start),
                         "per open session MB": round((open_mb - start) / sessions, 1)})
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:  # pragma: no cover
            proc.kill()
