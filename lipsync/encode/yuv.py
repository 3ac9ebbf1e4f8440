r"""RGB frames to planar YUV 4:2:0 (BT.709, limited range), the pixel format H.264 carries.

:class:`lipsync.encode.mp4.Mp4Writer` converts every frame here and pipes ``yuv420p`` to
ffmpeg instead of ``rgb24``: half the bytes through the pipe, and no swscale pass inside
ffmpeg. swscale's exact path for this conversion (``accurate_rnd+full_chroma_int``, the
only one that rounds correctly) cost 2.4 CPU-ms per 1280x720 frame (1.6 CPU-s of a 26.7 s
clip); this fused pass runs in the compiled extension (lipsync.morphing._flowkernel; numba's copy
of it when that is not built) on the caller's thread, outside the GIL. On the benchmark
clips 99 % of its output bytes equal swscale's; the rest differ by 1-5 levels in chroma at
sharp colour edges, where swscale filters over more than the 2x2 block.

The arithmetic is BT.709's (Rec. ITU-R BT.709-6, 3.2-3.5) on 8-bit codes, with the RGB
values taken as they are (no linearisation, as every video pipeline does): luma
``Y = 16 + 219 (0.2126 R + 0.7152 G + 0.0722 B) / 255`` and colour differences scaled to
224 levels around 128. Chroma is the mean of each 2x2 block (centred siting, as
swscale's default gives), computed from the block's RGB sums so a flat patch converts
exactly. Fixed point, round to nearest; grey stays exactly neutral (128, 128).

Examples
--------
>>> import numpy as np
>>> rgb = np.zeros((2, 4, 3), np.uint8); rgb[:, 2:] = 255
>>> yuv = rgb_to_yuv420p(rgb)
>>> yuv[:8].tolist(), yuv[8:].tolist()          # Y plane, then U (2 values), then V (2)
([16, 16, 235, 235, 16, 16, 235, 235], [128, 128, 128, 128])
"""

from __future__ import annotations

from typing import Optional

import numpy as np

try:  # the compiled conversion; numba's copy (lipsync.morphing._numba_kernels) when it is not built
    from ..morphing import _flowkernel as _compiled
except ImportError:  # pragma: no cover - depends on the install
    _compiled = None

_KR, _KB = 0.2126, 0.0722
_SHIFT = 16
_ONE = 1 << _SHIFT
# Luma weights in fixed point; their sum is 219/255 of one, so white lands on 235 exactly.
_YR = round(219 / 255 * _KR * _ONE)
_YB = round(219 / 255 * _KB * _ONE)
_YG = round(219 / 255 * _ONE) - _YR - _YB
# Colour-difference weights; each row sums to zero so that any grey gives exactly 128.
_UR = round(-224 / 255 * _KR / (2 * (1 - _KB)) * _ONE)
_UB = round(224 / 255 * 0.5 * _ONE)
_UG = -_UR - _UB
_VR = _UB
_VB = round(-224 / 255 * _KB / (2 * (1 - _KR)) * _ONE)
_VG = -_VR - _VB


# Luma rounds from 16 + one half; chroma works on sums of four pixels: two more bits of
# scale, and offset and rounding to match.
_COEFFICIENTS = (_YR, _YG, _YB, _UR, _UG, _UB, _VR, _VG, _VB)
_YHALF = (16 << _SHIFT) + (1 << (_SHIFT - 1))
_CHALF = (128 << (_SHIFT + 2)) + (1 << (_SHIFT + 1))
# The same, as the int32 values numba's copy of the kernel takes.
_NUMBA_CONSTANTS = (tuple(np.int32(c) for c in _COEFFICIENTS), np.int32(_YHALF), np.int32(_CHALF), np.int32(_SHIFT))


def yuv420p_size(width: int, height: int) -> int:
    """Bytes of one ``yuv420p`` frame of even ``width`` x ``height``: the Y plane, then U, then V.

    Examples
    --------
    >>> yuv420p_size(1280, 720)
    1382400
    """
    return width * height + 2 * (width // 2) * (height // 2)


def rgb_to_yuv420p(rgb: np.ndarray, out: Optional[np.ndarray] = None) -> np.ndarray:
    """Convert one RGB frame to planar YUV 4:2:0, BT.709, limited (tv) range.

    Parameters
    ----------
    rgb : ndarray
        ``uint8`` array of shape ``(height, width, 3)``; width and height must be even.
    out : ndarray, optional
        ``uint8`` array of :func:`yuv420p_size` elements to fill (one per frame in flight
        lets callers reuse memory).

    Returns
    -------
    ndarray
        1-D ``uint8``: the Y plane (``height`` rows of ``width``), then U and V (each
        ``height/2`` rows of ``width/2``) -- ffmpeg's ``yuv420p`` layout.

    Raises
    ------
    ValueError
        Wrong dtype or shape, odd dimensions, or ``out`` of the wrong size.
    """
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected a uint8 (height, width, 3) array, got {rgb.dtype} {rgb.shape}")
    h, w = rgb.shape[:2]
    if h % 2 or w % 2:
        raise ValueError(f"yuv420p needs even dimensions, got {w}x{h}")
    n = yuv420p_size(w, h)
    if out is None:
        out = np.empty(n, np.uint8)
    elif out.dtype != np.uint8 or out.shape != (n,):
        raise ValueError(f"out must be uint8 of shape ({n},), got {out.dtype} {out.shape}")
    rgb = np.ascontiguousarray(rgb)
    if _compiled is not None:
        _compiled.rgb_to_yuv420p(rgb, out, w, h, _COEFFICIENTS, _YHALF, _CHALF, _SHIFT)
    else:  # pragma: no cover - depends on the install
        from ..morphing._numba_kernels import rgb_to_yuv420p as convert

        convert(rgb, out, *_NUMBA_CONSTANTS)
    return out
