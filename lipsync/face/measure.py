"""Mouth and eye measures from face-mesh points, in units of the distance between the eyes.

Dividing by the eye distance makes every measure independent of how large the face is in
the picture (and of the camera's distance), so measures of rendered and real frames, of
different clips and of different people compare directly.

All functions take points shaped ``(..., 468, 2)`` or ``(..., 468, 3)`` (one face or a
whole track) and return one number per face.

Examples
--------
>>> import numpy as np
>>> from lipsync.face import topology as T
>>> p = np.zeros((468, 2))
>>> p[list(T.EYE_UPPER_L + T.EYE_LOWER_L)] = [100.0, 100.0]
>>> p[list(T.EYE_UPPER_R + T.EYE_LOWER_R)] = [160.0, 100.0]
>>> for a, b in T.INNER_LIP_PAIRS:
...     p[a], p[b] = [130.0, 170.0], [130.0, 182.0]
>>> float(lip_opening(p))
0.2
"""

from __future__ import annotations

import numpy as np

from . import topology as T

_LEFT_EYE = list(T.EYE_UPPER_L + T.EYE_LOWER_L)
_RIGHT_EYE = list(T.EYE_UPPER_R + T.EYE_LOWER_R)


def eye_centres(points: np.ndarray):
    """Centres of the eye on the image left and the other eye (means of their lid contours)."""
    p = np.asarray(points, np.float64)[..., :2]
    return p[..., _LEFT_EYE, :].mean(axis=-2), p[..., _RIGHT_EYE, :].mean(axis=-2)


def eye_distance(points: np.ndarray) -> np.ndarray:
    """Distance between the eye centres, in pixels."""
    a, b = eye_centres(points)
    return np.linalg.norm(b - a, axis=-1)


def _pair_distance(points: np.ndarray, pairs) -> np.ndarray:
    p = np.asarray(points, np.float64)[..., :2]
    i, j = np.array(pairs).T
    return np.linalg.norm(p[..., i, :] - p[..., j, :], axis=-1).mean(axis=-1)


def lip_opening(points: np.ndarray) -> np.ndarray:
    """Gap between the inner lip edges (mean of five facing pairs) over the eye distance."""
    return _pair_distance(points, T.INNER_LIP_PAIRS) / eye_distance(points)


def mouth_width(points: np.ndarray) -> np.ndarray:
    """Distance between the outer mouth corners over the eye distance."""
    return _pair_distance(points, [(T.MOUTH_CORNERS[0][0], T.MOUTH_CORNERS[1][0])]) / eye_distance(points)


def lip_protrusion(points: np.ndarray) -> np.ndarray:
    """How far the lips' middle stands out towards the camera beyond the mouth corners,
    over the eye distance (a proxy: the mesh's z is relative depth, inferred from one view).

    Rounded lips (OO, W) push the middle forward while the corners draw in.
    """
    p = np.asarray(points, np.float64)
    if p.shape[-1] < 3:
        raise ValueError("lip_protrusion needs the mesh's z (points of shape (..., 468, 3))")
    corners = p[..., [T.MOUTH_CORNERS[0][0], T.MOUTH_CORNERS[1][0]], 2].mean(axis=-1)
    middle = p[..., [T.LIP_MIDLINE[0], T.LIP_MIDLINE[1]], 2].mean(axis=-1)
    return (corners - middle) / eye_distance(p)


def eye_opening(points: np.ndarray) -> np.ndarray:
    """Mean lid gap of both eyes over the eye distance (near 0 in a blink)."""
    return (_pair_distance(points, T.EYE_LID_PAIRS_L) + _pair_distance(points, T.EYE_LID_PAIRS_R)) / (
        2 * eye_distance(points))


def mouth_shape(points: np.ndarray) -> np.ndarray:
    """A mouth shape descriptor: the 40 lip points in the eyes' frame, scaled by the eye
    distance, as ``(..., 80)``. Two faces with the same mouth shape have nearby descriptors
    whatever their position, size or tilt in the picture."""
    p = np.asarray(points, np.float64)[..., :2]
    a, b = eye_centres(p)
    u = b - a
    d = np.linalg.norm(u, axis=-1, keepdims=True)
    u = u / d
    v = np.stack([-u[..., 1], u[..., 0]], axis=-1)
    lips = list(dict.fromkeys(T.LIP_OUTER_UPPER + T.LIP_OUTER_LOWER + T.LIP_INNER_UPPER + T.LIP_INNER_LOWER))
    rel = p[..., lips, :] - ((a + b) / 2)[..., None, :]
    x = (rel * u[..., None, :]).sum(-1) / d
    y = (rel * v[..., None, :]).sum(-1) / d
    return np.concatenate([x, y], axis=-1)
