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
from ..face.video import VideoInfo, probe_video, read_video

#: Transcript files looked for beside a video, in this order (MFA's ``.lab``, plain ``.txt``).
TRANSCRIPT_SUFFIXES = (".txt", ".lab")

#: Frames looked at to tell which way up the face is: every 10th of the first 80 (3.2 s at
#: 25 fps, where a recording's speaker is already in view), 8 frames.
UPRIGHT_EVERY, UPRIGHT_FRAMES = 10, 80
#: Which way up, in two steps (measured on bbwm5s.mpg tagged 90/180 and a phone-style clip):
#: the face mesh's "up" (mouth to eyes) gives the quarter turn -- the detector's keypoints
#: turn its region with a sideways face (up at -91.8 degrees for a 90-degree tag, -2.0
#: upright) -- but not upside down, where they stay upright; there the detector's score
#: tells: upright 0.96, upside down 0.57-0.72 (3 GRID clips), so the half turn is taken when
#: it scores this much more.
FLIP_MARGIN = 0.1
#: An "up" further than this from a quarter turn (degrees) is a head too tilted to guess.
UP_TOLERANCE_DEG = 30.0
#: The detector's score from which a frame counts as showing a face.
UPRIGHT_MIN_SCORE = 0.5
#: Fewest pixels between the eyes the face room places lips on well enough to tell mouth
#: shapes apart (which differ by 0.1-0.3 eye distances). Measured on bbwm5s.mpg scaled down
#: (tracked points against the full-size clip's, 46 px between the eyes): median lip point
#: error 0.009 eye distances at 30 px, 0.017 at 23, 0.047 at 16, 0.087 at 12, 0.17 at 8.
MIN_EYE_DISTANCE_PX = 16.0


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
    """``info`` with the quarter turns that make the face upright (:attr:`VideoInfo.turns`),
    after checking the face is large enough to track (:data:`MIN_EYE_DISTANCE_PX`).

    ffmpeg has already applied the video's rotation tag (a phone's portrait video comes
    upright); this finds pixels still sideways or upside down -- a wrong tag, a camera held
    on its side -- from a few frames (:data:`FLIP_MARGIN`). No face in those frames: left
    as it is, for the tracker to report.

    Raises
    ------
    InputError
        The head is tilted too far to tell which way up it is, or the face is too small.
    """
    import warnings

    import numpy as np

    from ..face.landmarks import FaceMesh, NoFaceError
    from ..face.measure import eye_distance

    mesh = mesh or FaceMesh()
    frames = [f for i, f in zip(range(UPRIGHT_FRAMES), read_video(path, info=info))
              if i % UPRIGHT_EVERY == UPRIGHT_EVERY // 2]
    ups, sizes = [], []
    for f in frames:
        try:
            with warnings.catch_warnings():  # "2 faces found": the tracker warns about that itself
                warnings.simplefilter("ignore")
                p = mesh.find(f, refine=0)  # the detector's region is close enough for a direction
        except NoFaceError:
            continue
        up = (p[33, :2] + p[263, :2]) / 2 - (p[13, :2] + p[14, :2]) / 2  # mouth to eyes
        ups.append(np.degrees(np.arctan2(up[0], -up[1])))  # 0: up is up; 90: up points right
        sizes.append(float(eye_distance(p[None])[0]))
    if not frames:
        return info
    h, w = frames[0].shape[:2]
    if sizes and float(np.median(sizes)) < MIN_EYE_DISTANCE_PX:
        raise InputError(f"the face is too small: {np.median(sizes):.0f} px between the eyes in a {w}x{h} picture, "
                         f"at least {MIN_EYE_DISTANCE_PX:g} are needed to place the lips (film closer, or at a "
                         f"higher resolution)", path=path)
    if len(ups) < max(1, len(frames) // 2):
        return info
    angle = float(np.median(ups))
    quarter = int(round(angle / 90.0))
    if abs(angle - 90.0 * quarter) > UP_TOLERANCE_DEG:
        raise InputError(f"cannot tell which way up the face is (tilted {angle:.0f} degrees); turn the video "
                         f"upright first", path=path)
    turns = quarter % 4  # np.rot90 turns counterclockwise: "up" pointing right needs one turn

    def score(k: int) -> float:
        return float(np.median([max((d.score for d in mesh.detect(np.ascontiguousarray(np.rot90(f, k)))),
                                    default=0.0) for f in frames]))

    if score((turns + 2) % 4) > score(turns) + FLIP_MARGIN:
        turns = (turns + 2) % 4
    if turns == 0:
        return info
    how = {1: "turned 90 degrees clockwise", 2: "upside down", 3: "turned 90 degrees counterclockwise"}[turns]
    warnings.warn(f"{path}: the face is {how} in the picture (after ffmpeg's rotation tag); the frames are "
                  f"turned upright", UserWarning, stacklevel=3)
    from dataclasses import replace

    return replace(info, turns=(info.turns + turns) % 4, size=(h, w) if turns % 2 else (w, h))
