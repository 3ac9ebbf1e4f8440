"""Praat TextGrid (long text form) with one interval tier of visemes (default ``visemes``).

The tier spans ``[0, duration]`` with no holes, as Praat requires: every cue is an
interval, and any time not covered would be an empty interval. Times are written with
``repr`` precision, so a TextGrid reads back exactly. praatio and Praat read the result; our
TextGrid reader picks a ``visemes`` tier when the file has no phones tier and reads it as
visemes.
"""

from __future__ import annotations

from typing import List, Sequence

from .base import WRITERS, Cue, CueOptions, Writer


def _q(text: str) -> str:
    # Praat doubles a quote inside a string.
    return '"' + text.replace('"', '""') + '"'


def _n(x: float) -> str:
    return repr(float(x)) if x != int(x) else str(int(x))


def render(cues: Sequence[Cue], options: CueOptions) -> str:
    """A long-form TextGrid with one IntervalTier named ``options.tier``."""
    end = options.duration
    out: List[str] = [
        'File type = "ooTextFile"',
        'Object class = "TextGrid"',
        "",
        "xmin = 0",
        f"xmax = {_n(end)}",
        "tiers? <exists>",
        "size = 1",
        "item []:",
        "    item [1]:",
        '        class = "IntervalTier"',
        f"        name = {_q(options.tier)}",
        "        xmin = 0",
        f"        xmax = {_n(end)}",
        f"        intervals: size = {len(cues)}",
    ]
    for i, (a, b, v) in enumerate(cues, 1):
        out += [f"        intervals [{i}]:",
                f"            xmin = {_n(a)}",
                f"            xmax = {_n(b)}",
                f"            text = {_q(options.names.get(v, v))}"]
    return "\n".join(out) + "\n"


WRITERS.register("textgrid", Writer("textgrid", render, "Praat TextGrid (long form, one visemes tier)",
                                    resolution=1e-12),
                 extensions=(".textgrid",), aliases=("praat",))
