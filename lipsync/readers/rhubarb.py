"""Rhubarb Lip Sync output: TSV, JSON and XML mouth cues (visemes A-H and X).

* TSV: ``time<TAB>shape`` per line; each cue lasts until the next one starts. The last line
  (Rhubarb writes X at the end of the recording) marks the end and has no length.
* JSON: ``{"mouthCues": [{"start": s, "end": e, "value": "A"}, ...]}``.
* XML: ``<rhubarbResult><mouthCues><mouthCue start=".." end="..">A</mouthCue>...``.
"""

from __future__ import annotations

import re
from typing import Optional

from ..errors import TimelineError
from ..motion.timeline import MAX_TIMELINE_S, VISEME, Timeline
from .base import READERS, Reader, ReadOptions
from ._common import (build, decode_text, first_nonblank, json_list, json_time, line_of, parse_number, sniff_text)

_TSV_ROW = re.compile(r"\d+(\.\d+)?\t[A-Za-z]\w*")


def read_tsv(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read Rhubarb's TSV output (cue start times; ends are the next start)."""
    text = decode_text(path, data)
    cues = []
    for n, raw in enumerate(text.split("\n"), 1):
        if not raw.strip():
            continue
        fields = raw.strip().split("\t")
        if len(fields) != 2:
            raise TimelineError(f"expected 'time<TAB>shape', got {raw.strip()!r}", path=path, line=n)
        t = parse_number(fields[0], path, n, "time")
        if t > MAX_TIMELINE_S:  # here, not in build(): this line holds the time (the cue before ends at it)
            raise TimelineError(f"time {t:g} s is past the limit of {MAX_TIMELINE_S:g} s (24 hours)", path=path, line=n)
        cues.append((t, fields[1].strip(), n))
    if not cues:
        raise TimelineError("no mouth cues in the file", path=path, line=1)
    rows = [(t, cues[i + 1][0] if i + 1 < len(cues) else t, label, n)
            for i, (t, label, n) in enumerate(cues)]
    return build(path, rows, VISEME, stated_end=cues[-1][0])


def read_json(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read Rhubarb's JSON output."""
    doc, cues, lines = json_list(path, data, "mouthCues", "Rhubarb JSON")
    rows = []
    for i, cue in enumerate(cues):
        line = line_of(lines, i)
        if not isinstance(cue, dict) or not {"start", "end", "value"} <= set(cue):
            raise TimelineError('a mouth cue needs "start", "end" and "value"', path=path, line=line)
        if not isinstance(cue["value"], str):
            raise TimelineError(f"mouth cue value {cue['value']!r} is not a string", path=path, line=line)
        rows.append((json_time(cue["start"], path, line, "start"), json_time(cue["end"], path, line, "end"),
                     cue["value"], line))
    duration: Optional[float] = None
    meta = doc.get("metadata")
    if isinstance(meta, dict) and isinstance(meta.get("duration"), (int, float)) \
            and not isinstance(meta.get("duration"), bool):
        duration = json_time(meta["duration"], path, 1, "duration")  # float() overflowed on 10**400 (fuzzing)
    return build(path, rows, VISEME, stated_end=duration)


def read_xml(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read Rhubarb's XML output (line numbers from expat)."""
    from xml.parsers import expat

    text = decode_text(path, data)
    parser = expat.ParserCreate()
    cues = []
    state = {"cue": None, "duration": None, "in_duration": False, "buf": []}

    def start(name, attrs):
        if name == "mouthCue":
            state["cue"] = (attrs, parser.CurrentLineNumber)
            state["buf"] = []
        elif name == "duration":
            state["in_duration"] = True
            state["buf"] = []

    def end(name):
        if name == "mouthCue" and state["cue"] is not None:
            attrs, line = state["cue"]
            cues.append((attrs, "".join(state["buf"]).strip(), line))
            state["cue"] = None
        elif name == "duration":
            state["in_duration"] = False
            state["duration"] = ("".join(state["buf"]).strip(), parser.CurrentLineNumber)

    def chars(s):
        state["buf"].append(s)

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = chars
    # Entity declarations are refused so that no document can expand into gigabytes.
    parser.EntityDeclHandler = _refuse_entities
    try:
        parser.Parse(text, True)
    except expat.ExpatError as exc:
        raise TimelineError(f"not valid XML ({expat.errors.messages.get(exc.code, exc)})",
                            path=path, line=exc.lineno) from None
    except _EntityRefused:
        raise TimelineError("XML entity declarations are not allowed", path=path,
                            line=parser.CurrentLineNumber) from None
    if not cues:
        raise TimelineError("no <mouthCue> elements: not Rhubarb XML output", path=path, line=1)
    rows = []
    for attrs, label, line in cues:
        if "start" not in attrs or "end" not in attrs:
            raise TimelineError('a <mouthCue> needs "start" and "end" attributes', path=path, line=line)
        rows.append((parse_number(attrs["start"], path, line, "start"),
                     parse_number(attrs["end"], path, line, "end"), label, line))
    duration = None
    if state["duration"] is not None:
        duration = parse_number(state["duration"][0], path, state["duration"][1], "duration")
    return build(path, rows, VISEME, stated_end=duration)


class _EntityRefused(Exception):
    pass


def _refuse_entities(*args):
    raise _EntityRefused()


def _sniff_tsv(head: bytes) -> bool:
    return bool(_TSV_ROW.fullmatch(first_nonblank(sniff_text(head))[1]))


def _sniff_json(head: bytes) -> bool:
    text = sniff_text(head).lstrip()
    return text.startswith("{") and '"mouthCues"' in text


def _sniff_xml(head: bytes) -> bool:
    text = sniff_text(head).lstrip()
    return text.startswith("<") and ("<rhubarbResult" in text or "<mouthCues" in text)


READERS.register("rhubarb-tsv", Reader("rhubarb-tsv", read_tsv, _sniff_tsv, "Rhubarb Lip Sync TSV"),
                 extensions=(".tsv",), aliases=("tsv",))
READERS.register("rhubarb-json", Reader("rhubarb-json", read_json, _sniff_json, "Rhubarb Lip Sync JSON"),
                 extensions=(".json",))
READERS.register("rhubarb-xml", Reader("rhubarb-xml", read_xml, _sniff_xml, "Rhubarb Lip Sync XML"),
                 extensions=(".xml",), aliases=("xml",))
