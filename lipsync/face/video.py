"""Frames of a video, decoded by the ffmpeg that ships with imageio-ffmpeg.

Any container and codec that ffmpeg reads (mp4, mov, mkv, webm, avi, MPEG-1 ...). Frames
come as RGB ``uint8`` ``(H, W, 3)``, upright (ffmpeg applies a phone's rotation tag), at a
constant rate: a variable-frame-rate video (a phone's, whose rate drops in low light) is read
at :attr:`VideoInfo.fps`, a constant rate chosen from its frame times (:func:`constant_rate`),
frame ``n`` being the frame the video shows at ``n / fps`` (ffmpeg's ``fps`` filter with
``round=up``), so that frame numbers are times everywhere (tracks, banks, dubs).

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
    variable : (float, float) or None
        For a variable-frame-rate video, its lowest and highest rates (fps, from the
        intervals between its frames); its frames are then read at the constant ``fps``.
    """

    path: Path
    fps: float
    size: Tuple[int, int]
    duration: float
    has_audio: bool
    turns: int = 0
    variable: Optional[Tuple[float, float]] = None

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
    rate, variable = constant_rate(frame_times(path), fps)
    if variable is not None:
        fps = rate
    if not (FPS_RANGE[0] <= fps <= FPS_RANGE[1]):
        raise InputError(f"frame rate {fps:g} is not a video's ({FPS_RANGE[0]:g}-{FPS_RANGE[1]:g} fps)", path=path)
    w, h = meta["size"]
    return VideoInfo(path=path, fps=fps, size=(int(w), int(h)), duration=float(meta.get("duration") or 0.0),
                     has_audio=bool(meta.get("audio_codec")), variable=variable)


def frame_times(path: PathLike) -> np.ndarray:
    """Presentation times (seconds, sorted) of the frames of the first video stream, from the
    container's packets (ffmpeg, copying the stream: nothing is decoded); empty when ffmpeg
    cannot list them.

    Examples
    --------
    >>> frame_times("no-such-file.mp4").size
    0
    """
    import subprocess

    import imageio_ffmpeg

    from .._media import input_args

    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-nostdin", *input_args(path),
           "-map", "0:v:0", "-c", "copy", "-f", "framecrc", "-"]
    try:
        out = subprocess.run(cmd, capture_output=True, timeout=_TIMES_TIMEOUT).stdout.decode("ascii", "replace")
    except (OSError, subprocess.SubprocessError):
        return np.zeros(0)
    base, pts = None, []
    for line in out.splitlines():
        if line.startswith("#tb 0:"):
            num, _, den = line.split(":", 1)[1].strip().partition("/")
            base = float(num) / float(den or 1)
        elif line and not line.startswith("#"):
            fields = line.split(",")
            if len(fields) > 2 and fields[0].strip() == "0" and fields[2].strip().lstrip("-").isdigit():
                pts.append(int(fields[2]))
    if base is None or not pts:
        return np.zeros(0)
    return np.sort(np.asarray(pts, np.float64)) * base


#: Seconds :func:`frame_times` may take (it reads the file once without decoding: a 1 GB
#: video takes about a second).
_TIMES_TIMEOUT = 120

#: Intervals between frames further than this fraction from their median make a video's
#: rate variable: timestamps rounded to a coarse clock (a 29.97 fps video in milliseconds,
#: 33 and 34 ms) stay well within it; a dropped frame (twice the interval) does not.
VARIABLE_TOLERANCE = 0.25

#: Rates a variable-frame-rate video is read at when its fastest stretch is within
#: :data:`RATE_SNAP` of one (cameras record at these).
COMMON_RATES = (10.0, 12.0, 15.0, 24000 / 1001, 24.0, 25.0, 30000 / 1001, 30.0, 48.0, 50.0, 60000 / 1001, 60.0,
                90.0, 100.0, 120000 / 1001, 120.0, 240.0)
RATE_SNAP = 0.03


def constant_rate(times: np.ndarray, fps: float) -> Tuple[float, Optional[Tuple[float, float]]]:
    """The rate to read a video at, given its frame ``times`` and its header's ``fps``:
    ``(fps, None)`` for a constant-rate video; for a variable one, the rate of its faster
    stretches (the 10th percentile of its frame intervals, snapped to a :data:`COMMON_RATES`
    within 3%), so no stretch loses frames, with ``(lowest, highest)`` of its rates.

    Examples
    --------
    >>> t = np.r_[np.arange(25) / 25, 1 + np.arange(0, 25, 3) / 25, 2 + np.arange(25) / 25]
    >>> rate, (lo, hi) = constant_rate(t, 19.3)
    >>> rate, round(lo, 2), round(hi, 2)
    (25.0, 8.33, 25.0)
    >>> constant_rate(np.arange(50) * 0.04, 25.0)
    (25.0, None)
    """
    d = np.diff(np.unique(np.asarray(times, np.float64)))
    d = d[d > 0]
    if d.size < 2:
        return fps, None
    med = float(np.median(d))
    if np.abs(d - med).max() <= VARIABLE_TOLERANCE * med:
        return fps, None
    rate = 1.0 / float(np.percentile(d, 10))
    near = min(COMMON_RATES, key=lambda r: abs(r - rate))
    rate = near if abs(near - rate) <= RATE_SNAP * near else round(rate, 3)
    rate = float(min(max(rate, FPS_RANGE[0]), FPS_RANGE[1]))
    return rate, (1.0 / float(d.max()), 1.0 / float(d.min()))


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
        From :func:`probe_video`, if the caller has it (else the video is probed first: a
        variable frame rate must be known before decoding).

    Yields
    ------
    numpy.ndarray
    """
    from fractions import Fraction

    p = Path(os.fspath(path))
    vi = info or probe_video(p)
    # a variable rate read at the constant one: each output frame the one shown at its time
    rate = Fraction(vi.fps).limit_denominator(1001 * 1000)
    extra = ["-vf", f"fps=fps={rate}:round=up"] if vi.variable is not None else []
    gen, meta = _reader(p, output_params=extra)
    w, h = vi.size
    turns = vi.turns % 4
    if turns % 2:
        w, h = h, w  # decoded before the turn
    if tuple(int(v) for v in meta["size"]) != (w, h):  # replaced since it was probed
        gen.close()
        raise InputError(f"changed while it was being read (frames of {meta['size'][0]}x{meta['size'][1]}, "
                         f"{w}x{h} when probed)", path=p)
    try:
        for buf in gen:
            frame = np.frombuffer(buf, np.uint8).reshape(h, w, 3)
            if turns:
                frame = np.ascontiguousarray(np.rot90(frame, turns))
                frame.flags.writeable = False
            yield frame
    finally:
        gen.close()
