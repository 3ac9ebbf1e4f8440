"""GRID corpus word alignments (``.align``): ``start end word`` per line, times in 1/25000 s.

The GRID audio-visual corpus (Cooke et al. 2006) ships one file per sentence with its
words' times from an HMM aligner, in units of 1/25000 s (one video frame at 25 fps is 1000
units). ``sil`` and ``sp`` (a short pause) are silence. Words become phones through CMUdict
by typical durations (:func:`lipsync.speech.phonetise.words_to_phones`), as the other word
formats do. Chosen by extension (``.align``, confirmed by a first row of ``sil``) or by
name: its rows look like TIMIT's, so content alone never picks it.

Examples
--------
>>> import tempfile, os
>>> from lipsync.readers import read_timeline
>>> d = tempfile.mkdtemp(); p = os.path.join(d, "s.align")
>>> _ = open(p, "w").write("0 23750 sil\\r\\n23750 29500 bin\\r\\n29500 75000 sil\\r\\n")
>>> [s.label for s in read_timeline(p)], read_timeline(p).duration
(['B', 'IH', 'N'], 3.0)
"""

from __future__ import annotations

import re

from ..errors import TimelineError
from ..motion.timeline import PHONEME, Timeline
from .base import READERS, Reader, ReadOptions
from ._common import build, decode_text, first_nonblank, parse_number, sniff_text

#: GRID's time unit: 25 kHz ticks (the corpus' audio was recorded at 25 kHz, 1000 ticks a frame).
TICKS_PER_SECOND = 25000
#: Labels that are silence, not words.
SILENCE = ("sil", "sp")


def read_words(path: str, data: bytes) -> Timeline:
    """The words of a GRID alignment as a timeline of words (silence as gaps)."""
    text = decode_text(path, data)
    rows = []
    last = 0.0
    for lineno, raw in enumerate(text.splitlines(), 1):
        fields = raw.split()
        if not fields:
            continue
        if len(fields) != 3:
            raise TimelineError(f"expected 'start end word', got {raw.strip()!r}", path=path, line=lineno)
        start = parse_number(fields[0], path, lineno, "start") / TICKS_PER_SECOND
        end = parse_number(fields[1], path, lineno, "end") / TICKS_PER_SECOND
        last = max(last, end)
        rows.append((start, end, "" if fields[2].lower() in SILENCE else fields[2], lineno))
    if not rows:
        raise TimelineError("no rows in the file", path=path, line=1)
    return build(path, rows, PHONEME, stated_end=last)


def read(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read a GRID ``.align`` file as a phone timeline."""
    from ..speech.phonetise import words_to_phones

    return words_to_phones(read_words(path, data))


_FIRST_ROW = re.compile(r"\d+\s+\d+\s+sil")


def sniff(head: bytes) -> bool:
    # Only confirms the extension (see the module docstring): TIMIT comes first in sniffing.
    _, first = first_nonblank(sniff_text(head))
    return bool(_FIRST_ROW.fullmatch(first.strip()))


READERS.register("grid", Reader("grid", read, sniff, "GRID corpus word alignment (.align)"),
                 extensions=(".align",), aliases=("grid-align",))
