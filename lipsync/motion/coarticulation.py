"""Coarticulation: the ``dominance`` timing model (Cohen & Massaro's dominance functions).

The rule-based sequencer (:mod:`lipsync.motion.sequencer`) gives every sound its own shape, held
around its middle, with short transitions centred on the boundaries. Real lips do not
move like that (measured on GRID speaker s1, ``python -m lipsync.bench --only coarticulation``):
they are always on their way somewhere, a vowel between two closures is less open than
the same vowel held, lips round ahead of a rounded vowel, and a short sound is undershot
rather than reached. Cohen & Massaro (1993) model this with a *dominance function* per
sound: how strongly the sound pulls the mouth toward its own shape at each moment. The
shape shown is the dominance-weighted blend of the sounds' shapes.

The model here, per planned viseme segment ``[s, e)`` of class ``c`` (a viseme's class
comes from the phones the map sends to it, :func:`viseme_classes`):

* full dominance ``D_c`` on ``[s - LEAD, e - LEAD)``: the mouth leads the sound by
  ``lead`` (lips move before the acoustic event they make);
* before it, an anticipatory rise over ``anticipation_c`` seconds, after it a carry-over
  decay over ``carryover_c`` seconds, both raised-cosine tails (smooth, and exactly zero
  beyond their range, so a frame depends on a bounded stretch of the future: the live
  look-ahead, :func:`lookahead`);
* the weights of each viseme are summed; the renderer shows two visemes at a time, so each
  frame is the blend of the two heaviest, ``alpha = w_to / (w_from + w_to)`` with ``from``
  the one whose sound came first (the same (from, to, alpha) every bank and method takes;
  a third viseme's weight is dropped: measured in ``make bench``, it costs 0.003 of
  correlation with real lips, and the toon's mouth lines sit 0.3 px from the full blend on
  average, so a three-way blend, which would need a new kernel path, is not worth it);
* a closure (the map's ``closures``: P, B, M) is shown exactly on every frame inside its
  sound, and on the frame nearest its middle when it is shorter than a frame, whatever the
  weights say: the most visible lip-sync error is lips that do not close;
* the breath before speech: speakers part their lips to draw breath before they speak
  (measured on GRID s1: the mouth opens to about its slightly-open consonant shape 200-400
  ms before the first sound, twice its opening at rest). After a pause of at least
  :data:`BREATH_MIN_PAUSE_S`, the last ``breath.duration`` seconds before speech weigh
  toward the map's ``breath`` viseme (Rhubarb's B) with their own dominance and tails, as
  one more segment would; maps without a ``breath`` viseme have none.

Closures and labiodentals (F, V) get high dominance, so they win over their neighbours
(lips close on P/B/M, touch on F/V), rounded sounds a long anticipation (lips round ahead),
tongue consonants low dominance (lips barely care about them: the neighbouring vowels
shape the mouth). The constants are fitted to real speech (:data:`DEFAULT_PARAMS` says how)
and may be fitted again to one speaker (:func:`fit`) and stored in the speaker's bank.yaml.

Examples
--------
>>> from lipsync.motion.timeline import Segment, Timeline
>>> tl = Timeline((Segment(0, 0.4, "X"), Segment(0.4, 0.5, "A"), Segment(0.5, 0.9, "D"),
...                Segment(0.9, 1.3, "X")), kind="viseme")
>>> specs = dominance_sequence(tl, fps=25, rest="X", closures=["A"])
>>> [f.shown or "~" for f in specs][8:18]    # 25 fps: closed on the P, then open
['X', '~', 'A', 'A', 'A', '~', 'D', 'D', 'D', 'D']
"""

from __future__ import annotations

import math
from typing import Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from ..errors import InputError
from .frames import FrameSpec, base_track, checked_frames
from .timeline import VISEME, Timeline
from .timing import DEFAULT_CURVE, check_timing, is_model

#: Smallest dominance accepted. Weights are dominance x a tail in 0..1 and are compared as
#: ratios: a subnormal dominance (5e-324) underflowed to 0 and turned 52 of 75 frames into
#: fixed 0.5 blends. 1e-6 against the largest (1e4) keeps every ratio within float64.
MIN_DOMINANCE = 1e-6

#: The articulatory classes a viseme can have (what its dominance constants depend on).
CLASSES = ("closure", "labiodental", "rounded", "open", "other", "rest")

# Phone classes of the canonical English phone set (configs/phonesets/english.yaml), which
# decide a viseme's class by the phones a map sends to it.
_LABIODENTAL = frozenset({"F", "V"})
_BILABIAL = frozenset({"P", "B", "M"})
# English /r/ and /er/ are lip-rounded, as are the back rounded vowels and /w/.
_ROUNDED = frozenset({"UW", "UH", "OW", "AO", "W", "R", "ER"})
_VOWELS = frozenset({"AA", "AE", "AH", "AO", "AW", "AY", "EH", "ER", "EY", "IH", "IY", "OW", "OY", "UH", "UW"})


class ClassTiming(BaseModel):
    """Dominance constants of one viseme class.

    Attributes
    ----------
    dominance : float
        How strongly a sound of this class pulls the mouth to its shape (relative; only
        ratios between classes matter).
    anticipation : float
        Seconds before the sound (less the lead) over which its dominance rises from zero.
    carryover : float
        Seconds after the sound over which its dominance decays to zero.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)
    dominance: float = Field(ge=MIN_DOMINANCE, le=1e4)
    anticipation: float = Field(ge=0, le=0.3)
    carryover: float = Field(ge=0, le=0.3)


class BreathTiming(ClassTiming):
    """Dominance constants of the breath before speech (module docstring).

    Attributes
    ----------
    duration : float
        Seconds before the first sound after a pause over which the breath viseme has full
        dominance; 0 turns the breath off.
    """

    duration: float = Field(0.0, ge=0, le=0.3)


#: No breath: what :class:`DominanceParams` made without a ``breath`` has.
NO_BREATH = BreathTiming(dominance=1.0, anticipation=0.0, carryover=0.0, duration=0.0)

#: Pauses at least this long end with a breath (shorter gaps lie between words of one breath
#: group: a speaker does not inhale there). A cut of the live sequencer inside a pause keeps
#: at least this much of it, so the window sees the same breaths.
BREATH_MIN_PAUSE_S = 0.3


class DominanceParams(BaseModel):
    """The dominance model's constants: a lead, one :class:`ClassTiming` per class and the
    breath before speech (:class:`BreathTiming`).

    Stored in bank.yaml under ``coarticulation:`` when fitted to a speaker (every key
    optional there: missing ones keep :data:`DEFAULT_PARAMS`' values).

    Examples
    --------
    >>> DEFAULT_PARAMS.closure.dominance > DEFAULT_PARAMS.other.dominance
    True
    >>> round(lookahead(DEFAULT_PARAMS), 3) <= 0.38
    True
    """

    model_config = ConfigDict(extra="forbid", frozen=True)
    lead: float = Field(ge=-0.1, le=0.1)
    closure: ClassTiming
    labiodental: ClassTiming
    rounded: ClassTiming
    open: ClassTiming
    other: ClassTiming
    rest: ClassTiming
    breath: BreathTiming = NO_BREATH

    def of(self, cls: str) -> ClassTiming:
        return getattr(self, cls)

    def merged(self, overrides: Mapping) -> "DominanceParams":
        """A copy with the given keys replaced (nested per class), validated.

        Examples
        --------
        >>> DEFAULT_PARAMS.merged({"lead": 0.0, "rest": {"dominance": 2.0}}).rest.dominance
        2.0
        """
        data = self.model_dump()
        for key, value in dict(overrides).items():
            if isinstance(value, Mapping) and isinstance(data.get(key), dict):
                data[key] = {**data[key], **dict(value)}
            else:
                data[key] = value
        return DominanceParams.model_validate(data)


class ClassTimingOverrides(BaseModel):
    """Some constants of one class, as bank.yaml's ``coarticulation:`` may give them."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    dominance: Optional[float] = Field(None, ge=MIN_DOMINANCE, le=1e4)
    anticipation: Optional[float] = Field(None, ge=0, le=0.3)
    carryover: Optional[float] = Field(None, ge=0, le=0.3)


class BreathTimingOverrides(ClassTimingOverrides):
    """Some constants of the breath before speech, as bank.yaml may give them."""

    duration: Optional[float] = Field(None, ge=0, le=0.3)


class DominanceOverrides(BaseModel):
    """bank.yaml's ``coarticulation:``: constants fitted to the bank's speaker, every key optional.

    Examples
    --------
    >>> DominanceOverrides(lead=0.03, rounded={"anticipation": 0.2}).apply().rounded.anticipation
    0.2
    """

    model_config = ConfigDict(extra="forbid", frozen=True)
    lead: Optional[float] = Field(None, ge=-0.1, le=0.1)
    closure: Optional[ClassTimingOverrides] = None
    labiodental: Optional[ClassTimingOverrides] = None
    rounded: Optional[ClassTimingOverrides] = None
    open: Optional[ClassTimingOverrides] = None
    other: Optional[ClassTimingOverrides] = None
    rest: Optional[ClassTimingOverrides] = None
    breath: Optional[BreathTimingOverrides] = None

    def apply(self, base: Optional["DominanceParams"] = None) -> "DominanceParams":
        """The full constants: ``base`` (default :data:`DEFAULT_PARAMS`) with these replaced."""
        return (base or DEFAULT_PARAMS).merged(self.model_dump(exclude_none=True))


# --- the constants ------------------------------------------------------------------------
# Fitted on GRID speaker s1's BANK_CLIPS (lipsync.bench.grid; the held-out sentences took no
# part), phones from lipsync's own aligner with the transcripts, the english-to-rhubarb map,
# and an ideal bank (each viseme the speaker's median lip opening over the frames aligned
# to it): :func:`fit` maximised the mean correlation between the predicted and the real lip
# opening (face mesh, lipsync.face), from :data:`START_PARAMS` (below, "start"). Rounded to
# two digits: the fit is flat there (the rounded constants score within 0.002 of the fitted
# ones). ``python -m lipsync.bench --only coarticulation`` refits and prints the held-out
# figures.
#: Where :func:`fit` started (the "start" values below): textbook magnitudes, no lead.
START_PARAMS = DominanceParams(
    lead=0.0,
    closure=ClassTiming(dominance=8.0, anticipation=0.04, carryover=0.04),
    labiodental=ClassTiming(dominance=4.0, anticipation=0.04, carryover=0.04),
    rounded=ClassTiming(dominance=2.0, anticipation=0.15, carryover=0.06),
    open=ClassTiming(dominance=1.0, anticipation=0.08, carryover=0.08),
    other=ClassTiming(dominance=0.3, anticipation=0.06, carryover=0.06),
    rest=ClassTiming(dominance=0.5, anticipation=0.1, carryover=0.1),
    breath=BreathTiming(dominance=0.5, anticipation=0.1, carryover=0.1, duration=0.2),
)

DEFAULT_PARAMS = DominanceParams(
    # Lips move ahead of the sound they make: the picture of speech leads its sound by tens
    # of ms (start 0; fitted 13 ms).
    lead=0.013,
    # P, B, M: ten times a vowel's pull, short tails: the lips close for the stop and open
    # at its release (start: 8, 40 ms; fitted to the bound of 10, FIT_DOMINANCE_RANGE, and
    # 39 ms). The fit is flat in this dominance, as every frame inside a closure shows it
    # anyway (``closures``); it matters for the frames around one, where the lips are on
    # their way to or from closing.
    closure=ClassTiming(dominance=10.0, anticipation=0.039, carryover=0.039),
    # F, V: seven times a vowel's pull (lower lip to the upper teeth must happen, and no
    # frame is forced for it), as brief as a closure (start 4; fitted 7.1, 39 ms).
    labiodental=ClassTiming(dominance=7.1, anticipation=0.039, carryover=0.039),
    # UW, W, R, AO ...: a vowel's pull, but rounding starts earlier, 117 ms ahead of the
    # sound (start: 2, 150 ms; fitted 0.84, 117 ms, and 76 ms after).
    rounded=ClassTiming(dominance=0.84, anticipation=0.117, carryover=0.076),
    # Vowels: the unit of dominance; their pull reaches 76 ms either side (start: 80 ms).
    open=ClassTiming(dominance=1.0, anticipation=0.076, carryover=0.076),
    # Tongue consonants (T, S, K, N, L ...) and the close front vowels that share their
    # viseme in small viseme sets: a tenth of a vowel's pull, so neighbouring vowels and lip
    # sounds shape the mouth over them (start 0.3; fitted to the bound of 0.1).
    other=ClassTiming(dominance=0.1, anticipation=0.076, carryover=0.076),
    # Silence: a third of a vowel's pull, so a short pause keeps the shape around it, but
    # its 181 ms tails relax the mouth into a pause and out of it (start: 0.5, 100 ms;
    # fitted 0.32, 181 ms).
    rest=ClassTiming(dominance=0.32, anticipation=0.181, carryover=0.181),
    # The breath before speech: the lips part 258 ms before the first sound after a pause,
    # pulling harder than the pause around them (start: 0.5, 200 ms, tails 100 ms; fitted
    # 1.4, tails 109 ms, and the 258 ms that keep the live look-ahead at the bound
    # FIT_MAX_LOOKAHEAD_S: 13 + 258 + 109 = 380 ms). This is the longest reach ahead, so it
    # sets the live look-ahead (of maps with a breath viseme).
    breath=BreathTiming(dominance=1.4, anticipation=0.109, carryover=0.109, duration=0.258),
)

#: A blend this close to one viseme is shown as that viseme. Dominance tails make long
#: sounds exact only where no neighbour's tail reaches; the last 2 % of a blend moves a
#: mouth edge by well under a pixel (mouth shapes differ by ~20-80 px at 512 px), yet each such
#: frame would be rendered instead of repeated (a held frame is written again, not
#: rendered). Snapping them keeps the holds (measured in ``make bench``: coarticulation).
SNAP_ALPHA = 0.02

# Numerical slack when comparing alphas (float noise, not a tuning value).
_EPS = 1e-9
#: Frames computed at once (bounds memory for long recordings: a few MB per chunk).
_CHUNK = 4096


def as_params(timing) -> DominanceParams:
    """The dominance constants ``timing`` stands for: ``"dominance"`` (or its alias) gives
    :data:`DEFAULT_PARAMS`, a :class:`DominanceParams` itself, a mapping the defaults
    with those keys replaced.

    Examples
    --------
    >>> as_params("dominance") is DEFAULT_PARAMS, as_params({"lead": 0.0}).lead
    (True, 0.0)
    """
    if isinstance(timing, DominanceParams):
        return timing
    if isinstance(timing, str):
        check_timing(timing)
        if not is_model(timing):
            raise InputError(f"timing {timing!r} is a transition curve, not the dominance model")
        return DEFAULT_PARAMS
    if isinstance(timing, Mapping):
        try:
            return DEFAULT_PARAMS.merged(timing)
        except ValidationError as exc:
            raise InputError(f"dominance constants: {_first_error(exc)}") from None
    raise InputError(f"a timing must be a curve name, a callable, 'dominance' or DominanceParams, not {timing!r}")


def _first_error(exc: ValidationError) -> str:
    err = exc.errors()[0]
    where = ".".join(str(x) for x in err.get("loc", ()))
    return f"{where}: {err.get('msg', 'invalid')}" if where else str(err.get("msg", "invalid"))


def resolve_timing(timing=None, bank=None):
    """The timing a render uses: the one asked for, else the bank's, else the default curve.

    ``timing`` None means "not chosen": the bank's ``timing:`` from bank.yaml if it has
    one, else :data:`lipsync.motion.timing.DEFAULT_CURVE`. The dominance model, however chosen,
    takes the bank's fitted constants (``coarticulation:`` in bank.yaml) when it has them.
    What comes back is what :func:`lipsync.motion.sequencer.sequence` takes as ``timing``.

    Examples
    --------
    >>> resolve_timing(), resolve_timing("linear"), resolve_timing("dominance") is DEFAULT_PARAMS
    ('sqrt-fast-middle', 'linear', True)
    """
    if timing is None:
        timing = getattr(bank, "timing", None) or DEFAULT_CURVE
    if isinstance(timing, str) and is_model(timing):
        fitted = getattr(bank, "coarticulation", None)
        return fitted if fitted is not None else as_params(timing)
    return timing


def lookahead(params: DominanceParams = DEFAULT_PARAMS, *, breath: bool = True) -> float:
    """Seconds of data past a frame's time that decide it: the longest anticipation plus the lead.

    A sound starting at ``s`` weighs on frames from ``s - lead - anticipation`` on, and on
    no earlier one; the breath before it (``breath``: when the map has a breath viseme)
    from ``s - lead - breath.duration - breath.anticipation`` on. Everything else a frame
    depends on (the sound it lies in, the tails of earlier sounds, closures within half a
    frame, the length of the pause it lies in) is older.

    Examples
    --------
    >>> p = DEFAULT_PARAMS.merged({"lead": 0.02, "rounded": {"anticipation": 0.2}})
    >>> round(lookahead(p, breath=False), 3)
    0.22
    """
    reach = max(params.of(c).anticipation for c in CLASSES)
    if breath and params.breath.duration > 0:
        reach = max(reach, params.breath.duration + params.breath.anticipation)
    return max(0.0, params.lead + reach)


def carryover(params: DominanceParams = DEFAULT_PARAMS) -> float:
    """Seconds after a sound's end (less the lead) that its dominance still reaches (a
    breath's too)."""
    return max(0.0, max(params.of(c).carryover for c in CLASSES + ("breath",)) - params.lead)


class VisemeClasses(dict):
    """Viseme -> class (:data:`CLASSES`), and the viseme of the breath before speech.

    A plain dict of the classes, with ``breath`` (a viseme name, or None for no breath)
    beside them, so that everything that hands a map's classes to the model hands on its
    breath viseme too.

    Examples
    --------
    >>> c = VisemeClasses({"X": "rest", "B": "other"}, breath="B")
    >>> c["X"], c.breath
    ('rest', 'B')
    """

    def __init__(self, classes=(), breath: Optional[str] = None):
        super().__init__(classes)
        self.breath = breath

    def __repr__(self) -> str:
        return f"VisemeClasses({dict.__repr__(self)}, breath={self.breath!r})"

    def __reduce__(self):
        return (VisemeClasses, (dict(self), self.breath))


def viseme_classes(pmap, rest: Optional[str] = None) -> VisemeClasses:
    """Each viseme of a phoneme map -> its class (:data:`CLASSES`), from the phones it shows.

    The map's ``closures`` are ``closure`` and its silence viseme ``rest``; any other viseme
    takes the class most of its phones have (a diphthong's half counts half): ``labiodental``
    (F, V), ``rounded`` (UW, UH, OW, AO, W, R, ER), ``open`` (other vowels) or ``other``
    (tongue consonants). Phones outside the English phone set count as ``other``. The map's
    ``breath`` viseme comes along as ``.breath``.

    Examples
    --------
    >>> from lipsync.phonetics.phonemes import load_map
    >>> c = viseme_classes(load_map("english-to-rhubarb"))
    >>> [c[v] for v in "ABCDEFGHX"], c.breath
    (['closure', 'other', 'open', 'open', 'rounded', 'rounded', 'labiodental', 'other', 'rest'], 'B')
    """
    votes: Dict[str, Dict[str, float]] = {}
    for phone, target in pmap.map.items():
        targets = [target] if isinstance(target, str) else list(target)
        share = 1.0 / len(targets)
        for i, v in enumerate(targets):
            p = phone.upper()
            if p in _BILABIAL:
                cls = "closure"
            elif p in _LABIODENTAL:
                cls = "labiodental"
            elif p in _ROUNDED or (p in ("OW", "AW") and i == len(targets) - 1):
                cls = "rounded"
            elif p in _VOWELS:
                cls = "open"
            else:
                cls = "other"
            # A diphthong's halves: OW's and AW's end is rounded, AY's and OY's end is IY-like.
            if p in ("AY", "OY", "EY") and i == len(targets) - 1:
                cls = "other"
            if p == "OY" and i == 0:
                cls = "rounded"
            votes.setdefault(v, {}).setdefault(cls, 0.0)
            votes[v][cls] += share
    out = {}
    for v in pmap.visemes():
        tally = votes.get(v, {})
        out[v] = max(CLASSES[:5], key=lambda c: (tally.get(c, 0.0), -CLASSES.index(c))) if tally else "other"
    # closure: only what the map declares (a viseme of B, M, P the map does not call a
    # closure keeps the strongest other class rather than forced frames it never asked for)
    for v, cls in list(out.items()):
        if cls == "closure" and v not in pmap.closures:
            out[v] = "labiodental"
    for v in pmap.closures:
        out[v] = "closure"
    out[rest if rest is not None else pmap.silence] = "rest"
    return VisemeClasses(out, breath=getattr(pmap, "breath", None))


#: The default map's (english-to-rhubarb) viseme classes, written out: the sequencer sits
#: below the maps (lipsync.phonetics.phonemes reads timelines), so it cannot load the map to learn
#: them. tests/test_coarticulation.py checks this table against
#: ``viseme_classes(load_map(DEFAULT_MAP))``.
DEFAULT_MAP_CLASSES = {
    "A": "closure",      # M, B, P: lips pressed
    "B": "other",        # most consonants: lips parted, teeth near
    "C": "open",         # EH, AE, ...: open
    "D": "open",         # AA, AY: wide open
    "E": "rounded",      # AO, ER: slightly rounded
    "F": "rounded",      # UW, OW, W: puckered
    "G": "labiodental",  # F, V: lower lip on the teeth
    "H": "other",        # L: tongue behind the teeth
    "X": "rest",         # silence
}


def default_classes(names: Iterable[str], *, rest: str, closures: Iterable[str] = ()) -> VisemeClasses:
    """Classes for visemes when no map is given: the default map's, where the names are its.
    No breath: without a map, which viseme the bank draws breath with is unknown.

    Examples
    --------
    >>> default_classes(["A", "F", "zz"], rest="X", closures=["A"])
    VisemeClasses({'A': 'closure', 'F': 'rounded', 'zz': 'other', 'X': 'rest'}, breath=None)
    """
    out = {v: DEFAULT_MAP_CLASSES.get(v, "other") for v in names}
    for v in closures:
        out[v] = "closure"
    out[rest] = "rest"
    return VisemeClasses(out)


def plan(visemes: Timeline, *, rest: str, closures: Iterable[str] = (), duration: Optional[float] = None,
         start: float = 0.0) -> List[Tuple[float, float, str]]:
    """The segments the model weighs: the sequencer's rules 1-2 (gaps are rest, equal
    neighbours merge). No sound is dropped or held: short sounds are undershot by their
    neighbours' dominance instead, and a short pause is outweighed by the sounds around it.

    Examples
    --------
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> plan(Timeline((Segment(0.1, 0.2, "A"), Segment(0.2, 0.21, "A")), kind="viseme"), rest="X", duration=0.3)
    [(0.0, 0.1, 'X'), (0.1, 0.21, 'A'), (0.21, 0.3, 'X')]
    """
    return [(s.start, s.end, s.label) for s in base_track(visemes, rest=rest, duration=duration, start=start)]


def _tail(x: np.ndarray) -> np.ndarray:
    # Raised cosine on [0, 1), exactly 0 from 1 on: smooth at both ends, compact support.
    return np.where(x < 1.0, np.cos(0.5 * np.pi * np.minimum(x, 1.0)) ** 2, 0.0)


def breaths(segments: Sequence[Tuple[float, float, str]], *, classes: Mapping[str, str],
            params: DominanceParams = DEFAULT_PARAMS) -> List[Tuple[float, float, str]]:
    """The breaths before speech of a planned track: ``(start, end, breath viseme)`` each.

    One at the end of every rest segment of at least :data:`BREATH_MIN_PAUSE_S` that speech
    follows, ``params.breath.duration`` long (or the whole pause, if shorter). None when
    ``classes`` has no ``breath`` viseme (:class:`VisemeClasses`) or the duration is 0.

    Examples
    --------
    >>> c = VisemeClasses({"X": "rest", "A": "closure", "B": "other"}, breath="B")
    >>> p = DEFAULT_PARAMS.merged({"breath": {"duration": 0.2}})
    >>> breaths([(0, 0.5, "X"), (0.5, 0.6, "A"), (0.6, 0.8, "X"), (0.8, 0.9, "A")], classes=c, params=p)
    [(0.3, 0.5, 'B')]
    """
    viseme = getattr(classes, "breath", None)
    duration = params.breath.duration
    if viseme is None or duration <= 0:
        return []
    out = []
    for (s, e, v), (_, _, nxt) in zip(segments[:-1], segments[1:]):
        if classes.get(v) == "rest" and e - s >= BREATH_MIN_PAUSE_S - _EPS and classes.get(nxt) != "rest":
            out.append((max(s, e - duration), e, viseme))
    return out


def _weighted(segments, classes, params) -> List[Tuple[float, float, str, ClassTiming]]:
    # Every segment with its class's constants, then the breaths with theirs.
    out = [(s, e, v, params.of(classes.get(v, "other"))) for s, e, v in segments]
    return out + [(s, e, v, params.breath) for s, e, v in breaths(segments, classes=classes, params=params)]


def weights(segments: Sequence[Tuple[float, float, str]], times: np.ndarray, *, classes: Mapping[str, str],
            params: DominanceParams = DEFAULT_PARAMS) -> np.ndarray:
    """Dominance of every segment, then of every breath (:func:`breaths`), at every time:
    ``(len(segments) + len(breaths), len(times))``.

    Examples
    --------
    >>> w = weights([(0, 1, "X"), (1, 2, "A")], np.array([0.5, 0.99, 1.5]), classes={"X": "rest", "A": "closure"})
    >>> (w[:, 0] > 0).tolist(), bool(w[1, 1] > w[0, 1])
    ([True, False], True)
    """
    t = np.asarray(times, dtype=np.float64)
    weighted = _weighted(segments, classes, params)
    out = np.zeros((len(weighted), len(t)))
    for k, (s, e, v, ct) in enumerate(weighted):
        out[k] = _segment_weight(s, e, ct, params.lead, t)
    return out


def _segment_weight(s: float, e: float, ct: ClassTiming, lead: float, t: np.ndarray) -> np.ndarray:
    before = (s - lead) - t
    after = t - (e - lead)
    w = np.full(t.shape, ct.dominance)
    if ct.anticipation > 0:
        w = np.where(before > 0, ct.dominance * _tail(before / ct.anticipation), w)
    else:
        w = np.where(before > 0, 0.0, w)
    if ct.carryover > 0:
        w = np.where(after >= 0, ct.dominance * _tail(after / ct.carryover), w)
    else:
        w = np.where(after >= 0, 0.0, w)
    return w


def dominance_frames(segments: Sequence[Tuple[float, float, str]], *, fps: float, classes: Mapping[str, str],
                     params: DominanceParams = DEFAULT_PARAMS, closures: Iterable[str] = (), first: int = 0,
                     stop: int, end: Optional[int] = None) -> List[FrameSpec]:
    """FrameSpecs of frames ``first .. stop - 1`` of a planned track (:func:`plan`).

    ``end`` is the number of frames of the whole track (default ``stop``). A frame depends
    only on the segments whose dominance reaches it (module docstring), so computing a part
    of a track from the segments around it gives exactly the frames of the whole track (the
    live animator relies on it).

    Examples
    --------
    >>> segs = [(0, 0.4, "X"), (0.4, 0.8, "D"), (0.8, 1.2, "X")]
    >>> [f.shown or "~" for f in dominance_frames(segs, fps=10, classes={"X": "rest", "D": "open"}, stop=12)]
    ['X', 'X', 'X', 'X', '~', '~', 'D', '~', '~', 'X', 'X', 'X']
    """
    end = stop if end is None else end
    if stop <= first:
        return []
    closure_set = set(closures)
    weighted = _weighted(segments, classes, params)
    names = sorted({v for _, _, v, _ in weighted})   # a fixed order: ties break the same way everywhere
    index = {v: i for i, v in enumerate(names)}
    starts = np.array([s for s, _, _ in segments], dtype=np.float64)
    lead = params.lead
    lo_t = np.array([s - lead - ct.anticipation for s, _, _, ct in weighted])  # weighs on frames after lo_t ...
    hi_t = np.array([e - lead + ct.carryover for _, e, _, ct in weighted])     # ... and before hi_t
    specs: List[FrameSpec] = []
    for c0 in range(first, stop, _CHUNK):
        c1 = min(stop, c0 + _CHUNK)
        t = np.arange(c0, c1, dtype=np.float64) / fps
        w = np.zeros((len(names), c1 - c0))
        order = np.full((len(names), c1 - c0), np.inf)   # start of the earliest sound weighing, per viseme
        for k in np.nonzero((hi_t > t[0]) & (lo_t < t[-1]))[0]:
            s, e, v, ct = weighted[k]
            a = max(int(math.floor((lo_t[k]) * fps)) - c0, 0)
            b = min(int(math.ceil((hi_t[k]) * fps)) + 1 - c0, c1 - c0)
            if b <= a:
                continue
            wk = _segment_weight(s, e, ct, lead, t[a:b])
            i = index[v]
            w[i, a:b] += wk
            order[i, a:b] = np.where(wk > 0, np.minimum(order[i, a:b], s), order[i, a:b])
        # No weight at all happens only at the very end of a track whose last sound's
        # carry-over is shorter than the lead: the frame shows the sound it lies in.
        for col in np.nonzero(~(w > 0).any(axis=0))[0]:
            k = max(int(np.searchsorted(starts, t[col], side="right")) - 1, 0)
            w[index[segments[k][2]], col] = 1.0
        specs.extend(_project(w, order, names))
    _force_closures(specs, segments, closure_set, fps=fps, first=first, stop=stop, end=end)
    return specs


def _project(w: np.ndarray, order: np.ndarray, names: List[str]) -> List[FrameSpec]:
    # The two heaviest visemes per frame, their weights renormalised, the earlier-sounding one
    # as "from". Measured on the toon's control lines (make bench, coarticulation_projection):
    # the shown mouth is 0.3 px from the full blend of every viseme on average; taking the
    # third weight off both (continuous except where three weights meet) was worse at 25 fps,
    # as near such a point the pair's alpha swings with tiny weight changes.
    n = w.shape[1]
    if len(names) == 1:
        return [FrameSpec(names[0], names[0], 0.0)] * n
    top = np.argsort(-w, axis=0, kind="stable")[:2]
    cols = np.arange(n)
    i1, i2 = top[0], top[1]
    w1, w2 = w[i1, cols], w[i2, cols]
    swap = order[i2, cols] < order[i1, cols]
    fi, ti = np.where(swap, i2, i1), np.where(swap, i1, i2)
    wf, wt = np.where(swap, w2, w1), np.where(swap, w1, w2)
    total = wf + wt
    alpha = np.where(total > 0, wt / np.where(total > 0, total, 1.0), 0.0)
    out = []
    for f, g, a in zip(fi.tolist(), ti.tolist(), alpha.tolist()):
        if a <= SNAP_ALPHA:
            out.append(FrameSpec(names[f], names[f], 0.0))
        elif a >= 1.0 - SNAP_ALPHA:
            out.append(FrameSpec(names[g], names[g], 0.0))
        else:
            out.append(FrameSpec(names[f], names[g], a))
    return out


def _force_closures(specs: List[FrameSpec], segments, closure_set, *, fps: float, first: int, stop: int,
                    end: int) -> None:
    # Every frame inside a closure shows it exactly; a closure shorter than a frame gets the
    # frame nearest its middle (as the sequencer's rule 7 does).
    for s, e, v in segments:
        if v not in closure_set:
            continue
        lo = max(int(math.ceil(s * fps - _EPS)), 0)
        hi = min(int(math.ceil(e * fps - _EPS)) - 1, end - 1)
        rng = range(lo, hi + 1) if hi >= lo else [min(max(int(round(0.5 * (s + e) * fps)), 0), end - 1)]
        for n in rng:
            if first <= n < stop:
                specs[n - first] = FrameSpec(v, v, 0.0)


def dominance_sequence(visemes: Timeline, *, fps: float, rest: str, closures: Iterable[str] = (),
                       classes: Optional[Mapping[str, str]] = None, params: DominanceParams = DEFAULT_PARAMS,
                       duration: Optional[float] = None) -> List[FrameSpec]:
    """One FrameSpec per output frame of a viseme timeline, by the dominance model.

    What :func:`lipsync.motion.sequencer.sequence` does with ``timing="dominance"``.

    Parameters
    ----------
    visemes : Timeline
        A viseme timeline (gaps are silence).
    fps : float
        Frame rate, 1 to 120; frame n shows time n / fps.
    rest : str
        The rest viseme.
    closures : iterable of str
        Visemes shown exactly on every frame inside them (the closed lips of P, B, M).
    classes : mapping, optional
        Viseme -> class (:func:`viseme_classes` of the map); default :func:`default_classes`.
    params : DominanceParams
        The constants (default :data:`DEFAULT_PARAMS`, or a bank's fitted ones).
    duration : float, optional
        Length of the output; default ``visemes.duration``.

    Returns
    -------
    list of FrameSpec
        Exactly ``ceil(duration * fps)`` entries.

    Examples
    --------
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> tl = Timeline((Segment(0, 0.3, "X"), Segment(0.3, 0.6, "D")), kind="viseme")
    >>> len(dominance_sequence(tl, fps=10, rest="X"))
    6
    """
    fps, total, n_frames = checked_frames(visemes, fps, duration)
    closure_set = set(closures)
    if n_frames == 0:
        return []
    segs = plan(visemes, rest=rest, closures=closure_set, duration=total)
    if classes is None:
        classes = default_classes({v for _, _, v in segs}, rest=rest, closures=closure_set)
    return dominance_frames(segs, fps=fps, classes=classes, params=params, closures=closure_set, stop=n_frames)


# --- fitting ------------------------------------------------------------------------------

#: The constants :func:`fit` adjusts, each group sharing one value (13 in all: 10 for the
#: classes, 3 for the breath before speech). With about 30 s of one speaker's video, letting
#: the 18 class constants go free fitted the dev sentences better (r 0.737 against 0.694,
#: before the breath) and the held-out ones no better (0.721 against 0.723), and pushed two
#: anticipations to their 300 ms bound.
#: The open vowels' dominance is the unit (only ratios matter), so it is not fitted.
FIT_GROUPS: Tuple[Tuple[Tuple[str, str], ...], ...] = (
    (("lead", ""),),
    (("closure", "dominance"),),
    (("labiodental", "dominance"),),
    (("rounded", "dominance"),),
    (("other", "dominance"),),
    (("rest", "dominance"),),
    # the lips' own stops: brief tails either side
    (("closure", "anticipation"), ("closure", "carryover"), ("labiodental", "anticipation"),
     ("labiodental", "carryover")),
    # rounding starts early
    (("rounded", "anticipation"),),
    # every other sound: one tail length
    (("rounded", "carryover"), ("open", "anticipation"), ("open", "carryover"), ("other", "anticipation"),
     ("other", "carryover")),
    # relaxing into and out of a pause
    (("rest", "anticipation"), ("rest", "carryover")),
    # the breath before speech: how hard, how long, and its tails
    (("breath", "dominance"),),
    (("breath", "duration"),),
    (("breath", "anticipation"), ("breath", "carryover")),
)

#: The live look-ahead :func:`fit` may not exceed: the rule-based sequencer's (380 ms,
#: :data:`lipsync.live.causal.LOOKAHEAD_S`), which apps streaming TTS events are built around.
#: Only the breath reaches that far (the longest anticipation of a sound is 115 ms), so the
#: fit shortens the breath's full-dominance stretch to stay within it.
FIT_MAX_LOOKAHEAD_S = 0.38


#: Dominances :func:`fit` may choose, relative to an open vowel's 1. A class pulling much
#: harder than its neighbours turns its tails into cuts: fitted freely, F/V went to 23 and
#: the toon showed a sound between two of them for one frame, alone, twice in 40 random
#: tracks (a pop); bounded at 10, the same held-out correlation (0.723) and no pop.
FIT_DOMINANCE_RANGE = (0.1, 10.0)


def _to_vector(params: DominanceParams) -> np.ndarray:
    out = []
    for group in FIT_GROUPS:
        cls, key = group[0]
        if cls == "lead":
            out.append(params.lead * 10.0)      # ~0.1-sized steps, as the logs below
        elif key == "dominance":
            out.append(math.log(params.of(cls).dominance))
        else:
            out.append(math.log(max(getattr(params.of(cls), key), 1e-3)))
    return np.array(out)


def _from_vector(x: np.ndarray, base: DominanceParams) -> DominanceParams:
    data = base.model_dump()
    for value, group in zip(x, FIT_GROUPS):
        for cls, key in group:
            if cls == "lead":
                data["lead"] = float(np.clip(value / 10.0, -0.1, 0.1))
            elif key == "dominance":
                data[cls]["dominance"] = float(np.clip(math.exp(value), *FIT_DOMINANCE_RANGE))
            else:
                data[cls][key] = float(np.clip(math.exp(min(value, 5.0)), 0.0, 0.3))
    b = data["breath"]
    b["duration"] = min(b["duration"], max(0.0, FIT_MAX_LOOKAHEAD_S - data["lead"] - b["anticipation"]))
    return DominanceParams.model_validate(data)


def predicted(specs: Sequence[FrameSpec], values: Mapping[str, float]) -> np.ndarray:
    """A measure per frame of a schedule: each viseme's value blended by the frame's alpha.

    Examples
    --------
    >>> predicted([FrameSpec("A", "D", 0.25), FrameSpec("D", "D", 0.0)], {"A": 0.0, "D": 1.0}).tolist()
    [0.25, 1.0]
    """
    return np.array([(1.0 - f.alpha) * values[f.from_viseme] + f.alpha * values[f.to_viseme] for f in specs])


def fit(tracks: Sequence[Tuple[Sequence[Tuple[float, float, str]], np.ndarray]], values: Mapping[str, float], *,
        fps: float, classes: Mapping[str, str], closures: Iterable[str] = (),
        start: DominanceParams = DEFAULT_PARAMS, iterations: int = 600, restarts: int = 2) -> DominanceParams:
    """Constants that make the model follow a speaker's real lips (the groups of :data:`FIT_GROUPS`).

    Maximises the mean, over tracks, of the correlation between the real measure and the one
    the model predicts with ``values`` per viseme (frames as the renderer shows them: the
    projected (from, to, alpha), closures forced), by Nelder-Mead on the logarithms of the
    constants, restarted from its own result (a simplex collapses early on a flat objective).

    Parameters
    ----------
    tracks : sequence of (segments, numpy.ndarray) or (segments, numpy.ndarray, fps)
        Per recording: its planned viseme segments (:func:`plan`), the real measure per
        frame (e.g. :func:`lipsync.face.measure.lip_opening` of its face track; NaN frames,
        where no face was found, are left out), and its frame rate if not ``fps``.
    values : mapping
        The measure of each viseme's image in the bank (or the speaker's median over frames
        aligned to it: an "ideal bank").
    fps : float
        Frame rate of the tracks.
    classes, closures
        As for :func:`dominance_frames`.
    start : DominanceParams
        Where the search starts; constants outside :data:`FIT_GROUPS` keep its values.
    iterations, restarts : int
        Simplex steps per run, and runs after the first.

    Returns
    -------
    DominanceParams

    Examples
    --------
    >>> segs = [(0, 0.5, "X"), (0.5, 0.62, "A"), (0.62, 0.9, "D"), (0.9, 1.4, "X")]
    >>> real = np.r_[np.zeros(11), np.ones(12), np.zeros(12)]    # lips open early, then rest
    >>> p = fit([(segs, real)], {"X": 0, "A": 0, "D": 1}, fps=25, classes={"X": "rest", "A": "closure", "D": "open"},
    ...         closures=["A"], iterations=60, restarts=0)
    >>> isinstance(p, DominanceParams)
    True
    """
    closures = list(closures)
    prepared = []
    for track in tracks:
        segs, real = track[0], np.asarray(track[1], dtype=np.float64)
        rate = float(track[2]) if len(track) > 2 else fps
        ok = np.isfinite(real)          # frames where the face was lost do not count
        if ok.sum() >= 3 and real[ok].std() > 0:
            prepared.append((list(segs), real, ok, rate))
    if not prepared:
        raise InputError("fit() needs at least one track with a moving measure")

    def loss(x: np.ndarray) -> float:
        params = _from_vector(x, start)
        rs = []
        for segs, real, ok, rate in prepared:
            specs = dominance_frames(segs, fps=rate, classes=classes, params=params, closures=closures,
                                     stop=len(real))
            pred = predicted(specs, values)[ok]
            rs.append(0.0 if pred.std() == 0 else float(np.corrcoef(pred, real[ok])[0, 1]))
        return -float(np.mean(rs))

    x = _to_vector(start)
    for _ in range(restarts + 1):
        x, _ = _nelder_mead(loss, x, step=0.3, iterations=iterations)
    return _from_vector(x, start)


def _nelder_mead(f, x0: np.ndarray, *, step: float, iterations: int, tol: float = 1e-6):
    # The textbook simplex (reflect, expand, contract, shrink); a few lines here rather than
    # scipy as a dependency for one call.
    n = len(x0)
    pts = [np.asarray(x0, dtype=np.float64)] + [x0 + step * np.eye(n)[i] for i in range(n)]
    vals = [f(p) for p in pts]
    for _ in range(iterations):
        order = np.argsort(vals)
        pts, vals = [pts[i] for i in order], [vals[i] for i in order]
        if abs(vals[-1] - vals[0]) < tol:
            break
        centre = np.mean(pts[:-1], axis=0)
        xr = centre + (centre - pts[-1])
        fr = f(xr)
        if fr < vals[0]:
            xe = centre + 2.0 * (centre - pts[-1])
            fe = f(xe)
            pts[-1], vals[-1] = (xe, fe) if fe < fr else (xr, fr)
        elif fr < vals[-2]:
            pts[-1], vals[-1] = xr, fr
        else:
            xc = centre + 0.5 * (pts[-1] - centre)
            fc = f(xc)
            if fc < vals[-1]:
                pts[-1], vals[-1] = xc, fc
            else:
                pts = [pts[0]] + [pts[0] + 0.5 * (p - pts[0]) for p in pts[1:]]
                vals = [vals[0]] + [f(p) for p in pts[1:]]
    i = int(np.argmin(vals))
    return pts[i], vals[i]


#: Fitting a speaker in ``lipsync init --video`` (:func:`fit_speaker`): fewer simplex steps
#: than the dev fit, from the defaults (measured on GRID s1's 10 bank sentences: the same
#: constants as 600 steps x 3 runs, 4.4 s of CPU instead of 6).
SPEAKER_ITERATIONS = 300
SPEAKER_RESTARTS = 1
#: Less speech than this (seconds of frames inside sounds) says too little about how the
#: speaker's lips move: the defaults are kept.
MIN_SPEECH_S = 5.0


def fit_speaker(recordings, values: Mapping[str, float], pmap) -> Optional[DominanceParams]:
    """The dominance constants for one speaker, from videos of them talking (or None).

    To store in a bank's bank.yaml (``coarticulation:``, :func:`rounded`). Measured on GRID s1
    (``make bench``, ``coarticulation_rendered``), with a bank made by ``lipsync init --video``
    from the 10 bank sentences: held-out sentences rendered with constants fitted this way
    (to the same 10 sentences) follow the real lips no better than with
    :data:`DEFAULT_PARAMS` (r 0.719 against 0.721; an earlier bank of the same speaker:
    0.676 against 0.671), so ``init --video`` keeps the defaults; a speaker unlike the one
    they were fitted on may gain more.

    Parameters
    ----------
    recordings : sequence of (segments, numpy.ndarray, float)
        Per video: its viseme segments (start, end, viseme) covering it, the lip opening
        per frame (:func:`lipsync.face.measure.lip_opening`; NaN where no face), its fps.
    values : mapping
        Each viseme's lip opening in the bank's pictures.
    pmap : PhonemeMap
        The map the bank was made with (its visemes' classes and closures).

    Returns
    -------
    DominanceParams or None
        None when the videos hold less than :data:`MIN_SPEECH_S` of speech.
    """
    from .timeline import Segment

    classes = viseme_classes(pmap)
    rest = pmap.silence
    tracks, speech = [], 0.0
    for segments, opening, rate in recordings:
        n = len(opening)
        tl = Timeline(tuple(Segment(s, e, v) for s, e, v in segments), kind=VISEME, stated_end=n / rate)
        segs = plan(tl, rest=rest, closures=pmap.closures, duration=n / rate)
        speech += sum(min(e, n / rate) - s for s, e, v in segs if v != rest and s < n / rate)
        tracks.append((segs, opening, rate))
    if speech < MIN_SPEECH_S or not tracks:
        return None
    try:
        return fit(tracks, values, fps=tracks[0][2], classes=classes, closures=pmap.closures,
                   iterations=SPEAKER_ITERATIONS, restarts=SPEAKER_RESTARTS)
    except InputError:
        return None


def rounded(params: DominanceParams) -> dict:
    """The constants as bank.yaml stores them: dominance to 2 digits, times to the ms.

    Examples
    --------
    >>> rounded(DEFAULT_PARAMS)["breath"]
    {'dominance': 1.4, 'anticipation': 0.109, 'carryover': 0.109, 'duration': 0.258}
    """
    def sig(x: float) -> float:
        return float(f"{x:.2g}")

    out: dict = {"lead": round(params.lead, 3)}
    for c in CLASSES + ("breath",):
        t = params.of(c)
        out[c] = {"dominance": sig(t.dominance), "anticipation": round(t.anticipation, 3),
                  "carryover": round(t.carryover, 3)}
    out["breath"]["duration"] = round(params.breath.duration, 3)
    return out
