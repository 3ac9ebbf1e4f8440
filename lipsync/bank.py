"""Viseme banks: ``bank.yaml`` plus one image per mouth shape (DESIGN.md "Formats").

Loading validates everything a later stage relies on, so that preprocessing and rendering
never meet a bad bank: the same line names in every viseme, readable images of one size,
no zero-length line, an existing rest viseme, mirror partners when ``symmetry: true``,
image paths inside the bank folder. Errors are :class:`~lipsync.errors.BankError` naming
the file, the YAML line, the viseme and the control line.
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Tuple, Union

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from .errors import BankError

#: Refuse images above this many pixels (8K UHD): a decompression bomb or a mistake, and
#: each flow of such a size would need hundreds of MB.
MAX_IMAGE_PIXELS = 7680 * 4320
#: bank.yaml larger than this is not a hand-written bank.
MAX_YAML_BYTES = 1 << 20
#: Each line costs ~5 ns per pixel per flow; beyond a few hundred the warp is unusably slow
#: and no face needs that many.
MAX_LINES = 256
#: Flows grow with the square of the viseme count (pairs); 64 covers every viseme set in use.
MAX_VISEMES = 64

_NAME = re.compile(r"^[A-Za-z0-9_.+-]{1,64}$")
_Point = Tuple[float, float]


class WarpParams(BaseModel):
    """Beier–Neely weight parameters: ``weight = (length**p / (a + dist))**b``."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    a: float = Field(1.0, gt=0, le=1e4)
    b: float = Field(2.0, gt=0, le=8)
    p: float = Field(0.5, ge=0, le=2)


class _VisemeSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    image: str
    lines: Dict[str, Tuple[_Point, _Point]]


class _BankSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    rest: str
    warp: WarpParams = WarpParams()
    symmetry: bool = False
    visemes: Dict[str, _VisemeSpec]

    @field_validator("visemes")
    @classmethod
    def _not_empty(cls, v):
        if not v:
            raise ValueError("a bank needs at least one viseme")
        return v


def _mirror_partner(name: str) -> Optional[str]:
    if name.endswith("_l"):
        return name[:-2] + "_r"
    if name.endswith("_r"):
        return name[:-2] + "_l"
    return None


@dataclass(frozen=True)
class Bank:
    """A validated viseme bank.

    Attributes
    ----------
    path : Path
        The bank folder.
    name, rest : str
        The subject's name and the viseme shown for silence.
    warp : WarpParams
        Beier–Neely weight parameters.
    symmetry : bool
        Whether lines are normalised to be mirror-symmetric.
    names : tuple of str
        Viseme names in file order.
    line_names : tuple of str
        Control line names, in one order shared by every viseme's ``lines`` array.
    images : dict
        Viseme name -> RGB ``uint8`` ``(H, W, 3)`` image.
    lines : dict
        Viseme name -> float64 ``(L, 2, 2)`` control lines in ``line_names`` order.

    Examples
    --------
    >>> from lipsync._data import default_bank_dir
    >>> bank = Bank.load(default_bank_dir())
    >>> bank.rest in bank.names
    True
    """

    path: Path
    name: str
    rest: str
    warp: WarpParams
    symmetry: bool
    names: Tuple[str, ...]
    line_names: Tuple[str, ...]
    images: Dict[str, np.ndarray] = field(repr=False)
    lines: Dict[str, np.ndarray] = field(repr=False)

    @property
    def shape(self) -> Tuple[int, int]:
        """``(H, W)`` of every image."""
        return self.images[self.names[0]].shape[:2]  # type: ignore[return-value]

    @property
    def yaml_path(self) -> Path:
        return self.path / "bank.yaml"

    def image_digest(self, viseme: str) -> str:
        """sha256 of a viseme's decoded pixels (what the flow store keys on)."""
        img = self.images[viseme]
        h = hashlib.sha256(repr(img.shape).encode())
        h.update(img.tobytes())
        return h.hexdigest()

    @classmethod
    def load(cls, path: Union[str, os.PathLike]) -> "Bank":
        """Load and validate a bank folder (or its ``bank.yaml``).

        Parameters
        ----------
        path : path-like
            The bank folder, or the path of its ``bank.yaml``.

        Returns
        -------
        Bank

        Raises
        ------
        BankError
            Naming the file, line, viseme and control line that are wrong.

        Examples
        --------
        >>> from lipsync._data import default_bank_dir
        >>> Bank.load(default_bank_dir()).shape
        (512, 512)
        """
        return _load(Path(path))


# --------------------------------------------------------------------------- loading

def _yaml_line(root: Optional[yaml.Node], keys: List[str]) -> Optional[int]:
    """1-based line of the YAML node at ``keys`` (a path of mapping keys), best effort."""
    node = root
    line = None
    for key in keys:
        if not isinstance(node, yaml.MappingNode):
            break
        for k, v in node.value:
            if isinstance(k, yaml.ScalarNode) and k.value == key:
                line = k.start_mark.line + 1
                node = v
                break
        else:
            break
    return line


def _read_yaml(yaml_path: Path):
    try:
        size = yaml_path.stat().st_size
    except FileNotFoundError:
        raise BankError("no bank.yaml here (a bank is a folder with bank.yaml and images)",
                        path=yaml_path) from None
    except OSError as exc:
        raise BankError(f"cannot read: {exc.strerror}", path=yaml_path) from None
    if size > MAX_YAML_BYTES:
        raise BankError(f"file is {size} bytes; a bank.yaml is at most {MAX_YAML_BYTES}", path=yaml_path)
    try:
        text = yaml_path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BankError(f"not UTF-8 text (byte {exc.start})", path=yaml_path) from None
    except OSError as exc:
        raise BankError(f"cannot read: {exc.strerror}", path=yaml_path) from None
    try:
        # One parse: compose the node tree (it keeps line numbers for error messages), then
        # build plain data from it. SafeLoader refuses custom tags; libyaml's C loader is
        # ~10x faster when PyYAML was built with it.
        # Found by fuzzing: libyaml's composer recurses on the C stack and segfaults on ~50,000
        # nested "[" or "- " (100 kB); such text goes to the Python loader, whose RecursionError
        # is caught below.
        fast = getattr(yaml, "CSafeLoader", None)
        loader = (fast if fast is not None and _yaml_depth(text) <= _C_LOADER_MAX_DEPTH else yaml.SafeLoader)(text)
        try:
            root = loader.get_single_node()
            data = loader.construct_document(root) if root is not None else None
        finally:
            loader.dispose()
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        # min(): PyYAML marks an error at the end of a file without a final newline one line
        # past the last (found by fuzzing).
        raise BankError(f"invalid YAML: {problem}", path=yaml_path,
                        line=min(mark.line + 1, text.count("\n") + 1) if mark is not None else None) from None
    except RecursionError:
        raise BankError("invalid YAML: nested too deeply", path=yaml_path) from None
    except ValueError as exc:  # found by fuzzing: an integer of > 4300 digits (Python's int-from-text limit)
        raise BankError(f"invalid YAML: {str(exc)[:60]}", path=yaml_path) from None
    return root, data


#: Deepest nesting handed to libyaml: far beyond any bank (which nests 5 levels), far below
#: the ~10,000s of levels at which its recursion overflows the C stack.
_C_LOADER_MAX_DEPTH = 200


def _yaml_depth(text: str) -> int:
    """Upper bound on the flow nesting plus the longest "- - -" run on one line."""
    codes = np.frombuffer(text.encode("utf-8", "surrogatepass"), dtype=np.uint8)
    step = np.isin(codes, (ord("["), ord("{"))).astype(np.int64) - np.isin(codes, (ord("]"), ord("}")))
    flow = int(np.cumsum(step).max()) if codes.size else 0
    dashes = max((len(m.group()) // 2 for m in re.finditer(r"(?:-[ \t]+)+", text)), default=0)
    return flow + dashes


def _read_image(path: Path, where: str, yaml_path: Path, line: Optional[int]) -> np.ndarray:
    import cv2

    try:
        size = path.stat().st_size
    except OSError:
        raise BankError(f"{where}: image {path.name!r} does not exist", path=yaml_path, line=line) from None
    if not path.is_file():  # found by fuzzing: "image: ." reached np.fromfile and raised IsADirectoryError
        raise BankError(f"{where}: image path {path.name!r} is not a file", path=yaml_path, line=line)
    header = _png_size(path) or _jpeg_size(path)
    if header is not None and header[0] * header[1] > MAX_IMAGE_PIXELS:
        raise BankError(f"{where}: image {path.name!r} is {header[0]}x{header[1]}, above the limit of "
                        f"{MAX_IMAGE_PIXELS} pixels", path=yaml_path, line=line)
    if size > 4 * MAX_IMAGE_PIXELS:
        raise BankError(f"{where}: image file {path.name!r} is {size} bytes, too large", path=yaml_path, line=line)
    data = np.fromfile(str(path), dtype=np.uint8)
    try:
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    except cv2.error:  # OpenCV's own size limit (2**30 pixels) raises instead of returning None
        img = None
    if img is None:
        raise BankError(f"{where}: cannot decode image {path.name!r}", path=yaml_path, line=line)
    if img.shape[0] * img.shape[1] > MAX_IMAGE_PIXELS:
        raise BankError(f"{where}: image {path.name!r} is above the limit of {MAX_IMAGE_PIXELS} pixels",
                        path=yaml_path, line=line)
    if img.dtype != np.uint8:
        # 16-bit PNGs: keep the high byte; the renderer works in 8 bits.
        img = (img >> 8).astype(np.uint8) if img.dtype == np.uint16 else img.astype(np.uint8)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    else:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(img)


def _jpeg_size(path: Path) -> Optional[Tuple[int, int]]:
    """(width, height) from a JPEG's frame header without decoding, or None if not found.

    Found by fuzzing: a 629-byte JPEG whose header claims 30000x30000 made OpenCV allocate
    and fill 2.7 GB before the pixel limit below could refuse it.
    """
    try:
        with open(path, "rb") as fh:
            if fh.read(2) != b"\xff\xd8":
                return None
            # Segments before the frame header are few (APPn, DQT, DHT); the bound stops junk.
            for _ in range(_JPEG_MAX_SEGMENTS):
                marker = fh.read(2)
                while marker[:1] == b"\xff" and marker[1:2] == b"\xff":  # fill bytes
                    marker = marker[1:] + fh.read(1)
                if len(marker) < 2 or marker[0] != 0xFF:
                    return None
                kind = marker[1]
                if kind in _JPEG_NO_LENGTH:
                    continue
                length = int.from_bytes(fh.read(2), "big")
                if kind in _JPEG_SOF:
                    head = fh.read(5)
                    if len(head) < 5:
                        return None
                    return int.from_bytes(head[3:5], "big"), int.from_bytes(head[1:3], "big")
                if kind == 0xDA or length < 2:  # scan data before any frame header: not a JPEG
                    return None
                fh.seek(length - 2, os.SEEK_CUR)
    except OSError:
        return None
    return None


_JPEG_MAX_SEGMENTS = 256
#: Start-of-frame markers (baseline, progressive, lossless, arithmetic): they carry the size.
_JPEG_SOF = frozenset([0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF])
#: Markers without a length field (restart markers, TEM, SOI).
_JPEG_NO_LENGTH = frozenset(list(range(0xD0, 0xD8)) + [0x01, 0xD8])


def _png_size(path: Path) -> Optional[Tuple[int, int]]:
    """(width, height) from a PNG header without decoding, or None if not a PNG."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(24)
    except OSError:
        return None
    if len(head) == 24 and head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
        return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    return None


def _load(path: Path) -> Bank:
    if path.is_dir():
        folder, yaml_path = path, path / "bank.yaml"
    else:
        folder, yaml_path = path.parent, path
    root, data = _read_yaml(yaml_path)
    if not isinstance(data, dict):
        raise BankError("expected a mapping with name, rest and visemes", path=yaml_path, line=1)

    try:
        spec = _BankSpec.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = [str(x) for x in err["loc"]]
        where = ".".join(loc) or "bank"
        raise BankError(f"{where}: {err['msg']}", path=yaml_path, line=_yaml_line(root, loc)) from None

    def fail(msg: str, keys: List[str]):
        raise BankError(msg, path=yaml_path, line=_yaml_line(root, keys))

    if len(spec.visemes) > MAX_VISEMES:
        fail(f"{len(spec.visemes)} visemes; at most {MAX_VISEMES} are supported", ["visemes"])
    names = tuple(spec.visemes)
    for v in names:
        if not _NAME.match(v):
            fail(f"viseme {v!r}: names use letters, digits and _ . + - only", ["visemes", v])
    if spec.rest not in spec.visemes:
        fail(f"rest viseme {spec.rest!r} is not among the visemes ({', '.join(names)})", ["rest"])

    first = names[0]
    line_names = tuple(spec.visemes[first].lines)
    if not line_names:
        fail(f"viseme {first!r}: no control lines", ["visemes", first, "lines"])
    if len(line_names) > MAX_LINES:
        fail(f"viseme {first!r}: {len(line_names)} lines; at most {MAX_LINES} are supported",
             ["visemes", first, "lines"])
    for v in names:
        have = set(spec.visemes[v].lines)
        missing = [n for n in line_names if n not in have]
        extra = [n for n in spec.visemes[v].lines if n not in set(line_names)]
        if missing:
            fail(f"viseme {v!r}: missing line {missing[0]!r} (every viseme needs the same line names "
                 f"as {first!r})", ["visemes", v, "lines"])
        if extra:
            fail(f"viseme {v!r}: line {extra[0]!r} is not in viseme {first!r} (every viseme needs the "
                 f"same line names)", ["visemes", v, "lines", extra[0]])
    if spec.symmetry:
        for n in line_names:
            partner = _mirror_partner(n)
            if partner is not None and partner not in set(line_names):
                fail(f"viseme {first!r}, line {n!r}: symmetry is on but its mirror partner "
                     f"{partner!r} is missing", ["visemes", first, "lines", n])

    lines: Dict[str, np.ndarray] = {}
    for v in names:
        arr = np.array([spec.visemes[v].lines[n] for n in line_names], dtype=np.float64)
        for i, n in enumerate(line_names):
            if not np.all(np.isfinite(arr[i])):
                fail(f"viseme {v!r}, line {n!r}: coordinates must be finite numbers",
                     ["visemes", v, "lines", n])
            if np.hypot(*(arr[i, 1] - arr[i, 0])) < 1e-6:
                fail(f"viseme {v!r}, line {n!r}: zero-length line (P equals Q)",
                     ["visemes", v, "lines", n])
        lines[v] = arr

    folder_real = folder.resolve()
    images: Dict[str, np.ndarray] = {}
    shape = None
    for v in names:
        rel = spec.visemes[v].image
        keys = ["visemes", v, "image"]
        line = _yaml_line(root, keys)
        if not rel or os.path.isabs(rel) or rel.startswith(("/", "\\")) or re.match(r"^[A-Za-z]:", rel):
            fail(f"viseme {v!r}: image path {rel!r} must be relative to the bank folder", keys)
        img_path = folder / rel
        try:
            real = img_path.resolve()
        except (OSError, RuntimeError, ValueError):  # ValueError: a NUL byte in the path (fuzzing)
            fail(f"viseme {v!r}: cannot resolve image path {rel!r}", keys)
        if folder_real != real and folder_real not in real.parents:
            fail(f"viseme {v!r}: image path {rel!r} leads outside the bank folder", keys)
        img = _read_image(real, f"viseme {v!r}", yaml_path, line)
        if shape is None:
            shape = img.shape
        elif img.shape != shape:
            fail(f"viseme {v!r}: image {rel!r} is {img.shape[1]}x{img.shape[0]} but "
                 f"{names[0]!r} is {shape[1]}x{shape[0]}; all images need one size", keys)
        images[v] = img

    h, w = shape[:2]  # type: ignore[index]
    for v in names:
        arr = lines[v]
        # Lines far outside the image are almost always a typo (swapped x/y, wrong scale).
        margin = max(h, w)
        bad = np.flatnonzero(np.any((arr[..., 0] < -margin) | (arr[..., 0] > w + margin) |
                                    (arr[..., 1] < -margin) | (arr[..., 1] > h + margin), axis=1))
        if bad.size:
            n = line_names[bad[0]]
            fail(f"viseme {v!r}, line {n!r}: lies far outside the {w}x{h} image", ["visemes", v, "lines", n])

    return Bank(path=folder, name=spec.name, rest=spec.rest, warp=spec.warp, symmetry=spec.symmetry,
                names=names, line_names=line_names, images=images, lines=lines)
