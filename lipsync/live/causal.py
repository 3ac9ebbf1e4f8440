"""Causal sequencing: the sequencer's rules applied to a viseme track that grows at its end.

:class:`CausalSequencer` takes viseme segments in time order (``extend``) and answers
"which FrameSpec does frame n show" (``spec``) from what it has been given so far. It does
not have rules of its own: it calls :func:`lipsync.motion.sequencer.plan_segments`,
:func:`~lipsync.motion.sequencer.plan_transitions` and :func:`~lipsync.motion.sequencer.frame_specs`,
the same functions :func:`~lipsync.motion.sequencer.sequence` is made of, on a *window* of the
track that starts at the last **cut**.

Cuts (why planning a window gives the offline frames)
-----------------------------------------------------
The offline sequencer plans the whole track at once; replanning all of it on every push
would cost O(track length) per push. A cut at time ``c`` inside a long segment ``G``
(pushed, or a gap, which is rest) splits the track into a frozen past and a window that
is replanned alone, and the window's frames equal the whole track's when:

* ``G`` is never dropped (rule 4: it is >= MIN_SEGMENT_S, and segments only grow when a
  neighbour is dropped) nor relabelled (rule 3: a rest >= MAX_HELD_PAUSE_S is not held),
  so it separates the drops on its left from those on its right: shortest-first dropping
  decides each side alone. The planned segment containing ``G`` only grows outward.
* ``c >= G.start + max(MAX_TRANSITION_S / 2, 1 / fps)``: the transition into ``G`` ends by
  ``G.start + MAX_TRANSITION_S / 2`` (``G`` holds from its midpoint - 40 ms, which is later
  for a segment >= 200 ms), and a closure just before ``G`` forces at most the frame half a
  frame after its end (rule 7). Frames from ``c`` on show ``G`` exactly until its
  transition out.
* ``G.end - c >= max(MAX_TRANSITION_S + 2 HOLD_HALF_WIDTH_S, MAX_TRANSITION_S / 2 + 1 / fps)``:
  the window's first segment ``[c, G.end]`` is itself "long" (>= 200 ms), so its transition
  out starts MAX_TRANSITION_S / 2 before its end, as the whole track's does, and at least
  one frame of the window shows it (so rule 7 never forces one there).

So the shortest ``G`` that gives a cut is 60 + 200 = 260 ms at 25 fps: pauses between
phrases and long vowels. Frames before a cut are final as soon as ``G`` is pushed.

Look-ahead
----------
Frame ``t`` shows the planned segment around ``t`` or a transition toward the next
boundary ``b``; a transition starts at most MAX_TRANSITION_S / 2 = 60 ms before ``b`` and
ends at ``b + 60 ms`` or, when the target is shorter than MAX_TRANSITION_S = 120 ms, at its
midpoint. The target's planned length is its own plus a pause after it that rule 3 holds
(a pause < MAX_HELD_PAUSE_S = 200 ms followed by more speech). So what a frame shows is
settled once the data reaches 60 + 120 + 200 = **380 ms** past it: :data:`LOOKAHEAD_S`.
Real timelines need less (measured in the tests and ``make bench``: 140-300 ms on the
samples and the MFA and Gentle files). A run of five or more segments each shorter than
MIN_SEGMENT_S can in principle reach further, as shortest-first dropping is decided over
the whole run.

The dominance model
-------------------
With ``timing="dominance"`` (:mod:`lipsync.motion.coarticulation`) the same window is planned with
the model instead of rules 3-7. A sound starting at ``s`` weighs on frames after
``s - lead - anticipation`` only, and on nothing later than its end plus its carry-over, so:
the look-ahead is ``lead + the longest anticipation`` (:func:`lipsync.motion.coarticulation.lookahead`),
where the breath before speech reaches furthest: 380 ms with the default constants and a
map with a breath viseme (194 ms without one). A cut at ``c`` inside ``G`` is valid once
the carry-over of every sound before ``G`` has ended (``c >= G.start + carry-over - lead``,
and at least a frame in, for a closure's forced frame) and while no sound after ``G``
reaches back to it (``G.end - c >= look-ahead``), which also leaves a cut pause at least
:data:`~lipsync.motion.coarticulation.BREATH_MIN_PAUSE_S` long, so it ends in the same breath as
the whole pause: with the defaults, inside pauses and sounds of 550 ms or more. No sound
is dropped or held, so nothing else reaches across ``G``.

Examples
--------
>>> cs = CausalSequencer(fps=10, rest="X")
>>> cs.extend([(0.0, 0.5, "X"), (0.5, 1.0, "D")])
>>> [cs.spec(n).shown or "~" for n in range(4, 8)], round(cs.final_until, 2)
(['X', '~', 'D', 'D'], 0.62)
"""

from __future__ import annotations

import math
from typing import Iterable, List, Mapping, Optional, Tuple

from ..motion.sequencer import HOLD_HALF_WIDTH_S, MAX_HELD_PAUSE_S, MAX_TRANSITION_S, FrameSpec, check_fps, frame_count, frame_specs, plan_segments, plan_transitions
from ..motion.timeline import MAX_TIMELINE_S, VISEME, Segment, Timeline
from ..motion.timing import DEFAULT_CURVE, get_curve, is_model

#: Data needed past a frame's time for the frame to be final (see the module docstring):
#: a transition starts up to half a transition before its boundary, its end depends on the
#: target's length up to a full transition, and the target grows by a held pause after it.
LOOKAHEAD_S = MAX_TRANSITION_S / 2 + MAX_TRANSITION_S + MAX_HELD_PAUSE_S

#: Past the data, the head relaxes as a timeline ends: the frames up to this long after
#: the last pushed time are planned with trailing silence (the sequencer's own transition
#: to rest, which reaches rest MAX_TRANSITION_S / 2 after the end); later ones are rest.
RELAX_S = MAX_HELD_PAUSE_S

# The window's first segment must be "long" in the sequencer's sense (rule hold-long).
_LONG_S = MAX_TRANSITION_S + 2 * HOLD_HALF_WIDTH_S

# Pushes may overlap the previous one by float noise; the same slack as Timeline's.
_OVERLAP_TOLERANCE_S = 1e-4

Track = List[Tuple[float, float, str]]


class CausalSequencer:
    """FrameSpecs of a growing viseme track (module docstring); not thread-safe by itself.

    Parameters
    ----------
    fps : float
        Frame rate, 1 to 120. Frame n shows time n / fps.
    rest : str
        The rest viseme (gaps, and the head past the data).
    timing : str, callable or DominanceParams
        Transition timing curve, or the dominance model (``"dominance"`` or its constants).
    closures : iterable of str
        Visemes always shown fully (the map's closures).
    classes : mapping, optional
        For the dominance model: viseme -> class (default: the default map's classes).

    Examples
    --------
    >>> cs = CausalSequencer(fps=25, rest="X")
    >>> cs.spec(100)
    FrameSpec(from_viseme='X', to_viseme='X', alpha=0.0)
    """

    def __init__(self, *, fps: float, rest: str, timing=DEFAULT_CURVE, closures: Iterable[str] = (),
                 classes: Optional[Mapping[str, str]] = None):
        self.fps = check_fps(fps)
        self.rest = rest
        self.closures = frozenset(closures)
        self.params = None      # the dominance model's constants, when it is the timing
        if is_model(timing) or not (isinstance(timing, str) or callable(timing)):
            from ..motion import coarticulation as co

            self.params = co.as_params(timing)
            self.curve = None
            self.classes = classes
            breath = getattr(classes, "breath", None) is not None
            #: Seconds of data past a frame that decide it (module docstring).
            self.lookahead = co.lookahead(self.params, breath=breath)
            self._lead = max(co.carryover(self.params), 1.0 / self.fps)
            # frames before the cut are frozen when G is pushed: no sound after G may reach
            # them; and a pause cut keeps enough of itself to end in the same breath
            self._tail = max(self.lookahead, 1.0 / self.fps, co.BREATH_MIN_PAUSE_S if breath else 0.0)
            self._relax_s = max(RELAX_S, co.carryover(self.params))
        else:
            self.curve = get_curve(timing)
            self.lookahead = LOOKAHEAD_S
            self._lead = max(MAX_TRANSITION_S / 2, 1.0 / self.fps)
            self._tail = max(_LONG_S, MAX_TRANSITION_S / 2 + 1.0 / self.fps)
            self._relax_s = RELAX_S
        self._frozen: List[FrameSpec] = []   # frames 0 .. first - 1, final
        self._frozen_shapes: List[str] = []  # ... and the shape each shows as a cue (:meth:`shape`)
        self._cut = 0.0                      # the window starts here (= first / fps)
        self._raw: Track = []                # pushed segments from the cut on
        self._horizon = 0.0                  # end of the pushed data
        self._window: Optional[List[FrameSpec]] = []   # frames first .. frame_count(horizon) - 1
        self._relax: Optional[List[FrameSpec]] = []    # the next frames, relaxing to rest
        self._rest_spec = FrameSpec(rest, rest, 0.0)
        self.cuts = 0

    # ------------------------------------------------------------------ input
    @property
    def horizon(self) -> float:
        """Seconds of track pushed so far (the end of the last segment)."""
        return self._horizon

    @property
    def final_until(self) -> float:
        """Frames at times up to this are final (pushed data reaches the look-ahead past them)."""
        return self._horizon - self.lookahead

    def extend(self, segments: Iterable[Tuple[float, float, str]]) -> None:
        """Append viseme segments ``(start, end, viseme)`` in time order (gaps are rest).

        A segment starting before the end of the track so far (beyond float noise) raises
        ValueError; one within the noise is clipped to start there.
        """
        added = False
        for start, end, label in segments:
            start, end = float(start), float(end)
            if not (math.isfinite(start) and math.isfinite(end)) or end < start or start < 0 \
                    or end > MAX_TIMELINE_S:
                raise ValueError(f"segment {start:g}-{end:g} {label!r}: times must be finite, "
                                 f"0 <= start <= end <= {MAX_TIMELINE_S:g}")
            if start < self._horizon - _OVERLAP_TOLERANCE_S:
                raise ValueError(f"segment {start:g}-{end:g} {label!r} starts before the end of the "
                                 f"track so far ({self._horizon:g} s): push in time order")
            start = max(start, self._horizon)
            if end <= start:
                continue
            self._raw.append((start, end, label))
            self._horizon = end
            added = True
        if added:
            self._window = None
            self._relax = None

    # ------------------------------------------------------------------ output
    def spec(self, n: int) -> FrameSpec:
        """The FrameSpec of frame ``n`` (time ``n / fps``) from the track so far."""
        if n < 0:
            n = 0
        if self._window is None:
            self._advance_cut()
            self._window = self._plan(self._horizon, self._first, frame_count(self._horizon, self.fps))
        if n < self._first:
            return self._frozen[n]
        stop = self._first + len(self._window)
        if n < stop:
            return self._window[n - self._first]
        if self._relax is None:
            relax = self._horizon + self._relax_s
            self._relax = self._plan(relax, stop, frame_count(relax, self.fps))
        if n < stop + len(self._relax):
            return self._relax[n - stop]
        return self._rest_spec

    def spec_with(self, n: int, tail: Track) -> FrameSpec:
        """Frame ``n`` as it would be if ``tail`` (segments from the end of the track on) were
        pushed, without pushing them: the live audio's provisional phones
        (:meth:`lipsync.LiveAnimator.feed_audio`), replanned with each block."""
        tail = [(max(float(s), self._horizon), float(e), v) for s, e, v in tail if e > self._horizon]
        if not tail:
            return self.spec(n)
        if self._window is None:
            self.spec(self._first)       # moves the cut with what is pushed
        n = max(n, 0)
        if n < self._first:
            return self._frozen[n]
        raw, horizon = self._raw, self._horizon
        try:
            self._raw, self._horizon = raw + tail, tail[-1][1]
            total = self._horizon if n < frame_count(self._horizon, self.fps) else self._horizon + self._relax_s
            end = frame_count(total, self.fps)
            if n >= end:
                return self._rest_spec
            return self._plan(total, n, n + 1, end)[0]
        finally:
            self._raw, self._horizon = raw, horizon

    def specs_with(self, first: int, stop: int, tail: Track) -> List[FrameSpec]:
        """Frames ``first .. stop - 1`` as :meth:`spec_with` gives them one by one, planned
        in one pass (a live session's sample window: :mod:`lipsync.live.samples`)."""
        tail = [(max(float(s), self._horizon), float(e), v) for s, e, v in tail if e > self._horizon]
        first = max(first, 0)
        if not tail or stop <= first:
            return [self.spec(n) for n in range(first, stop)]
        if self._window is None:
            self.spec(self._first)
        out = [self._frozen[n] for n in range(first, min(stop, self._first))]
        lo = max(first, self._first)
        raw, horizon = self._raw, self._horizon
        try:
            self._raw, self._horizon = raw + tail, tail[-1][1]
            data = frame_count(self._horizon, self.fps)
            if lo < min(stop, data):
                out += self._plan(self._horizon, lo, min(stop, data), data)
            if stop > data:
                total = self._horizon + self._relax_s
                end = frame_count(total, self.fps)
                out += self._plan(total, max(lo, data), min(stop, end), end)
                out += [self._rest_spec] * (stop - first - len(out))
            return out
        finally:
            self._raw, self._horizon = raw, horizon

    def cue(self, n: int) -> str:
        """The mouth shape frame ``n`` shows as a cue, from the track so far: the viseme of
        the planned segment (:func:`lipsync.motion.sequencer.plan_segments`, the track
        ``lipsync cues`` writes offline) at the middle of the frame's interval, whatever the
        timing curve or model blends between segments; rest past the data.

        Examples
        --------
        >>> cs = CausalSequencer(fps=10, rest="X", timing="dominance")
        >>> cs.extend([(0.0, 0.5, "X"), (0.5, 1.0, "D")])
        >>> [cs.cue(n) for n in range(3, 8)]
        ['X', 'X', 'D', 'D', 'D']
        """
        return self.cue_with(n, [])

    def cue_with(self, n: int, tail: Track) -> str:
        """:meth:`cue` as it would be if ``tail`` were pushed (as :meth:`spec_with`)."""
        n = max(int(n), 0)
        if self._window is None:
            self.spec(self._first)       # moves the cut with what is pushed
        if n < self._first:
            return self._frozen_shapes[n]
        tail = [(max(float(s), self._horizon), float(e), v) for s, e, v in tail if e > self._horizon]
        raw, horizon = self._raw, self._horizon
        try:
            if tail:
                self._raw, self._horizon = raw + tail, tail[-1][1]
            return self._shapes(n, n + 1)[0]
        finally:
            self._raw, self._horizon = raw, horizon

    def _shapes(self, first: int, stop: int) -> List[str]:
        """Shapes of frames first .. stop - 1 of the window (rest where the track has ended)."""
        if stop <= first:
            return []
        mids = [(n + 0.5) / self.fps for n in range(first, stop)]
        if not self._raw or mids[0] >= self._horizon:
            return [self.rest] * len(mids)
        track = Timeline(tuple(Segment(s, e, v) for s, e, v in self._raw), kind=VISEME)
        segs = plan_segments(track, rest=self.rest, closures=self.closures, duration=self._horizon, start=self._cut)
        out, i = [], 0
        for t in mids:
            while i < len(segs) and segs[i][1] <= t:
                i += 1
            out.append(segs[i][2] if i < len(segs) else self.rest)
        return out

    def is_final(self, n: int) -> bool:
        """True when frame ``n`` cannot change with later pushes (by the look-ahead rule)."""
        return n < self._first or n / self.fps <= self.final_until

    # ------------------------------------------------------------------ planning
    @property
    def _first(self) -> int:
        return len(self._frozen)

    def _plan(self, total: float, first: int, stop: int, end: Optional[int] = None) -> List[FrameSpec]:
        # Frames first .. stop - 1 of the window's track ending at ``total`` (stop is its end).
        if stop <= first:
            return []
        track = Timeline(tuple(Segment(s, e, v) for s, e, v in self._raw), kind=VISEME)
        if self.params is not None:
            from ..motion import coarticulation as co

            segs = co.plan(track, rest=self.rest, closures=self.closures, duration=total, start=self._cut)
            classes = self.classes
            if classes is None:
                classes = co.default_classes({v for _, _, v in segs}, rest=self.rest, closures=self.closures)
            return co.dominance_frames(segs, fps=self.fps, classes=classes, params=self.params,
                                       closures=self.closures, first=first, stop=stop, end=end)
        segs = plan_segments(track, rest=self.rest, closures=self.closures, duration=total, start=self._cut)
        windows = plan_transitions(segs)
        return frame_specs(segs, windows, fps=self.fps, curve=self.curve, closures=self.closures,
                           first=first, stop=stop, end=end)

    def _anchor(self) -> Optional[int]:
        """The first frame of the latest valid cut in the window (module docstring), if any."""
        best = None
        prev_end = self._cut
        for start, end, _ in self._raw:
            # the gap before this segment (rest), then the segment itself
            for g0, g1 in ((prev_end, start), (start, end)):
                if g1 - g0 < self._lead + self._tail:
                    continue
                first = frame_count(g0 + self._lead, self.fps)
                if first / self.fps > g0 + self._lead - 1e-9 and g1 - first / self.fps >= self._tail \
                        and first > self._first:
                    best = first
            prev_end = end
        return best

    def _advance_cut(self) -> None:
        first = self._anchor()
        if first is None:
            return
        # The window's frames before the cut are final (they depend on nothing after G).
        window = self._plan(self._horizon, self._first, frame_count(self._horizon, self.fps))
        self._frozen_shapes.extend(self._shapes(self._first, first))
        self._frozen.extend(window[:first - self._first])
        cut = first / self.fps
        self._raw = [(max(s, cut), e, v) for s, e, v in self._raw if e > cut]
        self._cut = cut
        self.cuts += 1
