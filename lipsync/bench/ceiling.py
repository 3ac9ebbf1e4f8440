"""How far one mouth shape per viseme can follow real lips (figure ``coarticulation_ceiling``).

Issue 21 asks an ideal bank (each viseme the speaker's median lip opening) driven by the
timing model to follow the real lips at r >= 0.88 on held-out GRID sentences. Its premise is
that the timing model is the cap. This figure measures the cap of the *shapes*: the same
dominance timing (:data:`lipsync.motion.coarticulation.DEFAULT_PARAMS`, full blend of every
segment's weight, not projected onto two visemes), the same held-out sentences and
lipsync's aligned phones (:mod:`lipsync.bench.coarticulation`), with each segment's opening
chosen in ways a bank of one picture per viseme could and could not follow:

* ``medians``: the ideal bank (what the issue's target is set on);
* ``fitted to the bank clips``: one value per viseme chosen to maximise the mean r on the
  10 bank sentences (Nelder-Mead from the medians), judged on the held-out ones;
* ``fitted to the held-out clips``: the same, fitted on the held-out sentences themselves:
  no set of one value per viseme does better with this timing;
* ``phone medians``: finer than visemes, each phone's median over the bank sentences'
  frames (a segment of several phones takes their duration-weighted mean);
* ``loudness``: each sound's opening scaled by its loudness relative to the sentence's
  speech (lips open wider in louder syllables), the scale fitted on the bank clips;
* ``each segment its own real opening``: an oracle no bank can be: every viseme segment
  given the mean real opening of its own frames.

Rows give the held-out mean of per-clip r and the gap to the medians.
"""

from __future__ import annotations

import re
import warnings
from typing import Dict, List

import numpy as np

from . import FIGURES, Context
from . import grid as G
from .coarticulation import FPS, _pmap, ideal_bank, viseme_track

#: Loudness scales tried for the ``loudness`` row: a sound ``z`` tens of dB above the
#: sentence's median speech level has its opening (above rest) times 1 + scale * z, within
#: LOUDNESS_RANGE. 0 is the medians row.
LOUDNESS_SCALES = (0.0, 0.1, 0.2, 0.3, 0.5, 0.8)
LOUDNESS_RANGE = (0.3, 1.6)
#: Simplex steps of the per-viseme value fits (enough to converge on 9 values: more moved
#: the held-out r by under 0.001).
VALUE_ITERATIONS = 3000


class _Clip:
    """One sentence: its weighted segments, normalised weights (segments x frames) and the
    real opening on the frames where the face was found."""

    def __init__(self, name: str, pmap):
        from ..motion import coarticulation as co

        real = G.real_measures(name)["opening"]
        classes = co.viseme_classes(pmap)
        segs = co.plan(viseme_track(name, "align", pmap), rest=pmap.silence, closures=pmap.closures,
                       duration=len(real) / FPS)
        self.name = name
        self.segments = segs + co.breaths(segs, classes=classes)
        self.n_sounds = len(segs)
        w = co.weights(segs, np.arange(len(real)) / FPS, classes=classes)
        self.ok = np.isfinite(real)
        self.weights = (w / np.maximum(w.sum(axis=0), 1e-12))[:, self.ok]
        self.real = real[self.ok]
        self.times = (np.arange(len(real)) / FPS)[self.ok]

    def r(self, values: np.ndarray) -> float:
        """Pearson's r of the real opening and the blend of one value per segment."""
        return G.correlation(values @ self.weights, self.real)

    def by_viseme(self, table: Dict[str, float]) -> np.ndarray:
        return np.array([table[v] for _, _, v in self.segments])


def _mean_r(clips: List[_Clip], values_of) -> float:
    return float(np.mean([c.r(values_of(c)) for c in clips]))


def _fit_values(clips: List[_Clip], start: Dict[str, float]) -> Dict[str, float]:
    from ..motion.coarticulation import _nelder_mead

    names = sorted(start)
    x0 = np.array([start[n] for n in names])

    def loss(x):
        table = dict(zip(names, x))
        return -_mean_r(clips, lambda c: c.by_viseme(table))

    x, _ = _nelder_mead(loss, x0, step=0.01, iterations=VALUE_ITERATIONS)
    return dict(zip(names, x))


def _phone_medians(pmap) -> Dict[str, float]:
    """Each phone's (no stress) median opening over the bank sentences' frames."""
    vals: Dict[str, List[float]] = {}
    for c in G.BANK_CLIPS:
        real = G.real_measures(c)["opening"]
        t = np.arange(len(real)) / FPS
        for p in G.phones(c, "align"):
            inside = real[(t >= p.start) & (t < p.end)]
            vals.setdefault(re.sub(r"\d", "", p.label), []).extend(inside[np.isfinite(inside)].tolist())
    return {p: float(np.median(v)) for p, v in vals.items() if v}


def _by_phone(clip: _Clip, phone_median: Dict[str, float], medians: Dict[str, float]) -> np.ndarray:
    phones = list(G.phones(clip.name, "align"))
    out = clip.by_viseme(medians)
    for k, (s, e, v) in enumerate(clip.segments[: clip.n_sounds]):
        acc = tot = 0.0
        for p in phones:
            overlap = min(e, p.end) - max(s, p.start)
            label = re.sub(r"\d", "", p.label)
            if overlap > 0 and label in phone_median:
                acc, tot = acc + overlap * phone_median[label], tot + overlap
        if tot > 0:
            out[k] = acc / tot
    return out


def _loudness(clip: _Clip, rest: str) -> np.ndarray:
    """Each sound's level in tens of dB against the sentence's median speech sound (0 for
    rest and the breath)."""
    from ..speech.audio import load_audio

    pcm = load_audio(G.video(clip.name)).astype(np.float64) / 32768.0
    level = np.zeros(len(clip.segments))
    for k, (s, e, v) in enumerate(clip.segments[: clip.n_sounds]):
        x = pcm[int(s * 16000): int(e * 16000)]
        level[k] = 10 * np.log10(np.mean(x * x) + 1e-10) if len(x) and v != rest else np.nan
    speech = level[: clip.n_sounds][np.isfinite(level[: clip.n_sounds])]
    z = (level - (np.median(speech) if len(speech) else 0.0)) / 10.0
    return np.where(np.isfinite(z), z, 0.0)


def _oracle(clip: _Clip, medians: Dict[str, float]) -> np.ndarray:
    out = clip.by_viseme(medians)
    for k, (s, e, _) in enumerate(clip.segments[: clip.n_sounds]):
        inside = (clip.times >= s) & (clip.times < e)
        if inside.any():
            out[k] = float(clip.real[inside].mean())
    return out


@FIGURES.decorator("coarticulation_ceiling")
def figure(ctx: Context, rows: List[dict]) -> None:
    pmap = _pmap()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bank = [_Clip(c, pmap) for c in G.BANK_CLIPS]
        held = [_Clip(c, pmap) for c in (G.held_out()[:8] if ctx.quick else G.held_out())]
    medians = ideal_bank(G.BANK_CLIPS, "align", "opening", pmap)
    base = _mean_r(held, lambda c: c.by_viseme(medians))

    def row(what: str, r: float, **extra) -> None:
        rows.append({"figure": "coarticulation_ceiling", "opening of each segment": what,
                     "r held-out": round(r, 3), "vs medians": f"{r - base:+.3f}", **extra})

    row("medians (the ideal bank)", base)
    fitted = _fit_values(bank, medians)
    row("one value per viseme, fitted to the bank clips", _mean_r(held, lambda c: c.by_viseme(fitted)))
    best = _fit_values(held, medians)
    row("one value per viseme, fitted to the held-out clips (the best one picture per viseme can do)",
        _mean_r(held, lambda c: c.by_viseme(best)))
    phone_median = _phone_medians(pmap)
    row("phone medians", _mean_r(held, lambda c: _by_phone(c, phone_median, medians)))
    rest = medians[pmap.silence]
    levels = {c.name: _loudness(c, pmap.silence) for c in bank + held}

    def loud(scale):
        lo, hi = LOUDNESS_RANGE
        return lambda c: rest + (c.by_viseme(medians) - rest) * np.clip(1 + scale * levels[c.name], lo, hi)

    scale = max(LOUDNESS_SCALES, key=lambda s: _mean_r(bank, loud(s)))
    row("medians scaled by loudness", _mean_r(held, loud(scale)), scale=scale)
    row("each segment its own real opening (an oracle, not a bank)", _mean_r(held, lambda c: _oracle(c, medians)))
