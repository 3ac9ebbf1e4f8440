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
        if text is not None:
            words, origin = read_transcript(text), "--text"
        elif p.resolve() in given:
            words, origin = given[p.resolve()], "given"
        else:
            beside = transcript_beside(p)
            words, origin = (read_transcript(str(beside)), beside.name) if beside else (None, "recognised")
        out.append(Source(path=p, info=info, text=words, text_from=origin if words else "recognised"))
    return out
