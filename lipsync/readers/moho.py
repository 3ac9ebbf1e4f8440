"""Moho (Anime Studio) switch data ``.dat``: ``MohoSwitch1`` then ``frame viseme`` lines.

Frames are 1-based at the file's frame rate (``fps``, default 24; Papagayo and Rhubarb
write these files). Each switch holds until the next; the last one is shown for one frame.
Labels are visemes (Preston Blair names from Papagayo, A-H/X from Rhubarb).
"""

from __future__ import annotations

from ..errors import TimelineError
from ..motion.timeline import MAX_TIMELINE_S, VISEME, Timeline
from .base import READERS, Reader, ReadOptions
from ._common import build, decode_text, first_nonblank, parse_number, sniff_text

MAGIC = "MohoSwitch1"


def read(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read a Moho switch file; frame f (1-based) starts at ``(f - 1) / options.fps``."""
    text = decode_text(path, data)
    lineno, first = first_nonblank(text)
    if first != MAGIC:
        raise TimelineError(f"first line must be {MAGIC!r}, not {first[:40]!r}", path=path, line=lineno or 1)
    keys = []
    for n, raw in enumerate(text.split("\n")[lineno:], lineno + 1):
        fields = raw.split()
        if not fields:
            continue
        if len(fields) != 2:
            raise TimelineError(f"expected 'frame viseme', got {raw.strip()!r}", path=path, line=n)
        frame = parse_number(fields[0], path, n, "frame number")
        if frame != int(frame):
            raise TimelineError(f"frame number {fields[0]!r} is not a whole number", path=path, line=n)
        if frame < 1:
            raise TimelineError(f"frame number {fields[0]} is below 1 (frames are 1-based)", path=path, line=n)
        t = (frame - 1) / options.fps
        if t > MAX_TIMELINE_S:  # here, not in build(): this key's line holds the frame (the key before ends at it)
            raise TimelineError(f"frame {fields[0]} is {t:g} s in at {options.fps:g} fps, past the limit of "
                                f"{MAX_TIMELINE_S:g} s (24 hours)", path=path, line=n)
        keys.append((t, fields[1], n))
    if not keys:
        raise TimelineError("no switch keys after the header", path=path, line=lineno)
    rows = []
    for i, (t, label, n) in enumerate(keys):
        end = keys[i + 1][0] if i + 1 < len(keys) else t + 1.0 / options.fps
        if end < t:
            raise TimelineError(f"frame numbers are not in order (line {keys[i + 1][2]} is before this one)",
                                path=path, line=keys[i + 1][2])
        rows.append((t, end, label, n))
    return build(path, rows, VISEME)


def sniff(head: bytes) -> bool:
    return first_nonblank(sniff_text(head))[1] == MAGIC


READERS.register("moho", Reader("moho", read, sniff, "Moho/Papagayo switch data (MohoSwitch1)"),
                 extensions=(".dat",), aliases=("dat", "papagayo"))
