"""Step 2: when each mouth shape is shown — the speech aligned, its phones mapped to visemes.

Each video's sound is aligned with its transcript by the project's aligner
(:func:`lipsync.speech.align.align`, pocketsphinx; audio decoded from the container by the
bundled ffmpeg) and the phones mapped to the bank's visemes by the phoneme map, exactly as
``lipsync render`` maps them, so that the frame picked for a viseme shows what the renderer
will show for the same sounds. Silence (gaps between words, before and after) becomes the
map's silence viseme: the rest shape.

Examples
--------
>>> from lipsync.motion.timeline import Segment, Timeline
>>> from lipsync.phonetics.phonemes import load_map
>>> tl = Timeline((Segment(0.5, 0.6, "S"), Segment(0.6, 0.7, "T"), Segment(0.7, 0.9, "AA1")),
...               stated_end=1.5)
>>> [(s.label, s.start, s.end) for s in viseme_spans(tl, load_map("english-to-rhubarb"))]
[('X', 0.0, 0.5), ('B', 0.5, 0.7), ('D', 0.7, 0.9), ('X', 0.9, 1.5)]
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import List, Optional, Tuple

from ..errors import InputError
from ..phonetics.phonemes import PhonemeMap, map_timeline
from ..motion.timeline import Segment, Timeline
from .sources import Source


@dataclass(frozen=True)
class Speech:
    """What was said in one video, and when.

    Attributes
    ----------
    source : Source
    words : tuple of str
        The words aligned.
    phones : Timeline
        ARPAbet phones (silence is gaps).
    visemes : tuple of Segment
        Viseme spans covering the whole video (same-viseme neighbours merged).
    recognised : bool
        Whether the words were recognised (no transcript, or one that did not fit).
    confidence : float or None
        How well the transcript fits (the aligner's figure).
    """

    source: Source
    words: Tuple[str, ...]
    phones: Timeline
    visemes: Tuple[Segment, ...]
    recognised: bool
    confidence: Optional[float]


def viseme_spans(phones: Timeline, pmap: PhonemeMap) -> Tuple[Segment, ...]:
    """The viseme timeline of ``phones`` with neighbours of one viseme merged into one span.

    Two sounds of one shape in a row (S then T: both B) are one held mouth shape: its
    steady middle is the middle of both.
    """
    with warnings.catch_warnings():
        # an unknown phone is shown as the map's fallback by render too; nothing to add here
        warnings.simplefilter("ignore")
        mapped = map_timeline(phones, pmap)
    out: List[Segment] = []
    for s in mapped:
        if s.end <= s.start:
            continue
        if out and out[-1].label == s.label and abs(out[-1].end - s.start) < 1e-9:
            out[-1] = Segment(out[-1].start, s.end, s.label)
        else:
            out.append(s)
    return tuple(out)


def transcribe(source: Source, pmap: PhonemeMap, *, quiet: bool = True, jobs: Optional[int] = None,
               lang: Optional[str] = None) -> Speech:
    """Align one video's speech (with its transcript when it has one) and map it to visemes.

    Warns
    -----
    lipsync.speech.align.AlignmentWarning
        The transcript does not fit the speech (passed on from the aligner).
    """
    from ..speech.align import align

    al = align(source.path, source.text, quiet=quiet, jobs=jobs, lang=lang)
    if len(al.words) == 0:
        # a silent track gave an empty alignment (and nine copies of the rest shape)
        dropped = f"; the transcript ({source.text_from}) could not be used" if source.text else ""
        raise InputError(f"its sound track has no speech (silent, or too quiet to hear){dropped}: the speech is "
                         f"what tells which mouth shape each frame shows (record with sound)", path=source.path)
    phones = Timeline(tuple(al.phones), kind=al.phones.kind, path=str(source.path), stated_end=al.duration)
    return Speech(source=source, words=tuple(al.words.labels()), phones=phones,
                  visemes=viseme_spans(phones, pmap), recognised=al.recognised, confidence=al.confidence)
