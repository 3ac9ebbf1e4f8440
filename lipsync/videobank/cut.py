"""Step 6: the finalist frames cut out of the videos, stabilised, at the bank's size.

The videos are decoded a second time and only the frames asked for are kept, then warped
into the bank's picture (:meth:`~lipsync.videobank.stabilise.Framing.matrix`): holding
every frame of a 30 s video in memory would take 230 MB at 360x288 and 2 GB at 1280x720,
while decoding again costs a fraction of the tracking pass. The finalists' frames are kept
as decoded while they fit :data:`RAW_BUDGET_BYTES`, so that the final crop, fitted to the
chosen frames alone, does not need a third pass.

Examples
--------
>>> import numpy as np
>>> img = np.arange(16 * 16 * 3, dtype=np.uint8).reshape(16, 16, 3)
>>> same = warp_frame(img, np.array([[1.0, 0, 0], [0, 1.0, 0]]), (16, 16))
>>> bool((same == img).all())
True
"""

from __future__ import annotations

from typing import Dict, Mapping, Tuple

import cv2
import numpy as np

from ..face.video import read_video

#: Finalists' decoded frames are kept in memory up to this many bytes (54 frames of
#: 1280x720 take 150 MB); beyond it (4K video) they are decoded once more for the final crop.
RAW_BUDGET_BYTES = 256 * 2 ** 20
#: Below this scale a bilinear warp would skip source pixels (aliasing: jagged hair, moiré
#: on shirts); the frame is first shrunk with area averaging, then warped.
AREA_BELOW = 0.75


def warp_frame(image: np.ndarray, matrix: np.ndarray, size: Tuple[int, int]) -> np.ndarray:
    """``image`` warped by the 2x3 ``matrix`` (source pixels → output pixels) into ``size`` (W, H)."""
    m = np.asarray(matrix, np.float64)
    scale = float(np.sqrt(abs(np.linalg.det(m[:, :2]))))
    if scale < AREA_BELOW:
        h, w = image.shape[:2]
        sw, sh = max(1, int(round(w * scale))), max(1, int(round(h * scale)))
        small = cv2.resize(image, (sw, sh), interpolation=cv2.INTER_AREA)
        # small's pixel x' covers source (x' + 0.5) w / sw - 0.5
        fx, fy = w / sw, h / sh
        pre = np.array([[fx, 0, 0.5 * fx - 0.5], [0, fy, 0.5 * fy - 0.5], [0, 0, 1.0]])
        m = m @ pre
        image = small
    return cv2.warpAffine(np.ascontiguousarray(image), m, tuple(size), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REPLICATE)


def grab_frames(path, frames, info=None) -> Dict[int, np.ndarray]:
    """Frame index → the decoded frame, for the indices in ``frames`` (read-only arrays;
    turned upright as ``info``, the video's :class:`~lipsync.face.video.VideoInfo`, says).

    Raises
    ------
    lipsync.errors.InputError
        The video ends before a wanted frame (it changed since it was tracked).
    """
    from ..errors import InputError

    frames = set(frames)
    out: Dict[int, np.ndarray] = {}
    last = max(frames) if frames else -1
    for i, frame in enumerate(read_video(path, info=info)):
        if i in frames:
            out[i] = frame
        if i >= last:
            break
    if len(out) < len(frames):
        raise InputError(f"ended before frame {last} on the second reading (did it change meanwhile?)", path=path)
    return out


def cut_frames(path, wanted: Mapping[int, np.ndarray], size: Tuple[int, int]) -> Dict[int, np.ndarray]:
    """Frame index → the frame warped by its matrix into ``size``, for the frames in ``wanted``."""
    return {i: warp_frame(f, wanted[i], size) for i, f in grab_frames(path, wanted).items()}
