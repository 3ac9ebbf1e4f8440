"""Plate time: which frame of a plate (the idle stretch, or a video being dubbed) each output
frame shows, when the output is longer than the plate.

Playing a short plate forwards and backwards (ping-pong) repeats its one blink and its one
head tilt at every turn: a 9 s dub of a 2 s clip showed the same blink twice 0.77 s apart.
Instead the plate is extended as a *video texture* (Schödl, Szeliski, Salesin and Essa,
"Video Textures", SIGGRAPH 2000): it plays forwards in runs, and a run ends with a jump to
another frame that looks like the one that would have come next, so the join is a step
no larger than the plate's own::

    features (above the nose, per plate frame) --distance, over two frames (motion too)-->
        cost of showing frame j right after frame i   (in the plate's median frame step)
    eye opening (face landmarks) --> blinks (+ margin) --> never join into or out of one
    runs: from the start, play forwards; end the run where a join is cheap, chosen at
        random (seeded by the clip) among the cheap ones, longer runs preferred;
        a blink is not shown again within REPEAT_GAP_S of its last showing

**Blinks** are found from the eye opening of the face landmarks
(:func:`lipsync.face.measure.eye_opening`: the lids' gap over the eye distance): a frame
whose opening is below :data:`BLINK_BELOW` of the plate's median opening is in a blink;
the blink's frames and :data:`BLINK_MARGIN` frames either side (the lids starting to fall
and still rising) are never the frame a join leaves from or lands on, so a blink is always
shown whole.

**Where a clip starts** on the plate (:func:`default_start`) is derived from the clip
itself (a hash of its timeline or sound), so rendering one clip again gives the same frames
and two different sentences start at different places: a series of clips does not blink in
unison. ``--plate-start SECONDS`` sets it.

Examples
--------
A plate of 10 frames with a blink at frames 4-5, played for 30 frames: it never jumps into
or out of the blink, and the blink is not shown twice within 12 frames (REPEAT at 1 fps
here: 12 s):

>>> import numpy as np
>>> feats = np.sin(np.arange(10)[:, None] * np.array([[0.7, 1.3]]))
>>> eyes = np.ones(10); eyes[4:6] = 0.1
>>> times = PlateTimes(feats, eyes, fps=1.0, repeat_gap=12.0, min_run=2.0, margin=0)
>>> line = PlateTimeline(times, start=0.0)
>>> shown = [line.frame(k) for k in range(30)]
>>> starts = [k for k in range(30) if shown[k] == 4]
>>> all(b - a >= 12 for a, b in zip(starts, starts[1:]))
True
"""

from __future__ import annotations

import hashlib
import threading
from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

__all__ = ["PlateTimes", "PlateTimeline", "default_start", "blink_runs", "upper_face_features",
           "BLINK_BELOW", "REPEAT_GAP_S", "RESTART_S", "KEEP_S"]

#: Eye opening below this share of the plate's median is a blink (or the lids lowered to
#: read: as visible, and as bad to repeat). The face mesh never lets the lids meet: GRID
#: s1's closed eyes (bbwm5s frames 8, 24-25, 37-45, checked by eye) measure 0.63-0.77 of the
#: median, open ones 0.86-1.1.
BLINK_BELOW = 0.8
#: Frames either side of a blink that belong to it: the lids start to fall a frame or two
#: before the opening drops below BLINK_BELOW and are still rising as long after (25 fps).
BLINK_MARGIN = 2
#: A blink is not shown again within this many seconds of its last showing (issue 36): people
#: blink every 2-10 s, and the same blink twice in a row reads as a loop.
REPEAT_GAP_S = 4.0
#: Shortest run played straight before a join, seconds: shorter runs make the motion stutter
#: (a glance cut off, a nod started twice).
MIN_RUN_S = 0.6
#: A join must land at least this far from the frame that would have come next (seconds):
#: a jump of a frame or two back is a stutter, forward a skip, however alike the frames.
MIN_JUMP_S = 0.4
#: Joins costing at most this many of the plate's median frame steps more than the cheapest
#: are chosen among (at random): one more ordinary step of the head and eyes is not seen as a
#: cut, and always the same cheapest join would make a loop of its own.
JOIN_SLACK = 1.0
#: Cost added (median frame steps) to a join landing on a frame shown just now, falling
#: linearly to 0 for one last shown REPEAT_GAP_S ago: the same stretch again and again is
#: the loop this module exists to avoid, and footage not shown for a while (its blinks
#: among it) comes back.
LOOP_PENALTY = 3.0
#: After this many seconds without a blink shown, joins landing just before a blink that may
#: be shown again get a bonus, growing to BLINK_DUE_BONUS median steps over as long again.
BLINK_DUE_S = 6.0
BLINK_DUE_BONUS = 8.0
#: Temperature of the random choice among cheap joins, in median frame steps (Schödl et
#: al.'s sigma): cheaper joins are likelier, but not always the same one.
JOIN_SIGMA = 0.5
#: A run's join is looked for from at most this many exit frames (spread evenly over the run's
#: allowed range) and, from each, among its this many cheapest joins: a run's choice then
#: costs the same on a 3 s plate as on a 10-minute video.
EXITS, JOINS_PER_EXIT = 100, 64
#: Each frame keeps its this many cheapest joins (found block by block: memory O(N K)); a
#: plate of at most this many frames keeps every join (a still stretch's frames are each
#: other's nearest: a short list would never leave it).
NEIGHBOURS = 1500
_BLOCK = 1024
#: A live session's plan (:meth:`PlateTimeline.restarting`) asked for a step this many
#: seconds past its end, or before its start, restarts there rather than planning every
#: step on the way: planning runs at ~0.2 ms a step, so a clock told it is 24 h in took
#: minutes, and a viewer who was away that long saw none of the frames between. Restarts
#: begin on a grid of this many seconds (a frame costs at most so many steps of planning,
#: ~50 ms), so the same far frame asked twice is the same plate frame.
RESTART_S = 10.0
#: A live plan (:meth:`PlateTimeline.restarting`) keeps the plate frames of at least its last
#: this many seconds of steps and drops older ones (a day's session held 2.16 million; the
#: planning reads only the last REPEAT_GAP_S): a step older than those kept is a far jump back.
KEEP_S = 60.0


def blink_runs(eyes: np.ndarray, *, below: float = BLINK_BELOW) -> List[Tuple[int, int]]:
    """``[(start, stop), ...]`` of the frames whose eye opening is below ``below`` of the
    median (NaN frames: not blinks).

    Examples
    --------
    >>> blink_runs(np.array([1.0, 1.0, 0.2, 0.1, 1.0, 0.9, 0.3, 1.0]))
    [(2, 4), (6, 7)]
    """
    e = np.asarray(eyes, np.float64)
    ok = np.isfinite(e)
    if not ok.any():
        return []
    shut = np.zeros(len(e), bool)
    shut[ok] = e[ok] < below * float(np.median(e[ok]))
    d = np.diff(np.concatenate([[0], shut.astype(np.int8), [0]]))
    return list(zip(np.nonzero(d == 1)[0].tolist(), np.nonzero(d == -1)[0].tolist()))


def upper_face_features(points: np.ndarray, found: Optional[np.ndarray] = None) -> np.ndarray:
    """Per frame, the face-mesh points above the nose tip (brows, eyes, lids, the nose's
    bridge) where they are in the picture, in eye distances (the median over the frames):
    a join between two frames whose features are close moves the head and eyes no more
    than a frame step. ``(N, 2K)``; NaN rows where the face was not found."""
    from ..face.measure import eye_distance

    p = np.asarray(points, np.float64)[..., :2]
    ok = np.ones(len(p), bool) if found is None else np.asarray(found, bool)
    d = float(np.nanmedian(eye_distance(p[ok]))) if ok.any() else 1.0
    ref = np.nanmedian(p[ok], axis=0) if ok.any() else p[0]
    above = np.nonzero(ref[:, 1] < ref[4, 1])[0]  # point 4: the nose tip
    out = p[:, above, :].reshape(len(p), -1) / d
    out[~ok] = np.nan
    return out


def default_start(*parts) -> float:
    """A start fraction in ``[0, 1)`` from the clip's own content (its timeline or sound):
    the same clip always gives the same, different clips spread over the plate.

    Examples
    --------
    >>> default_start("hello") == default_start("hello"), default_start("hello") == default_start("bye")
    (True, False)
    """
    h = hashlib.sha256()
    for p in parts:
        h.update(p.tobytes() if isinstance(p, np.ndarray) else repr(p).encode())
    return int.from_bytes(h.digest()[:8], "big") / 2.0 ** 64


def _pair_costs(f: np.ndarray, step: float) -> Tuple[np.ndarray, np.ndarray]:
    """``(idx, cost)``, each ``(N, K)``: for every frame i, the frames j that may follow it
    cheapest, cost = distance of frames (i, j-1) and (i-1, j-2), averaged (Schödl et al.'s
    filtered distance: the motion into the join matches too), in median steps."""
    n = len(f)
    g = np.nan_to_num(f, nan=1e6)
    sq = (g * g).sum(1)
    k = min(NEIGHBOURS, max(n - 1, 1))
    idx = np.zeros((n, k), np.int64)
    cost = np.full((n, k), np.inf)
    prev = np.concatenate([g[:1], g[:-1]])  # frame i-1 (frame 0 its own)
    sqp = (prev * prev).sum(1)
    for a in range(0, n, _BLOCK):
        b = min(n, a + _BLOCK)
        d0 = np.sqrt(np.maximum(sq[a:b, None] + sq[None, :] - 2 * g[a:b] @ g.T, 0.0))       # d(i, m)
        d1 = np.sqrt(np.maximum(sqp[a:b, None] + sq[None, :] - 2 * prev[a:b] @ g.T, 0.0))   # d(i-1, m)
        c = np.full((b - a, n), np.inf)
        c[:, 1:] = d0[:, :-1]                  # j follows i: j-1 like i
        c[:, 2:] = 0.5 * (d0[:, 1:-1] + d1[:, :-2])
        c /= step
        top = np.argpartition(c, k - 1, axis=1)[:, :k] if k < n else np.tile(np.arange(n), (b - a, 1))[:, :k]
        idx[a:b] = top
        cost[a:b] = np.take_along_axis(c, top, axis=1)
    return idx, cost


class PlateTimes:
    """What a plate's timelines are planned from, worked out once per plate (shared by clips).

    Parameters
    ----------
    features : numpy.ndarray
        ``(N, F)`` per plate frame, above the nose: pixels (the idle plate) or face-mesh
        points (:func:`upper_face_features`); NaN rows: no face (never joined to or from).
    eyes : numpy.ndarray
        ``(N,)`` eye opening (:func:`lipsync.face.measure.eye_opening`); NaN: unknown.
    fps : float
        The plate's frame rate.
    repeat_gap, min_run, min_jump : float
        Seconds: :data:`REPEAT_GAP_S`, :data:`MIN_RUN_S`, :data:`MIN_JUMP_S`.
    margin : int
        :data:`BLINK_MARGIN`.
    """

    def __init__(self, features: np.ndarray, eyes: np.ndarray, fps: float, *, repeat_gap: float = REPEAT_GAP_S,
                 min_run: float = MIN_RUN_S, min_jump: float = MIN_JUMP_S, margin: int = BLINK_MARGIN):
        f = np.asarray(features, np.float64).reshape(len(features), -1)
        self.n = len(f)
        self.fps = float(fps)
        self.blinks = blink_runs(eyes)
        busy = ~np.isfinite(f).all(axis=1)
        self.blink_of = np.full(self.n, -1, np.int64)   # frame -> blink (with its margin)
        self.spans = []                                 # blink -> (first, stop) with margin
        for b, (a, z) in enumerate(self.blinks):
            a0, z0 = max(0, a - margin), min(self.n, z + margin)
            self.blink_of[a0:z0] = b
            self.spans.append((a0, z0))
        self.busy = busy | (self.blink_of >= 0)        # frames a join never leaves from or lands on
        steps = np.linalg.norm(np.diff(f, axis=0), axis=1)
        steps = steps[np.isfinite(steps) & (steps > 0)]
        self.step = float(np.median(steps)) if steps.size else 1.0
        self.repeat = int(round(repeat_gap * self.fps))
        self.min_run = max(1, int(round(min_run * self.fps)))
        self.min_jump = max(2, int(round(min_jump * self.fps)))
        self.idx, self.cost = _pair_costs(f, self.step) if self.n > 1 else (np.zeros((1, 0), int), np.zeros((1, 0)))
        self._joins: dict = {}

    def joins(self, i: int) -> List[Tuple[int, float]]:
        """The allowed joins out of frame ``i``: ``[(j, cost), ...]`` (do not modify it)."""
        # Planning asks the same few hundred frames for their joins at every run of a long
        # clip or session; sorting each time was over half of the planning (a session told
        # the clock is an hour in planned for ~19 s).
        got = self._joins.get(i)
        if got is None:
            got = self._joins[i] = self._joins_of(i)
        return got

    def _joins_of(self, i: int) -> List[Tuple[int, float]]:
        if self.busy[i]:
            return []
        out = []
        for k in np.argsort(self.cost[i], kind="stable").tolist():
            j, c = int(self.idx[i, k]), float(self.cost[i, k])
            if not np.isfinite(c) or len(out) >= JOINS_PER_EXIT:
                break
            if not self.busy[j] and abs(j - (i + 1)) >= self.min_jump:
                out.append((j, c))
        return out


@dataclass
class _State:
    pos: int             # the next run starts here
    last: dict           # blink -> output step it last began


class PlateTimeline:
    """One clip's plate frames: :meth:`frame` ``(k)`` is the plate frame at step ``k`` of
    the plate's clock, planned run by run as far as asked (thread-safe).

    Parameters
    ----------
    times : PlateTimes
    start : float
        Where on the plate the clip begins, as a fraction ``[0, 1)`` of its length
        (:func:`default_start`); moved back to a blink's beginning if it falls in one.
    straight : int
        Frames the first run plays at least before its join (a dub plays its video through
        before joining it to itself).
    """

    def __init__(self, times: PlateTimes, start: float = 0.0, straight: int = 0):
        self.times = times
        n = times.n
        pos = int(np.floor((float(start) % 1.0) * n)) if n else 0
        if n and times.blink_of[pos] >= 0:
            pos = times.spans[times.blink_of[pos]][0]  # never start in the middle of a blink
        self._start = float(start)
        self._first_pos = pos
        self._straight = int(straight)
        self._lock = threading.Lock()
        #: Steps past the plan's end (or before its start) that restart it; None: never.
        self._far: Optional[int] = None
        self._keep: Optional[int] = None   # steps of the plan kept (restarting: KEEP_S)
        #: ``(step, from_frame, to_frame, cost)`` of every join made so far (of the plan since
        #: its last restart; a live plan's: of the steps it keeps).
        self.joins: List[Tuple[int, int, int, float]] = []
        self._begin(0)

    def _begin(self, step: int) -> None:
        """Plan afresh from output step ``step``: step 0 from the clip's start; a restart's
        step from a place on the plate drawn from the clip's start and the step."""
        t = self.times
        if step == 0:
            pos, seed = self._first_pos, default_start(self._start)
        else:
            seed = default_start(self._start, step)
            pos = int(np.floor(seed * t.n)) if t.n else 0
            if t.n and t.blink_of[pos] >= 0:
                pos = t.spans[t.blink_of[pos]][0]
        # (offset, plan): the plan's first step and its plate frames, swapped as one
        self._seg: Tuple[int, List[int]] = (int(step), [])
        self._plan = self._seg[1]
        self._origin = int(step)   # where this plan began (steps are counted from the clip's 0)
        self._state = _State(pos=pos, last={})
        self._rng = np.random.default_rng(int(pos) * 7919 + int(seed * 2 ** 31))
        self.joins = []

    def restarting(self) -> "PlateTimeline":
        """This timeline, restarting its plan at a far jump of the clock (:data:`RESTART_S`):
        a live session's, whose clock may be told any time. Ordinary playback (each step
        asked after the one before, or within RESTART_S of the plan's end) plays exactly as
        without; an offline render never restarts (its frames never depend on the order
        they are asked in).

        Examples
        --------
        >>> times = PlateTimes(np.sin(np.arange(50)[:, None] * [[0.3, 0.7]]), np.ones(50), fps=25.0)
        >>> line = PlateTimeline(times, start=0.5).restarting()
        >>> j = line.frame(25 * 86400)               # a day in: planned from a restart near it
        >>> line.planned <= int(RESTART_S * 25), 0 <= j < 50
        (True, True)
        """
        self._far = max(1, int(round(RESTART_S * self.times.fps)))
        self._keep = max(self._far, self.times.repeat, int(round(KEEP_S * self.times.fps)))
        return self

    @property
    def planned(self) -> int:
        """Steps planned since the last (re)start: the plan's state."""
        return len(self._seg[1])

    def frame(self, k: int) -> int:
        """The plate frame shown at step ``k`` of the plate's clock."""
        k = max(int(k), 0)
        first, plan = self._seg
        if first <= k < first + len(plan):
            return plan[k - first]
        with self._lock:
            first, plan = self._seg
            if self._far is not None and (k < first or k >= first + len(plan) + self._far):
                self._begin(k - k % self._far)
                first, plan = self._seg
            while self._seg[0] + len(self._seg[1]) <= k:
                self._extend()   # (may drop old steps: the plan is read anew)
            first, plan = self._seg
            return plan[k - first]

    def frames(self, count: int) -> np.ndarray:
        """:meth:`frame` of steps ``0 .. count-1``, planned straight on from step 0."""
        if self._keep is not None:   # a live plan keeps only its last steps: ask them in order
            return np.array([self.frame(k) for k in range(count)], np.int64)
        with self._lock:
            if self._seg[0] != 0:
                self._begin(0)
            while len(self._plan) < count:
                self._extend()
            return np.asarray(self._plan[:count], np.int64)

    # ------------------------------------------------------------------ planning

    def _limit(self, pos: int, at: int, last: dict) -> int:
        """The last frame a run from ``pos`` (shown from step ``at``) may play: before the
        first blink it would show again too soon, and at most the plate's end."""
        t = self.times
        for b, (a, z) in enumerate(t.spans):
            if z <= pos or (a < pos and t.blink_of[pos] != b):
                continue
            shown = at + max(a, pos) - pos
            if b in last and shown - last[b] < t.repeat:
                return max(a - 1, pos - 1)
        return t.n - 1

    def _blinks_in(self, a: int, e: int, at: int, last: dict) -> dict:
        out = dict(last)
        for b, (s, z) in enumerate(self.times.spans):
            if s >= a and s <= e or (s < a <= z - 1 and b not in out):
                out[b] = at + max(s, a) - a
        return out

    def _extend(self) -> None:
        t, st = self.times, self._state
        at = self._seg[0] + len(self._plan)   # the output step the run starts at
        if self._keep is not None and len(self._plan) > 2 * self._keep:
            self._drop_old()
        if t.n <= 1:
            self._plan.append(0)
            return
        limit = self._limit(st.pos, at, st.last)
        best = self._choose(st.pos, at, limit, st.last, strict=True)
        if best is None:  # nothing keeps the blink rule: the footage is too short for it
            best = self._choose(st.pos, at, t.n - 1, {}, strict=False)
        if best is None:  # no join at all (a plate of one blink): play to the end, start again
            e, j, c = t.n - 1, 0, float("inf")
        else:
            e, j, c = best
        self._plan.extend(range(st.pos, e + 1))
        st.last = self._blinks_in(st.pos, e, at, st.last)
        self.joins.append((self._seg[0] + len(self._plan), e, j, c))
        st.pos = j

    def _drop_old(self) -> None:
        """A live plan: drop the plate frames of steps older than the last ``_keep`` (the
        planning reads only the last REPEAT_GAP_S; every step count is from the clip's 0)."""
        first, plan = self._seg
        drop = len(plan) - self._keep
        kept = plan[drop:]
        self._seg = (first + drop, kept)   # one swap: a reader sees the old plan or the new
        self._plan = kept
        self.joins = [x for x in self.joins if x[0] > first + drop]   # the joins of the steps kept
    def _blink_due(self, pos: int, at: int, options, last: dict) -> np.ndarray:
        """Per option, the bonus (median steps) for landing just before a blink that may be
        shown again, once none has been shown for BLINK_DUE_S: it grows to BLINK_DUE_BONUS
        over as long again (people blink every 2-10 s; a plate that never goes back to its
        blinks stares)."""
        t = self.times
        if not t.spans:
            return np.zeros(len(options))
        since = (at - max(last.values())) if last else at - self._origin
        due = int(round(BLINK_DUE_S * t.fps))
        if since <= due:
            return np.zeros(len(options))
        gain = BLINK_DUE_BONUS * min(1.0, (since - due) / max(due, 1))
        out = np.zeros(len(options))
        for k, (e, j, _) in enumerate(options):
            ahead = [a for b, (a, z) in enumerate(t.spans) if j < a <= j + 2 * t.min_run
                     and (b not in last or at + (e - pos) + 1 + (a - j) - last[b] >= t.repeat)]
            out[k] = gain if ahead else 0.0
        return out

    def _last_shown(self, at: int) -> np.ndarray:
        """Per plate frame, the output step it was last shown at (far past: never)."""
        shown = np.full(self.times.n, -10 ** 9, np.int64)
        recent = self._plan[-self.times.repeat:] if self.times.repeat else []
        shown[np.asarray(recent, np.int64)] = np.arange(at - len(recent), at)
        return shown

    def _choose(self, pos: int, at: int, limit: int, last: dict, strict: bool):
        """``(exit frame, next frame, cost)`` of this run's join, or None."""
        t = self.times
        straight = self._straight if at == 0 else 0
        first = min(pos + max(t.min_run, straight) - 1, limit) if strict else pos
        options = []
        lo = max(first, pos)
        exits = np.unique(np.linspace(lo, limit, EXITS).round().astype(int)).tolist() if limit >= lo else []
        for e in exits:
            seen = self._blinks_in(pos, e, at, last) if strict else {}
            when = at + e - pos + 1
            for j, c in t.joins(e):
                if strict and self._limit(j, when, seen) - j + 1 < t.min_run:
                    continue  # it would have to leave again at once, before a blink shown too soon
                options.append((e, j, c))
        if not options:
            return None
        costs = np.array([o[2] for o in options])
        if at > self._origin:
            shown = self._last_shown(at)
            lands = np.array([o[1] for o in options])
            costs = costs + LOOP_PENALTY * np.clip(1.0 - (at - shown[lands]) / max(t.repeat, 1), 0.0, 1.0)
        costs = costs - self._blink_due(pos, at, options, last)
        runs = np.array([o[0] - pos + 1 for o in options], np.float64)
        cheap = costs <= float(costs.min()) + JOIN_SLACK
        w = np.where(cheap, np.exp(-(costs - costs.min()) / JOIN_SIGMA) * runs, 0.0)
        e, j, _ = options[int(self._rng.choice(len(options), p=w / w.sum()))]
        return e, j, float(next(o[2] for o in options if o[0] == e and o[1] == j))

