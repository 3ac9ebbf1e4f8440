"""Moho (Anime Studio) switch data ``.dat``: ``MohoSwitch1``, then ``frame name`` keys.

Frames are 1-based at ``options.fps``: a cue starting at ``t`` seconds is keyed at frame
``1 + round(t * fps)``, and each key holds until the next. After the last cue a key with
the rest shape marks the end of the recording, as Rhubarb and Papagayo write it (the
reader shows that key for one frame). Names come from ``options.names`` (the map's
Preston Blair aliases: MBP, etc, E, AI, O, U, FV, L, rest), else the viseme's own name.

Quantisation: every boundary moves to the nearest frame (at most half a frame). A frame
shows one shape, so when two cues start on the same frame (cues shorter than a frame):

* the longer one takes the frame, being the one a viewer would see, unless the shorter
  is a closure (``options.closures``: closed lips for P, B, M), which always keeps its
  key, as the sequencer always shows closures;
* a cue that loses the frame moves to the next one if that still starts inside the cue,
  and is dropped otherwise (a closure is never dropped).
"""

from __future__ import annotations

import math
from typing import List, Sequence

from ..errors import InputError
from ..readers.moho import MAGIC
from .base import WRITERS, Cue, CueOptions, Writer

# Float noise in t * fps (0.1 * 30 = 3.0000000000000004) must not move a key by a frame.
_FRAME_EPS = 1e-6


def frame_of(t: float, fps: float) -> int:
    """The 1-based frame whose start is nearest ``t`` (halves round up).

    Examples
    --------
    >>> frame_of(0.0, 24), frame_of(0.5, 24), frame_of(0.02, 24), frame_of(0.021, 24)
    (1, 13, 1, 2)
    """
    return 1 + int(math.floor(t * fps + 0.5 + _FRAME_EPS))


def render(cues: Sequence[Cue], options: CueOptions) -> str:
    """Moho switch keys at ``options.fps``, ending with a rest key."""
    for name in {options.names.get(v, v) for _, _, v in cues} | {options.names.get(options.rest, options.rest)}:
        if not name or any(c.isspace() for c in name):
            raise InputError(f"moho: a switch name cannot be empty or contain spaces: {name!r}")
    keys: List[List] = []  # [frame, cue], frames increasing
    for cue in cues:
        f = frame_of(cue[0], options.fps)
        closure = cue[2] in options.closures
        if keys and f <= keys[-1][0]:
            prev = keys[-1][1]
            if prev[2] not in options.closures and cue[1] - cue[0] > prev[1] - prev[0]:
                keys[-1][1] = cue  # the longer cue takes the shared frame
                continue
            f = keys[-1][0] + 1
            if not closure and (f - 1) / options.fps >= cue[1] - _FRAME_EPS:
                continue  # no frame of its own starts inside it
        keys.append([f, cue])
    lines: List[str] = [MAGIC]
    last_name = None
    for f, cue in keys:
        name = options.names.get(cue[2], cue[2])
        if name != last_name:  # the previous key already shows it
            lines.append(f"{f} {name}")
            last_name = name
    end = frame_of(options.duration, options.fps)
    last_frame = keys[-1][0] if keys else 0
    lines.append(f"{max(end, last_frame + 1)} {options.names.get(options.rest, options.rest)}")
    return "\n".join(lines) + "\n"


WRITERS.register("moho", Writer("moho", render, "Moho/Papagayo switch data (MohoSwitch1)"),
                 extensions=(".dat",), aliases=("dat", "papagayo"))
