"""Stream RGB frames to an H.264 mp4 (with optional audio) or a numbered PNG sequence.

Frames are written one at a time, so memory stays flat however long the clip. Every output
is built under a temporary name beside ``OUT`` and renamed into place only when complete;
on any failure -- an exception inside the ``with`` block, Ctrl-C, ffmpeg dying, a full disk
-- the temporary output is deleted, nothing is left at ``OUT`` and the error propagates.

Encoders are looked up in :data:`ENCODERS` (explicit name first, then ``OUT``'s shape and
extension, see :func:`open_writer`).

mp4 details
    The ffmpeg binary bundled with imageio-ffmpeg is driven as a subprocess reading raw
    ``yuv420p`` frames on stdin, converted from RGB in this process (:mod:`lipsync.yuv`,
    BT.709 limited range): H.264 (libx264), tagged BT.709 matrix, primaries and transfer
    and tv range (the matrix web players assume for untagged RGB-sourced video),
    ``-movflags +faststart``, ``-crf`` and ``-preset`` (x264's presets, or a name from
    :data:`X264_PRESETS`). yuv420p needs even dimensions: an odd width or height is padded by one
    pixel that repeats the last column/row (padding rather than cropping keeps every drawn
    pixel; repeating the edge avoids a dark seam bleeding into chroma).

    With ``audio=FILE`` the video length is authoritative (``n_frames / fps``): the audio
    starts at the first frame (t = 0), is padded with silence when short (``apad``) and cut
    at the video's duration (``-t``) when long. When the caller announces the frame count
    (``frames=N``, as :func:`lipsync.clip.render_clip` does) one ffmpeg process encodes the
    video and the audio together; writing any other number of frames is then an error.
    Otherwise the count is only known at the end: the video is encoded first, then muxed
    with the audio in a second (cheap, stream-copy) pass rather than with ``-shortest``.

PNG sequence details
    Frame ``i`` (0-based, so it shows time ``i / fps``) is ``OUT/frame_000000.png`` etc.
    If ``OUT`` already exists it must be empty or hold only files named like our frames (a
    previous run); such a folder is replaced as a whole once the new sequence is complete,
    so frames of an older, longer clip never linger. A folder with any other file is
    refused before any work, so a user's files are never deleted. PNG sequences carry no
    audio; ``audio`` is still checked, and a warning says it was not used.

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

import errno
import os
import re
import shutil
import subprocess
import sys
import tempfile
import warnings
from fractions import Fraction
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np

from .errors import InputError, PathLike, UnknownNameError
from .registry import Registry

__all__ = ["ENCODERS", "EncodeError", "Writer", "Mp4Writer", "PngWriter", "open_writer", "format_for", "probe"]

ENCODERS: "Registry[type]" = Registry("output format")

#: Named encoder settings beyond x264's own presets: name -> (x264 preset, -x264-params).
#: Any other ``preset`` is passed to x264 as it is.
#:
#: ``talking-head``: ultrafast's cheap analysis (diamond search, subme 0, one reference)
#: plus the tools that pay on mostly-static frames: CABAC, 3 B-frames, the macroblock tree
#: over a short lookahead, deblocking and 8x8 transforms. b-adapt 0 and a 5-frame lookahead
#: were both faster *and* smaller here than b-adapt 1 / 10 frames. x264 alone, one thread,
#: crf 18, the 26.7 s benchmark clip (video only):
#:
#: ==============  ===================  ===================
#: clip            veryfast CPU s / MB  talking-head
#: ==============  ===================  ===================
#: face 512x512    0.90 / 0.21          0.52 / 0.26
#: toon 512x512    1.05 / 0.33          0.58 / 0.47
#: face 1280x720   3.62 / 0.70          1.80 / 0.56
#: ==============  ===================  ===================
#:
#: PSNR-Y against the source within 0.9 dB of veryfast's (51.4 vs 51.9, 50.0 vs 49.5, 50.8
#: vs 51.6 dB): all far above visible loss. ultrafast itself is as fast but 3-8x larger
#: (1.5 / 1.9 / 6.4 MB with audio); superfast 2-6x larger.
X264_PRESETS: Dict[str, Tuple[str, Optional[str]]] = {
    "talking-head": ("ultrafast", "cabac=1:bframes=3:b-adapt=0:mbtree=1:rc-lookahead=5:deblock=1:"
                                  "8x8dct=1:partitions=i8x8,i4x4"),
}

# How much of ffmpeg's stderr an EncodeError quotes: enough for the actual error line and
# its context, short enough to read in a terminal.
STDERR_TAIL_CHARS = 2000

# Seconds to let a failing ffmpeg exit on its own (so its stderr is complete) before killing it.
FFMPEG_EXIT_WAIT = 5.0

# Audio bitrate for the AAC track: transparent for speech and music at 48 kHz stereo.
AAC_BITRATE = "192k"

# Markers in ffmpeg's stderr meaning the disk filled up (strerror text on POSIX/Windows).
_DISK_FULL_MARKERS = ("No space left on device", "There is not enough space on the disk")

# ffmpeg muxer for each container extension the "mp4" encoder accepts, and whether the
# container takes +faststart (moov atom first so playback starts before download ends).
_CONTAINERS = {
    ".mp4": ("mp4", True),
    ".m4v": ("mp4", True),
    ".mov": ("mov", True),
    ".mkv": ("matroska", False),
}

_FRAME_NAME = "frame_{:06d}.png"
_FRAME_RE = re.compile(r"frame_\d{6,}\.png\Z")


class EncodeError(RuntimeError):
    """ffmpeg failed while encoding ``path``; the message ends with its stderr tail.

    Attributes
    ----------
    path : str
        The output that was being written (nothing is left there).
    stderr : str
        The last :data:`STDERR_TAIL_CHARS` characters of ffmpeg's stderr.
    returncode : int or None
        ffmpeg's exit status, when it had exited.
    """

    def __init__(self, message: str, *, path: PathLike, stderr: str = "", returncode: Optional[int] = None):
        self.path = os.fspath(path)
        self.stderr = stderr
        self.returncode = returncode
        text = f"{self.path}: {message}"
        if stderr.strip():
            text += "\nffmpeg said:\n" + stderr.rstrip()
        super().__init__(text)


def _ffmpeg_exe() -> str:
    # A function (not a constant) so tests can substitute a failing ffmpeg.
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


def _fps_arg(fps: Union[int, float, Fraction]) -> str:
    """ffmpeg rate text for ``fps``: exact for integers and NTSC rates like 30000/1001."""
    rate = Fraction(fps).limit_denominator(1001 * 1000)
    return str(rate.numerator) if rate.denominator == 1 else f"{rate.numerator}/{rate.denominator}"


def _remove(path: str) -> None:
    """Delete a file or folder if present; cleanup must never mask the original error."""
    try:
        if os.path.isdir(path) and not os.path.islink(path):
            shutil.rmtree(path, ignore_errors=True)
        else:
            os.remove(path)
    except OSError:
        pass


def _disk_full(exc: BaseException) -> bool:
    return isinstance(exc, OSError) and exc.errno == errno.ENOSPC


def _tail(stream) -> str:
    """The last STDERR_TAIL_CHARS characters of a captured stderr file."""
    try:
        stream.seek(0)
        data = stream.read()
    except (OSError, ValueError):
        return ""
    text = data.decode("utf-8", "replace") if isinstance(data, bytes) else data
    return text[-STDERR_TAIL_CHARS:]


def _check_output_folder(folder: str, out: str) -> None:
    """Fail early, with a message naming the folder, if OUT's folder cannot take files."""
    if not os.path.exists(folder):
        raise FileNotFoundError(errno.ENOENT, f"cannot write {out}: output folder does not exist", folder)
    if not os.path.isdir(folder):
        raise NotADirectoryError(errno.ENOTDIR, f"cannot write {out}: output folder is not a folder", folder)


def _check_audio(audio: PathLike) -> str:
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
        info = _probe_streams(path)
    except OSError as exc:  # ffmpeg itself missing or not runnable: not the user's file's fault
        raise EncodeError(f"cannot run ffmpeg to read the audio ({exc})", path=path) from exc
    if not any(kind == "audio" for kind, _ in info["streams"]):
        raise InputError("no audio stream that ffmpeg can read", path=path)
    return path


class Writer:
    """Base class of the encoders: a context manager taking RGB ``uint8`` frames.

    Subclasses implement ``_start``, ``_write_payload``, ``_finish`` and ``_cleanup`` (and
    ``prepare`` when a frame needs encoding work before it is written); this class validates
    frames, counts them, shows progress and guarantees that an exception anywhere between
    opening and a successful :meth:`close` leaves nothing at ``out``.

    ``write(frame)`` is ``write_prepared(prepare(frame))``. ``prepare`` touches no state of
    the writer, so a renderer's worker threads can call it on the frames they make (the
    colour conversion or PNG compression then runs in parallel, off the writing thread),
    and the writing thread sends the results in order with :meth:`write_prepared`.

    Parameters
    ----------
    out : path-like
        Final output path.
    fps : float
        Frames per second (> 0).
    size : (int, int)
        Frame ``(width, height)`` in pixels; frames are arrays of shape ``(height, width, 3)``.
    quiet : bool
        Hide the progress counter.
    total : int, optional
        Expected frame count, for the progress bar only.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> out = os.path.join(tempfile.mkdtemp(), "seq") + os.sep
    >>> with open_writer(out, fps=10, size=(8, 6), quiet=True) as w:
    ...     w.write(np.zeros((6, 8, 3), np.uint8))
    >>> w.n_frames, sorted(os.listdir(out))
    (1, ['frame_000000.png'])
    """

    extension = ""

    def __init__(self, out: PathLike, *, fps: float, size: Tuple[int, int], quiet: bool = False,
                 total: Optional[int] = None):
        self.out = os.path.abspath(os.fspath(out).rstrip("/\\") or os.fspath(out))
        if not (isinstance(fps, (int, float, Fraction)) and float(fps) > 0 and np.isfinite(float(fps))):
            raise ValueError(f"fps must be a positive number, got {fps!r}")
        width, height = (int(v) for v in size)
        if width <= 0 or height <= 0:
            raise ValueError(f"size must be positive (width, height), got {size!r}")
        self.fps = fps
        self.size = (width, height)
        self.n_frames = 0
        self.closed = False
        self._failed = False
        self._bar = None
        self._quiet = quiet
        self._total = total
        self._own_payload = None  # write()'s buffer, reused frame after frame
        self.folder = os.path.dirname(self.out)
        _check_output_folder(self.folder, self.out)
        try:
            self._start()
        except BaseException:
            self._abort()
            raise

    # -- subclass hooks -------------------------------------------------------------------
    def _start(self) -> None:
        raise NotImplementedError

    def _write_payload(self, payload) -> None:
        raise NotImplementedError

    def _finish(self) -> None:
        raise NotImplementedError

    def prepare(self, frame: np.ndarray, out=None):
        """What :meth:`write_prepared` sends for ``frame`` (thread-safe; ``out``: a previous
        result of this writer's to reuse as the buffer, or None). Default: the frame."""
        return frame

    def _cleanup(self) -> None:
        raise NotImplementedError

    # -- public API -----------------------------------------------------------------------
    def __enter__(self) -> "Writer":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is not None:
            self._abort()
            return False
        self.close()
        return False

    def write(self, frame: np.ndarray) -> None:
        """Append one frame: an RGB ``uint8`` array of shape ``(height, width, 3)``."""
        if self.closed:
            raise ValueError(f"write to a closed writer for {self.out}")
        frame = np.asarray(frame)
        width, height = self.size
        if frame.dtype != np.uint8 or frame.shape != (height, width, 3):
            self._abort()
            raise ValueError(
                f"frame {self.n_frames} for {self.out}: expected uint8 of shape {(height, width, 3)} "
                f"(size={self.size} is width, height), got {frame.dtype} {frame.shape}"
            )
        try:
            payload = self._own_payload = self.prepare(frame, self._own_payload)
        except BaseException:
            self._abort()
            raise
        self.write_prepared(payload)

    def write_prepared(self, payload) -> None:
        """Append one frame made by :meth:`prepare` (frames are written in call order)."""
        if self.closed:
            raise ValueError(f"write to a closed writer for {self.out}")
        try:
            self._write_payload(payload)
        except BaseException:
            self._abort()
            raise
        self.n_frames += 1
        if not self._quiet:
            if self._bar is None:
                from tqdm import tqdm

                self._bar = tqdm(total=self._total, unit="frame", desc=os.path.basename(self.out),
                                 leave=False, file=sys.stderr)
            self._bar.update(1)

    def close(self) -> None:
        """Finish the output and rename it into place; on failure clean up and re-raise."""
        if self.closed:
            return
        try:
            if self.n_frames == 0:
                raise EncodeError("no frames were written", path=self.out)
            self._finish()
        except BaseException:
            self._abort()
            raise
        self.closed = True
        self._close_bar()

    def abort(self) -> None:
        """Stop without producing output: kill the encoder and delete temporary files."""
        self._abort()

    # -- internals ------------------------------------------------------------------------
    def _close_bar(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def _abort(self) -> None:
        if self.closed:
            return
        self.closed = True
        self._failed = True
        self._close_bar()
        self._cleanup()

    def __del__(self):  # a writer dropped without close() must not leave temp files
        try:
            if not getattr(self, "closed", True):
                self._abort()
        except Exception:
            pass


class Mp4Writer(Writer):
    """H.264 in an mp4 (or .m4v/.mov/.mkv) container via the bundled ffmpeg.

    Use :func:`open_writer` rather than this class directly.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> out = os.path.join(tempfile.mkdtemp(), "odd.mp4")
    >>> with Mp4Writer(out, fps=25, size=(33, 21), quiet=True) as w:
    ...     w.write(np.zeros((21, 33, 3), np.uint8))
    >>> probe(out)["width"], probe(out)["height"]   # padded to even
    (34, 22)
    """

    extension = ".mp4"

    def __init__(self, out: PathLike, *, fps: float, size: Tuple[int, int], audio: Optional[PathLike] = None,
                 crf: int = 18, preset: str = "medium", quiet: bool = False, total: Optional[int] = None,
                 frames: Optional[int] = None, threads: Optional[int] = None):
        self.audio = _check_audio(audio) if audio is not None else None
        if frames is not None and int(frames) < 1:
            raise ValueError(f"frames must be a positive count, got {frames!r}")
        self.frames = None if frames is None else int(frames)
        # one ffmpeg process for video and audio when the length is known up front
        self.single_pass = self.audio is not None and self.frames is not None
        self.crf = int(crf)
        self.preset = str(preset)
        self.threads = None if threads is None else max(1, int(threads))
        self._proc: Optional[subprocess.Popen] = None
        self._stderr = None
        self._temps: List[str] = []
        super().__init__(out, fps=fps, size=size, quiet=quiet, total=total)

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

    def _start(self) -> None:
        ext = os.path.splitext(self.out)[1].lower()
        self.muxer, self.faststart = _CONTAINERS.get(ext, ("mp4", True))
        self.partial = self._temp_name("partial", ext or ".mp4")
        if os.path.isdir(self.out):
            raise IsADirectoryError(errno.EISDIR, f"cannot write {self.out}: a folder of that name exists", self.out)
        self._reserve(self.partial)
        # With audio the video goes to an intermediate file and is muxed once its length is
        # known. mp4, not mkv: matroska rounds timestamps to 1 ms, which would make 60 or
        # 29.97 fps video slightly variable-rate after the stream copy.
        two_pass = self.audio is not None and not self.single_pass
        self.video_path = self._temp_name("video", ".mp4") if two_pass else self.partial
        if two_pass:
            self._reserve(self.video_path)
        width, height = self.size
        self._pad = (width % 2, height % 2)
        cmd = [
            _ffmpeg_exe(), "-y", "-hide_banner", "-nostats", "-loglevel", "error",
            # Frames arrive already converted (lipsync.yuv, on the writing thread): see
            # prepare(). Tagged on input too, so ffmpeg sees nothing to convert.
            "-f", "rawvideo", "-pix_fmt", "yuv420p", "-color_range", "tv", "-colorspace", "bt709",
            "-color_primaries", "bt709", "-color_trc", "bt709",
            "-s", f"{width + self._pad[0]}x{height + self._pad[1]}",
            "-framerate", _fps_arg(self.fps), "-i", "pipe:0",
        ]
        if self.single_pass:
            cmd += ["-i", self.audio, "-map", "0:v:0", "-map", "1:a:0"]
        else:
            cmd += ["-map", "0:v:0"]
        cmd += [
            # Tagged so players convert back to RGB the way the frames were converted.
            "-color_primaries", "bt709", "-color_trc", "bt709", "-colorspace", "bt709", "-color_range", "tv",
            "-c:v", "libx264", "-crf", str(self.crf),
        ]
        x264_preset, x264_params = X264_PRESETS.get(self.preset, (self.preset, None))
        cmd += ["-preset", x264_preset]
        if x264_params:
            cmd += ["-x264-params", x264_params]
        if self.threads is not None:
            cmd += ["-threads", str(self.threads)]
        if self.single_pass:
            # Pad short audio with silence, then cut both at the video's length.
            cmd += ["-af", "apad", "-c:a", "aac", "-b:a", AAC_BITRATE,
                    "-t", f"{self.frames / float(Fraction(self.fps)):.6f}"]
            if self.faststart:
                cmd += ["-movflags", "+faststart"]
            cmd += ["-f", self.muxer, self.partial]
        elif self.audio:
            cmd += ["-f", "mp4", self.video_path]
        else:
            if self.faststart:
                cmd += ["-movflags", "+faststart"]
            cmd += ["-f", self.muxer, self.partial]
        from .yuv import rgb_to_yuv420p

        self._to_yuv = rgb_to_yuv420p
        pw, ph = width + self._pad[0], height + self._pad[1]
        self._payload_bytes = pw * ph + 2 * (pw // 2) * (ph // 2)
        self._stderr = tempfile.TemporaryFile()
        self._proc = _popen(cmd, stdin=subprocess.PIPE, stderr=self._stderr)

    def prepare(self, frame: np.ndarray, out=None) -> np.ndarray:
        """The yuv420p bytes of ``frame`` (padded to even size), into ``out`` when given.

        Converted here rather than by swscale in ffmpeg: half the bytes through the pipe and
        a quarter of the CPU (1.1 ms vs 2.4 ms a 1280x720 frame; lipsync/yuv.py).
        """
        if any(self._pad):
            frame = np.pad(frame, ((0, self._pad[1]), (0, self._pad[0]), (0, 0)), mode="edge")
        return self._to_yuv(frame, out)

    def _write_payload(self, payload: np.ndarray) -> None:
        if payload.nbytes != self._payload_bytes:
            raise ValueError(f"frame {self.n_frames} for {self.out}: {payload.nbytes} bytes of yuv420p, "
                             f"{self._payload_bytes} expected")
        try:
            _write_all(self._proc.stdin, payload.data)
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
        tail = _tail(self._stderr) if self._stderr is not None else ""
        if (exc is not None and _disk_full(exc)) or any(m in tail for m in _DISK_FULL_MARKERS):
            return OSError(errno.ENOSPC, f"disk full while encoding {self.out}; the partial output was "
                                         f"removed. ffmpeg said: {tail.strip()[-500:]}", self.folder)
        return EncodeError(f"{what} (exit status {code})", path=self.out, stderr=tail, returncode=code)

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
            _ffmpeg_exe(), "-y", "-hide_banner", "-nostats", "-nostdin", "-loglevel", "error",
            "-i", self.video_path, "-i", self.audio,
            "-map", "0:v:0", "-map", "1:a:0", "-c:v", "copy",
            # Pad short audio with silence, then cut both at the video's length.
            "-af", "apad", "-c:a", "aac", "-b:a", AAC_BITRATE,
            "-t", f"{duration:.6f}",
        ]
        if self.faststart:
            cmd += ["-movflags", "+faststart"]
        cmd += ["-f", self.muxer, self.partial]
        self._stderr.seek(0)
        self._stderr.truncate()
        self._proc = _popen(cmd, stdin=subprocess.DEVNULL, stderr=self._stderr)
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
            _remove(path)
        self._temps = []
        if self._stderr is not None:
            self._stderr.close()
            self._stderr = None


def _popen(cmd: List[str], **kwargs) -> subprocess.Popen:
    # A separate process group: Ctrl-C in a terminal reaches only Python, which then
    # decides (kill ffmpeg, delete the temp file) instead of ffmpeg finalising a file on its own.
    if os.name == "posix":
        kwargs["start_new_session"] = True
    else:  # pragma: no cover - Windows
        kwargs["creationflags"] = subprocess.CREATE_NEW_PROCESS_GROUP
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, **kwargs)


def _write_all(stream, data) -> None:
    """Write ``data`` to a binary file object (one place for tests to inject OS errors)."""
    stream.write(data)
    stream.flush()


class PngWriter(Writer):
    """A numbered PNG sequence in a folder, ``frame_000000.png`` upwards (lossless).

    Use :func:`open_writer` rather than this class directly.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> out = os.path.join(tempfile.mkdtemp(), "frames")
    >>> with PngWriter(out, fps=25, size=(4, 2), quiet=True) as w:
    ...     w.write(np.full((2, 4, 3), 7, np.uint8))
    ...     w.write(np.full((2, 4, 3), 9, np.uint8))
    >>> sorted(os.listdir(out))
    ['frame_000000.png', 'frame_000001.png']
    """

    def __init__(self, out: PathLike, *, fps: float, size: Tuple[int, int], audio: Optional[PathLike] = None,
                 quiet: bool = False, total: Optional[int] = None, **_ignored: Any):
        if audio is not None:
            _check_audio(audio)
            warnings.warn(f"{out}: a PNG sequence has no audio track; {os.fspath(audio)} was not used",
                          stacklevel=3)
        self._tmp: Optional[str] = None
        super().__init__(out, fps=fps, size=size, quiet=quiet, total=total)

    def _start(self) -> None:
        if os.path.exists(self.out):
            if not os.path.isdir(self.out):
                raise FileExistsError(errno.EEXIST, f"cannot write a PNG sequence to {self.out}: "
                                                    "a file of that name exists", self.out)
            foreign = sorted(n for n in os.listdir(self.out) if not _FRAME_RE.match(n))
            if foreign:
                raise FileExistsError(
                    errno.EEXIST, f"refusing to replace {self.out}: it holds files that are not frames "
                                  f"of an earlier sequence ({', '.join(foreign[:3])}"
                                  f"{', ...' if len(foreign) > 3 else ''}); choose an empty or new folder",
                    self.out)
        tmp = os.path.join(self.folder, f".{os.path.basename(self.out)}.partial-{os.getpid()}")
        _remove(tmp)  # a leftover from a killed run with our pid
        try:
            os.mkdir(tmp)
        except OSError as exc:
            raise type(exc)(exc.errno, f"cannot write {self.out}: output folder is not writable "
                                       f"({exc.strerror})", self.folder) from None
        self._tmp = tmp

    def prepare(self, frame: np.ndarray, out=None) -> bytes:
        """The PNG file's bytes for ``frame`` (compression runs on the caller's thread)."""
        import cv2

        ok, buf = cv2.imencode(".png", frame[:, :, ::-1])
        if not ok:  # pragma: no cover - cv2 only fails on invalid arrays, checked in write()
            raise EncodeError("PNG encoding failed", path=self.out)
        return buf

    def _write_payload(self, buf) -> None:
        path = os.path.join(self._tmp, _FRAME_NAME.format(self.n_frames))
        try:
            with open(path, "wb") as f:
                _write_all(f, memoryview(buf))
        except OSError as exc:
            if _disk_full(exc):
                raise OSError(errno.ENOSPC, f"disk full while writing frame {self.n_frames} of the PNG "
                                            f"sequence {self.out}; the partial output was removed",
                              path) from exc
            raise

    def _finish(self) -> None:
        old = None
        if os.path.isdir(self.out):
            old = os.path.join(self.folder, f".{os.path.basename(self.out)}.old-{os.getpid()}")
            _remove(old)
            os.replace(self.out, old)
        try:
            os.replace(self._tmp, self.out)
        except BaseException:
            if old is not None:  # put the previous sequence back
                os.replace(old, self.out)
            raise
        self._tmp = None
        if old is not None:
            _remove(old)

    def _cleanup(self) -> None:
        if self._tmp is not None:
            _remove(self._tmp)
            self._tmp = None


ENCODERS.register("mp4", Mp4Writer, extensions=tuple(_CONTAINERS), aliases=("h264", "mov", "mkv"))
ENCODERS.register("png", PngWriter, aliases=("png-sequence", "frames"))


def format_for(out: PathLike) -> str:
    """The encoder name :func:`open_writer` picks for ``out`` when no format is given.

    An existing folder, or a path ending with a separator, is a PNG sequence; otherwise
    the extension decides.

    Examples
    --------
    >>> format_for("talk.mp4"), format_for("frames/"), format_for("clip.MOV")
    ('mp4', 'png', 'mp4')
    """
    text = os.fspath(out)
    if text.endswith(("/", os.sep)) or os.path.isdir(text):
        return "png"
    ext = os.path.splitext(text)[1]
    name = ENCODERS.name_for_extension(ext) if ext else None
    if name is None:
        known = ", ".join(sorted(e for e in _CONTAINERS))
        raise UnknownNameError(
            f"cannot tell the output format from the name (extension {ext or 'none'!r}); valid formats: "
            f"{', '.join(ENCODERS.names())} (mp4 for {known}; png for a folder, e.g. 'frames/')",
            path=text)
    return name


def open_writer(out: PathLike, *, fps: float, size: Tuple[int, int], format: Optional[str] = None,
                audio: Optional[PathLike] = None, crf: int = 18, preset: str = "medium",
                quiet: bool = False, total: Optional[int] = None, frames: Optional[int] = None,
                threads: Optional[int] = None) -> Writer:
    """Open a streaming writer for ``out``.

    Parameters
    ----------
    out : path-like
        Output file (``.mp4``, ``.m4v``, ``.mov``, ``.mkv``) or folder for a PNG sequence.
    fps : float
        Frames per second.
    size : (int, int)
        ``(width, height)``; every frame must be a ``uint8`` array ``(height, width, 3)``.
    format : str, optional
        An :data:`ENCODERS` name ("mp4", "png"); default: chosen by :func:`format_for`.
    audio : path-like, optional
        Sound to mux as AAC (mp4 only), starting at the first frame, padded or cut to the
        video's duration ``n_frames / fps``.
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
        x264 encoding threads (mp4; default: x264's own choice, 1.5 per core).

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
    kwargs: Dict[str, Any] = dict(fps=fps, size=size, audio=audio, quiet=quiet, total=total)
    if cls is Mp4Writer:
        kwargs.update(crf=crf, preset=preset, frames=frames, threads=threads)
    return cls(out, **kwargs)


# -- reading back --------------------------------------------------------------------------

_STREAM_RE = re.compile(r"^\s*Stream #\d+:\d+\S*(?:\([^)]*\))?: (Video|Audio|Subtitle|Data|Attachment): (\w+)(.*)$")
_DURATION_RE = re.compile(r"Duration: (\d+):(\d\d):(\d\d(?:\.\d+)?)")


def _probe_streams(path: str) -> Dict[str, Any]:
    """Parse ``ffmpeg -i path``'s stream listing (ffmpeg exits 1 there: no output given)."""
    res = subprocess.run([_ffmpeg_exe(), "-hide_banner", "-nostdin", "-i", path],
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
    info = _probe_streams(path)
    text = info.pop("_text")
    if not info["streams"]:
        last = text.strip().splitlines()[-1] if text.strip() else "no streams"
        raise InputError(f"ffmpeg cannot read this file ({last})", path=path)
    info["n_frames"] = None
    info["video_duration"] = None
    info["audio_duration"] = None
    if info["video_codec"] is not None:
        # Decode (not just count packets) so the count is what a player would show.
        res = subprocess.run([_ffmpeg_exe(), "-hide_banner", "-nostdin", "-i", path, "-map", "0:v:0",
                              "-f", "null", "-"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        frames = re.findall(r"frame=\s*(\d+)", res.stderr.decode("utf-8", "replace"))
        info["n_frames"] = int(frames[-1]) if frames else 0
        if info["fps"]:
            info["video_duration"] = info["n_frames"] / info["fps"]
    if info["audio_codec"] is not None:
        proc = subprocess.Popen([_ffmpeg_exe(), "-hide_banner", "-nostdin", "-loglevel", "error", "-i", path,
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
