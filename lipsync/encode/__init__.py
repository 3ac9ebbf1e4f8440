"""Stream RGB or RGBA frames to a video (with optional audio), an animation or a PNG sequence.

One module per output kind, each registering its writer(s) in :data:`ENCODERS` (name:
extensions; alpha: whether RGBA frames keep their transparency):

============  ===================  =====  ===================================================================
module        name: extensions     alpha  output
============  ===================  =====  ===================================================================
:mod:`.mp4`   mp4: .mp4 .m4v .mkv  no     H.264, AAC audio (the default; H.264 in .mov with ``format="mp4"``)
:mod:`.png`   png: a folder        yes    ``frame_000000.png`` ... (no audio)
:mod:`.webm`  webm: .webm          yes    VP9 (``yuva420p``), Opus audio
:mod:`.mov`   mov: .mov            yes    ProRes 4444 (``yuva444p12le``), PCM audio
:mod:`.mov`   qtrle                yes    QuickTime Animation (lossless RLE), PCM audio
:mod:`.webp`  webp: .webp          yes    animated WebP, looping (no audio)
:mod:`.gif`   gif: .gif            1-bit  animated GIF, one palette, looping (no audio)
============  ===================  =====  ===================================================================

:mod:`.base` holds the writer protocol and the registry, :mod:`.ffmpeg` the plumbing every
video writer shares (the bundled ffmpeg as a subprocess, audio muxing, error reporting) and
:func:`probe`, which reads an output back.

Frames are written one at a time, so memory stays flat however long the clip. Every output
is built under a temporary name beside ``OUT`` and renamed into place only when complete;
on any failure -- an exception inside the ``with`` block, Ctrl-C, ffmpeg dying, a full disk
-- the temporary output is deleted, nothing is left at ``OUT`` and the error propagates.

Errors
    * an unknown format: :class:`~lipsync.errors.UnknownNameError` listing the valid ones;
    * a missing or unreadable audio file: :class:`~lipsync.errors.InputError` naming it;
    * an output folder that is missing or not writable: the ``OSError`` from trying to
      create the temporary output, re-raised with a message naming the folder, before any
      frame is rendered;
    * ffmpeg failing: :class:`EncodeError` with the tail of ffmpeg's stderr and the path;
    * a full disk: ``OSError`` with ``errno.ENOSPC`` and a message saying what happened.

    Only a SIGKILL of the Python process itself can leave a temporary file behind
    (``.OUT.partial-<pid>.mp4``, a hidden name beside ``OUT``); ``OUT`` is never touched.

Examples
--------
>>> import numpy as np, tempfile, os
>>> out = os.path.join(tempfile.mkdtemp(), "clip.mp4")
>>> with open_writer(out, fps=25, size=(64, 48), quiet=True) as w:
...     for i in range(10):
...         w.write(np.full((48, 64, 3), 20 * i, np.uint8))
>>> info = probe(out)
>>> info["n_frames"], info["width"], info["height"], info["video_codec"]
(10, 64, 48, 'h264')
"""

from __future__ import annotations

import os
from typing import Any, Dict, Optional, Tuple

from ..errors import PathLike, UnknownNameError
from .base import ENCODERS, EncodeError, Writer
from .ffmpeg import probe
# Importing the writers' modules registers them, in this order (the CLI lists them so).
from .mp4 import X264_PRESETS, Mp4Writer
from .png import PngWriter
from .webm import WebmWriter
from .mov import AnimationWriter, ProresWriter
from .webp import WebpWriter
from .gif import GifWriter

__all__ = ["ENCODERS", "EncodeError", "Writer", "Mp4Writer", "PngWriter", "WebmWriter", "ProresWriter",
           "AnimationWriter", "WebpWriter", "GifWriter", "open_writer", "format_for", "probe", "X264_PRESETS",
           "has_alpha"]


def has_alpha(format: str) -> bool:
    """Whether the output format ``format`` (an :data:`ENCODERS` name) keeps transparency.

    Examples
    --------
    >>> has_alpha("webm"), has_alpha("mp4")
    (True, False)
    """
    return bool(ENCODERS.get(format).alpha)


def format_for(out: PathLike) -> str:
    """The encoder name :func:`open_writer` picks for ``out`` when no format is given.

    An existing folder, or a path ending with a separator, is a PNG sequence; otherwise
    the extension decides.

    Examples
    --------
    >>> format_for("talk.mp4"), format_for("frames/"), format_for("clip.MOV"), format_for("a.webm")
    ('mp4', 'png', 'mov', 'webm')
    """
    text = os.fspath(out)
    if text.endswith(("/", os.sep)) or os.path.isdir(text):
        return "png"
    ext = os.path.splitext(text)[1]
    name = ENCODERS.name_for_extension(ext) if ext else None
    if name is None:
        by_format = "; ".join(f"{n} for {', '.join(exts)}" for n, exts in ENCODERS.extensions().items())
        raise UnknownNameError(
            f"cannot tell the output format from the name (extension {ext or 'none'!r}); valid formats: "
            f"{', '.join(ENCODERS.names())} ({by_format}; png for a folder, e.g. 'frames/')",
            path=text)
    return name


def open_writer(out: PathLike, *, fps: float, size: Tuple[int, int], format: Optional[str] = None,
                audio: Optional[PathLike] = None, crf: int = 18, preset: str = "medium",
                quiet: bool = False, total: Optional[int] = None, frames: Optional[int] = None,
                threads: Optional[int] = None, channels: int = 3) -> Writer:
    """Open a streaming writer for ``out``.

    Parameters
    ----------
    out : path-like
        Output file (``.mp4``, ``.m4v``, ``.mkv``, ``.webm``, ``.mov``, ``.webp``, ``.gif``)
        or folder for a PNG sequence.
    fps : float
        Frames per second.
    size : (int, int)
        ``(width, height)``; every frame must be a ``uint8`` array ``(height, width, channels)``.
    format : str, optional
        An :data:`ENCODERS` name ("mp4", "png", "webm", "mov", "qtrle", "webp", "gif");
        default: chosen by :func:`format_for`.
    audio : path-like, optional
        Sound to mux (AAC in mp4, Opus in WebM, PCM in MOV; the others have no audio track
        and warn), starting at the first frame, padded or cut to the video's duration
        ``n_frames / fps``.
    crf, preset : int, str
        libx264 quality (lower is better; 18 is visually lossless for drawn faces) and speed:
        an x264 preset or a name in :data:`X264_PRESETS`.
    quiet : bool
        Hide the progress counter.
    total : int, optional
        Expected number of frames, for the progress bar.
    frames : int, optional
        The exact number of frames that will be written (mp4 with audio: video and audio
        are then encoded by one ffmpeg process; writing another number is an error).
    threads : int, optional
        Encoder threads (mp4, webm; default: the encoder's own choice).
    channels : {3, 4}
        RGB frames, or RGBA with straight alpha (formats with alpha only: see :func:`has_alpha`).

    Returns
    -------
    Writer
        A context manager with ``write(frame)`` and ``close()``.

    Raises
    ------
    UnknownNameError
        ``format`` or the extension is not known.
    InputError
        ``audio`` is missing or has no readable audio stream.
    OSError
        The output folder is missing or not writable; a disk filled up (``errno.ENOSPC``).
    EncodeError
        ffmpeg failed.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> out = os.path.join(tempfile.mkdtemp(), "a.mp4")
    >>> with open_writer(out, fps=25, size=(16, 16), quiet=True) as w:
    ...     w.write(np.zeros((16, 16, 3), np.uint8))
    >>> os.path.exists(out)
    True
    """
    name = format if format is not None else format_for(out)
    cls = ENCODERS.get(name)
    kwargs: Dict[str, Any] = dict(fps=fps, size=size, audio=audio, quiet=quiet, total=total, channels=channels)
    options = dict(crf=crf, preset=preset, frames=frames, threads=threads)
    kwargs.update((k, v) for k, v in options.items() if k in cls.options)
    return cls(out, **kwargs)
