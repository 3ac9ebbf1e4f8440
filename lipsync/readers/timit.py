"""TIMIT ``.phn`` files: ``begin end label`` per line, times in samples (16 kHz in TIMIT).

Labels are kept as TIMIT writes them (all 61 TIMIT labels, lower case: closures such as
``bcl``, silences ``h#``, ``pau``, ``epi``, and ``ax-h``); the English phone set maps them.
"""

from __future__ import annotations

import re

from ..errors import TimelineError
from ..motion.timeline import PHONEME, Timeline
from .base import READERS, Reader, ReadOptions
from ._common import build, decode_text, first_nonblank, parse_number, sniff_text

_ROW = re.compile(r"\d+(\.\d+)?\s+\d+(\.\d+)?\s+\S+")


def read(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read a TIMIT phone file; sample numbers are divided by ``options.sample_rate``."""
    text = decode_text(path, data)
    rows = []
    sr = options.sample_rate
    for lineno, raw in enumerate(text.split("\n"), 1):
        fields = raw.split()
        if not fields:
            continue
        if len(fields) != 3:
            raise TimelineError(f"expected 'begin end label', got {raw.strip()!r}", path=path, line=lineno)
        begin = parse_number(fields[0], path, lineno, "begin sample")
        end = parse_number(fields[1], path, lineno, "end sample")
        rows.append((begin / sr, end / sr, fields[2], lineno))
    if not rows:
        raise TimelineError("no phone rows in the file", path=path, line=1)
    return build(path, rows, PHONEME)


def sniff(head: bytes) -> bool:
    _, first = first_nonblank(sniff_text(head))
    return bool(_ROW.fullmatch(first)) and "\t" not in first


READERS.register("timit", Reader("timit", read, sniff, "TIMIT .phn (sample numbers)"),
                 extensions=(".phn",), aliases=("phn",))
