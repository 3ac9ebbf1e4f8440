"""Rhubarb Lip Sync's three output formats, with its field names and structure.

* TSV: ``start<TAB>shape`` per cue, then the end of the recording with the rest shape X
  (Rhubarb's last line marks the end and has no length).
* JSON: ``{"metadata": {"soundFile", "duration"}, "mouthCues": [{"start", "end", "value"}]}``,
  one cue per line as Rhubarb prints them.
* XML: ``<rhubarbResult><metadata><soundFile/><duration/></metadata><mouthCues>`` with
  ``<mouthCue start=".." end="..">A</mouthCue>`` elements.

Shapes are Rhubarb's: the six basic A-F, the extended G, H and X. Rhubarb prints times with
two decimals because it works in centiseconds; lipsync's cues are not on that grid, so
times are written to the millisecond (every Rhubarb consumer parses them as decimals).
"""

from __future__ import annotations

import json
from typing import Sequence
from xml.sax.saxutils import escape, quoteattr

from ..errors import InputError
from .base import WRITERS, Cue, CueOptions, Writer

SHAPES = ("A", "B", "C", "D", "E", "F", "G", "H", "X")

#: ``--shapes``: which of Rhubarb's shapes a track may use, and what the others become.
#: Rhubarb's own fallbacks (its ``getBasicShape``: G -> B, H -> C), kept for those who draw
#: only the basic shapes A-F (and X, the idle mouth; Rhubarb's ``--extendedShapes X``).
SHAPE_SETS = {
    "all": {},                       # A-H and X, as drawn for the default map
    "basic": {"G": "B", "H": "C"},   # F/V's teeth on lip -> clenched teeth; L's tongue -> open
}


def basic_shapes_track(timeline, pmap, base, shapes: str):
    """A viseme timeline with only the shapes of ``shapes`` (a :data:`SHAPE_SETS` name).

    ``timeline`` and ``pmap`` are in the bank's viseme names (as
    :func:`lipsync.cli._common.load_viseme_timeline` returns them), ``base`` the map as
    loaded, in its own names (Rhubarb's letters): the fallbacks are found in the bank's names
    through the phones both maps send to each viseme.

    Examples
    --------
    >>> from lipsync.phonetics.phonemes import load_map
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> m = load_map("rhubarb")
    >>> tl = Timeline((Segment(0, 1, "G"), Segment(1, 2, "H"), Segment(2, 3, "D")), kind="viseme")
    >>> basic_shapes_track(tl, m, m, "basic").labels()
    ['B', 'C', 'D']
    """
    fallbacks = SHAPE_SETS.get(shapes)
    if fallbacks is None:
        raise InputError(f"--shapes {shapes!r}: one of {', '.join(SHAPE_SETS)}")
    if not fallbacks:
        return timeline
    if not set(SHAPES) <= set(base.visemes()):
        raise InputError(f"--shapes {shapes} keeps to Rhubarb's shapes A-F: the map {base.name!r} has other "
                         f"visemes ({', '.join(base.visemes())}); use the default map (english-to-rhubarb)")
    rename = {base.silence: pmap.silence, base.fallback: pmap.fallback}
    for phone in base.map:
        rename.update(zip(base.targets(phone), pmap.targets(phone)))
    table = {rename.get(a, a): rename.get(b, b) for a, b in fallbacks.items()}
    segments = tuple(type(seg)(seg.start, seg.end, table.get(seg.label, seg.label)) for seg in timeline)
    return timeline.replace(segments=segments)

# Milliseconds: the finest step a 1000 fps clock shows, and finer than any frame rate.
_DECIMALS = 3


def _t(x: float) -> str:
    return f"{x:.{_DECIMALS}f}"


def _shapes(cues: Sequence[Cue], options: CueOptions, fmt: str) -> Sequence[Cue]:
    out = [(a, b, options.names.get(v, v)) for a, b, v in cues]
    rest = options.names.get(options.rest, options.rest)
    bad = sorted({v for _, _, v in out} - set(SHAPES)) or ([rest] if rest not in SHAPES else [])
    if bad:
        raise InputError(f"{fmt} writes Rhubarb's mouth shapes {', '.join(SHAPES)}; these cues use "
                         f"{', '.join(bad)} (use a map whose visemes are Rhubarb's, e.g. --map rhubarb, "
                         "or another cue format)")
    return out


def render_tsv(cues: Sequence[Cue], options: CueOptions) -> str:
    """Rhubarb TSV: each cue's start and shape, then the end with X."""
    cues = _shapes(cues, options, "rhubarb-tsv")
    lines = [f"{_t(a)}\t{v}" for a, _, v in cues]
    lines.append(f"{_t(options.duration)}\tX")
    return "\n".join(lines) + "\n"


def render_json(cues: Sequence[Cue], options: CueOptions) -> str:
    """Rhubarb JSON, laid out as Rhubarb prints it."""
    cues = _shapes(cues, options, "rhubarb-json")
    rows = ",\n".join(f'    {{ "start": {_t(a)}, "end": {_t(b)}, "value": {json.dumps(v)} }}' for a, b, v in cues)
    return ("{\n"
            '  "metadata": {\n'
            f'    "soundFile": {json.dumps(options.sound_file or "")},\n'
            f'    "duration": {_t(options.duration)}\n'
            "  },\n"
            '  "mouthCues": [\n'
            + (rows + "\n" if rows else "")
            + "  ]\n"
            "}\n")


def render_xml(cues: Sequence[Cue], options: CueOptions) -> str:
    """Rhubarb XML, laid out as Rhubarb prints it."""
    cues = _shapes(cues, options, "rhubarb-xml")
    rows = "".join(f"    <mouthCue start={quoteattr(_t(a))} end={quoteattr(_t(b))}>{escape(v)}</mouthCue>\n"
                   for a, b, v in cues)
    return ('<?xml version="1.0" encoding="utf-8"?>\n'
            "<rhubarbResult>\n"
            "  <metadata>\n"
            f"    <soundFile>{escape(options.sound_file or '')}</soundFile>\n"
            f"    <duration>{_t(options.duration)}</duration>\n"
            "  </metadata>\n"
            "  <mouthCues>\n"
            + rows
            + "  </mouthCues>\n"
            "</rhubarbResult>\n")


WRITERS.register("rhubarb-tsv", Writer("rhubarb-tsv", render_tsv, "Rhubarb Lip Sync TSV"),
                 extensions=(".tsv",), aliases=("tsv",))
WRITERS.register("rhubarb-json", Writer("rhubarb-json", render_json, "Rhubarb Lip Sync JSON"),
                 extensions=(".json",), aliases=("json",))
WRITERS.register("rhubarb-xml", Writer("rhubarb-xml", render_xml, "Rhubarb Lip Sync XML"),
                 extensions=(".xml",), aliases=("xml",))
