"""Timelines: labelled time intervals read from the files users bring.

A :class:`Timeline` is an immutable, sorted sequence of non-overlapping :class:`Segment`
objects (start and end in seconds, a label). ``kind`` says whether the labels are phonemes
(to be mapped to visemes by :mod:`lipsync.phonemes`) or already visemes (Rhubarb, Moho).

Silence convention
------------------
Intervals that carry **no label** in the file (an empty TextGrid interval, the time between
two Audacity labels, a Gentle word that was not found in the audio) are **left out**: they
are gaps between segments. Labels that *name* silence (``sil``, ``sp``, ``h#``, ``pau``, ...)
are kept as the file writes them. The phoneme mapper (:func:`lipsync.phonemes.map_timeline`)
turns both gaps and silence labels into the rest viseme, and the sequencer also shows rest in
any gap left in a viseme timeline, so a reader never has to invent segments.

Reader lookup (the same order as imageio's plugins): an explicit ``format`` first, then the
file extension, then content sniffing of the first bytes; an unknown format name raises
:class:`~lipsync.errors.UnknownNameError` listing the valid ones.

Examples
--------
>>> import os, tempfile
>>> d = tempfile.mkdtemp()
>>> p = os.path.join(d, "hi.phn")
>>> _ = open(p, "w").write("0 1600 h#\\n1600 4800 hh\\n4800 8000 ay\\n")
>>> tl = read_timeline(p)
>>> tl.kind, len(tl), tl[1].label, tl.duration
('phoneme', 3, 'hh', 0.5)
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Optional, Sequence, Tuple, Union, overload

from .errors import InputError, TimelineError
from .registry import Registry

PathLike = Union[str, "os.PathLike[str]"]

PHONEME = "phoneme"
VISEME = "viseme"
KINDS = (PHONEME, VISEME)


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


@dataclass(frozen=True)
class ReadOptions:
    """What a reader may need besides the text: chosen tier, TIMIT sample rate, Moho frame rate."""

    tier: Optional[str] = None
    sample_rate: float = 16000
    fps: float = 24.0


@dataclass(frozen=True)
class Reader:
    """A timeline file format.

    ``read(path, data, options)`` gets the raw bytes and returns a Timeline; ``sniff(head)``
    gets the first bytes and says whether they look like this format.
    """

    name: str
    read: Callable[[str, bytes, ReadOptions], Timeline]
    sniff: Callable[[bytes], bool]
    description: str = ""


READERS: Registry[Reader] = Registry("timeline format")

_SNIFF_BYTES = 4096


def read_timeline(path: PathLike, format: Optional[str] = None, *, tier: Optional[str] = None,
                  sample_rate: float = 16000, fps: float = 24.0) -> Timeline:
    """Read a phoneme or viseme timeline from any supported file.

    Parameters
    ----------
    path : path-like
        The timeline file.
    format : str, optional
        A name from ``READERS.names()``; default: by extension, then by content.
    tier : str, optional
        TextGrid tier to read (default ``phones``, as the Montreal Forced Aligner writes it).
    sample_rate : float
        Samples per second of TIMIT ``.phn`` times (16000 for TIMIT itself).
    fps : float
        Frame rate of a Moho switch ``.dat`` file (frames are 1-based).

    Returns
    -------
    Timeline
        Labels normalised by the reader (stress digits and Gentle's position suffixes removed).

    Raises
    ------
    TimelineError
        The file cannot be read as a timeline; the message names the file and line.
    UnknownNameError
        ``format`` is not a known format name.

    Examples
    --------
    >>> import os, tempfile
    >>> p = os.path.join(tempfile.mkdtemp(), "cues.txt")
    >>> _ = open(p, "w").write("0.00\\tX\\n0.12\\tB\\n0.40\\tX\\n")
    >>> tl = read_timeline(p, "rhubarb-tsv")
    >>> tl.kind, tl.labels(), tl.duration
    ('viseme', ['X', 'B'], 0.4)
    """
    name = os.fspath(path)
    if format is not None:
        reader = READERS.get(format)
    else:
        reader = None
    if sample_rate is None or not (0 < float(sample_rate) < float("inf")):
        raise InputError(f"sample rate must be a positive number, not {sample_rate!r}")
    if fps is None or not (0 < float(fps) < float("inf")):
        raise InputError(f"frame rate must be a positive number, not {fps!r}")
    try:
        data = Path(name).read_bytes()
    except FileNotFoundError:
        raise TimelineError("no such file", path=name) from None
    except IsADirectoryError:
        raise TimelineError("is a folder, not a timeline file", path=name) from None
    except OSError as exc:
        raise TimelineError(f"cannot read: {exc.strerror or exc}", path=name) from None
    if not data.strip():
        raise TimelineError("empty file", path=name, line=1)
    if reader is None:
        reader = _choose_reader(name, data)
    options = ReadOptions(tier=tier, sample_rate=float(sample_rate), fps=float(fps))
    return reader.read(name, data, options)


def _choose_reader(name: str, data: bytes) -> Reader:
    ext_name = READERS.name_for_extension(Path(name).suffix)
    head = data[:_SNIFF_BYTES]
    # Several formats share ".txt" / ".json" (Rhubarb TSV vs Audacity, Rhubarb JSON vs
    # Gentle JSON), so an extension match is confirmed by sniffing when the content disagrees.
    if ext_name is not None:
        reader = READERS.get(ext_name)
        if reader.sniff(head):
            return reader
    for _, reader in READERS.items():
        if reader.sniff(head):
            return reader
    # JSON the first bytes did not give away: recognised by its structure, or an error
    # listing the JSON formats (rather than one format's complaint about missing keys).
    from .readers.jsonkind import json_reader_for
    reader = json_reader_for(name, data)
    if reader is not None:
        return reader
    if ext_name is not None:
        return READERS.get(ext_name)  # its own errors say what is wrong with the content
    from .readers._common import looks_binary
    if looks_binary(data):
        raise TimelineError("binary data, not a timeline file", path=name, line=1)
    raise TimelineError(
        "cannot tell the timeline format from the name or content; give it explicitly "
        f"(valid: {', '.join(READERS.names())})", path=name, line=1)


def _load_readers() -> None:
    # Each reader module registers itself; imported here (not above) because they import
    # Segment and Timeline from this module.
    from .readers import load_all

    load_all()


_load_readers()
