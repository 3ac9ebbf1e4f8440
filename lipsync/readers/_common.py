"""Shared checks for the readers: text decoding, numbers, and the interval rules.

Every reader turns its format into rows ``(start, end, label, line)`` and hands them to
:func:`build`, so the rules about order, overlap and negative times are stated once.
"""

from __future__ import annotations

import codecs
import math
import re
from typing import Iterable, List, Optional, Tuple

from ..errors import TimelineError
from ..motion.timeline import _OVERLAP_TOLERANCE_S, MAX_TIMELINE_S, Segment, Timeline

Row = Tuple[float, float, str, Optional[int]]

# Share of control bytes (other than tab, CR, LF, FF) above which a file is binary junk
# rather than text with a stray character; text formats never contain more than a few.
_BINARY_CONTROL_SHARE = 0.05
_CONTROL = bytes(b for b in range(32) if b not in (9, 10, 12, 13)) + b"\x7f"


def looks_binary(data: bytes) -> bool:
    """True if ``data`` (without a UTF-16 BOM) is not text."""
    head = data[:4096]
    if not head:
        return False
    if head.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        return False
    controls = sum(head.count(bytes([c])) for c in _CONTROL)
    return controls / len(head) > _BINARY_CONTROL_SHARE


def _utf16_without_bom(data: bytes) -> bool:
    # ASCII text stored as UTF-16 has a zero byte in every other position.
    head = data[:512]
    if len(head) < 4:
        return False
    even, odd = head[0::2], head[1::2]
    return even.count(0) > 0.4 * len(even) or odd.count(0) > 0.4 * len(odd)


def decode_text(path: str, data: bytes) -> str:
    """Decode a text file: UTF-8 (BOM optional) or UTF-16 with BOM; newlines normalised to ``\\n``.

    Raises TimelineError for binary data, UTF-16 without a BOM (its byte order cannot be
    known for sure) and bytes that are not valid UTF-8, naming the line.
    """
    if data.startswith(codecs.BOM_UTF8):
        encoding, body = "utf-8", data[len(codecs.BOM_UTF8):]
    elif data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        encoding, body = "utf-16", data
    else:
        if _utf16_without_bom(data):
            raise TimelineError(
                "looks like UTF-16 without a byte-order mark; save it as UTF-8 or as UTF-16 with a BOM",
                path=path, line=1)
        if looks_binary(data):
            raise TimelineError("binary data, not a text timeline", path=path, line=1)
        encoding, body = "utf-8", data
    try:
        text = body.decode(encoding)
    except UnicodeDecodeError as exc:
        if encoding == "utf-8":
            line = body.count(b"\n", 0, exc.start) + 1
        else:
            line = None
        raise TimelineError(f"not valid {encoding.upper()} text ({exc.reason})", path=path, line=line) from None
    if "\x00" in text:
        raise TimelineError("binary data (NUL characters), not a text timeline", path=path,
                            line=text.count("\n", 0, text.index("\x00")) + 1)
    return text.replace("\r\n", "\n").replace("\r", "\n")


_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def parse_number(text: str, path: str, line: Optional[int], what: str = "time") -> float:
    """``float(text)`` for a plain decimal number, else TimelineError naming file and line."""
    t = text.strip()
    if not _NUMBER.fullmatch(t):
        raise TimelineError(f"{what} {t!r} is not a number", path=path, line=line)
    value = float(t)
    if not math.isfinite(value):
        raise TimelineError(f"{what} {t!r} is not a finite number", path=path, line=line)
    return value


def build(path: str, rows: Iterable[Row], kind: str, *, stated_end: Optional[float] = None,
          sort: bool = False) -> Timeline:
    """Check rows and make a Timeline; empty labels and zero-length rows become gaps.

    Rules (each a TimelineError naming the file and the row's line): times are finite, not
    negative and at most :data:`~lipsync.motion.timeline.MAX_TIMELINE_S`; an end is not before its start; rows are in time order and do not overlap
    (overlaps below ``_OVERLAP_TOLERANCE_S`` are float noise from the writing tool and are
    snapped to the previous end). ``sort=True`` is for formats whose rows are not required to
    be in order (Audacity label tracks).
    """
    rows = list(rows)
    if sort:
        rows.sort(key=lambda r: (r[0], r[1]))
    segments: List[Segment] = []
    prev_start, prev_end, prev_line = 0.0, 0.0, None
    for start, end, label, line in rows:
        for value, what in ((start, "start"), (end, "end")):
            if not math.isfinite(value):
                raise TimelineError(f"{what} time is not a finite number", path=path, line=line)
            if value < 0:
                raise TimelineError(f"negative {what} time {value:g}", path=path, line=line)
            if value > MAX_TIMELINE_S:
                raise TimelineError(f"{what} time {value:g} s is past the limit of {MAX_TIMELINE_S:g} s (24 hours; "
                                    f"milliseconds or samples read as seconds?)", path=path, line=line)
        if end < start:
            raise TimelineError(f"end {end:g} is before start {start:g}", path=path, line=line)
        if start < prev_start:
            raise TimelineError(
                f"intervals are not in time order: start {start:g} comes after start {prev_start:g}"
                + (f" (line {prev_line})" if prev_line else ""), path=path, line=line)
        if start < prev_end - _OVERLAP_TOLERANCE_S:
            raise TimelineError(
                f"interval {start:g}-{end:g} overlaps the one before, which ends at {prev_end:g}"
                + (f" (line {prev_line})" if prev_line else ""), path=path, line=line)
        start = max(start, prev_end)
        end = max(end, start)
        prev_start, prev_line = start, line
        prev_end = max(prev_end, end)
        label = label.strip()
        if not label or end <= start:
            continue
        segments.append(Segment(float(start), float(end), label))
    if stated_end is not None and not math.isfinite(stated_end):
        stated_end = None
    if stated_end is not None and stated_end > MAX_TIMELINE_S:
        raise TimelineError(f"the file's end time {stated_end:g} s is past the limit of {MAX_TIMELINE_S:g} s "
                            f"(24 hours)", path=path)
    return Timeline(tuple(segments), kind=kind, path=path, stated_end=stated_end)


def first_nonblank(text: str) -> Tuple[int, str]:
    """(1-based line number, stripped content) of the first non-blank line, or (0, "")."""
    for i, raw in enumerate(text.split("\n"), 1):
        if raw.strip():
            return i, raw.strip()
    return 0, ""


def sniff_text(head: bytes) -> str:
    """Best-effort decoding of the first bytes for sniffing (never raises)."""
    if head.startswith(codecs.BOM_UTF8):
        head = head[3:]
    if head.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        # Cut to whole code units so a truncated head still decodes.
        return head[: len(head) // 2 * 2].decode("utf-16", errors="ignore")
    return head.decode("utf-8", errors="ignore")


def load_json(path: str, text: str):
    """``json.loads`` with its errors (syntax at their line, nesting too deep, an integer of
    more than 4300 digits) as TimelineError naming the file (:func:`lipsync._files.load_json`)."""
    from .._files import load_json as _load

    return _load(text, path, error=TimelineError)


def json_array_lines(text: str, key: str) -> List[int]:
    """1-based line of each element of the first array stored under ``"key"`` in ``text``.

    json does not report positions of values, so the array is found by its key and each
    element is decoded in place to learn where the next one starts. Returns [] if the array
    cannot be located (callers then report no line).
    """
    import json

    m = re.search(r'"' + re.escape(key) + r'"\s*:\s*\[', text)
    if not m:
        return []
    return array_lines_at(text, m.end())


def array_lines_at(text: str, pos: int) -> List[int]:
    """1-based line of each element of the JSON array whose ``[`` ends just before ``pos``.

    Returns [] if the array cannot be decoded (callers then report no line).
    """
    import json

    decoder = json.JSONDecoder()
    lines: List[int] = []
    ws = re.compile(r"[\s,]*")
    line, counted = text.count("\n", 0, pos) + 1, pos   # newlines counted up to `counted`
    try:
        while True:
            pos = ws.match(text, pos).end()
            if pos >= len(text) or text[pos] == "]":
                return lines
            # counted on from the element before: counting from the start each time made a
            # 40,000-cue Rhubarb JSON take ~100 s (issue 38)
            line += text.count("\n", counted, pos)
            counted = pos
            lines.append(line)
            _, pos = decoder.raw_decode(text, pos)
    except (ValueError, RecursionError):
        return []


def json_list(path: str, data: bytes, key: str, tool: str):
    """Decode a JSON document whose ``key`` holds a list: ``(doc, items, lines)``.

    ``lines`` are the 1-based lines of the items (see :func:`json_array_lines`); a document
    without such a list is a TimelineError saying it is not ``tool``'s output.
    """
    text = decode_text(path, data)
    doc = load_json(path, text)
    items = doc.get(key) if isinstance(doc, dict) else None
    if not isinstance(items, list):
        raise TimelineError(f'no "{key}" list: not {tool} output', path=path, line=1)
    return doc, items, json_array_lines(text, key)


def line_of(lines: List[int], index: int) -> Optional[int]:
    return lines[index] if 0 <= index < len(lines) else None


def json_time(value, path: str, line: Optional[int], what: str) -> float:
    """A JSON number (or numeric string) as a float, else TimelineError."""
    if isinstance(value, bool) or value is None:
        raise TimelineError(f"{what} {value!r} is not a number", path=path, line=line)
    if isinstance(value, (int, float)):
        try:
            v = float(value)
        except OverflowError:  # found by fuzzing: a JSON integer beyond float range (10**400)
            raise TimelineError(f"{what} {str(value)[:20]}... is too large", path=path, line=line) from None
        if not math.isfinite(v):
            raise TimelineError(f"{what} {value!r} is not a finite number", path=path, line=line)
        return v
    if isinstance(value, str):
        return parse_number(value, path, line, what)
    raise TimelineError(f"{what} {value!r} is not a number", path=path, line=line)
