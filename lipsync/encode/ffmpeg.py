"""The ffmpeg plumbing every video encoder shares, in one place.

* :func:`ffmpeg_exe`: the binary bundled with imageio-ffmpeg;
* :class:`PipeWriter`: a :class:`~lipsync.encode.base.Writer` that pipes raw frames to one
  ffmpeg process writing a hidden temporary file beside ``OUT`` (``.OUT.partial-<pid>.EXT``),
  muxes the audio, and renames the result into place;
* :func:`check_audio`, :func:`probe`: reading inputs and outputs back.

Audio with a :class:`PipeWriter`: the video length is authoritative (``n_frames / fps``).
The audio starts at the first frame (t = 0), is padded with silence when short (``apad``)
and cut at the video's duration (``-t``) when long. When the caller announces the frame
count (``frames=N``, as :func:`lipsync.pipeline.clip.render_clip` does) one ffmpeg process encodes
the video and the audio together; writing any other number of frames is then an error.
Otherwise the count is only known at the end: the video is encoded first, then muxed with
the audio in a second (cheap, stream-copy) pass rather than with ``-shortest``.

Only a SIGKILL of the Python process itself can leave a temporary file behind; ``OUT`` is
never touched before the output is complete.
"""

from __future__ import annotations

import errno
import os
import re
import subprocess
import tempfile
import warnings
from fractions import Fraction
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np

from .._media import OUTPUT_DEMUXERS, REFUSED_TEXT, input_args, refused
from ..errors import InputError, PathLike
from . import base as _base
from .base import STDERR_TAIL_CHARS, EncodeError, Writer, disk_full

__all__ = ["ffmpeg_exe", "PipeWriter", "RgbPipeWriter", "check_audio", "probe"]

# Seconds to let a failing ffmpeg exit on its own (so its stderr is complete) before killing it.
FFMPEG_EXIT_WAIT = 5.0

# Audio bitrate for the AAC track: transparent for speech and music at 48 kHz stereo.
AAC_BITRATE = "192k"

# Markers in ffmpeg's stderr meaning the disk filled up (strerror text on POSIX/Windows).
_DISK_FULL_MARKERS = ("No space left on device", "There is not enough space on the disk")


def ffmpeg_exe() -> str:
    """Path of the ffmpeg binary bundled with imageio-ffmpeg.

    A function (not a constant) so tests can substitute a failing ffmpeg.

    Examples
    --------
    >>> import os
    >>> os.path.isfile(ffmpeg_exe())
    True
    """
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


def fps_arg(fps: Union[int, float, Fraction]) -> str:
    """ffmpeg rate text for ``fps``: exact for integers and NTSC rates like 30000/1001.

    Examples
    --------
    >>> fps_arg(25), fps_arg(30000 / 1001)
    ('25', '30000/1001')
    """
    rate = Fraction(fps).limit_denominator(1001 * 1000)
    return str(rate.numerator) if rate.denominator == 1 else f"{rate.numerator}/{rate.denominator}"


#: False in a serve job's worker process (lipsync.server.jobs), which is killed with its
#: whole process group: its ffmpeg must be in that group to go with it.
OWN_SESSION = True


def popen(cmd: List[str], **kwargs) -> subprocess.Popen:
    """Start ffmpeg with stdout discarded, in its own process group."""
    # A separate process group: Ctrl-C in a terminal reaches only Python, which then
    # decides (kill ffmpeg, delete the temp file) instead of ffmpeg finalising a file on its own.
    if os.name == "posix" and not OWN_SESSION:
        pass
    elif os.name == "posix":
        kwargs["start_new_session"] = True
    else:  # pragma: no cover - Windows
        kwargs["creationflags"] = subprocess.CREATE_NEW_PROCESS_GROUP
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, **kwargs)


def tail(stream) -> str:
    """The last STDERR_TAIL_CHARS characters of a captured stderr file."""
    try:
        stream.seek(0)
        data = stream.read()
    except (OSError, ValueError):
        return ""
    text = data.decode("utf-8", "replace") if isinstance(data, bytes) else data
    return text[-STDERR_TAIL_CHARS:]


def check_audio(audio: PathLike) -> str:
    """Return ``audio`` as a str after making sure ffmpeg can read an audio stream from it."""
    path = os.fspath(audio)
    if not os.path.isfile(path):
        raise InputError("audio file not found" if not os.path.exists(path) else "audio path is not a file", path=path)
    try:
        with open(path, "rb"):
            pass
    except OSError as exc:
        raise InputError(f"cannot read audio file ({exc.strerror})", path=path) from None
    try:
        info = probe_streams(path)
    except OSError as exc:  # ffmpeg itself missing or not runnable: not the user's file's fault
        raise EncodeError(f"cannot run ffmpeg to read the audio ({exc})", path=path) from exc
    if not info["streams"] and refused(info["_text"]):
        raise InputError(REFUSED_TEXT, path=path)
    if not any(kind == "audio" for kind, _ in info["streams"]):
        raise InputError("no audio stream that ffmpeg can read", path=path)
    return path


class PipeWriter(Writer):
    """Raw frames on ffmpeg's stdin, one temporary output renamed into place at the end.

    Subclasses say what a frame is on the pipe (:meth:`_input_args`, :meth:`prepare`,
    ``self._payload_bytes``), how to encode it (:meth:`_codec_args`), the container
    (:meth:`_container`) and the audio codec (:attr:`audio_args`); this class runs the
    process, the audio (one pass when the frame count is announced, else a stream-copy mux),
    and turns ffmpeg's failures into :class:`EncodeError` or ``ENOSPC`` errors.
    """

    options: Tuple[str, ...] = ("frames",)
    audio_track = True
    #: ffmpeg arguments encoding the audio track.
    audio_args: Tuple[str, ...] = ("-c:a", "aac", "-b:a", AAC_BITRATE)
    #: (extension, muxer) of the video-only file made before the audio is muxed (two-pass
    #: audio); None: the output's own container.
    intermediate: Optional[Tuple[str, str]] = None

    def __init__(self, out: PathLike, *, fps: float, size: Tuple[int, int], audio: Optional[PathLike] = None,
                 quiet: bool = False, total: Optional[int] = None, frames: Optional[int] = None,
                 channels: int = 3):
        if audio is not None and not self.audio_track:
            check_audio(audio)
            warnings.warn(f"{out}: this format has no audio track; {os.fspath(audio)} was not used",
                          stacklevel=3)
            audio = None
        self.audio = check_audio(audio) if audio is not None else None
        if frames is not None and int(frames) < 1:
            raise ValueError(f"frames must be a positive count, got {frames!r}")
        self.frames = None if frames is None else int(frames)
        # one ffmpeg process for video and audio when the length is known up front
        self.single_pass = self.audio is not None and self.frames is not None
        self._proc: Optional[subprocess.Popen] = None
        self._stderr = None
        self._temps: List[str] = []
        self._payload_bytes = 0
        super().__init__(out, fps=fps, size=size, quiet=quiet, total=total, channels=channels)

    # -- subclass hooks -------------------------------------------------------------------
    def _container(self, ext: str) -> Tuple[str, bool]:
        """(ffmpeg muxer, whether it takes ``+faststart``) for the output extension."""
        raise NotImplementedError

    def _input_args(self) -> List[str]:
        """The raw input's description up to (not including) ``-framerate``; sets
        ``self._payload_bytes``."""
        raise NotImplementedError

    def _codec_args(self) -> List[str]:
        """Video encoding arguments (after ``-map``)."""
        raise NotImplementedError

    # -- plumbing -------------------------------------------------------------------------
    def _temp_name(self, tag: str, ext: str) -> str:
        base = os.path.basename(self.out)
        return os.path.join(self.folder, f".{base}.{tag}-{os.getpid()}{ext}")

    def _reserve(self, path: str) -> None:
        """Create ``path`` now: proves the folder is writable before any frame is made."""
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        except OSError as exc:
            raise type(exc)(exc.errno, f"cannot write {self.out}: output folder is not writable "
                                       f"({exc.strerror})", self.folder) from None
        os.close(fd)
        self._temps.append(path)

    def _output_args(self, muxer: str, path: str) -> List[str]:
        return (["-movflags", "+faststart"] if self.faststart else []) + ["-f", muxer, path]

    def _start(self) -> None:
        ext = os.path.splitext(self.out)[1].lower()
        self.muxer, self.faststart = self._container(ext)
        self.partial = self._temp_name("partial", ext or self.extension)
        if os.path.isdir(self.out):
            raise IsADirectoryError(errno.EISDIR, f"cannot write {self.out}: a folder of that name exists", self.out)
        self._reserve(self.partial)
        # With audio the video goes to an intermediate file and is muxed once its length is known.
        two_pass = self.audio is not None and not self.single_pass
        mid_ext, mid_muxer = self.intermediate or (ext or self.extension, self.muxer)
        self.video_path = self._temp_name("video", mid_ext) if two_pass else self.partial
        if two_pass:
            self._reserve(self.video_path)
        cmd = [ffmpeg_exe(), "-y", "-hide_banner", "-nostats", "-loglevel", "error"]
        cmd += self._input_args() + ["-framerate", fps_arg(self.fps), "-i", "pipe:0"]
        if self.single_pass:
            cmd += [*input_args(self.audio), "-map", "0:v:0", "-map", "1:a:0"]
        else:
            cmd += ["-map", "0:v:0"]
        cmd += self._codec_args()
        if self.single_pass:
            # Pad short audio with silence, then cut both at the video's length.
            cmd += ["-af", "apad", *self.audio_args, "-t", f"{self.frames / float(Fraction(self.fps)):.6f}"]
            cmd += self._output_args(self.muxer, self.partial)
        elif self.audio:
            cmd += ["-f", mid_muxer, self.video_path]
        else:
            cmd += self._output_args(self.muxer, self.partial)
        self._stderr = tempfile.TemporaryFile()
        self._proc = popen(cmd, stdin=subprocess.PIPE, stderr=self._stderr)

    def _write_payload(self, payload: np.ndarray) -> None:
        if payload.nbytes != self._payload_bytes:
            raise ValueError(f"frame {self.n_frames} for {self.out}: {payload.nbytes} bytes on the pipe, "
                             f"{self._payload_bytes} expected")
        try:
            _base.write_all(self._proc.stdin, payload.data)
        except OSError as exc:
            # ffmpeg died (BrokenPipe) or the pipe failed: report ffmpeg's own words.
            raise self._failure("ffmpeg stopped reading frames", exc) from exc

    def _failure(self, what: str, exc: Optional[BaseException] = None) -> BaseException:
        proc = self._proc
        code = None
        if proc is not None:
            if exc is not None and not isinstance(exc, BrokenPipeError):
                # The failure is on our side and ffmpeg is still waiting for frames.
                proc.kill()
            try:
                # A broken pipe means ffmpeg is exiting: let it finish writing its error.
                code = proc.wait(timeout=FFMPEG_EXIT_WAIT)
            except subprocess.TimeoutExpired:
                proc.kill()
                code = proc.wait()
        said = tail(self._stderr) if self._stderr is not None else ""
        if (exc is not None and disk_full(exc)) or any(m in said for m in _DISK_FULL_MARKERS):
            return OSError(errno.ENOSPC, f"disk full while encoding {self.out}; the partial output was "
                                         f"removed. ffmpeg said: {said.strip()[-500:]}", self.folder)
        return EncodeError(f"{what} (exit status {code})", path=self.out, stderr=said, returncode=code)

    def _finish(self) -> None:
        proc = self._proc
        if self.single_pass and self.n_frames != self.frames:
            raise EncodeError(f"{self.n_frames} frames were written, {self.frames} were announced "
                              f"(the audio is cut to the announced length)", path=self.out)
        try:
            proc.stdin.close()
        except OSError as exc:
            raise self._failure("ffmpeg stopped reading frames", exc) from exc
        if proc.wait() != 0:
            raise self._failure("ffmpeg failed")
        self._proc = None
        if self.audio and not self.single_pass:
            self._mux()
        os.replace(self.partial, self.out)
        self._temps.remove(self.partial)
        self._cleanup()

    def _mux(self) -> None:
        duration = self.n_frames / float(Fraction(self.fps))
        cmd = [
            ffmpeg_exe(), "-y", "-hide_banner", "-nostats", "-nostdin", "-loglevel", "error",
            "-i", self.video_path, *input_args(self.audio),
            "-map", "0:v:0", "-map", "1:a:0", "-c:v", "copy",
            # Pad short audio with silence, then cut both at the video's length.
            "-af", "apad", *self.audio_args,
            "-t", f"{duration:.6f}",
        ]
        cmd += self._output_args(self.muxer, self.partial)
        self._stderr.seek(0)
        self._stderr.truncate()
        self._proc = popen(cmd, stdin=subprocess.DEVNULL, stderr=self._stderr)
        if self._proc.wait() != 0:
            raise self._failure(f"ffmpeg failed to mux the audio from {self.audio}")
        self._proc = None

    def _cleanup(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None:
            for stream in (proc.stdin,):
                try:
                    if stream is not None:
                        stream.close()
                except OSError:
                    pass
            if proc.poll() is None:
                proc.kill()
            proc.wait()
        for path in self._temps:
            _base.remove(path)
        self._temps = []
        if self._stderr is not None:
            self._stderr.close()
            self._stderr = None


class RgbPipeWriter(PipeWriter):
    """A :class:`PipeWriter` sending the frames as they are (``rgb24``, or ``rgba`` with
    straight alpha); ffmpeg converts them for the codec (see :func:`to_yuv`)."""

    def _input_args(self) -> List[str]:
        width, height = self.size
        self._payload_bytes = width * height * self.channels
        return ["-f", "rawvideo", "-pix_fmt", "rgba" if self.channels == 4 else "rgb24", "-s", f"{width}x{height}"]

    def prepare(self, frame: np.ndarray, out=None) -> np.ndarray:
        """The frame itself: it is written before its buffer is used again."""
        return np.ascontiguousarray(frame)


def to_yuv(pix_fmt: str) -> List[str]:
    """ffmpeg arguments converting RGB(A) input to ``pix_fmt`` with the BT.709 matrix, tv range,
    and tagging the stream so (as :mod:`lipsync.encode.yuv` does for mp4: swscale's own default
    would be BT.601, shifting colours in every player that reads the tags).

    Examples
    --------
    >>> to_yuv("yuva420p")[:2]
    ['-vf', 'scale=out_color_matrix=bt709:out_range=tv,format=yuva420p']
    """
    return ["-vf", f"scale=out_color_matrix=bt709:out_range=tv,format={pix_fmt}",
            "-color_primaries", "bt709", "-color_trc", "bt709", "-colorspace", "bt709", "-color_range", "tv"]


# -- reading back --------------------------------------------------------------------------

_STREAM_RE = re.compile(r"^\s*Stream #\d+:\d+\S*(?:\([^)]*\))?: (Video|Audio|Subtitle|Data|Attachment): (\w+)(.*)$")
_DURATION_RE = re.compile(r"Duration: (\d+):(\d\d):(\d\d(?:\.\d+)?)")


def probe_streams(path: str, demuxers=None) -> Dict[str, Any]:
    """Parse ``ffmpeg -i path``'s stream listing (ffmpeg exits 1 there: no output given).
    ``path`` is opened only as one of ``demuxers`` (:func:`lipsync._media.input_args`)."""
    res = subprocess.run([ffmpeg_exe(), "-hide_banner", "-nostdin", *input_args(path, demuxers=demuxers)],
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    text = res.stderr.decode("utf-8", "replace")
    info: Dict[str, Any] = {"streams": [], "duration": None, "width": None, "height": None,
                            "fps": None, "video_codec": None, "audio_codec": None, "_text": text}
    m = _DURATION_RE.search(text)
    if m:
        h, mnt, s = m.groups()
        info["duration"] = int(h) * 3600 + int(mnt) * 60 + float(s)
    for line in text.splitlines():
        sm = _STREAM_RE.match(line)
        if not sm:
            continue
        kind, codec, rest = sm.group(1).lower(), sm.group(2), sm.group(3)
        info["streams"].append((kind, codec))
        if kind == "video" and info["video_codec"] is None:
            info["video_codec"] = codec
            size = re.search(r"[ ,](\d+)x(\d+)[ ,\[]", rest + " ")
            if size:
                info["width"], info["height"] = int(size.group(1)), int(size.group(2))
            rate = re.search(r"([\d.]+)(k?) fps", rest)
            if rate:
                info["fps"] = float(rate.group(1)) * (1000 if rate.group(2) else 1)
        elif kind == "audio" and info["audio_codec"] is None:
            info["audio_codec"] = codec
    return info


# Sample rate audio is decoded at to measure its duration: 48 kHz gives ~21 us resolution.
_PROBE_RATE = 48000


def probe(path: PathLike) -> Dict[str, Any]:
    """Read back a video file with the bundled ffmpeg.

    Parameters
    ----------
    path : path-like
        A video (or audio) file.

    Returns
    -------
    dict
        ``n_frames`` (decoded count), ``fps`` (as listed), ``duration`` (container, s),
        ``video_duration`` (``n_frames / fps``), ``width``, ``height``, ``video_codec``,
        ``audio_codec`` (None without audio), ``audio_duration`` (s, from the decoded sample
        count; None without audio), ``streams`` (list of ``(kind, codec)``).

    Raises
    ------
    InputError
        ffmpeg cannot read ``path``.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from lipsync.encode import open_writer
    >>> out = os.path.join(tempfile.mkdtemp(), "p.mp4")
    >>> with open_writer(out, fps=20, size=(16, 8), quiet=True) as w:
    ...     for _ in range(4):
    ...         w.write(np.zeros((8, 16, 3), np.uint8))
    >>> p = probe(out)
    >>> p["n_frames"], p["fps"], p["video_duration"], p["streams"]
    (4, 20.0, 0.2, [('video', 'h264')])
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError("file not found", path=path)
    info = probe_streams(path, OUTPUT_DEMUXERS)
    text = info.pop("_text")
    if not info["streams"]:
        last = text.strip().splitlines()[-1] if text.strip() else "no streams"
        raise InputError(f"ffmpeg cannot read this file ({last})", path=path)
    info["n_frames"] = None
    info["video_duration"] = None
    info["audio_duration"] = None
    if info["video_codec"] is not None:
        # Decode (not just count packets) so the count is what a player would show.
        res = subprocess.run([ffmpeg_exe(), "-hide_banner", "-nostdin", *input_args(path, demuxers=OUTPUT_DEMUXERS),
                              "-map", "0:v:0",
                              "-f", "null", "-"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        frames = re.findall(r"frame=\s*(\d+)", res.stderr.decode("utf-8", "replace"))
        info["n_frames"] = int(frames[-1]) if frames else 0
        if info["fps"]:
            info["video_duration"] = info["n_frames"] / info["fps"]
    if info["audio_codec"] is not None:
        proc = subprocess.Popen([ffmpeg_exe(), "-hide_banner", "-nostdin", "-loglevel", "error",
                                 *input_args(path, demuxers=OUTPUT_DEMUXERS),
                                 "-map", "0:a:0", "-ac", "1", "-ar", str(_PROBE_RATE), "-f", "s16le", "-"],
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        n_bytes = 0
        while True:
            chunk = proc.stdout.read(1 << 20)
            if not chunk:
                break
            n_bytes += len(chunk)
        proc.wait()
        info["audio_duration"] = n_bytes / 2 / _PROBE_RATE
    return info
