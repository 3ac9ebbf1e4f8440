"""Pixel flows between visemes (paper 3.3), with symmetric halving.

For an ordered pair (A, B), ``forward_flow`` lives on A's pixel grid: pixel X of A moves to
``X + forward_flow(X)`` in B. It is the Beier–Neely displacement with A's lines as the
destination and B's lines as the source; ``backward_flow`` (on B's grid) swaps the roles.

When both line sets are mirror-symmetric about ``x = axis``, the warp commutes with the
reflection, so the field on the right of the axis is the reflection of the field on the
left with its x component negated. Only the left columns (plus any right columns whose
mirror falls outside the image) are computed; the rest is a column flip.
"""

from __future__ import annotations

import math
from typing import Optional, Sequence, Tuple

import numpy as np

from .bank import WarpParams
from .normalise import is_symmetric
from .warp import beier_neely_displacement


def _mirror_plan(width: int, axis: float) -> Tuple[int, int, int]:
    """Columns to compute: ``[0, left_end)`` and ``[right_start, width)``; columns between are mirrored.

    ``axis`` must be a multiple of 0.5 so that column ``x`` mirrors to column ``2*axis - x``.
    """
    two_c = int(round(2 * axis))
    left_end = min(width, max(0, math.floor(axis) + 1))
    right_start = min(width, max(left_end, two_c + 1))  # columns beyond 2c have no mirror
    return left_end, right_start, two_c


def mirror_fill(field: np.ndarray, axis: float) -> None:
    """Fill the mirrored columns of ``field`` (H, W, 2) in place from the computed ones.

    Examples
    --------
    >>> f = np.zeros((1, 4, 2), np.float32)
    >>> f[0, :2] = [[1, 5], [2, 6]]
    >>> mirror_fill(f, axis=1.5)
    >>> f[0].tolist()
    [[1.0, 5.0], [2.0, 6.0], [-2.0, 6.0], [-1.0, 5.0]]
    """
    width = field.shape[1]
    left_end, right_start, two_c = _mirror_plan(width, axis)
    cols = np.arange(left_end, right_start)
    if cols.size == 0:
        return
    src = two_c - cols
    field[:, cols, 0] = -field[:, src, 0]
    field[:, cols, 1] = field[:, src, 1]


def flow_field(shape: Tuple[int, ...], dst_lines: np.ndarray, src_lines: np.ndarray, warp: WarpParams,
               *, axis: Optional[float] = None) -> np.ndarray:
    """Displacement field from ``dst_lines`` to ``src_lines``, halved by symmetry if possible.

    Parameters
    ----------
    shape : tuple
        ``(H, W)`` of the images.
    dst_lines, src_lines : numpy.ndarray
        ``(L, 2, 2)`` control lines; the field lives on the grid of the image whose lines
        are ``dst_lines``.
    warp : WarpParams
        Weight parameters.
    axis : float, optional
        Mirror axis (a multiple of 0.5). Used only when both line sets are exactly
        symmetric about it; pass the line names via :func:`pair_flows` for that check.

    Returns
    -------
    numpy.ndarray
        float32 ``(H, W, 2)``.

    Examples
    --------
    >>> from lipsync.bank import WarpParams
    >>> a = np.array([[[2.0, 2.0], [2.0, 8.0]]]); b = a + [1.0, 0.0]
    >>> float(flow_field((10, 10), a, b, WarpParams())[5, 5, 0])
    1.0
    """
    h, w = int(shape[0]), int(shape[1])
    kw = dict(dst_lines=dst_lines, src_lines=src_lines, a=warp.a, b=warp.b, p=warp.p)
    if axis is None:
        return beier_neely_displacement((h, w), **kw)
    left_end, right_start, _ = _mirror_plan(w, axis)
    field = np.empty((h, w, 2), np.float32)
    if left_end > 0:
        field[:, :left_end] = beier_neely_displacement((h, w), columns=(0, left_end), **kw)
    if right_start < w:
        field[:, right_start:] = beier_neely_displacement((h, w), columns=(right_start, w), **kw)
    mirror_fill(field, axis)
    return field


def pair_flows(shape: Tuple[int, ...], lines_a: np.ndarray, lines_b: np.ndarray, warp: WarpParams,
               *, line_names: Sequence[str] = (), axis: Optional[float] = None
               ) -> Tuple[np.ndarray, np.ndarray]:
    """``(forward_flow, backward_flow)`` between visemes A and B (paper 3.3).

    Symmetric halving is used when ``axis`` is given and both line sets are exactly
    symmetric about it (checked with ``line_names``); otherwise fields are computed whole.

    Examples
    --------
    >>> from lipsync.bank import WarpParams
    >>> a = np.array([[[2.0, 2.0], [2.0, 8.0]]]); b = a + [0.0, 1.0]
    >>> fwd, bwd = pair_flows((10, 10), a, b, WarpParams())
    >>> float(fwd[4, 4, 1]), float(bwd[4, 4, 1])
    (1.0, -1.0)
    """
    use_axis = None
    if axis is not None and line_names and is_symmetric(lines_a, line_names, axis) \
            and is_symmetric(lines_b, line_names, axis):
        use_axis = axis
    forward = flow_field(shape, lines_a, lines_b, warp, axis=use_axis)
    backward = flow_field(shape, lines_b, lines_a, warp, axis=use_axis)
    return forward, backward
