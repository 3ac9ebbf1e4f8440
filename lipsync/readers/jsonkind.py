"""Which reader a JSON file is for, from the structure of the whole document.

Several formats are JSON (Gentle, Rhubarb, Polly speech marks, Azure viseme events,
Whisper-style word timings, ElevenLabs alignments). Content sniffing looks at the first
bytes only; when it cannot decide (a long transcript before the word list, an extension
shared by all of them), :func:`json_reader_for` parses the document and recognises it by
its keys, and a JSON document none of them fits is an error that lists the JSON formats
and what each looks like.
"""

from __future__ import annotations

import json
from typing import Any, Callable, List, Optional, Tuple

from ..errors import TimelineError

# (reader, what its documents look like, test on the parsed document). The order matters
# only where tests overlap: Gentle's words carry "case", Whisper's do not.
_KINDS: List[Tuple[str, str, Callable[[Any], bool]]] = []


def _first(items) -> Any:
    return items[0] if isinstance(items, list) and items else None


def _is_gentle(doc) -> bool:
    w = _first(doc.get("words")) if isinstance(doc, dict) else None
    return isinstance(w, dict) and ("case" in w or "alignedWord" in w)


def _is_rhubarb(doc) -> bool:
    return isinstance(doc, dict) and isinstance(doc.get("mouthCues"), list)


def _is_azure(doc) -> bool:
    from .azure import ID_KEYS, LIST_KEYS

    items = doc if isinstance(doc, list) else next(
        (doc[k] for k in LIST_KEYS if isinstance(doc, dict) and isinstance(doc.get(k), list)), None)
    ev = _first(items)
    if isinstance(ev, dict) and isinstance(ev.get("Data"), dict):
        ev = ev["Data"]
    return isinstance(ev, dict) and any(k in ev for k in ID_KEYS)


def _is_elevenlabs(doc) -> bool:
    from .words import _SPELLINGS, _WRAPPERS

    if not isinstance(doc, dict):
        return False
    for al in [doc] + [doc[k] for k in _WRAPPERS if isinstance(doc.get(k), dict)]:
        if any(all(k in al for k in s[:3]) for s in _SPELLINGS):
            return True
    return False


def _is_whisper(doc) -> bool:
    items = doc if isinstance(doc, list) else next(
        (doc[k] for k in ("words", "segments", "transcription", "chunks")
         if isinstance(doc, dict) and isinstance(doc.get(k), list)), None)
    item = _first(items)
    return isinstance(item, dict) and ("start" in item or "offsets" in item or "timestamp" in item
                                       or "words" in item)


def _is_polly(doc) -> bool:
    m = _first(doc) if isinstance(doc, list) else doc
    return isinstance(m, dict) and "time" in m and "type" in m


_KINDS += [
    ("gentle", '{"words": [{"case", "start", "phones"}]}', _is_gentle),
    ("rhubarb-json", '{"mouthCues": [{"start", "end", "value"}]}', _is_rhubarb),
    ("polly", 'lines of {"time", "type", "value"}', _is_polly),
    ("azure", '[{"audioOffset", "visemeId"}]', _is_azure),
    ("elevenlabs", '{"characters", "character_start_times_seconds", "character_end_times_seconds"}',
     _is_elevenlabs),
    ("whisper", '{"segments": [{"words": [{"word", "start", "end"}]}]} or [{"word", "start", "end"}]',
     _is_whisper),
]


def _parse(data: bytes) -> Tuple[bool, Any]:
    """(is JSON, document); JSON lines give the first line's document."""
    import re

    from ._common import sniff_text

    # Look at the first bytes before decoding anything: a large binary file is not JSON.
    if not re.match(rb"(\xef\xbb\xbf)?\s*[\[{]", data[:4096].lstrip()[:8]):
        return False, None
    text = sniff_text(data).strip()
    if not text or text[0] not in "[{":
        return False, None
    try:
        return True, json.loads(text)
    except (ValueError, RecursionError):
        pass
    first = text.split("\n", 1)[0]
    try:
        doc = json.loads(first)
    except (ValueError, RecursionError):
        return False, None
    return isinstance(doc, dict), doc  # several objects, one per line (Polly)


def kind_of(data: bytes) -> Optional[str]:
    """The reader name for a JSON document, or None (not JSON, or no known shape).

    Examples
    --------
    >>> kind_of(b'{"mouthCues": []}'), kind_of(b'[{"word": "hi", "start": 0, "end": 1}]'), kind_of(b"0 1 a")
    ('rhubarb-json', 'whisper', None)
    """
    ok, doc = _parse(data)
    if not ok:
        return None
    return next((name for name, _, test in _KINDS if test(doc)), None)


def json_reader_for(path: str, data: bytes):
    """The reader for a JSON file the sniffers did not recognise; None if it is not JSON.

    Raises TimelineError (listing the JSON formats) for valid JSON of no known shape.
    """
    from .base import READERS

    ok, doc = _parse(data)
    if not ok:
        return None  # not JSON, or broken JSON: the extension's reader says what is wrong
    name = next((n for n, _, test in _KINDS if test(doc)), None)
    if name is None:
        shapes = "; ".join(f"{n}: {shape}" for n, shape, _ in _KINDS)
        raise TimelineError(f"JSON of no timeline format lipsync reads (give --timeline-format if it is one). "
                            f"Formats: {shapes}", path=path, line=1)
    return READERS.get(name)
