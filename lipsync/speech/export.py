"""Writing an :class:`~lipsync.speech.align.Alignment`: Praat TextGrid (long form) or JSON.

Both are written to a temporary file in the destination folder and renamed into place, so a
failure leaves nothing half-written.

Examples
--------
>>> import os, tempfile
>>> from lipsync.motion.timeline import Segment, Timeline
>>> from lipsync.speech.align import Alignment
>>> words = Timeline((Segment(0.1, 0.4, "hi"),), stated_end=0.5)
>>> phones = Timeline((Segment(0.1, 0.2, "HH"), Segment(0.2, 0.4, "AY1")), stated_end=0.5)
>>> p = os.path.join(tempfile.mkdtemp(), "hi.TextGrid")
>>> write_alignment(Alignment(words, phones, 0.5), p)
>>> from lipsync import read_timeline
>>> read_timeline(p).labels(), read_timeline(p, tier="words").labels()
(['HH', 'AY'], ['hi'])
"""

from __future__ import annotations

import json
import os
from typing import Optional, Union

from .._files import atomic_write_bytes
from ..registry import Registry

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["write_alignment", "ALIGNMENT_FORMATS", "to_textgrid", "to_json"]

#: Tier names as the Montreal Forced Aligner writes them (our TextGrid reader's default tier).
WORDS_TIER, PHONES_TIER = "words", "phones"


def _tiers(alignment):
    return ((WORDS_TIER, alignment.words), (PHONES_TIER, alignment.phones))


def _quote(label: str) -> str:
    return '"' + label.replace('"', '""') + '"'


def to_textgrid(alignment) -> str:
    """Praat long-text TextGrid with tiers ``words`` and ``phones`` covering the whole audio.

    Silence is an empty interval, so each tier's intervals tile 0..duration as Praat expects.

    Examples
    --------
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> from lipsync.speech.align import Alignment
    >>> al = Alignment(Timeline((Segment(0.1, 0.4, "hi"),)), Timeline((Segment(0.1, 0.4, "AY1"),)), 0.5)
    >>> text = to_textgrid(al)
    >>> text.count("intervals [3]:"), 'text = "AY1"' in text
    (2, True)
    """
    end = float(alignment.duration)
    out = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "", "xmin = 0", f"xmax = {end!r}",
           "tiers? <exists>", "size = 2", "item []:"]
    for n, (name, tl) in enumerate(_tiers(alignment), 1):
        intervals, t = [], 0.0
        for seg in tl:
            if seg.start > t:
                intervals.append((t, seg.start, ""))
            intervals.append((seg.start, seg.end, seg.label))
            t = seg.end
        if t < end or not intervals:
            intervals.append((t, end, ""))
        out += [f"    item [{n}]:", '        class = "IntervalTier"', f"        name = {_quote(name)}",
                "        xmin = 0", f"        xmax = {end!r}", f"        intervals: size = {len(intervals)}"]
        for i, (a, b, label) in enumerate(intervals, 1):
            out += [f"        intervals [{i}]:", f"            xmin = {a!r}", f"            xmax = {b!r}",
                    f"            text = {_quote(label)}"]
    return "\n".join(out) + "\n"


def to_json(alignment) -> str:
    """JSON: ``duration``, ``words`` and ``phones`` (with ``start`` and ``end``), and how they were made.

    Examples
    --------
    >>> import json
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> from lipsync.speech.align import Alignment
    >>> al = Alignment(Timeline((Segment(0.1, 0.4, "hi"),)), Timeline((Segment(0.1, 0.4, "AY1"),)), 0.5)
    >>> json.loads(to_json(al))["phones"]
    [{'phone': 'AY1', 'start': 0.1, 'end': 0.4}]
    """
    doc = {
        "duration": alignment.duration,
        "recognised": alignment.recognised,
        "confidence": alignment.confidence,
        "missing_words": list(alignment.missing),
        "skipped_words": list(alignment.skipped),
        "words": [{"word": s.label, "start": s.start, "end": s.end} for s in alignment.words],
        "phones": [{"phone": s.label, "start": s.start, "end": s.end} for s in alignment.phones],
    }
    return json.dumps(doc, indent=1) + "\n"


#: name -> function(alignment) -> text; ``lipsync align --format`` choices come from here.
ALIGNMENT_FORMATS: "Registry" = Registry("alignment format")
ALIGNMENT_FORMATS.register("textgrid", to_textgrid, extensions=(".textgrid",))
ALIGNMENT_FORMATS.register("json", to_json, extensions=(".json",))


def write_alignment(alignment, path: PathLike, format: Optional[str] = None) -> None:
    """Write ``alignment`` to ``path`` atomically (temporary file, then rename).

    Parameters
    ----------
    alignment : Alignment
    path : path-like
        Destination file.
    format : str, optional
        ``textgrid`` or ``json`` (default: from the extension, else textgrid).

    Examples
    --------
    >>> import os, tempfile
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> from lipsync.speech.align import Alignment
    >>> al = Alignment(Timeline((Segment(0.1, 0.4, "hi"),)), Timeline((Segment(0.1, 0.4, "AY1"),)), 0.5)
    >>> d = tempfile.mkdtemp()
    >>> write_alignment(al, os.path.join(d, "hi.json"))
    >>> os.listdir(d)
    ['hi.json']
    """
    name = os.fspath(path)
    if format is None:
        format = ALIGNMENT_FORMATS.name_for_extension(os.path.splitext(name)[1]) or "textgrid"
    text = ALIGNMENT_FORMATS.get(format)(alignment)
    atomic_write_bytes(name, lambda fh: fh.write(text.encode("utf-8")))
