"""Choosing one mouth sample per rendered frame (:meth:`Selector.select`).

Per frame t the *target* is what the render should show: the phone said then and its
neighbours (from the timeline), the viseme the sequencer shows, and the lip opening and
width the dominance model predicts (:func:`lipsync.motion.coarticulation.predicted`: the
phones' schedule, each phone valued at its samples' median, blended with the one-picture
morph's schedule of the pictures' openings, :data:`PICTURE_SHARE`). Per frame the candidates are
the :data:`NEAREST` samples of that viseme nearest the predicted opening and width
(OpenCV's FLANN k-d tree, exact search, one tree per viseme, built once) and the next frames of the
:data:`FOLLOW` cheapest candidates of frame t-1 (so a run of real video can continue).
The :class:`~lipsync.selection.viterbi.Viterbi` pass then finds the cheapest path under
the costs of :data:`WEIGHTS`: a join between two samples that are consecutive frames of
the source costs nothing.

Silence and closures are exact: a frame the sequencer shows closed (a bilabial) takes
samples of that viseme whose lips are closed (opening at most :data:`CLOSED`), a frame of
silence showing the rest shape samples of silence with the lips at rest; a run continued
from the frame before may bring any sample whose lips are closed (see :meth:`Selector.allowed`).

Examples
--------
>>> WEIGHTS["join"] > 0 and WEIGHTS["phone_same"] == 0
True
"""

from __future__ import annotations

import threading
import time
import weakref
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence

import numpy as np

from ..samples.quality import softness
from .viterbi import Viterbi

#: The costs, one unit being a lip opening 0.033 eye distances off the prediction. Chosen
#: on 6 held-out GRID s1 sentences (grid.held_out()[24:30], left out of the figure's
#: sentences), bank of the 10 bank sentences: lip opening r of the chosen samples 0.71-0.73
#: for open 30-60 against 0.66-0.70 at 10 (the prediction itself reaches 0.73: it is the
#: cap); raising the phone-context terms lowered r (0.55-0.69).
#:
#: ================  =====  =========================================================
#: term              cost   why
#: ================  =====  =========================================================
#: open              30     per eye distance of lip opening off the prediction
#: width             4      per eye distance of mouth width off (rounding, spreading)
#: phone_same        0      the sample was said as this very phone
#: phone_viseme      0.3    another phone of the same viseme (its context differs)
#: phone_other       1.5    another viseme's phone (a run continued across a boundary)
#: context           0.15   each of the previous and next phones that differs
#: position          1      per unit of how far into its phone (0-1) the sample is off
#:                          the frame's (a run starts where its phone starts)
#: join              0.3    any cut between two samples that are not source neighbours
#:                          (runs of ~3 frames; 0.5 gave ~4 and r 0.72)
#: lips              1      per mouth width of RMS lip-point distance across a cut
#: look              1      per unit of RMS thumbnail difference (0-1 grey) across a cut
#: blur              10     per unit of the sample's softness (log sharpness below its
#:                          opening's usual: :func:`lipsync.samples.quality.softness`);
#:                          not on closures (see :meth:`Selector.target_cost`)
#: ================  =====  =========================================================
#:
#: ``blur`` (round 5, issue 35): footage of speech holds motion-blurred frames, and among
#: samples that fit equally the crisp one is the better. On the tuning sentences
#: (held_out()[18:30], rendered with the audio target, encoded) weight 0 / 2 / 10 / 40 gave
#: the lips' sharpness 0.866 / 0.872 / 0.914 / 0.919 of the real frames' at lip r 0.766 /
#: 0.767 / 0.769 / 0.767: 10 takes most of the gain. A softness of 0.2 (a fifth softer)
#: then costs 2, an opening 0.033 eye distances off under the audio target's weight. Charged
#: only where a run starts (a run's own soft frames free, as the source's motion blurred
#: them) it kept longer runs (2.80 frames against 2.55 blind and 2.13 charged everywhere)
#: but reached only 0.885 at 10 and 0.876 at 30; charged half within runs, 0.919 at 2.21
#: frames a run. Every frame pays it: a rendered mouth rarely moves as its source did.
WEIGHTS = {"open": 30.0, "width": 4.0, "phone_same": 0.0, "phone_viseme": 0.3, "phone_other": 1.5,
           "context": 0.15, "position": 1.0, "join": 0.3, "lips": 1.0, "look": 1.0, "blur": 10.0}
#: The predicted opening's excursion from rest is scaled by this: medians blended by the
#: dominance weights undershoot the speaker's peaks. On the tuning sentences (joins cut):
#: gain 1.0 / 1.6 / 2.2 gave the rendered opening 0.86 / 1.24 / 1.79 of the real one's
#: standard deviation at r 0.69 / 0.72 / 0.71; 1.3 sits between (the videobank's SPAN_GAIN
#: is 1.5 for the same reason).
TARGET_GAIN = 1.3
#: Share of the target opening taken from the one-picture morph's schedule (the dominance
#: blend of the bank pictures' openings, samples.npz ``picture_opening``: the range rule of
#: lipsync.videobank.select placed them) rather than from the phones' medians. The two err
#: differently: the phones' medians know every sound but undershoot; the pictures follow the
#: timing's blends at the speaker's range. Chosen on held_out()[18:30] (12 sentences), lip
#: opening r of the chosen samples: share 0 / 0.3 / 0.5 / 0.7 / 1 gave 0.720 / 0.739 /
#: 0.762 / 0.759 / 0.741; on held_out()[:18], never tuned on, 0.733 (share 0) -> 0.802 (0.5),
#: the pictures' schedule alone 0.791 there.
PICTURE_SHARE = 0.5
#: Shares (opening, width) of the target taken from the speech's own prediction (the
#: bank's audio lip model, :mod:`lipsync.samples.lipmodel`) where the render has the sound.
#: Chosen on held_out()[18:30] (12 sentences; grid-s1's bank), lip opening r of the chosen
#: samples (share / AUDIO_GAIN / AUDIO_OPEN_WEIGHT): no sound 0.763; 0.2 / 1.5 / 2: 0.778;
#: 0.3 / 1.5 / 2: 0.783; 0.3 / 1.2 / 2: 0.777; 0.3 / 1.5 / 3: 0.787; 0.4 / 1.5 / 3: 0.784;
#: 0.5 / 1.5 / 3: 0.782; 0.5 / 1 / 2: 0.771; 0.7 / 1.5 / 3: 0.774; 0 / 1 / 3 (the weight
#: alone): 0.761; with the joins blended as planned (see AUDIO_OPEN_WEIGHT), 0.3 / 1.5 / 2
#: 0.765, 0.4 / 1.5 / 2 0.741, 0.5 / 1.5 / 2 0.731, 0.3 / 2 / 2 0.746 (no sound 0.745). The
#: target's own r: 0.766 (phones) -> 0.794 (share 0.3), the prediction alone 0.757. The
#: width is left to the phones: the model's width r there is ~0.5.
#: Round 5 (issue 35), target r on the same sentences (0.794 with these constants; selected
#: 0.783): none of these did better by more than 0.005 — a linear blend at any share (0.784-
#: 0.795), a blend learnt over +-1..4 frames of both (0.802-0.811 fitted *on* the sentences
#: themselves: the ceiling of the kind), the model predicting the phones' target's residual
#: (0.773), the phones' target fed to the model (0.791), no share in silence and more in
#: speech (0.789-0.795), the prediction smoothed (0.779-0.792), the dominance timing 0.5 /
#: 0.75 / 1.5 x or its lead 0 / 30 / 50 ms (0.793-0.798), phones valued at their 65th / 80th
#: percentile rather than the median (0.791 / 0.782), the bank's own opening before speech
#: (a speaker parts the lips 4-8 frames before speaking: 0.787), the samples' own sound as a
#: target cost (selected 0.775-0.778). With the real opening put in the silent frames the
#: target would reach 0.827, in the spoken ones 0.960: what is missing is in the speech.
AUDIO_SHARE = (0.3, 0.0)
#: The prediction's excursion from its mean is scaled by this: a ridge regression's
#: prediction undershoots the real range (1.0 left the chosen samples' range at 0.90 of
#: the speaker's, 1.5 at 1.04).
AUDIO_GAIN = 1.5
#: With the speech's prediction in the target, its opening term weighs this many times
#: WEIGHTS["open"]: the phone and context terms were tuned against a target made from the
#: phones themselves, and outweigh a target that disagrees with the phones' usual samples.
#: Heavier follows the target closer but cuts more often, and a cut is morphed (which the
#: chosen samples' own r does not see): on held_out()[18:30], share 0.3, the opening shown
#: once joins are blended as lipsync.selection.plan does (the chosen samples' openings
#: blended by the plan's alpha) had r 0.757 / 0.762 / 0.765 / 0.745 at weight 1 / 1.5 / 2
#: / 3 (runs of 3.1 / 2.7 / 2.5 / 2.1 frames; the phones' target alone 0.745, 3.0); the
#: first bench run at 3 rendered r 0.777 against the phones' target's 0.782. With joins cut
#: (JOIN_FRAMES 0, round 5), the chosen samples' r at weight 1.5 / 2 / 3 / 5: 0.768 / 0.783 /
#: 0.787 / 0.789 (runs 2.8 / 2.6 / 2.2 / 1.9 frames; with WEIGHTS["join"] 0.15: 0.776 / 0.786
#: / 0.789 / 0.789, runs down to 1.6): under 0.01 for a third more joins, so 2 stays.
AUDIO_OPEN_WEIGHT = 2.0
#: Candidates per frame from the viseme's tree: 24 keep the cost of a 10-minute clip's
#: selection to seconds (K^2 joins per frame).
NEAREST = 24
#: Runs followed from the previous frame: its cheapest candidates' successors.
FOLLOW = 16
#: A sample's lips count as closed at most this inner-lip gap (eye distances): GRID s1's
#: P/B/M frames measure a median 0.01, and 0.03 is a visibly parted lip.
CLOSED = 0.03


class Tree:
    """Exact k nearest neighbours with OpenCV's FLANN single k-d tree (already a dependency;
    ``checks=-1``: unlimited, so the search is exact, not approximate).

    Examples
    --------
    >>> t = Tree(np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 5.0]]))
    >>> t.query([0.9, 0.1], k=2)[1].tolist()
    [1, 0]
    """

    def __init__(self, points: np.ndarray):
        import cv2

        self._data = np.ascontiguousarray(points, np.float32)
        self._index = cv2.flann_Index(self._data, dict(algorithm=4, leaf_max_size=10))  # KDTREE_SINGLE

    def query(self, point, k: int):
        """``(distances, indices)`` of the ``k`` points nearest ``point``, nearest first."""
        q = np.asarray(point, np.float32).reshape(1, -1)
        idx, dist = self._index.knnSearch(q, int(k), params=dict(checks=-1))
        return np.sqrt(dist[0]), idx[0].astype(np.int64)


@dataclass
class Target:
    """What each frame should show (arrays of one row per frame)."""

    phone: np.ndarray      # str
    prev: np.ndarray
    next: np.ndarray
    viseme: np.ndarray     # the viseme the sequencer shows (the nearer of from/to)
    opening: np.ndarray    # predicted, eye distances
    width: np.ndarray
    closed: np.ndarray     # bool: must show closed lips
    rest: np.ndarray       # bool: silence at rest
    position: np.ndarray = None  # how far into its phone each frame is, 0-1
    open_weight: float = 1.0     # the opening term's weight over WEIGHTS["open"] (AUDIO_OPEN_WEIGHT with sound)


@dataclass
class Selection:
    """The chosen samples and how the choice was made."""

    samples: np.ndarray                 # (T,) sample index per frame
    target: Target
    seconds: float = 0.0
    candidates: float = 0.0             # mean candidates per frame
    cost: float = 0.0
    joins: np.ndarray = field(default=None)  # bool (T,): frame t is not frame t-1's source successor

    def runs(self) -> float:
        """Mean length of the runs of consecutive source frames shown."""
        return len(self.samples) / max(1, int(self.joins.sum()) + 1)


def frame_phones(timeline, n: int, fps: float):
    """Per frame, the phone at its time and its neighbours (``sil`` for silence; a viseme
    timeline's labels stand in for phones)."""
    from ..samples.build import phone_rows

    return [np.array(x) for x in phone_rows(timeline, n, fps)]


def positions(labels: np.ndarray, breaks: Optional[np.ndarray] = None) -> np.ndarray:
    """How far into its stretch of one label each entry is: ``(k + 0.5) / length`` for the
    k-th of a stretch; a stretch also ends where ``breaks`` (bool, "starts anew here") says.

    Examples
    --------
    >>> positions(np.array(["a", "a", "b", "b", "b", "b"])).tolist()
    [0.25, 0.75, 0.125, 0.375, 0.625, 0.875]
    """
    n = len(labels)
    start = np.ones(n, bool)
    start[1:] = labels[1:] != labels[:-1]
    if breaks is not None:
        start |= breaks
    first = np.maximum.accumulate(np.where(start, np.arange(n), 0))
    ends = np.r_[np.nonzero(start)[0][1:], n]
    length = (ends - np.nonzero(start)[0])[np.cumsum(start) - 1]
    return (np.arange(n) - first + 0.5) / length


def shown(spec) -> str:
    """The viseme a frame shows most of."""
    return spec.from_viseme if spec.alpha < 0.5 else spec.to_viseme


def viseme_of(labels: np.ndarray, pmap, rest: str) -> np.ndarray:
    """The map's (first) viseme of each phone label (the rest viseme for silence and unknown labels)."""
    out = {}
    for lab in set(labels.tolist()):
        got = None if lab == "sil" else pmap.targets(lab)
        out[lab] = got[0] if got else rest
    return np.array([out[x] for x in labels.tolist()])


def make_target(samples, specs, timeline, fps: float, pmap, rest: str, closures: Sequence[str],
                params=None, audio: Optional[np.ndarray] = None) -> Target:
    """The :class:`Target` of a render's frames (``specs``, the sequencer's) and phones.

    The predicted lip opening and width are the dominance model's schedule *of the phones*
    (:func:`phone_schedule`: each phone its own shape, valued at its samples' median) when
    the timeline has phones, else of the visemes (``specs``); where the table has the
    pictures' openings, the opening is blended with the pictures' schedule
    (:data:`PICTURE_SHARE`). ``audio``, ``(frames, 2)``: the opening and width the speech
    predicts (:meth:`lipsync.samples.lipmodel.LipModel.predict`), blended in by
    :data:`AUDIO_SHARE` (None: the phones' target alone)."""
    from ..motion.coarticulation import predicted

    n = len(specs)
    phone, prev, nxt = frame_phones(timeline, n, fps)
    view = np.array([shown(s) for s in specs])
    closed = np.array([(s.from_viseme in closures and s.alpha <= 0.2) or (s.to_viseme in closures and s.alpha >= 0.8)
                       for s in specs], bool)
    by_phone = phone_schedule(samples, timeline, n, fps, pmap, rest, closures, params)
    if by_phone is not None:
        opening, width = by_phone
        rest_open = _groups(samples).rest_opening() if MEMO_MEDIANS else _rest_opening(samples.labels, samples.opening)
        opening = rest_open + TARGET_GAIN * (opening - rest_open)
        pictures = picture_openings(samples)
        if pictures and all(s.from_viseme in pictures and s.to_viseme in pictures for s in specs):
            opening = (1.0 - PICTURE_SHARE) * opening + PICTURE_SHARE * predicted(specs, pictures)
    else:
        values = _medians(samples, viseme_of(samples.labels, pmap, rest),
                          {s.from_viseme for s in specs} | {s.to_viseme for s in specs}, closures)
        opening = predicted(specs, {v: x[0] for v, x in values.items()})
        width = predicted(specs, {v: x[1] for v, x in values.items()})
    heard = audio is not None and n > 0
    if heard:
        opening, width = with_audio(opening, width, audio)
    return Target(phone=phone, prev=prev, next=nxt, viseme=view, opening=opening, width=width, closed=closed,
                  rest=(view == rest) & (phone == "sil"), position=positions(phone),
                  open_weight=AUDIO_OPEN_WEIGHT if heard else 1.0)


def with_audio(opening: np.ndarray, width: np.ndarray, audio: np.ndarray):
    """The target ``opening`` and ``width`` blended with the speech's prediction ``audio``
    (``(frames, 2)``; a shorter one's last row repeated) by :data:`AUDIO_SHARE`, the
    prediction's excursion from its mean scaled by :data:`AUDIO_GAIN`.

    Examples
    --------
    >>> o, w = with_audio(np.zeros(2), np.ones(2), np.array([[0.2, 1.0], [0.4, 1.0]]))
    >>> bool(np.allclose(o, AUDIO_SHARE[0] * (0.3 + AUDIO_GAIN * np.array([-0.1, 0.1])))), w.tolist()
    (True, [1.0, 1.0])
    """
    a = np.asarray(audio, np.float64)[:len(opening)]
    if len(a) < len(opening):
        a = np.vstack([a, np.repeat(a[-1:], len(opening) - len(a), axis=0)])
    a = a.mean(axis=0) + AUDIO_GAIN * (a - a.mean(axis=0))
    return ((1.0 - AUDIO_SHARE[0]) * opening + AUDIO_SHARE[0] * a[:, 0],
            (1.0 - AUDIO_SHARE[1]) * width + AUDIO_SHARE[1] * a[:, 1])


def picture_openings(samples) -> Dict[str, float]:
    """``viseme -> its picture's lip opening`` from the table (empty for a table without them).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> picture_openings(SimpleNamespace(table={"pictures": np.array(["A", "D"]),
    ...                                         "picture_opening": np.array([0.01, 0.2])}))
    {'A': 0.01, 'D': 0.2}
    """
    t = samples.table
    if "pictures" not in t:
        return {}
    return {str(v): float(x) for v, x in zip(t["pictures"].tolist(), t["picture_opening"].tolist())}


def _medians(samples, keys: np.ndarray, wanted, closed_keys) -> Dict[str, tuple]:
    """``key -> (median opening, median width)`` of the samples whose ``keys`` equal it (the
    closed ones for ``closed_keys``); every sample's median where none has it."""
    out = {}
    for v in wanted:
        mine = keys == v
        if v in closed_keys:
            mine &= samples.opening <= CLOSED
        pick = mine if mine.any() else slice(None)
        out[v] = (float(np.median(samples.opening[pick])), float(np.median(samples.width[pick])))
    return out


#: Whether :func:`phone_schedule` takes its medians from the samples' memo (:func:`_groups`);
#: False computes them afresh at every call (the benchmark's "before", the tests' reference).
MEMO_MEDIANS = True


class _Groups:
    """One samples table's (opening, width) medians per group of its phones, each computed
    once: a live session makes a target for every look-ahead window from the same samples,
    and recomputing the medians was most of a window's cost (5.6 ms of its 14.5 ms a frame).
    A group is a set of phone labels (one phone, or the phones of a viseme), all its samples
    or only the closed ones; the value is :func:`_medians`' for the same samples.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> s = SimpleNamespace(labels=np.array(["a", "b", "a", "c"]), opening=np.array([0.0, 0.25, 0.5, 0.75]),
    ...                     width=np.array([1.0, 2.0, 3.0, 4.0]))
    >>> g = _Groups(s)
    >>> g.medians(("a",), False), g.medians(("a",), True), g.medians(("a", "b"), False), g.medians(("z",), False)
    ((0.25, 2.0), (0.0, 1.0), (0.25, 2.0), (0.375, 2.5))
    """

    def __init__(self, samples):
        self.names, self.inverse = np.unique(np.asarray(samples.labels), return_inverse=True)
        self.inverse = self.inverse.reshape(-1)
        self.index = {str(x): k for k, x in enumerate(self.names.tolist())}
        self.opening, self.width = samples.opening, samples.width
        self._done: Dict[tuple, tuple] = {}

    def medians(self, labels: tuple, closed: bool) -> tuple:
        """``(median opening, median width)`` of the samples of ``labels`` (only those with
        closed lips when ``closed``), every sample's where there are none."""
        key = (labels, bool(closed))
        got = self._done.get(key)
        if got is None:
            codes = [self.index[x] for x in labels if x in self.index]
            mine = np.isin(self.inverse, codes)
            if closed:
                mine &= self.opening <= CLOSED
            pick = mine if mine.any() else slice(None)
            got = self._done[key] = (float(np.median(self.opening[pick])), float(np.median(self.width[pick])))
        return got


    def rest_opening(self) -> float:
        """:func:`_rest_opening` of these samples, computed once (every window's target reads
        it, and it scans the whole table)."""
        got = self._done.get("rest")
        if got is None:
            got = self._done["rest"] = _rest_opening(self.names[self.inverse], self.opening)
        return got


def _rest_opening(labels: np.ndarray, opening: np.ndarray) -> float:
    """The lips' opening at rest: the median of the silent samples with closed lips (0 when
    the footage has none).

    Examples
    --------
    >>> _rest_opening(np.array(["sil", "sil", "a", "sil"]), np.array([0.01, 0.03, 0.0, 0.2]))
    0.02
    >>> _rest_opening(np.array(["a"]), np.array([0.01]))
    0.0
    """
    quiet = (np.asarray(labels) == "sil") & (opening <= CLOSED)
    return float(np.median(opening[quiet])) if quiet.any() else 0.0


#: id(samples) -> (weak reference to it, the arrays read, its _Groups): see :func:`_groups`.
_GROUPS: Dict[int, tuple] = {}
_GROUPS_LOCK = threading.Lock()


def _groups(samples) -> "_Groups":
    """The memo of ``samples``' medians (:class:`_Groups`), one per samples object while it
    lives: a bank's samples are loaded once per process and never change (a live session's
    windows, every utterance of a batch). Keyed on the object and the opening and width
    arrays it holds (a table whose arrays were replaced is a new memo); an object that
    takes no weak reference gets a fresh one each call."""
    try:
        ref = weakref.ref(samples)
    except TypeError:
        return _Groups(samples)
    arrays = (id(samples.opening), id(samples.width))
    with _GROUPS_LOCK:
        got = _GROUPS.get(id(samples))
        if got is not None and got[0]() is samples and got[1] == arrays:
            return got[2]
        for k in [k for k, v in _GROUPS.items() if v[0]() is None]:
            del _GROUPS[k]
        groups = _Groups(samples)
        _GROUPS[id(samples)] = (ref, arrays, groups)
        return groups


def phone_schedule(samples, timeline, n: int, fps: float, pmap, rest: str, closures: Sequence[str], params=None):
    """``(opening, width)`` per frame predicted by the dominance model run over the *phones*
    (:func:`lipsync.motion.coarticulation.dominance_sequence`, each phone its own shape with its
    viseme's class; silence the rest), each phone valued at its samples' median: every sound
    its own real opening rather than its viseme's. None for a timeline of visemes.

    The medians come from the samples' memo (:func:`_groups`, :data:`MEMO_MEDIANS`): a window
    of a live session costs its own phones' dominance, not the samples' statistics again."""
    from ..motion.coarticulation import DEFAULT_PARAMS, VisemeClasses, dominance_sequence, predicted, viseme_classes
    from ..motion.timeline import Segment, Timeline
    from ..samples.build import SILENCE, phone_label

    if getattr(timeline, "kind", "phoneme") != "phoneme" or not len(timeline):
        return None
    segs = [Segment(seg.start, seg.end, phone_label(seg.label)) for seg in timeline.segments]
    segs = [seg for seg in segs if seg.label != SILENCE]
    labels = sorted({s.label for s in segs})
    vis = dict(zip(labels, viseme_of(np.array(labels), pmap, rest).tolist())) if labels else {}
    vclass = viseme_classes(pmap, rest)
    classes = VisemeClasses({p: vclass.get(v, "other") for p, v in vis.items()})
    classes[SILENCE] = "rest"
    shut = [p for p, v in vis.items() if v in closures]
    specs = dominance_sequence(Timeline(tuple(segs), kind="viseme"), fps=fps, rest=SILENCE, closures=shut,
                               classes=classes, params=params if params is not None else DEFAULT_PARAMS,
                               duration=n / fps)[:n]
    values = _phone_values(samples, labels, vis, shut, pmap, rest, closures)
    return predicted(specs, {k: x[0] for k, x in values.items()}), predicted(specs, {k: x[1] for k, x in values.items()})


def _phone_values(samples, labels, vis, shut, pmap, rest: str, closures) -> Dict[str, tuple]:
    """``phone -> (median opening, median width)`` for :func:`phone_schedule`: each phone's
    samples (the closed ones for a closure and silence), a phone the footage never said its
    viseme's samples."""
    from ..samples.build import SILENCE

    if not MEMO_MEDIANS:
        values = _medians(samples, samples.labels, set(labels) | {SILENCE}, set(shut) | {SILENCE})
        for p in labels:
            if not (samples.labels == p).any():
                values[p] = _medians(samples, viseme_of(samples.labels, pmap, rest), {vis[p]}, closures)[vis[p]]
        return values
    g = _groups(samples)
    closed = set(shut) | {SILENCE}
    values = {p: g.medians((p,), p in closed) for p in set(labels) | {SILENCE}}
    unseen = [p for p in labels if p not in g.index]
    if unseen:   # a phone the footage never said: its viseme's samples (the phones of that viseme)
        of = dict(zip(g.index, viseme_of(g.names.astype(str), pmap, rest).tolist()))
        for p in unseen:
            values[p] = g.medians(tuple(sorted(x for x, v in of.items() if v == vis[p])), vis[p] in closures)
    return values


#: Join features kept: the principal components holding this share of their variance (the
#: 88 lip coordinates and 192 thumbnail pixels of GRID s1's samples: 99% in ~40 of 280), so
#: each frame's K x K distances cost a fifth.
JOIN_VARIANCE = 0.99


def _principal(features: np.ndarray) -> np.ndarray:
    """``features`` in the basis of their principal components, the fewest holding
    :data:`JOIN_VARIANCE` of the variance (distances between rows kept to that share).

    Examples
    --------
    >>> x = np.c_[np.arange(10.0), np.zeros(10), np.arange(10.0)]
    >>> y = _principal(x)
    >>> y.shape, round(float(np.linalg.norm(y[3] - y[7])), 6) == round(float(np.linalg.norm(x[3] - x[7])), 6)
    ((10, 1), True)
    """
    centred = features - features.mean(axis=0)
    _, sv, vt = np.linalg.svd(centred, full_matrices=False)
    share = np.cumsum(sv ** 2) / max(float((sv ** 2).sum()), 1e-300)
    k = int(np.searchsorted(share, JOIN_VARIANCE)) + 1
    return np.ascontiguousarray(centred @ vt[:k].T)


class Selector:
    """A bank's samples made ready for selection under one phoneme map: per viseme (and per
    viseme's closed and rest subsets) a k-d tree (:class:`Tree`) over (opening, width) scaled by their weights,
    and the join features. Built once per bank and map; :meth:`select` per utterance."""

    def __init__(self, samples, pmap, rest: str, closures: Sequence[str] = ()):
        self.samples, self.pmap, self.rest, self.closures = samples, pmap, rest, tuple(closures)
        self.succ = samples.successor()
        self.vis = viseme_of(samples.labels, pmap, rest)
        self.labels = samples.labels
        self.prev_labels = samples.phones[samples.prev]
        self.next_labels = samples.phones[samples.next]
        breaks = np.r_[True, samples.run[1:] != samples.run[:-1]]
        self.position = positions(self.labels, breaks)
        self.point = np.stack([samples.opening * WEIGHTS["open"], samples.width * WEIGHTS["width"]], axis=1)
        self.softness = softness(samples)
        lips = samples.lips.reshape(len(samples), -1).astype(np.float64)
        scale = float(np.median(np.ptp(samples.lips[..., 0], axis=1))) or 1.0  # mouth width, bank pixels
        # lips and thumbnails scaled so that a squared distance is the join's squared cost
        feats = np.concatenate([lips * (WEIGHTS["lips"] / scale / np.sqrt(lips.shape[1] / 2)),
                                samples.appearance.astype(np.float64) * (WEIGHTS["look"] /
                                                                         np.sqrt(samples.appearance.shape[1]))], axis=1)
        self.join_features = _principal(feats)
        # labels as integer codes: the per-frame comparisons are of ints, not strings
        self._codes: Dict[str, int] = {}
        self.c_phone, self.c_prev, self.c_next, self.c_vis = (self.encode(x) for x in (
            self.labels, self.prev_labels, self.next_labels, self.vis))
        closed = samples.opening <= CLOSED
        silent = self.labels == "sil"
        self._pools = {}
        for v in set(self.vis.tolist()) | {rest}:
            for kind, mask in (("any", self.vis == v), ("closed", (self.vis == v) & closed),
                               ("rest", (self.vis == v) & silent & closed)):
                idx = np.nonzero(mask)[0]
                if idx.size:
                    self._pools[(v, kind)] = (idx, Tree(self.point[idx]))
        everything = np.arange(len(samples))
        self._pools[("*", "any")] = (everything, Tree(self.point))
        closed_all = np.nonzero(closed)[0]
        self._pools[("*", "closed")] = (closed_all, Tree(self.point[closed_all])) if closed_all.size else \
            self._pools[("*", "any")]

    def encode(self, labels: np.ndarray) -> np.ndarray:
        """Labels as integer codes (a label first seen gets the next code)."""
        return np.array([self._codes.setdefault(x, len(self._codes)) for x in labels.tolist()], np.int32)

    def pool(self, viseme: str, kind: str):
        """The samples a frame may take and their tree: the viseme's (closed or at rest when
        the frame must be), else any viseme's closed ones, else all (a sound with no sample)."""
        order = {"any": ((viseme, "any"), ("*", "any")), "closed": ((viseme, "closed"), ("*", "closed")),
                 "rest": ((viseme, "rest"), (viseme, "closed"), ("*", "closed"))}[kind]
        for key in order:
            if key in self._pools:
                return self._pools[key]
        raise AssertionError("unreachable: the '*' pools always exist")

    def allowed(self, ids: np.ndarray, kind: str) -> np.ndarray:
        """Which of ``ids`` (the next frames of runs) a frame of ``kind`` (any, closed, rest)
        may show: for a closure any closed lips, not only its viseme's (a run of silence's
        closed, relaxed lips may continue into an M). Kept to the viseme's own closed samples,
        GRID's tuning sentences did not change (r 0.769 -> 0.766; 2 of 42 closure frames had
        shown silence), but a small bank lost closures: movie-hello's 87 samples, P/B/M frames
        closed 1.0 -> 0.93 rendered and 0.6 -> 0.2 dubbed (few closed samples of its own M)."""
        if kind == "any":
            return np.ones(len(ids), bool)
        ok = self.samples.opening[ids] <= CLOSED
        return ok & (self.labels[ids] == "sil") if kind == "rest" else ok

    def target_cost(self, ids: np.ndarray, tg: Target, t: int, codes=None) -> np.ndarray:
        """The target cost of each of ``ids`` at frame ``t`` (see :data:`WEIGHTS`); ``codes``:
        the target's phone, prev, next and viseme codes (:meth:`encode`), made once per utterance."""
        w = WEIGHTS
        if codes is None:
            codes = tuple(self.encode(x) for x in (tg.phone, tg.prev, tg.next, tg.viseme))
        phone_c, prev_c, next_c, vis_c = codes
        d = np.abs(self.point[ids] - [tg.opening[t] * w["open"], tg.width[t] * w["width"]]) @ [tg.open_weight, 1.0]
        phone = np.where(self.c_phone[ids] == phone_c[t], w["phone_same"],
                         np.where(self.c_vis[ids] == vis_c[t], w["phone_viseme"], w["phone_other"]))
        ctx = w["context"] * ((self.c_prev[ids] != prev_c[t]).astype(float) +
                              (self.c_next[ids] != next_c[t]).astype(float))
        where = w["position"] * np.abs(self.position[ids] - tg.position[t])
        # a closure is exempt: lips pressing for P/B/M move fast, so the footage's pressed
        # frames are the soft ones, and charging them chose still, relaxed lips instead (GRID
        # dubs, 9 held-out pairs: 16 of 17 closures as closed as the real speaker's, 17 exempt;
        # the render's lips on held_out()[:18] 0.917 -> 0.907, r 0.827 -> 0.822)
        blur = 0.0 if tg.closed[t] else w["blur"]
        return d + phone + ctx + where + blur * self.softness[ids]

    def join_cost(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``(len(a), len(b))``: the cost of showing sample ``b[j]`` after ``a[i]`` (0 when
        ``b[j]`` is ``a[i]``'s next frame in the source)."""
        fa, fb = self.join_features[a], self.join_features[b]
        d2 = (fa * fa).sum(1)[:, None] + (fb * fb).sum(1)[None, :] - 2.0 * fa @ fb.T
        cost = WEIGHTS["join"] + np.sqrt(np.maximum(d2, 0.0))
        cost[self.succ[a][:, None] == b[None, :]] = 0.0
        return cost

    def candidates(self, tg: Target, t: int, v: Optional[Viterbi]) -> np.ndarray:
        """Frame ``t``'s candidates: the nearest of its pool, and the successors of the
        previous frame's cheapest candidates that the frame allows."""
        kind = "closed" if tg.closed[t] else "rest" if tg.rest[t] else "any"
        idx, tree = self.pool(tg.viseme[t], kind)
        k = min(NEAREST, len(idx))
        _, near = tree.query([tg.opening[t] * WEIGHTS["open"], tg.width[t] * WEIGHTS["width"]], k=k)
        ids = idx[np.atleast_1d(near)]
        if v is not None and len(v):
            order = np.argsort(v.costs)[:FOLLOW]
            nxt = self.succ[v.last[order]]
            nxt = nxt[nxt >= 0]
            ids = np.concatenate([ids, nxt[self.allowed(nxt, kind)]])
        return np.unique(ids)

    def select(self, specs, timeline, fps: float, params=None, audio=None) -> Selection:
        """One sample per frame of ``specs`` (the sequencer's schedule) for the phones of
        ``timeline``; ``params``: the dominance model's constants (the bank's); ``audio``:
        the speech's predicted opening and width per frame (:func:`make_target`)."""
        t0 = time.perf_counter()
        tg = make_target(self.samples, specs, timeline, fps, self.pmap, self.rest, self.closures, params, audio)
        v = Viterbi()
        count = 0
        codes = tuple(self.encode(x) for x in (tg.phone, tg.prev, tg.next, tg.viseme))
        for t in range(len(specs)):
            ids = self.candidates(tg, t, v)
            count += len(ids)
            v.step(ids, self.target_cost(ids, tg, t, codes), None if t == 0 else self.join_cost(v.last, ids))
        path = np.array(v.path(), np.int64)
        joins = np.ones(len(path), bool)
        if len(path) > 1:
            joins[1:] = self.succ[path[:-1]] != path[1:]
        return Selection(samples=path, target=tg, seconds=time.perf_counter() - t0,
                         candidates=count / max(1, len(specs)), cost=v.cost if len(path) else 0.0, joins=joins)
