"""The writer protocol every encoder follows, the :data:`ENCODERS` registry, and the helpers
that keep outputs atomic (nothing at ``OUT`` until it is complete)."""

from __future__ import annotations

import errno
import os
import shutil
import sys
from fractions import Fraction
from typing import Optional, Tuple

import numpy as np

from .._files import remove_stale_partials
from ..errors import PathLike
from ..registry import Registry

__all__ = ["ENCODERS", "EncodeError", "Writer"]

#: Output formats: name -> :class:`Writer` subclass (explicit name first, then extension).
ENCODERS: "Registry[type]" = Registry("output format")

# How much of ffmpeg's stderr an EncodeError quotes: enough for the actual error line and
# its context, short enough to read in a terminal.
STDERR_TAIL_CHARS = 2000


class EncodeError(RuntimeError):
    """ffmpeg failed while encoding ``path``; the message ends with its stderr tail.

    Attributes
    ----------
    path : str
        The output that was being written (nothing is left there).
    stderr : str
        The last :data:`~lipsync.encode.base.STDERR_TAIL_CHARS` characters of ffmpeg's stderr.
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


def remove(path: str) -> None:
    """Delete a file or folder if present; cleanup must never mask the original error."""
    try:
        if os.path.isdir(path) and not os.path.islink(path):
            shutil.rmtree(path, ignore_errors=True)
        else:
            os.remove(path)
    except OSError:
        pass


def disk_full(exc: BaseException) -> bool:
    return isinstance(exc, OSError) and exc.errno == errno.ENOSPC


def write_all(stream, data) -> None:
    """Write ``data`` to a binary file object (one place for tests to inject OS errors)."""
    stream.write(data)
    stream.flush()


def check_output_folder(folder: str, out: str) -> None:
    """Make OUT's folder if it is missing (as every command's ``-o`` does), or fail early
    with a message naming it; then remove partial outputs of OUT that killed runs left."""
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise NotADirectoryError(errno.ENOTDIR, f"cannot write {out}: output folder is not a folder", folder)
    try:
        os.makedirs(folder or ".", exist_ok=True)
    except OSError as exc:
        raise type(exc)(exc.errno, f"cannot write {out}: cannot make its folder ({exc.strerror})", folder) from None
    # ".OUT.partial-PID.mp4" (or a PNG sequence's folder, or the two-pass ".OUT.video-PID.mp4")
    # of a process that no longer exists: a SIGKILL mid-render; never a running render's.
    remove_stale_partials(out, tags=("partial", "video"))


class Writer:
    """Base class of the encoders: a context manager taking RGB (or RGBA) ``uint8`` frames.

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
        Frame ``(width, height)`` in pixels; frames are arrays of shape ``(height, width, channels)``.
    quiet : bool
        Hide the progress counter.
    total : int, optional
        Expected frame count, for the progress bar only.
    channels : {3, 4}
        RGB frames, or RGBA with straight alpha (only writers whose :attr:`alpha` is True:
        an opaque format needs the frames flattened first, see :func:`lipsync.morphing.alpha.flatten`).

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from lipsync.encode import open_writer
    >>> out = os.path.join(tempfile.mkdtemp(), "seq") + os.sep
    >>> with open_writer(out, fps=10, size=(8, 6), quiet=True) as w:
    ...     w.write(np.zeros((6, 8, 3), np.uint8))
    >>> w.n_frames, sorted(os.listdir(out))
    (1, ['frame_000000.png'])
    """

    extension = ""
    #: Whether the format stores transparency (``channels=4`` frames).
    alpha = False
    #: Whether the container carries a sound track (``audio=`` is muxed, else warned about).
    audio_track = False
    #: Keyword options of :func:`lipsync.encode.open_writer` this writer takes beyond the
    #: common ones (``fps``, ``size``, ``audio``, ``quiet``, ``total``).
    options: Tuple[str, ...] = ()

    def __init__(self, out: PathLike, *, fps: float, size: Tuple[int, int], quiet: bool = False,
                 total: Optional[int] = None, channels: int = 3):
        self.out = os.path.abspath(os.fspath(out).rstrip("/\\") or os.fspath(out))
        if channels not in (3, 4):
            raise ValueError(f"channels must be 3 (RGB) or 4 (RGBA), got {channels!r}")
        if channels == 4 and not self.alpha:
            raise ValueError(f"{self.out}: {type(self).__name__} stores no alpha; flatten RGBA frames onto a "
                             f"background first (lipsync.morphing.alpha.flatten) or write a format with alpha "
                             f"({', '.join(n for n, c in ENCODERS.items() if c.alpha)})")
        self.channels = channels
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
        check_output_folder(self.folder, self.out)
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
        """Append one frame: a ``uint8`` array of shape ``(height, width, channels)``."""
        if self.closed:
            raise ValueError(f"write to a closed writer for {self.out}")
        frame = np.asarray(frame)
        width, height = self.size
        if frame.dtype != np.uint8 or frame.shape != (height, width, self.channels):
            self._abort()
            raise ValueError(
                f"frame {self.n_frames} for {self.out}: expected uint8 of shape {(height, width, self.channels)} "
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
