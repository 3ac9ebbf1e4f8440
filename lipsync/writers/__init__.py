"""Mouth-cue writers: a viseme track in the formats other lip-sync tools read.

The counterpart of :mod:`lipsync.readers`: one module per file format, each registering a
:class:`Writer` in :data:`WRITERS` (explicit name first, then the output's extension, as for
the readers). Every writer turns a cue track -- contiguous ``(start, end, viseme)`` cues
covering ``[0, duration]`` -- into text; :func:`write_cues` checks the track once and writes
the file atomically (temporary file in the same folder, then rename), so a failure never
leaves a half-written file.

Round trip: :func:`lipsync.readers.read_timeline` reads every file written here back cue
for cue (times to the precision each format stores; Moho to whole frames).

Examples
--------
>>> import os, tempfile
>>> from lipsync.motion.timeline import Segment, Timeline
>>> from lipsync.readers import read_timeline
>>> cues = Timeline((Segment(0, 0.2, "X"), Segment(0.2, 0.5, "A"), Segment(0.5, 0.8, "X")), kind="viseme")
>>> out = os.path.join(tempfile.mkdtemp(), "cues.tsv")
>>> write_cues(cues, out)
'rhubarb-tsv'
>>> open(out).read().splitlines()
['0.000\\tX', '0.200\\tA', '0.500\\tX', '0.800\\tX']
>>> read_timeline(out).labels()
['X', 'A', 'X']
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable, List, Mapping, Optional, Sequence, Tuple, Union

from ..errors import InputError
from ..motion.timeline import MAX_TIMELINE_S, Segment, Timeline
from ..motion.timing import DEFAULT_CURVE
from .base import DEFAULT_FPS, DEFAULT_TIER, WRITERS, Cue, CueOptions, PathLike, Writer

__all__ = ["DEFAULT_FPS", "DEFAULT_TIER", "WRITERS", "Cue", "CueOptions", "Writer", "cue_track", "format_for",
           "write_cues"]


def cue_track(cues: Union[Timeline, Sequence[Cue]], *, rest: str,
              duration: Optional[float] = None) -> Tuple[List[Cue], float]:
    """Contiguous cues covering ``[0, duration]``: gaps become ``rest``, empty cues go.

    Parameters
    ----------
    cues : Timeline or sequence of (start, end, viseme)
        Sorted, non-overlapping (a :class:`~lipsync.motion.timeline.Timeline` guarantees it).
    rest : str
        Viseme for gaps.
    duration : float, optional
        End of the track (default: the timeline's duration, or the last cue's end).

    Examples
    --------
    >>> cue_track([(0.1, 0.3, "A")], rest="X", duration=0.5)
    ([(0.0, 0.1, 'X'), (0.1, 0.3, 'A'), (0.3, 0.5, 'X')], 0.5)
    """
    if isinstance(cues, Timeline):
        total = cues.duration if duration is None else float(duration)
        rows = [(s.start, s.end, s.label) for s in cues]
    else:
        rows = [(float(a), float(b), str(v)) for a, b, v in cues]
        # Timeline checks order, overlap and finiteness once for both kinds of input.
        Timeline(tuple(Segment(a, b, v) for a, b, v in rows), kind="viseme")
        total = (rows[-1][1] if rows else 0.0) if duration is None else float(duration)
    if not 0 <= total <= MAX_TIMELINE_S:  # NaN and infinities fail too
        raise InputError(f"cue track duration {total!r} is not a number of seconds within 0..{MAX_TIMELINE_S:g}")
    out: List[Cue] = []
    t = 0.0
    for start, end, label in rows:
        if start >= total:
            break
        end = min(end, total)
        if start > t:
            out.append((t, start, rest))
        if end > start:
            out.append((start, end, label))
        t = max(t, end)
    if t < total:
        out.append((t, total, rest))
    return out, total


def format_for(path: PathLike) -> str:
    """The writer name for an output path's extension, or InputError listing the formats.

    Examples
    --------
    >>> format_for("cues.json"), format_for("song.DAT"), format_for("a.TextGrid")
    ('rhubarb-json', 'moho', 'textgrid')
    """
    ext = Path(os.fspath(path)).suffix
    name = WRITERS.name_for_extension(ext)
    if name is None:
        raise InputError(f"cannot tell the cue format from the extension {ext or '(none)'!r}; "
                         f"give --format (valid: {', '.join(WRITERS.names())})", path=os.fspath(path))
    return name


def write_cues(cues: Union[Timeline, Sequence[Cue]], path: PathLike, format: Optional[str] = None, *,
               rest: str = "X", fps: float = DEFAULT_FPS, tier: str = DEFAULT_TIER,
               sound_file: Optional[str] = None, names: Optional[Mapping[str, str]] = None,
               closures: Iterable[str] = (), duration: Optional[float] = None, timing=DEFAULT_CURVE,
               timeline: Optional[Timeline] = None, classes: Optional[Mapping[str, str]] = None,
               atlas=None) -> str:
    """Write a viseme track as mouth cues; returns the format name used.

    Parameters
    ----------
    cues : Timeline or sequence of (start, end, viseme)
        The track (gaps are written as ``rest``).
    path : path-like
        Output file, written atomically (temporary file, then rename).
    format : str, optional
        A name from ``WRITERS.names()``; default: from the extension of ``path``.
    rest : str
        The rest viseme (Rhubarb's X).
    fps : float
        Frame rate of Moho ``.dat`` files.
    tier : str
        TextGrid tier name.
    sound_file : str, optional
        The recording, named in Rhubarb's JSON and XML metadata.
    names : mapping, optional
        Viseme -> name written (Moho: Preston Blair names); unmapped visemes keep their name.
    closures : iterable of str
        Visemes shown however short (closed lips); Moho gives them a key first.
    duration : float, optional
        End of the track (default: the timeline's duration).
    timing : str or DominanceParams
        How the mouth moves, as :func:`lipsync.motion.sequencer.sequence` takes it (the atlas
        frames are the sequencer's frames).
    timeline : Timeline, optional
        The viseme timeline the cues were planned from (the atlas frames sequence it, as
        ``render`` does; default: the cues).
    classes : mapping, optional
        Viseme -> class, for the dominance timing model
        (:func:`lipsync.motion.coarticulation.viseme_classes`).
    atlas : Atlas, optional
        For ``atlas``: the sprite atlas (:func:`lipsync.atlas.load_atlas`) whose cells the
        frames name.

    Returns
    -------
    str
        The writer's name.

    Raises
    ------
    InputError
        Unknown format or extension, a frame rate out of range, or visemes the format cannot
        name (Rhubarb's formats take A-H and X only).

    Examples
    --------
    >>> import os, tempfile
    >>> out = os.path.join(tempfile.mkdtemp(), "cues.dat")
    >>> write_cues([(0, 0.5, "A"), (0.5, 1.0, "D")], out, fps=4, names={"A": "MBP", "D": "AI", "X": "rest"})
    'moho'
    >>> print(open(out).read(), end="")
    MohoSwitch1
    1 MBP
    3 AI
    5 rest
    """
    from .._files import atomic_write_bytes

    name = format_for(path) if format is None else format
    writer = WRITERS.get(name)
    if fps is None or not (0 < float(fps) < float("inf")):
        raise InputError(f"frame rate must be a positive number, not {fps!r}")
    track, total = cue_track(cues, rest=rest, duration=duration)
    options = CueOptions(duration=total, rest=rest, fps=float(fps), tier=tier, sound_file=sound_file,
                         names=dict(names or {}), closures=frozenset(closures), timing=timing, timeline=timeline,
                         classes=_copy_classes(classes), atlas=atlas,
                         output=os.fspath(path))
    text = writer.render(track, options)
    data = text.encode("utf-8")
    atomic_write_bytes(Path(os.fspath(path)), lambda fh: fh.write(data))
    return writer.name


def _copy_classes(classes):
    # A copy the caller cannot change under the writer; a map's VisemeClasses keeps its
    # breath viseme (the dominance model shows it before speech).
    if classes is None:
        return None
    from ..motion.coarticulation import VisemeClasses

    return VisemeClasses(classes, breath=getattr(classes, "breath", None))


# Each writer module registers itself in WRITERS (lipsync.writers.base).
from . import rhubarb, moho, textgrid, audacity, atlas  # noqa: E402,F401  (registration order = --format choices)
