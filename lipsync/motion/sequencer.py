"""The sequencer: a viseme timeline becomes one :class:`FrameSpec` per output frame.

Frame ``n`` shows time ``n / fps``; a timeline of duration D gives ``ceil(D * fps)`` frames.
Each frame is a morph between two visemes at some alpha (alpha 0 shows ``from_viseme``,
alpha 1 shows ``to_viseme``); a frame that shows one viseme exactly is
``FrameSpec(v, v, 0.0)``.

How a timeline is turned into frames (Rhubarb Lip Sync's ``src/animation`` is the model:
a few small passes, each with one rule):

1. gaps (time with no label) become the rest viseme;
2. adjacent equal visemes merge;
3. a pause shorter than ``MAX_HELD_PAUSE_S`` between two spoken visemes holds the viseme
   before it; longer pauses return to rest;
4. a segment shorter than ``MIN_SEGMENT_S`` is dropped, its time split between its
   neighbours at its midpoint (it would only be a flicker); closures and rest (leading or
   trailing silence) are never dropped;
5. every boundary gets a transition of at most ``MAX_TRANSITION_S``, centred on the boundary,
   but never starting before the source segment's hold window nor ending after the target's:
   a segment of 200 ms or more therefore holds its viseme exactly for
   ``2 * HOLD_HALF_WIDTH_S`` around its midpoint, and every transition reaches its target
   no later than the target segment's midpoint;
6. alpha inside a transition follows the timing curve (:mod:`lipsync.motion.timing`);
7. a closure (e.g. the closed-lips viseme for P, B, M) that no frame shows exactly gets the
   frame nearest its midpoint forced to it, so lips always close fully even when the
   closure is shorter than a frame.

The rules, as data with the reason for each, are in :data:`RULES`.

Examples
--------
>>> from lipsync.motion.timeline import Segment, Timeline
>>> tl = Timeline((Segment(0, 0.4, "X"), Segment(0.4, 0.8, "A"), Segment(0.8, 1.2, "X")), kind="viseme")
>>> frames = sequence(tl, fps=10, rest="X")
>>> len(frames), frames[0], frames[6]
(12, FrameSpec(from_viseme='X', to_viseme='X', alpha=0.0), FrameSpec(from_viseme='A', to_viseme='A', alpha=0.0))
"""

from __future__ import annotations

import heapq
import math
from typing import Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from ._plan_kernel import plan_arrays
from .coarticulation import as_params, dominance_sequence
# FrameSpec and the frame arithmetic live below both timing models; imported here as they
# always were (lipsync.motion.sequencer.FrameSpec etc.).
from .frames import FPS_RANGE, MAX_FRAMES, FrameSpec, base_track, check_fps, checked_frames, frame_count, merge  # noqa: F401  # noqa: F401
from .timeline import Segment, Timeline
from .timing import DEFAULT_CURVE, Curve, get_curve, is_model

# --- tuning constants (seconds) -------------------------------------------------------------

# Longest transition between two visemes. Lip and jaw movements between speech postures
# take roughly 100-150 ms; longer morphs make speech look mushy, shorter ones look like cuts.
MAX_TRANSITION_S = 0.12

# Half-width of the window around a segment's midpoint that must show the viseme exactly,
# for segments long enough (>= MAX_TRANSITION_S + 2 * HOLD_HALF_WIDTH_S = 200 ms). 40 ms is
# one frame at 25 fps either side of the midpoint, so a 200 ms sound is seen for 3 frames.
HOLD_HALF_WIDTH_S = 0.04

# Pauses shorter than this between spoken sounds hold the previous mouth shape: speakers do
# not relax the mouth for a stop gap or a quick breath, and dropping to rest and back within
# a few frames looks like chattering. Equal to the "long segment" length above, so a pause
# long enough to be shown at all is also long enough to be shown fully.
MAX_HELD_PAUSE_S = 0.2

# Non-closure segments shorter than this are dropped: lips cannot visibly reach a shape in
# under 50 ms (about one frame at 24 fps), so showing it only adds a one-frame flicker.
MIN_SEGMENT_S = 0.05
# Tracks with at least this many segments are planned on arrays (lipsync.motion._plan_kernel:
# numpy and a numba-compiled rule 4, the same plan): below it the segment-by-segment code is
# quicker than numba's import (~0.3 s), which the live animator, planning a few seconds at a
# time, must not pay; above it, that code's ~10 us a segment dominates (3.6 million 10 ms
# cues, a 10-hour track, took ~50 s).
ARRAY_PLAN_FROM = 20_000

# Numerical slack when comparing alphas and times (float noise, not a tuning value).
_EPS = 1e-9

# The rules as a literal table: (name, rule, reason). Documentation and the CLI's --help
# read it; the code above and below implements each row.
RULES: Tuple[Tuple[str, str, str], ...] = (
    ("gaps", "time with no label shows the rest viseme",
     "readers leave unlabelled time as gaps; silence is the rest shape"),
    ("merge", "adjacent equal visemes merge into one segment",
     "a morph from a shape to itself is a still frame; merging keeps holds long"),
    ("short-pause-hold", f"pauses < {MAX_HELD_PAUSE_S * 1000:.0f} ms between sounds hold the previous viseme",
     "speakers do not relax the mouth in short gaps; rest-and-back looks like chattering"),
    ("long-pause-rest", f"pauses >= {MAX_HELD_PAUSE_S * 1000:.0f} ms (and leading/trailing silence) show rest",
     "the mouth relaxes when the speaker stops"),
    ("drop-short", f"non-closure, non-rest segments < {MIN_SEGMENT_S * 1000:.0f} ms are dropped",
     "too short to be reached; showing them would flash for a frame"),
    ("closures-kept", "closure visemes are never dropped and are shown exactly on at least one frame",
     "a P, B or M without closed lips is the most visible lip-sync error"),
    ("bounded-transition", f"transitions last at most {MAX_TRANSITION_S * 1000:.0f} ms, centred on the boundary",
     "real articulator movements take about 100-150 ms"),
    ("reach-by-mid", "a transition reaches its target no later than the target segment's midpoint",
     "every sound must be seen; arriving late lags the audio"),
    ("hold-long", f"segments >= {(MAX_TRANSITION_S + 2 * HOLD_HALF_WIDTH_S) * 1000:.0f} ms hold their viseme "
     f"exactly for +-{HOLD_HALF_WIDTH_S * 1000:.0f} ms around the midpoint",
     "long sounds must read as a clear shape, not a permanent blend"),
    ("timing-curve", "alpha within a transition follows the timing curve (default sqrt-fast-middle)",
     "slow in, slow out: real mouths accelerate and decelerate"),
)


def plan_segments(visemes: Timeline, *, rest: str, closures: Iterable[str] = (),
                  max_held_pause: float = MAX_HELD_PAUSE_S, min_segment: float = MIN_SEGMENT_S,
                  duration: Optional[float] = None, start: float = 0.0) -> List[Tuple[float, float, str]]:
    """Rules 1-4: the cleaned viseme track (start, end, viseme) that covers [start, duration].

    ``start`` (default 0) is where the track begins; the live animator
    (:mod:`lipsync.live`) plans from a cut point with it, on segments that begin there.

    Examples
    --------
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> tl = Timeline((Segment(0.2, 0.5, "A"), Segment(0.6, 0.9, "D")), kind="viseme")
    >>> plan_segments(tl, rest="X", duration=1.0)
    [(0.0, 0.2, 'X'), (0.2, 0.6, 'A'), (0.6, 0.9, 'D'), (0.9, 1.0, 'X')]
    """
    closure_set = set(closures)
    if len(visemes) >= ARRAY_PLAN_FROM:
        total = visemes.duration if duration is None else float(duration)
        return plan_arrays(visemes, rest=rest, closures=closure_set, max_held_pause=max_held_pause,
                           min_segment=min_segment, total=total, start=start)
    segs = base_track(visemes, rest=rest, duration=duration, start=start)   # rules 1-2
    # Rule 3: short pauses between sounds hold the previous viseme.
    held: List[Segment] = []
    for i, s in enumerate(segs):
        inner = 0 < i < len(segs) - 1
        if s.label == rest and inner and s.duration < max_held_pause:
            held.append(Segment(s.start, s.end, held[-1].label))
        else:
            held.append(s)
    return _drop_short(merge(held), rest=rest, closures=closure_set, min_segment=min_segment)  # rule 4


def _drop_short(segs: List[Segment], *, rest: str, closures, min_segment: float
                ) -> List[Tuple[float, float, str]]:
    """Rule 4: drop short non-closure segments, shortest first, so that a run of short ones
    keeps the longest of them; the freed time goes half to each neighbour.

    A heap of candidates over a linked list, so n log n: the list-scanning loop it replaces
    was quadratic (40k alternating 10 ms cues took over 100 s). Ties go to the earliest
    segment, as that loop's ``min`` did: a segment keeps the index it started with (a merge
    keeps the left one's), and indices stay in track order.
    """
    n = len(segs)
    lo = [s.start for s in segs]
    hi = [s.end for s in segs]
    label = [s.label for s in segs]
    prev = list(range(-1, n - 1))
    nxt = list(range(1, n)) + [-1] if n else []
    version = [0] * n  # bumped when a segment changes; -1 once it is gone
    alive, head = n, 0

    def candidate(i: int) -> bool:
        # Rest is exempt: inner pauses that survive rule 3 are long, and leading or trailing
        # silence, however short, keeps the first and last frames at rest.
        return hi[i] - lo[i] < min_segment and label[i] not in closures and label[i] != rest

    heap = [(hi[i] - lo[i], i, 0) for i in range(n) if candidate(i)]
    heapq.heapify(heap)
    while alive > 1 and heap:
        _, i, ver = heapq.heappop(heap)
        if ver != version[i]:
            continue  # a stale entry: the segment grew or went since
        version[i] = -1
        alive -= 1
        a, b = prev[i], nxt[i]
        if a < 0:
            lo[b], head = lo[i], b
        elif b < 0:
            hi[a] = hi[i]
        else:
            mid = 0.5 * (lo[i] + hi[i])
            hi[a], lo[b] = mid, mid
        if a >= 0:
            nxt[a] = b
        if b >= 0:
            prev[b] = a
        if a >= 0 and b >= 0 and label[a] == label[b]:
            hi[a] = hi[b]          # rule 2 again: the neighbours now touch
            nxt[a] = nxt[b]
            if nxt[b] >= 0:
                prev[nxt[b]] = a
            version[b] = -1
            alive -= 1
        for j in (a, b):
            if j >= 0 and version[j] >= 0:
                version[j] += 1
                if candidate(j):
                    heapq.heappush(heap, (hi[j] - lo[j], j, version[j]))
    out: List[Tuple[float, float, str]] = []
    i = head if n else -1
    while i >= 0:
        out.append((lo[i], hi[i], label[i]))
        i = nxt[i]
    return out


def plan_transitions(segments: Sequence[Tuple[float, float, str]], *,
                     max_transition: float = MAX_TRANSITION_S,
                     hold_half_width: float = HOLD_HALF_WIDTH_S) -> np.ndarray:
    """Rule 5: transition windows, an array ``(len(segments) - 1, 2)`` of (t0, t1) per boundary.

    Transition k goes from segment k to segment k+1. It is centred on their boundary and at
    most ``max_transition`` long, but starts no earlier than segment k's hold window ends and
    ends no later than segment k+1's hold window starts. The hold window of a segment is
    ``mid ± h`` with ``h = clip(length/2 - max_transition/2, 0, hold_half_width)``: long
    segments hold around their midpoint, short ones are touched exactly at it.

    Examples
    --------
    >>> plan_transitions([(0, 1, "X"), (1, 1.05, "A"), (1.05, 2, "X")]).round(3).tolist()
    [[0.94, 1.025], [1.025, 1.11]]
    """
    if len(segments) < 2:
        return np.zeros((0, 2))
    seg = np.asarray([(s, e) for s, e, _ in segments], dtype=np.float64)
    mid = seg.mean(axis=1)
    half = np.clip((seg[:, 1] - seg[:, 0]) / 2 - max_transition / 2, 0.0, hold_half_width)
    hold_lo, hold_hi = mid - half, mid + half
    boundary = seg[1:, 0]
    t0 = np.maximum(boundary - max_transition / 2, hold_hi[:-1])
    t1 = np.minimum(boundary + max_transition / 2, hold_lo[1:])
    return np.stack([t0, t1], axis=1)


def sequence(visemes: Timeline, *, fps: float, rest: str, timing: Union[str, Curve, object] = DEFAULT_CURVE,
             closures: Iterable[str] = (), duration: Optional[float] = None,
             max_transition: float = MAX_TRANSITION_S, hold_half_width: float = HOLD_HALF_WIDTH_S,
             max_held_pause: float = MAX_HELD_PAUSE_S, min_segment: float = MIN_SEGMENT_S,
             classes=None) -> List[FrameSpec]:
    """Turn a viseme timeline into one FrameSpec per output frame.

    Parameters
    ----------
    visemes : Timeline
        A timeline of kind "viseme" (map phoneme timelines first with
        :func:`lipsync.phonetics.phonemes.map_timeline`). Gaps are silence.
    fps : float
        Output frame rate, 1 to 120. Frame n shows time n / fps.
    rest : str
        The viseme for silence (the bank's rest viseme).
    timing : str, callable or DominanceParams
        Timing curve name from ``lipsync.motion.timing.CURVES`` or a callable on [0, 1] (rules 5-7
        with that curve); or ``"dominance"`` (or fitted
        :class:`~lipsync.motion.coarticulation.DominanceParams`): the coarticulation model of
        :mod:`lipsync.motion.coarticulation` instead of rules 3-7.
    closures : iterable of str
        Visemes that must be shown fully even when short (the closed-lips viseme).
    duration : float, optional
        Length of the output; default ``visemes.duration``.
    max_transition, hold_half_width, max_held_pause, min_segment : float
        The rule constants (seconds), overridable for experiments.
    classes : mapping, optional
        For the dominance model: viseme -> class, and the viseme of the breath before speech
        (:func:`lipsync.motion.coarticulation.viseme_classes` of the map; without it, no breath).

    Returns
    -------
    list of FrameSpec
        Exactly ``ceil(duration * fps)`` entries.

    Examples
    --------
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> tl = Timeline((Segment(0, 0.3, "X"), Segment(0.3, 0.6, "D")), kind="viseme")
    >>> [f.shown or "~" for f in sequence(tl, fps=10, rest="X")]
    ['X', 'X', 'X', '~', 'D', 'D']
    """
    if is_model(timing) or not (isinstance(timing, str) or callable(timing)):
        return dominance_sequence(visemes, fps=fps, rest=rest, closures=closures, classes=classes,
                                  params=as_params(timing), duration=duration)
    fps, total, n_frames = checked_frames(visemes, fps, duration)
    curve = get_curve(timing)
    closure_set = set(closures)
    if n_frames == 0:
        return []
    segs = plan_segments(visemes, rest=rest, closures=closure_set, max_held_pause=max_held_pause,
                         min_segment=min_segment, duration=total)
    windows = plan_transitions(segs, max_transition=max_transition, hold_half_width=hold_half_width)
    return frame_specs(segs, windows, fps=fps, curve=curve, closures=closure_set, stop=n_frames)


def frame_specs(segments: Sequence[Tuple[float, float, str]], windows: np.ndarray, *, fps: float, curve: Curve,
                closures: Iterable[str] = (), first: int = 0, stop: int, end: Optional[int] = None) -> List[FrameSpec]:
    """Rules 6-7: the FrameSpecs of frames ``first .. stop - 1`` of a planned track.

    ``segments`` come from :func:`plan_segments`, ``windows`` from :func:`plan_transitions`;
    ``end`` is the number of frames of the whole track (default ``stop``). The result is the
    slice ``[first, stop)`` of the frames of the whole track: :func:`sequence` asks for all of
    them, the live animator (:mod:`lipsync.live`) for parts. Frame n shows time ``n / fps``.

    Examples
    --------
    >>> segs = [(0, 0.3, "X"), (0.3, 0.6, "D")]
    >>> [f.shown or "~" for f in frame_specs(segs, plan_transitions(segs), fps=10,
    ...                                       curve=get_curve("linear"), first=2, stop=6)]
    ['X', '~', 'D', 'D']
    """
    end = stop if end is None else end
    if stop <= first:
        return []
    # Rule 7 may force a frame of [first, stop) for a closure whose own frames lie partly
    # outside it, and a forced frame counts as shown for a later closure: take in every
    # closure whose forced frame would land in the range being computed, and widen the
    # range to cover its frames, until nothing changes.
    closure_set = set(closures)
    spans = []  # (lo, hi, nearest, viseme) per closure, in track order
    for s, e, v in segments:
        if v in closure_set:
            lo = max(int(math.ceil(s * fps - _EPS)), 0)
            hi = min(int(math.ceil(e * fps - _EPS)) - 1, end - 1)
            nearest = min(max(int(round(0.5 * (s + e) * fps)), 0), end - 1)
            spans.append((lo, hi, nearest, v))
    r0, r1 = first, stop
    taken = [False] * len(spans)
    changed = True
    while changed:
        changed = False
        for i, (lo, hi, nearest, _) in enumerate(spans):
            if not taken[i] and r0 <= nearest < r1:
                taken[i] = changed = True
                r0, r1 = min(r0, lo), max(r1, hi + 1)
    specs = _held_and_transition_specs(segments, windows, fps=fps, curve=curve, first=r0, stop=r1)

    # Rule 7: every closure is shown exactly on at least one frame.
    for i, (lo, hi, nearest, v) in enumerate(spans):
        if not taken[i] or any(specs[n - r0].shown == v for n in range(lo, hi + 1)):
            continue
        specs[nearest - r0] = FrameSpec(v, v, 0.0)
    return specs[first - r0:stop - r0]


def _held_and_transition_specs(segments, windows, *, fps: float, curve: Curve, first: int, stop: int
                               ) -> List[FrameSpec]:
    # Rule 6 for frames first .. stop - 1.
    n_frames = stop - first
    names = [v for _, _, v in segments]
    times = np.arange(first, stop, dtype=np.float64) / fps

    # Rule 6, vectorised: the last transition that started at or before each frame time;
    # inside it the frame is a morph, after it the frame holds that transition's target.
    k = np.searchsorted(windows[:, 0], times, side="right") - 1 if len(windows) else np.full(n_frames, -1)
    in_transition = np.zeros(n_frames, dtype=bool)
    alpha = np.zeros(n_frames)
    valid = k >= 0
    if len(windows):
        kk = np.clip(k, 0, None)
        t0, t1 = windows[kk, 0], windows[kk, 1]
        span = np.maximum(t1 - t0, _EPS)
        in_transition = valid & (times < t1)
        u = np.clip((times - t0) / span, 0.0, 1.0)
        alpha = np.where(in_transition, np.asarray(curve(u), dtype=np.float64), 0.0)
    held_index = np.where(valid, k + 1, 0)

    specs: List[FrameSpec] = []
    for n in range(n_frames):
        if in_transition[n]:
            a = float(alpha[n])
            src, dst = names[k[n]], names[k[n] + 1]
            if a <= _EPS:
                specs.append(FrameSpec(src, src, 0.0))
            elif a >= 1.0 - _EPS:
                specs.append(FrameSpec(dst, dst, 0.0))
            else:
                specs.append(FrameSpec(src, dst, a))
        else:
            v = names[held_index[n]]
            specs.append(FrameSpec(v, v, 0.0))
    return specs


def describe(specs: Sequence[FrameSpec], fps: float) -> str:
    """A frame schedule as text, one line per frame: number, time, from, to, alpha.

    Examples
    --------
    >>> text = describe([FrameSpec("X", "X", 0.0), FrameSpec("X", "A", 0.5)], 10)
    >>> [line.split() for line in text.splitlines()]
    [['0', '0.000', 'X', 'X', '0.000'], ['1', '0.100', 'X', 'A', '0.500']]
    """
    return "\n".join(f"{n}\t{n / fps:.3f}\t{f.from_viseme}\t{f.to_viseme}\t{f.alpha:.3f}"
                     for n, f in enumerate(specs))
