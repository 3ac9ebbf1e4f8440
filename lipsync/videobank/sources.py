"""Step 1: the videos given, each with its transcript, checked before any long work.

A transcript comes from ``--text`` (only when one video is given: one text cannot be the
words of several), else from ``NAME.txt`` or ``NAME.lab`` beside ``NAME.<ext>`` (the
convention of forced aligners such as MFA), else the words are recognised.

Examples
--------
>>> find_sources(["no-such.mp4"])
Traceback (most recent call last):
...
lipsync.errors.InputError: no-such.mp4: no such file
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import List, Mapping, Optional, Sequence

from ..errors import InputError, PathLike
from ..face.video import VideoInfo, probe_video

#: Transcript files looked for beside a video, in this order (MFA's ``.lab``, plain ``.txt``).
TRANSCRIPT_SUFFIXES = (".txt", ".lab")

#: Frames looked at to tell which way up the face is: every 10th of the first 80 (3.2 s at
#: 25 fps, where a recording's speaker is already in view), 8 frames x 4 turns ~ 0.3 s.
UPRIGHT_EVERY, UPRIGHT_FRAMES = 10, 80
#: The face detector (BlazeFace) scores a face turned from upright lower: on the GRID s1
#: clips (3 clips x 7 frames) medians 0.95-0.96 upright, 0.84-0.91 turned a quarter, 0.58-0.72
#: upside down. A turn is taken when its median beats every other turn's by this much; a
#: closer race is reported rather than guessed.
UPRIGHT_MARGIN = 0.03
#: Below this median score no turn shows a face: left to the tracker to report.
UPRIGHT_MIN_SCORE = 0.5


@dataclass(frozen=True)
class Source:
    """One video and where its words come from.

    Attributes
    ----------
    path : Path
    info : VideoInfo
    text : str or None
        The transcript; None: the words are recognised.
    text_from : str
        ``"--text"``, the transcript file's name, or ``"recognised"`` (for the report).
    """

    path: Path
    info: VideoInfo
    text: Optional[str]
    text_from: str

    @property
    def name(self) -> str:
        return self.path.name


def transcript_beside(video: Path) -> Optional[Path]:
    """``NAME.txt`` or ``NAME.lab`` beside ``video``, if there is one."""
    for suffix in TRANSCRIPT_SUFFIXES:
        p = video.with_suffix(suffix)
        if p.is_file():
            return p
    return None


def find_sources(videos: Sequence[PathLike], text: Optional[str] = None, *,
                 texts: Optional[Mapping[PathLike, str]] = None) -> List[Source]:
    """Probe every video and find its transcript.

    Parameters
    ----------
    videos : sequence of path-like
    text : str, optional
        ``--text``: a transcript or a file holding it, for a single video.
    texts : mapping, optional
        Video (as given in ``videos``) → its transcript, for callers that have them in hand
        (a corpus's own transcripts); these come before files beside the videos.

    Returns
    -------
    list of Source

    Raises
    ------
    InputError
        No videos, a video given twice, ``text`` with several videos, a file that is not a
        video, a video without an audio stream, an unreadable transcript.
    """
    from ..speech.align import read_transcript

    if not videos:
        raise InputError("--video needs at least one video file")
    paths = [Path(os.fspath(v)) for v in videos]
    seen = {}
    for p in paths:
        key = p.resolve()
        if key in seen:
            raise InputError(f"given twice (also as {seen[key]})", path=p)
        seen[key] = p
    if text is not None and len(paths) > 1:
        raise InputError("--text gives the words of one video; with several videos put each one's "
                         "transcript beside it as NAME.txt or NAME.lab")
    given = {Path(os.fspath(k)).resolve(): v for k, v in (texts or {}).items()}
    out = []
    for p in paths:
        info = probe_video(p)
        if not info.has_audio:
            raise InputError("has no audio stream: the speech is what tells which mouth shape each frame "
                             "shows (record with sound)", path=p)
        info = find_upright(p, info)
        if text is not None:
            words, origin = read_transcript(text), "--text"
        elif p.resolve() in given:
            words, origin = given[p.resolve()], "given"
        else:
            beside = transcript_beside(p)
            words, origin = (read_transcript(str(beside)), beside.name) if beside else (None, "recognised")
        out.append(Source(path=p, info=info, text=words, text_from=origin if words else "recognised"))
    return out


def find_upright(path: PathLike, info: VideoInfo, mesh=None) -> VideoInfo:
    """``info`` with the quarter turns that make the face upright (:attr:`VideoInfo.turns`).

    ffmpeg has already applied the video's rotation tag (a phone's portrait video comes
    upright); this finds pixels that are still sideways or upside down -- a wrong tag, a
    camera held on its side -- by asking the face detector which of the four turns of a
    few frames looks most like an upright face (:data:`UPRIGHT_MARGIN`).

    Raises
    ------
    InputError
        Two turns score too alike to tell which way up the face is.
    """
    import warnings

    import numpy as np

    from ..face.landmarks import FaceMesh
    from ..face.video import read_video

    mesh = mesh or FaceMesh()
    frames = []
    for i, frame in enumerate(read_video(path, info=info)):
        if i >= UPRIGHT_FRAMES:
            break
        if i % UPRIGHT_EVERY == UPRIGHT_EVERY // 2:
            frames.append(frame)
    if not frames:
        return info
    scores = []
    for k in range(4):
        best = [max((d.score for d in mesh.detect(np.ascontiguousarray(np.rot90(f, k)))), default=0.0)
                for f in frames]
        scores.append(float(np.median(best)))
    order = sorted(range(4), key=lambda k: -scores[k])
    top, second = order[0], order[1]
    if scores[top] < UPRIGHT_MIN_SCORE:
        return info  # no face at any turn: the tracker says so with its own words
    if scores[top] - scores[second] < UPRIGHT_MARGIN:
        raise InputError(f"cannot tell which way up the face is (the face detector scores it "
                         f"{scores[top]:.2f} turned {90 * top} degrees and {scores[second]:.2f} turned "
                         f"{90 * second}); turn the video upright first", path=path)
    if top == 0:
        return info
    # np.rot90 turns counterclockwise: the face was turned clockwise by as much
    how = {1: "turned 90 degrees clockwise", 2: "upside down", 3: "turned 90 degrees counterclockwise"}[top]
    warnings.warn(f"{path}: the face is {how} in the picture (after ffmpeg's rotation tag); the frames are "
                  f"turned upright", UserWarning, stacklevel=3)
    w, h = info.size
    from dataclasses import replace

    return replace(info, turns=(info.turns + top) % 4, size=(h, w) if top % 2 else (w, h))
