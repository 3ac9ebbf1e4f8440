"""Audacity label tracks: ``start<TAB>end<TAB>label`` in seconds, one label per line.

Audacity writes point labels with ``start == end``; such a label marks where a sound
begins, so it lasts until the next label starts (the last one ``LAST_POINT_LABEL_S``).
Lines starting with a backslash carry a label's frequency range (spectral selection) and
are skipped. Time between labels is a gap (silence).
"""

from __future__ import annotations

import re

from ..errors import TimelineError
from ..motion.timeline import PHONEME, Timeline
from .base import READERS, Reader, ReadOptions
from ._common import build, decode_text, first_nonblank, parse_number, sniff_text

# A last point label has no next label to end it; 150 ms is a typical phone length.
LAST_POINT_LABEL_S = 0.15

_ROW = re.compile(r"[-+]?\d+(\.\d+)?\t[-+]?\d+(\.\d+)?(\t.*)?")


def read(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read an Audacity label file (region and point labels)."""
    text = decode_text(path, data)
    raw_rows = []
    for lineno, raw in enumerate(text.split("\n"), 1):
        if not raw.strip() or raw.lstrip().startswith("\\"):
            continue
        fields = raw.split("\t")
        if len(fields) < 2:
            raise TimelineError(f"expected 'start<TAB>end<TAB>label', got {raw.strip()!r}",
                                path=path, line=lineno)
        start = parse_number(fields[0], path, lineno, "start time")
        end = parse_number(fields[1], path, lineno, "end time")
        label = "\t".join(fields[2:]).strip()
        raw_rows.append([start, end, label, lineno])
    if not raw_rows:
        raise TimelineError("no labels in the file", path=path, line=1)
    for i, row in enumerate(raw_rows):
        if row[0] == row[1]:  # a point label runs to the next label's start
            nxt = next((r[0] for r in raw_rows[i + 1:] if r[0] > row[0]), None)
            row[1] = nxt if nxt is not None else row[0] + LAST_POINT_LABEL_S
    return build(path, [tuple(r) for r in raw_rows], PHONEME)


def sniff(head: bytes) -> bool:
    _, first = first_nonblank(sniff_text(head))
    return bool(_ROW.fullmatch(first))


READERS.register("audacity", Reader("audacity", read, sniff, "Audacity label track"),
                 extensions=(".txt", ".labels"), aliases=("labels",))
