"""Step 5: one frame per viseme — candidates from the speech, ranked by the face.

**Candidates.** A viseme's candidates are the frames in the *steady middle* of the spans the
aligned speech gives it (:data:`STEADY_TRIM` of each end left out: there the lips are still
coming from the sound before or already going to the next); a span too short to have a
middle gives its one frame nearest the centre. The rest viseme's candidates come from
silence of at least :data:`REST_MIN_S`: its frames at least :data:`REST_GUARD_S` away from speech (lips part before a word
begins and settle after it ends).

**Ranking** (lowest score wins; each term's scale is named with its reason):

* *typical shape* — the distance of the frame's mouth
  (:func:`lipsync.face.measure.mouth_shape`: the 40 lip points in the eyes' frame, in eye
  distances) from the median mouth of all the viseme's candidates, over the candidates'
  median distance. A viseme spoken in many contexts shows a spread of shapes (a B between
  two open vowels is more open than one between closures); the most typical is the one
  that stands for the viseme best wherever the renderer shows it;
* *typical opening* — the frame's lip opening (:func:`lipsync.face.measure.lip_opening`)
  against the candidates' median (for a closure, a low percentile of them: its picture must
  show closed lips, :data:`CLOSURE_OPENING_PERCENTILE`), over their median absolute
  deviation (:data:`OPENING_WEIGHT`);
* *steady lips* — the lips' speed (eye distances per second) over :data:`MOTION_SCALE`:
  a frame between two shapes is blurred and not any viseme;
* *eyes open* — a blink is never chosen (:data:`BLINK_BELOW`), half-closed eyes cost;
* *low stabilisation residual* — the head turned or nodded against the reference pose
  shows as still points the similarity could not fit (:data:`RESIDUAL_SCALE`): such a
  frame would morph with a swimming face;
* *sharpness* — the mouth region's detail (variance of its Laplacian) against the sharpest
  finalist, once the best :data:`FINALISTS` per viseme have been cut out of the video.

**Visemes the video never shows** get the picture of the closest shape available
(:data:`NEAREST_SHAPES`) and a warning that names them and the sounds to record.

Examples
--------
>>> steady_frames(1.0, 1.4, 25.0, 100)
[28, 29, 30, 31, 32]
>>> steady_frames(1.0, 1.04, 25.0, 100)   # one frame long: the one nearest the middle
[26]
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..face import measure as M
from ..face import topology as T
from ..samples.quality import sharpness  # the pictures' measure is the samples' (one definition)

#: Share of a span left out at each end: its middle half is its steady part (a held sound
#: reaches its shape within ~50-80 ms and leaves it as late before the next; GRID's
#: phones last 60-200 ms).
STEADY_TRIM = 0.25
#: Only a silence this long shows the mouth at rest: the sequencer holds the last shape
#: through shorter pauses (:data:`lipsync.motion.sequencer.MAX_HELD_PAUSE_S`, 0.2 s), and so do
#: speakers; a longer one leaves a relaxed middle once the guards below are taken off.
REST_MIN_S = 0.35
#: Silence frames closer than this to speech are not rest candidates: lips part ~100-200 ms
#: before the first sound of a word (anticipation) and settle as long after it.
REST_GUARD_S = 0.16
#: Eyes less open than this share of the video's median opening are a blink: never chosen.
BLINK_BELOW = 0.6
#: A stabilisation residual of this many eye distances (1.4 px on GRID's 46-px eye
#: distance; the head turned about 3 degrees) costs as much as a mouth one typical spread
#: from the viseme's median shape. GRID's frames measure 0.008-0.04.
RESIDUAL_SCALE = 0.03
#: Lip speed (eye distances per second) that costs as much as one typical spread: lips in
#: the middle of a transition move at ~2 eye distances per second, held ones at ~0.2.
MOTION_SCALE = 2.0
#: How open the lips are is what the eye reads first in a mouth (and what the jaw does),
#: but it is one of 80 numbers in the shape distance: a frame may have a typical outline and
#: an untypical opening. On GRID's bank clips the shape distance alone chose a D (AA) at
#: 0.074 eye distances while D's candidates have a median of 0.109; with this term (in MADs
#: of the candidates' openings) the openings of the chosen frames, driven by the sequencer
#: over the held-out sentences, follow the real lips as well as the per-viseme medians do
#: (r = 0.686 against 0.661 without; weights of 2 and more change nothing further).
OPENING_WEIGHT = 1.0
#: A closure's (P, B, M: the map's ``closures``) opening is judged against this percentile of
#: its candidates' openings, not their median: closed lips are what the picture must show
#: (the renderer shows it on every frame inside a P, B or M). At 25 fps with good
#: alignment most of a closure's middle frames are closed and the median is too (GRID s1:
#: the same frame either way); at 15 fps, or an aligner a frame off, the middle of a 60-90 ms
#: closure holds the lips parting, and the median chose a picture more open than the
#: slightly-open B (kphotoalbum's demo webcam clip, tools/other_face.py: 0.049 against 0.044
#: eye distances).
CLOSURE_OPENING_PERCENTILE = 10
#: The speaker's range (issue 28): an open shape's picture is chosen near its candidates'
#: median lip opening moved this many times as far from the rest shape's median
#: (``rest + SPAN_GAIN * (median - rest)``), not near the median itself. A viseme's
#: candidates are every instance of it in every context; the renderer reaches a picture
#: only in the middle of a held sound and coarticulation pulls it towards its neighbours
#: (lipsync.motion.coarticulation), so median pictures render a mouth that opens 0.58 times as
#: much as the speaker's (std of the rendered inner-lip opening over the real one's; GRID
#: s1, 30 held-out sentences, ``python -m lipsync.bench --only videobank_range``). Scaling
#: the open shapes alike from the rest keeps the pattern of openings the timing blends (the
#: dominance blend is affine in the pictures' openings), so its correlation with the real
#: lips: with the ideal pictures, predicted r 0.777 for gains 1.0-1.6 and std ratios 0.67,
#: 0.88, 1.01, 1.08 for 1.0, 1.3, 1.5, 1.6. Rendered (one face, B C D H spanning, opening
#: weight 3): std 0.84, r 0.778 (median pictures: 0.58, 0.774). Measured and not taken: the
#: 75th/80th percentile of B-E and H instead (std 0.77/0.98, r 0.767/0.762: a percentile
#: moves each viseme by its own spread, not by how open it is); gain 1.5 with the opening
#: weight 1 (the ranking's other terms won: D's picture at 0.12 for a 0.16 target, std 0.70,
#: r 0.754); gain 1.3 (std 0.67); E spanning too (r 0.768).
SPAN_GAIN = 1.5
#: The shapes (Rhubarb names; other maps' visemes through their twins) whose pictures span
#: the range: the open ones. E (rounded open), F (puckered) and G (F/V) show their shape,
#: not an opening (with E spanning too: r 0.768 against 0.778).
SPAN_SHAPES = "BCDH"
#: With spanning pictures, the opening term weighs this much (:data:`OPENING_WEIGHT` without):
#: the target lies away from the typical instance, and at weight 1 typicality, stillness and
#: sharpness outvoted it (see :data:`SPAN_GAIN`).
SPAN_OPENING_WEIGHT = 3.0

#: A frame at half the sharpness of the viseme's sharpest finalist costs half a spread.
SHARPNESS_WEIGHT = 1.0
#: Eyes half as open as usual (but not a blink) cost this much.
EYES_WEIGHT = 1.0
#: How many of each viseme's best-ranked candidates are cut out of the video and judged on
#: sharpness (decoding them again costs one pass over the video).
FINALISTS = 6
#: The rest viseme's picture is the bank's *plate*: every other viseme shows its eyes, hair
#: and clothes (:mod:`lipsync.composite.face`), so its eyes must be open, not merely
#: unblinking: eyes less open than the video's median cost this many spreads per unit
#: (eyes at 0.8 of the median cost 0.8, as much as a mouth shape 0.8 spreads off).
PLATE_EYES_WEIGHT = 4.0

#: For each Rhubarb mouth shape, the other shapes from most to least alike (by opening,
#: rounding and what touches the lips), for a viseme the video never shows. Names of other
#: systems (Preston Blair, Oculus) go through their Rhubarb twins
#: (:data:`lipsync.banks.names.SYSTEMS`).
NEAREST_SHAPES = {
    "A": "XBGFEHCD",   # closed lips: the relaxed closed mouth, then teeth together
    "B": "CHXAGEFD",   # teeth nearly together: slightly more open, L, the rest
    "C": "BHDEXFAG",   # open: less open, L's open jaw, wide open
    "D": "CEHBFXAG",   # wide open: open, rounded open
    "E": "FCDBHXAG",   # slightly rounded: puckered, open
    "F": "EBXACHDG",   # puckered: slightly rounded, then small openings
    "G": "BAXCHFED",   # lower lip under the upper teeth: teeth together, closed
    "H": "CBDEXFAG",   # tongue up, jaw open: open, teeth together
    "X": "ABGFECHD",   # rest: closed lips, then nearly closed
}


@dataclass(frozen=True)
class Candidate:
    """A frame that may show a viseme, with its scores.

    Attributes
    ----------
    video : int
        Index of its video in the run.
    frame : int
    time : float
        Seconds.
    viseme : str
    span : (float, float)
        The speech span (or silence) it lies in.
    typicality, opening, motion, eyes, residual, sharpness : float
        The ranking terms (see the module docstring); ``sharpness`` NaN until measured.
    score : float
        The sum of the penalties (lower is better).
    """

    video: int
    frame: int
    time: float
    viseme: str
    span: Tuple[float, float]
    typicality: float = math.nan
    opening: float = math.nan
    motion: float = math.nan
    eyes: float = math.nan
    residual: float = math.nan
    sharpness: float = math.nan
    score: float = math.nan

    def report(self) -> dict:
        """The scores as plain numbers (for the JSON report)."""
        def r(x, n=4):
            return None if x is None or not math.isfinite(x) else round(float(x), n)

        return {"frame": self.frame, "time": r(self.time, 3), "span": [r(self.span[0], 3), r(self.span[1], 3)],
                "score": r(self.score), "typicality": r(self.typicality), "opening": r(self.opening), "motion": r(self.motion),
                "eyes": r(self.eyes), "residual": r(self.residual), "sharpness": r(self.sharpness, 1)}


def steady_frames(start: float, end: float, fps: float, n_frames: int, *, trim: float = STEADY_TRIM) -> List[int]:
    """Frames (frame n shows time n / fps) in the steady middle of ``[start, end)``."""
    d = end - start
    a, b = start + trim * d, end - trim * d
    frames = [n for n in range(max(0, math.ceil(a * fps - 1e-9)), min(n_frames, math.floor(b * fps + 1e-9) + 1))
              if a - 1e-9 <= n / fps <= b + 1e-9]
    if not frames:
        mid = int(round((start + end) / 2 * fps))
        if 0 <= mid < n_frames and start - 0.5 / fps <= mid / fps < end + 0.5 / fps:
            frames = [mid]
    return frames


def rest_frames(spans: Sequence, index: int, fps: float, n_frames: int, *, guard: float = REST_GUARD_S
                ) -> List[int]:
    """Frames of silence span ``spans[index]`` at least ``guard`` seconds from speech."""
    s = spans[index]
    if s.end - s.start < REST_MIN_S:
        return []
    a = s.start + (guard if index > 0 else 0.0)
    b = s.end - (guard if index < len(spans) - 1 else 0.0)
    return [n for n in range(max(0, math.ceil(a * fps - 1e-9)), min(n_frames, math.floor(b * fps + 1e-9) + 1))
            if a - 1e-9 <= n / fps <= b + 1e-9]


def candidates(spans: Sequence, *, video: int, fps: float, found: np.ndarray, rest: str) -> List[Candidate]:
    """Every candidate frame of one video (frames with a face only)."""
    out = []
    n = len(found)
    for i, s in enumerate(spans):
        frames = rest_frames(spans, i, fps, n) if s.label == rest else steady_frames(s.start, s.end, fps, n)
        out += [Candidate(video=video, frame=f, time=f / fps, viseme=s.label, span=(s.start, s.end))
                for f in frames if found[f]]
    return out


def lip_speed(points: np.ndarray, fps: float) -> np.ndarray:
    """Mean speed of the 40 lip points, eye distances per second, per frame (central differences)."""
    lips = list(dict.fromkeys(T.LIP_OUTER_UPPER + T.LIP_OUTER_LOWER + T.LIP_INNER_UPPER + T.LIP_INNER_LOWER))
    p = np.asarray(points, np.float64)[:, lips, :2] / M.eye_distance(points)[:, None, None]
    if len(p) < 2:
        return np.zeros(len(p))
    v = np.gradient(p, axis=0) * fps
    return np.linalg.norm(v, axis=-1).mean(axis=-1)


@dataclass(frozen=True)
class FrameMeasures:
    """Per-frame measures of one video that the ranking uses."""

    shape: np.ndarray      # (N, 80) mouth_shape
    opening: np.ndarray    # (N,) lip_opening
    motion: np.ndarray     # (N,) lip speed
    eyes: np.ndarray       # (N,) eye opening over the video's median
    residual: np.ndarray   # (N,) stabilisation residual

    @classmethod
    def of(cls, points: np.ndarray, fps: float, residual: np.ndarray) -> "FrameMeasures":
        eyes = M.eye_opening(points)
        return cls(shape=M.mouth_shape(points), opening=M.lip_opening(points), motion=lip_speed(points, fps),
                   eyes=eyes / np.nanmedian(eyes), residual=np.asarray(residual, np.float64))


def rank(cands: Sequence[Candidate], measures: Sequence[FrameMeasures], *,
         closures: Sequence[str] = (), rest: Optional[str] = None, span: float = 1.0) -> Dict[str, List[Candidate]]:
    """Candidates scored and sorted best first, per viseme (blinks left out when a viseme has
    other candidates). ``closures``: visemes whose pictures must show closed lips
    (:data:`CLOSURE_OPENING_PERCENTILE`). ``rest`` and ``span`` (:data:`SPAN_GAIN`): the
    other visemes' openings are judged against their median moved ``span`` times as far from
    the rest's median, and their typical shape is the median of the candidates opened about
    that wide."""
    by: Dict[str, List[Candidate]] = {}
    for c in cands:
        by.setdefault(c.viseme, []).append(c)
    out = {}
    rest_opening = (float(np.median([measures[c.video].opening[c.frame] for c in by[rest]]))
                    if rest in by and span != 1.0 else None)
    weight = OPENING_WEIGHT if rest_opening is None else SPAN_OPENING_WEIGHT
    for v, group in by.items():
        shapes = np.stack([measures[c.video].shape[c.frame] for c in group])
        opening = np.array([measures[c.video].opening[c.frame] for c in group])
        median = float(np.median(opening))
        mad = max(float(np.median(np.abs(opening - median))), 1e-6)
        # a closure: an opening one of its candidates has (the lowest of a few, a low one of many)
        mid = float(np.percentile(opening, CLOSURE_OPENING_PERCENTILE, method="lower")) if v in closures else median
        like = np.ones(len(group), bool)
        if rest_opening is not None and v not in closures and v != rest and rhubarb_shape(v) in set(SPAN_SHAPES):
            mid = rest_opening + span * (median - rest_opening)
            # the typical shape of the instances opened that wide, not of all of them
            near = np.abs(opening - mid) <= mad
            like = near if near.sum() >= 3 else like
        dist = np.linalg.norm(shapes - np.median(shapes[like], axis=0), axis=1)
        typ = dist / max(float(np.median(dist)), 1e-9)
        scored = []
        for c, t, o in zip(group, typ, opening):
            m = measures[c.video]
            eyes, motion, res = float(m.eyes[c.frame]), float(m.motion[c.frame]), float(m.residual[c.frame])
            score = (float(t) + weight * abs(float(o) - mid) / mad + motion / MOTION_SCALE
                     + res / RESIDUAL_SCALE + EYES_WEIGHT * max(0.0, 1.0 - eyes))
            scored.append(replace(c, typicality=float(t), opening=float(o), motion=motion, eyes=eyes, residual=res,
                                  score=score))
        open_eyes = [c for c in scored if c.eyes >= BLINK_BELOW]
        out[v] = sorted(open_eyes or scored, key=lambda c: c.score)
    return out


def for_plate(ranked: Sequence[Candidate]) -> List[Candidate]:
    """The rest viseme's candidates re-ranked for the plate every viseme shares: eyes open
    (:data:`PLATE_EYES_WEIGHT`) on top of the rest's own ranking (a relaxed closed mouth,
    still, a low residual).

    Examples
    --------
    >>> a = Candidate(video=0, frame=1, time=0.04, viseme="X", span=(0, 1), eyes=0.8, score=1.0)
    >>> b = Candidate(video=0, frame=2, time=0.08, viseme="X", span=(0, 1), eyes=1.05, score=1.5)
    >>> [c.frame for c in for_plate([a, b])]
    [2, 1]
    """
    def plate_score(c: Candidate) -> float:
        return c.score + PLATE_EYES_WEIGHT * max(0.0, 1.0 - c.eyes)

    return [replace(c, score=plate_score(c)) for c in sorted(ranked, key=plate_score)]


def with_sharpness(finalists: Sequence[Candidate], sharpness: Sequence[float]) -> List[Candidate]:
    """Finalists of one viseme with their sharpness added to the score, best first."""
    top = max(max(sharpness), 1e-9)
    out = [replace(c, sharpness=float(s), score=c.score + SHARPNESS_WEIGHT * (1.0 - float(s) / top))
           for c, s in zip(finalists, sharpness)]
    return sorted(out, key=lambda c: c.score)


def rhubarb_shape(viseme: str) -> Optional[str]:
    """The Rhubarb mouth shape a viseme name stands for (any known naming system), or None."""
    from ..banks.names import SYSTEMS

    for table in SYSTEMS.values():
        if viseme in table:
            return table[viseme]
    return None


def nearest_available(missing: str, available: Sequence[str], *, fallback: Optional[str] = None) -> str:
    """The available viseme whose mouth shape is most like ``missing``'s.

    Examples
    --------
    >>> nearest_available("G", ["X", "A", "B", "C"])
    'B'
    >>> nearest_available("kk", ["sil", "PP", "DD", "aa"])   # k and t both teeth together
    'DD'
    """
    shape = rhubarb_shape(missing)
    if shape is not None:
        order = shape + NEAREST_SHAPES[shape]
        ranked = sorted(((order.index(s), i, v) for i, v in enumerate(available)
                         if (s := rhubarb_shape(v)) is not None and s in order))
        if ranked:
            return ranked[0][2]
    if fallback is not None and fallback in available:
        return fallback
    return available[0]
