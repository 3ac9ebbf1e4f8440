"""Audacity label track: ``start<TAB>end<TAB>label`` per cue, times in seconds.

Audacity prints label times with six decimals (``%f``); so does this writer. Every cue,
rest included, is a region label, so File > Import > Labels shows the whole track.
"""

from __future__ import annotations

from typing import Sequence

from ..errors import InputError
from .base import WRITERS, Cue, CueOptions, Writer


def render(cues: Sequence[Cue], options: CueOptions) -> str:
    """One region label per cue."""
    lines = []
    for a, b, v in cues:
        name = options.names.get(v, v)
        if "\t" in name or "\n" in name or "\r" in name:
            raise InputError(f"audacity: a label cannot contain a tab or line break: {name!r}")
        lines.append(f"{a:.6f}\t{b:.6f}\t{name}")
    return "\n".join(lines) + ("\n" if lines else "")


WRITERS.register("audacity", Writer("audacity", render, "Audacity label track", resolution=1e-6),
                 extensions=(".txt", ".labels"), aliases=("labels",))
