"""Live sessions with mouth samples (``live_samples``, issue 35 item 4): selection within the
look-ahead against the offline render and the old live morph, and what it costs per frame.

Bank: ``visemes/grid-s1`` (its samples are the ten :data:`~lipsync.bench.grid.BANK_CLIPS`).
Sentences: the first 18 held-out GRID s1 clips (:func:`~lipsync.bench.grid.held_out`, the
ones no weight of the selection was tuned on; 6 with ``--quick``), each rendered four ways
on the bank's plate from the same bank:

* **offline samples** -- ``lipsync render`` of the clip's alignment (its audio and
  transcript through the aligner), samples on;
* **live samples** -- ``lipsync render AUDIO --live`` (the audio fed in 20 ms chunks, the
  phone loop's phones, each frame and its sample fixed 200 ms after its time), samples on:
  the windows' targets blend in the bank's audio lip model's prediction from the audio
  heard (:data:`lipsync.live.samples.LIVE_AUDIO_SHARE`);
* **live samples, no audio target** -- the same with the phones' target alone (share 0);
* **live old morph** -- the same, ``--samples off`` (one picture per viseme, morphed);
* **live samples, aligned phones** -- the alignment's phones pushed one by one and each
  frame taken as soon as the data reaches 200 ms past it: the selection's own look-ahead
  loss, without the phone loop's errors.

**lip r**: Pearson's r of the inner-lip opening tracked (face mesh) in the rendered frames
against the real clip's, mean over sentences (frames as rendered, not encoded).

**cost**: the same audio sessions run side by side, samples on and off, OpenCV on one
thread, CPU time of this thread (``time.thread_time``): per frame, the audio's processing
(recogniser, sequencer and, with samples, the selection) and the frame's render; the
selection alone per window (one dynamic programme over the frames from the one being fixed
to the end of the audio heard) and per frame.
"""

from __future__ import annotations

import time
import warnings
from typing import Dict, List

import numpy as np

from . import FIGURES, Context
from . import grid

#: The renderings compared, in the order printed.
METHODS = ("offline samples", "live samples", "live samples, no audio target", "live old morph",
           "live samples, aligned phones")
#: The judged sentences: held_out()[:18] (lipsync.bench.samples.TUNED_FROM: the rest tuned the selection).
JUDGED = 18


def _pcm(clip: str) -> np.ndarray:
    from ..speech.audio import load_audio

    return load_audio(str(grid.video(clip)))


def _offline(bank, clip: str, fps: float) -> List[np.ndarray]:
    from ..pipeline.animator import Animator

    anim = Animator(bank, grid.alignment_of(clip).phones, fps=fps, samples="on", plate_start=0.0)
    return [anim.frame(i).copy() for i in range(len(anim))]


def _live_clip(bank, pcm, fps: float, samples: str, audio_target: bool = True) -> List[np.ndarray]:
    from ..live import samples as LS
    from ..pipeline.liveclip import LiveClip

    keep = LS.LIVE_AUDIO_SHARE
    LS.LIVE_AUDIO_SHARE = keep if audio_target else 0.0
    try:
        anim = LiveClip(bank, pcm, fps=fps, samples=samples)
        return [anim.frame(i).copy() for i in range(len(anim))]
    finally:
        LS.LIVE_AUDIO_SHARE = keep


def _live_aligned(bank, clip: str, fps: float, lag: float) -> List[np.ndarray]:
    """The alignment's phones pushed one by one, each frame rendered when the data reaches ``lag`` past it."""
    from ..live import LiveAnimator

    tl = grid.alignment_of(clip).phones
    live = LiveAnimator(bank, fps=fps, prepare=False, samples="on")
    n_total = int(np.ceil(max(tl.duration, len(grid.track(clip)) / fps) * fps - 1e-9))
    out, n = [], 0
    for seg in tl.segments:
        live.push(float(seg.start), float(seg.end), str(seg.label), kind="phoneme")
        while n < n_total and n / fps + lag <= seg.end + 1e-9:
            out.append(live.frame(n).copy())
            n += 1
    out.extend(live.frame(k).copy() for k in range(n, n_total))
    return out


def _session_cost(bank, pcm, fps: float, samples: str, audio_target: bool = True) -> Dict[str, float]:
    """CPU ms per frame of a live audio session: audio processing, render; the selection's windows."""
    from ..live import samples as LS

    keep = LS.LIVE_AUDIO_SHARE
    LS.LIVE_AUDIO_SHARE = keep if audio_target else 0.0
    try:
        return _session_run(bank, pcm, fps, samples)
    finally:
        LS.LIVE_AUDIO_SHARE = keep


def _session_run(bank, pcm, fps: float, samples: str) -> Dict[str, object]:
    """One audio session fed in blocks, each frame rendered when due: CPU seconds (this
    thread) of feeding and of rendering, its frames and, with samples, its selection's
    windows, seconds and fixed path."""
    from ..live import LiveAnimator
    from ..live.audio import BLOCK, RATE

    live = LiveAnimator(bank, fps=fps, prepare=False, samples=samples)
    feed = render = 0.0
    frames = 0
    clock = time.thread_time
    if live.samples is not None:
        live.samples.selection.clock = clock     # the selection's share of the same CPU time
    for i in range(0, len(pcm), BLOCK):
        t0 = clock()
        due = live.feed_audio(pcm[i:i + BLOCK], RATE)
        feed += clock() - t0
        for n in due:
            t0 = clock()
            live.frame(n)
            render += clock() - t0
            frames += 1
    got = {"frames": frames, "feed": feed, "render": render}
    if live.samples is not None:
        sel = live.samples.selection
        got.update(windows=sel.windows, select=sel.seconds, window_frames=sel.window_frames, path=list(sel.path))
    return got


def live_samples_figures(ctx: Context, rows: List[dict]) -> None:
    import cv2

    from .._data import default_bank_dir
    from ..banks.bank import Bank
    from ..face import measure as M
    from ..face.landmarks import FaceMesh
    from ..face.track import track_frames
    from ..live import AUDIO_LOOKAHEAD_S

    bank_path = default_bank_dir().parent / "grid-s1"
    if len(grid.held_out()) < JUDGED or not (bank_path / "samples.npz").is_file():
        rows.append({"figure": "live_samples", "case": f"skipped: GRID's clips are not in {grid.grid_dir()}"})
        return
    bank = Bank.load(bank_path)
    mesh = FaceMesh()
    clips = grid.held_out()[:JUDGED][: 6 if ctx.quick else JUDGED]
    r: Dict[str, List[float]] = {m: [] for m in METHODS}
    cost = {"on": [], "on, no audio target": [], "off": []}
    threads = cv2.getNumThreads()
    for clip in clips:
        fps = grid.track(clip).fps
        real = grid.real_measures(clip)["opening"]
        pcm = _pcm(clip)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            made = {"offline samples": _offline(bank, clip, fps),
                    "live samples": _live_clip(bank, pcm, fps, "on"),
                    "live samples, no audio target": _live_clip(bank, pcm, fps, "on", audio_target=False),
                    "live old morph": _live_clip(bank, pcm, fps, "off"),
                    "live samples, aligned phones": _live_aligned(bank, clip, fps, AUDIO_LOOKAHEAD_S)}
        for m, frames in made.items():
            n = min(len(frames), len(real))
            tr = track_frames(frames[:n], fps=fps, mesh=mesh)
            r[m].append(grid.correlation(M.lip_opening(tr.points), real[:n]))
        cv2.setNumThreads(1)
        try:
            for opt in cost:          # side by side, the same audio
                cost[opt].append(_session_cost(bank, pcm, fps, opt.split(",")[0], audio_target="no audio" not in opt))
        finally:
            cv2.setNumThreads(threads)
    for m in METHODS:
        rows.append({"figure": "live_samples", "case": m, "sentences": len(clips),
                     "lip_r_mean": round(float(np.mean(r[m])), 3), "lip_r_median": round(float(np.median(r[m])), 3)})
    rows.append({"figure": "live_samples", "case": "live samples: audio target - phones' target alone",
                 "lip_r_mean": round(float(np.mean(r["live samples"]) - np.mean(r["live samples, no audio target"])), 3)})
    rows.append({"figure": "live_samples", "case": "gap offline - live samples",
                 "lip_r_mean": round(float(np.mean(r["offline samples"]) - np.mean(r["live samples"])), 3)})
    _cost_rows(cost, rows)


def _cost_rows(cost, rows: List[dict]) -> None:
    per = {}
    for opt, runs in cost.items():
        frames = sum(c["frames"] for c in runs)
        per[opt] = {k: 1000 * sum(c[k] for c in runs) / frames for k in ("feed", "render")}
        per[opt]["total"] = per[opt]["feed"] + per[opt]["render"]
        rows.append({"figure": "live_samples", "case": f"CPU per frame, samples {opt}", "frames": frames,
                     "audio_ms": round(per[opt]["feed"], 2), "render_ms": round(per[opt]["render"], 2),
                     "total_ms": round(per[opt]["total"], 2)})
    for opt in ("on", "on, no audio target"):
        on = cost[opt]
        windows = sum(c["windows"] for c in on)
        rows.append({"figure": "live_samples", "case": "selection" + ("" if opt == "on" else ", no audio target"),
                     "windows": windows,
                     "ms_per_window": round(1000 * sum(c["select"] for c in on) / windows, 2),
                     "frames_per_window": round(sum(c["window_frames"] for c in on) / windows, 1),
                     "ms_per_frame": round(1000 * sum(c["select"] for c in on) / sum(c["frames"] for c in on), 2)})
    rows.append({"figure": "live_samples", "case": "ratio samples on / off",
                 "render": round(per["on"]["render"] / per["off"]["render"], 2),
                 "total": round(per["on"]["total"] / per["off"]["total"], 2)})
    rows.append({"figure": "live_samples", "case": "ratio audio target on / off (samples on)",
                 "audio": round(per["on"]["feed"] / per["on, no audio target"]["feed"], 2),
                 "total": round(per["on"]["total"] / per["on, no audio target"]["total"], 2)})


FIGURES.register("live_samples", live_samples_figures)
