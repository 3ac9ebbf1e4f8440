"""Living renders and dubs (``dub``): a bank's idle plate and ``lipsync dub``, on GRID speaker s1.

A bank is made from GRID's bank sentences (:data:`lipsync.bench.grid.BANK_CLIPS`; three in
``--quick``); the held-out sentences are taken in pairs (A, B):

* **render** — B's sound and transcript rendered with the bank, on its idle plate
  (:mod:`lipsync.composite.plate`), as ``lipsync render B.wav --text ...`` does;
* **dub** — A's video re-voiced with B's sound and transcript (:func:`lipsync.dub`, the same
  bank), as ``lipsync dub A.mpg --audio B.wav --text ... --bank BANK`` does;
* **real** — B's own frames.

Measured on each (the face mesh tracked through the decoded frames):

* **pops**: the 99th percentile over frames of the mean absolute grey change above the
  nose between consecutive frames (:func:`lipsync.bench.grid.above_nose_pops`, over the
  face's columns: :func:`face_pops`), mean over the pairs; the issue asks render and dub
  for at most twice the real clips' (B's for a render, A's, the plate, for a dub);
* **lips r**: correlation of the inner-lip opening with B's real lips, frame by frame;
* **kept** (dub): the mean absolute grey difference of the dub's frames from A's own frames
  above the nose and in the eye region (both eyes with their brows, the box of those mesh
  points grown by a fifth of the eye distance), mean and worst frame.

Cost, one core (``time.thread_time``, this thread's CPU), per frame, side by side in one
run, at 360×288 and at 1280×720 (the clips scaled by the ``face`` figure's helper; bank
and plate made from those): **today's frame** (the bank's still pictures morphed,
``still=True``), **render on the plate** (the morph plus the plate frame and the lower face
warped onto it), **dub** (the morph plus the lower face warped onto a decoded video frame;
decoding per frame alongside), with each stage's share.

Wall time of ``lipsync dub`` of 30 s of video (ten held-out sentences joined) with another
30 s of speech, no ``--bank`` (the bank made from the video itself), a fresh cache, as a
child process (start-up included), on all cores; then again with the cache warm.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import time
import warnings
from pathlib import Path
from typing import Dict, List

import numpy as np

from . import FIGURES, Context
from . import grid


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _make_bank(out: Path, videos: List[Path], texts: Dict[Path, str]):
    from ..videobank import make_bank

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return make_bank(out, videos, texts=texts, force=True, quiet=True)


def _lips(frames, fps: float, mesh):
    from ..face import measure as M
    from ..face.track import track_frames

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tr = track_frames(frames, fps=fps, mesh=mesh)
    return M.lip_opening(tr.points), tr.points


def eye_box(points: np.ndarray, shape) -> tuple:
    """``(y0, y1, x0, x1)``: both eyes with their brows (mesh points of a track, median
    over frames), grown by a fifth of the eye distance."""
    from ..face import topology as T
    from ..face.measure import eye_distance

    p = np.nanmedian(np.asarray(points, np.float64)[..., :2], axis=0)
    idx = list(T.EYE_UPPER_L + T.EYE_LOWER_L + T.BROW_L + T.EYE_UPPER_R + T.EYE_LOWER_R + T.BROW_R)
    g = 0.2 * float(eye_distance(p))
    h, w = shape[:2]
    y0, x0 = np.floor(p[idx].min(axis=0)[::-1] - g).astype(int)
    y1, x1 = np.ceil(p[idx].max(axis=0)[::-1] + g).astype(int)
    return max(0, y0), min(h, y1), max(0, x0), min(w, x1)


def face_pops(frames, points) -> float:
    """:func:`lipsync.bench.grid.above_nose_pops` over the face's own columns (between the
    face outline's ear-level points, the median over the track): frames framed differently
    (the bank's crop, the whole video picture) then compare over the same part of the
    face; over whole rows, a wide background would dilute a clip's changes and a tight
    crop concentrate them."""
    from ..face import topology as T

    p = np.nanmedian(np.asarray(points, np.float64)[..., :2], axis=0)
    w = frames[0].shape[1]
    x0 = max(0, int(np.floor(p[T.JAW_L[0], 0])))
    x1 = min(w, int(np.ceil(p[T.JAW_R[0], 0])) + 1)
    return grid.above_nose_pops([f[:, x0:x1] for f in frames], points)


def kept(out_frames, src_frames, rows: int, box: tuple) -> Dict[str, float]:
    """Mean absolute grey difference of ``out_frames`` from ``src_frames`` (frame i against
    frame i) above the nose (``rows``) and in the eye ``box``: mean over frames and worst frame."""
    import cv2

    y0, y1, x0, x1 = box
    above, eyes = [], []
    for a, b in zip(out_frames, src_frames):
        ga = cv2.cvtColor(np.ascontiguousarray(a), cv2.COLOR_RGB2GRAY).astype(np.int16)
        gb = cv2.cvtColor(np.ascontiguousarray(b), cv2.COLOR_RGB2GRAY).astype(np.int16)
        d = np.abs(ga - gb)
        above.append(float(d[:rows].mean()))
        eyes.append(float(d[y0:y1, x0:x1].mean()))
    return {"above_nose_mean": float(np.mean(above)), "above_nose_worst": float(np.max(above)),
            "eyes_mean": float(np.mean(eyes)), "eyes_worst": float(np.max(eyes))}


def _quality(ctx: Context, bank_path: Path, rows: List[dict]) -> None:
    from ..pipeline.animator import Animator
    from ..banks.bank import Bank
    from ..pipeline.dubbing import dub
    from ..face.landmarks import FaceMesh
    from ..face.video import read_video

    pairs = grid.held_out()
    pairs = list(zip(pairs[0::2], pairs[1::2]))[: 3 if ctx.quick else 10]
    mesh = FaceMesh()
    bank = Bank.load(bank_path)
    got = {k: [] for k in ("render_r", "dub_r", "render_pops", "dub_pops", "real_pops", "real_a_pops", "above_mean",
                           "above_worst", "eyes_mean", "eyes_worst")}
    for a, b in pairs:
        real_b = list(read_video(grid.video(b)))
        fps = grid.track(b).fps
        real_open = grid.real_measures(b)["opening"]
        got["real_pops"].append(face_pops(real_b, grid.track(b).points))
        # render: B's speech on the bank's plate
        anim = Animator(bank, grid.alignment_of(b).phones, fps=fps)
        n = min(len(anim), len(real_b))
        rendered = [anim.frame(i) for i in range(n)]
        opening, pts = _lips(rendered, fps, mesh)
        got["render_r"].append(grid.correlation(opening[:n], real_open[:n]))
        got["render_pops"].append(face_pops(rendered, pts))
        # dub: A's video, B's speech
        out = ctx.tmp / f"dub-{a}-{b}.mp4"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            dub(grid.video(a), grid.video(b), out, text=grid.transcript(b), bank=bank, quiet=True,
                cache=ctx.tmp / "dub-cache")
        dubbed = list(read_video(out))
        opening, pts = _lips(dubbed, fps, mesh)
        n = min(len(dubbed), len(real_open))
        got["dub_r"].append(grid.correlation(opening[:n], real_open[:n]))
        got["dub_pops"].append(face_pops(dubbed, pts))
        src = list(read_video(grid.video(a)))
        src_pts = grid.track(a).points
        got["real_a_pops"].append(face_pops(src, src_pts))
        k = kept(dubbed, src, grid.above_nose_rows(src_pts), eye_box(src_pts, src[0].shape))
        for key in ("above_nose_mean", "above_nose_worst", "eyes_mean", "eyes_worst"):
            got[key.replace("above_nose", "above")].append(k[key])
    for what in ("render", "dub"):
        # the real clips the output is compared with: B's frames for a render; for a dub,
        # A's (its plate) -- the dub's frames above the nose are A's
        real = float(np.mean(got["real_pops" if what == "render" else "real_a_pops"]))
        pops = float(np.mean(got[f"{what}_pops"]))
        row = {"figure": "dub", "case": f"{what}: {len(pairs)} held-out sentence pairs, bank of "
                                        f"{3 if ctx.quick else 10} GRID sentences",
               "lips_r_mean": round(float(np.nanmean(got[f"{what}_r"])), 3),
               "lips_r_min": round(float(np.nanmin(got[f"{what}_r"])), 3),
               "pops_p99": round(pops, 2), "real_pops_p99": round(real, 2), "pops_over_real": round(pops / real, 2)}
        if what == "dub":
            row.update({"above_nose_diff_mean": round(float(np.mean(got["above_mean"])), 2),
                        "above_nose_diff_worst_frame": round(float(np.max(got["above_worst"])), 2),
                        "eyes_diff_mean": round(float(np.mean(got["eyes_mean"])), 2),
                        "eyes_diff_worst_frame": round(float(np.max(got["eyes_worst"])), 2)})
        rows.append(row)


def cost_per_frame(bank_path: Path, video: Path, speech: Path, text: str, repeat: int = 3) -> Dict[str, float]:
    """CPU ms per frame (one thread) of today's frame, render on the plate and a dub frame,
    and the stages of each, for ``speech`` rendered with ``bank_path`` and dubbed onto ``video``."""
    from ..pipeline.animator import Animator
    from ..banks.bank import Bank
    from ..pipeline.dubbing import bank_face, colour_table, plate_poses, video_track
    from ..composite.plate import PlateCompositor
    from ..face.video import probe_video, read_video
    from ..speech.align import align

    bank = Bank.load(bank_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        phones = align(str(speech), text).phones
    still = Animator(bank, phones, still=True)
    live = Animator(bank, phones)
    for a in (still, live):
        a.renderer.frame_threads = 1
    n = len(still)
    buf = np.empty(still.renderer.shape + (3,), np.uint8)
    mouth = np.empty_like(buf)

    def per_frame(fn) -> float:
        best = None
        for _ in range(repeat + 1):  # the first pass warms the flows up
            t = time.thread_time()
            for i in range(n):
                fn(i)
            ms = (time.thread_time() - t) * 1e3 / n
            best = ms if best is None else min(best, ms)
        return best

    specs = still.specs
    out = {"frames": n}
    out["today_ms"] = per_frame(lambda i: still.frame(i, out=buf))
    out["render_plate_ms"] = per_frame(lambda i: live.frame(i, out=buf))
    plate = live.plate
    out["plate_copy_ms"] = per_frame(lambda i: np.copyto(buf, plate.frames[plate.index(i, live.fps)]))
    still.frame(0, out=mouth)
    out["plate_composite_ms"] = per_frame(
        lambda i: plate.compositor.apply_prepared(mouth, buf, plate._prepared[plate.index(i, live.fps)]))

    # dub: the lower face onto the video's own frames (decoded beforehand; decoding timed apart)
    info = probe_video(video)
    t = time.thread_time()
    frames = [f.copy() for f in read_video(video)]
    out["decode_ms"] = (time.thread_time() - t) * 1e3 / len(frames)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        track = video_track(video, info, entry=None, quiet=True)
    mask, bank_mesh = bank_face(bank)
    poses = plate_poses(bank_mesh, track)
    comp = PlateCompositor(mask, lut=colour_table(bank, video, track, poses, bank_mesh, mask))
    big = np.empty_like(frames[0])
    nv = len(frames)
    geometry = [comp.geometry(p, big.shape) for p in poses]

    def dub_frame(i):
        j = i % nv
        np.copyto(big, frames[j])
        s = specs[i]
        still.renderer.render(s.from_viseme, s.to_viseme, s.alpha, out=mouth, region=comp.region)
        comp.apply(mouth, big, poses[j], geometry[j])

    out["dub_ms"] = per_frame(dub_frame)
    out["dub_copy_ms"] = per_frame(lambda i: np.copyto(big, frames[i % nv]))
    out["dub_composite_ms"] = per_frame(lambda i: comp.apply(mouth, big, poses[i % nv], geometry[i % nv]))
    out["bank"] = "x".join(map(str, bank.shape[::-1]))
    out["video"] = "x".join(map(str, info.size))
    return out


def _cost_rows(ctx: Context, bank_path: Path, label: str, video: Path, speech: Path, text: str,
               rows: List[dict]) -> None:
    c = cost_per_frame(bank_path, video, speech, text, repeat=1 if ctx.quick else 3)
    today = c["today_ms"]
    rows.append({"figure": "dub", "case": f"cost per frame, {label} (bank {c['bank']}, video {c['video']}), one core",
                 "today_ms": round(today, 3),
                 "render_plate_ms": round(c["render_plate_ms"], 3),
                 "render_plate_over_today": round(c["render_plate_ms"] / today, 2),
                 "dub_ms": round(c["dub_ms"], 3), "dub_over_today": round(c["dub_ms"] / today, 2),
                 "stages_ms": (f"morph {today:.3f}; plate: copy {c['plate_copy_ms']:.3f} + lower face "
                               f"{c['plate_composite_ms']:.3f}; dub: frame copy {c['dub_copy_ms']:.3f} + lower face "
                               f"{c['dub_composite_ms']:.3f}; decode {c['decode_ms']:.3f}")})


def joined(names: List[str], out: Path) -> Path:
    """The clips ``names`` joined into one video with sound (ffmpeg's concat filter)."""
    import imageio_ffmpeg

    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-y"]
    for n in names:
        cmd += ["-i", str(grid.video(n))]
    streams = "".join(f"[{i}:v][{i}:a]" for i in range(len(names)))
    cmd += ["-filter_complex", f"{streams}concat=n={len(names)}:v=1:a=1[v][a]", "-map", "[v]", "-map", "[a]",
            "-c:v", "libx264", "-crf", "16", "-preset", "veryfast", "-c:a", "aac", str(out)]
    subprocess.run(cmd, check=True)
    return out


def _wall_30s(ctx: Context, rows: List[dict]) -> None:
    held = grid.held_out()
    if len(held) < 20:
        rows.append({"figure": "dub", "case": f"30 s dub skipped: {len(held)} held-out clips in {grid.grid_dir()}"})
        return
    video = joined(held[:10], ctx.tmp / "video-30s.mp4")
    speech = joined(held[10:20], ctx.tmp / "speech-30s.mp4")
    (ctx.tmp / "video-30s.txt").write_text(" ".join(grid.transcript(n) for n in held[:10]) + "\n")
    text = " ".join(grid.transcript(n) for n in held[10:20])
    cache = ctx.tmp / "dub-30s-cache"
    for run in ("fresh cache", "cache warm"):
        cmd = [sys.executable, "-m", "lipsync", "dub", str(video), "--audio", str(speech), "--text", text,
               "-o", str(ctx.tmp / "dub-30s.mp4"), "--quiet", "--cache", str(cache)]
        c0, t0 = _children_cpu(), time.perf_counter()
        subprocess.run(cmd, check=True, stderr=subprocess.DEVNULL)
        wall, cpu = time.perf_counter() - t0, _children_cpu() - c0
        rows.append({"figure": "dub", "case": f"lipsync dub, 30 s of 360x288 video + 30 s of speech, {run}"
                                              f"{' (bank made from the video)' if run == 'fresh cache' else ''}",
                     "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "cores": os.cpu_count(),
                     "real_time_x": round(30.0 / wall, 2)})


@FIGURES.decorator("dub")
def dub_figures(ctx: Context, rows: List[dict]) -> None:
    from .face import _upscaled
    from .videobank import _with_sound

    names = [c for c in grid.BANK_CLIPS if grid.video(c).is_file()]
    if len(names) < len(grid.BANK_CLIPS) or len(grid.held_out()) < 6:
        rows.append({"figure": "dub", "case": f"skipped: GRID's clips are not in {grid.grid_dir()}"})
        return
    names = names[:3] if ctx.quick else names
    videos = [grid.video(c) for c in names]
    texts = {v: grid.transcript(c) for v, c in zip(videos, names)}
    bank = _make_bank(ctx.tmp / "dub-bank", videos, texts).path
    _quality(ctx, bank, rows)

    a, b = grid.held_out()[:2]
    _cost_rows(ctx, bank, "360x288", grid.video(a), grid.video(b), grid.transcript(b), rows)
    big = _with_sound(videos[:3], ctx.tmp)
    bank720 = _make_bank(ctx.tmp / "dub-bank-720p", big, {p: texts[v] for p, v in zip(big, videos)}).path
    held720 = _upscaled([grid.video(a)], ctx.tmp)[0]
    _cost_rows(ctx, bank720, "1280x720", held720, grid.video(b), grid.transcript(b), rows)
    _wall_30s(ctx, rows)
