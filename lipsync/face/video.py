"""Frames of a video, decoded by the ffmpeg that ships with imageio-ffmpeg.

Any container and codec that ffmpeg reads (mp4, mov, mkv, webm, avi, MPEG-1 ...). Frames
come as RGB ``uint8`` ``(H, W, 3)``, upright (ffmpeg applies a phone's rotation tag).

Examples
--------
>>> probe_video("no-such-file.mp4")
Traceback (most recent call last):
...
lipsync.errors.InputError: no-such-file.mp4: no such file
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Optional, Tuple

import numpy as np

from ..errors import InputError, PathLike

#: Frames per second outside this range are a broken header, not a video.
FPS_RANGE = (1.0, 240.0)


@dataclass(frozen=True)
class VideoInfo:
    """What a video holds.

    Attributes
    ----------
    path : Path
    fps : float
    size : tuple of int
        ``(W, H)`` of the decoded (upright) frames.
    duration : float
        Seconds, as the container says (0 when it does not say).
    has_audio : bool
        Whether it has an audio stream.
    turns : int
        Quarter turns (counterclockwise, as :func:`numpy.rot90`) :func:`read_video` gives
        each decoded frame: a face filmed sideways or upside down, after ffmpeg has applied
        the rotation tag (found by :func:`lipsync.videobank.sources.find_upright`). ``size``
        is the turned frames' size.
    """

    path: Path
    fps: float
    size: Tuple[int, int]
    duration: float
    has_audio: bool
    turns: int = 0

    @property
    def frame_count(self) -> int:
        """Frames the container's duration implies (decoding may give one more or less)."""
        return int(round(self.duration * self.fps))


def _rotation_note(record) -> bool:
    """imageio-ffmpeg's note that a rotation tag changed the frame size: expected (ffmpeg
    turns a phone's portrait video upright), so not shown to users."""
    return "is different from the source frame size" not in record.getMessage()


def _reader(path: Path, **kwargs):
    import logging

    import imageio_ffmpeg

    log = logging.getLogger("imageio_ffmpeg")
    if _rotation_note not in log.filters:
        log.addFilter(_rotation_note)

    if not path.is_file():
        raise InputError("no such file" if not path.exists() else "not a file", path=path)
    from .._media import REFUSED_TEXT, input_args, refused

    # only as a media container, never a playlist or list pointing at other files (lipsync._media)
    *params, _, url = input_args(path)
    gen = imageio_ffmpeg.read_frames(url, pix_fmt="rgb24", input_params=params + kwargs.pop("input_params", []),
                                     **kwargs)
    try:
        meta = next(gen)
    except (OSError, RuntimeError, StopIteration) as e:
        gen.close()
        if refused(str(e)):
            raise InputError(REFUSED_TEXT, path=path) from None
        if "Output file does not contain any stream" in str(e):  # it opened, but holds only sound
            raise InputError("has no video stream (only sound): give a video of the speaker's face",
                             path=path) from None
        text = str(e).strip().splitlines()
        raise InputError("not a video ffmpeg can read" + (f" ({text[-1]})" if text else ""), path=path) from None
    return gen, meta


def _info(path: Path, meta: dict) -> VideoInfo:
    fps = float(meta.get("fps") or 0.0)
    if not (FPS_RANGE[0] <= fps <= FPS_RANGE[1]):
        raise InputError(f"frame rate {fps:g} is not a video's ({FPS_RANGE[0]:g}-{FPS_RANGE[1]:g} fps)", path=path)
    w, h = meta["size"]
    return VideoInfo(path=path, fps=fps, size=(int(w), int(h)), duration=float(meta.get("duration") or 0.0),
                     has_audio=bool(meta.get("audio_codec")))


def probe_video(path: PathLike) -> VideoInfo:
    """Frame rate, size, duration and whether there is sound, without decoding frames.

    Raises
    ------
    InputError
        Missing file, or no video stream ffmpeg can read (names the file).
    """
    p = Path(os.fspath(path))
    gen, meta = _reader(p)
    gen.close()
    return _info(p, meta)


def read_video(path: PathLike, *, info: Optional[VideoInfo] = None) -> Iterator[np.ndarray]:
    """Every frame of a video in order, as read-only RGB ``uint8`` ``(H, W, 3)`` arrays.

    Parameters
    ----------
    path : path-like
    info : VideoInfo, optional
        From :func:`probe_video`, if the caller has it (saves nothing but a check).

    Yields
    ------
    numpy.ndarray
    """
    p = Path(os.fspath(path))
    gen, meta = _reader(p)
    vi = info or _info(p, meta)
    w, h = vi.size
    turns = vi.turns % 4
    if turns % 2:
        w, h = h, w  # decoded before the turn
    try:
        for buf in gen:
            frame = np.frombuffer(buf, np.uint8).reshape(h, w, 3)
            if turns:
                frame = np.ascontiguousarray(np.rot90(frame, turns))
                frame.flags.writeable = False
            yield frame
    finally:
        gen.close()
