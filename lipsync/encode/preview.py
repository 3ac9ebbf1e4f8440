"""Pictures for people: control lines drawn over visemes, preview sheets and morph strips.

Pure drawing on RGB ``uint8`` arrays (or RGBA, straight alpha: a sheet or strip of images
with transparency keeps it, with the lines, captions and gaps opaque); nothing here reads a
bank.  Three uses:

* :func:`draw_lines` — one image with its control lines, to check where lines sit;
* :func:`preview_sheet` — every viseme of a bank with its lines, captioned, in one grid;
* :func:`strip` — a labelled grid of frames, like the paper's figures 8–9 (rows: forward warps,
  blends, backward warps; columns: alpha).

:func:`save_png` writes any of them atomically.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence

import cv2
import numpy as np

from .._files import atomic_write_bytes

__all__ = ["draw_lines", "feature_lines", "preview_sheet", "strip", "save_png"]

# Distinct, saturated colours that stay visible on skin, lips, teeth and dark mouth interiors.
# Lines get them in sorted order of their base name, so a line keeps its colour in every
# viseme of a bank and mirror partners (name_l / name_r) share one.
PALETTE = (
    (230, 25, 75), (60, 180, 75), (0, 130, 200), (245, 130, 48), (145, 30, 180),
    (70, 240, 240), (240, 50, 230), (210, 245, 60), (0, 128, 128), (170, 110, 40),
    (255, 225, 25), (0, 0, 128), (128, 0, 0), (128, 128, 0), (255, 160, 200),
    (100, 100, 255), (255, 100, 0), (0, 200, 150), (190, 190, 0), (90, 0, 200),
)
FONT = cv2.FONT_HERSHEY_SIMPLEX
BACKGROUND = (245, 245, 245)
TEXT = (20, 20, 20)
# Space between grid cells, in pixels: enough to separate frames without wasting the sheet.
GAP = 4


def _base_name(name: str) -> str:
    return name[:-2] if name.endswith(("_l", "_r")) else name


def _as_rgb(image, what: str = "image") -> np.ndarray:
    """The image as uint8 RGB ``(H, W, 3)`` or RGBA ``(H, W, 4)`` (a grey image becomes RGB)."""
    a = np.asarray(image)
    if a.ndim == 2:
        a = np.repeat(a[:, :, None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] not in (3, 4) or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"{what} must be an RGB array (H, W, 3) or RGBA (H, W, 4), got shape {a.shape}")
    if a.dtype != np.uint8:
        a = np.clip(np.round(a.astype(np.float64)), 0, 255).astype(np.uint8)
    return a


def _ink(colour, img: np.ndarray) -> tuple:
    """A drawing colour for ``img``: opaque on RGBA (cv2 would draw alpha 0 with an RGB tuple)."""
    return tuple(colour) + (255,) if img.shape[2] == 4 else tuple(colour)


def _with_channels(img: np.ndarray, channels: int) -> np.ndarray:
    if img.shape[2] == channels:
        return img
    return cv2.cvtColor(img, cv2.COLOR_RGB2RGBA)  # only ever RGB -> RGBA (opaque)


def _as_line(name: str, line) -> np.ndarray:
    """A line ``(2, 2)`` or a curve as its chain of segments ``(N, 2, 2)``."""
    a = np.asarray(line, dtype=np.float64)
    ok = a.shape == (2, 2) or (a.ndim == 3 and a.shape[0] >= 1 and a.shape[1:] == (2, 2))
    if not ok or not np.all(np.isfinite(a)):
        raise ValueError(f"line {name!r} must be [[Px, Py], [Qx, Qy]] (or a curve's (N, 2, 2) "
                         f"segments) with finite numbers, got {line!r}")
    return a


def feature_lines(line_names, lines) -> dict[str, np.ndarray]:
    """Group a bank's expanded lines by feature: curve segments ``name#i`` become one entry.

    Parameters
    ----------
    line_names : sequence of str
        ``Bank.line_names``.
    lines : array_like (L, 2, 2)
        One viseme's lines in that order.

    Returns
    -------
    dict
        Feature name → ``(2, 2)`` for a line, ``(N, 2, 2)`` for a curve's segments, ready for
        :func:`draw_lines`.

    Examples
    --------
    >>> import numpy as np
    >>> out = feature_lines(["nose", "lip#0", "lip#1"], np.zeros((3, 2, 2)))
    >>> {k: v.shape for k, v in out.items()}
    {'nose': (2, 2), 'lip': (2, 2, 2)}
    """
    arr = np.asarray(lines, dtype=np.float64)
    out: dict[str, list] = {}
    for i, n in enumerate(line_names):
        base, sep, _ = str(n).partition("#")
        out.setdefault(base if sep else str(n), []).append((sep, arr[i]))
    return {k: (np.stack([a for _, a in v]) if v[0][0] else v[0][1]) for k, v in out.items()}


def _colours(names) -> dict[str, tuple[int, int, int]]:
    bases = sorted({_base_name(n) for n in names})
    return {b: PALETTE[i % len(PALETTE)] for i, b in enumerate(bases)}


def _scale_for(shape) -> float:
    # Marks and text are sized for a 512-pixel image and scale with the image.
    return max(min(shape[0], shape[1]) / 512.0, 0.5)


def _text(img, s: str, org, scale: float, colour, *, outline=True):
    thick = max(1, round(scale * 2))
    if outline:
        cv2.putText(img, s, org, FONT, scale, _ink((0, 0, 0), img), thick + 2, cv2.LINE_AA)
    cv2.putText(img, s, org, FONT, scale, _ink(colour, img), thick, cv2.LINE_AA)


def draw_lines(image, lines: Mapping[str, object], *, labels: bool = True) -> np.ndarray:
    """Draw control lines over a copy of an RGB image.

    Each line is drawn from P to Q with a filled dot at P and an arrow head at Q, so its
    direction shows.  Mirror partners (``name_l`` / ``name_r``) share a colour.

    Parameters
    ----------
    image : array_like, (H, W, 3) uint8
        RGB image (a 2-D grey image is accepted and drawn in colour).
    lines : Mapping[str, array_like (2, 2) or (N, 2, 2)]
        Line name → ``[[Px, Py], [Qx, Qy]]`` in pixels (x right, y down), or a curve's
        segments (see :func:`feature_lines`), drawn as one chain with ticks at the joins.
    labels : bool, default True
        Write each line's name beside it in small text.

    Returns
    -------
    numpy.ndarray
        A new (H, W, 3) uint8 RGB image; ``image`` is not modified.

    Raises
    ------
    ValueError
        If the image is not (H, W, 3) or a line is not a finite 2×2 array.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.zeros((64, 64, 3), np.uint8)
    >>> out = draw_lines(img, {"lip_l": [[10, 32], [30, 32]]}, labels=False)
    >>> out.shape, bool(out[32, 20].any()), bool(out[5, 5].any())
    ((64, 64, 3), True, False)
    """
    out = _as_rgb(image).copy()
    parsed = {str(n): _as_line(str(n), l) for n, l in lines.items()}
    colours = _colours(parsed)
    k = _scale_for(out.shape)
    thick = max(1, round(1.2 * k))
    dot = max(2, round(2.5 * k))
    # cv2 draws with integer vertices plus fractional bits; 4 bits is 1/16 pixel.
    frac = 4
    one = 1 << frac
    def fixed(point):
        return tuple(int(round(v * one)) for v in point)

    for name, shape in parsed.items():
        col = _ink(colours[_base_name(name)], out)
        if shape.ndim == 3:  # a curve: its segments as one chain, small ticks at the joins
            chain = np.concatenate([shape[:, 0], shape[-1:, 1]])
            if len(chain) > 2:
                cv2.polylines(out, [np.round(chain[:-1] * one).astype(np.int32)], False, col, thick,
                              cv2.LINE_AA, frac)
                for joint in chain[1:-1]:
                    cv2.circle(out, fixed(joint), max(1, dot // 2) * one, col, -1, cv2.LINE_AA, frac)
            p, q = shape[-1]
            start = chain[0]
        else:
            p, q = shape
            start = p
        length = float(np.hypot(*(q - p)))
        # Arrow heads of a fixed size in pixels, whatever the line's length.
        tip = min(0.6, 7.0 * k / length) if length > 0 else 0.0
        cv2.arrowedLine(out, fixed(p), fixed(q), col, thick, cv2.LINE_AA, frac, tip)
        cv2.circle(out, fixed(start), dot * one, col, -1, cv2.LINE_AA, frac)
    if labels:
        scale = 0.3 * k
        for name, shape in parsed.items():
            col = colours[_base_name(name)]
            # A curve is labelled beside its middle segment.
            p, q = shape[len(shape) // 2] if shape.ndim == 3 else shape
            mid = (p + q) / 2
            d = q - p
            n = np.array([-d[1], d[0]]) / (np.hypot(*d) or 1.0)
            # Put the name on the side away from the image's vertical centre line, so the
            # two halves of a symmetric set do not write over each other.
            if n[0] * (mid[0] - out.shape[1] / 2) < 0 or (n[0] == 0 and n[1] < 0):
                n = -n
            (tw, th), _ = cv2.getTextSize(name, FONT, scale, 1)
            at = mid + n * 6 * k
            x = int(round(at[0] - (tw if at[0] < mid[0] - 1 else 0 if at[0] > mid[0] + 1
                                   else tw / 2)))
            y = int(round(at[1] + th / 2))
            _text(out, name, (x, y), scale, col)
    return out


def _resize_to_width(img: np.ndarray, width: int | None) -> tuple[np.ndarray, float]:
    if width is None or width == img.shape[1]:
        return img, 1.0
    if width < 1:
        raise ValueError(f"tile width must be a positive number of pixels, got {width}")
    f = width / img.shape[1]
    h = max(1, round(img.shape[0] * f))
    interp = cv2.INTER_AREA if f < 1 else cv2.INTER_CUBIC
    if img.shape[2] == 4:  # resampled premultiplied: no dark rim around transparency
        from ..morphing.alpha import resize_rgba

        return resize_rgba(img, (width, h), interpolation=interp), f
    return cv2.resize(img, (width, h), interpolation=interp), f


def _grid(cells: list[list[np.ndarray | None]], *, top: int = 0, left: int = 0):
    """Place cells on a background; return the canvas and every cell's (y, x) origin."""
    ch = max((c.shape[0] for row in cells for c in row if c is not None), default=1)
    cw = max((c.shape[1] for row in cells for c in row if c is not None), default=1)
    ncols = max((len(r) for r in cells), default=0)
    H = top + GAP + len(cells) * (ch + GAP)
    W = left + GAP + ncols * (cw + GAP)
    channels = max((c.shape[2] for row in cells for c in row if c is not None), default=3)
    canvas = np.empty((H, W, channels), np.uint8)
    canvas[:] = _ink(BACKGROUND, canvas)
    origins = []
    for r, row in enumerate(cells):
        for c, cell in enumerate(row):
            y, x = top + GAP + r * (ch + GAP), left + GAP + c * (cw + GAP)
            origins.append((y, x))
            if cell is not None:
                canvas[y:y + cell.shape[0], x:x + cell.shape[1]] = _with_channels(cell, channels)
    return canvas, origins, (ch, cw)


def _caption(img: np.ndarray, text: str) -> np.ndarray:
    k = _scale_for(img.shape)
    scale = 0.6 * k
    thick = max(1, round(scale * 2))
    (tw, _), _ = cv2.getTextSize(text, FONT, scale, thick)
    # The band's height comes from the font, not the text, so every caption is equally tall.
    (_, th), base = cv2.getTextSize("Ag", FONT, scale, thick)
    band = np.empty((th + base + 10, img.shape[1], img.shape[2]), np.uint8)
    band[:] = _ink(BACKGROUND, band)
    _text(band, text, ((img.shape[1] - tw) // 2, th + 5), scale, TEXT, outline=False)
    return np.concatenate([band, img], axis=0)


def preview_sheet(images: Mapping[str, object], lines: Mapping[str, Mapping[str, object]], *,
                  columns: int | None = None, tile: int | None = None) -> np.ndarray:
    """Every viseme with its control lines and names, captioned, in one grid.

    Parameters
    ----------
    images : Mapping[str, array_like (H, W, 3) uint8]
        Viseme name → RGB image, in the order to show them.
    lines : Mapping[str, Mapping[str, array_like (2, 2)]]
        Viseme name → its control lines (as for :func:`draw_lines`); a viseme missing here is
        shown without lines.
    columns : int, optional
        Number of grid columns; default ``ceil(sqrt(n))``.
    tile : int, optional
        Scale every image to this width (aspect kept) before drawing, so the sheet stays small
        and the line names stay legible.

    Returns
    -------
    numpy.ndarray
        The sheet, RGB uint8.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.full((40, 60, 3), 200, np.uint8)
    >>> sheet = preview_sheet({"A": img, "B": img}, {"A": {"x": [[5, 5], [50, 30]]}}, columns=2)
    >>> sheet.shape[1] == 3 * GAP + 2 * 60
    True
    """
    names = list(images)
    if not names:
        raise ValueError("preview_sheet needs at least one image")
    ncols = columns if columns is not None else math.ceil(math.sqrt(len(names)))
    if ncols < 1:
        raise ValueError(f"columns must be at least 1, got {columns}")
    cells = []
    for name in names:
        img, f = _resize_to_width(_as_rgb(images[name], f"image {name!r}"), tile)
        # Pixel centres sit at integers, so scaling by f maps x to (x + 0.5) f - 0.5.
        scaled = {ln: (l + 0.5) * f - 0.5 for ln, l in
                  ((ln, _as_line(ln, l)) for ln, l in (lines.get(name) or {}).items())}
        cells.append(_caption(draw_lines(img, scaled), str(name)))
    rows = [cells[i:i + ncols] for i in range(0, len(cells), ncols)]
    return _grid(rows)[0]


def strip(rows: Sequence[Sequence[object]], *, row_labels: Sequence[str] = (),
          column_labels: Sequence[str] = (), tile: int | None = None) -> np.ndarray:
    """A labelled grid of images, like the paper's figures 8–9.

    Parameters
    ----------
    rows : sequence of sequences of array_like (H, W, 3) uint8
        ``rows[r][c]`` is shown in row r, column c; rows may differ in length.
    row_labels : sequence of str, optional
        One label per row, written in a margin on the left.
    column_labels : sequence of str, optional
        One label per column, written in a margin on top (e.g. ``"α=0.25"``).
    tile : int, optional
        Scale every image to this width (aspect kept).

    Returns
    -------
    numpy.ndarray
        RGB uint8.  Cells are ``GAP`` pixels apart and ``GAP`` from the edges (after the label
        margins); every cell has the size of the largest (scaled) image.

    Raises
    ------
    ValueError
        If there are no rows, or labels are given but their number does not match.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.zeros((10, 20, 3), np.uint8)
    >>> strip([[a, a, a], [a, a, a]]).shape == (3 * GAP + 2 * 10, 4 * GAP + 3 * 20, 3)
    True
    """
    if not rows or not any(len(r) for r in rows):
        raise ValueError("strip needs at least one image")
    ncols = max(len(r) for r in rows)
    if row_labels and len(row_labels) != len(rows):
        raise ValueError(f"{len(row_labels)} row labels for {len(rows)} rows")
    if column_labels and len(column_labels) != ncols:
        raise ValueError(f"{len(column_labels)} column labels for {ncols} columns")
    cells = [[_resize_to_width(_as_rgb(im, f"image at row {r}, column {c}"), tile)[0]
              for c, im in enumerate(row)] for r, row in enumerate(rows)]
    ch = max(c.shape[0] for row in cells for c in row)
    cw = max(c.shape[1] for row in cells for c in row)
    scale = 0.5 * _scale_for((ch, cw))
    thick = max(1, round(scale * 2))
    left = top = 0
    if row_labels:
        left = max(cv2.getTextSize(str(s), FONT, scale, thick)[0][0] for s in row_labels) + 2 * GAP
    if column_labels:
        sizes = [cv2.getTextSize(str(s), FONT, scale, thick) for s in column_labels]
        top = max(h + b for (_, h), b in sizes) + 2 * GAP
    canvas, origins, _ = _grid(cells, top=top, left=left)
    for r, label in enumerate(row_labels):
        (tw, th), _ = cv2.getTextSize(str(label), FONT, scale, thick)
        y = top + GAP + r * (ch + GAP) + (ch + th) // 2
        _text(canvas, str(label), (left - GAP - tw, y), scale, TEXT, outline=False)
    for c, label in enumerate(column_labels):
        (tw, th), base = cv2.getTextSize(str(label), FONT, scale, thick)
        x = left + GAP + c * (cw + GAP) + (cw - tw) // 2
        _text(canvas, str(label), (x, top - GAP - base), scale, TEXT, outline=False)
    return canvas


def save_png(path, rgb) -> None:
    """Write an RGB image to a PNG file atomically.

    The image is encoded in memory, written to a temporary file in the destination folder and
    renamed over ``path`` only when complete, so readers never see a partial file.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; its folder must exist.
    rgb : array_like, (H, W, 3) or (H, W, 4) uint8
        RGB image, or RGBA (written with its alpha); a 2-D grey image is accepted.

    Examples
    --------
    >>> import numpy as np, tempfile, os, cv2
    >>> p = os.path.join(tempfile.mkdtemp(), "red.png")
    >>> save_png(p, np.full((2, 2, 3), (255, 0, 0), np.uint8))
    >>> cv2.imread(p)[0, 0].tolist()   # OpenCV reads BGR
    [0, 0, 255]
    """
    img = _as_rgb(rgb)
    ok, data = cv2.imencode(".png", cv2.cvtColor(img, cv2.COLOR_RGBA2BGRA if img.shape[2] == 4 else cv2.COLOR_RGB2BGR))
    if not ok:
        raise ValueError(f"could not encode a {img.shape} image as PNG")
    atomic_write_bytes(path, lambda fh: fh.write(data.tobytes()))
