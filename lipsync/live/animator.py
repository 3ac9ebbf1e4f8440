"""LiveAnimator: frames of a talking head for a playback clock, fed events as they arrive.

Events (phonemes, visemes or words with start and end times, or whole timelines) are
mapped to the bank's visemes by the same functions as the offline :class:`lipsync.Animator`
(:func:`lipsync.phonemes.bank_viseme_timeline`), sequenced causally by
:class:`lipsync.live.causal.CausalSequencer` (the sequencer's own rules on a window of the
track) and rendered by :class:`lipsync.render.Renderer`.

Examples
--------
>>> from lipsync import Bank, LiveAnimator
>>> from lipsync._data import default_bank_dir
>>> live = LiveAnimator(Bank.load(default_bank_dir()), fps=25)
>>> live.push(0.0, 0.3, "M"); live.push(0.3, 0.7, "AA"); live.push(0.7, 1.0, "sil")
>>> live.frame_at(0.5).shape, live.spec_at(0.5).shown, live.spec_at(5.0).shown
((512, 512, 3), 'D', 'X')
"""

from __future__ import annotations

import math
import os
import threading
import warnings
from typing import List, Optional, Tuple, Union

import numpy as np

from ..bank import Bank
from ..coarticulation import resolve_timing, viseme_classes
from ..errors import InputError, TimelineError
from ..phonemes import DEFAULT_MAP, PhonemeMap, bank_viseme_timeline, check_map_against, load_map
from ..frames import DEFAULT_FPS
from ..sequencer import FrameSpec
from ..store import FlowStore
from ..timeline import MAX_TIMELINE_S, PHONEME, VISEME, Segment, Timeline
from .causal import LOOKAHEAD_S, CausalSequencer
from .pool import RendererPool

#: What a pushed label may be; ``None`` (auto) tries them in the order of
#: :meth:`LiveAnimator.resolve`.
KINDS = ("viseme", "phoneme", "word")

#: Seconds after the last possible data (MAX_TIMELINE_S) by which every frame is rest: the
#: relaxation (RELAX_S) is well under it.
_REST_AFTER_S = 60.0

#: Longest single event accepted: a phone or word longer than a minute is a wrong time
#: (milliseconds sent as seconds), not speech, and would plan thousands of frames at once.
MAX_EVENT_S = 60.0


def _word_phones():
    """``lipsync.speech.phonetise.words_to_phones`` when that module exists, else None."""
    try:
        from ..speech.phonetise import words_to_phones  # type: ignore[import-not-found]
    except ImportError:
        return None
    return words_to_phones


class LiveAnimator:
    """Frames for a playback clock from events pushed as they arrive (thread-safe).

    Parameters
    ----------
    bank : Bank or path-like
        The subject.
    fps : float
        Frame rate, 1 to 120; frame n shows time n / fps.
    map : str, path-like or PhonemeMap, optional
        Phoneme-to-viseme map (default: the shipped English to Rhubarb-shapes map).
    timing : str, callable or DominanceParams, optional
        How the mouth moves, as for :class:`lipsync.Animator` (default: the bank's timing,
        else ``sqrt-fast-middle``).
    method : str
        Renderer method (``flow``, ``splat``, ``beier-neely``, ``dissolve``).
    lookahead : float, optional
        Seconds of pushed data past a frame's time after which the frame counts as final
        (:attr:`final_until`, :meth:`is_final`); default: the bound the timing implies,
        :data:`LOOKAHEAD_S` (0.38 s) for the sequencer's rules,
        :func:`lipsync.coarticulation.lookahead` (0.38 s with the default constants and a map with
        a breath viseme, 0.194 s without one) for
        the dominance model. It does not change which frame is shown.
    store : FlowStore, optional
        Flow store (default: the bank's).
    renderer : RendererPool, optional
        Renderers shared with other animators (a server's sessions); default: a pool of
        one of its own. ``method`` and ``store`` are then the pool's.
    prepare : bool
        Compute missing flows now (all pairs) so that no frame waits for one; default True
        for the ``flow`` and ``splat`` methods.

    Notes
    -----
    ``push`` and ``frame_at`` may be called from different threads. Pushes must come in
    time order (an event may start after a gap, which is silence). Frames depend only on
    what has been pushed; when the clock passes the data the head holds the last shape up
    to the end of the data, then relaxes to rest as a timeline's end does. When everything
    is pushed before the first frame, every frame equals the offline Animator's.
    """

    def __init__(self, bank: Union[Bank, str, "os.PathLike[str]"], fps: float = DEFAULT_FPS, *,
                 map: Union[str, "os.PathLike[str]", PhonemeMap, None] = None, timing=None,
                 method: str = "flow", lookahead: Optional[float] = None, store: Optional[FlowStore] = None,
                 renderer: Optional[RendererPool] = None, prepare: Optional[bool] = None):
        self.bank = bank if isinstance(bank, Bank) else Bank.load(bank)
        self.pmap = map if isinstance(map, PhonemeMap) else load_map(map or DEFAULT_MAP)
        self._map_path = map if isinstance(map, (str, os.PathLike)) and os.path.isfile(map) else None
        names = check_map_against(self.pmap, self.bank.names, path=self._map_path)
        self._bank_map = self.pmap.renamed(names)  # what bank_viseme_timeline hands the sequencer
        self.timing = resolve_timing(timing, self.bank)
        self._seq = CausalSequencer(fps=fps, rest=self.bank.rest, timing=self.timing, closures=self._bank_map.closures,
                                    classes=viseme_classes(self._bank_map, self.bank.rest))
        self.lookahead = self._seq.lookahead if lookahead is None else float(lookahead)
        if not (0.0 <= self.lookahead < 60.0):
            raise InputError(f"lookahead must be 0..60 s, got {lookahead!r}")
        self.fps = self._seq.fps
        self.renderer = renderer if renderer is not None else RendererPool(self.bank, method=method, store=store, size=1)
        if prepare is None:
            prepare = self.renderer.method in ("flow", "splat")
        if prepare:
            from ..preprocess import preprocess

            preprocess(self.bank, store=self.renderer.store, quiet=True, normalised=self.renderer.nb)
        self._state = threading.Lock()   # the track and its plan (the pool guards the renderers)
        self._warned: set = set()
        self._words = _word_phones()
        # viseme names a map knows under other names (Preston Blair's MBP, etc, rest ...)
        self._viseme_aliases = {a.lower() for names in self.pmap.aliases.values() for a in names}

    # ------------------------------------------------------------------ input
    def push(self, start, end: Optional[float] = None, label: Optional[str] = None, *,
             kind: Optional[str] = None, offset: float = 0.0) -> None:
        """Add one event, or a whole :class:`~lipsync.timeline.Timeline`.

        Parameters
        ----------
        start, end : float
            Seconds on the playback clock (``end >= start``). Events must come in time
            order; time between events is silence.
        label : str
            A viseme of the bank, a phoneme (any notation the map's phone set reads:
            ARPAbet, TIMIT, IPA; silence labels too) or a word.
        kind : {"viseme", "phoneme", "word"}, optional
            What ``label`` is; default: see :meth:`resolve`.
        offset : float
            Added to the times (of a timeline too): an utterance timed from its own start.

        ``push(timeline, offset=...)`` pushes every segment, mapped exactly as the offline
        Animator maps a file (gaps, silence labels, split phones, a stated end).

        Raises
        ------
        InputError
            Bad times, out of order, or a viseme the bank lacks; nothing is pushed then.
        """
        if isinstance(start, Timeline):
            segs = self.resolve_timeline(start, offset=offset)
        else:
            if end is None or label is None:
                raise InputError("push(start, end, label) needs all three (or a Timeline)")
            segs = self.resolve(start, end, label, kind=kind, offset=offset)
        with self._state:
            try:
                self._seq.extend(segs)
            except ValueError as exc:
                raise TimelineError(str(exc)) from None

    def resolve(self, start, end, label: str, *, kind: Optional[str] = None, offset: float = 0.0
                ) -> List[Tuple[float, float, str]]:
        """The bank's viseme segments for one event (nothing is pushed).

        With ``kind=None`` a label that is a viseme name of the bank (or of the map, under
        an alias such as the Preston Blair names) is a viseme, one the map knows is a phoneme, and anything else a word (through
        ``lipsync.speech.phonetise.words_to_phones``; without it, the map's fallback viseme
        with one warning per label).

        Examples
        --------
        >>> from lipsync._data import default_bank_dir
        >>> live = LiveAnimator(default_bank_dir(), prepare=False)
        >>> live.resolve(0.0, 0.2, "AY1")
        [(0.0, 0.1, 'D'), (0.1, 0.2, 'B')]
        """
        try:
            t0, t1 = float(start) + float(offset), float(end) + float(offset)
        except (TypeError, ValueError):
            raise InputError(f"event times must be numbers, got {start!r}, {end!r}") from None
        if not (math.isfinite(t0) and math.isfinite(t1)) or t0 < 0 or t1 < t0:
            raise InputError(f"event {label!r} at {start!r}-{end!r}: times must be finite with 0 <= start <= end")
        if t1 - t0 > MAX_EVENT_S:
            raise InputError(f"event {label!r} lasts {t1 - t0:g} s, over {MAX_EVENT_S:g} s (times in ms?)")
        if t1 > MAX_TIMELINE_S:
            raise InputError(f"event {label!r} ends at {t1:g} s, past the limit of {MAX_TIMELINE_S:g} s (24 hours)")
        if not isinstance(label, str) or not label.strip() and label != "":
            raise InputError(f"event label must be text, got {label!r}")
        if kind is not None and kind not in KINDS:
            raise InputError(f"unknown event kind {kind!r}; valid: {', '.join(KINDS)}")
        if kind is None:
            if label in self.bank.names or label.lower() in self._viseme_aliases:
                kind = "viseme"
            elif self.pmap.targets(label) is not None or self.pmap.is_silence(label):
                kind = "phoneme"
            else:
                kind = "word" if self._words is not None else "phoneme"
        if kind == "word":
            return self._word(t0, t1, label)
        tl = Timeline((Segment(t0, t1, label),), kind=VISEME if kind == "viseme" else PHONEME)
        return self._map_timeline(tl, 0.0, first=t0)

    def resolve_timeline(self, timeline: Timeline, *, offset: float = 0.0) -> List[Tuple[float, float, str]]:
        """The bank's viseme segments for a whole timeline, mapped as the offline Animator maps it.

        Examples
        --------
        >>> from lipsync._data import default_bank_dir
        >>> live = LiveAnimator(default_bank_dir(), prepare=False)
        >>> live.resolve_timeline(Timeline((Segment(0.1, 0.3, "M"),), stated_end=0.5))
        [(0.0, 0.1, 'X'), (0.1, 0.3, 'A'), (0.3, 0.5, 'X')]
        """
        return self._map_timeline(timeline, offset)

    def _word(self, t0: float, t1: float, word: str) -> List[Tuple[float, float, str]]:
        if self._words is None:
            raise InputError(f"word events need lipsync.speech.phonetise (not installed): {word!r}")
        phones = self._words(Timeline((Segment(t0, t1, word),), kind=PHONEME))
        if not len(phones):  # nothing to say ("..."): the mouth rests for the word's time
            return [(t0, t1, self.bank.rest)]
        return self._map_timeline(phones, 0.0, first=t0)

    def _map_timeline(self, tl: Timeline, offset: float, first: float = 0.0) -> List[Tuple[float, float, str]]:
        if offset:
            tl = tl.replace(segments=tuple(Segment(s.start + offset, s.end + offset, s.label) for s in tl),
                            stated_end=None if tl.stated_end is None else tl.stated_end + offset)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            mapped, _ = bank_viseme_timeline(tl, self.pmap, self.bank.names, rest=self.bank.rest,
                                             map_path=self._map_path)
        for w in caught:  # unknown labels: one warning per label for the whole session
            key = str(w.message)
            if key not in self._warned:
                self._warned.add(key)
                warnings.warn(w.message, w.category, stacklevel=3)
        # map_timeline fills time before the first segment with rest: not ours to push
        return [(s.start, s.end, s.label) for s in mapped if s.end > first or (s.start >= first and s.end == s.start)]

    # ------------------------------------------------------------------ output
    @property
    def horizon(self) -> float:
        """Seconds of speech pushed so far."""
        with self._state:
            return self._seq.horizon

    @property
    def final_until(self) -> float:
        """Frames at times up to this are final: the data reaches ``lookahead`` past them."""
        with self._state:
            return self._seq.horizon - self.lookahead

    def is_final(self, t: float) -> bool:
        """True when the frame at ``t`` cannot change with later pushes."""
        return t <= self.final_until

    def index(self, t: float) -> int:
        """The frame number shown at time ``t`` (the frame whose interval holds ``t``; >= 0).

        Any number is a time: before 0 is frame 0, and a time past everything that can be
        pushed (:data:`~lipsync.timeline.MAX_TIMELINE_S`, infinity included) is a frame of
        rest. NaN is refused (InputError): a broken clock, not a time.
        """
        t = float(t)
        if math.isnan(t):
            raise InputError("time must be a number, got nan")
        # Pushed data ends by MAX_TIMELINE_S and relaxes within seconds: every later frame
        # is rest, so clamping there keeps the frame number finite without changing a frame.
        t = min(max(t, 0.0), MAX_TIMELINE_S + _REST_AFTER_S)
        return max(int(math.floor(t * self.fps + 1e-9)), 0)

    def spec(self, n: int) -> FrameSpec:
        """The FrameSpec of frame ``n`` from what has been pushed."""
        with self._state:
            return self._seq.spec(int(n))

    def spec_at(self, t: float) -> FrameSpec:
        """The FrameSpec shown at time ``t``."""
        return self.spec(self.index(t))

    def frame(self, n: int, *, out: Optional[np.ndarray] = None) -> np.ndarray:
        """Frame ``n`` as RGB ``uint8`` (RGBA for a transparent bank; a new array unless ``out`` is given)."""
        spec = self.spec(n)
        return self.renderer.render(spec.from_viseme, spec.to_viseme, spec.alpha, out=out)

    def frame_at(self, t: float, *, out: Optional[np.ndarray] = None) -> np.ndarray:
        """The frame for playback time ``t`` seconds, RGB ``uint8`` ``(H, W, 3)`` (RGBA ``(H, W, 4)``
        for a bank with transparency).

        Uses only what has been pushed; past the data the head holds, then rests. Never
        raises for a number (a negative time is frame 0, a huge or infinite one rest); a
        NaN time is refused with InputError.
        """
        return self.frame(self.index(t), out=out)

    @property
    def shape(self) -> Tuple[int, int]:
        """Frame height and width."""
        return self.renderer.shape


def replay_specs(live: LiveAnimator, segments, n_frames: int, lag: float) -> List[FrameSpec]:
    """The FrameSpecs a stream shows when each frame is taken ``lag`` seconds behind the data.

    ``segments`` (viseme segments, e.g. from :meth:`LiveAnimator.resolve_timeline`) are
    pushed one at a time; frame n is taken as soon as the data reaches ``n / fps + lag``.
    With ``lag`` >= the look-ahead the result equals the offline frames (tests, ``make bench``).

    Examples
    --------
    >>> from lipsync._data import default_bank_dir
    >>> live = LiveAnimator(default_bank_dir(), fps=10, prepare=False)
    >>> segs = [(0.0, 0.5, "X"), (0.5, 0.9, "D"), (0.9, 1.3, "X")]
    >>> [s.shown or "~" for s in replay_specs(live, segs, 13, 0.0)][3:8]   # no look-ahead: late
    ['X', 'X', 'X', 'D', 'D']
    >>> live = LiveAnimator(default_bank_dir(), fps=10, prepare=False)
    >>> [s.shown or "~" for s in replay_specs(live, segs, 13, LOOKAHEAD_S)][3:8]
    ['X', 'X', '~', 'D', 'D']
    """
    got: List[FrameSpec] = []
    n = 0
    for seg in segments:
        live.push(*seg, kind="viseme")
        while n < n_frames and n / live.fps + lag <= seg[1] + 1e-12:
            got.append(live.spec(n))
            n += 1
    got.extend(live.spec(k) for k in range(n, n_frames))
    return got
