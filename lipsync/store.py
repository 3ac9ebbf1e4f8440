"""The flow store: precomputed pixel flows on disk, content-addressed (black's cache.py style).

One entry per unordered viseme pair {A, B} (A before B in bank order) holds the forward
flow (on A's grid) and the backward flow (on B's grid). The key is a sha256 of a format
version, both images' pixels, both line sets, the warp parameters and the mirror axis, so
editing one viseme changes only the keys of the pairs that involve it.

Storage, per entry (``<store>/flows/<key>.npz``, an uncompressed numpy zip):

* each field first loses a dead zone: displacements are shrunk by :data:`FLOW_DEADZONE`
  px (``d * max(0, 1 - deadzone / |d|)``, continuous, so no seam), which makes the static
  parts of the face exactly still;
* each field is cropped to the box where its displacement is non-zero, the box made
  symmetric about the axis when the lines are, and then only its left half kept;
* values are float16 displacements: for |d| < 64 px the rounding error is at most
  2**-11 * |d| <= 0.031 px (<= 0.004 px for |d| < 8 px), well under bilinear sampling's
  own error, at half the bytes of float32;
* a ``meta`` member (JSON bytes) repeats the key and carries a sha256 of the arrays, so a
  flipped or cut byte is detected, on top of the zip's own CRC.

Writes go to a temporary file in the same folder, fsync, then ``os.replace``: readers see a
whole entry or none. Any entry that is missing, short, corrupt or from another version is a
cache miss (with a warning when it existed), never a crash. The zip members carry a fixed
timestamp, so the same inputs give byte-identical files whatever the run.
"""

from __future__ import annotations

import errno
import hashlib
import io
import json
import os
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Tuple

import numpy as np

from .bank import Bank

#: Bump when the flow computation or the entry layout changes: old entries become misses.
FORMAT_VERSION = 3
#: Every stored displacement is shrunk by this many pixels (and so is zero below it).
#: Beier-Neely weights fall off only as 1/dist^b, so a moving mouth drags the whole face
#: by tenths of a pixel: motion nobody wants (the anchors are there to hold the face
#: still) that would also force the renderer to redraw the whole frame. A quarter pixel
#: is below what a viewer sees as motion; shrinking (rather than cutting) keeps the
#: field continuous, so no seam appears where it reaches zero.
FLOW_DEADZONE = 0.25
#: Displacements at or below this (px) after the dead zone count as zero for cropping.
CROP_EPS = 1e-6
_ZIP_TIME = (2000, 1, 1, 0, 0, 0)
_TMP_PREFIX = ".tmp-"


class StoreWarning(UserWarning):
    """A store entry was unusable and is being recomputed."""


@dataclass(frozen=True)
class Crop:
    """Where a stored field is non-zero: rows ``[y0, y1)``, columns ``[x0, x1)``."""

    y0: int
    y1: int
    x0: int
    x1: int

    @property
    def empty(self) -> bool:
        return self.y1 <= self.y0 or self.x1 <= self.x0


def support_box(field: np.ndarray, axis: Optional[float], eps: float = None) -> Crop:
    """Bounding box of ``|field| > eps``, made symmetric about ``axis`` when given.

    Examples
    --------
    >>> f = np.zeros((5, 6, 2), np.float32); f[1:3, 1, 0] = 1.0
    >>> support_box(f, None)
    Crop(y0=1, y1=3, x0=1, x1=2)
    >>> support_box(f, 2.5)
    Crop(y0=1, y1=3, x0=1, x1=5)
    """
    eps = CROP_EPS if eps is None else eps
    h, w = field.shape[:2]
    mask = (np.abs(field[..., 0]) > eps) | (np.abs(field[..., 1]) > eps)
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return Crop(0, 0, 0, 0)
    y0, y1, x0, x1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
    if axis is not None:
        two_c = int(round(2 * axis))
        lo = min(x0, two_c - (x1 - 1))
        hi = max(x1 - 1, two_c - x0)
        if lo >= 0 and hi < w:
            x0, x1 = lo, hi + 1
    return Crop(y0, y1, x0, x1)


def apply_deadzone(field: np.ndarray, deadzone: Optional[float] = None) -> np.ndarray:
    """Shrink every displacement by ``deadzone`` px: ``d * max(0, 1 - deadzone / |d|)``.

    Examples
    --------
    >>> apply_deadzone(np.array([[[3.0, 4.0], [0.1, 0.0]]], np.float32), 0.5)[0].tolist()
    [[2.700000047683716, 3.5999999046325684], [0.0, 0.0]]
    """
    deadzone = FLOW_DEADZONE if deadzone is None else deadzone
    mag = np.hypot(field[..., 0], field[..., 1])
    scale = np.maximum(mag - deadzone, 0.0) / np.maximum(mag, 1e-12)
    return (field * scale[..., None]).astype(np.float32)


def _npy_bytes(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.ascontiguousarray(arr), allow_pickle=False)
    return buf.getvalue()


def _digest(arrays: Dict[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(name.encode() + str(a.dtype).encode() + repr(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _entry_bytes(meta: dict, arrays: Dict[str, np.ndarray]) -> bytes:
    """The bytes of a store entry: an uncompressed zip of .npy members, fixed timestamps."""
    members = dict(arrays)
    members["meta"] = np.frombuffer(json.dumps(meta, sort_keys=True).encode(), dtype=np.uint8)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        for name in sorted(members):
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_TIME)
            info.external_attr = 0o644 << 16
            zf.writestr(info, _npy_bytes(members[name]))
    return buf.getvalue()


def _clean_stale_temps(folder: Path) -> None:
    """Remove temp files left by processes that no longer exist (killed mid-write)."""
    try:
        entries = list(folder.iterdir())
    except OSError:
        return
    for p in entries:
        if not p.name.startswith(_TMP_PREFIX):
            continue
        try:
            pid = int(p.name[len(_TMP_PREFIX):].split("-")[0])
            os.kill(pid, 0)
            continue  # its writer is alive
        except (ValueError, ProcessLookupError):
            pass
        except PermissionError:
            continue
        try:
            p.unlink()
        except OSError:
            pass


def atomic_write_bytes(path: Path, data_writer) -> None:
    """Write a file via a temp file in its folder, fsync, then rename into place.

    ``data_writer(fh)`` writes the content to the open binary file.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f"{_TMP_PREFIX}{os.getpid()}-{os.urandom(4).hex()}"
    try:
        with open(tmp, "wb") as fh:
            data_writer(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise


class FlowStore:
    """Content-addressed on-disk cache of pair flows and normalised images.

    Parameters
    ----------
    root : path-like
        The store folder (created on first write). By default a bank keeps its store in
        ``<bank>/.lipsync``.

    Examples
    --------
    >>> import tempfile
    >>> from lipsync.bank import Bank
    >>> from lipsync._data import default_bank_dir
    >>> bank = Bank.load(default_bank_dir())
    >>> store = FlowStore(tempfile.mkdtemp())
    >>> store.get_pair(bank, bank.names[0], bank.names[1]) is None   # not computed yet
    True
    """

    def __init__(self, root):
        self.root = Path(root)

    @classmethod
    def for_bank(cls, bank: Bank, root=None) -> "FlowStore":
        """The store at ``root``, else ``<bank>/.lipsync``, else a per-user cache folder.

        The fallback serves banks in read-only places (a system-wide install): their
        flows go to ``$XDG_CACHE_HOME/lipsync/<hash of the bank path>``.
        """
        if root is not None:
            return cls(root)
        default = bank.path / ".lipsync"
        if os.access(default if default.exists() else bank.path, os.W_OK):
            return cls(default)
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "lipsync"
        tag = hashlib.sha256(str(bank.path.resolve()).encode()).hexdigest()[:16]
        return cls(base / f"{bank.name}-{tag}")

    # ----------------------------------------------------------------------- keys
    @staticmethod
    def _key(parts: List[bytes]) -> str:
        h = hashlib.sha256()
        for part in parts:
            h.update(len(part).to_bytes(8, "little"))
            h.update(part)
        return h.hexdigest()

    def pair_key(self, bank: Bank, a: str, b: str, axis: Optional[float]) -> str:
        """The key of the entry for the ordered pair (a, b)."""
        w = bank.warp
        return self._key([
            f"lipsync-flow-v{FORMAT_VERSION}".encode(),
            repr(bank.shape).encode(),
            bank.image_digest(a).encode(), bank.image_digest(b).encode(),
            np.ascontiguousarray(bank.lines[a]).tobytes(), np.ascontiguousarray(bank.lines[b]).tobytes(),
            "\0".join(bank.line_names).encode(),
            json.dumps([w.a, w.b, w.p, bank.symmetry, axis]).encode(),
        ])

    def image_key(self, bank: Bank, v: str, axis: Optional[float]) -> str:
        w = bank.warp
        return self._key([
            f"lipsync-image-v{FORMAT_VERSION}".encode(),
            bank.image_digest(v).encode(),
            np.ascontiguousarray(bank.lines[v]).tobytes(),
            "\0".join(bank.line_names).encode(),
            json.dumps([w.a, w.b, w.p, axis]).encode(),
        ])

    def pair_path(self, key: str) -> Path:
        return self.root / "flows" / f"{key}.npz"

    def image_path(self, key: str) -> Path:
        return self.root / "images" / f"{key}.npz"

    # ----------------------------------------------------------------------- entries
    def _write_entry(self, path: Path, meta: dict, arrays: Dict[str, np.ndarray]) -> None:
        data = _entry_bytes(dict(meta, sha256=_digest(arrays), version=FORMAT_VERSION), arrays)
        atomic_write_bytes(path, lambda fh: fh.write(data))

    def _read_entry(self, path: Path, key: str) -> Optional[Tuple[dict, Dict[str, np.ndarray]]]:
        if not path.exists():
            return None
        try:
            data = path.read_bytes()
            with np.load(io.BytesIO(data), allow_pickle=False) as npz:
                arrays = {name: npz[name] for name in npz.files}
            meta = json.loads(arrays.pop("meta").tobytes().decode())
            if meta.get("version") != FORMAT_VERSION or meta.get("key") != key:
                raise ValueError("entry is for other inputs or another format version")
            if meta.get("sha256") != _digest(arrays):
                raise ValueError("checksum mismatch")
            # Found by the crash-safety tests: a flipped byte in the zip headers (timestamps,
            # the local CRC and sizes, the central directory) is covered by neither the CRC
            # nor the checksum and loaded fine. Entries are byte-deterministic, so a sound
            # entry re-encodes to exactly its own bytes.
            if _entry_bytes(meta, arrays) != data:
                raise ValueError("zip structure damaged (entry does not re-encode to its bytes)")
            return meta, arrays
        except Exception as exc:  # any damage is a miss: recompute, never crash
            warnings.warn(f"{path}: unusable flow store entry ({type(exc).__name__}: {exc}); "
                          f"recomputing it", StoreWarning, stacklevel=3)
            return None

    # ----------------------------------------------------------------------- pairs
    def put_pair(self, key: str, forward: np.ndarray, backward: np.ndarray, *, axis: Optional[float],
                 names: Tuple[str, str] = ("", "")) -> int:
        """Store a pair's flows under ``key`` (after the dead zone); returns the entry's size in bytes."""
        arrays: Dict[str, np.ndarray] = {}
        meta: dict = {"key": key, "kind": "pair", "names": list(names), "shape": list(forward.shape[:2]),
                      "axis": axis, "deadzone": FLOW_DEADZONE}
        for name, field in (("forward", forward), ("backward", backward)):
            field = apply_deadzone(field)
            crop = support_box(field, axis)
            part = field[crop.y0:crop.y1, crop.x0:crop.x1]
            half = None
            if axis is not None and not crop.empty:
                local_axis = axis - crop.x0
                if 2 * local_axis == (crop.x1 - crop.x0 - 1):  # box symmetric: keep left half
                    half = int(np.floor(local_axis)) + 1
                    part = part[:, :half]
            arrays[name] = part.astype(np.float16)
            meta[name] = {"crop": [crop.y0, crop.y1, crop.x0, crop.x1], "half": half}
        path = self.pair_path(key)
        self._write_entry(path, meta, arrays)
        return path.stat().st_size

    def load_pair(self, key: str, shape: Tuple[int, int]) -> Optional[Tuple["StoredField", "StoredField"]]:
        """The stored (forward, backward) fields for ``key``, or None (a miss)."""
        entry = self._read_entry(self.pair_path(key), key)
        if entry is None:
            return None
        meta, arrays = entry
        try:
            if tuple(meta["shape"]) != tuple(shape):
                raise ValueError(f"entry is for images of shape {meta['shape']}, not {list(shape)}")
            fields = tuple(StoredField.from_entry(meta[name], arrays[name], shape, meta["axis"])
                           for name in ("forward", "backward"))
        except (KeyError, TypeError, ValueError) as exc:
            warnings.warn(f"{self.pair_path(key)}: unusable flow store entry ({exc}); recomputing it",
                          StoreWarning, stacklevel=2)
            return None
        return fields  # type: ignore[return-value]

    def get_pair(self, bank: Bank, a: str, b: str) -> Optional[Tuple["StoredField", "StoredField"]]:
        """Flows for the ordered pair (a, b) if stored: ``(forward on a, backward on b)``."""
        from .normalise import bank_axis

        axis = bank_axis(bank) if bank.symmetry else None
        i, j = bank.names.index(a), bank.names.index(b)
        if i <= j:
            return self.load_pair(self.pair_key(bank, a, b, axis), bank.shape)
        got = self.load_pair(self.pair_key(bank, b, a, axis), bank.shape)
        return None if got is None else (got[1], got[0])

    # ----------------------------------------------------------------------- normalised images
    def get_normalised(self, bank: Bank, v: str, axis: Optional[float]) -> Optional[np.ndarray]:
        key = self.image_key(bank, v, axis)
        entry = self._read_entry(self.image_path(key), key)
        if entry is None:
            return None
        img = entry[1].get("image")
        if img is None or img.shape != bank.images[v].shape or img.dtype != np.uint8:
            return None
        return img

    def put_normalised(self, bank: Bank, v: str, axis: Optional[float], image: np.ndarray) -> None:
        key = self.image_key(bank, v, axis)
        try:
            self._write_entry(self.image_path(key), {"key": key, "kind": "image", "name": v}, {"image": image})
        except OSError as exc:
            if exc.errno not in (errno.EACCES, errno.EROFS, errno.EPERM):
                raise
            # A read-only bank (installed package) still renders; it just cannot cache.

    # ----------------------------------------------------------------------- housekeeping
    def clean_temps(self) -> None:
        for sub in ("flows", "images"):
            _clean_stale_temps(self.root / sub)

    def entries(self) -> Iterator[Path]:
        for sub in ("flows", "images"):
            folder = self.root / sub
            if folder.is_dir():
                yield from sorted(p for p in folder.iterdir() if p.suffix == ".npz")

    def size_bytes(self) -> int:
        """Bytes on disk of all entries."""
        return sum(p.stat().st_size for p in self.entries())


@dataclass(frozen=True)
class StoredField:
    """A flow field as stored: a float16 crop, expanded on demand.

    Attributes
    ----------
    shape : (int, int)
        Full image shape.
    crop : Crop
        Where the field is non-zero; zero elsewhere.
    data : numpy.ndarray
        float32 ``(crop height, crop width, 2)`` displacement inside ``crop``.
    """

    shape: Tuple[int, int]
    crop: Crop
    data: np.ndarray

    @classmethod
    def from_entry(cls, meta: dict, arr: np.ndarray, shape, axis) -> "StoredField":
        y0, y1, x0, x1 = (int(v) for v in meta["crop"])
        h, w = int(shape[0]), int(shape[1])
        crop = Crop(y0, y1, x0, x1)
        if not (0 <= y0 <= y1 <= h and 0 <= x0 <= x1 <= w) or arr.ndim != 3 or arr.shape[2] != 2:
            raise ValueError("crop box or field shape out of range")
        half = meta.get("half")
        data = np.zeros((y1 - y0, x1 - x0, 2), np.float32)
        if half is not None:
            if axis is None or arr.shape != (y1 - y0, int(half), 2):
                raise ValueError("half-field does not fit its crop box")
            from .flows import mirror_fill

            data[:, :half] = arr
            mirror_fill(data, axis - x0)
        else:
            if arr.shape != data.shape:
                raise ValueError("field does not fit its crop box")
            data[:] = arr
        if not np.all(np.isfinite(data)):
            raise ValueError("non-finite values in field")
        return cls(shape=(h, w), crop=crop, data=data)

    def full(self) -> np.ndarray:
        """The whole ``(H, W, 2)`` float32 field.

        Examples
        --------
        >>> f = StoredField((2, 3), Crop(0, 1, 1, 2), np.ones((1, 1, 2), np.float32))
        >>> f.full()[..., 0].tolist()
        [[0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]
        """
        out = np.zeros(self.shape + (2,), np.float32)
        c = self.crop
        out[c.y0:c.y1, c.x0:c.x1] = self.data
        return out
