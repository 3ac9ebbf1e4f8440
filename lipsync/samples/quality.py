"""How sharp each sample's lips are, and how much softer than usual for its opening.

Footage of speech holds motion blur: a frame caught while the lips move fast is soft,
its neighbours a frame later are crisp. Among samples that fit a rendered frame equally
well, the crisp one is the better sample, so the selection charges a soft one
(:data:`lipsync.selection.select.WEIGHTS` ``"blur"``). Sharpness is the variance of the
Laplacian of the luma in the lips' box of the crop as stored (:func:`sharpness`, the
measure the bank's pictures are chosen by too). Parted lips show
teeth and the dark gap, which add edges (GRID s1: r 0.59 between a crop's sharpness and its
opening), so a sample is judged against the samples of its opening: :func:`softness` is
how far its log sharpness falls below a straight-line fit of log sharpness on opening.

Examples
--------
>>> import numpy as np
>>> from types import SimpleNamespace
>>> rng = np.random.default_rng(0)
>>> crisp = rng.integers(0, 255, (2, 16, 16, 3)).astype(np.uint8)
>>> soft = np.full((1, 16, 16, 3), 128, np.uint8)              # no edges at all
>>> lips = np.tile([[4.0, 4.0], [12.0, 12.0]], (3, 22, 1))       # the box is the crop's middle
>>> s = SimpleNamespace(crops=np.concatenate([crisp, soft]), lips=lips, opening=np.zeros(3),
...                     affine=np.tile([[1.0, 0, 0], [0, 1.0, 0]], (3, 1, 1)))
>>> b = softness(s)
>>> bool(b[2] > 3.0), bool(np.all(b[:2] == 0.0))
(True, True)
"""

from __future__ import annotations

from typing import Tuple

import cv2
import numpy as np

#: Pixels added around the lips' box in the crop: the lips' edges themselves, where motion
#: blur shows, without the cheeks' flat skin diluting the variance.
MARGIN_PX = 2
#: Added to the variance before its log: a flat crop (variance 0) stays finite, and
#: differences among nearly flat crops (a dark or tiny mouth) do not read as blur.
FLOOR = 1.0


def sharpness(image: np.ndarray, box: Tuple[int, int, int, int]) -> float:
    """Variance of the Laplacian of the luma in ``box`` (``x0, y0, x1, y1``): focus and motion
    blur both lower it.

    Examples
    --------
    >>> img = np.zeros((8, 8, 3), np.uint8); img[:, 4:] = 200
    >>> sharpness(img, (0, 0, 8, 8)) > 0, sharpness(img, (0, 0, 4, 8)), sharpness(img, (2, 2, 2, 2))
    (True, 0.0, 0.0)
    """
    x0, y0, x1, y1 = box
    part = np.ascontiguousarray(image[y0:y1, x0:x1])
    if not part.size:  # an empty box (a face at the frame's edge): OpenCV refuses empty input
        return 0.0
    return float(cv2.Laplacian(cv2.cvtColor(part, cv2.COLOR_RGB2GRAY), cv2.CV_64F).var())


def lip_sharpness(samples) -> np.ndarray:
    """``(N,)``: the variance of the Laplacian of each crop's luma in its lips' box.

    ``samples`` has ``crops`` ``(N, h, w, 3)``, ``lips`` ``(N, P, 2)`` in bank pixels and
    ``affine`` ``(N, 2, 3)`` (crop -> bank pixels), as :class:`lipsync.samples.Samples`.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> crops = np.zeros((1, 8, 8, 3), np.uint8); crops[0, :, 4:] = 200    # one vertical edge
    >>> s = SimpleNamespace(crops=crops, lips=np.array([[[2.0, 2.0], [5.0, 5.0]]]),
    ...                     affine=np.array([[[1.0, 0, 0], [0, 1.0, 0]]]))
    >>> float(lip_sharpness(s)[0]) > 0, float(lip_sharpness(SimpleNamespace(
    ...     crops=np.zeros_like(crops), lips=s.lips, affine=s.affine))[0])
    (True, 0.0)
    """
    crops = samples.crops
    n, h, w = crops.shape[:3]
    out = np.zeros(n)
    aff = np.asarray(samples.affine, np.float64)
    lips = np.asarray(samples.lips, np.float64)
    for k in range(n):
        inv = cv2.invertAffineTransform(aff[k])
        p = lips[k] @ inv[:, :2].T + inv[:, 2]
        x0, y0 = np.floor(p.min(axis=0)).astype(int) - MARGIN_PX
        x1, y1 = np.ceil(p.max(axis=0)).astype(int) + MARGIN_PX + 1
        x0, y0, x1, y1 = max(0, x0), max(0, y0), min(w, x1), min(h, y1)
        if y1 - y0 >= 3 and x1 - x0 >= 3:
            out[k] = sharpness(crops[k], (x0, y0, x1, y1))
    return out


def softness(samples, sharpness=None) -> np.ndarray:
    """``(N,)``, at least 0: how far each sample's log lip sharpness (:func:`lip_sharpness`,
    or ``sharpness`` given) falls below what samples of its opening have (a least-squares
    line of log sharpness on opening over all the samples). 0.2 is a sample about a fifth
    softer than its opening's usual; 0 for every sample as sharp as usual or sharper.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> s = SimpleNamespace(opening=np.array([0.0, 0.0, 0.1, 0.1]))
    >>> np.round(softness(s, np.exp([5.0, 5.0, 6.0, 5.0]) - FLOOR), 3).tolist()   # the last is soft
    [0.0, 0.0, 0.0, 0.5]
    >>> np.round(softness(s, np.exp([5.0, 5.0, 6.0, 6.0]) - FLOOR), 3).tolist()   # all as usual
    [0.0, 0.0, 0.0, 0.0]
    """
    sharp = lip_sharpness(samples) if sharpness is None else np.asarray(sharpness, np.float64)
    opening = np.asarray(samples.opening, np.float64)
    if len(sharp) < 2:
        return np.zeros(len(sharp))
    y = np.log(sharp + FLOOR)
    x = np.c_[np.ones(len(y)), opening]
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    return np.maximum(0.0, x @ coef - y)
