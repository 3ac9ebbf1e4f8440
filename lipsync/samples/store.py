"""The sample store on disk: ``samples.mp4`` (the crops) and ``samples.npz`` (one row per crop).

bank.yaml names them: ``samples: {video: samples.mp4, table: samples.npz}`` (``enabled:
false`` keeps the files and renders one picture per viseme). The table is a NumPy ``.npz``
read with ``allow_pickle=False``; its arrays (N samples, V source clips, P phone labels):

==============  =================  ===========================================================
array           shape, dtype       meaning
==============  =================  ===========================================================
``version``     ``()`` int         :data:`FORMAT_VERSION`
``clips``       ``(V,)`` str       source clip names
``fps``         ``(V,)`` float     each clip's frame rate
``clip``        ``(N,)`` int       which clip the sample is from
``frame``       ``(N,)`` int       its frame index there
``run``         ``(N,)`` int       run id: a run is consecutive frames of one clip, in order
``opening``     ``(N,)`` float     inner-lip gap / eye distance (:mod:`lipsync.face.measure`)
``width``       ``(N,)`` float     mouth-corner distance / eye distance
``protrusion``  ``(N,)`` float     the protrusion proxy
``lips``        ``(N, 44, 2)``     the lip contour points (outer upper, outer lower, inner upper,
                                   inner lower: :mod:`lipsync.face.topology`), bank pixels
``phones``      ``(P,)`` str       phone labels (``sil`` for silence)
``phone``       ``(N,)`` int       index into ``phones``: the phone said at the frame
``prev``/``next`` ``(N,)`` int     the phones before and after it
``origin``      ``(N, 2)`` int     the crop's top-left corner in the source frame (pixels)
``affine``      ``(N, 2, 3)``      crop pixels -> bank pixels (the stabilisation onto the
                                   bank's canonical face frame, the shift of the crop composed)
``appearance``  ``(N, D)`` float   a small grey thumbnail of the mouth box in bank pixels,
                                   mean removed (the selection's appearance distance)
``gain``        ``(N, 3)`` float   per-channel colour gain onto the rest picture's colour
``mask``        ``(H, W)`` uint8   where a sample is shown, bank pixels (0-255, feathered):
                                   the lower face inside the jaw line
``pictures``    ``(K,)`` str       optional: the bank's visemes (its one picture each) ...
``picture_opening`` ``(K,)`` float ... and each picture's lip opening, as ``opening``: the
                                   selection's target blends the openings the one-picture
                                   morph would show (:mod:`lipsync.selection.select`)
``lip_weights`` ``(D, 2)`` float   optional, with the next two: the audio lip model
``lip_bias``    ``(2,)`` float     (:mod:`lipsync.samples.lipmodel`), a ridge regression from
``lip_context`` ``()`` int         a frame's audio features (D = 26 x (2 x context + 1)) to its
                                   opening and width; the selection's target follows the
                                   new speech's prediction (a bank without it: the phones')
==============  =================  ===========================================================

``samples.mp4`` has exactly N frames, all the crop size (H.264 at crf :data:`CROP_CRF`).

Examples
--------
>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "samples.npz"
>>> _ = p.write_bytes(b"not a table")
>>> read_table(p)
Traceback (most recent call last):
...
lipsync.errors.BankError: ...samples.npz: the samples table does not read (...)
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Optional

import numpy as np

from ..errors import BankError

#: bank.yaml's file names.
VIDEO_NAME, TABLE_NAME = "samples.mp4", "samples.npz"
#: Bump when the table's arrays change meaning (an older bank is refused with a message).
FORMAT_VERSION = 1
#: x264 quality of the crops: near-transparent (crf 8 measured a variance-of-Laplacian of the
#: GRID s1 mouth crops within 2% of the PNG originals; crf 12, the plate's, 6% below), and
#: still a few hundred bytes per crop.
CROP_CRF = 8
#: The most samples a bank keeps: 10 minutes at 25 fps (about 0.6 GB of crops decoded at
#: GRID's scale; the table and the crops are the only things held per sample).
MAX_SAMPLES = 15000

#: (array, dtype kind, trailing shape) the table must hold; kinds: i integer, f float, U str.
ARRAYS = (
    ("clips", "U", ()), ("fps", "f", ()), ("clip", "i", ()), ("frame", "i", ()), ("run", "i", ()),
    ("opening", "f", ()), ("width", "f", ()), ("protrusion", "f", ()), ("lips", "f", (44, 2)),
    ("phones", "U", ()), ("phone", "i", ()), ("prev", "i", ()), ("next", "i", ()),
    ("origin", "i", (2,)), ("affine", "f", (2, 3)), ("appearance", "f", None), ("gain", "f", (3,)),
    ("mask", "i", None),
)
#: Arrays a table may hold (banks made before them lack them): the pictures' openings.
OPTIONAL = (("pictures", "U", ()), ("picture_opening", "f", ()))
#: Arrays with one row per sample (the rest are per clip or per phone label).
PER_SAMPLE = ("clip", "frame", "run", "opening", "width", "protrusion", "lips", "phone", "prev", "next",
              "origin", "affine", "appearance", "gain")


def lip_points() -> tuple:
    """The 44 face-mesh indices of a sample's ``lips`` (outer upper, outer lower, inner upper, inner lower)."""
    from ..face import topology as T

    return tuple(T.LIP_OUTER_UPPER + T.LIP_OUTER_LOWER + T.LIP_INNER_UPPER + T.LIP_INNER_LOWER)


@dataclass
class Samples:
    """A bank's samples in memory: the table's arrays (see the module docstring) and the crops.

    Attributes
    ----------
    table : dict
        Array name -> array.
    crops : numpy.ndarray
        ``(N, h, w, 3)`` RGB ``uint8``.
    path : Path
        The table file (for messages).
    """

    table: Dict[str, np.ndarray]
    crops: np.ndarray
    path: Path

    def __len__(self) -> int:
        return len(self.table["frame"])

    def __getattr__(self, name: str):
        table = self.__dict__.get("table")
        if table is not None and name in table:
            return table[name]
        raise AttributeError(name)

    @property
    def labels(self) -> np.ndarray:
        """The phone label of every sample (str array)."""
        return self.table["phones"][self.table["phone"]]

    def successor(self) -> np.ndarray:
        """Per sample, the index of the next frame of its run, or -1 (the run's last)."""
        run = self.table["run"]
        out = np.full(len(run), -1, np.int64)
        same = (run[1:] == run[:-1])
        out[:-1][same] = np.arange(1, len(run))[same]
        return out


def read_table(path: Path) -> Dict[str, np.ndarray]:
    """The samples table at ``path``, validated (every array present, shapes agreeing, finite,
    indices in range, runs in order).

    Raises
    ------
    lipsync.errors.BankError
        Naming the file and what is wrong with it.
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as npz:
            table = {k: npz[k] for k in npz.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise BankError(f"the samples table does not read ({type(exc).__name__}: {exc})", path=path) from None
    problem = _problem(table)
    if problem:
        raise BankError(f"samples table: {problem}", path=path)
    return table


def _problem(t: Dict[str, np.ndarray]) -> Optional[str]:
    """What is wrong with a table, or None."""
    if "version" not in t or t["version"].shape != () or int(t["version"]) != FORMAT_VERSION:
        return f"not format version {FORMAT_VERSION} (made by another lipsync: make the bank again)"
    for name, kind, tail in ARRAYS:
        if name not in t:
            return f"array {name!r} is missing"
        a = t[name]
        if (kind == "U") != (a.dtype.kind == "U") or (kind == "i" and a.dtype.kind not in "iu") or (
                kind == "f" and a.dtype.kind not in "fiu"):
            return f"array {name!r} has type {a.dtype}"
        if tail is not None and a.shape[1:] != tail:
            return f"array {name!r} has shape {a.shape}, not (N, {', '.join(map(str, tail))})" if tail else \
                f"array {name!r} has shape {a.shape}, not one value per row"
        if kind == "f" and not np.isfinite(a).all():
            return f"array {name!r} holds a value that is not a finite number"
    if ("pictures" in t) != ("picture_opening" in t):
        return "arrays 'pictures' and 'picture_opening' come together"
    for name, kind, tail in OPTIONAL if "pictures" in t else ():
        a = t[name]
        if (kind == "U") != (a.dtype.kind == "U") or a.ndim != 1 or (kind == "f" and not np.isfinite(a).all()):
            return f"array {name!r} must be one {'name' if kind == 'U' else 'finite number'} per picture"
    if "pictures" in t and (len(t["pictures"]) != len(t["picture_opening"]) or (t["picture_opening"] < 0).any()):
        return "arrays 'pictures' and 'picture_opening' must pair a name with an opening of 0 or more"
    from .lipmodel import problem as model_problem

    bad_model = model_problem(t)
    if bad_model:
        return bad_model
    n = len(t["frame"])
    if n == 0 or n > MAX_SAMPLES:
        return f"{n} samples (1 to {MAX_SAMPLES})"
    bad = [k for k in PER_SAMPLE if len(t[k]) != n]
    if bad:
        return f"array {bad[0]!r} has {len(t[bad[0]])} rows, 'frame' has {n}"
    if t["appearance"].ndim != 2:
        return "array 'appearance' must be (N, D)"
    if t["mask"].ndim != 2 or t["mask"].max(initial=0) == 0:
        return "array 'mask' must be a non-empty (H, W) picture"
    if len(t["fps"]) != len(t["clips"]) or (t["fps"] <= 0).any():
        return "'fps' must hold one positive rate per clip"
    for name, top in (("clip", len(t["clips"])), ("phone", len(t["phones"])), ("prev", len(t["phones"])),
                      ("next", len(t["phones"]))):
        if (t[name] < 0).any() or (t[name] >= top).any():
            return f"array {name!r} indexes past its {top} entries"
    same = t["run"][1:] == t["run"][:-1]
    if (same & ((t["clip"][1:] != t["clip"][:-1]) | (t["frame"][1:] != t["frame"][:-1] + 1))).any():
        return "a run is not consecutive frames of one clip"
    return None


def load_samples(bank, *, quiet: bool = True) -> Optional[Samples]:
    """The bank's samples (bank.yaml ``samples:``), or None when it has none or they are off.

    Raises
    ------
    lipsync.errors.BankError
        A samples file that does not read or does not agree with the other (names it).

    Examples
    --------
    >>> from lipsync.banks.bank import Bank
    >>> from lipsync._data import default_bank_dir
    >>> load_samples(Bank.load(default_bank_dir())) is None      # a drawn bank has none
    True
    """
    files = getattr(bank, "samples", None)
    if files is None or not files.enabled:
        return None
    table = read_table(files.table)
    if table["mask"].shape != tuple(bank.shape):
        raise BankError(f"samples table: its mask is {table['mask'].shape[1]}x{table['mask'].shape[0]}, the bank "
                        f"{bank.shape[1]}x{bank.shape[0]}", path=files.table)
    crops = read_crops(files.video, len(table["frame"]))
    return Samples(table=table, crops=crops, path=Path(files.table))


def read_crops(path: Path, n: int) -> np.ndarray:
    """The ``n`` crops of ``samples.mp4`` as one ``(n, h, w, 3)`` array (BankError: not a video of ``n`` frames)."""
    from ..errors import InputError
    from ..face.video import probe_video, read_video

    try:
        info = probe_video(path)
        w, h = info.size
        out = np.empty((n, h, w, 3), np.uint8)
        got = 0
        for i, f in enumerate(read_video(path, info=info)):
            if i >= n:
                got = n + 1
                break
            out[i] = f
            got = i + 1
    except InputError as exc:
        raise BankError(f"the sample crops do not read ({exc.reason})", path=path) from None
    if got != n:
        raise BankError(f"{'more than ' if got > n else ''}{min(got, n)} sample crops against {n} rows in "
                        f"{TABLE_NAME}", path=path)
    return out


def samples_wanted(option) -> Optional[bool]:
    """``--samples on|off`` (or True/False/None) as True, False or None (the bank decides).

    Examples
    --------
    >>> samples_wanted("off"), samples_wanted(None), samples_wanted("on")
    (False, None, True)
    """
    if option is None or isinstance(option, bool):
        return option
    text = str(option).strip().lower()
    if text in ("on", "true", "yes", "1"):
        return True
    if text in ("off", "false", "no", "0"):
        return False
    from ..errors import InputError

    raise InputError(f"--samples must be on or off, got {option!r}")
