"""What every cue writer shares: the cue type, the writers' options, :class:`Writer` and the
:data:`WRITERS` registry (each writer module registers itself; :mod:`lipsync.writers`
imports them all). Separate from the package so that the writer modules import it and the
package imports them, and nothing imports in a circle.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Callable, FrozenSet, Mapping, Optional, Sequence, Tuple, Union

from ..registry import Registry
from ..motion.timing import DEFAULT_CURVE

PathLike = Union[str, "os.PathLike[str]"]

Cue = Tuple[float, float, str]

#: Moho's own default, and Rhubarb's ``--datFrameRate`` default.
DEFAULT_FPS = 24.0

#: Tier name of the TextGrid writer (the TextGrid reader picks it when there is no phones tier).
DEFAULT_TIER = "visemes"


@dataclass(frozen=True)
class CueOptions:
    """What a writer may need besides the cues (one frozen config, passed keyword-only).

    Parameters
    ----------
    duration : float
        End of the track in seconds (the last cue's end).
    rest : str
        The rest (silence) viseme: Rhubarb and Moho files end with it.
    fps : float
        Frame rate of Moho switch files (frames are 1-based).
    tier : str
        TextGrid tier name.
    sound_file : str, optional
        The recording the cues belong to (Rhubarb's ``metadata.soundFile``).
    names : mapping
        Viseme -> name written, for formats with their own names (Moho: Preston Blair).
    closures : frozenset
        Visemes that must be shown however short (the map's closures): Moho keys them first
        when cues share a frame.
    timing : str or DominanceParams
        How the mouth moves (formats holding frames, the atlas frames): what
        :func:`lipsync.motion.sequencer.sequence` takes as ``timing``.
    timeline : Timeline, optional
        The viseme timeline the cues were planned from (formats holding frames sequence it
        as ``render`` does; default: the cues themselves).
    classes : mapping, optional
        Viseme -> articulatory class, for the dominance timing model.
    atlas : Atlas, optional
        The sprite atlas whose cells the atlas frames name (:mod:`lipsync.atlas`).
    output : str, optional
        The file being written (formats that name other files relative to it).
    """

    duration: float
    rest: str = "X"
    fps: float = DEFAULT_FPS
    tier: str = DEFAULT_TIER
    sound_file: Optional[str] = None
    names: Mapping[str, str] = field(default_factory=dict)
    closures: FrozenSet[str] = frozenset()
    timing: object = DEFAULT_CURVE
    timeline: Optional[object] = None
    classes: Optional[Mapping[str, str]] = None
    atlas: Optional[object] = None
    output: Optional[str] = None


@dataclass(frozen=True)
class Writer:
    """A mouth-cue file format: ``render(cues, options) -> str`` (the whole file's text)."""

    name: str
    render: Callable[[Sequence[Cue], CueOptions], str]
    description: str = ""
    #: How close a read-back time is to the written one (seconds): the format's precision.
    resolution: float = 1e-3


WRITERS: Registry[Writer] = Registry("cue format")
