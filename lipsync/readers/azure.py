"""Azure Speech viseme events saved as JSON (``VisemeReceived``: audio offset + viseme ID).

The Speech SDK reports each viseme as an event with an audio offset in ticks of 100 ns and
one of 22 viseme IDs (0 silence ... 21 p b m). Apps save them in several spellings; all
of these are read:

* a JSON array of events, or an object holding one under ``visemes``/``Visemes``/
  ``events``/``visemeEvents``/``viseme_events``;
* the service's own ``{"Metadata": [{"Type": "Viseme", "Data": {"Offset", "VisemeId"}}]}``;
* the ID as ``VisemeId``, ``visemeId``, ``viseme_id``, ``visemeID``, ``VisemeID`` or
  ``viseme``; the offset in ticks as ``AudioOffset``, ``audioOffset``, ``audio_offset``,
  ``Offset`` or ``offset``, or in milliseconds as ``audio_offset_ms``, ``audioOffsetMs``,
  ``offset_ms`` or ``offsetMs``.

Events are points: each lasts until the next, the last one
:data:`~._events.LAST_MARK_S`. IDs are mapped to the shipped shapes by
``configs/maps/azure-to-rhubarb.yaml``.
"""

from __future__ import annotations

import re
from typing import List, Optional, Tuple

from ..errors import TimelineError
from ..motion.timeline import Timeline
from .base import READERS, Reader, ReadOptions
from ._common import decode_text, json_array_lines, json_time, load_json, sniff_text
from ._events import point_rows, top_array_lines, viseme_timeline

MAP = "azure-to-rhubarb"
VISEME_IDS = range(22)

ID_KEYS = ("VisemeId", "visemeId", "viseme_id", "visemeID", "VisemeID", "viseme")
# (key, seconds per unit): the SDK's offsets are ticks of 100 ns.
OFFSET_KEYS = (("AudioOffset", 1e-7), ("audioOffset", 1e-7), ("audio_offset", 1e-7), ("Offset", 1e-7),
               ("offset", 1e-7), ("audio_offset_ms", 1e-3), ("audioOffsetMs", 1e-3), ("offset_ms", 1e-3),
               ("offsetMs", 1e-3))
LIST_KEYS = ("visemes", "Visemes", "events", "visemeEvents", "viseme_events", "Metadata")


def _events(path: str, text: str) -> Tuple[list, List[int]]:
    doc = load_json(path, text)
    if isinstance(doc, list):
        return doc, top_array_lines(text)
    if isinstance(doc, dict):
        for key in LIST_KEYS:
            if isinstance(doc.get(key), list):
                return doc[key], json_array_lines(text, key)
    raise TimelineError(f"no list of viseme events (a JSON array, or one under {', '.join(LIST_KEYS)})",
                        path=path, line=1)


def _event(path: str, ev, line: Optional[int]) -> Optional[Tuple[float, str, Optional[int]]]:
    if isinstance(ev, dict) and "Type" in ev and "Data" in ev:  # the service's metadata message
        if ev["Type"] != "Viseme":
            return None  # word boundaries and session ends carry no mouth shape
        ev = ev["Data"]
    if not isinstance(ev, dict):
        raise TimelineError("a viseme event is not a JSON object", path=path, line=line)
    id_key = next((k for k in ID_KEYS if k in ev), None)
    off_key = next(((k, unit) for k, unit in OFFSET_KEYS if k in ev), None)
    if id_key is None or off_key is None:
        raise TimelineError(f"a viseme event needs a viseme ID ({'/'.join(ID_KEYS)}) and an audio offset "
                            f"({'/'.join(k for k, _ in OFFSET_KEYS)})", path=path, line=line)
    vid = ev[id_key]
    if isinstance(vid, bool) or not isinstance(vid, int) or vid not in VISEME_IDS:
        raise TimelineError(f"viseme ID {vid!r} is not one of Azure's 0-21", path=path, line=line)
    t = json_time(ev[off_key[0]], path, line, "audio offset") * off_key[1]
    return t, str(vid), line


def read(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read saved Azure viseme events as a viseme timeline."""
    text = decode_text(path, data)
    events, lines = _events(path, text)
    points = []
    for i, ev in enumerate(events):
        p = _event(path, ev, lines[i] if i < len(lines) else None)
        if p is not None:
            points.append(p)
    if not points:
        raise TimelineError("no viseme events in the file", path=path, line=1)
    return viseme_timeline(path, point_rows(points), MAP)


_ID = re.compile(r'"(VisemeId|visemeId|viseme_id|visemeID|VisemeID)"\s*:')
_OFFSET = re.compile(r'"(AudioOffset|audioOffset|audio_offset|Offset|offset|audio_offset_ms|audioOffsetMs|'
                     r'offset_ms|offsetMs)"\s*:')


def sniff(head: bytes) -> bool:
    text = sniff_text(head).lstrip()
    return text[:1] in ("[", "{") and bool(_ID.search(text)) and bool(_OFFSET.search(text))


READERS.register("azure", Reader("azure", read, sniff, "Azure Speech viseme events (JSON)"),
                 extensions=(".json",), aliases=("azure-visemes",))
