"""Comparing two pictures of one face: register by the still points, then judge the mouth.

What every real-footage measurement needs (a rendered frame against the real one, an
in-between against the real frame between): the two faces put on top of each other by a
similarity transform fitted on points that do not move in speech
(:data:`~lipsync.face.topology.STILL_POINTS`: eye corners and the nose bridge), a mouth
region defined from the face itself, and the usual image measures on that region.

Examples
--------
>>> import numpy as np
>>> a = np.zeros((40, 40, 3), np.uint8); b = a.copy(); b[10:20, 10:20] = 20
>>> round(float(psnr(a, b)), 2)
34.15
>>> round(ssim(a, a), 3)
1.0
"""

from __future__ import annotations

from typing import Optional, Tuple

import cv2
import numpy as np

from . import topology as T
from .measure import eye_centres

#: The mouth region reaches this many eye distances beyond the outer lip contour sideways
#: and up (the skin the lips move), and down over the chin, which the jaw moves with them.
MOUTH_MARGIN_SIDE = 0.25
MOUTH_MARGIN_UP = 0.2
MOUTH_MARGIN_DOWN = 0.45


def similarity_from_points(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares similarity (rotation, uniform scale, shift) taking ``src`` onto ``dst``.

    Umeyama's closed form on ``(N, 2)`` point sets; returns a 2×3 matrix for cv2.warpAffine.

    Examples
    --------
    >>> src = np.array([[0.0, 0], [10, 0], [0, 10]])
    >>> m = similarity_from_points(src, src * 2 + [5, 1])
    >>> np.round(m, 6).tolist()
    [[2.0, 0.0, 5.0], [0.0, 2.0, 1.0]]
    """
    src = np.asarray(src, np.float64)[:, :2]
    dst = np.asarray(dst, np.float64)[:, :2]
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    cov = b.T @ a / len(src)
    u, s, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u @ vt))
    fix = np.diag([1.0, d])
    r = u @ fix @ vt
    scale = (s * np.diag(fix)).sum() / (a ** 2).sum(1).mean()
    m = np.empty((2, 3))
    m[:, :2] = scale * r
    m[:, 2] = md - scale * r @ ms
    return m


def register(image: np.ndarray, points: np.ndarray, onto: np.ndarray, shape: Optional[Tuple[int, int]] = None
             ) -> Tuple[np.ndarray, np.ndarray, float]:
    """Warp ``image`` (whose face has mesh ``points``) so its still points lie on ``onto``'s.

    Parameters
    ----------
    image : numpy.ndarray
        The picture to move.
    points, onto : numpy.ndarray
        Mesh points ``(468, 2|3)`` of ``image`` and of the picture to register onto.
    shape : tuple of int, optional
        ``(H, W)`` of the output (default: ``image``'s).

    Returns
    -------
    warped : numpy.ndarray
        ``image`` registered (bilinear; outside pixels replicate the border).
    matrix : numpy.ndarray
        The 2×3 similarity used.
    residual : float
        RMS distance of the still points after registration, in eye distances of ``onto``.
    """
    still = list(T.STILL_POINTS)
    m = similarity_from_points(points[still], onto[still])
    h, w = shape or image.shape[:2]
    warped = cv2.warpAffine(image, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    moved = np.asarray(points, np.float64)[still, :2] @ m[:, :2].T + m[:, 2]
    a, b = eye_centres(onto)
    residual = float(np.sqrt(((moved - np.asarray(onto, np.float64)[still, :2]) ** 2).sum(1).mean())
                     / np.linalg.norm(b - a))
    return warped, m, residual


def mouth_box(points: np.ndarray, shape: Tuple[int, int]) -> Tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)`` (exclusive ends) of the mouth region of a face, inside ``shape``.

    The outer lip contour's box widened by :data:`MOUTH_MARGIN_SIDE`, :data:`MOUTH_MARGIN_UP`
    and :data:`MOUTH_MARGIN_DOWN` eye distances.
    """
    p = np.asarray(points, np.float64)[:, :2]
    lips = p[list(T.LIP_OUTER_UPPER + T.LIP_OUTER_LOWER)]
    a, b = eye_centres(p)
    d = float(np.linalg.norm(b - a))
    h, w = shape
    x0 = int(np.floor(lips[:, 0].min() - MOUTH_MARGIN_SIDE * d))
    x1 = int(np.ceil(lips[:, 0].max() + MOUTH_MARGIN_SIDE * d)) + 1
    y0 = int(np.floor(lips[:, 1].min() - MOUTH_MARGIN_UP * d))
    y1 = int(np.ceil(lips[:, 1].max() + MOUTH_MARGIN_DOWN * d)) + 1
    return max(0, x0), max(0, y0), min(w, x1), min(h, y1)


def _crop(img: np.ndarray, box) -> np.ndarray:
    if box is None:
        return img
    x0, y0, x1, y1 = box
    return img[y0:y1, x0:x1]


def psnr(a: np.ndarray, b: np.ndarray, box=None) -> float:
    """Peak signal-to-noise ratio in dB of two ``uint8`` pictures (over ``box`` if given)."""
    x = _crop(a, box).astype(np.float64)
    y = _crop(b, box).astype(np.float64)
    mse = float(((x - y) ** 2).mean())
    return float("inf") if mse == 0 else float(10.0 * np.log10(255.0 ** 2 / mse))


#: SSIM's constants (Wang et al. 2004): K1 = 0.01, K2 = 0.03 of the 255 range; Gaussian
#: window of sigma 1.5 (11 taps).
_C1, _C2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2


def ssim(a: np.ndarray, b: np.ndarray, box=None) -> float:
    """Mean structural similarity of two ``uint8`` pictures on their luma (over ``box``).

    Wang, Bovik, Sheikh & Simoncelli (2004) with the reference implementation's Gaussian
    window (sigma 1.5), on Rec. 601 luma, averaged over the region without its 5-pixel rim
    (where the window would reach outside).
    """
    def luma(img):
        img = _crop(img, box).astype(np.float64)
        return img @ np.array([0.299, 0.587, 0.114]) if img.ndim == 3 else img

    x, y = luma(a), luma(b)
    blur = lambda z: cv2.GaussianBlur(z, (11, 11), 1.5, borderType=cv2.BORDER_REFLECT)  # noqa: E731
    mx, my = blur(x), blur(y)
    sxx, syy, sxy = blur(x * x) - mx * mx, blur(y * y) - my * my, blur(x * y) - mx * my
    s = ((2 * mx * my + _C1) * (2 * sxy + _C2)) / ((mx * mx + my * my + _C1) * (sxx + syy + _C2))
    r = 5
    inner = s[r:-r, r:-r] if s.shape[0] > 2 * r and s.shape[1] > 2 * r else s
    return float(inner.mean())
