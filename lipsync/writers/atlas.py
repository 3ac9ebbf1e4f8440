"""Atlas frames (``frames.json``): the sprite-atlas cell of every frame at ``fps``.

The frames are the sequencer's: :func:`lipsync.motion.sequencer.sequence` of the viseme timeline
the cues were planned from (``options.timeline``, else the cue track), with the timing,
closures and classes ``render`` uses, so exactly the FrameSpecs ``lipsync render`` draws;
each becomes the nearest cell of the atlas (:mod:`lipsync.atlas.frames`). The document is
described in :mod:`lipsync.atlas.schema`. No extension picks this format (``.json`` is
Rhubarb's): name it with ``--format atlas``.
"""

from __future__ import annotations

import os
import warnings
from typing import Sequence

from ..errors import InputError
from .base import WRITERS, Cue, CueOptions, Writer


def render(cues: Sequence[Cue], options: CueOptions) -> str:
    """The frames.json text for a planned cue track."""
    from ..atlas.frames import quantise
    from ..atlas.schema import Atlas, frames_document
    from ..motion.sequencer import sequence
    from ..motion.timeline import VISEME, Segment, Timeline

    atlas = options.atlas
    if not isinstance(atlas, Atlas):
        raise InputError("the atlas format needs the atlas: --atlas ATLAS.json (written by `lipsync atlas`)")
    timeline = options.timeline
    if timeline is None:
        timeline = Timeline(tuple(Segment(a, b, v) for a, b, v in cues), kind=VISEME)
    unknown = sorted({s.label for s in timeline} - set(atlas.visemes))
    if unknown:
        raise InputError(f"visemes not in the atlas: {', '.join(unknown)} (atlas has: {', '.join(atlas.visemes)})",
                         path=atlas.path)
    specs = sequence(timeline, fps=options.fps, rest=options.rest, timing=options.timing,
                     closures=options.closures, classes=options.classes, duration=options.duration)
    cells, missing = quantise(atlas, specs)
    if missing:
        warnings.warn(f"{len(missing)} transition(s) are not in the atlas ({', '.join(f'{a}->{b}' for a, b in missing[:6])}"
                      f"{', ...' if len(missing) > 6 else ''}): those frames show the nearer viseme; build the atlas "
                      f"with this timeline (`lipsync atlas BANK -o ... TIMELINE`) or --pairs all", stacklevel=3)
    ref = atlas.path or "atlas.json"
    if options.output is not None and atlas.path is not None:
        ref = os.path.relpath(os.path.abspath(atlas.path), os.path.dirname(os.path.abspath(options.output)))
    return frames_document(ref.replace(os.sep, "/"), float(options.fps), options.duration, cells, missing)


WRITERS.register("atlas", Writer("atlas", render, "sprite-atlas cell of every frame (lipsync atlas)",
                                 resolution=1e-6), aliases=("atlas-frames",))
