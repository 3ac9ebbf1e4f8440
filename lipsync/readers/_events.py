"""Shared by the readers of timed events (TTS viseme marks, recogniser word timings).

TTS engines report *points*: "viseme p starts at 6 ms". :func:`point_rows` turns points
into intervals (each lasts until the next; the last one :data:`LAST_MARK_S`), and
:func:`viseme_timeline` maps an engine's viseme names to the shipped shapes through a map
in ``configs/maps/`` (``polly-to-rhubarb``, ``azure-to-rhubarb``).
"""

from __future__ import annotations

import re
from typing import List, Optional, Sequence, Tuple

from ..motion.timeline import PHONEME, Timeline
from ._common import Row, array_lines_at, build

# A last mark has no next mark to end it; 150 ms is a typical phone length, the same
# choice as for Audacity point labels. TTS engines end with a silence mark, so this
# usually only sets how long the closing rest lasts.
LAST_MARK_S = 0.15

Event = Tuple[float, str, Optional[int]]


def point_rows(events: Sequence[Event]) -> List[Row]:
    """Points ``(time, label, line)`` in file order -> rows lasting until the next point.

    Examples
    --------
    >>> point_rows([(0.0, "sil", 1), (0.1, "p", 2)])
    [(0.0, 0.1, 'sil', 1), (0.1, 0.25, 'p', 2)]
    """
    rows: List[Row] = []
    for i, (t, label, line) in enumerate(events):
        # A next point before this one is left for build() to report as out of order.
        end = events[i + 1][0] if i + 1 < len(events) else t + LAST_MARK_S
        rows.append((t, max(end, t), label, line))
    return rows


def viseme_timeline(path: str, rows: Sequence[Row], map_name: str) -> Timeline:
    """Rows of an engine's viseme names -> a viseme timeline in the map's shapes."""
    from ..phonetics.phonemes import load_map, map_timeline

    return map_timeline(build(path, rows, PHONEME), load_map(map_name))


def top_array_lines(text: str) -> List[int]:
    """1-based lines of the elements of a document that is a JSON array ([] otherwise)."""
    m = re.match(r"\s*\[", text)
    return array_lines_at(text, m.end()) if m else []
