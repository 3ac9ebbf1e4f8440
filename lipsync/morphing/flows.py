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

from ..banks.bank import WarpParams
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
    if right_start <= left_end:
        return
    # Column c takes column two_c - c: for c in [left_end, right_start) a descending run of
    # columns, so plain slices (views) instead of fancy indexing, which cost as much as the
    # compiled field itself (the halving then saved nothing).
    stop = two_c - right_start
    src = field[:, two_c - left_end: (stop if stop >= 0 else None): -1]
    np.negative(src[..., 0], out=field[:, left_end:right_start, 0])
    field[:, left_end:right_start, 1] = src[..., 1]


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
    >>> from lipsync.banks.bank import WarpParams
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
    >>> from lipsync.banks.bank import WarpParams
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


# --------------------------------------------------------------------------- inverse maps
#
# A frame at alpha needs, for every output pixel Y, the X with X + t F(X) = Y (t = alpha for
# the first image, 1 - alpha for the second). That inversion is per-pair work, so it is done
# here, once, at a table of t, and stored; the renderer only interpolates the tables.

#: Newton steps per table entry, warm-started from the previous entry (continuation in t).
#: One more than a frame could once afford (3 from the first-order guess): 4 steps from the
#: previous table converge wherever the warp does not fold (tests/test_render.py: vs 30 steps).
TABLE_ITERATIONS = 4
#: Smallest Jacobian determinant a Newton step divides by. Where the warp folds over
#: (det <= 0) there is no unique inverse; clamping keeps those rare pixels finite.
MIN_DET = 0.05
#: Largest Newton correction (px) per step, for the same reason.
MAX_STEP = 4.0
#: Inverse maps are solved and stored on every SOLVE_STEP-th pixel and upsampled bilinearly
#: at render time: the map is smooth, so this costs under 0.05 px on average
#: (tests/test_render.py) for a quarter of the storage and solving.
SOLVE_STEP = 2
#: Tables at t = k / TABLE_STEPS, k = 1..TABLE_STEPS (t = 0 is the identity, not stored).
#: The renderer interpolates the four nearest in t with a cubic; 4 steps keep the store at
#: 4 bytes per field pixel for whole-frame motion (see lipsync.morphing.store) and the residual of
#: X + t F(X) = Y under 0.05 px at ~99% of the pixels where a per-frame Newton solve gets it
#: there (measured in tests/test_render.py).
TABLE_STEPS = 4


def flow_jacobian(flow: np.ndarray) -> np.ndarray:
    """d(flow)/d(x, y) by central differences, as (h, w, 4): dFx/dx, dFx/dy, dFy/dx, dFy/dy.

    Examples
    --------
    >>> f = np.zeros((3, 4, 2), np.float32); f[..., 0] = 2.0 * np.arange(4)
    >>> flow_jacobian(f)[1, 1].tolist()
    [2.0, 0.0, 0.0, 0.0]
    """
    jac = np.empty(flow.shape[:2] + (4,), np.float32)
    for c in range(2):
        if flow.shape[0] > 1 and flow.shape[1] > 1:
            gy, gx = np.gradient(flow[..., c])
        else:
            gy = gx = np.zeros(flow.shape[:2], np.float32)
        jac[..., 2 * c] = gx
        jac[..., 2 * c + 1] = gy
    return jac


def newton_invert(flow: np.ndarray, jac: np.ndarray, t: float, points: np.ndarray, m: np.ndarray,
                  iterations: int) -> None:
    """Refine ``m`` toward the X with ``X + t*flow(X) = points``, in place (Newton's method).

    ``points`` and ``m`` are float32 ``(h, w, 2)`` positions in ``flow``'s pixel
    coordinates; ``jac`` is :func:`flow_jacobian` of ``flow``. The plain fixed-point
    iteration ``X <- Y - t F(X)`` diverges where ``t |dF/dX| > 1``, which is exactly where a
    closed mouth opens (the lips' gap expands five-fold or more); Newton's step divides by
    ``I + t J`` instead.

    Examples
    --------
    >>> f = np.zeros((8, 8, 2), np.float32); f[..., 0] = 0.5 * np.arange(8)  # x -> 1.5 x
    >>> y = np.array([[[3.0, 2.0]]], np.float32); m = y.copy()
    >>> newton_invert(f, flow_jacobian(f), 1.0, y, m, 3)
    >>> [round(float(v), 3) for v in m[0, 0]]
    [2.0, 2.0]
    """
    import cv2

    sampled = np.empty_like(m)
    js = np.empty(m.shape[:2] + (4,), np.float32)
    mx, my = m[..., 0], m[..., 1]
    for _ in range(iterations):
        cv2.remap(flow, m, None, cv2.INTER_LINEAR, dst=sampled, borderMode=cv2.BORDER_REPLICATE)
        cv2.remap(jac, m, None, cv2.INTER_LINEAR, dst=js, borderMode=cv2.BORDER_REPLICATE)
        rx = mx + t * sampled[..., 0] - points[..., 0]   # residual X + t F(X) - Y
        ry = my + t * sampled[..., 1] - points[..., 1]
        a = 1.0 + t * js[..., 0]                          # I + t J = [[a, b], [c, d]]
        b = t * js[..., 1]
        c = t * js[..., 2]
        d = 1.0 + t * js[..., 3]
        det = np.maximum(a * d - b * c, MIN_DET)
        mx -= np.clip((d * rx - b * ry) / det, -MAX_STEP, MAX_STEP)
        my -= np.clip((a * ry - c * rx) / det, -MAX_STEP, MAX_STEP)


def coarse_points(box_shape: Tuple[int, int], origin: Tuple[int, int] = (0, 0),
                  step: int = SOLVE_STEP) -> np.ndarray:
    """Centres of the coarse solve grid over a box, float32 ``(hc, wc, 2)`` in image pixels.

    Coarse point (i, j) sits at the centre of the ``step`` x ``step`` block it covers, the
    position bilinear upsampling by ``step`` (cv2.resize's convention) puts it at.

    Examples
    --------
    >>> coarse_points((4, 3), origin=(10, 20))[:, :, 0].tolist()[0]
    [20.5, 22.5]
    """
    h, w = int(box_shape[0]), int(box_shape[1])
    hc, wc = -(-h // step), -(-w // step)
    pts = np.empty((hc, wc, 2), np.float32)
    pts[..., 0] = (np.arange(wc) * step + (step - 1) / 2.0 + origin[1])[None, :]
    pts[..., 1] = (np.arange(hc) * step + (step - 1) / 2.0 + origin[0])[:, None]
    return pts


def inverse_tables(flow: np.ndarray, origin: Tuple[int, int], box_shape: Tuple[int, int],
                   steps: int = TABLE_STEPS, *, iterations: int = TABLE_ITERATIONS) -> np.ndarray:
    """Inverse displacements ``X - Y`` with ``X + t F(X) = Y`` at ``t = k / steps``.

    Parameters
    ----------
    flow : numpy.ndarray
        float32 ``(H, W, 2)`` field F (as the renderer will see it: dead-zoned, rounded).
    origin, box_shape : (int, int)
        Top-left ``(y0, x0)`` and ``(h, w)`` of the box the tables cover.
    steps : int
        Tables at ``t = 1/steps, 2/steps, ..., 1``.

    Returns
    -------
    numpy.ndarray
        float32 ``(steps, hc, wc, 2)`` on :func:`coarse_points` of the box.

    Examples
    --------
    >>> f = np.zeros((6, 6, 2), np.float32); f[..., 1] = 1.0   # everything moves down 1 px
    >>> tab = inverse_tables(f, (0, 0), (6, 6), 2)
    >>> tab.shape, float(tab[0, 1, 1, 1]), float(tab[1, 1, 1, 1])
    ((2, 3, 3, 2), -0.5, -1.0)
    """
    import cv2

    points = coarse_points(box_shape, origin)
    jac = flow_jacobian(flow)
    out = np.empty((steps,) + points.shape, np.float32)
    # First-order guess at the first t, then each table warm-starts from the one before.
    m = points - (1.0 / steps) * cv2.remap(flow, points, None, cv2.INTER_LINEAR,
                                           borderMode=cv2.BORDER_REPLICATE)
    for k in range(1, steps + 1):
        newton_invert(flow, jac, k / steps, points, m, iterations)
        out[k - 1] = m - points
    return out
