"""Viseme banks: ``bank.yaml`` plus one image per mouth shape (DESIGN.md "Formats").

Loading validates everything a later stage relies on, so that preprocessing and rendering
never meet a bad bank: the same line names in every viseme, readable images of one size,
no zero-length line, an existing rest viseme, mirror partners when ``symmetry: true``,
image paths inside the bank folder. Errors are :class:`~lipsync.errors.BankError` naming
the file, the YAML line, the viseme and the control line (also as the attributes
``viseme`` and ``feature`` of the error, for the editor).

Features: a control feature in ``lines`` is one of

* a line, ``name: [[Px, Py], [Qx, Qy]]`` (as always);
* a polyline, ``name: {polyline: [[x, y], ...], segments: N}``;
* a cubic Bézier, ``name: {bezier: [P0, C1, C2, P1, C3, C4, P2, ...], segments: N}``
  (3k+1 control points: k cubic pieces joined end to end).

Curves are expanded into ``segments`` line segments named ``name#0 .. name#N-1`` with
*correspondence by arc length*: segment i runs between the points at arc length i/N and
(i+1)/N of the whole curve, so the same fraction of a curve corresponds across visemes
however its control points are spaced. Without ``segments`` a Bézier gets
:data:`BEZIER_SEGMENTS_PER_PIECE` per piece and a polyline keeps its own edges (vertex i
matches vertex i). Every viseme must give a feature the same number of segments. Mirror
partners work for curves as for lines: ``mouth_l#i`` pairs with ``mouth_r#i``; a curve
without ``_l``/``_r`` crossing the axis pairs its segment i with segment N-1-i. The
expanded lines are what every later stage (normalisation, flows, the store key) sees.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from .. import _yaml
from ..motion.coarticulation import DominanceOverrides, DominanceParams
from ..errors import BankError, InputError
from ..motion.timing import check_timing


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
#: Feature names: like viseme names; "#" is reserved for the expanded segments of a curve.
_FEATURE_NAME = re.compile(r"^[A-Za-z0-9_.+-]{1,64}$")
_Point = Tuple[float, float]
#: Segments per cubic piece when a Bézier gives no ``segments``: 8 chords of a quarter
#: circle deviate from it by < 0.2 % of its radius, well under a pixel for mouth-sized curves.
BEZIER_SEGMENTS_PER_PIECE = 8
#: Most control points one curve may have (a whole lip contour needs ~10-20).
MAX_CURVE_POINTS = 64
#: Most segments one curve may expand into (MAX_LINES bounds the total anyway).
MAX_CURVE_SEGMENTS = 64
#: Samples per cubic piece for measuring arc length: the chord sum of 256 samples matches a
#: cubic's length to ~1e-5 relative, so resampled points sit well within 0.01 px.
_ARC_SAMPLES = 256


class WarpParams(BaseModel):
    """Beier–Neely weight parameters: ``weight = (length**p / (a + dist))**b``."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)  # NaN: "finite number", not a range
    a: float = Field(1.0, gt=0, le=1e4)
    b: float = Field(2.0, gt=0, le=8)
    p: float = Field(0.5, ge=0, le=2)


#: Largest mouth scale on a body: beyond it a mouth sprite is a blur of its pixels.
MAX_SCALE = 16.0


@dataclass(frozen=True)
class Composite:
    """A body image and where the mouth goes on it.

    Attributes
    ----------
    image : numpy.ndarray
        The body, RGB ``(H, W, 3)`` or straight RGBA ``(H, W, 4)`` ``uint8``.
    at : (float, float)
        The body pixel the mouth image's centre lands on.
    scale : float
        The mouth's size on the body relative to the bank's images.
    path : Path, optional
        Where the body image came from (for messages).
    """

    image: np.ndarray
    at: Tuple[float, float]
    scale: float = 1.0
    path: Optional[Path] = None

    def replace(self, *, image=None, at=None, scale=None, path=None) -> "Composite":
        return Composite(self.image if image is None else image, self.at if at is None else at,
                         self.scale if scale is None else scale, self.path if path is None else path)


def check_placement(body_shape: Sequence[int], at: Sequence[float], scale: float) -> Optional[str]:
    """What is wrong with a mouth centre ``at`` and ``scale`` on a body of ``body_shape``, or None.

    Examples
    --------
    >>> check_placement((100, 80), (10, 20), 1.0) is None
    True
    >>> check_placement((100, 80), (90, 20), 1.0)
    'at [90, 20] lies outside the 80x100 body image'
    """
    h, w = body_shape[:2]
    if len(at) != 2 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in at):
        return f"at must be two finite numbers [x, y], got {list(at)}"
    if not (isinstance(scale, (int, float)) and math.isfinite(scale) and 0 < scale <= MAX_SCALE):
        return f"scale must be a number in (0, {MAX_SCALE:g}], got {scale}"
    x, y = at
    if not (-0.5 <= x <= w - 0.5 and -0.5 <= y <= h - 0.5):
        return f"at [{x:g}, {y:g}] lies outside the {w}x{h} body image"
    return None



class _VisemeSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    image: str
    # Checked feature by feature in _parse_feature, for messages that name the feature.
    lines: Dict[str, object]


class _CompositeSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    image: str
    at: Tuple[float, float]
    scale: float = 1.0


class _PlateSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    video: str
    poses: str
    mask: str
    # bank.yaml's switch: false keeps the files but renders the still pictures
    enabled: bool = True


@dataclass(frozen=True)
class PlateFiles:
    """bank.yaml ``plate:`` (a bank made from video): the speaker's idle stretch of video,
    each frame's pose, and the lower-face mask (:mod:`lipsync.videobank.plate`); loaded by
    :func:`lipsync.composite.plate.load_plate` when a render needs it."""

    video: Path
    poses: Path
    mask: Path
    enabled: bool = True


class _SamplesSpec(BaseModel):
    # bank.yaml ``samples:`` (lipsync.samples): the mouth samples of a bank made from video
    model_config = ConfigDict(extra="forbid")
    video: str
    table: str
    enabled: bool = True


@dataclass(frozen=True)
class SampleFiles:
    """bank.yaml ``samples:``: the mouth-sample crops and their table (:mod:`lipsync.samples`),
    loaded by :func:`lipsync.samples.load_samples` when a render uses them."""

    video: Path
    table: Path
    enabled: bool = True


class _BankSpec(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    rest: str
    warp: WarpParams = WarpParams()
    symmetry: bool = False
    # Refine the line flows with optical flow at preprocess time (lipsync.morphing.refine, issue 22).
    refine: bool = True
    # How this subject's mouth moves when a render does not say (lipsync.motion.timing): a curve
    # name or "dominance"; banks made from video set "dominance" (issue 21).
    timing: Optional[str] = None
    # The dominance model's constants fitted to this speaker (lipsync.motion.coarticulation).
    coarticulation: Optional[DominanceOverrides] = None
    visemes: Dict[str, _VisemeSpec]
    composite: Optional[_CompositeSpec] = None
    plate: Optional[_PlateSpec] = None
    samples: Optional[_SamplesSpec] = None

    @field_validator("timing")
    @classmethod
    def _known_timing(cls, v):
        if v is not None:
            try:
                return check_timing(v)
            except InputError as exc:
                raise ValueError(exc.reason) from None
        return v

    @field_validator("visemes")
    @classmethod
    def _not_empty(cls, v):
        if not v:
            raise ValueError("a bank needs at least one viseme")
        return v


def _mirror_partner(name: str) -> Optional[str]:
    base, sep, index = name.partition("#")
    if base.endswith("_l"):
        return base[:-2] + "_r" + sep + index
    if base.endswith("_r"):
        return base[:-2] + "_l" + sep + index
    return None


def mirror_partner_index(line_names) -> np.ndarray:
    """For each line, the index of its mirror partner (itself when it has none).

    ``x_l``/``x_r`` pair up, also segment by segment for curves (``x_l#i`` with ``x_r#i``).
    Segment i of an unpaired curve ``x#0..x#N-1`` (one crossing the axis, like a chin)
    pairs with segment N-1-i: the reflection runs the curve backwards.

    Examples
    --------
    >>> mirror_partner_index(["a_l", "a_r", "nose", "c#0", "c#1", "c#2"]).tolist()
    [1, 0, 2, 5, 4, 3]
    """
    index = {n: i for i, n in enumerate(line_names)}
    counts: Dict[str, int] = {}
    for n in line_names:
        base, sep, _ = n.partition("#")
        if sep:
            counts[base] = counts.get(base, 0) + 1
    out = []
    for i, n in enumerate(line_names):
        partner = _mirror_partner(n)
        if partner is None and "#" in n:
            base, _, k = n.partition("#")
            partner = f"{base}#{counts[base] - 1 - int(k)}"
        out.append(index.get(partner, i) if partner is not None else i)
    return np.array(out, dtype=np.intp)


@dataclass(frozen=True)
class Feature:
    """One control feature of one viseme as written in bank.yaml.

    Attributes
    ----------
    kind : str
        ``"line"``, ``"polyline"`` or ``"bezier"``.
    points : numpy.ndarray
        float64 ``(K, 2)``: P and Q of a line, the vertices of a polyline, the control
        points of a Bézier.
    segments : int or None
        Segment count as written (None: the default for the kind).
    """

    kind: str
    points: np.ndarray = field(repr=False)
    segments: Optional[int] = None

    @property
    def segment_count(self) -> int:
        """How many line segments the feature expands into."""
        if self.kind == "line":
            return 1
        if self.segments is not None:
            return self.segments
        if self.kind == "polyline":
            return len(self.points) - 1
        return BEZIER_SEGMENTS_PER_PIECE * ((len(self.points) - 1) // 3)

    def expand(self) -> np.ndarray:
        """The feature as float64 ``(N, 2, 2)`` line segments (see module docstring).

        Examples
        --------
        >>> f = Feature("polyline", np.array([[0., 0], [3, 0], [3, 1]]), segments=4)
        >>> f.expand()[:, 0].tolist()
        [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]
        """
        pts = np.asarray(self.points, dtype=np.float64)
        n = self.segment_count
        if self.kind == "line" or (self.kind == "polyline" and self.segments is None):
            chain = pts
        else:
            chain = _arc_length_points(pts, n, bezier=self.kind == "bezier")
        return np.stack([chain[:-1], chain[1:]], axis=1)

    def to_yaml_value(self):
        """The plain data this feature is written as in bank.yaml."""
        pts = [[_num(x), _num(y)] for x, y in np.asarray(self.points).tolist()]
        if self.kind == "line":
            return pts
        out = {self.kind: pts}
        if self.segments is not None:
            out["segments"] = int(self.segments)
        return out


def _num(v: float):
    """A coordinate as written: integers without ".0", others rounded to 1/1000 px."""
    r = round(float(v), 3)
    return int(r) if r == int(r) else r


def _bezier_eval(ctrl: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Points of a chained cubic at global parameters ``t`` in [0, pieces]."""
    pieces = (len(ctrl) - 1) // 3
    k = np.clip(np.floor(t).astype(np.intp), 0, pieces - 1)
    u = (t - k)[:, None]
    p0, c1, c2, p1 = ctrl[3 * k], ctrl[3 * k + 1], ctrl[3 * k + 2], ctrl[3 * k + 3]
    v = 1.0 - u
    return v ** 3 * p0 + 3 * v * v * u * c1 + 3 * v * u * u * c2 + u ** 3 * p1


def _arc_length_points(pts: np.ndarray, n: int, *, bezier: bool) -> np.ndarray:
    """``n + 1`` points at equal arc-length steps along a polyline or a chained cubic."""
    if bezier:
        pieces = (len(pts) - 1) // 3
        t = np.linspace(0.0, pieces, pieces * _ARC_SAMPLES + 1)
        dense = _bezier_eval(pts, t)
    else:
        t = np.arange(len(pts), dtype=np.float64)
        dense = pts
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(dense, axis=0).T))])
    target = np.linspace(0.0, cum[-1], n + 1)
    # Map each target length back to a curve parameter (cum is non-decreasing) and evaluate
    # the exact curve there; for a polyline the parameter interpolates its vertices.
    tt = np.interp(target, cum, t)
    if bezier:
        out = _bezier_eval(pts, tt)
    else:
        k = np.clip(np.floor(tt).astype(np.intp), 0, len(pts) - 2)
        u = (tt - k)[:, None]
        out = (1 - u) * pts[k] + u * pts[k + 1]
    out[0], out[-1] = pts[0], pts[-1]  # exact ends, whatever the rounding
    return out


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
        Viseme name -> RGB ``uint8`` ``(H, W, 3)`` image; or, when any image of the bank has
        transparency, RGBA ``(H, W, 4)`` with straight alpha for every viseme (images without
        an alpha channel get alpha 255). An RGBA file whose alpha is 255 everywhere loads as
        RGB: an opaque bank is opaque however its files were saved (see :mod:`lipsync.morphing.alpha`).
    lines : dict
        Viseme name -> float64 ``(L, 2, 2)`` control lines in ``line_names`` order
        (curves already expanded into segments ``name#i``).
    features : dict
        Viseme name -> {feature name -> :class:`Feature`} as written in bank.yaml, in file
        order (for drawing and editing curves; empty for banks built by hand in code).
    composite : lipsync.composite.Composite or None
        For mouth sprites: the body image they are drawn on and where
        (``composite: {image: body.png, at: [x, y], scale: s}``: the mouth image's centre
        lands on body pixel (x, y), scaled by s; see :mod:`lipsync.composite`).
    timing : str or None
        bank.yaml's ``timing``: how this subject's mouth moves when a render does not say
        (a timing curve name or ``dominance``; see :func:`lipsync.motion.coarticulation.resolve_timing`).
    coarticulation : DominanceParams or None
        bank.yaml's ``coarticulation``: the dominance model's constants fitted to this
        speaker (keys it leaves out keep :data:`lipsync.motion.coarticulation.DEFAULT_PARAMS`).
    plate : PlateFiles or None
        bank.yaml's ``plate``: the idle stretch of the speaker's video a render composites
        the morphed lower face onto (banks made from video; ``enabled: false`` turns it off).
    samples : SampleFiles or None
        bank.yaml's ``samples``: the real mouth samples a render selects per frame
        (:mod:`lipsync.samples`; ``enabled: false`` renders one picture per viseme).

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
    features: Dict[str, Dict[str, Feature]] = field(default_factory=dict, repr=False)
    composite: Optional["Composite"] = field(default=None, repr=False)
    timing: Optional[str] = None
    coarticulation: Optional[DominanceParams] = field(default=None, repr=False)
    refine: bool = True
    plate: Optional[PlateFiles] = field(default=None, repr=False)
    samples: Optional[SampleFiles] = field(default=None, repr=False)

    @property
    def feature_names(self) -> Tuple[str, ...]:
        """Feature names in file order (line names, when no feature is a curve)."""
        if self.features:
            return tuple(self.features[self.names[0]])
        return self.line_names

    @property
    def shape(self) -> Tuple[int, int]:
        """``(H, W)`` of every image."""
        return self.images[self.names[0]].shape[:2]  # type: ignore[return-value]

    @property
    def channels(self) -> int:
        """3 for an opaque bank (RGB images), 4 for a bank with transparency (RGBA).

        Examples
        --------
        >>> from lipsync._data import default_bank_dir
        >>> Bank.load(default_bank_dir()).channels
        3
        """
        img = self.images[self.names[0]]
        return img.shape[2] if img.ndim == 3 else 1

    @property
    def yaml_path(self) -> Path:
        return self.path / "bank.yaml"

    def image_digest(self, viseme: str) -> str:
        """sha256 of a viseme's decoded pixels (what the flow store keys on).

        Kept per image object: every pair key needs two, and hashing a 720p image costs
        about a millisecond (a clip checks all pairs' keys before rendering). Images are
        never changed in place; a new array (a new bank) is hashed anew.
        """
        img = self.images[viseme]
        cache = self.__dict__.setdefault("_digest_cache", {})  # frozen: no setattr
        got = cache.get(viseme)
        if got is not None and got[0] is img:
            return got[1]
        h = hashlib.sha256(repr(img.shape).encode())
        h.update(np.ascontiguousarray(img).data)
        digest = h.hexdigest()
        cache[viseme] = (img, digest)
        return digest

    @classmethod
    def load(cls, path: Union[str, os.PathLike]) -> "Bank":
        """Load and validate a bank folder (or its ``bank.yaml``).

        Parameters
        ----------
        path : path-like
            The bank folder, or the path of its ``bank.yaml``, or the name of a shipped
            subject (``"toon"``, ``"grid-s1"``; see :func:`bank_path`).

        Returns
        -------
        Bank

        Raises
        ------
        BankError
            Naming the file, line, viseme and control line that are wrong.

        Examples
        --------
        >>> Bank.load("toon").shape                  # a shipped subject, by name
        (512, 512)
        >>> Bank.load("grid-s1").rest
        'X'
        """
        return _load(bank_path(path))

    @classmethod
    def from_text(cls, text: str, folder: Union[str, os.PathLike], *,
                  images: Optional[Dict[str, np.ndarray]] = None) -> "Bank":
        """Validate bank.yaml text as if it were ``folder/bank.yaml`` (nothing is written).

        ``images`` maps image file names (as written in the text) to decoded images already
        read from ``folder``, to skip decoding them again (the editor validates on every save).

        Examples
        --------
        >>> from lipsync._data import default_bank_dir
        >>> d = default_bank_dir()
        >>> Bank.from_text((d / "bank.yaml").read_text(), d).rest
        'X'
        """
        folder = Path(folder)
        yaml_path = folder / "bank.yaml"
        root, data = _parse_yaml_text(text, yaml_path)
        return _build(root, data, folder, yaml_path, images)


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
    return _parse_yaml_text(text, yaml_path)


def _parse_yaml_text(text: str, yaml_path: Path):
    if len(text.encode("utf-8", "surrogatepass")) > MAX_YAML_BYTES:
        raise BankError(f"text is over {MAX_YAML_BYTES} bytes, the limit of a bank.yaml", path=yaml_path)
    try:
        # One parse: compose the node tree (it keeps line numbers for error messages), then
        # build plain data from it. SafeLoader refuses custom tags; libyaml's C loader is
        # ~10x faster when PyYAML was built with it.
        # Found by fuzzing: libyaml's composer recurses on the C stack and segfaults on ~50,000
        # nested "[" or "- " (100 kB); such text goes to the Python loader, whose RecursionError
        # is caught below.
        # A key given twice (a viseme, a line) is refused, naming both lines (lipsync._yaml).
        fast = _yaml.CSafeLoader
        loader = (fast if fast is not None and _yaml_depth(text) <= _C_LOADER_MAX_DEPTH else _yaml.SafeLoader)(text)
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
        # A JPEG is decoded as every viewer (and the editor's browser) shows it: turned by
        # its EXIF orientation (a phone's portrait photo is stored sideways with that tag).
        # JPEGs have no alpha or 16 bits for IMREAD_UNCHANGED to keep.
        flag = cv2.IMREAD_COLOR if data[:2].tobytes() == b"\xff\xd8" else cv2.IMREAD_UNCHANGED
        img = cv2.imdecode(data, flag) if data.size else None
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
    if img.ndim == 3 and img.shape[2] == 2:  # grey + alpha
        img = np.dstack([cv2.cvtColor(np.ascontiguousarray(img[..., 0]), cv2.COLOR_GRAY2BGR), img[..., 1]])
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    elif img.shape[2] == 4:
        # Transparency is kept (issue 18); an alpha channel that is 255 everywhere is no
        # transparency, and such a file loads as RGB like any opaque image.
        opaque = cv2.minMaxLoc(np.ascontiguousarray(img[..., 3]))[0] == 255
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB if opaque else cv2.COLOR_BGRA2RGBA)
    else:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(img)


def read_image(path: Path) -> np.ndarray:
    """An image file as the bank loader reads it (RGB, or RGBA if it has transparency), with
    the same limits; errors are :class:`~lipsync.errors.InputError` naming the file.

    Examples
    --------
    >>> from lipsync._data import default_bank_dir
    >>> read_image(default_bank_dir() / "X.png").shape
    (512, 512, 3)
    """
    from ..errors import InputError

    try:
        return _read_image(Path(path), str(path), Path(path), None)
    except BankError as exc:
        raise InputError(exc.reason.replace(f"{path}: ", "", 1), path=path) from None


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


def bank_path(name_or_path: Union[str, os.PathLike]) -> Path:
    """The folder (or bank.yaml) a ``--bank`` value means: a path, or a shipped subject's name.

    What exists on disk wins: a folder or file of that name is used as it is. A bare name
    (no folder separator, no extension) that is not on disk is a shipped subject
    (``toon``, ``grid-s1``); an unknown one is an error listing the shipped subjects.

    Parameters
    ----------
    name_or_path : str or path-like

    Returns
    -------
    pathlib.Path

    Raises
    ------
    BankError
        A bare name that is neither on disk nor shipped.

    Examples
    --------
    >>> bank_path("toon").name, (bank_path("toon") / "bank.yaml").is_file()
    ('toon', True)
    >>> bank_path("visemes/mine").as_posix()
    'visemes/mine'
    """
    path = Path(name_or_path)
    text = os.fspath(name_or_path)
    if path.exists() or not _SUBJECT_NAME.match(text):
        return path
    from .._data import shipped_banks

    shipped = shipped_banks()
    if text in shipped:
        return shipped[text]
    raise BankError(f"no such folder, and no shipped subject of that name (shipped: {', '.join(shipped)}; "
                    f"or give a bank folder's path)", path=text)


# A --bank value that could be a shipped subject's name: one path component, no extension.
_SUBJECT_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$")


def _load(path: Path) -> Bank:
    if path.is_dir():
        folder, yaml_path = path, path / "bank.yaml"
    else:
        folder, yaml_path = path.parent, path
    root, data = _read_yaml(yaml_path)
    return _build(root, data, folder, yaml_path, None)


def _parse_feature(value, where: str, fail):
    """A bank.yaml feature value -> :class:`Feature` (``fail(msg)`` raises)."""
    def points(raw, what: str, least: int) -> np.ndarray:
        if not isinstance(raw, (list, tuple)) or len(raw) < least:
            fail(f"{where}: {what} needs a list of at least {least} [x, y] points")
        if len(raw) > MAX_CURVE_POINTS:
            fail(f"{where}: {what} has {len(raw)} points; at most {MAX_CURVE_POINTS} are supported")
        out = []
        for p in raw:
            if (not isinstance(p, (list, tuple)) or len(p) != 2
                    or not all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in p)):
                fail(f"{where}: {what} points must be [x, y] pairs of numbers, got {p!r}"[:200])
            try:
                out.append([float(p[0]), float(p[1])])
            except OverflowError:  # an integer too large for a float
                fail(f"{where}: coordinates must be finite numbers")
        arr = np.array(out, dtype=np.float64)
        if not np.all(np.isfinite(arr)):
            fail(f"{where}: coordinates must be finite numbers")
        return arr

    if isinstance(value, (list, tuple)):
        if len(value) != 2:
            fail(f"{where}: a line is [[Px, Py], [Qx, Qy]] (two points), got {len(value)} points; "
                 f"write longer shapes as {{polyline: [...]}} or {{bezier: [...]}}")
        return Feature("line", points(value, "a line", 2))
    if not isinstance(value, dict):
        fail(f"{where}: expected [[Px, Py], [Qx, Qy]], {{polyline: [...]}} or {{bezier: [...]}}")
    kinds = [k for k in ("polyline", "bezier") if k in value]
    unknown = [k for k in value if k not in ("polyline", "bezier", "segments")]
    if unknown or len(kinds) != 1:
        fail(f"{where}: a curve is {{polyline: [...]}} or {{bezier: [...]}} with optional segments: N"
             + (f"; unknown key {unknown[0]!r}" if unknown else ""))
    kind = kinds[0]
    pts = points(value[kind], f"a {kind}", 4 if kind == "bezier" else 2)
    if kind == "bezier" and (len(pts) - 1) % 3:
        fail(f"{where}: a cubic Bézier has 3k+1 control points (4, 7, 10, ...), got {len(pts)}")
    segments = value.get("segments")
    if segments is not None:
        if not isinstance(segments, int) or isinstance(segments, bool) or not 1 <= segments <= MAX_CURVE_SEGMENTS:
            fail(f"{where}: segments must be a whole number from 1 to {MAX_CURVE_SEGMENTS}")
    feature = Feature(kind, pts, segments)
    if feature.segment_count > MAX_CURVE_SEGMENTS:
        fail(f"{where}: expands into {feature.segment_count} segments; at most {MAX_CURVE_SEGMENTS}")
    return feature


def _build(root, data, folder: Path, yaml_path: Path, image_cache) -> Bank:
    if not isinstance(data, dict):
        raise BankError("expected a mapping with name, rest and visemes", path=yaml_path, line=1)

    try:
        spec = _BankSpec.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = [str(x) for x in err["loc"]]
        where = ".".join(loc) or "bank"
        error = BankError(f"{where}: {err['msg']}", path=yaml_path, line=_yaml_line(root, loc))
        if len(loc) >= 2 and loc[0] == "visemes":
            error.viseme = loc[1]
        raise error from None

    def fail(msg: str, keys: List[str]):
        error = BankError(msg, path=yaml_path, line=_yaml_line(root, keys))
        # Structured place of the error, for the editor to show it beside the feature.
        error.viseme = keys[1] if len(keys) > 1 and keys[0] == "visemes" else None
        error.feature = keys[3] if len(keys) > 3 else None
        raise error

    if len(spec.visemes) > MAX_VISEMES:
        fail(f"{len(spec.visemes)} visemes; at most {MAX_VISEMES} are supported", ["visemes"])
    names = tuple(spec.visemes)
    for v in names:
        if not _NAME.match(v):
            fail(f"viseme {v!r}: names use letters, digits and _ . + - only", ["visemes", v])
    if spec.rest not in spec.visemes:
        fail(f"rest viseme {spec.rest!r} is not among the visemes ({', '.join(names)})", ["rest"])

    first = names[0]
    feature_names = tuple(str(n) for n in spec.visemes[first].lines)
    if not feature_names:
        fail(f"viseme {first!r}: no control lines", ["visemes", first, "lines"])
    if len(feature_names) > MAX_LINES:
        fail(f"viseme {first!r}: {len(feature_names)} lines; at most {MAX_LINES} are supported",
             ["visemes", first, "lines"])
    for v in names:
        for n in spec.visemes[v].lines:
            if not _FEATURE_NAME.match(str(n)):
                fail(f"viseme {v!r}, line {n!r}: names use letters, digits and _ . + - only "
                     f"('#' marks the segments of a curve)", ["visemes", v, "lines", str(n)])
    for v in names:
        have = set(spec.visemes[v].lines)
        missing = [n for n in feature_names if n not in have]
        extra = [n for n in spec.visemes[v].lines if n not in set(feature_names)]
        if missing:
            fail(f"viseme {v!r}: missing line {missing[0]!r} (every viseme needs the same line names "
                 f"as {first!r})", ["visemes", v, "lines"])
        if extra:
            fail(f"viseme {v!r}: line {extra[0]!r} is not in viseme {first!r} (every viseme needs the "
                 f"same line names)", ["visemes", v, "lines", extra[0]])
    if spec.symmetry:
        for n in feature_names:
            partner = _mirror_partner(n)
            if partner is not None and partner not in set(feature_names):
                fail(f"viseme {first!r}, line {n!r}: symmetry is on but its mirror partner "
                     f"{partner!r} is missing", ["visemes", first, "lines", n])

    features: Dict[str, Dict[str, Feature]] = {}
    for v in names:
        features[v] = {}
        for n in feature_names:
            keys = ["visemes", v, "lines", n]
            features[v][n] = _parse_feature(spec.visemes[v].lines[n],
                                            f"visemes.{v}.lines.{n} (viseme {v!r}, line {n!r})",
                                            lambda msg, keys=keys: fail(msg, keys))
    counts = {n: features[first][n].segment_count for n in feature_names}
    for v in names:
        for n in feature_names:
            got = features[v][n].segment_count
            if got != counts[n]:
                fail(f"viseme {v!r}, line {n!r}: {got} segments but {counts[n]} in viseme {first!r} "
                     f"(a feature needs the same segment count in every viseme)", ["visemes", v, "lines", n])
    if spec.symmetry:
        for n in feature_names:
            partner = _mirror_partner(n)
            if partner is not None and counts[partner] != counts[n]:
                fail(f"viseme {first!r}, line {n!r}: {counts[n]} segments but its mirror partner "
                     f"{partner!r} has {counts[partner]}", ["visemes", first, "lines", n])

    line_names: List[str] = []
    for n in feature_names:
        kind = features[first][n].kind
        line_names += [n] if kind == "line" else [f"{n}#{i}" for i in range(counts[n])]
    if len(line_names) > MAX_LINES:
        fail(f"viseme {first!r}: {len(line_names)} lines (curves counted by segments); at most {MAX_LINES} "
             f"are supported", ["visemes", first, "lines"])
    for n in feature_names:
        kinds = {features[v][n].kind == "line" for v in names}
        if len(kinds) > 1:
            # A line in one viseme and a one-segment curve in another would give the segment
            # two names; ask for one spelling.
            v = next(v for v in names if (features[v][n].kind == "line") != (features[first][n].kind == "line"))
            fail(f"viseme {v!r}, line {n!r}: a line here but a curve in viseme {first!r}; write it the "
                 f"same way in every viseme", ["visemes", v, "lines", n])

    lines: Dict[str, np.ndarray] = {}
    for v in names:
        parts = []
        for n in feature_names:
            seg = features[v][n].expand()
            lengths = np.hypot(*(seg[:, 1] - seg[:, 0]).T)
            if lengths.min() < 1e-6:
                k = int(np.argmin(lengths))
                what = "zero-length line (P equals Q)" if features[v][n].kind == "line" else \
                    f"segment {k} has zero length (repeated points or a curve of no length)"
                fail(f"viseme {v!r}, line {n!r}: {what}", ["visemes", v, "lines", n])
            parts.append(seg)
        lines[v] = np.concatenate(parts, axis=0)

    folder_real = folder.resolve()

    def inside(rel: str, what: str, keys: List[str]) -> Path:
        """The resolved path of image ``rel``, which must stay inside the bank folder."""
        if not rel or os.path.isabs(rel) or rel.startswith(("/", "\\")) or re.match(r"^[A-Za-z]:", rel):
            fail(f"{what}: image path {rel!r} must be relative to the bank folder", keys)
        try:
            real = (folder / rel).resolve()
        except (OSError, RuntimeError, ValueError):  # ValueError: a NUL byte in the path (fuzzing)
            fail(f"{what}: cannot resolve image path {rel!r}", keys)
        if folder_real != real and folder_real not in real.parents:
            fail(f"{what}: image path {rel!r} leads outside the bank folder", keys)
        return real

    images: Dict[str, np.ndarray] = {}
    shape = None
    for v in names:
        rel = spec.visemes[v].image
        keys = ["visemes", v, "image"]
        line = _yaml_line(root, keys)
        real = inside(rel, f"viseme {v!r}", keys)
        if image_cache is not None and rel in image_cache:
            img = image_cache[rel]
        else:
            img = _read_image(real, f"viseme {v!r}", yaml_path, line)
        if shape is None:
            shape = img.shape
        elif img.shape[:2] != shape[:2]:
            fail(f"viseme {v!r}: image {rel!r} is {img.shape[1]}x{img.shape[0]} but "
                 f"{names[0]!r} is {shape[1]}x{shape[0]}; all images need one size", keys)
        images[v] = img
    if any(img.shape[2] == 4 for img in images.values()):
        # One layout for the whole bank: the opaque images get alpha 255.
        import cv2

        images = {v: img if img.shape[2] == 4 else cv2.cvtColor(img, cv2.COLOR_RGB2RGBA) for v, img in images.items()}

    h, w = shape[:2]  # type: ignore[index]
    for v in names:
        arr = lines[v]
        # Lines far outside the image are almost always a typo (swapped x/y, wrong scale).
        margin = max(h, w)
        bad = np.flatnonzero(np.any((arr[..., 0] < -margin) | (arr[..., 0] > w + margin) |
                                    (arr[..., 1] < -margin) | (arr[..., 1] > h + margin), axis=1))
        if bad.size:
            n = line_names[bad[0]].partition("#")[0]
            fail(f"viseme {v!r}, line {n!r}: lies far outside the {w}x{h} image", ["visemes", v, "lines", n])

    composite = None
    if spec.composite is not None:
        c = spec.composite
        keys = ["composite", "image"]
        real = inside(c.image, "composite", keys)
        if image_cache is not None and c.image in image_cache:
            body = image_cache[c.image]
        else:
            body = _read_image(real, "composite", yaml_path, _yaml_line(root, keys))
        problem = check_placement(body.shape, c.at, c.scale)
        if problem:
            fail(f"composite ({c.image!r}): {problem}", ["composite", "scale" if "scale" in problem else "at"])
        composite = Composite(image=body, at=(float(c.at[0]), float(c.at[1])), scale=float(c.scale), path=real)

    plate = None
    if spec.plate is not None:
        files = {}
        for key in ("video", "poses", "mask"):
            rel = getattr(spec.plate, key)
            real = inside(rel, f"plate {key}", ["plate", key])
            if not real.is_file():
                fail(f"plate {key}: file {rel!r} not found", ["plate", key])
            files[key] = real
        plate = PlateFiles(enabled=spec.plate.enabled, **files)
    samples = None
    if spec.samples is not None:  # the files are read and checked by lipsync.samples.load_samples
        got = {k: inside(getattr(spec.samples, k), f"samples {k}", ["samples", k]) for k in ("video", "table")}
        for k, real in got.items():
            if not real.is_file():
                fail(f"samples {k}: file {getattr(spec.samples, k)!r} not found", ["samples", k])
        samples = SampleFiles(enabled=spec.samples.enabled, **got)

    return Bank(path=folder, name=spec.name, rest=spec.rest, warp=spec.warp, symmetry=spec.symmetry,
                names=names, line_names=tuple(line_names), images=images, lines=lines, features=features,
                composite=composite, timing=spec.timing, refine=spec.refine, plate=plate, samples=samples,
                coarticulation=spec.coarticulation.apply() if spec.coarticulation is not None else None)
