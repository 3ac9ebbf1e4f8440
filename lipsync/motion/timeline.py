"""Timelines: labelled time intervals, as the readers (:mod:`lipsync.readers`) make them from files.

A :class:`Timeline` is an immutable, sorted sequence of non-overlapping :class:`Segment`
objects (start and end in seconds, a label). ``kind`` says whether the labels are phonemes
(to be mapped to visemes by :mod:`lipsync.phonetics.phonemes`) or already visemes (Rhubarb, Moho).

Silence convention
------------------
Intervals that carry **no label** in the file (an empty TextGrid interval, the time between
two Audacity labels, a Gentle word that was not found in the audio) are **left out**: they
are gaps between segments. Labels that *name* silence (``sil``, ``sp``, ``h#``, ``pau``, ...)
are kept as the file writes them. The phoneme mapper (:func:`lipsync.phonetics.phonemes.map_timeline`)
turns both gaps and silence labels into the rest viseme, and the sequencer also shows rest in
any gap left in a viseme timeline, so a reader never has to invent segments.

This module is the bottom of the timeline rooms: data only. Reading files is
:func:`lipsync.readers.read_timeline` (also ``lipsync.read_timeline``), writing cues
:mod:`lipsync.writers`; both import this module, never the other way round.

Examples
--------
>>> tl = Timeline((Segment(0.0, 0.1, "h#"), Segment(0.1, 0.3, "hh"), Segment(0.3, 0.5, "ay")))
>>> tl.kind, len(tl), tl[1].label, tl.duration
('phoneme', 3, 'hh', 0.5)
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Optional, Sequence, Tuple, Union, overload

from ..errors import InputError, TimelineError

PathLike = Union[str, "os.PathLike[str]"]

PHONEME = "phoneme"
VISEME = "viseme"
KINDS = (PHONEME, VISEME)

#: Latest time a timeline may reach: 24 hours. Longer than any speech track (an audiobook
#: chapter, a day-long recording), and finite so that a wrong number in a file (1e308,
#: milliseconds or samples read as seconds) is an error naming the file and line rather
#: than an overflow wherever time becomes a frame number (24 h at 120 fps is 10^7 frames,
#: which the sequencer's MAX_FRAMES then refuses with its own message).
MAX_TIMELINE_S = 86400.0


@dataclass(frozen=True)
class Segment:
    """One labelled interval of a timeline, in seconds.

    Examples
    --------
    >>> Segment(0.1, 0.25, "AA").duration
    0.15
    """

    start: float
    end: float
    label: str

    @property
    def duration(self) -> float:
        return self.end - self.start

    @property
    def mid(self) -> float:
        return 0.5 * (self.start + self.end)


@dataclass(frozen=True)
class Timeline(Sequence[Segment]):
    """A sorted, non-overlapping sequence of :class:`Segment` (gaps mean silence).

    Parameters
    ----------
    segments : tuple of Segment
        Sorted by start, non-overlapping (checked).
    kind : {"phoneme", "viseme"}
        What the labels are.
    path : str, optional
        The file the timeline came from, for messages.
    stated_end : float, optional
        The end the file states (a TextGrid's ``xmax``); :attr:`duration` prefers it.

    Examples
    --------
    >>> tl = Timeline((Segment(0.0, 0.5, "A"), Segment(0.5, 0.75, "X")), kind="viseme")
    >>> len(tl), tl[-1].label, tl.duration
    (2, 'X', 0.75)
    >>> Timeline((Segment(0.0, 0.5, "A"),), kind="viseme", stated_end=2.0).duration
    2.0
    """

    segments: Tuple[Segment, ...] = ()
    kind: str = PHONEME
    path: Optional[str] = None
    stated_end: Optional[float] = field(default=None, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "segments", tuple(self.segments))
        if self.kind not in KINDS:
            raise ValueError(f"timeline kind must be one of {KINDS}, not {self.kind!r}")
        prev_end = 0.0
        for i, seg in enumerate(self.segments):
            if not (seg.start >= prev_end - _OVERLAP_TOLERANCE_S and seg.end >= seg.start):
                raise TimelineError(
                    f"segment {i} ({seg.start:g}-{seg.end:g} {seg.label!r}) is out of order "
                    f"or overlaps the one before", path=self.path)
            prev_end = seg.end
        if prev_end > MAX_TIMELINE_S:  # also catches an infinite end
            raise TimelineError(f"the timeline reaches {prev_end:g} s, past the limit of {MAX_TIMELINE_S:g} s "
                                f"(24 hours; a time is likely wrong)", path=self.path)
        if self.stated_end is not None and not 0 <= self.stated_end <= MAX_TIMELINE_S:
            raise TimelineError(f"the stated end {self.stated_end:g} s is not within 0..{MAX_TIMELINE_S:g} s",
                                path=self.path)

    def __len__(self) -> int:
        return len(self.segments)

    def __iter__(self) -> Iterator[Segment]:
        return iter(self.segments)

    @overload
    def __getitem__(self, i: int) -> Segment: ...

    @overload
    def __getitem__(self, i: slice) -> Tuple[Segment, ...]: ...

    def __getitem__(self, i):
        return self.segments[i]

    @property
    def end(self) -> float:
        """End of the last segment (0 for an empty timeline)."""
        return self.segments[-1].end if self.segments else 0.0

    @property
    def duration(self) -> float:
        """The file's stated end when known (and not before the last segment), else the last end."""
        if self.stated_end is not None and self.stated_end >= self.end:
            return float(self.stated_end)
        return self.end

    def labels(self) -> list:
        """The labels in order."""
        return [s.label for s in self.segments]

    def replace(self, **changes) -> "Timeline":
        """A copy with some fields changed (``segments``, ``kind``, ``path``, ``stated_end``)."""
        fields = dict(segments=self.segments, kind=self.kind, path=self.path, stated_end=self.stated_end)
        fields.update(changes)
        return Timeline(**fields)


# Forced aligners print times with float noise (Gentle writes 19.399999 after 19.400000000000002):
# overlaps smaller than this are float noise, snapped away; larger ones are errors in the file.
_OVERLAP_TOLERANCE_S = 1e-4
