"""Real in-betweens (``real_inbetween``, issue 22): how close each method comes to real frames.

The paper's figure-7 claim, measured: its flow interpolation gives in-betweens "visually
more similar to the actual image" than the classic Beier–Neely morph. On GRID's speaker
(:mod:`lipsync.bench.grid`, real video):

1. **Pairs.** In every clip, for k = 2, 4, 6 (:data:`K_VALUES`), the two frames k apart
   whose mouths differ most (:func:`lipsync.face.measure.mouth_shape`, by the face mesh),
   among those whose frames between really lie between them (:func:`select_pairs`): an
   in-between can only be judged against a real frame that is an in-between.
2. **A two-viseme bank** of the two frames, written as PNG + bank.yaml and loaded by
   :meth:`lipsync.Bank.load`, so the real pipeline runs (normalise, flows, refinement, store).
   Its lines come from the face room two ways: ``track`` -- :func:`lipsync.face.lines.face_features`
   on the video's tracked mesh (what ``lipsync init --video`` does) -- and ``init`` --
   ``lipsync init`` on a folder holding the two frames as photos (its own mesh on each,
   :func:`lipsync.videobank.photos.init_bank`). ``symmetry: false`` in both: a real face is not a
   mirror image, and normalising would warp both pictures away from the real frames they
   are judged against -- every method would be judged on a face that is not the real one
   (``lipsync init`` turns symmetry on for some of GRID's frame pairs, whose faces are
   within :data:`lipsync.face.lines.SYMMETRIC_BELOW` of symmetric; the figure counts them
   and turns it off).
3. **In-betweens by every method** (flow, splat, beier-neely, dissolve, and a hard cut to the
   nearer end) at each real frame's alpha, fitted from its landmarks (:func:`fit_alpha`, the
   same for every method: timing is not judged here), and ``flow_lines``: the flow method on
   the same bank with ``refine: false`` (the line flows alone, as before issue 22).
4. **Judged** in the mouth region of the real frame (:func:`lipsync.face.compare.mouth_box`):
   PSNR and SSIM, each method's mean, and the share of frames where it is closest of all
   (``best``) and closer than classic Beier–Neely (``beats_bn``).

Beside it, preprocessing seconds per pair with the refinement and without.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import FIGURES, Context

#: Frames apart of the two ends: 2 at 25 fps is one fast consonant-vowel step, 6 a whole
#: opening and closing.
K_VALUES = (2, 4, 6)
#: Methods judged; "cut" shows the nearer end (the hard cut of lip-sync tools without morphs),
#: "flow_lines" is the flow method with ``refine: false``.
METHODS_JUDGED = ("flow", "splat", "beier-neely", "dissolve", "cut")
#: A real frame counts as an in-between when its moving points lie within this share of the
#: ends' motion from the straight path between them (RMS): the median frame lies at 0.14,
#: and the frames rejected are those where the mouth opened and closed again in between
#: (two closed ends, an open middle), which no interpolation of the two ends can show.
MAX_OFF_PATH = 0.35


def _moving_points() -> List[int]:
    from ..face import topology as T

    lips = T.LIP_OUTER_UPPER + T.LIP_OUTER_LOWER + T.LIP_INNER_UPPER + T.LIP_INNER_LOWER
    return sorted(set(lips) | set(T.JAW_L) | set(T.JAW_R) | set(T.CHIN_MIDLINE))


def fit_alpha(points_a: np.ndarray, points_b: np.ndarray, points_m: np.ndarray) -> Tuple[float, float]:
    """Where a real frame lies between two others, from the face mesh: ``(alpha, off_path)``.

    ``alpha`` is the least-squares position of the frame's moving points (lips, jaw, chin)
    on the straight path from A's to B's (not clipped); ``off_path`` the RMS distance left,
    over the RMS motion from A to B. The lips and jaw together fit the pictures better than
    the lips alone (measured: +0.1 dB for every method), and the same alpha serves every
    method.

    Examples
    --------
    >>> a = np.zeros((468, 2)); b = a + [0.0, 4.0]
    >>> fit_alpha(a, b, a + [0.0, 1.0])
    (0.25, 0.0)
    """
    idx = _moving_points()
    a, b, m = (np.asarray(p, np.float64)[idx, :2] for p in (points_a, points_b, points_m))
    d = (b - a).ravel()
    span = float(np.dot(d, d))
    if span == 0.0:
        return 0.0, float("inf")
    alpha = float(np.dot((m - a).ravel(), d) / span)
    off = np.sqrt(((m - (a + alpha * (b - a))) ** 2).sum(axis=1).mean()) / np.sqrt(span / len(idx))
    return alpha, float(off)


def select_pairs(points: np.ndarray, k: int, count: int = 1) -> List[Tuple[int, int]]:
    """Frame pairs ``(i, i + k)`` of a track whose mouths differ most, the frames between them
    in-betweens (alphas in (0, 1), increasing, each within :data:`MAX_OFF_PATH` of the path);
    at most ``count``, not overlapping.

    Examples
    --------
    >>> from lipsync.face import topology as T
    >>> pts = np.zeros((10, 468, 2)); pts[..., 0] = np.arange(468); pts[..., 1] = 100.0
    >>> pts[:, list(T.EYE_UPPER_R + T.EYE_LOWER_R), 0] += 60
    >>> pts[:, list(T.LIP_INNER_LOWER), 1] += np.minimum(np.arange(10), 6)[:, None]
    >>> select_pairs(pts, 2)
    [(0, 2)]
    """
    from ..face.measure import mouth_shape

    shape = mouth_shape(points)
    change = np.linalg.norm(shape[k:] - shape[:-k], axis=1)
    out: List[Tuple[int, int]] = []
    for i in np.argsort(-change, kind="stable"):
        i = int(i)
        if change[i] == 0 or any(abs(i - j) <= k for j, _ in out):
            continue
        fits = [fit_alpha(points[i], points[i + k], points[m]) for m in range(i + 1, i + k)]
        alphas = [a for a, _ in fits]
        if all(0.0 < a < 1.0 for a in alphas) and all(np.diff(alphas) > 0) and \
                all(off <= MAX_OFF_PATH for _, off in fits):
            out.append((i, i + k))
            if len(out) >= count:
                break
    return out


def _write_png(path: Path, image: np.ndarray) -> None:
    import cv2

    cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))


def pair_bank(folder: Path, image_a: np.ndarray, image_b: np.ndarray, points_a: Optional[np.ndarray],
              points_b: Optional[np.ndarray], *, lines: str = "track", refine: bool = True):
    """A bank of two real frames ``A`` (rest) and ``B`` in ``folder``, loaded by :meth:`Bank.load`.

    ``lines="track"``: face lines from the given mesh points (``symmetry: false``);
    ``lines="init"``: ``lipsync init`` on the folder (its own face mesh on each picture),
    with ``symmetry: false`` whatever init chose (the module docstring says why). ``refine``
    is written into bank.yaml. Returns ``(bank, whether lipsync init chose symmetry)``.
    """
    from ..banks.bank import Bank
    from ..banks.yamlio import dump_bank, write_bank_text

    folder.mkdir(parents=True, exist_ok=True)
    # X (rest) and D: names lipsync init reads as Rhubarb's; the bank calls them what they are
    _write_png(folder / "X.png", image_a)
    _write_png(folder / "D.png", image_b)
    if lines == "init":
        from ..videobank.photos import init_bank
        from ..banks.yamlio import header_comments
        import yaml

        init_bank(folder, lines="face", force=True)
        text = (folder / "bank.yaml").read_text()
        doc = yaml.safe_load(text)
        header = header_comments(text)
    elif lines == "track":
        from ..face.lines import FACE_WARP, face_features

        feats = face_features({"X": points_a, "D": points_b}, image_a.shape[:2])
        doc = {"name": folder.name, "rest": "X",
               "warp": {"a": FACE_WARP.a, "b": FACE_WARP.b, "p": FACE_WARP.p}, "symmetry": False,
               "visemes": {v: {"image": f"{v}.png", "lines": {n: f.to_yaml_value() for n, f in feats[v].items()}}
                           for v in ("X", "D")}}
        header = []
    else:
        raise ValueError(f"lines must be 'track' or 'init', not {lines!r}")
    doc = {k: v for k, v in doc.items() if k != "visemes"} | {"refine": bool(refine), "visemes": doc["visemes"]}
    init_symmetric = bool(doc.get("symmetry"))
    doc["symmetry"] = False
    write_bank_text(folder / "bank.yaml", dump_bank(doc, header=header))
    return Bank.load(folder), init_symmetric


@dataclass
class Judged:
    """One real in-between judged: where it came from, its alpha, each method's PSNR and SSIM."""

    clip: str
    k: int
    frame: int
    alpha: float
    psnr: Dict[str, float]
    ssim: Dict[str, float]


def judge_pair(frames: Sequence[np.ndarray], points: np.ndarray, i: int, j: int, folder: Path, *,
               lines: str = "track", clip: str = "", timings: Optional[Dict[str, list]] = None) -> List[Judged]:
    """Every real frame strictly between ``i`` and ``j`` against every method's in-between."""
    from ..face.compare import mouth_box, psnr, ssim
    from ..morphing.preprocess import preprocess
    from ..morphing.render import Renderer

    out: List[Judged] = []
    banks = {}
    for refine in (True, False):
        bank, symmetric = pair_bank(folder / ("refined" if refine else "lines"), frames[i], frames[j], points[i],
                                    points[j], lines=lines, refine=refine)
        t = time.perf_counter()
        preprocess(bank, jobs=1, quiet=True)
        if timings is not None:
            timings["refined" if refine else "lines"].append(time.perf_counter() - t)
            if refine:
                timings.setdefault("init_symmetric", []).append(symmetric)
        banks[refine] = bank
    renderers = {m: Renderer(banks[True], method=m) for m in METHODS_JUDGED if m != "cut"}
    renderers["flow_lines"] = Renderer(banks[False], method="flow")
    a_img, b_img = banks[True].images["X"], banks[True].images["D"]
    for m in range(i + 1, j):
        alpha, _ = fit_alpha(points[i], points[j], points[m])
        alpha = min(1.0, max(0.0, alpha))
        real = frames[m]
        box = mouth_box(points[m], real.shape[:2])
        scores_p, scores_s = {}, {}
        for name in METHODS_JUDGED + ("flow_lines",):
            img = (a_img if alpha < 0.5 else b_img) if name == "cut" else renderers[name].render("X", "D", alpha)
            scores_p[name] = psnr(img, real, box)
            scores_s[name] = ssim(img, real, box)
        out.append(Judged(clip=clip, k=j - i, frame=m, alpha=alpha, psnr=scores_p, ssim=scores_s))
    return out


def run(videos: Sequence[Path], *, ks: Sequence[int] = K_VALUES, per_clip: int = 1, lines: str = "track",
        folder: Optional[Path] = None, tracks: Optional[dict] = None,
        timings: Optional[Dict[str, list]] = None) -> List[Judged]:
    """The experiment on ``videos`` (each with its face track; ``tracks`` maps a path to one)."""
    from ..face.track import track_video
    from ..face.video import read_video

    out: List[Judged] = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(folder or tmp)
        for video in videos:
            video = Path(video)
            track = (tracks or {}).get(video) or track_video(video)
            frames = list(read_video(video))
            for k in ks:
                for i, j in select_pairs(track.points, k, per_clip):
                    out += judge_pair(frames, track.points, i, j, root / f"{video.stem}-{k}-{i}-{lines}",
                                      lines=lines, clip=video.stem, timings=timings)
    return out


def summarise(judged: Sequence[Judged]) -> Dict[str, dict]:
    """Per method: mean PSNR and SSIM, share of frames where it is closest (``best``, among
    :data:`METHODS_JUDGED`) and closer than classic Beier–Neely (``beats_bn``)."""
    names = list(METHODS_JUDGED) + ["flow_lines"]
    out = {}
    for name in names:
        p = np.array([j.psnr[name] for j in judged])
        s = np.array([j.ssim[name] for j in judged])
        best = np.mean([all(j.psnr[name] > j.psnr[o] for o in METHODS_JUDGED if o != name) for j in judged])
        beats = np.mean([j.psnr[name] > j.psnr["beier-neely"] for j in judged])
        out[name] = {"psnr": float(p.mean()), "ssim": float(s.mean()), "best": float(best), "beats_bn": float(beats)}
    return out


@FIGURES.decorator("real_inbetween")
def _figure(ctx: Context, rows: List[dict]) -> None:
    from . import grid

    names = grid.clips()[:10] if ctx.quick else grid.clips()
    videos = [grid.video(c) for c in names]
    tracks = {grid.video(c): grid.track(c) for c in names}
    for lines in ("track", "init"):
        timings: Dict[str, list] = {"refined": [], "lines": []}
        judged = run(videos, lines=lines, folder=ctx.tmp / f"inbetween-{lines}", tracks=tracks, timings=timings)
        summary = summarise(judged)
        bn = summary["beier-neely"]["psnr"]
        for name, s in summary.items():
            rows.append({"figure": "real_inbetween", "lines": lines, "method": name, "frames": len(judged),
                         "pairs": len(timings["refined"]), "mouth_psnr_db": round(s["psnr"], 3),
                         "vs_beier_neely_db": round(s["psnr"] - bn, 3), "mouth_ssim": round(s["ssim"], 4),
                         "best_share": round(s["best"], 3), "beats_bn_share": round(s["beats_bn"], 3)})
        for k in K_VALUES:
            sel = [j for j in judged if j.k == k]
            if sel:
                s = summarise(sel)
                rows.append({"figure": "real_inbetween", "lines": lines, "method": f"flow, k={k}",
                             "frames": len(sel), "mouth_psnr_db": round(s["flow"]["psnr"], 3),
                             "vs_beier_neely_db": round(s["flow"]["psnr"] - s["beier-neely"]["psnr"], 3),
                             "mouth_ssim": round(s["flow"]["ssim"], 4), "best_share": round(s["flow"]["best"], 3),
                             "beats_bn_share": round(s["flow"]["beats_bn"], 3)})
        rows.append({"figure": "real_inbetween_preprocess", "lines": lines, "pairs": len(timings["refined"]),
                     "init_chose_symmetry": int(sum(timings.get("init_symmetric", []))) if lines == "init" else None,
                     "size": "360x288",
                     "refined_s_per_pair": round(float(np.median(timings["refined"])), 3),
                     "lines_only_s_per_pair": round(float(np.median(timings["lines"])), 3),
                     "ratio": round(float(np.median(timings["refined"]) / np.median(timings["lines"])), 2)})


def _variant(src: Path, dst: Path, refine: bool) -> Path:
    """A copy of the bank folder ``src`` (without its store) saying ``refine: <refine>``."""
    import shutil

    import yaml

    from ..banks.yamlio import dump_bank, header_comments, write_bank_text

    if not dst.exists():
        shutil.copytree(src, dst, ignore=shutil.ignore_patterns(".lipsync"))
        text = (dst / "bank.yaml").read_text()
        doc = yaml.safe_load(text)
        doc = {k: v for k, v in doc.items() if k not in ("visemes", "refine")} | {"refine": refine,
                                                                                  "visemes": doc["visemes"]}
        write_bank_text(dst / "bank.yaml", dump_bank(doc, header=header_comments(text)))
    return dst


@FIGURES.decorator("refine_speed")
def _refine_speed(ctx: Context, rows: List[dict]) -> None:
    """The ``frame`` (toon) and ``whole_frame`` (drawn face) figures, measured side by side in
    one run on each bank with ``refine: true`` (the default) and ``refine: false`` (the line
    flows alone, as before issue 22): per-frame speed ratios, preprocessing time and store size."""
    from .render import _face_banks, _toon_banks, bench_methods, bench_store, bench_whole_frame

    for name, banks, bench in (("frame", _toon_banks(ctx), bench_methods),
                               ("whole_frame", _face_banks(ctx), bench_whole_frame)):
        for refine in (False, True):
            variants = {label: _variant(path, ctx.tmp / f"refine-{refine}-{path.name}", refine)
                        for label, path in banks.items()}
            for label, path in variants.items():
                t, c = time.perf_counter(), time.process_time()
                from ..banks.bank import Bank
                from ..morphing.preprocess import all_pairs, preprocess

                bank = Bank.load(path)
                preprocess(bank, quiet=True)
                n = len(all_pairs(bank.names))
                rows.append({"figure": "refine_speed_preprocess", "bank": f"{name} {label}", "refine": refine,
                             "pairs": n, "wall_s_per_pair": round((time.perf_counter() - t) / n, 3),
                             "cpu_s_per_pair": round((time.process_time() - c) / n, 3)})
            before = len(rows)
            bench(rows, variants, ctx.quick)
            bench_store(rows, variants)
            for r in rows[before:]:
                r["figure"] = f"refine_speed_{r['figure']}"
                r["refine"] = refine
