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

from typing import Dict, Mapping, Optional, Tuple

import cv2
import numpy as np

from ..face.video import read_video

#: Finalists' decoded frames are kept in memory up to this many bytes (54 frames of
#: 1280x720 take 150 MB); beyond it (4K video) they are decoded once more for the final crop.
RAW_BUDGET_BYTES = 256 * 2 ** 20
#: Below this scale a resample would skip source pixels (aliasing: jagged hair, moiré on
#: shirts); the frame is first shrunk with area averaging, then warped.
AREA_BELOW = 0.75
#: The cut's resample, where the map is not a whole-pixel translation. Any interpolation
#: at a fractional offset is a low-pass filter: on real GRID s1 mouths (60x40 boxes, 15
#: frames of three held-out sentences) the Laplacian's variance kept at a half-pixel shift
#: is bilinear 0.52, bicubic 0.85, Lanczos4 0.92 (a quarter pixel: 0.62 / 0.93 / 0.97; a
#: one-degree turn: 0.66 / 0.93 / 0.97); Lanczos4 overshoots no more than bicubic (pixels
#: beyond their source 3x3 neighbourhood's range by over 3 levels: 0.04 % at half a pixel,
#: 0.5 % at a 0.96 scale for both, bilinear 0.0 / 0.3 %): no halo for a seam to show.
INTERPOLATION = cv2.INTER_LANCZOS4


def _copy(image: np.ndarray, offset: Tuple[int, int], size: Tuple[int, int]) -> np.ndarray:
    """The ``size`` (W, H) window of ``image`` whose pixel (0, 0) is the image's pixel
    ``offset`` (x, y); rows and columns outside the image repeat its edge (as the warp's
    ``BORDER_REPLICATE`` does)."""
    h, w = image.shape[:2]
    ox, oy = offset
    if 0 <= oy and oy + size[1] <= h and 0 <= ox and ox + size[0] <= w:
        return np.array(image[oy:oy + size[1], ox:ox + size[0]])
    ys = np.clip(np.arange(size[1]) + oy, 0, h - 1)
    xs = np.clip(np.arange(size[0]) + ox, 0, w - 1)
    return image[ys[:, None], xs[None, :]]


def _warp(image: np.ndarray, m: np.ndarray, size: Tuple[int, int], interpolation: int) -> np.ndarray:
    """The resampling kernel: ``image`` by the 2x3 ``m`` (source -> output pixels) into
    ``size`` with ``interpolation``, area-averaged first where ``m`` shrinks below
    :data:`AREA_BELOW`."""
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
    return cv2.warpAffine(np.ascontiguousarray(image), m, tuple(size), flags=interpolation,
                          borderMode=cv2.BORDER_REPLICATE)


def copy_offset(matrix: np.ndarray, size: Tuple[int, int]) -> Optional[Tuple[int, int]]:
    """``(x, y)``, the source pixel that output pixel (0, 0) copies, if the 2x3 ``matrix``
    (source -> output pixels) is a translation to within
    :data:`lipsync.composite.samples.SNAP_PX` over the ``size`` (W, H) output; else None
    (it scales or turns: a resample).

    Examples
    --------
    >>> copy_offset(np.array([[1.0, 0, -10.4], [0, 1.0, 3.6]]), (82, 64))
    (10, -4)
    >>> copy_offset(np.array([[0.96, 0, -10.4], [0, 0.96, 3.6]]), (82, 64)) is None
    True
    """
    from ..composite.plate import pose_inverse
    from ..composite.samples import whole_shift

    # judged on the map back from the output window: the source is read only there
    return whole_shift(pose_inverse(np.asarray(matrix, np.float64)), (size[1], size[0]))


def warp_frame(image: np.ndarray, matrix: np.ndarray, size: Tuple[int, int],
               interpolation: int = INTERPOLATION) -> np.ndarray:
    """``image`` cut by the 2x3 ``matrix`` (source pixels → output pixels) into ``size``
    (W, H): a whole-pixel copy where the map is a translation within a pixel
    (:func:`copy_offset`: no resample at all), else one resample with ``interpolation``
    (:data:`INTERPOLATION`; the area shrink first below :data:`AREA_BELOW`).

    Examples
    --------
    >>> img = np.arange(8 * 8 * 3, dtype=np.uint8).reshape(8, 8, 3)
    >>> out = warp_frame(img, np.array([[1.0, 0, -2.3], [0, 1.0, -1.2]]), (4, 4))  # pixels (2..5, 1..4)
    >>> bool((out == img[1:5, 2:6]).all())
    True
    """
    m = np.asarray(matrix, np.float64)
    offset = copy_offset(m, size)
    if offset is not None:
        return _copy(image, offset, size)
    return _warp(image, m, size, interpolation)


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
