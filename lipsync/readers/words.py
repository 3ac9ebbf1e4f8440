"""Word timings from recognisers and TTS engines: words become phones by typical durations.

Two formats, each a registry entry:

``whisper`` -- word (or phrase) intervals in seconds, in the shapes Whisper and its kin
save them:

* openai-whisper / faster-whisper / whisperX: ``{"segments": [{"words": [{"word", "start",
  "end"}]}]}`` (a segment without ``words`` counts as one phrase over its ``start``-``end``);
  whisper-timestamped writes the word as ``"text"``; a bare list of such segments;
* the OpenAI API's ``verbose_json``: ``{"words": [{"word", "start", "end"}]}``;
* a plain list ``[{"word", "start", "end"}]``;
* whisper.cpp ``-oj``/``-ojf``: ``{"transcription": [{"offsets": {"from", "to"}, "text"}]}``
  (milliseconds; ``-ml 1`` gives one word per entry);
* Hugging Face ``pipeline(return_timestamps="word")``: ``{"chunks": [{"text", "timestamp": [s, e]}]}``.

Words without times (whisperX leaves some numbers untimed) are skipped: their time is
silence. Recognisers' word times may overlap by a few tens of milliseconds; a word that
starts before the previous one ends starts at that end instead (the earlier word keeps
its time), and a word left with no time is skipped.

``elevenlabs`` -- character alignment ``{"characters": [...], "character_start_times_seconds":
[...], "character_end_times_seconds": [...]}``, bare or under ``alignment`` /
``normalized_alignment`` (preferred when present: it is the text as spoken, numbers
spelled out), also in the SDKs' camelCase spellings and the websocket's ``chars``,
``charStartTimesMs``, ``charDurationsMs``. Characters are grouped into words at white
space; audio tags in square brackets (``[excited]``, eleven_v3) are not spoken and are
dropped.

Both give the words to :func:`lipsync.speech.phonetise.words_to_phones`.
"""

from __future__ import annotations

import re
from typing import Any, List, Optional, Tuple

from ..errors import TimelineError
from ..motion.timeline import PHONEME, Timeline
from .base import READERS, Reader, ReadOptions
from ._common import Row, build, decode_text, json_array_lines, json_time, load_json, sniff_text
from ._events import top_array_lines

# --- whisper-style -------------------------------------------------------------------------


def _doc(path: str, data: bytes) -> Tuple[Any, str]:
    text = decode_text(path, data)
    return load_json(path, text), text


def _time(value, path, line, what) -> Optional[float]:
    return None if value is None else json_time(value, path, line, what)


def _word_row(path: str, item: Any, line: Optional[int]) -> Optional[Row]:
    """One word or phrase entry -> (start, end, text, line), or None if it has no times."""
    if not isinstance(item, dict):
        raise TimelineError("a word entry is not a JSON object", path=path, line=line)
    label = item.get("word", item.get("text"))
    if not isinstance(label, str):
        raise TimelineError('a word entry needs a "word" (or "text") string', path=path, line=line)
    if "offsets" in item:  # whisper.cpp: milliseconds
        off = item["offsets"]
        if not isinstance(off, dict):
            raise TimelineError('"offsets" must hold "from" and "to"', path=path, line=line)
        start, end = _time(off.get("from"), path, line, "offsets.from"), _time(off.get("to"), path, line, "offsets.to")
        start, end = (None if start is None else start / 1000), (None if end is None else end / 1000)
    elif "timestamp" in item:  # Hugging Face pipeline chunks: [start, end]
        ts = item["timestamp"]
        if not isinstance(ts, (list, tuple)) or len(ts) != 2:
            raise TimelineError('"timestamp" must be [start, end]', path=path, line=line)
        start, end = _time(ts[0], path, line, "start"), _time(ts[1], path, line, "end")
    else:
        start, end = _time(item.get("start"), path, line, "start"), _time(item.get("end"), path, line, "end")
    if start is None or end is None:
        return None
    return start, end, label, line


def _whisper_rows(path: str, doc: Any, text: str) -> List[Row]:
    if isinstance(doc, dict):
        for key in ("words", "segments", "transcription", "chunks"):
            if isinstance(doc.get(key), list):
                return _entries(path, doc[key], json_array_lines(text, key))
        raise TimelineError('no "segments", "words", "transcription" or "chunks" list: not Whisper-style JSON',
                            path=path, line=1)
    if isinstance(doc, list):
        return _entries(path, doc, top_array_lines(text))
    raise TimelineError("expected a JSON object or array of word timings", path=path, line=1)


def _entries(path: str, items: list, lines: List[int]) -> List[Row]:
    rows: List[Row] = []
    for i, item in enumerate(items):
        line = lines[i] if i < len(lines) else None
        if isinstance(item, dict) and isinstance(item.get("words"), list) and item["words"]:
            for word in item["words"]:  # a segment with word times: the segment's line for errors
                row = _word_row(path, word, line)
                if row is not None:
                    rows.append(row)
            continue
        row = _word_row(path, item, line)
        if row is not None:
            rows.append(row)
    return rows


def _untangle(rows: List[Row]) -> List[Row]:
    """Overlapping word times: a word starts where the previous one ends."""
    out: List[Row] = []
    prev_end = 0.0
    for start, end, label, line in rows:
        if out and start < prev_end <= end:
            start = prev_end
        out.append((start, end, label, line))
        prev_end = max(prev_end, end)
    return out


def _phones(path: str, rows: List[Row], stated_end: Optional[float] = None) -> Timeline:
    from ..speech.phonetise import words_to_phones

    if not rows:
        raise TimelineError("no timed words in the file", path=path, line=1)
    return words_to_phones(build(path, _untangle(rows), PHONEME, stated_end=stated_end))


def read_whisper(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read Whisper-style word timings as a phone timeline."""
    doc, text = _doc(path, data)
    duration = doc.get("duration") if isinstance(doc, dict) else None
    stated = json_time(duration, path, 1, "duration") if isinstance(duration, (int, float)) \
        and not isinstance(duration, bool) else None
    return _phones(path, _whisper_rows(path, doc, text), stated)


# --- ElevenLabs ------------------------------------------------------------------------------

# (characters, starts, ends-or-durations, seconds per unit, ends are durations)
_SPELLINGS = (("characters", "character_start_times_seconds", "character_end_times_seconds", 1.0, False),
              ("characters", "characterStartTimesSeconds", "characterEndTimesSeconds", 1.0, False),
              ("chars", "charStartTimesMs", "charDurationsMs", 1e-3, True))
_WRAPPERS = ("normalized_alignment", "normalizedAlignment", "alignment")


def _alignment(path: str, doc: Any):
    if not isinstance(doc, dict):
        raise TimelineError("expected a JSON object with a character alignment", path=path, line=1)
    for key in _WRAPPERS:
        if isinstance(doc.get(key), dict) and any(s[0] in doc[key] for s in _SPELLINGS):
            return doc[key], key
    return doc, None


def read_elevenlabs(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read an ElevenLabs character alignment as a phone timeline."""
    doc, text = _doc(path, data)
    al, _ = _alignment(path, doc)
    spelling = next((s for s in _SPELLINGS if all(k in al for k in s[:3])), None)
    if spelling is None:
        raise TimelineError('no character alignment ("characters", "character_start_times_seconds", '
                            '"character_end_times_seconds")', path=path, line=1)
    ckey, skey, ekey, unit, durations = spelling
    chars, starts, ends = al[ckey], al[skey], al[ekey]
    line = (json_array_lines(text, ckey) or [None])[0]
    if not (isinstance(chars, list) and isinstance(starts, list) and isinstance(ends, list)):
        raise TimelineError(f'"{ckey}", "{skey}" and "{ekey}" must be lists', path=path, line=line)
    if not len(chars) == len(starts) == len(ends):
        raise TimelineError(f"{len(chars)} characters but {len(starts)} start and {len(ends)} end times",
                            path=path, line=line)
    rows: List[Row] = []
    word, w0, w1, depth = "", None, None, 0
    for c, s, e in zip(chars, starts, ends):
        if not isinstance(c, str):
            raise TimelineError(f"character {c!r} is not a string", path=path, line=line)
        t0 = json_time(s, path, line, "character start") * unit
        t1 = json_time(e, path, line, "character end") * unit + (t0 if durations else 0.0)
        if c == "[":
            depth += 1
        if depth or c.isspace() or not c:
            if word:
                rows.append((w0, w1, word, line))
            word, w0 = "", None
        else:
            word += c
            w0 = t0 if w0 is None else w0
            w1 = t1
        if c == "]" and depth:
            depth -= 1
    if word:
        rows.append((w0, w1, word, line))
    return _phones(path, rows)


# --- sniffing ----------------------------------------------------------------------------------

_CHARS = re.compile(r'"(character_start_times_seconds|characterStartTimesSeconds|charStartTimesMs)"\s*:')
_GENTLE_OR_RHUBARB = re.compile(r'"(case|alignedWord|mouthCues)"\s*:')
_WHISPER_KEYS = re.compile(r'"(segments|words|transcription|chunks)"\s*:\s*\[')
_WORD_ITEM = re.compile(r'^\[\s*\{[^{}]*"(word|text)"\s*:[^{}]*"start"\s*:'
                        r'|^\[\s*\{[^{}]*"start"\s*:[^{}]*"(word|text)"\s*:')


def sniff_elevenlabs(head: bytes) -> bool:
    text = sniff_text(head).lstrip()
    return text.startswith("{") and bool(_CHARS.search(text))


def sniff_whisper(head: bytes) -> bool:
    text = sniff_text(head).lstrip()
    if _GENTLE_OR_RHUBARB.search(text) or _CHARS.search(text):
        return False
    if text.startswith("{"):
        return bool(_WHISPER_KEYS.search(text))
    return bool(_WORD_ITEM.match(text)) or (text.startswith("[") and bool(_WHISPER_KEYS.search(text)))


READERS.register("elevenlabs", Reader("elevenlabs", read_elevenlabs, sniff_elevenlabs,
                                      "ElevenLabs character alignment (JSON)"),
                 extensions=(".json",), aliases=("eleven-labs", "character-alignment"))
READERS.register("whisper", Reader("whisper", read_whisper, sniff_whisper,
                                   "Whisper-style word timings (JSON), or a plain list of words"),
                 extensions=(".json",), aliases=("words", "word-timings", "faster-whisper", "whisper.cpp"))
