"""Plate time (``plate_time``): clips that do not blink in unison, long output that does not
loop, and an idle plate that moves as the speaker does (lipsync.composite.plate_time).

* **series**: two held-out GRID sentences rendered from their sound and transcripts with the
  shipped grid-s1 bank, each at its default plate start (derived from its timeline), and
  again both at ``--plate-start 0`` (what every render did before): the mean absolute grey
  difference of their frames above the nose (frame i against frame i, over the shorter),
  and the share of frames identical there (difference below 0.5 grey levels: the codec's
  own noise between two encodings of one frame is smaller).
* **long dub**: a 3 s GRID clip dubbed with 20 s of speech (seven other sentences' sound
  joined), as ``lipsync dub`` does it; blinks found **on the output's decoded frames** by the
  face mesh's eye opening (:func:`lipsync.face.measure.eye_opening` below
  :data:`~lipsync.composite.plate_time.BLINK_BELOW` of the median, runs of frames), and each
  blink's source found **by the pixels**: the input frame whose eye region is nearest the
  output's at the blink's deepest frame; a *copy* is two output blinks from one input blink
  (their sources within 3 frames); reported: blinks, copies closer than 4 s, the shortest gap
  between copies. Beside it the same count for ping-pong (the frame order every dub used
  before), over the same frames.
* **plate motion**: the mean absolute grey step between consecutive frames above the nose,
  over the face's columns (:func:`face_steps`), of grid-s1's idle plate (``plate.mp4``)
  against the real speaker's (the bank's source clips, :data:`lipsync.bench.grid.BANK_CLIPS`,
  at their own size), of the plate as a 20 s render plays it, and of the plate today's
  chooser makes from the same clips.
"""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path
from typing import List

import numpy as np

from . import FIGURES, Context
from . import grid

#: The two sentences rendered (held out) and the clip dubbed for 20 s, with its speech.
SERIES = ("bgbb3a", "lgbm4p")
LONG_CLIP, LONG_SPEECH = "bbwm5s", ("prap6p", "lwae8n", "bbbs6p", "bram2n", "brif7a", "brwt4n", "bwwb1a")
#: Two output blinks whose deepest frames come from input frames this close are one blink shown twice.
SAME_BLINK_FRAMES = 3


def _grey(f) -> np.ndarray:
    import cv2

    return cv2.cvtColor(np.ascontiguousarray(f[..., :3]), cv2.COLOR_RGB2GRAY).astype(np.float32)


def _frames(path: Path) -> List[np.ndarray]:
    from ..face.video import read_video

    return list(read_video(path))


def _render(name: str, out: Path, start=None) -> int:
    cmd = [sys.executable, "-m", "lipsync", "render", str(grid.video(name)), "--text", grid.transcript(name),
           "--bank", "grid-s1", "-o", str(out), "-q"]
    if start is not None:
        cmd += ["--plate-start", str(start)]
    return subprocess.run(cmd, capture_output=True, text=True).returncode


def _series(ctx: Context, rows: List[dict]) -> None:
    from ..face.track import track_frames

    for label, start in (("default plate start", None), ("--plate-start 0 (before)", 0)):
        outs = [ctx.tmp / f"{n}-{start}.mp4" for n in SERIES]
        codes = [_render(n, o, start) for n, o in zip(SERIES, outs)]
        a, b = (_frames(o) for o in outs)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rows_above = grid.above_nose_rows(track_frames(a[:10], fps=25.0).points)
        d = np.array([np.abs(_grey(x)[:rows_above] - _grey(y)[:rows_above]).mean() for x, y in zip(a, b)])
        rows.append({"figure": "plate_time_series", "renders": f"{SERIES[0]} vs {SERIES[1]}, {label}",
                     "exit": max(codes), "frames": len(d), "above-nose diff (mean)": round(float(d.mean()), 2),
                     "identical frames %": round(100 * float(np.mean(d < 0.5)), 1)})


def output_blinks(frames) -> tuple:
    """``(runs, deepest frame of each, eye box, track)`` of the blinks in ``frames``."""
    from ..composite.plate_time import blink_runs
    from ..face.measure import eye_opening
    from ..face.track import track_frames
    from .dub import eye_box

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tr = track_frames(frames, fps=25.0)
    e = eye_opening(tr.points)
    e[~tr.found] = np.nan
    runs = blink_runs(e)
    deepest = [a + int(np.nanargmin(e[a:b])) for a, b in runs]
    return runs, deepest, eye_box(tr.points, frames[0].shape), tr


def copies(deepest, sources, fps: float = 25.0) -> tuple:
    """``(copies closer than 4 s, shortest gap between copies in s)`` of blinks at output
    frames ``deepest`` whose input frames are ``sources``."""
    close, gaps = 0, []
    for i in range(len(deepest)):
        for j in range(i + 1, len(deepest)):
            if abs(sources[i] - sources[j]) <= SAME_BLINK_FRAMES:
                gap = (deepest[j] - deepest[i]) / fps
                gaps.append(gap)
                close += gap < 4.0
    return close, (round(min(gaps), 2) if gaps else None)


def _long_dub(ctx: Context, rows: List[dict]) -> None:
    from ..composite.plate import pingpong
    from .dub import joined

    speech = joined(list(LONG_SPEECH), ctx.tmp / "speech20.mp4")
    out = ctx.tmp / "long-dub.mp4"
    code = subprocess.run([sys.executable, "-m", "lipsync", "dub", str(grid.video(LONG_CLIP)), "--audio", str(speech),
                           "-o", str(out), "--cache", str(ctx.tmp / "cache-long"), "-q"],
                          capture_output=True, text=True).returncode
    src = _frames(grid.video(LONG_CLIP))
    frames = _frames(out)
    runs, deepest, (y0, y1, x0, x1), _ = output_blinks(frames)
    src_eyes = np.stack([_grey(f)[y0:y1, x0:x1] for f in src])
    sources = [int(np.argmin(np.abs(src_eyes - _grey(frames[k])[y0:y1, x0:x1]).mean(axis=(1, 2)))) for k in deepest]
    close, shortest = copies(deepest, sources)
    in_runs, in_deep, _, _ = output_blinks(src)
    rows.append({"figure": "plate_time_long_dub", "what": f"{LONG_CLIP} (3 s, {len(in_runs)} blinks) dubbed for "
                 f"{len(frames) / 25:.1f} s", "exit": code, "blinks": len(runs), "copies within 4 s": close,
                 "closest copies (s)": shortest})
    # ping-pong over as many frames: the blinks of the input where ping-pong shows them
    pp = [pingpong(i, len(src)) for i in range(len(frames))]
    pp_deep = [k for k in range(1, len(pp)) if pp[k] in in_deep]
    close, shortest = copies(pp_deep, [pp[k] for k in pp_deep])
    rows.append({"figure": "plate_time_long_dub", "what": "ping-pong of the same clip (before)",
                 "blinks": len(pp_deep), "copies within 4 s": close, "closest copies (s)": shortest})


def face_steps(frames, points) -> np.ndarray:
    """:func:`lipsync.bench.grid.above_nose_changes` over the face's own columns (between the
    face outline's ear-level points, median over the track): the background beside the head,
    wide in the video and narrow in the bank's crop, would dilute one and not the other."""
    from ..face import topology as T

    p = np.nanmedian(np.asarray(points, np.float64)[..., :2], axis=0)
    x0, x1 = max(0, int(p[T.JAW_L[0], 0])), int(p[T.JAW_R[0], 0]) + 1
    return grid.above_nose_changes([f[:, x0:x1] for f in frames], points)


def _motion(ctx: Context, rows: List[dict]) -> None:
    from .._data import shipped_banks
    from ..banks.bank import Bank
    from ..face.track import track_frames
    from ..pipeline.animator import Animator
    from ..motion.timeline import Segment, Timeline

    bank = Bank.load(shipped_banks()["grid-s1"])
    plate = _frames(bank.plate.video)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plate_points = track_frames(plate, fps=25.0).points
    steps = face_steps(plate, plate_points)
    real = np.concatenate([face_steps(_frames(grid.video(c)), grid.track(c).points) for c in grid.BANK_CLIPS])
    anim = Animator(bank, Timeline((Segment(0.0, 20.0, "sil"),), kind="phoneme"), fps=25.0)
    order = [anim.plate.index(i, 25.0, anim.plate_line) for i in range(len(anim))]
    played = face_steps([plate[j] for j in order], plate_points[order])
    rows.append({"figure": "plate_time_motion", "which": "grid-s1 as shipped",
                 "speaker (bank clips)": round(float(real.mean()), 2), "plate": round(float(steps.mean()), 2),
                 "plate / speaker": round(float(steps.mean() / real.mean()), 2),
                 "as a 20 s render plays it": round(float(played.mean()), 2)})
    # the same ten clips made into a bank by today's chooser (tools/make_grid_bank.py's input)
    import json

    from ..videobank import make_bank

    videos = [grid.video(c) for c in grid.BANK_CLIPS]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        made = make_bank(ctx.tmp / "grid-remade", videos, texts={v: grid.transcript(v.stem) for v in videos},
                         force=True, quiet=True, flows=False)
    doc = json.loads((made.path / "plate.json").read_text())
    plate = _frames(made.path / "plate.mp4")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        steps = face_steps(plate, track_frames(plate, fps=25.0).points)
    rows.append({"figure": "plate_time_motion", "which": f"remade today ({doc['source']['video']})",
                 "speaker (bank clips)": round(float(real.mean()), 2), "plate": round(float(steps.mean()), 2),
                 "plate / speaker": round(float(steps.mean() / real.mean()), 2),
                 "mesh motion above the nose / footage's": doc["source"].get("motion_above_nose_vs_footage")})


@FIGURES.decorator("plate_time")
def plate_time_figures(ctx: Context, rows: List[dict]) -> None:
    _series(ctx, rows)
    _long_dub(ctx, rows)
    _motion(ctx, rows)
