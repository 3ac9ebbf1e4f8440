"""A numbered PNG sequence in a folder (lossless; RGBA frames keep their alpha; no audio).

Frame ``i`` (0-based, so it shows time ``i / fps``) is ``OUT/frame_000000.png`` etc. If
``OUT`` already exists it must be empty or hold only files named like our frames (a previous
run); such a folder is replaced as a whole once the new sequence is complete, so frames of an
older, longer clip never linger. A folder with any other file is refused before any work, so
a user's files are never deleted. PNG sequences carry no audio; ``audio`` is still checked,
and a warning says it was not used.
"""

from __future__ import annotations

import errno
import os
import re
import warnings
from typing import Any, Optional, Tuple

import numpy as np

from ..errors import PathLike
from . import base as _base
from .base import ENCODERS, EncodeError, Writer, disk_full, remove
from .ffmpeg import check_audio

__all__ = ["PngWriter"]

_FRAME_NAME = "frame_{:06d}.png"
_FRAME_RE = re.compile(r"frame_\d{6,}\.png\Z")


class PngWriter(Writer):
    """A numbered PNG sequence in a folder, ``frame_000000.png`` upwards (lossless).

    Use :func:`~lipsync.encode.open_writer` rather than this class directly.

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

    alpha = True

    def __init__(self, out: PathLike, *, fps: float, size: Tuple[int, int], audio: Optional[PathLike] = None,
                 quiet: bool = False, total: Optional[int] = None, channels: int = 3, **_ignored: Any):
        if audio is not None:
            check_audio(audio)
            warnings.warn(f"{out}: a PNG sequence has no audio track; {os.fspath(audio)} was not used",
                          stacklevel=3)
        self._tmp: Optional[str] = None
        super().__init__(out, fps=fps, size=size, quiet=quiet, total=total, channels=channels)

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
        remove(tmp)  # a leftover from a killed run with our pid
        try:
            os.mkdir(tmp)
        except OSError as exc:
            raise type(exc)(exc.errno, f"cannot write {self.out}: output folder is not writable "
                                       f"({exc.strerror})", self.folder) from None
        self._tmp = tmp

    def prepare(self, frame: np.ndarray, out=None) -> bytes:
        """The PNG file's bytes for ``frame`` (compression runs on the caller's thread)."""
        import cv2

        # RGB(A) -> BGR(A), OpenCV's order (the alpha stays last)
        ok, buf = cv2.imencode(".png", frame[:, :, [2, 1, 0, 3]] if frame.shape[2] == 4 else frame[:, :, ::-1])
        if not ok:  # pragma: no cover - cv2 only fails on invalid arrays, checked in write()
            raise EncodeError("PNG encoding failed", path=self.out)
        return buf

    def _write_payload(self, buf) -> None:
        path = os.path.join(self._tmp, _FRAME_NAME.format(self.n_frames))
        try:
            with open(path, "wb") as f:
                _base.write_all(f, memoryview(buf))
        except OSError as exc:
            if disk_full(exc):
                raise OSError(errno.ENOSPC, f"disk full while writing frame {self.n_frames} of the PNG "
                                            f"sequence {self.out}; the partial output was removed",
                              path) from exc
            raise

    def _finish(self) -> None:
        old = None
        if os.path.isdir(self.out):
            old = os.path.join(self.folder, f".{os.path.basename(self.out)}.old-{os.getpid()}")
            remove(old)
            os.replace(self.out, old)
        try:
            os.replace(self._tmp, self.out)
        except BaseException:
            if old is not None:  # put the previous sequence back
                os.replace(old, self.out)
            raise
        self._tmp = None
        if old is not None:
            remove(old)

    def _cleanup(self) -> None:
        if self._tmp is not None:
            remove(self._tmp)
            self._tmp = None


ENCODERS.register("png", PngWriter, aliases=("png-sequence", "frames"))
