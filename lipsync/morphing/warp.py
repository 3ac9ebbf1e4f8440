"""Beier–Neely field warping (Beier & Neely 1992; paper eqs. 1–4) and image warps.

Conventions (DESIGN.md): points are ``(x, y)`` with pixel centres at integers; a set of
control lines is a float array ``(L, 2, 2)`` whose line i is ``((Px, Py), (Qx, Qy))``.

For a destination pixel X and a line pair (PQ in the destination, P'Q' in the source)::

    u  = (X-P)·(Q-P) / |Q-P|²          v  = (X-P)·perp(Q-P) / |Q-P|
    X' = P' + u·(Q'-P') + v·perp(Q'-P') / |Q'-P'|
    dist = |v| if 0 <= u <= 1, else |X-P| (u < 0) or |X-Q| (u > 1)
    weight = (length^p / (a + dist))^b,  length = |Q-P|
    X_src = X + Σ weight·(X' - X) / Σ weight

The kernel works on the displacement ``X' - X`` written as ``(P'-P) + u·(e'-e) + v·(n'-n)``
(``e = Q-P``, ``n = perp(e)/|e|``; primes for the source line). That form is exactly zero when a
line does not move, so identical line sets give the identity map without rounding noise,
and it is affine in (x, y): per line every quantity is a sum of a row part and a column
part, so a pixel costs adds, one square root and one division per line.

The per-pixel loop is compiled (``beier_neely_field`` in lipsync/_flowkernel.c, GCC's
vectorised AVX2 copy where the CPU has it; numba's copy in lipsync.morphing._numba_kernels when the
extension is not built): one pass over each block of pixels instead of numpy's ~15 passes
per line, and without the GIL, so preprocessing computes pairs in threads of the calling
process (no worker processes, which a library must not start; see lipsync.morphing.preprocess).
"""

from __future__ import annotations

from typing import Optional, Tuple

import numpy as np

try:  # the compiled field kernel; numba's copy (lipsync.morphing._numba_kernels) when it is not built
    from . import _flowkernel as _compiled
except ImportError:  # pragma: no cover - depends on the install
    _compiled = None

#: Columns per block of the field kernel: the per-line column terms of a block (4 x lines x
#: 64 float32, 42 KB for the toon's 41 lines) stay in cache while every row reuses them, at
#: any image width. 16 to 512 measured within noise of each other on the toon.
BLOCK_COLUMNS = 64
#: Order of the per-line coefficients handed to the kernel (see _line_coefficients).
_COEF_ORDER = ("sx", "sy", "s0", "vx", "vy", "v0", "half", "lenp", "dxx", "dxy", "dx0", "dyx", "dyy", "dy0")


def _as_lines(lines, name: str) -> np.ndarray:
    arr = np.asarray(lines, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[1:] != (2, 2):
        raise ValueError(f"{name} must have shape (L, 2, 2), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains non-finite coordinates")
    return arr


def _line_coefficients(dst: np.ndarray, src: np.ndarray, p: float):
    """Per-line affine coefficients of s, v and the displacement, in float64.

    Returns arrays of shape (L,) used by the kernel: for pixel (x, y)
    ``s = sx*x + sy*y + s0`` (signed distance along the line from its midpoint, in pixels),
    ``v = vx*x + vy*y + v0``, ``Dx = dxx*x + dxy*y + dx0``, ``Dy = dyx*x + dyy*y + dy0``.
    """
    P, Q = dst[:, 0], dst[:, 1]
    Ps, Qs = src[:, 0], src[:, 1]
    e = Q - P
    es = Qs - Ps
    length = np.hypot(e[:, 0], e[:, 1])
    length_s = np.hypot(es[:, 0], es[:, 1])
    if np.any(length <= 0) or np.any(length_s <= 0):
        raise ValueError("zero-length control line")
    # perp((x, y)) = (-y, x); either handedness works if used for both lines.
    n = np.stack([-e[:, 1], e[:, 0]], axis=1) / length[:, None]
    ns = np.stack([-es[:, 1], es[:, 0]], axis=1) / length_s[:, None]
    t = e / length[:, None]  # unit tangent
    # u = (X-P)·e/|e|²; with s = u·|e| - |e|/2 the endpoint test is symmetric: |s| <= |e|/2.
    sx, sy = t[:, 0], t[:, 1]
    s0 = -(P * t).sum(axis=1) - length / 2
    vx, vy = n[:, 0], n[:, 1]
    v0 = -(P * n).sum(axis=1)
    # u = (s + |e|/2) / |e|, so u·(es - e) = (s + |e|/2)·(es - e)/|e|.
    de = (es - e) / length[:, None]
    dn = ns - n
    off = Ps - P + de * (length / 2)[:, None]
    # D = off + s·de + v·dn, expanded in x and y.
    dxx = sx * de[:, 0] + vx * dn[:, 0]
    dxy = sy * de[:, 0] + vy * dn[:, 0]
    dx0 = off[:, 0] + s0 * de[:, 0] + v0 * dn[:, 0]
    dyx = sx * de[:, 1] + vx * dn[:, 1]
    dyy = sy * de[:, 1] + vy * dn[:, 1]
    dy0 = off[:, 1] + s0 * de[:, 1] + v0 * dn[:, 1]
    return dict(sx=sx, sy=sy, s0=s0, vx=vx, vy=vy, v0=v0, half=length / 2,
                lenp=length ** p, dxx=dxx, dxy=dxy, dx0=dx0, dyx=dyx, dyy=dyy, dy0=dy0)


def beier_neely_displacement(shape: Tuple[int, ...], *, dst_lines, src_lines, a: float = 1.0,
                             b: float = 2.0, p: float = 0.5,
                             columns: Optional[Tuple[int, int]] = None, kernel: Optional[str] = None) -> np.ndarray:
    """Displacement field ``X_src - X`` of the Beier–Neely warp, float32 ``(H, W, 2)``.

    Parameters
    ----------
    shape : tuple
        Image shape; only ``(H, W)`` is used.
    dst_lines, src_lines : array_like, shape (L, 2, 2)
        Control lines in the destination and in the source image.
    a, b, p : float
        Weight parameters: ``weight = (length**p / (a + dist))**b``.
    columns : (int, int), optional
        Compute only columns ``[c0, c1)``; the result then has width ``c1 - c0``.
    kernel : {None, "plain", "numba"}, optional
        Force a kernel (for tests and benchmarks): by default the compiled one (its AVX2
        path where the CPU has it), ``plain`` its portable path, ``numba`` numba's copy.
        All give the same floats up to rounding order (see tests/test_warp.py).

    Returns
    -------
    numpy.ndarray
        float32 array; ``[..., 0]`` is the x and ``[..., 1]`` the y displacement.

    Examples
    --------
    >>> lines = [[[10, 10], [30, 10]]]
    >>> moved = [[[12, 13], [32, 13]]]
    >>> d = beier_neely_displacement((40, 40), dst_lines=lines, src_lines=moved)
    >>> [round(float(c), 3) for c in d[5, 5]]
    [2.0, 3.0]
    """
    if a <= 0 or b <= 0 or p < 0:
        raise ValueError("warp parameters need a > 0, b > 0, p >= 0")
    dst = _as_lines(dst_lines, "dst_lines")
    src = _as_lines(src_lines, "src_lines")
    if dst.shape != src.shape:
        raise ValueError(f"dst_lines {dst.shape} and src_lines {src.shape} differ in shape")
    h, w_full = int(shape[0]), int(shape[1])
    c0, c1 = columns if columns is not None else (0, w_full)
    width = c1 - c0
    out = np.empty((h, width, 2), np.float32)
    if dst.shape[0] == 0 or width <= 0 or h <= 0:
        out.fill(0.0)
        return out
    coef = _line_coefficients(dst, src, p)
    table = np.ascontiguousarray(np.stack([coef[k] for k in _COEF_ORDER], axis=1), dtype=np.float64)
    xs = np.arange(c0, c1, dtype=np.float64)
    ys = np.arange(h, dtype=np.float64)
    if _compiled is not None and kernel != "numba":
        _compiled.beier_neely_field(xs, ys, table, out, width, h, len(table), int(BLOCK_COLUMNS),
                                    float(a), float(b), 0 if kernel == "plain" else 2)
    else:
        from ._numba_kernels import beier_neely_field  # numba loads only without the compiled kernel  # numba loads only without the compiled kernel

        beier_neely_field(xs, ys, table, float(a), float(b), int(BLOCK_COLUMNS), out)
    return out


def identity_grid(shape: Tuple[int, ...], dtype=np.float32) -> np.ndarray:
    """Pixel coordinates ``(H, W, 2)`` with ``[y, x] == (x, y)``: the identity map.

    Examples
    --------
    >>> identity_grid((2, 3))[1, 2].tolist()
    [2.0, 1.0]
    """
    h, w = int(shape[0]), int(shape[1])
    grid = np.empty((h, w, 2), dtype)
    grid[..., 0] = np.arange(w, dtype=dtype)[None, :]
    grid[..., 1] = np.arange(h, dtype=dtype)[:, None]
    return grid


def beier_neely_map(shape: Tuple[int, ...], *, dst_lines, src_lines, a: float = 1.0,
                    b: float = 2.0, p: float = 0.5) -> np.ndarray:
    """For every destination pixel, its source position under the Beier–Neely warp.

    Parameters
    ----------
    shape : tuple
        Destination image shape; ``(H, W)`` or ``(H, W, C)``.
    dst_lines : array_like, shape (L, 2, 2)
        Control lines where they are in the destination (the warped image).
    src_lines : array_like, shape (L, 2, 2)
        The same lines where they are in the source image.
    a, b, p : float
        Weight parameters, ``weight = (length**p / (a + dist))**b`` (p = 0 is paper eq. 4).

    Returns
    -------
    numpy.ndarray
        float32 ``(H, W, 2)``: ``[y, x] = (x_src, y_src)``, ready for :func:`cv2.remap`.

    Examples
    --------
    >>> m = beier_neely_map((4, 4), dst_lines=[[[0, 0], [3, 0]]], src_lines=[[[0, 0], [3, 0]]])
    >>> m[2, 3].tolist()
    [3.0, 2.0]
    """
    disp = beier_neely_displacement(shape, dst_lines=dst_lines, src_lines=src_lines, a=a, b=b, p=p)
    disp += identity_grid(shape)
    return disp


def warp(image: np.ndarray, inverse_map: np.ndarray, *, interpolation: str = "linear",
         dst: Optional[np.ndarray] = None) -> np.ndarray:
    """Warp ``image`` by an inverse map: ``out[y, x] = image[inverse_map[y, x]]``.

    Bilinear sampling by default (paper 3.2: nearest-neighbour resampling staircases
    diagonal edges); samples outside the image repeat the border pixel, which suits faces
    whose edges are background.

    Parameters
    ----------
    image : numpy.ndarray
        ``(H, W)`` or ``(H, W, C)`` array.
    inverse_map : numpy.ndarray
        float32 ``(H', W', 2)`` source positions ``(x, y)``.
    interpolation : {"linear", "nearest", "cubic"}
        Resampling kernel.
    dst : numpy.ndarray, optional
        Output buffer of shape ``(H', W') + image.shape[2:]`` to avoid an allocation.

    Examples
    --------
    >>> img = np.arange(12, dtype=np.uint8).reshape(3, 4)
    >>> warp(img, identity_grid(img.shape)).tolist() == img.tolist()
    True
    """
    import cv2

    flags = {"linear": cv2.INTER_LINEAR, "nearest": cv2.INTER_NEAREST, "cubic": cv2.INTER_CUBIC}
    if interpolation not in flags:
        raise ValueError(f"unknown interpolation {interpolation!r}; valid: {', '.join(flags)}")
    m = np.ascontiguousarray(inverse_map, dtype=np.float32)
    return cv2.remap(image, m, None, flags[interpolation], dst=dst, borderMode=cv2.BORDER_REPLICATE)
