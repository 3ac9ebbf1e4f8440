"""What every timing model produces and starts from: frames, and the plain viseme track.

Both timing models (the rule-based sequencer, :mod:`lipsync.motion.sequencer`, and the dominance
model, :mod:`lipsync.motion.coarticulation`) give one :class:`FrameSpec` per output frame, frame n
showing time ``n / fps``, and both start from the same track (:func:`base_track`: the
sequencer's rules 1 and 2). They live here, below both, so that neither imports the other
for them.

Examples
--------
>>> from lipsync.motion.timeline import Segment, Timeline
>>> base_track(Timeline((Segment(0.2, 0.5, "A"), Segment(0.5, 0.6, "A")), kind="viseme"), rest="X", duration=1.0)
[Segment(start=0.0, end=0.2, label='X'), Segment(start=0.2, end=0.6, label='A'), Segment(start=0.6, end=1.0, label='X')]
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Tuple

from ..errors import InputError
from .timeline import MAX_TIMELINE_S, VISEME, Segment, Timeline

#: Most frames one timeline may make: 11 hours at 25 fps, longer than any speech track, and
#: bounded so that a wrong number in a file (frame 10^9) is an error, not gigabytes of frames.
MAX_FRAMES = 1_000_000

FPS_RANGE = (1.0, 120.0)
#: The output frame rate when none is given, one value for every command and API that makes
#: frames (``lipsync render``, ``timeline --frames``, ``serve``, ``batch``, the animators), so
#: the schedule ``timeline --frames`` prints is the one ``render`` renders. 25 fps is PAL
#: video's rate and enough for lips (Rhubarb needs >= 24 for hard cuts; morphs look smooth
#: well below that, so lower rates are allowed).
DEFAULT_FPS = 25.0


@dataclass(frozen=True)
class FrameSpec:
    """What one output frame shows: ``from_viseme`` morphed toward ``to_viseme`` by ``alpha``.

    Examples
    --------
    >>> FrameSpec("A", "D", 0.25).alpha
    0.25
    """

    from_viseme: str
    to_viseme: str
    alpha: float

    @property
    def is_still(self) -> bool:
        """True when the frame is exactly one viseme (no morph needed)."""
        return self.from_viseme == self.to_viseme or self.alpha <= 0.0 or self.alpha >= 1.0

    @property
    def shown(self) -> Optional[str]:
        """The viseme shown exactly, or None for an in-between frame."""
        if self.from_viseme == self.to_viseme or self.alpha <= 0.0:
            return self.from_viseme
        if self.alpha >= 1.0:
            return self.to_viseme
        return None


def frame_count(duration: float, fps: float) -> int:
    """Number of frames for ``duration`` seconds: ``ceil(duration * fps)``.

    Examples
    --------
    >>> frame_count(1.0, 24), frame_count(1.01, 24), frame_count(0.0, 24)
    (24, 25, 0)
    """
    # Times like 1.358685 s * 25 fps carry float noise; a product within 1e-9 of an integer
    # is that integer, so a 2.0 s timeline never gets a 49th frame at 24 fps.
    if not duration <= MAX_TIMELINE_S:  # also NaN; an infinite product cannot become an int
        raise InputError(f"duration {duration:g} s is not within the limit of {MAX_TIMELINE_S:g} s (24 hours)")
    return max(0, int(math.ceil(duration * fps - 1e-9)))


def check_fps(fps: float) -> float:
    """``fps`` as a float if within FPS_RANGE, else InputError."""
    try:
        value = float(fps)
    except (TypeError, ValueError):
        raise InputError(f"frame rate must be a number, not {fps!r}") from None
    if not (FPS_RANGE[0] <= value <= FPS_RANGE[1]):
        raise InputError(f"frame rate {fps!r} is outside {FPS_RANGE[0]:g}..{FPS_RANGE[1]:g}")
    return value


def checked_frames(visemes: Timeline, fps: float, duration: Optional[float] = None) -> Tuple[float, float, int]:
    """``(fps, duration, frame count)`` of a viseme timeline to sequence, or InputError.

    Examples
    --------
    >>> checked_frames(Timeline((Segment(0, 1.01, "A"),), kind="viseme"), 24)
    (24.0, 1.01, 25)
    """
    fps = check_fps(fps)
    if not isinstance(visemes, Timeline):
        raise InputError("sequence() needs a Timeline")
    if visemes.kind != VISEME:
        raise InputError("sequence() needs a viseme timeline; map the phonemes first (map_timeline)",
                         path=visemes.path)
    total = visemes.duration if duration is None else float(duration)
    n_frames = frame_count(total, fps)
    if n_frames > MAX_FRAMES:  # found with the fuzz tests' huge numbers: Moho frame 10**9 asked for 7.8 GB here
        raise InputError(f"the timeline lasts {total:g} s: {n_frames} frames at {fps:g} fps, above the "
                         f"limit of {MAX_FRAMES} (a time or frame number in the file is likely wrong)",
                         path=visemes.path)
    return fps, total, n_frames


def base_track(visemes: Timeline, *, rest: str, duration: Optional[float] = None, start: float = 0.0
               ) -> List[Segment]:
    """The sequencer's rules 1 and 2: gaps are rest, adjacent equal visemes merge; the track
    covers ``[start, duration]`` (``start`` is where the live animator's window begins)."""
    total = visemes.duration if duration is None else float(duration)
    segs: List[Segment] = []
    t = float(start)
    for s in visemes:
        if s.start > total:
            break
        if s.start > t:
            segs.append(Segment(t, s.start, rest))
        segs.append(Segment(max(s.start, t), min(s.end, total), s.label))
        t = min(s.end, total)
    if t < total:
        segs.append(Segment(t, total, rest))
    return merge([s for s in segs if s.duration > 0])


def merge(segs: List[Segment]) -> List[Segment]:
    """Rule 2: adjacent equal visemes merge into one segment."""
    out: List[Segment] = []
    for s in segs:
        if out and out[-1].label == s.label:
            out[-1] = Segment(out[-1].start, s.end, s.label)
        else:
            out.append(s)
    return out
