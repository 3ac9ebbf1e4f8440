"""Error types that may escape the library.

Every error caused by a user's input is an :class:`InputError` (a ``ValueError``) whose
message names the file and, where it applies, the line, viseme or line segment. The CLI
turns these into exit code 2; anything else is a bug or an environment failure (exit 1).
"""

from __future__ import annotations

import os
from typing import Optional, Union

PathLike = Union[str, "os.PathLike[str]"]


class InputError(ValueError):
    """Bad user input: a file, option or value that cannot be used as given.

    Parameters
    ----------
    message : str
        What is wrong, in words a user can act on.
    path : path-like, optional
        The file the problem is in; prefixed to the message.
    line : int, optional
        1-based line number inside ``path``.

    Examples
    --------
    >>> str(InputError("end before start", path="a.phn", line=3))
    'a.phn:3: end before start'
    """

    def __init__(self, message: str, *, path: Optional[PathLike] = None, line: Optional[int] = None):
        self.reason = message
        self.path = os.fspath(path) if path is not None else None
        self.line = line
        where = ""
        if self.path is not None:
            where = self.path + (f":{line}" if line is not None else "") + ": "
        elif line is not None:
            where = f"line {line}: "
        super().__init__(where + message)


class TranscriptMismatch(UserWarning):
    """A transcript that does not fit its speech at all (the aligner's confidence is below
    :data:`lipsync.speech.align.NO_FIT_CONFIDENCE`).

    The library warns (:class:`lipsync.speech.align.TranscriptMismatchWarning`, also an
    ``AlignmentWarning``); the command line makes it an error (exit 2) unless
    ``--allow-mismatch`` is given. Defined here so the CLI can name it without loading
    the aligner.
    """


class BankError(InputError):
    """A viseme bank (``bank.yaml`` or its images) is invalid."""


class TimelineError(InputError):
    """A phoneme or viseme timeline file cannot be read."""


class MapError(InputError):
    """A phoneme-to-viseme map is invalid."""


class UnknownNameError(InputError, KeyError):
    """A name that is not in a registry; the message lists the valid ones."""

    def __str__(self) -> str:  # KeyError would otherwise quote the message
        return ValueError.__str__(self)


def check_number(value, name: str, lo: float, hi: float, *, integer: bool = False, lo_open: bool = False) -> float:
    """``value`` as a float (or int) if it is a finite number within ``lo..hi``, else InputError naming ``name``.

    For options: NaN, infinities, text and out-of-range values all get the same message,
    which names the option and the range (``lo_open``: ``lo`` itself excluded).

    Examples
    --------
    >>> check_number("2.5", "--idle-timeout", 0, 86400, lo_open=True)
    2.5
    >>> check_number(float("nan"), "--idle-timeout", 0, 86400, lo_open=True)
    Traceback (most recent call last):
    ...
    lipsync.errors.InputError: --idle-timeout must be a number above 0 and at most 86400, got nan
    """
    import math

    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        number = math.nan
    ok = math.isfinite(number) and (number > lo if lo_open else number >= lo) and number <= hi
    if ok and integer:
        ok = number == int(number)
    if not ok:
        low = f"above {lo:g}" if lo_open else f"at least {lo:g}"
        kind = "a whole number" if integer else "a number"
        raise InputError(f"{name} must be {kind} {low} and at most {hi:g}, got {value!r}"
                         if not isinstance(value, float) else
                         f"{name} must be {kind} {low} and at most {hi:g}, got {value:g}")
    return int(number) if integer else number

