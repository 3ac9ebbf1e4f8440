"""Gentle forced-aligner JSON: ``{"transcript": ..., "words": [{"case", "start", "phones"}]}``.

Only words with ``"case": "success"`` are used. Gentle also reports words it could not
place ("not-found-in-audio", which have no times) and words its free recogniser heard in
stretches that did not align ("not-found-in-transcript"), whose times are unreliable and
sometimes overlap the aligned words; both are skipped and their time is a gap (silence).

Each phone has a duration only; phones are laid end to end from their word's ``start``.
Gentle's position suffixes (``_B`` begin, ``_I`` inside, ``_E`` end, ``_S`` single) are
removed, leaving lower-case ARPAbet. Gentle's ``oov`` phone (a word outside its dictionary)
is speech of unknown phones; it is kept as ``oov``, which the shipped maps map explicitly.
"""

from __future__ import annotations

import re

from ..errors import TimelineError
from ..motion.timeline import PHONEME, Timeline
from .base import READERS, Reader, ReadOptions
from ._common import build, json_list, json_time, line_of, sniff_text

_SUFFIX = re.compile(r"_[BIES]$")


def normalise_label(phone: str) -> str:
    """Remove Gentle's word-position suffix: ``"ah_I"`` -> ``"ah"``.

    Examples
    --------
    >>> normalise_label("ay_S"), normalise_label("oov")
    ('ay', 'oov')
    """
    return _SUFFIX.sub("", phone.strip())


def read(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read a Gentle alignment (successfully aligned words only)."""
    _, words, lines = json_list(path, data, "words", "Gentle JSON")
    rows = []
    for i, word in enumerate(words):
        line = line_of(lines, i)
        if not isinstance(word, dict):
            raise TimelineError("a word entry is not a JSON object", path=path, line=line)
        if word.get("case") != "success":
            continue
        t = json_time(word.get("start"), path, line, "word start")
        phones = word.get("phones")
        if not isinstance(phones, list):
            raise TimelineError('an aligned word has no "phones" list', path=path, line=line)
        for phone in phones:
            if not isinstance(phone, dict) or not isinstance(phone.get("phone"), str):
                raise TimelineError('a phone needs a "phone" string and a "duration"', path=path, line=line)
            duration = json_time(phone.get("duration"), path, line, "phone duration")
            if duration < 0:
                raise TimelineError(f"negative phone duration {duration:g}", path=path, line=line)
            rows.append((t, t + duration, normalise_label(phone["phone"]), line))
            t += duration
    return build(path, rows, PHONEME)


def sniff(head: bytes) -> bool:
    text = sniff_text(head).lstrip()
    return text.startswith("{") and '"words"' in text and ('"case"' in text or '"alignedWord"' in text)


READERS.register("gentle", Reader("gentle", read, sniff, "Gentle forced-aligner JSON"),
                 extensions=(".json",))
