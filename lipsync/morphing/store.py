"""The flow store: precomputed pixel flows on disk, content-addressed (black's cache.py style).

One entry per unordered viseme pair {A, B} (A before B in bank order) holds the forward
flow (on A's grid) and the backward flow (on B's grid). The key is a sha256 of a format
version, both images' pixels, both line sets, the warp parameters and the mirror axis, so
editing one viseme changes only the keys of the pairs that involve it.

Storage, per entry (``<store>/flows/<key>.flow``, one flat file, memory-mapped when read):

* each field first loses a dead zone: displacements are shrunk by :data:`FLOW_DEADZONE`
  px (``d * max(0, 1 - deadzone / |d|)``, continuous, so no seam), which makes the static
  parts of the face exactly still;
* each field is cropped to the box where its displacement is non-zero, the box made
  symmetric about the axis when the lines are, and then only its left half kept;
* values are float16 displacements: for ``|d| < 64`` px the rounding error is at most
  ``2**-11 * |d| <= 0.031`` px (``<= 0.004`` px for ``|d| < 8`` px), well under bilinear sampling's
  own error, at half the bytes of float32;
* the **inverse maps** every frame needs (:func:`lipsync.morphing.flows.inverse_tables`): for each
  side, the displacement ``X - Y`` with ``X + t F(X) = Y`` at ``t = k / TABLE_STEPS``, on
  the coarse grid (every :data:`~lipsync.morphing.flows.SOLVE_STEP`-th pixel) of the box where
  either field moves, as int16 in 1/:data:`TABLE_SCALE` px (error <= 0.008 px, range
  +-512 px), left half only when the box is mirror-symmetric. The renderer reads them
  straight from the mapped file: a pair's first frame costs one checksum pass, no solve;
* layout: 8 magic bytes, a CRC-32 of everything after it, the header length, a JSON header
  (key, version, crops, table geometry, each array's dtype/shape/offset) and the arrays at
  64-byte-aligned offsets. Any flipped, cut or added byte fails the CRC.

Writes go to a temporary file in the same folder, fsync, then ``os.replace``: readers see a
whole entry or none (and a mapped entry is never rewritten in place). Any entry that is
missing, short, corrupt or from another version is a cache miss (with a warning when it
existed), never a crash. The same inputs give byte-identical files whatever the run.
Normalised images are stored as uncompressed numpy zips with a sha256 inside.
"""

from __future__ import annotations

import errno
import hashlib
import io
import json
import mmap
import os
import struct
import warnings
import zipfile
import zlib
from dataclasses import dataclass, field as dc_field
from pathlib import Path
from typing import Callable, Dict, Iterator, List, Optional, Tuple

import numpy as np

from .._files import atomic_write_bytes, remove_dead_partials_in
from ..banks.bank import Bank

#: Bump when the flow computation or the entry layout changes: old entries become misses.
#: 4: flat memory-mapped entries with the inverse-map tables.
FORMAT_VERSION = 4
#: Every stored displacement is shrunk by this many pixels (and so is zero below it).
#: Beier-Neely weights fall off only as 1/dist^b, so a moving mouth drags the whole face
#: by tenths of a pixel: motion nobody wants (the anchors are there to hold the face
#: still) that would also force the renderer to redraw the whole frame. A quarter pixel
#: is below what a viewer sees as motion; shrinking (rather than cutting) keeps the
#: field continuous, so no seam appears where it reaches zero.
FLOW_DEADZONE = 0.25
#: Displacements at or below this (px) after the dead zone count as zero for cropping.
CROP_EPS = 1e-6
#: Inverse-map tables are int16 in 1/TABLE_SCALE px: 1/64 px steps (rounding error
#: <= 0.008 px, below float16's for displacements over 16 px) and +-512 px of range, at the
#: bytes of float16 -- and integers are what the render kernel reads without conversion.
TABLE_SCALE = 64
#: Pixels the tables' box reaches beyond where either field moves: bilinear taps reach one
#: pixel out, and the inverse of a field that vanishes at the box edge must too.
TABLE_MARGIN = 2
_ZIP_TIME = (2000, 1, 1, 0, 0, 0)
_TMP_PREFIX = ".tmp-"
_MAGIC = b"LSFLOW\r\n"
_ALIGN = 64


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
    >>> np.round(apply_deadzone(np.array([[[3.0, 4.0], [0.1, 0.0]]], np.float32), 0.5)[0].astype(float), 4).tolist()
    [[2.7, 3.6], [0.0, 0.0]]
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


def _clear_the_way(path: Path) -> None:
    """A folder where an entry belongs is damage in our own store: removed, so the entry can
    be written (it was a miss for reading already)."""
    if path.is_dir() and not path.is_symlink():
        import shutil

        shutil.rmtree(path, ignore_errors=True)


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
    >>> from lipsync.banks.bank import Bank
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
        from .flows import SOLVE_STEP, TABLE_ITERATIONS, TABLE_STEPS
        from .refine import REFINE_VERSION

        w = bank.warp
        return self._key([
            f"lipsync-flow-v{FORMAT_VERSION}".encode(),
            # how the inverse tables are made: changing any of these must miss old entries
            json.dumps([TABLE_STEPS, TABLE_ITERATIONS, SOLVE_STEP, TABLE_SCALE, TABLE_MARGIN]).encode(),
            repr(bank.shape).encode(),
            bank.image_digest(a).encode(), bank.image_digest(b).encode(),
            np.ascontiguousarray(bank.lines[a]).tobytes(), np.ascontiguousarray(bank.lines[b]).tobytes(),
            "\0".join(bank.line_names).encode(),
            json.dumps([w.a, w.b, w.p, bank.symmetry, axis]).encode(),
            # refined flows (lipsync.morphing.refine) are other fields: their own keys, and a new
            # version of the refinement misses the old ones
            *([f"refine-v{REFINE_VERSION}".encode()] if bank.refine else []),
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
        return self.root / "flows" / f"{key}.flow"

    def image_path(self, key: str) -> Path:
        return self.root / "images" / f"{key}.npz"

    # ----------------------------------------------------------------------- entries
    def _write_entry(self, path: Path, meta: dict, arrays: Dict[str, np.ndarray]) -> None:
        data = _entry_bytes(dict(meta, sha256=_digest(arrays), version=FORMAT_VERSION), arrays)
        _clear_the_way(path)
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
        """Store a pair's flows and inverse tables under ``key``; returns the entry's size in bytes."""
        meta, arrays = pack_pair(forward, backward, axis=axis)
        meta.update(key=key, kind="pair", names=list(names), version=FORMAT_VERSION)
        data = _flat_entry_bytes(meta, arrays)
        path = self.pair_path(key)
        _clear_the_way(path)
        atomic_write_bytes(path, lambda fh: fh.write(data))
        return len(data)

    def load_pair(self, key: str, shape: Tuple[int, int]) -> Optional[Tuple["StoredField", "StoredField"]]:
        """The stored (forward, backward) fields for ``key``, or None (a miss).

        The entry is memory-mapped and its CRC checked; the arrays are views of the map.
        """
        path = self.pair_path(key)
        if not path.exists():
            return None
        try:
            meta, arrays = _read_flat_entry(path)
            if meta.get("version") != FORMAT_VERSION or meta.get("key") != key:
                raise ValueError("entry is for other inputs or another format version")
            if tuple(meta["shape"]) != tuple(shape):
                raise ValueError(f"entry is for images of shape {meta['shape']}, not {list(shape)}")
            return unpack_pair(meta, arrays, shape)
        except Exception as exc:  # any damage is a miss: recompute, never crash
            warnings.warn(f"{path}: unusable flow store entry ({type(exc).__name__}: {exc}); recomputing it",
                          StoreWarning, stacklevel=2)
            return None

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
    # ----------------------------------------------------------------------- sample joins
    def join_key(self, parts: List[bytes]) -> str:
        """The key of a flow between two mouth samples (lipsync.composite.samples): its inputs' bytes."""
        return self._key([f"lipsync-join-v{FORMAT_VERSION}".encode(), *parts])

    def join_path(self, key: str) -> Path:
        return self.root / "joins" / f"{key}.npz"

    def get_join(self, key: str) -> Optional[np.ndarray]:
        """The stored flow for ``key``, or None (absent or damaged: a miss, with a warning)."""
        got = self._read_entry(self.join_path(key), key)
        return None if got is None or "flow" not in got[1] else got[1]["flow"]

    def put_join(self, key: str, flow: np.ndarray) -> None:
        """Store a join's flow under ``key`` (written atomically)."""
        self._write_entry(self.join_path(key), {"key": key, "kind": "join"},
                          {"flow": np.ascontiguousarray(flow, np.float32)})

    def clean_temps(self) -> None:
        for sub in ("flows", "images"):
            _clean_stale_temps(self.root / sub)  # the ".tmp-PID-..." of earlier versions
            remove_dead_partials_in(self.root / sub)

    def entries(self) -> Iterator[Path]:
        """Every entry file: pair flows (``.flow``; ``.npz`` from format 3 and older) and images."""
        for sub in ("flows", "images"):
            folder = self.root / sub
            if folder.is_dir():
                yield from sorted(p for p in folder.iterdir() if p.suffix in (".npz", ".flow"))

    def size_bytes(self) -> int:
        """Bytes on disk of all entries."""
        return sum(p.stat().st_size for p in self.entries())


def _flat_entry_bytes(meta: dict, arrays: Dict[str, np.ndarray]) -> bytes:
    """A flat entry: magic, CRC-32 of the rest, header length, JSON header, aligned arrays."""
    members = {}
    offset = 0
    blobs = []
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        offset = -(-offset // _ALIGN) * _ALIGN
        members[name] = {"dtype": a.dtype.str, "shape": list(a.shape), "offset": offset}
        blobs.append((offset, a.tobytes()))
        offset += a.nbytes
    header = json.dumps(dict(meta, members=members), sort_keys=True).encode()
    # the arrays start at an aligned position of the file (magic + crc + length + header)
    start = -(-(len(_MAGIC) + 8 + len(header)) // _ALIGN) * _ALIGN
    body = bytearray(start - len(_MAGIC) - 4 + offset)
    struct.pack_into("<I", body, 0, len(header))
    body[4:4 + len(header)] = header
    base = start - len(_MAGIC) - 4
    for off, blob in blobs:
        body[base + off:base + off + len(blob)] = blob
    return _MAGIC + struct.pack("<I", zlib.crc32(body)) + bytes(body)


def _non_finite(name: str):
    raise ValueError(f"{name} in the entry's header")


def _read_flat_entry(path: Path) -> Tuple[dict, Dict[str, np.ndarray]]:
    """Map ``path`` read-only, check magic and CRC; raise ValueError on any damage."""
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        if size < len(_MAGIC) + 8:
            raise ValueError(f"entry is {size} bytes, too short")
        # MAP_POPULATE: the CRC pass reads every page anyway; faulting them in with the
        # mapping is one system call instead of one fault per page (a pair's first frame)
        populate = getattr(mmap, "MAP_POPULATE", 0)
        if populate:
            mm = mmap.mmap(fh.fileno(), 0, flags=mmap.MAP_SHARED | populate, prot=mmap.PROT_READ)
        else:  # pragma: no cover - platforms without MAP_POPULATE
            mm = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    buf = memoryview(mm)
    if bytes(buf[:len(_MAGIC)]) != _MAGIC:
        raise ValueError("not a lipsync flow entry (bad magic bytes)")
    (crc,) = struct.unpack_from("<I", buf, len(_MAGIC))
    body = buf[len(_MAGIC) + 4:]
    if zlib.crc32(body) != crc:
        raise ValueError("checksum mismatch")
    (hlen,) = struct.unpack_from("<I", body, 0)
    meta = json.loads(bytes(body[4:4 + hlen]).decode(), parse_constant=_non_finite)  # our writer never writes NaN
    start = -(-(len(_MAGIC) + 8 + hlen) // _ALIGN) * _ALIGN
    arrays = {}
    for name, m in meta.pop("members").items():
        dtype = np.dtype(m["dtype"])
        shape = tuple(int(v) for v in m["shape"])
        count = int(np.prod(shape))
        off = start + int(m["offset"])
        if off + count * dtype.itemsize > size:
            raise ValueError(f"member {name} runs past the end of the entry")
        arrays[name] = np.frombuffer(mm, dtype=dtype, count=count, offset=off).reshape(shape)
    return meta, arrays


def union_box(boxes, shape, margin: int) -> "Crop":
    """The box around all non-empty ``boxes``, grown by ``margin`` and clipped to ``shape``.

    Examples
    --------
    >>> union_box([Crop(2, 4, 2, 4), Crop(0, 0, 0, 0), Crop(3, 6, 5, 7)], (8, 8), 1)
    Crop(y0=1, y1=7, x0=1, x1=8)
    """
    boxes = [b for b in boxes if not b.empty]
    if not boxes:
        return Crop(0, 0, 0, 0)
    h, w = shape
    return Crop(max(0, min(b.y0 for b in boxes) - margin), min(h, max(b.y1 for b in boxes) + margin),
                max(0, min(b.x0 for b in boxes) - margin), min(w, max(b.x1 for b in boxes) + margin))


def pack_pair(forward: np.ndarray, backward: np.ndarray, *, axis: Optional[float]
              ) -> Tuple[dict, Dict[str, np.ndarray]]:
    """The header fields and arrays of a pair entry (see the module docstring).

    Inverse tables are solved on the fields exactly as :func:`unpack_pair` returns them
    (dead-zoned, float16-rounded, mirrored), so a fresh solve on a loaded field agrees.
    """
    from .flows import SOLVE_STEP, TABLE_STEPS, inverse_tables

    shape = forward.shape[:2]
    arrays: Dict[str, np.ndarray] = {}
    meta: dict = {"shape": list(shape), "axis": axis, "deadzone": FLOW_DEADZONE}
    for name, fld in (("forward", forward), ("backward", backward)):
        fld = apply_deadzone(fld)
        crop = support_box(fld, axis)
        part = fld[crop.y0:crop.y1, crop.x0:crop.x1]
        half = None
        if axis is not None and not crop.empty:
            local_axis = axis - crop.x0
            if 2 * local_axis == (crop.x1 - crop.x0 - 1):  # box symmetric: keep left half
                half = int(np.floor(local_axis)) + 1
                part = part[:, :half]
        arrays[name] = part.astype(np.float16)
        meta[name] = {"crop": [crop.y0, crop.y1, crop.x0, crop.x1], "half": half}
    fwd, bwd = unpack_pair(meta, arrays, shape, tables=False)
    box = union_box([fwd.crop, bwd.crop], shape, TABLE_MARGIN)
    bh, bw = box.y1 - box.y0, box.x1 - box.x0
    wc = -(-bw // SOLVE_STEP)
    # Mirror-symmetric coarse grid: the box symmetric about the axis and of even width (its
    # coarse columns then pair up, column j with wc - 1 - j).
    half_tables = bool(axis is not None and not box.empty and bw % 2 == 0 and SOLVE_STEP == 2
                       and 2 * (axis - box.x0) == bw - 1)
    keep = -(-wc // 2) if half_tables else wc
    for name, fld in (("forward", fwd), ("backward", bwd)):
        if box.empty:
            tab = np.zeros((TABLE_STEPS, 0, 0, 2), np.float32)
        else:
            tab = inverse_tables(fld.full(), (box.y0, box.x0), (bh, bw), TABLE_STEPS)[:, :, :keep]
        arrays[f"inverse_{name}"] = np.clip(np.rint(tab * TABLE_SCALE), -32767, 32767).astype(np.int16)
    meta["tables"] = {"box": [box.y0, box.y1, box.x0, box.x1], "step": SOLVE_STEP, "steps": TABLE_STEPS,
                      "half": half_tables, "coarse_width": wc, "scale": TABLE_SCALE}
    return meta, arrays


def unpack_pair(meta: dict, arrays: Dict[str, np.ndarray], shape, *, tables: bool = True
                ) -> Tuple["StoredField", "StoredField"]:
    """``(forward, backward)`` :class:`StoredField` s from an entry's header and arrays.

    Raises ValueError (or KeyError/TypeError) when they do not fit together.
    """
    out = []
    for name in ("forward", "backward"):
        inverse = None
        if tables:
            inverse = InverseTables.from_entry(meta["tables"], arrays[f"inverse_{name}"], shape)
        out.append(StoredField.from_entry(meta[name], arrays[name], shape, meta["axis"], inverse=inverse))
    return out[0], out[1]


@dataclass(frozen=True)
class InverseTables:
    """Inverse maps of one field at ``t = k / steps`` (k = 1..steps), as stored.

    Attributes
    ----------
    box : Crop
        The image box the tables cover (outside it nothing moves).
    step : int
        Coarse grid spacing: coarse point (i, j) is the centre of the ``step`` x ``step``
        block at box row ``step*i``, column ``step*j``.
    steps : int
        Number of tables.
    half : bool
        Only the left ``ceil(coarse_width / 2)`` coarse columns are kept; column j mirrors
        to ``coarse_width - 1 - j`` with its x displacement negated.
    coarse_width : int
        Coarse columns of the whole box.
    scale : int
        Values are int16 displacements in 1/scale px.
    data : numpy.ndarray
        int16 ``(steps, hc, kept columns, 2)`` (a view of the mapped entry).
    """

    box: Crop
    step: int
    steps: int
    half: bool
    coarse_width: int
    scale: int
    data: np.ndarray

    @classmethod
    def from_entry(cls, meta: dict, arr: np.ndarray, shape) -> "InverseTables":
        y0, y1, x0, x1 = (int(v) for v in meta["box"])
        box = Crop(y0, y1, x0, x1)
        step, steps, wc = int(meta["step"]), int(meta["steps"]), int(meta["coarse_width"])
        half = bool(meta["half"])
        if not (0 <= y0 <= y1 <= shape[0] and 0 <= x0 <= x1 <= shape[1]) or step < 1 or steps < 1:
            raise ValueError("table box out of range")
        hc = -(-(y1 - y0) // step) if not box.empty else 0
        if not box.empty and wc != -(-(x1 - x0) // step):
            raise ValueError("table width does not fit its box")
        keep = (-(-wc // 2) if half else wc) if not box.empty else 0
        if arr.dtype != np.int16 or arr.shape != (steps, hc, keep, 2):
            raise ValueError(f"inverse table of shape {arr.shape} does not fit its box")
        return cls(box=box, step=step, steps=steps, half=half, coarse_width=wc,
                   scale=int(meta["scale"]), data=arr)

    def full(self, k: int) -> np.ndarray:
        """Table ``k`` (t = k / steps, 1-based) as float32 displacements ``(hc, coarse_width, 2)``."""
        t = self.data[k - 1].astype(np.float32) / self.scale
        if not self.half:
            return t
        out = np.empty((t.shape[0], self.coarse_width, 2), np.float32)
        keep = t.shape[1]
        out[:, :keep] = t
        mirror = t[:, : self.coarse_width - keep][:, ::-1]
        out[:, keep:, 0] = -mirror[..., 0]
        out[:, keep:, 1] = mirror[..., 1]
        return out


@dataclass(frozen=True)
class StoredField:
    """A flow field as stored: a float16 crop, expanded on first use.

    Attributes
    ----------
    shape : (int, int)
        Full image shape.
    crop : Crop
        Where the field is non-zero; zero elsewhere.
    data : numpy.ndarray
        float32 ``(crop height, crop width, 2)`` displacement inside ``crop`` (expanded from
        the stored half on first access: the ``flow`` method never needs it).
    inverse : InverseTables, optional
        The field's inverse maps, when it came from a store entry.
    """

    shape: Tuple[int, int]
    crop: Crop
    _data: Optional[np.ndarray] = dc_field(repr=False, compare=False, default=None)
    inverse: Optional[InverseTables] = dc_field(repr=False, compare=False, default=None)
    _expand: Optional[Callable[[], np.ndarray]] = dc_field(repr=False, compare=False, default=None)

    @property
    def data(self) -> np.ndarray:
        if self._data is None:
            object.__setattr__(self, "_data", self._expand())
        return self._data

    @classmethod
    def from_entry(cls, meta: dict, arr: np.ndarray, shape, axis, inverse=None) -> "StoredField":
        y0, y1, x0, x1 = (int(v) for v in meta["crop"])
        h, w = int(shape[0]), int(shape[1])
        crop = Crop(y0, y1, x0, x1)
        if not (0 <= y0 <= y1 <= h and 0 <= x0 <= x1 <= w) or arr.ndim != 3 or arr.shape[2] != 2:
            raise ValueError("crop box or field shape out of range")
        half = meta.get("half")
        if half is not None:
            if axis is None or arr.shape != (y1 - y0, int(half), 2):
                raise ValueError("half-field does not fit its crop box")
        elif arr.shape != (y1 - y0, x1 - x0, 2):
            raise ValueError("field does not fit its crop box")

        def expand() -> np.ndarray:
            data = np.zeros((y1 - y0, x1 - x0, 2), np.float32)
            if half is not None:
                from .flows import mirror_fill

                data[:, :half] = arr
                mirror_fill(data, axis - x0)
            else:
                data[:] = arr
            # The CRC vouches for the bytes and our writer never stores NaN; checked here
            # (first use) rather than at load, which the flow method never pays for.
            if not np.isfinite(data).all():
                raise ValueError("non-finite values in field")
            return data

        return cls(shape=(h, w), crop=crop, inverse=inverse, _expand=expand)

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
