"""Packing equal cells into a texture: a grid as close to square as the count allows.

Every cell has the same size (they are all the same region of the frame), so a grid is the
tightest packing there is and an engine can also find a cell by arithmetic. Each cell gets
``padding`` pixels on every side that repeat its edge pixels, so that bilinear filtering and
mipmaps at the cell's border sample the cell itself, not its neighbour.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Tuple

from ..errors import InputError

#: Default largest texture side. 4096 is what every desktop GPU and nearly all mobile ones
#: of the last decade accept (WebGL 1 guarantees only 2048; desktop GL 4 and D3D11 16384).
DEFAULT_MAX_SIZE = 4096
#: Pixels around each cell repeating its edge. 2 covers bilinear filtering and one mip level.
DEFAULT_PADDING = 2


@dataclass(frozen=True)
class Grid:
    """Columns and rows of cells ``cell_size`` big (without padding) in a ``size`` texture."""

    cols: int
    rows: int
    cell_size: Tuple[int, int]
    padding: int

    @property
    def size(self) -> Tuple[int, int]:
        w, h = self.cell_size
        return self.cols * (w + 2 * self.padding), self.rows * (h + 2 * self.padding)

    def rect(self, i: int) -> Tuple[int, int, int, int]:
        """Cell i's rectangle (x, y, w, h) inside its padding, row by row."""
        w, h = self.cell_size
        r, c = divmod(i, self.cols)
        return c * (w + 2 * self.padding) + self.padding, r * (h + 2 * self.padding) + self.padding, w, h


def grid(n: int, cell_size: Tuple[int, int], padding: int = DEFAULT_PADDING) -> Grid:
    """The grid of ``n`` cells with the smallest longest side (then the least area).

    Examples
    --------
    >>> g = grid(10, (100, 50), padding=0)
    >>> (g.cols, g.rows), g.size, g.rect(4)
    ((3, 4), (300, 200), (100, 50, 100, 50))
    """
    if n < 1:
        raise ValueError("a grid needs at least one cell")
    w, h = cell_size[0] + 2 * padding, cell_size[1] + 2 * padding
    best = None
    for cols in range(1, n + 1):
        rows = math.ceil(n / cols)
        key = (max(cols * w, rows * h), cols * w * rows * h, cols)
        if best is None or key < best[0]:
            best = (key, cols, rows)
    return Grid(best[1], best[2], (int(cell_size[0]), int(cell_size[1])), padding)


def scaled(size: Tuple[int, int], scale: float) -> Tuple[int, int]:
    """A size times ``scale``, rounded, at least one pixel."""
    return max(1, int(round(size[0] * scale))), max(1, int(round(size[1] * scale)))


def fit(n: int, region: Tuple[int, int], *, scale: float, max_size: int,
        padding: int = DEFAULT_PADDING) -> Grid:
    """The grid at ``scale``, or InputError saying what would fit when it exceeds ``max_size``.

    Examples
    --------
    >>> fit(4, (100, 100), scale=1.0, max_size=256, padding=2).size
    (208, 208)
    >>> fit(9, (100, 100), scale=1.0, max_size=256, padding=2)
    Traceback (most recent call last):
    ...
    lipsync.errors.InputError: the atlas would be 312 x 312 px, above --max-size 256: use --scale 0.8 (or fewer --inbetweens, --pairs used, a larger --max-size)
    """
    g = grid(n, scaled(region, scale), padding)
    if max(g.size) <= max_size:
        return g
    # the largest scale (two decimals) that fits, found by stepping down
    s = math.floor(scale * 100) / 100
    while s > 0.01 and max(grid(n, scaled(region, s), padding).size) > max_size:
        s = round(s - 0.01, 2)
    hint = f"use --scale {s:g}" if s > 0.01 else "it does not fit at any scale"
    w, h = g.size
    raise InputError(f"the atlas would be {w} x {h} px, above --max-size {max_size}: {hint} "
                     f"(or fewer --inbetweens, --pairs used, a larger --max-size)")


def rects(g: Grid, n: int) -> List[Tuple[int, int, int, int]]:
    """The first ``n`` cell rectangles of a grid."""
    return [g.rect(i) for i in range(n)]
