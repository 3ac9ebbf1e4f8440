"""What a long live session with mouth samples costs (``live_samples_cost``), each fix
measured before and after side by side in one run.

Bank: ``visemes/grid-s1``. Audio: the first held-out GRID s1 sentences
(:func:`~lipsync.bench.grid.held_out`; 2 with ``--quick``), each fed in 20 ms chunks as
``lipsync serve`` does, every frame rendered when it falls due.

* **selection medians**: the CPU per frame of the same sessions (OpenCV on one thread,
  ``time.thread_time``: the audio's processing with the selection, and the render) with
  each look-ahead window's target recomputing the samples' per-phone medians (before:
  :data:`lipsync.selection.select.MEMO_MEDIANS` off) and taking them from the per-bank
  memo (after), and without samples (the viseme morph, for reference); the two with
  samples run alternately, and their fixed sample paths must be equal.
* **far jump**: the plate's plan (:class:`~lipsync.composite.plate_time.PlateTimeline`)
  asked for the frame 24 h in; before, with restarts off, only 10 minutes in (24 h would
  take minutes: the plan grows to every step on the way), after a restart at the jump
  (:data:`~lipsync.composite.plate_time.RESTART_S`): steps planned and CPU ms.
* **audio feature rows**: the bytes of rows a session's
  :class:`~lipsync.speech.features.RunningFeatures` holds after 10 minutes of audio fed
  in 20 ms blocks, without trimming (before) and trimmed to what the windows read (after).
"""

from __future__ import annotations

import time
import warnings
from typing import Dict, List

import numpy as np

from . import FIGURES, Context
from . import grid


def _session(bank, pcm, fps: float, memo: bool, samples: str = "on") -> Dict[str, object]:
    """One audio session: CPU seconds (this thread) of feeding and of rendering, its frames,
    its selection's seconds and its fixed path (``samples="off"``: the viseme morph, none)."""
    from ..selection import select as S
    from .live_samples import _session_run

    keep = S.MEMO_MEDIANS
    S.MEMO_MEDIANS = memo
    try:
        got = _session_run(bank, pcm, fps, samples)
        got.setdefault("select", 0.0)
        got.setdefault("path", [])
        return got
    finally:
        S.MEMO_MEDIANS = keep


def _medians_rows(bank, clips, repeat: int, rows: List[dict]) -> None:
    from ..speech.audio import load_audio

    got = {False: [], True: [], None: []}
    same = True
    for clip in clips:
        pcm = load_audio(str(grid.video(clip)))
        fps = grid.track(clip).fps
        for r in range(repeat):
            order = (False, True, None) if r % 2 == 0 else (True, False, None)   # alternate: neither first always
            runs = {m: _session(bank, pcm, fps, bool(m), "off" if m is None else "on") for m in order}
            same &= runs[False]["path"] == runs[True]["path"]
            for m in order:
                got[m].append(runs[m])
    for m, name in ((None, "reference: samples off (viseme morph)"), (False, "before: medians recomputed per window"),
                    (True, "after: medians memoised per bank")):
        frames = sum(c["frames"] for c in got[m])
        rows.append({"figure": "live_samples_cost", "case": name, "frames": frames,
                     "select_ms": round(1000 * sum(c["select"] for c in got[m]) / frames, 2),
                     "audio_ms": round(1000 * sum(c["feed"] for c in got[m]) / frames, 2),
                     "render_ms": round(1000 * sum(c["render"] for c in got[m]) / frames, 2),
                     "total_ms": round(1000 * sum(c["feed"] + c["render"] for c in got[m]) / frames, 2)})
    off, before, after = rows[-3], rows[-2], rows[-1]
    rows.append({"figure": "live_samples_cost", "case": "ratio after / before",
                 "select_ms": round(after["select_ms"] / before["select_ms"], 2),
                 "total_ms": round(after["total_ms"] / before["total_ms"], 2),
                 "same_paths": bool(same)})
    on_off = (before["total_ms"] / off["total_ms"], after["total_ms"] / off["total_ms"])
    rows.append({"figure": "live_samples_cost", "case": "samples on over off, before -> after",
                 "total_ms": f"{on_off[0]:.2f} -> {on_off[1]:.2f}"})


def _jump_rows(bank, rows: List[dict]) -> None:
    """The plate frame at a far step of a session's clock: before (no restart) 10 minutes
    in, after (restarting) 24 h in; and a near step after each (the next frame)."""
    from ..composite.plate_time import PlateTimeline
    from ..live.pool import shared_plate

    plate = shared_plate(bank)
    times = plate.times
    clock = time.thread_time
    for name, restart, seconds in (("before: no restart, jump 10 min", False, 600.0),
                                   ("after: restart, jump 24 h", True, 86400.0)):
        line = PlateTimeline(times, start=0.37)
        if restart:
            line.restarting()
        line.frame(3)
        k = int(round(seconds * plate.fps))
        t0 = clock()
        line.frame(k)
        far = clock() - t0
        t0 = clock()
        line.frame(k + 1)
        near = clock() - t0
        rows.append({"figure": "live_samples_cost", "case": f"plate plan, {name}", "steps_planned": line.planned,
                     "jump_ms": round(1000 * far, 2), "next_frame_ms": round(1000 * near, 3)})


def _feature_rows(seconds: float, rows: List[dict]) -> None:
    """``seconds`` of speech-like audio fed in 20 ms blocks to the session's running
    features, rows never dropped (before) and dropped as a session drops them (after)."""
    from ..live import samples as LS
    from ..live.audio import BLOCK, RATE
    from ..speech.features import RunningFeatures

    rng = np.random.default_rng(0)
    t = np.arange(int(seconds * RATE)) / RATE
    pcm = (3000 * (0.5 + 0.5 * np.sin(2 * np.pi * 3.0 * t) ** 2) * (np.sin(2 * np.pi * 140 * t)
                                                                   + 0.3 * rng.standard_normal(len(t)))).astype(np.int16)
    fps = 25.0
    behind = int(round(LS.FEATURES_BEHIND_S * fps)) + 8    # a window reads from ~CONTEXT_S + context behind the audio
    for name, drop in (("before: rows kept", False), ("after: rows dropped", True)):
        run = RunningFeatures(RATE, fps)
        t0 = time.thread_time()
        for i in range(0, len(pcm), BLOCK):
            run.add(pcm[i:i + BLOCK])
            if drop:
                run.forget(len(run) - int(round(1.0 * fps)) - behind)
        cpu = time.thread_time() - t0
        mb = run._rows.nbytes / 1e6
        rows.append({"figure": "live_samples_cost", "case": f"audio feature rows, {name}", "audio_s": seconds,
                     "rows_held": run.held, "rows_mb": round(mb, 2),
                     "mb_per_hour": round(mb * 3600 / seconds, 1) if not drop else "bounded",
                     "cpu_ms_per_block": round(1000 * cpu / (len(pcm) // BLOCK), 3)})


def live_samples_cost_figures(ctx: Context, rows: List[dict]) -> None:
    import cv2

    from .._data import default_bank_dir
    from ..banks.bank import Bank

    bank_path = default_bank_dir().parent / "grid-s1"
    if not grid.held_out() or not (bank_path / "samples.npz").is_file():
        rows.append({"figure": "live_samples_cost", "case": f"skipped: GRID's clips are not in {grid.grid_dir()}"})
        return
    bank = Bank.load(bank_path)
    clips = grid.held_out()[: 2 if ctx.quick else 4]
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _session(bank, np.zeros(16000, np.int16), 25.0, True)   # warm-up: the bank's samples loaded once
            _medians_rows(bank, clips, 1 if ctx.quick else 2, rows)
            _jump_rows(bank, rows)
            _feature_rows(120.0 if ctx.quick else 600.0, rows)
    finally:
        cv2.setNumThreads(threads)


FIGURES.register("live_samples_cost", live_samples_cost_figures)
