"""Where ``lipsync dub`` keeps data between runs (the cache) and during one (scratch frames).

The cache (``$XDG_CACHE_HOME/lipsync/dub``, or ``--cache DIR``) holds one entry per video
content, ``ROOT/DIGEST/``: ``track.npz`` (the face track) and ``bank-KEY/`` (a bank made from
the video, per map, transcript and language). Its rules:

* An entry that does not load, or loads but fails its checks (points that are not finite, a
  frame rate or size that is not the video's, a bank that does not load), is a miss: it is
  removed and made again.
* Nothing in an entry is a symbolic link: a link is removed, never followed, so a cache that
  someone else wrote into can neither feed a dub data from outside it nor make a dub write
  outside it (a bank's flows are written into the bank's folder).
* What a killed run left (hidden names carrying its process id, :mod:`lipsync._files`) is
  removed by the next run that opens the entry.
* A cache that cannot be written: a ``--cache`` the user named is an error naming it (exit
  2: they asked for that folder, and a dub that silently did not cache would be slow on
  every later run without saying why); the default one (a read-only home, a file where the
  folder should be) gives a warning and the dub goes on without caching, in a temporary
  folder removed when it ends (caching saves time, never changes the result, so it must not
  stop a dub the user did not ask to cache anywhere in particular).

Scratch frames (:class:`FrameStore`): the video's decoded frames, kept when the speech
outlasts the video (the video joined to itself), in an unnamed file in the temporary folder (``TMPDIR``)
that the OS removes with the process however it ends; the room is checked before the first
byte is written, and written with ordinary writes, so a full disk is an error, never the
``SIGBUS`` a memory map of a sparse file gives.

Examples
--------
>>> import tempfile
>>> root = Path(tempfile.mkdtemp())
>>> e = open_entry("0123abcd", root)
>>> e.path == root / "0123abcd", e.temporary
(True, False)
"""

from __future__ import annotations

import errno
import os
import shutil
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from ..errors import InputError, PathLike
from .._files import WRITE_ERRORS

__all__ = ["CacheWarning", "Entry", "FrameStore", "cache_root", "open_entry", "load_track", "save_track",
           "load_bank", "remove_item", "free_bytes"]


class CacheWarning(UserWarning):
    """The cache could not be used; the dub goes on without it."""




def _reason(exc: OSError) -> str:
    return WRITE_ERRORS.get(exc.errno) or exc.strerror or str(exc)


def cache_root() -> Path:
    """Where dub caches live by default: ``$XDG_CACHE_HOME/lipsync/dub`` (``~/.cache/lipsync/dub``),
    beside the flow stores of read-only banks (:meth:`lipsync.morphing.store.FlowStore.for_bank`).

    Examples
    --------
    >>> cache_root().parts[-2:]
    ('lipsync', 'dub')
    """
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "lipsync"
    return base / "dub"


def free_bytes(folder: PathLike) -> int:
    """Bytes free for this user on the file system holding ``folder`` (the one place dub asks,
    so a test can pretend a disk is full).

    Examples
    --------
    >>> free_bytes(tempfile.gettempdir()) > 0
    True
    """
    return shutil.disk_usage(os.fspath(folder)).free


def remove_item(path: Path) -> None:
    """Remove a file, a link (never what it points to) or a folder; errors ignored."""
    try:
        if path.is_symlink() or not path.is_dir():
            path.unlink()
        else:
            shutil.rmtree(path)
    except OSError:
        pass


@dataclass
class Entry:
    """One video's cache folder.

    Attributes
    ----------
    path : Path
        ``ROOT/DIGEST``, a real folder (not a link).
    temporary : bool
        True when the cache could not be written and this is a folder for this run only,
        removed by :meth:`close`, or when the entry is dropped, or at exit, whichever comes
        first (a killed run's is removed by the next run that needs one).
    """

    path: Path
    temporary: bool = False

    def __post_init__(self):
        import weakref

        if self.temporary:
            self._finalizer = weakref.finalize(self, shutil.rmtree, str(self.path.parent), True)

    def close(self) -> None:
        if self.temporary:
            self._finalizer()


#: Name of the temporary folders of runs without a cache (``.lipsync-dub.partial-PID-XXXX``
#: in the temporary folder, so a killed run's is found and removed).
_TEMPORARY = "lipsync-dub"


def _temporary_entry(digest: str) -> Entry:
    from .._files import partial_name, remove_stale_partials

    where = Path(tempfile.gettempdir()) / _TEMPORARY
    remove_stale_partials(where)
    return Entry(Path(tempfile.mkdtemp(prefix=partial_name(where) + "-", dir=where.parent)) / digest,
                 temporary=True)


def _prove_writable(folder: Path) -> None:
    """Make ``folder`` (and its parents) and a file in it, then remove the file: an OSError if
    the folder cannot be written."""
    from .._files import partial_name

    folder.mkdir(parents=True, exist_ok=True)
    if not folder.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "Not a directory", str(folder))
    fd, probe = tempfile.mkstemp(prefix=partial_name(folder / "probe") + "-", dir=folder)
    os.close(fd)
    os.unlink(probe)


def _real_folder(path: Path) -> None:
    """``path`` as a real folder of ours: a link or a file there is removed first."""
    if path.is_symlink() or (path.exists() and not path.is_dir()):
        path.unlink()
    path.mkdir(exist_ok=True)


def open_entry(digest: str, cache: Optional[PathLike] = None) -> Entry:
    """The entry of the video whose content digest is ``digest``, ready to read and write.

    Removes what killed runs left in the cache root and in the entry; replaces an entry that
    is a file or a link by a real folder.

    Parameters
    ----------
    digest : str
    cache : path-like, optional
        The cache root the user named (``--cache``); default :func:`cache_root`.

    Raises
    ------
    InputError
        ``cache`` was named and cannot be written (a file, read-only, no permission).

    Warns
    -----
    CacheWarning
        The default cache cannot be written: the returned entry is a temporary folder.
    """
    from .._files import remove_dead_partials_in

    root = Path(os.fspath(cache)) if cache is not None else cache_root()
    entry = root / digest
    try:
        _prove_writable(root)
        remove_dead_partials_in(root)
        _real_folder(entry)
        _prove_writable(entry)
    except OSError as exc:
        reason = _reason(exc)
        if cache is not None:
            raise InputError(f"cannot write the cache ({reason}): give --cache a folder you can write",
                             path=root) from None
        warnings.warn(f"{root}: cannot write the cache ({reason}); going on without a cache (the face track and "
                      f"the bank are made again on every run; --cache DIR keeps them elsewhere)", CacheWarning,
                      stacklevel=3)
        made = _temporary_entry(digest)
        made.path.mkdir()
        return made
    remove_dead_partials_in(entry)
    return entry_ready(Entry(entry))


def entry_ready(entry: Entry) -> Entry:
    """``entry`` with every link directly inside it removed (never followed)."""
    try:
        for p in entry.path.iterdir():
            if p.is_symlink():
                p.unlink()
    except OSError:
        pass
    return entry


# --------------------------------------------------------------------------- the face track

#: Largest distance (in frame widths/heights) a cached track's point may lie outside the
#: frame: the face mesh places points a little outside a face cut by the frame's edge; far
#: beyond is not a track of this video.
_POINT_MARGIN = 1.0


def load_track(path: Path, info):
    """The face track cached at ``path`` if it is one of the video ``info`` describes, else
    None (the entry is then removed: a miss). Checks: a regular file, not a link; arrays of
    the right shapes; every found frame's points finite and near the frame; the video's frame
    rate and size."""
    from ..face.track import FaceTrack

    if path.is_symlink():
        path.unlink(missing_ok=True)
        return None
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            points, found = np.asarray(z["points"]), np.asarray(z["found"])
            fps, size = float(z["fps"]), tuple(int(v) for v in z["size"])
        ok = (points.ndim == 3 and points.shape[1:] == (468, 3) and len(points) > 0
              and found.shape == (len(points),) and found.dtype == bool
              and abs(fps - float(info.fps)) <= 1e-6 * float(info.fps) and size == tuple(info.size))
        if ok:
            w, h = size
            xy = points[found][..., :2]
            lo, hi = -_POINT_MARGIN * np.array([w, h]), (1 + _POINT_MARGIN) * np.array([w, h])
            ok = bool(np.isfinite(points[found]).all() and ((xy >= lo) & (xy <= hi)).all())
    except Exception:  # any way of not loading is a miss
        ok = False
    if not ok:
        path.unlink(missing_ok=True)
        return None
    return FaceTrack(points=points, raw=points, found=found, fps=fps, size=size, source=str(path))


def save_track(path: Path, track) -> None:
    """Write ``track`` to ``path`` atomically; a cache that cannot be written is left as it is
    (it costs time, not the result)."""
    from .._files import atomic_write_bytes

    def write(f):
        np.savez(f, points=track.points, found=track.found, fps=np.float64(track.fps),
                 size=np.array(track.size, np.int64))

    try:
        atomic_write_bytes(path, write)
    except OSError:
        pass


# --------------------------------------------------------------------------- banks

def _has_link(folder: Path) -> bool:
    for top, dirs, files in os.walk(folder, followlinks=False):
        for name in dirs + files:
            if os.path.islink(os.path.join(top, name)):
                return True
    return False


def load_bank(folder: Path):
    """The bank cached in ``folder`` if it is a real folder (no link in it or at it) and loads,
    else None, the entry removed (a miss)."""
    from ..banks.bank import Bank

    if not folder.is_symlink() and not folder.exists():
        return None
    if folder.is_symlink() or not folder.is_dir() or _has_link(folder):
        remove_item(folder)
        return None
    try:
        return Bank.load(folder)
    except Exception:  # a broken entry is a miss
        remove_item(folder)
        return None


# --------------------------------------------------------------------------- scratch frames

#: Room left free on the temporary folder's disk beyond the kept frames: the output is
#: often on the same disk and the encoder needs room for it (a 30 s 720p dub is ~20 MB).
SCRATCH_MARGIN = 64 << 20


class FrameStore:
    """``count`` frames of ``shape`` (uint8), written once each and read back by index, in an
    unnamed file in ``folder`` (default: the temporary folder).

    Raises
    ------
    InputError
        Not enough room in ``folder`` (checked before anything is written), or a write failed
        there (the message names the folder and what is missing).

    Examples
    --------
    >>> s = FrameStore(2, (2, 2, 3))
    >>> s.put(1, np.full((2, 2, 3), 7, np.uint8)); int(s.get(1).sum())
    84
    >>> s.close()
    """

    def __init__(self, count: int, shape, *, folder: Optional[PathLike] = None, what: str = "the video's frames"):
        self.folder = Path(os.fspath(folder or tempfile.gettempdir()))
        self.shape = tuple(int(v) for v in shape)
        self.frame_bytes = int(np.prod(self.shape))
        need = int(count) * self.frame_bytes
        try:
            free = free_bytes(self.folder)
        except OSError as exc:
            raise InputError(f"cannot keep {what} there: {_reason(exc)} (set TMPDIR to a folder you can write)",
                             path=self.folder) from None
        if need + SCRATCH_MARGIN > free:
            raise InputError(f"not enough free space for {what} ({_mb(need)} needed, plus {_mb(SCRATCH_MARGIN)} "
                             f"spare; {_mb(free)} free): set TMPDIR to a folder on a disk with room", path=self.folder)
        self.what = what
        try:
            # O_TMPFILE on Linux: never has a name, so nothing is left whatever ends the process
            self._file = tempfile.TemporaryFile(dir=self.folder)
        except OSError as exc:
            raise InputError(f"cannot keep {what} there: {_reason(exc)} (set TMPDIR to a folder you can write)",
                             path=self.folder) from None
        self._fd = self._file.fileno()

    def put(self, i: int, frame: np.ndarray) -> None:
        data = memoryview(np.ascontiguousarray(frame)).cast("B")
        at, done = i * self.frame_bytes, 0
        try:
            while done < len(data):
                done += os.pwrite(self._fd, data[done:], at + done)
        except OSError as exc:
            raise InputError(f"cannot write: {'disk full' if exc.errno == errno.ENOSPC else _reason(exc)} "
                             f"(keeping {self.what})", path=self.folder) from None

    def get(self, i: int) -> np.ndarray:
        out = np.empty(self.shape, np.uint8)
        got = os.preadv(self._fd, [out], i * self.frame_bytes)
        if got != self.frame_bytes:
            raise OSError(errno.EIO, f"frame {i} of {self.what}: {got} of {self.frame_bytes} bytes read back")
        return out

    def close(self) -> None:
        self._file.close()


def _mb(n: int) -> str:
    return f"{n / 2 ** 20:.0f} MB"
