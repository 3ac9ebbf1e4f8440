"""Outputs written under a temporary name beside ``OUT`` and renamed into place when complete.

Every file lipsync writes goes through here or through an encoder (lipsync.encode), and
both name their temporary output ``.OUT.partial-PID...`` (hidden, beside ``OUT``, carrying
the writer's process id). A failure or Ctrl-C removes it; only a killed process
(SIGKILL, an OOM kill, a power cut) can leave one behind, and then the next write of the
same ``OUT`` removes it: :func:`remove_stale_partials` deletes the partials of ``OUT``
whose process no longer exists (never those of a running writer, and nothing else in the
folder).

Errors name ``OUT``, not the temporary file the OS complained about.

Examples
--------
>>> import os, tempfile
>>> d = tempfile.mkdtemp()
>>> atomic_write_bytes(os.path.join(d, "a.txt"), lambda fh: fh.write(b"hi"))
>>> os.listdir(d), open(os.path.join(d, "a.txt")).read()
(['a.txt'], 'hi')
"""

from __future__ import annotations

import errno
import os
import re
import shutil
from pathlib import Path
from typing import Callable, List, Tuple, Union

PathLike = Union[str, "os.PathLike[str]"]

#: Why a file or folder cannot be written, by errno, in words a user can act on (the
#: messages built on it name OUT or the cache, never a hidden temporary name the OS gave).
WRITE_ERRORS = {
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "the disk quota is used up",
    errno.EROFS: "the file system is read-only",
    errno.EACCES: "no permission to write there",
    errno.EPERM: "no permission to write there",
    errno.EEXIST: "a file stands where a folder on its path must be",
    errno.ENOTDIR: "a file stands where a folder on its path must be",
    errno.ENAMETOOLONG: "the name is too long for the file system",
}

PARTIAL = ".partial-"


def pid_alive(pid: int) -> bool:
    """Whether a process with this id exists (one of another user counts as alive).

    Examples
    --------
    >>> pid_alive(os.getpid()), pid_alive(2**22 + 1)   # Linux pids stop at 2**22
    (True, False)
    """
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (OverflowError, ValueError):  # not a pid this system can have
        return False
    return True


def partial_name(out: PathLike, suffix: str = "") -> str:
    """The temporary name of ``out`` for this process: ``.NAME.partial-PID`` plus ``suffix``.

    Examples
    --------
    >>> partial_name("/x/clip.mp4", ".mp4") == f".clip.mp4.partial-{os.getpid()}.mp4"
    True
    """
    return f".{os.path.basename(os.fspath(out))}{PARTIAL}{os.getpid()}{suffix}"


def remove_stale_partials(out: PathLike, tags: Tuple[str, ...] = ("partial",)) -> List[Path]:
    """Delete ``.NAME.partial-PID*`` files and folders beside ``out`` whose process is gone.

    ``tags``: the words between the name and the pid (an encoder's two-pass video file is
    ``.NAME.video-PID.mp4``).

    Returns what was removed. Partials of live processes (another render of the same
    ``OUT`` running now) and every other file are left alone; errors are ignored (this is
    cleanup, and must never stop the write that called it).

    Examples
    --------
    >>> import tempfile
    >>> d = tempfile.mkdtemp()
    >>> for pid in (os.getpid(), 2**22 + 12345):  # this process, and one that cannot exist
    ...     _ = open(os.path.join(d, f".a.mp4.partial-{pid}.mp4"), "w").write("x")
    >>> [p.name.split("-")[1] for p in remove_stale_partials(os.path.join(d, "a.mp4"))]
    ['4206649.mp4']
    >>> len(os.listdir(d))
    1
    """
    out = Path(os.fspath(out))
    words = "|".join(re.escape(t) for t in tags)
    pattern = re.compile(re.escape(f".{out.name}.") + f"(?:{words})-" + r"(\d+)(?:[-.].*)?$", re.S)
    removed: List[Path] = []
    try:
        entries = list(out.parent.iterdir())
    except OSError:
        return removed
    for p in entries:
        m = pattern.match(p.name)
        if m is None or pid_alive(int(m.group(1))):
            continue
        try:
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            else:
                p.unlink()
            removed.append(p)
        except OSError:
            pass
    return removed


def remove_dead_partials_in(folder: PathLike) -> List[Path]:
    """Every ``.NAME.partial-PID*`` in ``folder`` whose process is gone, removed (for folders
    that are wholly ours, such as a flow store's)."""
    pattern = re.compile(r"^\..+" + re.escape(PARTIAL) + r"(\d+)(?:[-.].*)?$", re.S)
    removed: List[Path] = []
    try:
        entries = list(Path(os.fspath(folder)).iterdir())
    except OSError:
        return removed
    for p in entries:
        m = pattern.match(p.name)
        if m is not None and not pid_alive(int(m.group(1))):
            try:
                shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
                removed.append(p)
            except OSError:
                pass
    return removed


#: Largest file :func:`read_input_bytes` reads whole unless told otherwise: timelines,
#: transcripts, JSON documents. An hour of MFA TextGrid (words and phones) is about 3 MB, so
#: 64 MB is ~20 hours; more is a mistake (or ``/dev/zero``), refused before it fills memory.
MAX_INPUT_BYTES = 64 << 20

#: Deepest JSON nesting :func:`load_json` hands to Python's parser: far beyond any document
#: lipsync reads (an atlas nests 4 levels), far below the ~1000 at which the parser recurses
#: out of stack (``RecursionError``).
MAX_JSON_DEPTH = 100


def read_input_bytes(path: PathLike, what: str, *, error: type = None, limit: int = None,
                     missing: str = "no such file") -> bytes:
    """The bytes of a file the user named, or ``error`` (an :class:`~lipsync.errors.InputError`
    class) naming it: missing, a folder ("not WHAT"), unreadable, or larger than
    :data:`MAX_INPUT_BYTES` ("larger than 64 MB: not WHAT", found after reading no more than
    that: ``/dev/zero`` fails at once). With ``limit``, at most ``limit + 1`` bytes are read
    and returned, so a caller can refuse a larger file (or use a head) itself.

    Examples
    --------
    >>> import tempfile
    >>> from lipsync.errors import InputError
    >>> d = tempfile.mkdtemp()
    >>> try:
    ...     read_input_bytes(d, "a manifest")
    ... except InputError as exc:
    ...     print(str(exc).endswith("is a folder, not a manifest"))
    True
    """
    from .errors import InputError

    error = error or InputError
    bound = MAX_INPUT_BYTES if limit is None else limit
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size if os.path.isfile(path) else None
            if limit is None and size is not None and size > bound:
                raise error(f"larger than {bound >> 20} MB: not {what}", path=path)
            data = _read_at_most(fh, bound + 1, size)
    except FileNotFoundError:
        raise error(missing, path=path) from None
    except IsADirectoryError:
        raise error(f"is a folder, not {what}", path=path) from None
    except OSError as exc:
        raise error(f"cannot read: {exc.strerror or exc}", path=path) from None
    if limit is None and len(data) > bound:
        raise error(f"larger than {bound >> 20} MB: not {what}", path=path)
    return data


def _read_at_most(fh, n: int, size=None) -> bytes:
    """Up to ``n`` bytes of ``fh``, allocating no more than what is there: ``fh.read(n)``
    would reserve ``n`` bytes at once, 64 MB for every small timeline. ``size``: the
    file's size when it is a regular file."""
    if size is not None and size < n:
        return fh.read(size + 1)  # +1: a file that grew since is still seen to be longer
    chunks, got = [], 0
    while got < n:
        chunk = fh.read(min(_READ_CHUNK, n - got))
        if not chunk:
            break
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks)


#: Bytes per read of a file whose size is not known up front (a pipe, ``/dev/zero``).
_READ_CHUNK = 1 << 20


def json_depth(text: str) -> int:
    """How deeply ``text`` (JSON) nests arrays and objects, brackets inside strings not counted.

    Vectorised in chunks of :data:`_DEPTH_CHUNK` bytes (what carries over: the bracket level,
    whether a string is open, a run of backslashes), so a 64 MB document takes well under a
    second and a few MB of temporaries.

    Examples
    --------
    >>> json_depth('{"a": [[1], "]]]"]}'), json_depth("[" * 5000)
    (3, 5000)
    """
    import numpy as np

    if "[" not in text and "{" not in text:
        return 0
    codes = text.encode("utf-8", "surrogatepass")
    if b'"' not in codes:
        return _bracket_depth(np.frombuffer(codes, dtype=np.uint8))
    codes = np.frombuffer(codes, dtype=np.uint8)
    deepest = level = 0
    inside = 0       # 1 while a string is open at the chunk's start
    slashes = 0      # backslashes ending the previous chunk
    for start in range(0, len(codes), _DEPTH_CHUNK):
        c = codes[start:start + _DEPTH_CHUNK]
        n = len(c)
        back = c == 92
        quote = c == 34
        if quote.any() and (slashes or back.any()):
            at = np.flatnonzero(quote)
            # backslashes right before each quote: an odd run escapes it
            pos = np.arange(n, dtype=np.int32)
            last_other = np.maximum.accumulate(np.where(back, np.int32(-1), pos))
            before = np.where(at > 0, last_other[np.maximum(at - 1, 0)], -1)
            run = (at - 1) - before + np.where(before < 0, slashes, 0)
            quote[at[(run & 1) == 1]] = False
        opened = np.bitwise_xor.accumulate(quote.view(np.uint8)) ^ np.uint8(inside)  # 1 inside a string
        step = ((c == 91) | (c == 123)).view(np.int8) - ((c == 93) | (c == 125)).view(np.int8)
        step[opened.view(bool)] = 0
        run_level = np.cumsum(step, dtype=np.int32)
        deepest = max(deepest, level + int(run_level.max()))
        level += int(run_level[-1])
        inside = int(opened[-1])
        if back[-1]:
            other = np.flatnonzero(~back)
            tail = n - 1 - (int(other[-1]) if len(other) else -1)
            slashes = tail + (slashes if tail == n else 0)
        else:
            slashes = 0
    return deepest


def _bracket_depth(codes) -> int:
    """Deepest run of ``[``/``{`` over ``]``/``}`` in the bytes ``codes``, strings not told apart:
    :func:`json_depth` of a text without strings, and at least that depth for any text."""
    import numpy as np

    deepest = level = 0
    for start in range(0, len(codes), _DEPTH_CHUNK):
        c = codes[start:start + _DEPTH_CHUNK]
        run = np.cumsum(((c == 91) | (c == 123)).view(np.int8) - ((c == 93) | (c == 125)).view(np.int8),
                        dtype=np.int32)
        deepest = max(deepest, level + int(run.max()))
        level += int(run[-1])
    return deepest


#: Bytes per step of :func:`json_depth` (a few MB of temporaries).
_DEPTH_CHUNK = 1 << 20


def load_json(text: str, path: PathLike, *, error: type = None, max_depth: int = MAX_JSON_DEPTH):
    """``json.loads(text)``, refusing nesting deeper than ``max_depth`` before parsing (Python's
    parser recurses, and a ``[[[[...`` of 100 kB overflows it) and naming ``path`` in every
    error (``error``, an InputError class; JSON syntax errors give their line).

    Examples
    --------
    >>> load_json('{"a": [1, 2]}', "x.json")
    {'a': [1, 2]}
    >>> load_json("[" * 100000, "deep.json")
    Traceback (most recent call last):
    ...
    lipsync.errors.InputError: deep.json:1: JSON nested 100000 levels deep (at most 100 are read)
    """
    import json

    from .errors import InputError

    error = error or InputError
    import numpy as np

    # the bracket count ignoring strings bounds the depth from above: the exact count (which
    # tells strings apart) only when that bound is over
    over = text.count("[") + text.count("{") > max_depth and _bracket_depth(
        np.frombuffer(text.encode("utf-8", "surrogatepass"), dtype=np.uint8)) > max_depth
    depth = json_depth(text) if over else 0
    if depth > max_depth:
        raise error(f"JSON nested {depth} levels deep (at most {max_depth} are read)", path=path, line=1)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"not valid JSON ({exc.msg})", path=path, line=exc.lineno) from None
    except (ValueError, RecursionError) as exc:
        # an integer of more than 4300 digits hits Python's int-from-text limit
        raise error(f"not usable JSON ({str(exc)[:80]})", path=path, line=1) from None


def _naming(exc: OSError, path: Path) -> OSError:
    """``exc`` again, its message naming ``path`` (the user's OUT, not our temporary file)."""
    return type(exc)(exc.errno, f"cannot write {path}: {exc.strerror or exc}")


def atomic_write_bytes(path: PathLike, data_writer: Callable) -> None:
    """Write a file via a temporary file in its folder, fsync, then rename into place.

    ``data_writer(fh)`` writes the content to the open binary file. A missing folder is
    created (as every command's ``-o`` does); stale partials of ``path`` left by killed
    processes are removed first. An ``OSError`` names ``path``, with its errno kept
    (``ENOSPC``: the disk is full).
    """
    path = Path(os.fspath(path))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _naming(exc, path) from None
    remove_stale_partials(path)
    tmp = path.parent / (partial_name(path) + "-" + os.urandom(4).hex())
    try:
        with open(tmp, "wb") as fh:
            data_writer(fh)
            fh.flush()
            os.fsync(fh.fileno())
        if path.is_dir() and not path.is_symlink():
            raise IsADirectoryError(21, "Is a directory")  # os.replace's own message would name tmp
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            tmp.unlink()
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise _naming(exc, path) from None
        raise


def refuse_output_over_input(outputs, inputs, *, folders=()) -> None:
    """Raise InputError when an output is one of the inputs (issue 38: ``-o`` equal to the
    input replaced it).

    The same file is the same inode, so a hard link, a symbolic link (to the file or to its
    folder) and another spelling of the path are caught as well as the same name. An output
    that is an existing file inside one of ``folders`` (a bank's folder: its pictures,
    bank.yaml, flows) is refused too. Outputs that do not exist yet replace nothing.

    Examples
    --------
    >>> import os, tempfile
    >>> d = tempfile.mkdtemp()
    >>> a = os.path.join(d, "a.wav"); _ = open(a, "wb").write(b"RIFF")
    >>> os.symlink(a, os.path.join(d, "link.wav"))
    >>> refuse_output_over_input([os.path.join(d, "out.mp4")], [a])           # a new file: fine
    >>> refuse_output_over_input([os.path.join(d, "link.wav")], [a])          # doctest: +ELLIPSIS
    Traceback (most recent call last):
    lipsync.errors.InputError: ...link.wav: is the input ...a.wav (the same file); write the output to another name
    """
    from .errors import InputError

    def stat(path):
        try:
            return os.stat(path)
        except (OSError, ValueError):   # missing, a broken link, an unreadable folder, a NUL byte
            return None

    ins = [(os.fspath(p), stat(p)) for p in inputs if p]
    roots = [os.path.realpath(f) for f in folders if f and os.path.isdir(f)]
    for out in outputs:
        if not out:
            continue
        st = stat(out)
        if st is None:
            continue
        for name, ist in ins:
            if ist is not None and os.path.samestat(st, ist):
                raise InputError(f"is the input {name} (the same file); write the output to another name",
                                 path=os.fspath(out))
        real = os.path.realpath(out)
        for root in roots:
            if os.path.isfile(real) and os.path.commonpath([real, root]) == root:
                raise InputError(f"is a file of the bank {root}; write the output outside the bank's folder",
                                 path=os.fspath(out))
