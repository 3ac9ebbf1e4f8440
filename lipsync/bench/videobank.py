"""Real-speaker figures (``videobank``): a bank made from video, judged against the real speaker.

1. **Speed.** ``lipsync init --video`` (:func:`lipsync.videobank.make_bank`) on GRID's
   :data:`~lipsync.bench.grid.BANK_CLIPS` (10 sentences, 30 s of 360×288 video): wall time
   to a finished bank, flows included, with this process's and its workers' CPU time and
   each step's share; the same clips at 1280×720 (scaled up 2.5× and pillarboxed by the
   ``face`` figure's helper, GRID's sound muxed back in).
2. **Quality** on the 30 held-out sentences (:func:`~lipsync.bench.grid.held_out`), each
   rendered from its own sound and transcript through the real pipeline
   (:meth:`lipsync.Animator.from_audio`: the aligner, the phoneme map, the sequencer, the
   flow renderer) at the video's 25 fps, frame i beside the real frame i:

   * **lip opening over time** (inner-lip gap over eye distance,
     :func:`lipsync.face.measure.lip_opening`) from the face mesh tracked through the rendered
     frames and through the real ones; its correlation with the real speaker's, per clip
     (mean over clips) and pooled over all frames;
   * **mouth-region PSNR and SSIM** after registering each rendered frame onto the real one by
     the still points (:func:`lipsync.face.compare.register`, region
     :func:`~lipsync.face.compare.mouth_box` of the real face).

   Against two baselines from the same bank and the same cues:

   * **hard cuts** — every frame shows one of the bank's pictures: the viseme the morph is
     nearer to (the sequencer's alpha rounded to 0 or 1), so the cut falls in the middle of
     each transition and the sequencer's rules (closures held, short sounds) stay; what
     Rhubarb-style tools show;
   * **still** — the rest picture held for the whole clip (its lip opening is constant, so it
     has no correlation; it is the floor for PSNR).

   And, for the correlation, what the sequencer can reach at best with these cues: the
   same frames with each picture replaced by its viseme's *median* real lip opening over the
   bank clips' candidate frames ("ideal pictures"; nothing rendered).
"""

from __future__ import annotations

import os
import resource
import subprocess
import time
import warnings
from pathlib import Path
from typing import Dict, List

import numpy as np

from . import FIGURES, Context
from . import grid


def _cpu() -> float:
    """CPU seconds of this process and of its finished children (the flow workers)."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def _make(out: Path, videos: List[Path], texts: Dict[Path, str]):
    from ..videobank import make_bank

    t0, c0 = time.perf_counter(), _cpu()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the aligner's and the tracker's notes: counted elsewhere
        result = make_bank(out, videos, texts=texts, force=True, quiet=True)
    return result, time.perf_counter() - t0, _cpu() - c0


def _with_sound(videos: List[Path], tmp: Path) -> List[Path]:
    """The clips at 1280x720 (the face figure's scaling) with their own sound muxed back in."""
    import imageio_ffmpeg

    from .face import _upscaled

    out = []
    for src, silent in zip(videos, _upscaled(videos, tmp)):
        p = tmp / f"{src.stem}.mp4"
        subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-y", "-i", str(silent), "-i", str(src),
                        "-map", "0:v", "-map", "1:a", "-c:v", "copy", "-c:a", "aac", str(p)], check=True)
        out.append(p)
    return out


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.std(a[ok]) < 1e-9 or np.std(b[ok]) < 1e-9:
        return float("nan")
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


#: The compared renderings, in the order printed.
METHODS = ("flow morph", "hard cuts", "still")


def judge_clip(bank, clip: str, mesh=None, *, timing=None, methods=METHODS) -> Dict[str, Dict[str, np.ndarray]]:
    """One held-out sentence rendered three ways, measured against its real frames.

    ``timing`` is the Animator's (default: the bank's); ``methods`` chooses which of
    :data:`METHODS` to render (the coarticulation figure renders each timing model's flow
    morph). The sentence's alignment is :func:`lipsync.bench.grid.alignment_of` (computed
    once per clip, as :meth:`lipsync.Animator.from_audio` would).

    Returns
    -------
    dict
        Method → ``{"open": lip opening per frame, "psnr": ..., "ssim": ...}``; also
        ``"real"`` → ``{"open": ...}`` and ``"specs"``, the sequencer's frames.
    """
    from ..pipeline.animator import Animator
    from ..face import measure as M
    from ..face.compare import mouth_box, psnr, register, ssim
    from ..face.landmarks import FaceMesh
    from ..face.track import track_frames
    from ..face.video import read_video

    mesh = mesh or FaceMesh()
    real = list(read_video(grid.video(clip)))
    real_track = grid.track(clip)
    anim = Animator(bank, grid.alignment_of(clip).phones, fps=real_track.fps, timing=timing)
    n = min(len(anim), len(real))
    makers = {
        "flow morph": lambda: [anim.frame(i) for i in range(n)],
        "hard cuts": lambda: [anim.renderer.render(s.from_viseme, s.to_viseme, float(round(s.alpha))).copy()
                              for s in anim.specs[:n]],
        "still": lambda: [anim.renderer.nb.images[bank.rest]] * n,
    }
    renders = {m: makers[m]() for m in methods}
    out = {"real": {"open": M.lip_opening(real_track.points[:n]),
                    "sharp": mouth_sharpness(real[:n], real_track.points[:n]),
                    "above_nose": grid.above_nose_changes(real[:n], real_track.points[:n])},
           "specs": anim.specs[:n]}
    shape = real[0].shape[:2]
    for method, frames in renders.items():
        tr = track_frames(frames, fps=real_track.fps, mesh=mesh)
        opening = M.lip_opening(tr.points)
        ps, ss = [], []
        for i in range(n):
            if not (tr.found[i] and real_track.found[i]):
                continue
            warped, _, _ = register(frames[i], tr.points[i], real_track.points[i], shape=shape)
            box = mouth_box(real_track.points[i], shape)
            ps.append(psnr(warped, real[i], box))
            ss.append(ssim(warped, real[i], box))
        out[method] = {"open": opening, "psnr": np.array(ps), "ssim": np.array(ss),
                       "sharp": mouth_sharpness(frames, tr.points),
                       "above_nose": grid.above_nose_changes(frames, _nose_rows(bank))}
    return out


def _nose_rows(bank) -> int:
    """Rows of a face bank's pictures above its rest viseme's nose base (its lines)."""
    f = bank.features[bank.rest]
    return int(np.floor(min(f["nose_base_l"].points[:, 1].min(), f["nose_base_r"].points[:, 1].min())))


def mouth_sharpness(frames, points) -> np.ndarray:
    """Per frame: variance of the Laplacian of the luma in the mouth region
    (:func:`lipsync.face.compare.mouth_box`, :func:`lipsync.videobank.select.sharpness`);
    NaN without a face. Compare frames at one scale (a bank from video keeps the video's)."""
    from ..face.compare import mouth_box
    from ..videobank.select import sharpness

    out = np.full(len(frames), np.nan)
    for i, (f, p) in enumerate(zip(frames, points)):
        if np.all(np.isfinite(p)):
            out[i] = sharpness(f[..., :3], mouth_box(p, f.shape[:2]))
    return out


def median_openings(names: List[str], pmap_name: str = "english-to-rhubarb") -> Dict[str, float]:
    """Each viseme's median real lip opening over its candidate frames in the clips ``names``
    (the "ideal pictures": what a bank would show if every picture had the typical opening)."""
    from ..face import measure as M
    from ..phonetics.phonemes import load_map
    from ..speech.align import align
    from ..videobank.select import candidates
    from ..videobank.speech import viseme_spans

    pmap = load_map(pmap_name)
    found: Dict[str, list] = {}
    for c in names:
        tr = grid.track(c)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            spans = viseme_spans(align(grid.video(c), grid.transcript(c)).phones, pmap)
        opening = M.lip_opening(tr.points)
        for cand in candidates(spans, video=0, fps=tr.fps, found=tr.found, rest=pmap.silence):
            found.setdefault(cand.viseme, []).append(float(opening[cand.frame]))
    return {v: float(np.median(x)) for v, x in found.items()}


@FIGURES.decorator("videobank")
def videobank_figures(ctx: Context, rows: List[dict]) -> None:
    from ..banks.bank import Bank
    from ..face.landmarks import FaceMesh

    names = [c for c in grid.BANK_CLIPS if grid.video(c).is_file()]
    if len(names) < len(grid.BANK_CLIPS):
        rows.append({"figure": "videobank", "case": f"skipped: GRID's bank clips are not in {grid.grid_dir()}"})
        return
    videos = [grid.video(c) for c in names]
    texts = {v: grid.transcript(c) for v, c in zip(videos, names)}
    seconds = sum(grid.track(c).times()[-1] + 1 / grid.track(c).fps for c in names)

    result, wall, cpu = _make(ctx.tmp / "grid-s1", videos, texts)
    steps = ", ".join(f"{k} {v:.1f}" for k, v in result.seconds.items())
    rows.append({"figure": "videobank", "case": f"init --video, {len(videos)} clips ({seconds:.0f} s, 360x288)",
                 "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "bank": "x".join(map(str, result.size)),
                 "steps_s": steps, "cores": os.cpu_count()})
    big = _with_sound(videos[:3] if ctx.quick else videos, ctx.tmp)
    r720, wall720, cpu720 = _make(ctx.tmp / "grid-720p", big, {b: texts[v] for b, v in zip(big, videos)})
    rows.append({"figure": "videobank", "case": f"init --video, {len(big)} clips at 1280x720",
                 "wall_s": round(wall720, 1), "cpu_s": round(cpu720, 1), "bank": "x".join(map(str, r720.size)),
                 "steps_s": ", ".join(f"{k} {v:.1f}" for k, v in r720.seconds.items()), "cores": os.cpu_count()})

    bank = Bank.load(result.path)
    clips = grid.held_out()[:6] if ctx.quick else grid.held_out()
    mesh = FaceMesh()
    per = {m: {"corr": [], "psnr": [], "ssim": []} for m in METHODS}
    pooled = {m: [] for m in METHODS + ("real", "ideal")}
    ideal = median_openings(names)
    ideal_corr = []
    for clip in clips:
        got = judge_clip(bank, clip, mesh)
        pooled["real"].append(got["real"]["open"])
        # the same frames with each picture's opening replaced by its viseme's median
        predicted = np.array([(1 - s.alpha) * ideal[s.from_viseme] + s.alpha * ideal[s.to_viseme]
                              for s in got["specs"]])
        ideal_corr.append(_corr(predicted, got["real"]["open"]))
        pooled["ideal"].append(predicted)
        for m in METHODS:
            per[m]["corr"].append(_corr(got[m]["open"], got["real"]["open"]))
            per[m]["psnr"].append(float(np.mean(got[m]["psnr"])))
            per[m]["ssim"].append(float(np.mean(got[m]["ssim"])))
            pooled[m].append(got[m]["open"])
    real_all = np.concatenate(pooled["real"])
    flow_corr, cut_corr = np.array(per["flow morph"]["corr"]), np.array(per["hard cuts"]["corr"])
    flow_psnr, cut_psnr = np.array(per["flow morph"]["psnr"]), np.array(per["hard cuts"]["psnr"])
    for m in METHODS:
        c = np.array(per[m]["corr"])
        row = {"figure": "videobank", "case": f"held out: {m} ({len(clips)} clips)",
               # the still face's opening is one value: no correlation (what the tracker
               # measures on the same picture repeated is its jitter, not a signal)
               "lip_corr_mean": None if m == "still" else round(float(np.nanmean(c)), 3),
               "lip_corr_pooled": None if m == "still" else round(_corr(np.concatenate(pooled[m]), real_all), 3),
               "mouth_psnr_db": round(float(np.mean(per[m]["psnr"])), 2),
               "mouth_ssim": round(float(np.mean(per[m]["ssim"])), 4)}
        if m == "flow morph":
            row["clips_corr_above_cuts"] = f"{int((flow_corr > cut_corr).sum())}/{len(clips)}"
            row["clips_psnr_above_cuts"] = f"{int((flow_psnr > cut_psnr).sum())}/{len(clips)}"
            row["psnr_over_still_db"] = round(float(np.mean(flow_psnr - np.array(per['still']['psnr']))), 2)
        rows.append(row)
    rows.append({"figure": "videobank", "case": "held out: ideal pictures (median real opening per viseme), "
                                                "same sequencer, no rendering",
                 "lip_corr_mean": round(float(np.nanmean(ideal_corr)), 3),
                 "lip_corr_pooled": round(_corr(np.concatenate(pooled["ideal"]), real_all), 3)})


def above_nose_spread(bank) -> float:
    """Mean absolute grey difference above the nose between two of a face bank's pictures,
    averaged over every pair (0: one face; a bank of whole frames from different moments
    differs in hair, eyes, framing and colour)."""
    import itertools

    import cv2

    rows = _nose_rows(bank)
    grey = {v: cv2.cvtColor(np.ascontiguousarray(bank.images[v][:rows, :, :3]), cv2.COLOR_RGB2GRAY).astype(np.int16)
            for v in bank.names}
    return float(np.mean([np.abs(grey[a] - grey[b]).mean() for a, b in itertools.combinations(bank.names, 2)]))


def _closure_frames(specs, closures) -> np.ndarray:
    """Frames that show a closure's picture (the morph at most a fifth of the way off it)."""
    return np.array([(s.from_viseme in closures and s.alpha <= 0.2) or (s.to_viseme in closures and s.alpha >= 0.8)
                     for s in specs], bool)


#: The banks the range figure compares: (label, VideoBankConfig options).
RANGE_BANKS = (("whole frames, median shapes (before issue 28)", dict(one_face=False, span=False)),
               ("one face, pictures spanning the range", dict(one_face=True, span=True)))


@FIGURES.decorator("videobank_range")
def range_figures(ctx: Context, rows: List[dict]) -> None:
    """Issue 28's one face, range and sharpness, on GRID's held-out sentences: for a bank of
    whole frames with median shapes and one of one face spanning the range (both from
    :data:`~lipsync.bench.grid.BANK_CLIPS`), rendered from each sentence's sound and
    transcript and tracked: the lip-opening r with the real speaker, the rendered opening's
    standard deviation over the real one's (pooled over the frames), the widest opening
    (99th percentile), the opening on frames showing a closure, the mouth region's
    sharpness (variance of the Laplacian) against the real frames', the pops figure (99th
    percentile of the mean grey change above the nose between consecutive frames), and the
    bank pictures' mean difference above the nose."""
    from ..banks.bank import Bank
    from ..face.landmarks import FaceMesh
    from ..face.compare import mouth_box
    from ..phonetics.phonemes import load_map
    from ..videobank import make_bank
    from ..videobank.select import sharpness

    names = [c for c in grid.BANK_CLIPS if grid.video(c).is_file()]
    if len(names) < len(grid.BANK_CLIPS):
        rows.append({"figure": "videobank_range", "case": f"skipped: GRID's bank clips are not in {grid.grid_dir()}"})
        return
    videos = [grid.video(c) for c in names]
    texts = {v: grid.transcript(c) for v, c in zip(videos, names)}
    closures = set(load_map("english-to-rhubarb").closures)
    clips = grid.held_out()[:6] if ctx.quick else grid.held_out()
    mesh = FaceMesh()
    real_done = False
    for label, options in RANGE_BANKS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            made = make_bank(ctx.tmp / f"range-{options['one_face']}", videos, texts=texts, force=True, quiet=True,
                             **options)
        bank = Bank.load(made.path)
        got = {k: [] for k in ("r", "open", "real", "sharp", "real_sharp", "pops", "real_pops", "closed", "real_closed")}
        for clip in clips:
            j = judge_clip(bank, clip, mesh, methods=("flow morph",))
            ren, real = j["flow morph"], j["real"]
            got["r"].append(_corr(ren["open"], real["open"]))
            ok = np.isfinite(ren["open"]) & np.isfinite(real["open"])
            got["open"].append(ren["open"][ok])
            got["real"].append(real["open"][ok])
            shut = _closure_frames(j["specs"], closures) & ok
            got["closed"].append(ren["open"][shut])
            got["real_closed"].append(real["open"][shut])
            got["sharp"].append(ren["sharp"])
            got["real_sharp"].append(real["sharp"])
            got["pops"].append(ren["above_nose"])
            got["real_pops"].append(real["above_nose"])
        cat = {k: np.concatenate(v) for k, v in got.items() if k != "r"}
        pictures = np.array([sharpness(bank.images[v][..., :3], mouth_box(mesh.find(bank.images[v][..., :3]), bank.shape))
                             for v in bank.names])
        if not real_done:
            rows.append({"figure": "videobank_range", "case": f"real frames ({len(clips)} held-out clips)",
                         "open_p99": round(float(np.percentile(cat["real"], 99)), 3),
                         "closure_open_median": round(float(np.median(cat["real_closed"])), 3),
                         "mouth_sharpness": round(float(np.nanmedian(cat["real_sharp"])), 1),
                         "pops_p99": round(float(np.percentile(cat["real_pops"], grid.POPS_PERCENTILE)), 2)})
            real_done = True
        rows.append({"figure": "videobank_range", "case": label,
                     "lip_r_mean": round(float(np.nanmean(got["r"])), 3),
                     "std_ratio": round(float(cat["open"].std() / cat["real"].std()), 3),
                     "open_p99": round(float(np.percentile(cat["open"], 99)), 3),
                     "closure_open_median": round(float(np.median(cat["closed"])), 3),
                     "mouth_sharpness": round(float(np.nanmedian(cat["sharp"])), 1),
                     "sharpness_vs_real": round(float(np.nanmedian(cat["sharp"]) / np.nanmedian(cat["real_sharp"])), 3),
                     "pictures_sharpness_vs_real": round(float(np.median(pictures) / np.nanmedian(cat["real_sharp"])), 3),
                     "pops_p99": round(float(np.percentile(cat["pops"], grid.POPS_PERCENTILE)), 2),
                     "pictures_above_nose_diff": round(above_nose_spread(bank), 2),
                     "plate": made.report.get("face_plate", {}).get("frame")})
