"""Word timings to phone timings: each word's time split among its phones by typical durations.

Recognisers (Whisper and its kin) and TTS engines (ElevenLabs, Polly word marks) give the
time of each *word*; a mouth needs the time of each *phone*. A word's text is normalised
(:func:`lipsync.speech.text.normalise_transcript`: numbers spelled out, punctuation
dropped), pronounced (:func:`lipsync.speech.lexicon.pronounce`: CMUdict, then analogy and
letter-to-sound rules, so no word is ever dropped) and its interval is split among its
phones in proportion to each phone's typical duration (:data:`TYPICAL_PHONE_S`), so a
long vowel gets more of the word than the stop before it.

One function does it, :func:`words_to_phones`, for every reader of word timings and for
the live animator alike.

Examples
--------
>>> from lipsync.motion.timeline import Segment, Timeline
>>> words = Timeline((Segment(0.0, 0.5, "Hello"), Segment(0.6, 1.0, "world!")))
>>> phones = words_to_phones(words)
>>> phones.labels()
['HH', 'AH', 'L', 'OW', 'W', 'ER', 'L', 'D']
>>> round(phones[0].start, 3), round(phones[3].end, 3), round(phones[4].start, 3)
(0.0, 0.5, 0.6)
"""

from __future__ import annotations

import re
from typing import Dict, List, Sequence, Tuple

from ..motion.timeline import PHONEME, Segment, Timeline

# Typical (inherent) durations of English phones in seconds, after Klatt's duration rules
# for American English (J. Acoust. Soc. Am. 59, 1976). Only the ratios matter: a word's
# measured time is shared out in these proportions. Grouped by the reason for the length.
TYPICAL_PHONE_S: Dict[str, float] = {
    # Tense and low vowels: the jaw travels far and the vowel is held.
    "AA": 0.240, "AE": 0.230, "AO": 0.240, "IY": 0.155, "UW": 0.210,
    # Diphthongs: two targets in one vowel, the longest sounds of English.
    "AW": 0.260, "AY": 0.250, "EY": 0.190, "OW": 0.220, "OY": 0.280,
    # Lax and central vowels: short, often reduced.
    "AH": 0.140, "EH": 0.150, "ER": 0.180, "IH": 0.135, "UH": 0.160,
    # Fricatives: the noise lasts as long as the constriction is held.
    "F": 0.100, "S": 0.105, "SH": 0.105, "TH": 0.090, "HH": 0.080,
    "V": 0.060, "Z": 0.075, "ZH": 0.070, "DH": 0.050,
    # Stops and affricates: a closure and a burst, shorter than any vowel.
    "P": 0.090, "B": 0.085, "T": 0.075, "D": 0.075, "K": 0.080, "G": 0.080,
    "CH": 0.070, "JH": 0.070,
    # Nasals: a closure with voicing, about stop length.
    "M": 0.070, "N": 0.060, "NG": 0.095,
    # Approximants: glides into the next vowel.
    "L": 0.080, "R": 0.080, "W": 0.080, "Y": 0.080,
}

# A phone missing from the table (none in CMUdict's set; kept for other lexicons) gets the
# length of an average consonant, the commonest kind of sound.
_DEFAULT_PHONE_S = 0.08

_STRESS = re.compile(r"[0-2]$")


def phones_of(text: str) -> Tuple[str, ...]:
    """ARPAbet phones (no stress digits) of a word or phrase as written.

    Examples
    --------
    >>> phones_of("2 cats")
    ('T', 'UW', 'K', 'AE', 'T', 'S')
    >>> phones_of("...")
    ()
    """
    from .lexicon import normalise_transcript, pronounce

    out: List[str] = []
    for word in normalise_transcript(text):
        out += [_STRESS.sub("", p) for p in pronounce(word)]
    return tuple(out)


def typical_duration(phones: Sequence[str]) -> float:
    """Sum of the typical durations of ``phones`` (seconds).

    Examples
    --------
    >>> round(typical_duration(("HH", "AY")), 3)
    0.33
    """
    return float(sum(TYPICAL_PHONE_S.get(p, _DEFAULT_PHONE_S) for p in phones))


def split_word(start: float, end: float, phones: Sequence[str]) -> List[Segment]:
    """``[start, end]`` split among ``phones`` in proportion to their typical durations.

    Examples
    --------
    >>> [(s.label, round(s.start, 3), round(s.end, 3)) for s in split_word(1.0, 1.33, ("HH", "AY"))]
    [('HH', 1.0, 1.08), ('AY', 1.08, 1.33)]
    """
    if not phones or end <= start:
        return []
    weights = [TYPICAL_PHONE_S.get(p, _DEFAULT_PHONE_S) for p in phones]
    total = sum(weights)
    out: List[Segment] = []
    acc = 0.0
    t0 = start
    for i, (p, w) in enumerate(zip(phones, weights)):
        acc += w
        # The last phone ends exactly at the word's end (no float drift past it).
        t1 = end if i == len(phones) - 1 else start + (end - start) * acc / total
        out.append(Segment(t0, t1, p))
        t0 = t1
    return out


def words_to_phones(words: Timeline) -> Timeline:
    """A timeline of words (or phrases) -> a phone timeline.

    Parameters
    ----------
    words : Timeline
        Segments whose labels are words or phrases as written ("Hello,", "18", "well-known",
        " I'm"); gaps between them stay gaps (silence).

    Returns
    -------
    Timeline
        ``kind="phoneme"`` with ARPAbet labels without stress digits (the english phone set),
        the same ``path`` and ``stated_end``. A label with no speakable letters or digits
        (punctuation, an empty string) leaves its time as a gap.

    Examples
    --------
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> tl = words_to_phones(Timeline((Segment(0.2, 0.53, "Hi."),), stated_end=1.0))
    >>> [(s.label, round(s.start, 2), round(s.end, 2)) for s in tl], tl.duration
    ([('HH', 0.2, 0.28), ('AY', 0.28, 0.53)], 1.0)
    """
    segments: List[Segment] = []
    for w in words:
        segments += split_word(w.start, w.end, phones_of(w.label))
    return Timeline(tuple(segments), kind=PHONEME, path=words.path, stated_end=words.stated_end)
