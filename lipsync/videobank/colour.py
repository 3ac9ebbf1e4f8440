"""Step 7: frames from different moments or clips made to look alike — exposure and white balance.

A camera's automatic exposure and white balance drift between takes (and within one, as
the speaker moves); morphing between two pictures of unequal brightness or tint would
pulse the whole face. Each chosen picture is corrected by one gain per colour channel so
that the **still part of the face** (forehead, temples, cheeks and nose down to the upper
lip; eyes and brows cut out, since blinks and raised brows change them) has the same mean
colour in every picture: the median of the pictures' means.

A gain per channel models both exposure (all three alike) and white balance (the channels
apart), and is exact for a camera's power-law tone curve: ``(g L)^(1/2.2) = g^(1/2.2)
L^(1/2.2)``, so a gain in linear light is a gain in the encoded values too.

Examples
--------
>>> import numpy as np
>>> a = np.full((4, 4, 3), 100, np.uint8); b = np.full((4, 4, 3), 120, np.uint8)
>>> mask = np.ones((4, 4), bool)
>>> out, gains = match_colour({"X": a, "A": b}, {"X": mask, "A": mask})
>>> out["X"][0, 0].tolist(), out["A"][0, 0].tolist()
([110, 110, 110], [110, 110, 110])
"""

from __future__ import annotations

import warnings
from typing import Dict, Mapping, Tuple

import cv2
import numpy as np

from ..face import topology as T

#: The still skin: the face's outline above the ears, the upper cheeks and the nose's base
#: (its convex hull reaches from the hairline down to just above the upper lip).
STILL_SKIN = T.FACE_UPPER_L + T.FACE_UPPER_R + (123, 50, 36, 352, 280, 266) + T.NOSE_BASE_L + T.NOSE_BASE_R
#: Cut out of it: each eye with its brow (blinks, raised brows).
EYE_REGIONS = (T.EYE_UPPER_L + T.EYE_LOWER_L + T.BROW_L, T.EYE_UPPER_R + T.EYE_LOWER_R + T.BROW_R)
#: The eye regions are grown by this share of the eye distance (lashes, lid shadows).
EYE_MARGIN = 0.12
#: Gains outside this range are not a drift of exposure but a different scene (a light
#: switched on, a face in shadow): corrected, with a warning.
PLAUSIBLE_GAIN = (0.7, 1.4)


def still_skin_mask(points: np.ndarray, shape: Tuple[int, int]) -> np.ndarray:
    """Boolean ``(H, W)`` mask of the still skin of a face with mesh ``points``."""
    from ..face.measure import eye_distance

    p = np.asarray(points, np.float64)[:, :2]
    mask = np.zeros(shape, np.uint8)
    cv2.fillConvexPoly(mask, np.round(cv2.convexHull(p[list(STILL_SKIN)].astype(np.float32))).astype(np.int32), 1)
    grow = EYE_MARGIN * float(eye_distance(p))
    for region in EYE_REGIONS:
        hull = cv2.convexHull(p[list(region)].astype(np.float32))[:, 0]
        centre = hull.mean(axis=0)
        d = hull - centre
        n = np.linalg.norm(d, axis=1, keepdims=True)
        grown = centre + d * (1 + grow / np.maximum(n, 1e-9))
        cv2.fillConvexPoly(mask, np.round(grown).astype(np.int32), 0)
    return mask.astype(bool)


def match_colour(images: Mapping[str, np.ndarray], masks: Mapping[str, np.ndarray], *, where: str = "video"
                 ) -> Tuple[Dict[str, np.ndarray], Dict[str, Tuple[float, float, float]]]:
    """Per-channel gains bringing every image's still skin to the median colour.

    Parameters
    ----------
    images : mapping
        Name → RGB ``uint8`` image.
    masks : mapping
        Name → boolean mask of its still skin (:func:`still_skin_mask`).
    where : str
        For the warning about implausible gains.

    Returns
    -------
    images : dict
        The corrected images.
    gains : dict
        Name → the three gains applied.
    """
    means = {}
    for k, img in images.items():
        m = masks[k]
        means[k] = img[m].reshape(-1, 3).astype(np.float64).mean(axis=0) if m.any() else None
    known = [m for m in means.values() if m is not None]
    if not known:
        return dict(images), {k: (1.0, 1.0, 1.0) for k in images}
    target = np.median(np.stack(known), axis=0)
    out, gains = {}, {}
    odd = []
    for k, img in images.items():
        g = np.ones(3) if means[k] is None else target / np.maximum(means[k], 1.0)
        if np.any(g < PLAUSIBLE_GAIN[0]) or np.any(g > PLAUSIBLE_GAIN[1]):
            odd.append(k)
        lut = np.clip(np.round(np.arange(256)[:, None] * g[None, :]), 0, 255).astype(np.uint8)
        out[k] = np.stack([lut[img[..., c], c] for c in range(3)], axis=-1)
        gains[k] = tuple(round(float(x), 4) for x in g)
    if odd:
        warnings.warn(f"{where}: the light differs a lot between the frames chosen for {', '.join(odd)} "
                      f"(colour gains beyond {PLAUSIBLE_GAIN[0]}-{PLAUSIBLE_GAIN[1]}); corrected, but record "
                      f"in steady light for a bank that morphs cleanly", UserWarning, stacklevel=2)
    return out, gains
