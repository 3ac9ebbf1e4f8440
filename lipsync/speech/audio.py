"""Audio decoding: any file ffmpeg reads -> 16 kHz mono 16-bit samples.

The bundled ffmpeg (imageio-ffmpeg) does the work, so every container and codec it knows
(wav, flac, mp3, m4a/aac, ogg/opus, webm, video files' sound) at any rate and channel count
is read the same way: channels averaged to mono, resampled to :data:`SAMPLE_RATE`.

Examples
--------
>>> import os
>>> from lipsync._data import default_bank_dir
>>> pcm = load_audio(os.path.join(default_bank_dir(), "..", "..", "samples", "hello.wav"))
>>> pcm.dtype, round(len(pcm) / SAMPLE_RATE, 2)
(dtype('int16'), 2.97)
"""

from __future__ import annotations

import os
import subprocess
from typing import Optional, Union

import numpy as np

from ..errors import TimelineError

PathLike = Union[str, "os.PathLike[str]"]

#: The rate pocketsphinx's en-us acoustic model was trained at.
SAMPLE_RATE = 16000

#: Extensions read as audio by the timeline reader and ``lipsync render`` (what people
#: record or export speech as; ffmpeg reads many more, which ``lipsync align`` accepts).
#: Video containers count too: their sound is the speech (``lipsync render clip.mp4 --text``
#: after ``lipsync init --video`` renders the subject saying what the clip says).
AUDIO_EXTENSIONS = (".wav", ".wave", ".flac", ".mp3", ".m4a", ".aac", ".ogg", ".oga", ".opus",
                    ".webm", ".wma", ".aif", ".aiff", ".caf", ".amr", ".mka",
                    ".mp4", ".m4v", ".mov", ".mkv", ".avi", ".mpg", ".mpeg", ".3gp")

# How much of ffmpeg's stderr an error quotes: its last line says what was wrong.
_STDERR_TAIL = 300


class AudioError(TimelineError):
    """An audio file that cannot be read (the message names the file).

    A :class:`~lipsync.errors.TimelineError` (so an :class:`~lipsync.errors.InputError`):
    audio is read as a timeline by ``lipsync render`` and the other timeline commands.
    """


def _ffmpeg_exe() -> str:
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


def load_audio(path: PathLike, *, sample_rate: int = SAMPLE_RATE, max_seconds: Optional[float] = None) -> np.ndarray:
    """Decode an audio file to mono 16-bit samples at ``sample_rate``.

    Parameters
    ----------
    path : path-like
        Any file ffmpeg can read an audio stream from.
    sample_rate : int
        Output rate in Hz (default 16000, the acoustic model's rate).
    max_seconds : float, optional
        Decode no further than this (a server checking an upload's length).

    Returns
    -------
    numpy.ndarray
        ``int16`` samples, channels averaged. May be empty (a file with no samples).

    Raises
    ------
    AudioError
        The file is missing, a folder, or not audio ffmpeg can read; the message names it.

    Examples
    --------
    >>> import os, subprocess, tempfile
    >>> p = os.path.join(tempfile.mkdtemp(), "tone.flac")
    >>> _ = subprocess.run([_ffmpeg_exe(), "-v", "error", "-f", "lavfi", "-i",
    ...                     "sine=frequency=440:sample_rate=44100:duration=0.5", "-ac", "2", p])
    >>> pcm = load_audio(p)
    >>> pcm.dtype, len(pcm)
    (dtype('int16'), 8000)
    """
    name = os.fspath(path)
    if not os.path.exists(name):
        raise AudioError("no such file", path=name)
    if os.path.isdir(name):
        raise AudioError("is a folder, not an audio file", path=name)
    from .._media import input_args, refused, REFUSED_TEXT

    cmd = [_ffmpeg_exe(), "-nostdin", "-v", "error", *input_args(name), "-map", "0:a:0", "-vn", "-sn", "-dn",
           "-ac", "1", "-ar", str(int(sample_rate)), "-f", "s16le", "-acodec", "pcm_s16le"]
    cmd += ["-t", f"{float(max_seconds):.3f}", "-"] if max_seconds is not None else ["-"]
    try:
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, check=False)
    except OSError as exc:  # ffmpeg itself not runnable: the environment, not the file
        raise OSError(f"cannot run ffmpeg to read {name}: {exc}") from exc
    if proc.returncode != 0:
        full = proc.stderr.decode("utf-8", "replace").strip()
        said = full[-_STDERR_TAIL:].splitlines()[-1] if full else f"ffmpeg exit status {proc.returncode}"
        if "matches no streams" in full:  # a video without sound, an image, ...
            said = "no audio stream"
        if refused(full):  # a playlist, a concat list, ...: see lipsync._media
            raise AudioError(REFUSED_TEXT, path=name)
        raise AudioError(f"cannot read as audio ({said})", path=name)
    data = proc.stdout
    return np.frombuffer(data[: len(data) // 2 * 2], dtype="<i2").astype(np.int16, copy=False)


def is_audio_path(path: PathLike) -> bool:
    """True if ``path`` has one of :data:`AUDIO_EXTENSIONS`.

    Examples
    --------
    >>> is_audio_path("talk.MP3"), is_audio_path("talk.TextGrid")
    (True, False)
    """
    return os.path.splitext(os.fspath(path))[1].lower() in AUDIO_EXTENSIONS
