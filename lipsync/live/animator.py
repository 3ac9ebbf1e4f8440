"""LiveAnimator: frames of a talking head for a playback clock, fed events as they arrive.

Events (phonemes, visemes or words with start and end times, or whole timelines) are
mapped to the bank's visemes by the same functions as the offline :class:`lipsync.Animator`
(:func:`lipsync.phonetics.phonemes.bank_viseme_timeline`), sequenced causally by
:class:`lipsync.live.causal.CausalSequencer` (the sequencer's own rules on a window of the
track) and rendered by :class:`lipsync.morphing.render.Renderer`.

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

from ..banks.bank import Bank
from ..motion.coarticulation import resolve_timing, viseme_classes
from ..errors import InputError, TimelineError
from ..phonetics.phonemes import DEFAULT_MAP, PhonemeMap, bank_viseme_timeline, check_map_against, load_map
from ..motion.frames import DEFAULT_FPS, frame_count
from ..motion.sequencer import FrameSpec
from ..morphing.store import FlowStore
from ..motion.timeline import MAX_TIMELINE_S, PHONEME, VISEME, Segment, Timeline
from .causal import LOOKAHEAD_S, CausalSequencer
from .pool import RendererPool, shared_plate

#: What a pushed label may be; ``None`` (auto) tries them in the order of
#: :meth:`LiveAnimator.resolve`.
KINDS = ("viseme", "phoneme", "word")

#: Seconds after the last possible data (MAX_TIMELINE_S) by which every frame is rest: the
#: relaxation (RELAX_S) is well under it.
_REST_AFTER_S = 60.0

#: Where a live session's audio chooses the look-ahead by default: frame t is made when the
#: audio reaches t + 200 ms. Measured (``python -m lipsync.bench --only live_audio``, the
#: agreement of live mouth shapes with the offline phone loop's against the look-ahead, on
#: the MFA recording and GRID sentences; docs/live.md has the table): agreement rises
#: steeply to ~140 ms and by under 2 points from 200 to 400 ms, and 200 ms is a delay a
#: call or a stream hides.
AUDIO_LOOKAHEAD_S = 0.2
#: Largest audio look-ahead: past it the frames equal the offline ones anyway.
MAX_AUDIO_LOOKAHEAD_S = 1.0
#: Audio phones are pushed (fixed for good) this long behind the frame being made: older
#: than anything that frame's plan depends on (the sequencer reaches back less than 400 ms),
#: so the recogniser's later revisions of them would change no frame still to be made.
COMMIT_AFTER_S = 0.6
#: How events may arrive, for :attr:`LiveAnimator.delay`: as each sound starts (its end
#: known: TTS engines' events, timelines) or as it ends (a recogniser's output).
EVENTS_AT = ("start", "end")
#: The longest event assumed for ``events_at="end"``: long vowels and phrase-final sounds
#: run to 300 ms (the MFA recording's longest phone, pauses aside, is 280 ms).
LONGEST_EVENT_S = 0.3

#: A session with samples asked for a frame this many frames past the last one fixed, when
#: they lie past the data (rest), starts its path there instead of fixing each (a clock run
#: on for minutes with nothing pushed would otherwise fix thousands of frames at once).
_JUMP_FRAMES = 50

#: Phones a session with samples keeps before dropping those its windows no longer reach.
_KEEP_PHONES = 256

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
        :func:`lipsync.motion.coarticulation.lookahead` (0.38 s with the default constants and a map with
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
    audio_lookahead : float, optional
        For :meth:`feed_audio`: the frame of time ``t`` is fixed when the audio reaches
        ``t + audio_lookahead`` (default :data:`AUDIO_LOOKAHEAD_S`, 0.2 s; 0 to 1 s).
    events_at : {"start", "end"}
        When pushed events arrive: as each sound starts (its end known: TTS events,
        timelines) or as it ends (a recogniser's output). Only :attr:`delay` depends on it.
    longest_event : float
        With ``events_at="end"``: the longest event expected, seconds (default 0.3).
    still : bool
        Show the bank's still pictures even when it has an idle plate (bank.yaml ``plate:``,
        banks made from video). By default frame n of such a bank is the plate frame
        :meth:`lipsync.composite.plate.Plate.index` shows at frame n with the morphed lower
        face on it, exactly as the offline :class:`lipsync.Animator` and ``lipsync render
        --live`` make it: the speaker blinks and moves on the session's clock. The plate is
        decoded once per process and shared by every animator of the bank
        (:func:`lipsync.live.pool.shared_plate`).
    plate_start : float
        Seconds into the idle plate where the session starts (as ``--plate-start``; default
        0, where ``lipsync render --live`` starts): sessions given different starts do not
        blink in unison (``lipsync serve`` gives each session its own).
    samples : {None, "on", "off"} or bool
        Whether a bank with mouth samples (bank.yaml ``samples:``, banks made from video)
        shows a real sample per frame on its plate, selected within the look-ahead
        (:mod:`lipsync.live.samples`; with everything pushed before the first frame, the
        offline render's samples); None: as bank.yaml says; ``"off"``: the viseme morph.

    Notes
    -----
    ``push`` and ``frame_at`` may be called from different threads. Pushes must come in
    time order (an event may start after a gap, which is silence). Frames depend only on
    what has been pushed; when the clock passes the data the head holds the last shape up
    to the end of the data, then relaxes to rest as a timeline's end does. When everything
    is pushed before the first frame, every frame equals the offline Animator's.

    Audio (:meth:`feed_audio`) may be fed instead of, or beside, events (events win where
    both exist); docs/live.md has the delays each input needs.
    """

    def __init__(self, bank: Union[Bank, str, "os.PathLike[str]"], fps: float = DEFAULT_FPS, *,
                 map: Union[str, "os.PathLike[str]", PhonemeMap, None] = None, timing=None,
                 method: str = "flow", lookahead: Optional[float] = None, store: Optional[FlowStore] = None,
                 renderer: Optional[RendererPool] = None, prepare: Optional[bool] = None,
                 audio_lookahead: Optional[float] = None, events_at: str = "start",
                 longest_event: float = LONGEST_EVENT_S, still: bool = False, plate_start: float = 0.0,
                 samples=None):
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
            from ..morphing.preprocess import preprocess

            preprocess(self.bank, store=self.renderer.store, quiet=True, normalised=self.renderer.nb)
        #: The idle plate frames are composited onto (None: the still pictures).
        self.plate = None if still else shared_plate(self.bank)
        if not (isinstance(plate_start, (int, float)) and np.isfinite(plate_start) and plate_start >= 0):
            raise InputError(f"plate_start must be a number of seconds, 0 or more (got {plate_start!r})")
        #: Where on the plate the session starts, seconds.
        self.plate_start = float(plate_start)
        # a live clock may be told any time: a far jump restarts the plate's plan (RESTART_S)
        self._plate_line = None if self.plate is None else self.plate.timeline(self.plate_start).restarting()
        #: The session's mouth samples (:mod:`lipsync.live.samples`; None: the viseme morph).
        self.samples = self._attach_samples(samples)
        self._phones: List[Tuple[float, float, str]] = []   # the phones pushed (the samples' targets)
        self._phone_kind = VISEME       # PHONEME once a phone was pushed
        self._phones_kept = 0           # phones left by the last pruning (_add_phones)
        self._version = 0               # bumped when the data a sample window sees changes
        self._mouth = threading.local()   # each render thread its own morphed frame
        self._state = threading.Lock()   # the track and its plan (the pool guards the renderers)
        self._warned: set = set()
        self._words = _word_phones()
        # viseme names a map knows under other names (Preston Blair's MBP, etc, rest ...)
        self._viseme_aliases = {a.lower() for names in self.pmap.aliases.values() for a in names}
        if events_at not in EVENTS_AT:
            raise InputError(f"events_at must be one of {', '.join(EVENTS_AT)}, got {events_at!r}")
        if not (isinstance(longest_event, (int, float)) and 0.0 <= longest_event <= MAX_EVENT_S):
            raise InputError(f"longest_event must be 0..{MAX_EVENT_S:g} s, got {longest_event!r}")
        self.events_at = events_at
        self.longest_event = float(longest_event)
        self.audio_lookahead = AUDIO_LOOKAHEAD_S if audio_lookahead is None else float(audio_lookahead)
        if not (0.0 <= self.audio_lookahead <= MAX_AUDIO_LOOKAHEAD_S):
            raise InputError(f"audio look-ahead must be 0..{MAX_AUDIO_LOOKAHEAD_S * 1000:g} ms, "
                             f"got {audio_lookahead!r} s")
        self._fe = None                 # the audio front-end, from the first feed_audio
        self._shown: List[FrameSpec] = []   # audio: frames fixed when their audio came
        self._shapes: List[str] = []        # ... and the shape (cue) each shows
        self._committed_f = 0           # audio: 10 ms frames whose phones are pushed
        self._events: List[Tuple[float, float, str]] = []   # mixed: events not yet pushed
        self._event_phones: List[Tuple[float, float, str]] = []   # mixed: their phones (the samples' targets)
        self._tail: Optional[List[Tuple[float, float, str]]] = None   # provisional segments
        self._finished = False          # audio: finish_audio was called
        self._closed = False            # audio: close was called (the recogniser freed)

    # ------------------------------------------------------------------ input
    def push(self, start, end: Optional[float] = None, label: Optional[str] = None, *,
             kind: Optional[str] = None, offset: float = 0.0) -> None:
        """Add one event, or a whole :class:`~lipsync.motion.timeline.Timeline`.

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
            phones = [(s.start + offset, s.end + offset, s.label) for s in start.segments]
            phone_kind = start.kind
        else:
            if end is None or label is None:
                raise InputError("push(start, end, label) needs all three (or a Timeline)")
            segs, phones, phone_kind = self._resolve(start, end, label, kind=kind, offset=offset)
        with self._state:
            self._version += 1
            if self._fe is not None:
                self._hold_events(segs)
                self._hold_event_phones(phones, phone_kind)
                return
            try:
                self._seq.extend(segs)
            except ValueError as exc:
                raise TimelineError(str(exc)) from None
            self._add_phones(phones, phone_kind)

    def _add_phones(self, phones, kind: str) -> None:
        """Keep pushed phones (or visemes) for the samples' targets, in time order."""
        if self.samples is None:
            return
        if kind == PHONEME:
            self._phone_kind = PHONEME
        last = self._phones[-1][1] if self._phones else 0.0
        self._phones.extend((max(float(a), last), float(b), lab) for a, b, lab in phones if b > last)
        # (amortised: a long list pushed ahead of the frames is scanned rarely)
        if len(self._phones) > 2 * self._phones_kept + _KEEP_PHONES:
            # a window reaches back CONTEXT_S before the next frame to fix: older phones are
            # never read again (each window's cost stays independent of the session's length)
            from .samples import CONTEXT_S

            cut = len(self.samples) / self.fps - 2 * CONTEXT_S
            self._phones = [p for p in self._phones if p[1] > cut]
            self._phones_kept = len(self._phones)

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
        return self._resolve(start, end, label, kind=kind, offset=offset)[0]

    def _resolve(self, start, end, label: str, *, kind: Optional[str] = None, offset: float = 0.0):
        """``(viseme segments, phone segments, kind of the phone segments)`` of one event."""
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
        return self._map_timeline(tl, 0.0, first=t0), [(t0, t1, label)], tl.kind

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
            return [(t0, t1, self.bank.rest)], [], PHONEME
        return (self._map_timeline(phones, 0.0, first=t0), [(s.start, s.end, s.label) for s in phones.segments],
                PHONEME)

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
        """True when the frame at ``t`` cannot change with later pushes (or audio: a frame
        is fixed once the audio has reached ``audio_lookahead`` past it)."""
        if self._fe is not None:
            with self._state:
                if self._finished or self.index(t) < len(self._shown):
                    return True
        return t <= self.final_until

    @property
    def delay(self) -> float:
        """Seconds a player must run behind the newest data for every frame to be final when due.

        * audio (:meth:`feed_audio`): ``audio_lookahead`` (the frame of time ``t`` is made
          when the audio reaches ``t + audio_lookahead``);
        * events pushed as each sound *starts* (with its end: TTS engines' phoneme or viseme
          events, a timeline): ``lookahead``;
        * events pushed as each sound *ends* (a recogniser's output, ``events_at="end"``):
          the data then reaches only the end of the last finished sound, up to one sound
          behind the clock, so ``lookahead + longest_event`` (measured in
          ``python -m lipsync.bench --only live``: 380 ms is never enough there; with the
          MFA recording's phones pushed at their ends every frame was final at
          380 + its longest event).

        Examples
        --------
        >>> from lipsync._data import default_bank_dir
        >>> LiveAnimator(default_bank_dir(), prepare=False, events_at="end").delay
        0.68
        """
        if self._fe is not None:
            return self.audio_lookahead
        extra = self.longest_event if self.events_at == "end" else 0.0
        return round(self.lookahead + extra, 6)

    def index(self, t: float) -> int:
        """The frame number shown at time ``t`` (the frame whose interval holds ``t``; >= 0).

        Any number is a time: before 0 is frame 0, and a time past everything that can be
        pushed (:data:`~lipsync.motion.timeline.MAX_TIMELINE_S`, infinity included) is a frame of
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
        """The FrameSpec of frame ``n`` from what has been pushed (and the audio fed: a frame
        is fixed once the audio reaches ``audio_lookahead`` past it, later ones show the
        best guess so far)."""
        n = max(int(n), 0)
        with self._state:
            if self._fe is None:
                return self._seq.spec(n)
            if n < len(self._shown):
                return self._shown[n]
            return self._provisional(n)

    # ------------------------------------------------------------------ audio
    def feed_audio(self, samples, sample_rate: int = 16000) -> List[int]:
        """Add audio (mono; any chunk size; ``int16``, or float in [-1, 1]); returns the frame
        numbers it made due.

        The audio is the playback clock: its first sample is time 0. A voice gate and
        pocketsphinx's phone loop (:mod:`lipsync.live.audio`) turn it into phones, the map
        into visemes, the sequencer (the animator's timing) into frames. The frame of time
        ``t`` is fixed as soon as the audio reaches ``t + audio_lookahead`` (a player shows
        it with the sound delayed by that much: :attr:`delay`), from everything heard by
        then. Events pushed in the same session win over the audio where both exist (their
        phones too, in a samples bank's target).

        Invariance: the audio is processed in 20 ms blocks of 16 kHz samples whatever the
        chunks, so the frames depend only on the samples fed, never on how they were cut
        (any chunk sizes, int16 or the same values as float); a stream keeps one rate.

        Parameters
        ----------
        samples : array-like
            Mono samples, ``int16`` or float in [-1, 1] (``int16 / 32768`` gives exactly the
            same frames as the integers).
        sample_rate : int
            8000 to 192000 Hz; resampled to 16 kHz inside.

        Returns
        -------
        list of int
            Frames fixed by this chunk (each ``spec(n)`` is then final).

        Examples
        --------
        >>> import numpy as np
        >>> from lipsync._data import default_bank_dir
        >>> live = LiveAnimator(default_bank_dir(), prepare=False)
        >>> due = live.feed_audio(np.zeros(16000, np.int16), 16000)   # one second of silence
        >>> len(due), live.spec(due[-1]).shown
        (21, 'X')
        """
        from .audio import AudioFrontEnd

        with self._state:
            if self._finished or self._closed:
                raise InputError("the audio has ended (finish_audio or close was called); start a new animator")
            if self._fe is None:
                self._fe = AudioFrontEnd()
                if self.samples is not None:   # its blocks also feed the samples' audio lip target
                    self._fe.on_block = self.samples.hear
            self._fe.add(samples, sample_rate)
            due: List[int] = []
            while self._fe.step():   # one block at a time: the state after each is the same for any chunking
                self._tail = None
                self._version += 1
                self._commit(self._fe.frames - self._commit_frames())
                now = self._fe.time
                while True:
                    n = len(self._shown)
                    if n / self.fps + self.audio_lookahead > now + 1e-9:
                        break
                    self._fix(n)
                    due.append(n)
            return due

    def finish_audio(self) -> List[int]:
        """The audio has ended: decide its last phones and deliver every remaining frame.

        The front-end processes the last partial block (completed with silence) and ends the
        phone loop's utterance; everything heard is pushed; then every frame up to the end
        of the audio is fixed from all of it -- the last look-ahead's frames (about
        ``audio_lookahead * fps`` of them), which no later audio would ever have made due.
        After it, the frames fixed by :meth:`feed_audio` and by this call are exactly the
        ``ceil(duration * fps)`` frames of the audio fed (``duration`` = samples fed / their
        rate), as many as an offline render of that audio has (``lipsync render --live``
        and ``lipsync cues --live`` call it after the file's last chunk; a ``lipsync
        serve`` session on a ``{"type": "end"}`` message). More audio is then refused; a
        second call returns ``[]``.

        Returns
        -------
        list of int
            The frame numbers this call fixed, in order (each ``spec(n)`` / ``frame(n)`` is
            then final): what a streaming caller still has to show. Empty when no audio was
            fed.

        Examples
        --------
        >>> import numpy as np
        >>> from lipsync._data import default_bank_dir
        >>> live = LiveAnimator(default_bank_dir(), prepare=False)
        >>> due = live.feed_audio(np.zeros(3200, np.int16))      # 0.2 s: frame 0 is due
        >>> due, live.finish_audio(), live.spec(4).shown, live.is_final(0.16)
        ([0], [1, 2, 3, 4], 'X', True)
        """
        from ..motion.frames import frame_count

        with self._state:
            if self._fe is None or self._finished or self._closed:
                return []
            self._fe.end()   # its last block, completed with silence, reaches the samples too
            if self.samples is not None and self.samples.features is not None:
                self.samples.features.finish(frame_count(self._fe.duration, self.fps))
            self._tail = None
            self._version += 1
            self._commit(self._fe.frames, flush=True)
            self._finished = True
            total = frame_count(self._fe.duration, self.fps)
            due = list(range(len(self._shown), total))
            for n in due:
                self._fix(n)
            return due

    @property
    def frames_total(self) -> Optional[int]:
        """After :meth:`finish_audio`: how many frames the stream has (``ceil(duration * fps)``,
        the offline render's count); None while the audio goes on."""
        if not self._finished:
            return None
        from ..motion.frames import frame_count

        return max(len(self._shown), frame_count(self._fe.duration, self.fps))

    def close(self) -> None:
        """Free the audio front-end (the recogniser's ~30 MB) and give the memory back to the
        system (:func:`lipsync.live.audio.trim_memory`); a server calls it when a session
        ends. Frames already fixed stay readable; more audio is refused.

        Examples
        --------
        >>> import numpy as np
        >>> from lipsync._data import default_bank_dir
        >>> live = LiveAnimator(default_bank_dir(), prepare=False)
        >>> _ = live.feed_audio(np.zeros(3200, np.int16)); live.close()
        >>> live.spec(0).shown
        'X'
        """
        from .audio import trim_memory

        with self._state:
            if self._fe is None or self._closed:
                return
            self._fe.close()
            self._closed = True
        trim_memory()

    @property
    def audio_time(self) -> float:
        """Seconds of audio fed and processed so far (whole 20 ms blocks)."""
        return 0.0 if self._fe is None else self._fe.time

    def _commit_frames(self) -> int:
        from .audio import FRAME_S

        return int(round((self.audio_lookahead + COMMIT_AFTER_S) / FRAME_S))

    def _phone_segments(self, runs, start_f: int) -> List[Tuple[float, float, str]]:
        """Gated phone runs (10 ms frames) -> the bank's viseme segments (one call to the map)."""
        from .audio import FRAME_S

        if not runs:
            return []
        tl = Timeline(tuple(Segment(a * FRAME_S, b * FRAME_S, p) for a, b, p in runs), kind=PHONEME)
        first = runs[0][0] * FRAME_S
        # the map fills the time before the first sound with rest: gaps are rest anyway
        return [(max(a, first), b, v) for a, b, v in self._map_timeline(tl, 0.0, first=first) if b > first]

    def _commit(self, upto_f: int, *, flush: bool = False) -> None:
        """Push the audio's phones before frame ``upto_f`` (and the held events before them)."""
        from .audio import FRAME_S

        fe = self._fe
        if upto_f <= self._committed_f and not flush:
            return
        runs = fe.phones(self._committed_f)
        keep = [r for r in runs if r[1] <= upto_f]
        straddle = [r for r in runs if r[0] < upto_f < r[1]]
        new_f = straddle[0][0] if straddle else max(upto_f, self._committed_f)
        if flush:
            keep, new_f = runs, max(fe.frames, self._committed_f)
        segs = self._phone_segments(keep, self._committed_f)
        cut = new_f * FRAME_S
        if flush and self._events:
            cut = max(cut, self._events[-1][1])
        self._commit_phones([(a * FRAME_S, b * FRAME_S, p) for a, b, p in keep], cut, flush)
        mixed = _overlay(segs, self._events)
        push = [s for s in mixed if s[1] <= cut + 1e-9]
        self._events = [e for e in self._events if e[1] > cut + 1e-9]
        try:
            self._seq.extend(push)
        except ValueError as exc:  # pragma: no cover - segments are in order by construction
            raise TimelineError(str(exc)) from None
        self._committed_f = new_f
        fe.forget(new_f)

    def _commit_phones(self, heard, cut: float, flush: bool) -> None:
        """The samples' targets: the audio's phones ``heard``, pushed events' phones where
        they lie (as their visemes win over the audio's), up to ``cut``."""
        if flush and self._event_phones:
            cut = max(cut, self._event_phones[-1][1])
        said = _overlay(heard, self._event_phones)
        self._add_phones([p for p in said if p[1] <= cut + 1e-9], PHONEME)
        self._event_phones = [e for e in self._event_phones if e[1] > cut + 1e-9]

    def _hold_event_phones(self, phones, kind: str) -> None:
        """Mixed session: the phones of events pushed (phonemes, or words' phonemes) are the
        samples' targets where they lie, the audio's phones elsewhere: an app pushing its
        own timing (a TTS engine's phonemes) says which sound is made when, exactly, where
        the phone loop guesses; the audio's lip prediction (what is heard) still blends in.
        Viseme events carry no phones: the audio's stay under them (the events' visemes
        still set the frames' visemes and closures)."""
        if self.samples is None or kind != PHONEME or not phones:
            return
        h = self._seq.horizon   # as _hold_events: time already pushed is too late for them
        self._event_phones.extend((max(float(a), h), float(b), lab) for a, b, lab in phones if b > h)

    def _provisional(self, n: int) -> FrameSpec:
        return self._seq.spec_with(n, self._tail_segments())

    def _provisional_shape(self, n: int) -> str:
        return self._seq.cue_with(n, self._tail_segments())

    def _fix(self, n: int) -> None:
        """Frame ``n`` (the next) is due: fix its spec and its shape (and its sample) from what is heard now."""
        self._shown.append(self._provisional(n))
        self._shapes.append(self._provisional_shape(n))
        if self.samples is not None:
            self._fix_sample_heard(n)

    def _fix_sample_heard(self, n: int) -> None:
        """Audio: fix frame ``n``'s sample from a window over the frames the audio reaches."""
        from .samples import frames_heard

        tail = self._tail_segments()
        stop = max(n + 1, frames_heard(self._fe.time, self.fps))
        phones = self._phones + self._tail_phones()
        while len(self.samples) <= n:   # (frames rendered from pushed events before the audio are fixed)
            self.samples.fix(lambda a, b: self._shown[a:n + 1] + self._seq.specs_with(n + 1, b, tail), phones,
                             PHONEME, stop, (self._version, stop))

    def _tail_phones(self) -> List[Tuple[float, float, str]]:
        """Audio: the phones heard but not yet pushed (provisional), as segments."""
        from .audio import FRAME_S

        runs = self._fe.phones(self._committed_f)
        return _overlay([(a * FRAME_S, b * FRAME_S, p) for a, b, p in runs], self._event_phones)

    def _attach_samples(self, option):
        """The session's :class:`~lipsync.live.samples.LiveSamples` when the bank has samples,
        they are on and frames go onto its plate; else None (the viseme morph)."""
        from ..motion.coarticulation import DominanceParams
        from .samples import LiveSamples, samples_wanted, shared_samples

        samples_wanted(option)   # a bad value is refused whatever the bank
        if self.plate is None:
            return None
        shared = shared_samples(self.bank, option, self._bank_map, self.renderer.store)
        if shared is None:
            return None
        return LiveSamples(shared, self.fps, self.timing if isinstance(self.timing, DominanceParams) else None)

    def sample(self, n: int) -> int:
        """The mouth sample frame ``n`` shows (an index into the bank's samples; its frame
        shows it, or the morph into it across a join); fixed now if it was not (pushed
        events: from what is pushed by now, and every earlier frame first). Fixed samples
        never change. ValueError when the session does not use samples."""
        if self.samples is None:
            raise ValueError("this session shows the viseme morph (no samples)")
        return self._sample_shown(n)[0]

    def _sample_shown(self, n: int) -> Tuple[int, int]:
        """``(sample, frame whose plan is shown)``: with audio, a frame not due yet holds
        the newest fixed one (its sample is fixed when its audio comes)."""
        n = max(int(n), 0)
        with self._state:
            sel = self.samples.selection
            if self._fe is not None:
                if n >= len(sel):
                    n = len(sel) - 1
                if n < sel.first:   # nothing heard yet: the viseme morph's rest
                    return -1, -1
                return sel.sample(n), n
            if n < sel.first:       # skipped by a jump (below): never shown with a sample
                return -1, -1
            rest_from = frame_count(self._seq.horizon + self._seq._relax_s, self.fps)
            if n - max(len(sel), rest_from) > _JUMP_FRAMES:
                # far past the data (a clock that ran on with nothing pushed): the frames
                # from rest_from on are rest; fix those with data, then go on from frame n
                # rather than fixing every frame on the way
                while len(sel) < rest_from:
                    self._fix_sample_pushed()
                sel.restart(n)
            while len(sel) <= n:
                self._fix_sample_pushed()
            return sel.sample(n), n

    def _fix_sample_pushed(self) -> None:
        """Pushed events: fix the next frame's sample from a window up to the end of the data."""
        c = len(self.samples)
        stop = max(c + 1, frame_count(self._seq.horizon, self.fps))
        self.samples.fix(lambda a, b: [self._seq.spec(k) for k in range(a, b)], self._phones, self._phone_kind,
                         stop, (self._version, stop))

    def _tail_segments(self) -> List[Tuple[float, float, str]]:
        if self._tail is None:
            runs = self._fe.phones(self._committed_f) if self._fe is not None else []
            self._tail = _overlay(self._phone_segments(runs, self._committed_f), self._events)
            if self._fe is not None and self._fe.time > (self._tail[-1][1] if self._tail else 0.0):
                # the audio heard so far is the track's end: silence after the last sound
                end = self._fe.time
                start = max(self._tail[-1][1] if self._tail else 0.0, self._seq.horizon)
                if end > start:
                    self._tail.append((start, end, self.bank.rest))
        return self._tail

    def _hold_events(self, segs) -> None:
        """Mixed session: keep events until the audio's phones around them are pushed."""
        if not segs:
            return
        last = self._events[-1][1] if self._events else self._seq.horizon
        if segs[0][0] < last - 1e-4 and self._events:
            raise TimelineError(f"event at {segs[0][0]:g} s starts before the end of the events so far "
                                f"({last:g} s): push in time order")
        # events for time already pushed from the audio are too late for it: their rest counts
        h = self._seq.horizon
        self._events.extend((max(a, h), b, v) for a, b, v in segs if b > h)
        self._tail = None

    def cue(self, n: int) -> str:
        """The mouth shape frame ``n`` shows as a cue (a viseme of the bank): the planned
        segment at the middle of the frame's interval
        (:meth:`lipsync.live.causal.CausalSequencer.cue`) -- what a cartoon that swaps
        whole drawings shows, and what ``lipsync cues AUDIO --live`` writes -- rather
        than the blend :meth:`spec` renders (with a timing model such as ``dominance`` a
        frame is a mixture of several segments' shapes, and its nearer viseme lags or leads
        the sound). Audio: fixed with the frame (:meth:`feed_audio`).

        Examples
        --------
        >>> from lipsync._data import default_bank_dir
        >>> live = LiveAnimator(default_bank_dir(), prepare=False)
        >>> live.push(0.0, 0.3, "M"); live.push(0.3, 0.7, "AA"); live.push(0.7, 1.0, "sil")
        >>> [live.cue(n) for n in (2, 10, 30)]
        ['A', 'D', 'X']
        """
        n = max(int(n), 0)
        with self._state:
            if self._fe is None:
                return self._seq.cue(n)
            if n < len(self._shapes):
                return self._shapes[n]
            return self._provisional_shape(n)

    def spec_at(self, t: float) -> FrameSpec:
        """The FrameSpec shown at time ``t``."""
        return self.spec(self.index(t))

    def frame(self, n: int, *, out: Optional[np.ndarray] = None) -> np.ndarray:
        """Frame ``n`` as RGB ``uint8`` (RGBA for a transparent bank; a new array unless ``out`` is given)."""
        if self.samples is not None:
            n = max(int(n), 0)
            _, k = self._sample_shown(n)   # fixes frames up to n (pushed events: from what is pushed now)
            if k >= 0:
                if out is None:
                    out = np.empty(self.renderer.shape + (self.renderer.channels,), np.uint8)
                return self.samples.render(n, self.plate, self._plate_line, out, shows=k)
        spec = self.spec(n)
        if self.plate is None:
            return self.renderer.render(spec.from_viseme, spec.to_viseme, spec.alpha, out=out)
        if out is None:
            out = np.empty(self.renderer.shape + (self.renderer.channels,), np.uint8)
        mouth = getattr(self._mouth, "frame", None)
        if mouth is None:
            mouth = self._mouth.frame = np.empty_like(out)
        # the plate frame due at the session's clock (frame n, as the offline Animator's frame
        # n), with only the lower face's box of the morph made and composited onto it
        self.renderer.render(spec.from_viseme, spec.to_viseme, spec.alpha, out=mouth, region=self.plate.region)
        return self.plate.render_into(max(int(n), 0), self.fps, mouth, out, self._plate_line)

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


def _overlay(base: List[Tuple[float, float, str]], top: List[Tuple[float, float, str]]
             ) -> List[Tuple[float, float, str]]:
    """``base`` segments where no ``top`` segment lies, ``top`` ones where they do (time order).

    Examples
    --------
    >>> _overlay([(0.0, 1.0, "A"), (1.0, 2.0, "B")], [(0.5, 1.2, "C")])
    [(0.0, 0.5, 'A'), (0.5, 1.2, 'C'), (1.2, 2.0, 'B')]
    """
    if not top:
        return list(base)
    out: List[Tuple[float, float, str]] = []
    for a, b, v in base:
        pieces = [(a, b)]
        for s, e, _ in top:
            if e <= a or s >= b:
                continue
            pieces = [p for x, y in pieces for p in ((x, min(y, s)), (max(x, e), y)) if p[1] > p[0]]
        out.extend((x, y, v) for x, y in pieces)
    out.extend(top)
    out.sort(key=lambda seg: (seg[0], seg[1]))
    return out
