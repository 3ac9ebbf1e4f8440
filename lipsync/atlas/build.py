"""Rendering an atlas: every viseme and N in-betweens of each pair, cropped to what changes.

Stages, on what ``lipsync render`` uses: the bank, its flow store (missing flows computed
first, as ``render`` does), the :class:`~lipsync.morphing.render.Renderer` for every cell, then
:mod:`.layout` for the texture. Pairs come from timelines through the same reader, map and
sequencer stages as ``render`` (:func:`pairs_in_plan` of the sequencer's plan), or are all
pairs of the bank.

Cropping: the cells hold one common region of the frame, the bounding box of every pixel
that differs between any cell and the rest viseme, and the JSON says where it goes
(``region``) beside a base image holding the rest of the frame. One region for all cells,
rather than a box per cell: mouths overlap, so per-cell boxes would save little more, while
equal cells keep the texture a plain grid, every cell drawn at one offset, and no pivot that
jumps from frame to frame. On the shipped toon the region is 306 x 251 of 512 x 512 px: the
texture is a third of the uncropped one, so three times the in-betweens fit a 4096 texture.

Frames are RGBA in the texture: an opaque bank's cells get alpha 255, and a bank with alpha
keeps it (the renderer's fourth channel, when it gives one).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, List, Optional, Sequence, Tuple, Union

import cv2
import numpy as np

from ..errors import InputError
from .layout import DEFAULT_MAX_SIZE, DEFAULT_PADDING, fit, scaled
from .schema import Atlas, Cell

PathLike = Union[str, "os.PathLike[str]"]
Box = Tuple[int, int, int, int]  # x0, y0, x1, y1 (exclusive)

#: Most in-betweens per pair: 64 puts frames 1/65 alpha apart, finer than any eye tells
#: (a grey level per step on a 256-level edge); more only grows the texture.
MAX_INBETWEENS = 64


@dataclass
class AtlasBuild:
    """A rendered atlas: the RGBA texture, the base image (or None) and the description."""

    texture: np.ndarray
    base: Optional[np.ndarray]
    atlas: Atlas


def bank_pairs(names: Sequence[str]) -> List[Tuple[str, str]]:
    """Every unordered pair of visemes, each once, ``from`` first in the bank's order.

    Examples
    --------
    >>> bank_pairs(["A", "B", "X"])
    [('A', 'B'), ('A', 'X'), ('B', 'X')]
    """
    names = list(names)
    return [(a, b) for i, a in enumerate(names) for b in names[i + 1:]]


def pairs_in_plan(plan: Iterable[Tuple[float, float, str]], names: Sequence[str]) -> List[Tuple[str, str]]:
    """The pairs a planned track morphs between (each boundary of the sequencer's plan).

    The plan (:func:`lipsync.motion.sequencer.plan_segments`) does not depend on the frame rate, so
    neither does the atlas. Pairs are ordered as the bank orders its visemes.

    Examples
    --------
    >>> pairs_in_plan([(0, 1, "X"), (1, 2, "A"), (2, 3, "X"), (3, 4, "B")], ["A", "B", "X"])
    [('A', 'X'), ('B', 'X')]
    """
    order = {v: i for i, v in enumerate(names)}
    found = set()
    plan = list(plan)
    for (_, _, a), (_, _, b) in zip(plan, plan[1:]):
        if a != b:
            found.add((a, b) if order[a] < order[b] else (b, a))
    return sorted(found, key=lambda p: (order[p[0]], order[p[1]]))


def pairs_in_specs(specs: Iterable, names: Sequence[str]) -> List[Tuple[str, str]]:
    """The pairs a list of FrameSpecs morphs between, ordered as the bank orders its visemes.

    Examples
    --------
    >>> from lipsync.motion.sequencer import FrameSpec
    >>> pairs_in_specs([FrameSpec("X", "X", 0.0), FrameSpec("X", "A", 0.4), FrameSpec("D", "A", 0.5)], "ADX")
    [('A', 'X'), ('A', 'D')]
    """
    order = {v: i for i, v in enumerate(names)}
    found = {tuple(sorted((s.from_viseme, s.to_viseme), key=order.__getitem__)) for s in specs if not s.is_still}
    return sorted(found, key=lambda p: (order[p[0]], order[p[1]]))


def _rgba(frame: np.ndarray) -> np.ndarray:
    """An RGBA copy of a renderer frame (RGB frames get alpha 255)."""
    if frame.shape[2] == 4:
        return frame.copy()
    return cv2.cvtColor(frame, cv2.COLOR_RGB2RGBA)


def _changed(frame: np.ndarray, base: np.ndarray) -> Optional[Box]:
    """Bounding box of the pixels where ``frame`` differs from ``base`` (clear in both: equal)."""
    mask = np.any(frame != base, axis=2)
    mask &= (frame[..., 3] != 0) | (base[..., 3] != 0)
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if not len(rows):
        return None
    return int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1


def _union(a: Optional[Box], b: Optional[Box]) -> Optional[Box]:
    if a is None or b is None:
        return a or b
    return min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])


def _resize(img: np.ndarray, size: Tuple[int, int]) -> np.ndarray:
    """Area-average resize; with partial alpha in premultiplied form, so clear pixels add no colour."""
    if img.shape[1] == size[0] and img.shape[0] == size[1]:
        return img
    alpha = img[..., 3:4].astype(np.float32) / 255.0
    if np.all(alpha == 1.0):
        return cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    pre = np.concatenate([img[..., :3].astype(np.float32) * alpha, alpha * 255.0], axis=2)
    out = cv2.resize(pre, size, interpolation=cv2.INTER_AREA)
    a = out[..., 3:4]
    rgb = np.where(a > 0, out[..., :3] * 255.0 / np.maximum(a, 1e-6), 0.0)
    return np.clip(np.concatenate([rgb, a], axis=2) + 0.5, 0, 255).astype(np.uint8)


def build_atlas(bank, *, pairs: Union[str, Iterable[Tuple[str, str]]] = "all", inbetweens: int = 3,
                method: str = "flow", store=None, scale: float = 1.0, max_size: int = DEFAULT_MAX_SIZE,
                padding: int = DEFAULT_PADDING, crop: bool = True, jobs: Optional[int] = None,
                quiet: bool = True) -> AtlasBuild:
    """Render a sprite atlas of a bank.

    Parameters
    ----------
    bank : Bank or path-like
        The subject.
    pairs : "all" or iterable of (from, to)
        The transitions to hold in-betweens of (either direction of a pair is the same
        pair); ``"all"``: every pair of the bank's visemes.
    inbetweens : int
        In-betweens per pair, at alpha ``k / (inbetweens + 1)``, 0 to :data:`MAX_INBETWEENS`.
    method : str
        Renderer method (``flow``, ``splat``, ``beier-neely``, ``dissolve``).
    store : FlowStore or path-like, optional
        The bank's flow store (default: the bank's own); missing flows are computed first.
    scale : float
        Texture pixels per frame pixel, in (0, 1].
    max_size : int
        Largest texture side; a larger atlas is an InputError naming a scale that fits.
    padding : int
        Pixels around each cell repeating its edge (0..64).
    crop : bool
        Cells hold only the region that changes (see the module notes); False: whole frames.
    jobs : int, optional
        Processes for computing missing flows.
    quiet : bool
        No progress bars.

    Returns
    -------
    AtlasBuild

    Examples
    --------
    >>> from lipsync._data import default_bank_dir
    >>> built = build_atlas(default_bank_dir(), pairs=[("A", "D")], inbetweens=1)
    >>> [(c.from_viseme, c.to_viseme, c.alpha) for c in built.atlas.cells][-2:]
    [('X', 'X', 0.0), ('A', 'D', 0.5)]
    >>> built.atlas.region, built.texture.shape  # the toon's mouth and jaw: 306 x 249 of 512 x 512
    ((103, 261, 306, 249), (1012, 930, 4))
    """
    from tqdm import tqdm

    from ..banks.bank import Bank
    from ..morphing.preprocess import all_pairs, preprocess
    from ..morphing.render import Renderer
    from ..morphing.store import FlowStore

    if not isinstance(bank, Bank):
        bank = Bank.load(bank)
    if isinstance(inbetweens, bool) or not isinstance(inbetweens, int) or not 0 <= inbetweens <= MAX_INBETWEENS:
        raise InputError(f"--inbetweens must be a whole number 0..{MAX_INBETWEENS}, got {inbetweens!r}")
    if not (0 < float(scale) <= 1):
        raise InputError(f"--scale must be in (0, 1], got {scale!r}")
    if not 0 <= int(padding) <= 64:
        raise InputError(f"--padding must be 0..64, got {padding!r}")
    if int(max_size) < 1:
        raise InputError(f"--max-size must be positive, got {max_size!r}")
    names = list(bank.names)
    order = {v: i for i, v in enumerate(names)}
    if isinstance(pairs, str):
        if pairs != "all":
            raise InputError(f"pairs must be 'all' or a list of (from, to), got {pairs!r}")
        chosen = bank_pairs(names)
    else:
        chosen = []
        for a, b in pairs:
            for v in (a, b):
                if v not in order:
                    raise InputError(f"viseme {v!r} is not in the bank (bank has: {', '.join(names)})",
                                     path=bank.yaml_path)
            if a != b:
                p = (a, b) if order[a] < order[b] else (b, a)
                if p not in chosen:
                    chosen.append(p)
        chosen.sort(key=lambda p: (order[p[0]], order[p[1]]))
    alphas = [k / (inbetweens + 1) for k in range(1, inbetweens + 1)]
    specs = [(v, v, 0.0) for v in names] + [(a, b, t) for a, b in chosen for t in alphas]

    if not isinstance(store, FlowStore):
        store = FlowStore.for_bank(bank, store)
    renderer = Renderer(bank, method=method, store=store)
    if renderer.method in ("flow", "splat") and chosen:
        nb = renderer.nb
        if any(not store.pair_path(store.pair_key(bank, a, b, nb.axis)).exists() for a, b in all_pairs(names)):
            preprocess(bank, store=store, jobs=jobs, quiet=quiet, normalised=nb)

    base_full = _rgba(renderer.render(bank.rest, bank.rest, 0.0))
    height, width = base_full.shape[:2]
    # the visemes bound the region from below: check the size before rendering in-betweens
    crops: List[Tuple[Optional[Box], Optional[np.ndarray]]] = []
    region: Optional[Box] = None
    with tqdm(total=len(specs), desc="atlas", unit="cell", disable=quiet, leave=False) as bar:
        for i, (a, b, t) in enumerate(specs):
            frame = _rgba(renderer.render(a, b, t))
            box = _changed(frame, base_full)
            region = _union(region, box)
            crops.append((box, None if box is None else frame[box[1]:box[3], box[0]:box[2]].copy()))
            bar.update(1)
            if i == len(names) - 1:
                fit(len(specs), _size(region if crop else None, width, height), scale=scale,
                    max_size=max_size, padding=padding)
    if not crop or region is None:
        region = (0, 0, width, height)
    rx0, ry0, rx1, ry1 = region
    rsize = (rx1 - rx0, ry1 - ry0)
    g = fit(len(specs), rsize, scale=scale, max_size=max_size, padding=padding)
    cell_size = scaled(rsize, scale)
    texture = np.zeros((g.size[1], g.size[0], 4), np.uint8)
    cells = []
    for i, ((a, b, t), (box, part)) in enumerate(zip(specs, crops)):
        cell = base_full[ry0:ry1, rx0:rx1].copy()
        if box is not None:
            cell[box[1] - ry0:box[3] - ry0, box[0] - rx0:box[2] - rx0] = part
        cell = _resize(cell, cell_size)
        x, y, w, h = g.rect(i)
        p = padding
        texture[y - p:y + h + p, x - p:x + w + p] = cv2.copyMakeBorder(cell, p, p, p, p, cv2.BORDER_REPLICATE)
        cells.append(Cell((x, y, w, h), a, b, float(t)))
    base: Optional[np.ndarray] = None
    if rsize != (width, height):
        base = base_full.copy()
        base[ry0:ry1, rx0:rx1] = 0
        base = None if not base[..., 3].any() else _resize(base, scaled((width, height), scale))
    atlas = Atlas(image="atlas.png", image_size=g.size, base="atlas.base.png" if base is not None else None,
                  frame_size=(width, height), region=(rx0, ry0, rsize[0], rsize[1]), scale=float(scale),
                  padding=int(padding), bank=bank.name, rest=bank.rest, visemes=tuple(names),
                  method=renderer.method, inbetweens=inbetweens, cells=tuple(cells))
    return AtlasBuild(texture=texture, base=base, atlas=atlas)


def _size(box: Optional[Box], width: int, height: int) -> Tuple[int, int]:
    if box is None:
        return width, height
    return box[2] - box[0], box[3] - box[1]


def _png_bytes(rgba: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".png", cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGRA))
    if not ok:
        raise ValueError(f"could not encode a {rgba.shape} image as PNG")
    return data.tobytes()


def write_atlas(built: AtlasBuild, output: PathLike) -> Atlas:
    """Write ``OUT.png`` (the texture), ``OUT.base.png`` (when there is a base) and ``OUT.json``.

    Each file goes to a temporary name and is renamed into place when complete; the JSON,
    which names the images, is written last.

    Returns
    -------
    Atlas
        As written (image names filled in, ``path`` the JSON file).
    """
    from dataclasses import replace

    from .._files import atomic_write_bytes

    out = Path(os.fspath(output))
    if out.suffix.lower() != ".png":
        raise InputError(f"the atlas texture must be a .png file, got {out.name!r}", path=out)
    json_path = out.with_suffix(".json")
    base_path = out.with_name(out.stem + ".base.png")
    atlas = replace(built.atlas, image=out.name, base=base_path.name if built.base is not None else None,
                    path=str(json_path))
    texture = _png_bytes(built.texture)
    atomic_write_bytes(out, lambda fh: fh.write(texture))
    if built.base is not None:
        base = _png_bytes(built.base)
        atomic_write_bytes(base_path, lambda fh: fh.write(base))
    text = atlas.to_json().encode("utf-8")
    atomic_write_bytes(json_path, lambda fh: fh.write(text))
    return atlas


def compose(atlas: Atlas, texture: np.ndarray, base: Optional[np.ndarray], cell: int) -> np.ndarray:
    """The full frame a cell stands for, as an engine draws it (scale 1): base, then the cell.

    A plain reference for tests and tools; RGBA ``uint8`` ``(H, W, 4)``.
    """
    if atlas.scale != 1.0:
        raise ValueError("compose() draws atlases at scale 1 only")
    w, h = atlas.frame_size
    frame = np.zeros((h, w, 4), np.uint8) if base is None else base.copy()
    x, y, cw, ch = atlas.cells[cell].rect
    rx, ry, rw, rh = atlas.region
    frame[ry:ry + rh, rx:rx + rw] = texture[y:y + ch, x:x + cw]
    return frame
