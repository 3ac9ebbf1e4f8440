"""Amazon Polly speech marks: JSON lines ``{"time": ms, "type": ..., "value": ...}``.

Polly returns one JSON object per line (``--output-format json`` with
``--speech-mark-types``); a JSON array of the same objects is accepted too. Mark types:

* ``viseme``: the mouth shape starting at ``time`` (milliseconds). Viseme marks are points:
  each lasts until the next viseme mark, the last one :data:`~._events.LAST_MARK_S`.
  Polly's viseme names (p t S T f k i r s u @ a e E o O sil, case-sensitive) are mapped to
  the shipped shapes by ``configs/maps/polly-to-rhubarb.yaml``.
* ``word``: used only when the file has no viseme marks. A word lasts until the next word
  starts, but no longer than :data:`WORD_STRETCH` times its typical length (a pause after
  it is silence; the last word lasts its typical length), and becomes phones through
  :func:`lipsync.speech.phonetise.words_to_phones`.
  SSML tags reported as words (``<break time="300ms"/>``) are not spoken and are skipped.
* ``sentence`` and ``ssml``: carry no timing a mouth needs; ignored.
"""

from __future__ import annotations

import re

from ..errors import TimelineError
from ..motion.timeline import PHONEME, Timeline
from .base import READERS, Reader, ReadOptions
from ._common import build, decode_text, json_time, load_json, sniff_text
from ._events import point_rows, top_array_lines, viseme_timeline

MAP = "polly-to-rhubarb"
TYPES = ("viseme", "word", "sentence", "ssml")

# A word spoken at half the typical rate is slow speech; beyond twice its typical length
# the rest of the time before the next word is a pause, shown as rest.
WORD_STRETCH = 2.0


def _marks(path: str, text: str):
    """[(mark, line)] from JSON lines or a JSON array."""
    if text.lstrip().startswith("["):
        doc = load_json(path, text)
        lines = top_array_lines(text)
        return [(m, lines[i] if i < len(lines) else None) for i, m in enumerate(doc)]
    out = []
    for n, raw in enumerate(text.split("\n"), 1):
        if raw.strip():
            try:
                out.append((load_json(path, raw), n))
            except TimelineError as exc:  # its line counts within this one line
                raise TimelineError(exc.reason, path=path, line=n) from None
    return out


def read(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read Polly speech marks (viseme marks, else word marks)."""
    from ..phonetics.phonemes import load_map

    text = decode_text(path, data)
    names = load_map(MAP).map
    visemes, words = [], []
    for mark, line in _marks(path, text):
        if not isinstance(mark, dict) or "time" not in mark or "type" not in mark:
            raise TimelineError('a speech mark needs "time" and "type"', path=path, line=line)
        kind, value = mark["type"], mark.get("value")
        if kind not in TYPES:
            raise TimelineError(f"unknown speech mark type {kind!r} (Polly writes {', '.join(TYPES)})",
                                path=path, line=line)
        t = json_time(mark["time"], path, line, "time") / 1000.0
        if kind in ("viseme", "word") and not isinstance(value, str):
            raise TimelineError(f'a {kind} mark needs a "value" string', path=path, line=line)
        if kind == "viseme":
            if value not in names:
                raise TimelineError(f"unknown Polly viseme {value!r} (valid: {' '.join(names)})",
                                    path=path, line=line)
            visemes.append((t, value, line))
        elif kind == "word" and not re.match(r"\s*<", value):
            words.append((t, value, line))
    if visemes:
        return viseme_timeline(path, point_rows(visemes), MAP)
    if words:
        return _words_timeline(path, words)
    raise TimelineError("no viseme or word marks (request speech mark types viseme or word)", path=path, line=1)


def _words_timeline(path: str, words) -> Timeline:
    from ..speech.phonetise import phones_of, typical_duration, words_to_phones

    rows = []
    for i, (t, value, line) in enumerate(words):
        typical = typical_duration(phones_of(value))
        # The last word has no next mark to end it: nothing says it was slow.
        nxt = words[i + 1][0] if i + 1 < len(words) else t + typical
        rows.append((t, max(t, min(nxt, t + WORD_STRETCH * typical)), value, line))
    return words_to_phones(build(path, rows, PHONEME))


_MARK = re.compile(r'^\[?\s*\{.*"time"\s*:.*"type"\s*:\s*"(viseme|word|sentence|ssml)"')


def sniff(head: bytes) -> bool:
    for raw in sniff_text(head).lstrip().split("\n", 1)[:1]:
        return bool(_MARK.match(raw.strip())) or bool(
            re.match(r'^\[?\s*\{', raw) and '"time"' in raw and '"type"' in raw and "viseme" in raw)
    return False


READERS.register("polly", Reader("polly", read, sniff, "Amazon Polly speech marks (JSON lines)"),
                 extensions=(".marks", ".jsonl"), aliases=("polly-speech-marks", "speech-marks"))
