"""The edited timeline: words, phones and visemes on one frame grid, validated, loaded and saved.

A :class:`TimingDoc` is what ``lipsync edit-timeline`` edits and what its API's JSON holds:
three tiers of :class:`~lipsync.motion.timeline.Timeline` (words as written, phones without
stress digits, the bank's visemes covering the whole recording) and the recording's duration.
Every word and phone time is a whole frame at the editor's ``fps`` (``frame / fps``), as in
Papagayo: what the page snaps to and what .pgo files hold, so a saved file reads back as
exactly the edited timeline. The viseme tier is what the phoneme map makes of the phones,
exactly as ``lipsync render`` maps them (so the preview is render's frames): a diphthong's
two visemes share its time and may meet half-way through a frame. Rhubarb's millisecond
times hold that exactly at 25 or 50 fps; Moho's whole frames move such a split by half a
frame (the only change a save-and-reopen makes, and only in Moho files).

The stages used are the pipeline's own: :mod:`lipsync.readers` (any timeline file),
:func:`lipsync.speech.align.align` (audio and a transcript), the phoneme map
(:func:`lipsync.phonetics.phonemes.bank_viseme_timeline`), the lexicon and the language's
letters-to-sounds for a retyped word (:func:`breakdown`), and the writers.

Examples
--------
>>> from lipsync.motion.timeline import Segment, Timeline
>>> doc = TimingDoc.from_json({"words": [{"start": 0.2, "end": 0.6, "label": "hi"}],
...                            "phones": [{"start": 0.2, "end": 0.32, "label": "HH"},
...                                       {"start": 0.32, "end": 0.6, "label": "AY"}]},
...                           context=Context(duration=1.0, fps=25))
>>> [(s.label, round(s.start, 3), round(s.end, 3)) for s in doc.visemes]  # AY: D then B, half each
[('X', 0.0, 0.2), ('C', 0.2, 0.32), ('D', 0.32, 0.46), ('B', 0.46, 0.6), ('X', 0.6, 1.0)]
"""

from __future__ import annotations

import math
import os
import re
import warnings
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

from ..errors import InputError
from ..motion.timeline import PHONEME, VISEME, Segment, Timeline

#: Longest recording the editor opens: one hour. The page holds its waveform peaks and the
#: server its 16 kHz samples (115 MB for an hour) and every tier in memory; a longer file is
#: refused before it is decoded past this length.
MAX_AUDIO_S = 3600.0
#: Segments per tier: an hour of fast speech has ~60 000 phones; a bigger request is hostile.
MAX_SEGMENTS = 100_000
#: Longest label (a word as typed, a phone, a viseme name).
MAX_LABEL = 100
#: Frame rates the editor snaps to (the sequencer's range).
FPS_RANGE = (1.0, 120.0)
TIERS = ("words", "phones", "visemes")


@dataclass(frozen=True)
class Context:
    """What validation needs besides the JSON: the recording and the bank's shapes.

    Attributes
    ----------
    duration : float
        Seconds of audio; no segment may end after it.
    fps : float
        The frame grid times are snapped to.
    visemes : tuple of str
        The bank's viseme names (a viseme label must be one); default the toon's.
    rest : str
        The bank's rest viseme (gaps in the viseme tier).
    pmap : PhonemeMap, optional
        The phoneme map (default: the shipped English one).
    lang : str, optional
        The speech's language (BCP 47): a retyped word's phones come from its
        letters-to-sounds (default: English, CMUdict).

    Examples
    --------
    >>> c = Context(duration=2.99, fps=25)
    >>> c.last_frame, c.rest
    (74, 'X')
    """

    duration: float
    fps: float = 25.0
    visemes: Tuple[str, ...] = ("A", "B", "C", "D", "E", "F", "G", "H", "X")
    rest: str = "X"
    pmap: object = None
    lang: Optional[str] = None

    def __post_init__(self):
        if not FPS_RANGE[0] <= self.fps <= FPS_RANGE[1]:
            raise InputError(f"--fps must be within {FPS_RANGE[0]:g}..{FPS_RANGE[1]:g}, got {self.fps:g}")
        if self.pmap is None:
            from ..phonetics.phonemes import DEFAULT_MAP, load_map

            object.__setattr__(self, "pmap", load_map(DEFAULT_MAP))

    @property
    def last_frame(self) -> int:
        """The last whole frame inside the recording: the latest boundary on the grid (a
        segment may also end at the recording's own end, :attr:`duration`)."""
        return int(math.floor(self.duration * self.fps + 1e-9))


@dataclass(frozen=True)
class TimingDoc:
    """Words, phones and visemes of one recording, every time on the frame grid.

    ``visemes_edited`` is True once the viseme tier was changed by hand (it is then kept
    as given instead of being derived from the phones).

    Examples
    --------
    >>> doc = TimingDoc.from_json({"words": [], "phones": [{"start": 0.5, "end": 0.61, "label": "M"}]},
    ...                           context=Context(duration=1.0))
    >>> doc.to_json()["phones"], [v.label for v in doc.visemes]
    ([{'start': 0.52, 'end': 0.6, 'label': 'M'}], ['X', 'A', 'X'])
    """

    words: Timeline
    phones: Timeline
    visemes: Timeline
    context: Context = field(compare=False)
    visemes_edited: bool = field(default=False, compare=False)

    # ------------------------------------------------------------------ JSON
    def to_json(self) -> dict:
        """``{"words": [...], "phones": [...], "visemes": [...]}`` with ``start``, ``end``, ``label``."""
        return {name: [{"start": s.start, "end": s.end, "label": s.label} for s in getattr(self, name)]
                for name in TIERS}

    @classmethod
    def from_json(cls, obj, *, context: Context) -> "TimingDoc":
        """Validate the API's JSON (InputError naming the tier and segment), words and phones
        snapped to frames.

        ``visemes`` may be left out or null: the viseme tier is then derived from the phones
        through the map. Empty labels are silence (left as gaps).
        """
        if not isinstance(obj, dict):
            raise InputError('expected {"words": [...], "phones": [...], "visemes": [...]}')
        unknown = sorted(set(obj) - set(TIERS))
        if unknown:
            raise InputError(f"unknown keys: {', '.join(map(str, unknown))} (expected words, phones, visemes)")
        words = _tier(obj.get("words", []), "words", context)
        phones = _tier(obj.get("phones", []), "phones", context)
        check_phones(phones, context)
        if obj.get("visemes") is None:
            return cls.derived(words, phones, context)
        visemes = _tier(obj["visemes"], "visemes", context)
        bad = sorted({s.label for s in visemes} - set(context.visemes))
        if bad:
            raise InputError(f"visemes: {', '.join(bad[:8])} not in the bank (its visemes: "
                             f"{' '.join(context.visemes)})")
        return cls(words, phones, _cover(visemes, context), context, visemes_edited=True)

    @classmethod
    def derived(cls, words: Timeline, phones: Timeline, context: Context) -> "TimingDoc":
        """The doc whose visemes are the phones through the map, snapped to frames."""
        return cls(words, phones, derive_visemes(phones, context), context)


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{where} must be a finite number of seconds, not {value!r}")
    return float(value)


def _tier(rows, name: str, context: Context) -> Timeline:
    """A JSON tier checked (order, overlap, bounds, labels); words and phones snapped to the
    frame grid (the visemes are kept as given: the page snaps what it moves)."""
    if not isinstance(rows, list):
        raise InputError(f"{name} must be a list of {{start, end, label}}")
    if len(rows) > MAX_SEGMENTS:
        raise InputError(f"{name}: {len(rows)} segments, over the limit of {MAX_SEGMENTS}")
    fps, last = context.fps, context.last_frame
    out: List[Segment] = []
    prev_end, prev_frame = 0.0, 0
    for i, row in enumerate(rows):
        where = f"{name}[{i}]"
        if not isinstance(row, dict) or not {"start", "end", "label"} <= set(row):
            raise InputError(f"{where} must be an object with start, end and label")
        start, end = _number(row["start"], f"{where}.start"), _number(row["end"], f"{where}.end")
        label = row["label"]
        if not isinstance(label, str) or len(label) > MAX_LABEL or any(c in label for c in "\n\r\t"):
            raise InputError(f"{where}.label must be text of at most {MAX_LABEL} characters on one line")
        if start < 0:
            raise InputError(f"{where} starts at {start:g} s: times cannot be negative")
        if end <= start:
            raise InputError(f"{where} ends ({end:g} s) at or before it starts ({start:g} s)")
        if start < prev_end - 1e-9:
            raise InputError(f"{where} ({start:g}-{end:g} s) overlaps the one before (which ends at {prev_end:g} s)")
        if end > context.duration + 0.5 / fps:
            raise InputError(f"{where} ends at {end:g} s, after the recording ({context.duration:g} s)")
        prev_end = end
        label = label.strip()
        if not label:
            continue  # silence: a gap
        if name == "visemes":  # kept as given: a diphthong's visemes meet between frames
            out.append(Segment(start, min(end, context.duration), label))
            continue
        a = max(_frame(start, fps), prev_frame)
        b = max(_frame(end, fps), a + 1)  # a segment keeps at least one frame, as in Papagayo
        if a >= last and not a / fps < context.duration:
            raise InputError(f"{where}: no room for it before the end of the recording at {fps:g} fps "
                             f"(segments before it were given at least one frame each)")
        # the recording's end is a boundary too, on the grid or not
        end_t = context.duration if b > last or abs(end - context.duration) < 1e-9 else b / fps
        out.append(Segment(a / fps, end_t, label))
        prev_frame = b
    kind = VISEME if name == "visemes" else PHONEME
    return Timeline(tuple(out), kind=kind, stated_end=context.duration)


def _frame(t: float, fps: float) -> int:
    return int(math.floor(t * fps + 0.5))


def snap_timeline(tl: Timeline, context: Context, *, kind: Optional[str] = None) -> Timeline:
    """``tl`` on the frame grid (each segment at least one frame, none past the end).

    Examples
    --------
    >>> tl = Timeline((Segment(0.01, 0.03, "P"), Segment(0.03, 0.21, "AA")))
    >>> [(s.label, s.start, s.end) for s in snap_timeline(tl, Context(duration=1.0, fps=25))]
    [('P', 0.0, 0.04), ('AA', 0.04, 0.2)]
    """
    rows = [{"start": min(s.start, context.duration), "end": min(s.end, context.duration), "label": s.label}
            for s in tl if min(s.end, context.duration) > min(s.start, context.duration)]
    # a segment pushed past the end by the ones before it is dropped rather than refused
    fps, out, prev = context.fps, [], 0
    for r in rows:
        if not r["label"].strip():
            continue
        a = max(_frame(r["start"], fps), prev)
        b = max(_frame(r["end"], fps), a + 1)
        if a / fps >= context.duration:
            break
        out.append(Segment(a / fps, context.duration if b > context.last_frame else b / fps, r["label"].strip()))
        prev = b
    return Timeline(tuple(out), kind=kind or tl.kind, stated_end=context.duration)


def check_phones(phones: Timeline, context: Context) -> None:
    """InputError listing the phone labels the map does not know (they would show its fallback)."""
    from ..phonetics.phonemes import UnknownLabelWarning, map_timeline

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UnknownLabelWarning)
        map_timeline(phones, context.pmap, rest=context.rest)
    said = [str(w.message) for w in caught if issubclass(w.category, UnknownLabelWarning)]
    if said:
        labels = [m.group(1) for m in (re.search(r"label '([^']*)'", t) for t in said) if m] or said
        raise InputError(f"unknown phone label(s): {', '.join(labels[:8])} (the map "
                         f"{getattr(context.pmap, 'name', '')!r} has no viseme for them; write ARPAbet or IPA)")


def derive_visemes(phones: Timeline, context: Context) -> Timeline:
    """The bank's viseme tier for ``phones``: exactly what ``lipsync render`` maps them to (so
    the preview is render's frames). A diphthong's visemes share its time, so their common
    boundary may fall between frames (half a frame at most)."""
    from ..phonetics.phonemes import bank_viseme_timeline

    tl, _ = bank_viseme_timeline(phones.replace(stated_end=context.duration), context.pmap, context.visemes,
                                 rest=context.rest)
    return tl.replace(stated_end=context.duration)


def _cover(visemes: Timeline, context: Context) -> Timeline:
    """The viseme tier with its gaps filled by rest (as the sequencer shows them), up to the end."""
    out: List[Segment] = []
    t = 0.0
    for s in list(visemes) + [Segment(context.duration, context.duration, context.rest)]:
        if s.start > t:
            out.append(Segment(t, s.start, context.rest))
        if s.end > s.start:
            out.append(s)
        t = max(t, s.end)
    return Timeline(tuple(out), kind=VISEME, stated_end=context.duration)


# ---------------------------------------------------------------- breakdown (retyping a word)

def breakdown(word: str, lang: Optional[str] = None) -> Tuple[str, ...]:
    """The phones of a typed word: CMUdict (then its letter-to-sound rules) for English,
    espeak-ng's letters-to-sounds (IPA) for ``lang`` — Papagayo's "breakdown".

    Examples
    --------
    >>> breakdown("bin"), breakdown("Hello")
    (('B', 'IH', 'N'), ('HH', 'AH', 'L', 'OW'))
    """
    from ..phonetics.g2p import is_english

    if lang is None or is_english(lang):
        from ..speech.phonetise import phones_of

        return phones_of(word)
    from ..phonetics.g2p import transcribe

    return tuple(p for w in transcribe(word, lang) for p in w.phones)


def retype(doc: TimingDoc, index: int, text: str) -> TimingDoc:
    """``doc`` with word ``index`` retyped: its label, and the phones inside it replaced by the
    breakdown of ``text`` spread over the word's frames by typical durations.

    Examples
    --------
    >>> ctx = Context(duration=1.0, fps=25)
    >>> doc = TimingDoc.from_json({"words": [{"start": 0.2, "end": 0.6, "label": "hi"}],
    ...                            "phones": [{"start": 0.2, "end": 0.6, "label": "AY"}]}, context=ctx)
    >>> [(s.label, s.start, s.end) for s in retype(doc, 0, "bin").phones]
    [('B', 0.2, 0.32), ('IH', 0.32, 0.52), ('N', 0.52, 0.6)]
    """
    from ..speech.phonetise import TYPICAL_PHONE_S

    if not 0 <= index < len(doc.words):
        raise InputError(f"no word {index} (the timeline has {len(doc.words)})")
    text = text.strip()
    if not text or len(text) > MAX_LABEL or any(c in text for c in "\n\r\t"):
        raise InputError(f"a word is text of 1..{MAX_LABEL} characters on one line")
    ctx = doc.context
    w = doc.words[index]
    phones = breakdown(text, ctx.lang)
    if not phones:
        raise InputError(f"{text!r} has no sounds to show (no letters or digits)")
    a, b = _frame(w.start, ctx.fps), _frame(w.end, ctx.fps)
    if len(phones) > b - a:
        raise InputError(f"{text!r} has {len(phones)} phones but the word lasts {b - a} frames at {ctx.fps:g} fps: "
                         f"widen the word first")
    cuts = _share(b - a, [TYPICAL_PHONE_S.get(p, 0.08) for p in phones])
    new = [Segment((a + c0) / ctx.fps, (a + c1) / ctx.fps, p) for p, c0, c1 in zip(phones, cuts, cuts[1:])]
    kept = [p for p in doc.phones if p.end <= w.start or p.start >= w.end]
    segs = sorted(kept + new, key=lambda s: s.start)
    words = list(doc.words)
    words[index] = Segment(w.start, w.end, text)
    words_tl = doc.words.replace(segments=tuple(words))
    phones_tl = doc.phones.replace(segments=tuple(segs))
    check_phones(phones_tl, ctx)
    return TimingDoc.derived(words_tl, phones_tl, ctx)


def _share(frames: int, weights: Sequence[float]) -> List[int]:
    """Cut points 0..frames giving each weight its share, every part at least one frame."""
    total = float(sum(weights))
    cuts, acc = [0], 0.0
    for i, wgt in enumerate(weights[:-1]):
        acc += wgt
        ideal = int(round(frames * acc / total))
        # at least one frame for this part and one for each part still to come
        cuts.append(min(max(ideal, cuts[-1] + 1), frames - (len(weights) - 1 - i)))
    cuts.append(frames)
    return cuts


# ---------------------------------------------------------------- loading

def load_doc(audio_duration: float, *, context: Context, timeline: Optional[str] = None,
             alignment=None, tier: Optional[str] = None) -> TimingDoc:
    """The starting doc: from an :class:`~lipsync.speech.align.Alignment`, or a timeline file
    read by :func:`lipsync.read_timeline` (words from its ``words`` tier where it has one)."""
    if alignment is not None:
        words, phones = alignment.words, alignment.phones
        phones = phones.replace(segments=tuple(Segment(s.start, s.end, _strip_stress(s.label)) for s in phones))
    else:
        words, phones = _read_file(timeline, tier, context.fps)
    words = snap_timeline(words, context, kind=PHONEME)
    if phones.kind == VISEME:
        visemes = _cover(_clip(_bank_names(phones, context), context), context)
        return TimingDoc(words, Timeline((), stated_end=context.duration), visemes, context, visemes_edited=True)
    phones = snap_timeline(phones, context)
    try:
        check_phones(phones, context)
    except InputError as exc:
        raise InputError(str(exc), path=timeline or getattr(alignment, "path", None)) from None
    return TimingDoc.derived(words, phones, context)


def _strip_stress(label: str) -> str:
    return label[:-1] if label[-1:] in "012" and len(label) > 1 else label


def _bank_names(visemes: Timeline, context: Context) -> Timeline:
    from ..phonetics.phonemes import bank_viseme_timeline

    tl, _ = bank_viseme_timeline(visemes, context.pmap, context.visemes, rest=context.rest)
    return tl


def _read_file(path: str, tier: Optional[str], fps: float) -> Tuple[Timeline, Timeline]:
    """(words, phones) of a timeline file; words empty where the format has none. A Moho
    file's frames are read at the editor's ``fps`` (the rate its saves write)."""
    from ..readers import READERS, read_timeline
    from ..readers.papagayo import read_words

    phones = read_timeline(path, tier=tier, fps=fps)
    ext = os.path.splitext(path)[1].lower()
    words = Timeline(())
    if ext == ".pgo":
        words = read_words(path, tier)
    elif READERS.name_for_extension(ext) == "textgrid" and tier is None:
        try:
            words = read_timeline(path, "textgrid", tier="words")
        except InputError:
            pass  # a TextGrid without a words tier
    elif ext == ".align":  # GRID's word alignments: the words are the file's own labels
        words = _grid_words(path)
    return words, phones


def _grid_words(path: str) -> Timeline:
    """The words of a GRID ``.align`` file (times in 1/25000 s; ``sil`` and ``sp`` are silence)."""
    rows = []
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            parts = line.split()
            if len(parts) == 3 and parts[2] not in ("sil", "sp"):
                rows.append(Segment(int(parts[0]) / 25000.0, int(parts[1]) / 25000.0, parts[2]))
    return Timeline(tuple(rows))


# ---------------------------------------------------------------- saving

#: Save formats: name -> (extension, what it holds). Words and phones go to TextGrid and
#: .pgo; the cue formats hold the viseme tier.
SAVE_FORMATS: Dict[str, Tuple[str, str]] = {
    "textgrid": (".TextGrid", "words and phones tiers (Praat)"),
    "pgo": (".pgo", "Papagayo-NG project: words and their phonemes at frames"),
    "rhubarb-tsv": (".tsv", "the viseme tier as Rhubarb's tab-separated cues"),
    "rhubarb-json": (".json", "the viseme tier as Rhubarb's JSON cues"),
    "moho": (".dat", "the viseme tier as a Moho switch file (Preston Blair names)"),
}


def save_text(doc: TimingDoc, format: str, path: str, *, sound_file: str) -> None:
    """Write ``doc`` as ``format`` to ``path`` (a temporary file to be renamed by the caller)."""
    ctx = doc.context
    if format == "textgrid":
        from ..speech.align import Alignment
        from ..speech.export import write_alignment

        write_alignment(Alignment(doc.words, doc.phones, ctx.duration), path, "textgrid")
    elif format == "pgo":
        from ..writers.papagayo import write_pgo

        write_pgo(doc.words, doc.phones, path, duration=ctx.duration, fps=ctx.fps, sound_file=sound_file)
    elif format in ("rhubarb-tsv", "rhubarb-json", "moho"):
        from ..writers import write_cues

        names = {}
        if format == "moho":
            names = {v: aliases[0] for v, aliases in ctx.pmap.aliases.items() if aliases}
        write_cues(doc.visemes, path, format, rest=ctx.rest, fps=ctx.fps, names=names,
                   sound_file=sound_file, duration=ctx.duration)
    else:
        raise InputError(f"unknown format {format!r} (valid: {', '.join(SAVE_FORMATS)})")


def _clip(tl: Timeline, context: Context) -> Timeline:
    """``tl`` without what lies past the recording's end (a Moho file's last key, say)."""
    d = context.duration
    segs = tuple(Segment(s.start, min(s.end, d), s.label) for s in tl if s.start < d)
    return tl.replace(segments=segs, stated_end=d)
