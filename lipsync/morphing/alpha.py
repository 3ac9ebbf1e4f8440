"""Transparency: straight and premultiplied alpha, and the blends every stage shares.

Images with transparency are RGBA ``uint8`` ``(H, W, 4)`` with *straight* alpha at the API
(colour as drawn, alpha beside it: what PNG files, ProRes 4444 and VP9 alpha hold). Any
mixing of pixels -- bilinear resampling, the morph's blend, scaling, compositing -- is done
on *premultiplied* values (colour times alpha): a transparent pixel then contributes
nothing, whatever hidden colour it carries, so edges do not pick up a dark (or any) fringe.
Straight alpha mixed directly would average an edge's colour with the black of the empty
pixels beside it.

Opaque images stay RGB ``(H, W, 3)`` and never pass through here.

Examples
--------
>>> import numpy as np
>>> red = np.array([[[255, 0, 0, 255]]], np.uint8)
>>> empty = np.array([[[0, 0, 0, 0]]], np.uint8)      # transparent, hidden colour black
>>> blend(red, empty, 0.5)[0, 0].tolist()               # half as opaque, still pure red
[255, 0, 0, 128]
"""

from __future__ import annotations

from typing import Optional, Sequence, Tuple, Union

import cv2
import numpy as np

__all__ = ["has_alpha", "is_opaque", "premultiply", "unpremultiply", "blend", "blend_premultiplied", "over",
           "flatten", "warp_rgba", "resize_rgba", "parse_colour"]


def has_alpha(image: np.ndarray) -> bool:
    """Whether ``image`` is RGBA ``(H, W, 4)``.

    Examples
    --------
    >>> has_alpha(np.zeros((2, 2, 4), np.uint8)), has_alpha(np.zeros((2, 2, 3), np.uint8))
    (True, False)
    """
    return image.ndim == 3 and image.shape[2] == 4


def is_opaque(image: np.ndarray) -> bool:
    """Whether every pixel is fully opaque (RGB, or RGBA with alpha 255 everywhere).

    Examples
    --------
    >>> img = np.full((2, 2, 4), 255, np.uint8)
    >>> is_opaque(img), is_opaque(img[..., :3])
    (True, True)
    """
    return not has_alpha(image) or bool(cv2.minMaxLoc(np.ascontiguousarray(image[..., 3]))[0] == 255)


def premultiply(rgba: np.ndarray, *, dtype=np.float32) -> np.ndarray:
    """Straight RGBA ``uint8`` -> premultiplied, colour ``c * a / 255`` (alpha unchanged).

    ``dtype=np.uint8`` rounds to bytes (what the frame kernels read); float32 keeps the
    colour of faint pixels exact (for resampling that is done once, like normalisation).

    Examples
    --------
    >>> premultiply(np.array([[[200, 100, 0, 51]]], np.uint8))[0, 0].tolist()
    [40.0, 20.0, 0.0, 51.0]
    """
    if dtype == np.uint8:
        # OpenCV's SIMD conversion: round(c * a / 255), exactly
        return cv2.cvtColor(np.ascontiguousarray(rgba), cv2.COLOR_RGBA2mRGBA)
    p = rgba.astype(np.float32)
    p[..., :3] *= p[..., 3:4]
    p[..., :3] /= np.float32(255.0)
    return p


def unpremultiply(p: np.ndarray, out: Optional[np.ndarray] = None) -> np.ndarray:
    """Premultiplied RGBA (float or uint8) -> straight RGBA ``uint8``, into ``out`` if given.

    Colour is ``c * 255 / a``, rounded and clipped; where alpha is zero the colour is zero.

    Examples
    --------
    >>> unpremultiply(np.array([[[40.0, 20.0, 0.0, 51.0]]], np.float32))[0, 0].tolist()
    [200, 100, 0, 51]
    """
    p = np.asarray(p, np.float32)
    a = p[..., 3:4]
    scale = np.divide(np.float32(255.0), a, out=np.zeros_like(a), where=a > 0)
    straight = np.empty(p.shape, np.float32)
    np.multiply(p[..., :3], scale, out=straight[..., :3])
    straight[..., 3:] = a
    if out is None:
        out = np.empty(p.shape, np.uint8)
    np.clip(np.rint(straight, out=straight), 0, 255, out=straight)
    out[...] = straight
    return out


def blend(a: np.ndarray, b: np.ndarray, t: float, out: Optional[np.ndarray] = None) -> np.ndarray:
    """``(1 - t) a + t b`` of two straight RGBA images, mixed premultiplied.

    Examples
    --------
    >>> a = np.array([[[0, 0, 255, 255]]], np.uint8); b = np.array([[[255, 0, 0, 255]]], np.uint8)
    >>> blend(a, b, 0.25)[0, 0].tolist()
    [64, 0, 191, 255]
    """
    p = premultiply(a)
    p *= np.float32(1.0 - t)
    p += premultiply(b) * np.float32(t)
    return unpremultiply(p, out)


def blend_premultiplied(pa: np.ndarray, pb: np.ndarray, t: float, out: np.ndarray) -> np.ndarray:
    """``(1 - t) pa + t pb`` of two premultiplied RGBA ``uint8`` images, as straight RGBA
    into ``out``: two SIMD passes of OpenCV (the renderer's baselines use it per frame; a
    pixel of alpha a is exact to about 255 / a levels of its straight colour, nothing once
    composited).

    Examples
    --------
    >>> pa = premultiply(np.array([[[255, 0, 0, 255]]], np.uint8), dtype=np.uint8)
    >>> pb = np.zeros((1, 1, 4), np.uint8)
    >>> blend_premultiplied(pa, pb, 0.5, np.empty((1, 1, 4), np.uint8))[0, 0].tolist()
    [255, 0, 0, 128]
    """
    mixed = cv2.addWeighted(pa, 1.0 - t, pb, t, 0.0)
    if out.flags.c_contiguous:
        cv2.cvtColor(mixed, cv2.COLOR_mRGBA2RGBA, dst=out)
    else:  # a view into a larger frame: OpenCV would write a new array
        np.copyto(out, cv2.cvtColor(mixed, cv2.COLOR_mRGBA2RGBA))
    return out


def over(top: np.ndarray, bottom: np.ndarray, out: Optional[np.ndarray] = None) -> np.ndarray:
    """Porter-Duff "over": straight RGBA ``top`` composited onto ``bottom`` (same height and width).

    ``bottom`` RGB gives RGB (an opaque result); ``bottom`` RGBA gives straight RGBA.

    Examples
    --------
    >>> top = np.array([[[255, 0, 0, 128]]], np.uint8)
    >>> over(top, np.array([[[0, 0, 255]]], np.uint8))[0, 0].tolist()
    [128, 0, 127]
    >>> over(top, np.zeros((1, 1, 4), np.uint8))[0, 0].tolist()   # onto nothing: itself
    [255, 0, 0, 128]
    """
    pt = premultiply(top)
    rest = np.float32(1.0) - pt[..., 3:4] * np.float32(1.0 / 255.0)
    if not has_alpha(bottom):
        res = pt[..., :3]
        res += bottom.astype(np.float32) * rest
        np.clip(np.rint(res, out=res), 0, 255, out=res)
        if out is None:
            return res.astype(np.uint8)
        out[...] = res
        return out
    pb = premultiply(bottom)
    pb *= rest
    pb += pt
    return unpremultiply(pb, out)


def flatten(rgba: np.ndarray, background: Union[np.ndarray, Sequence[int]], out: Optional[np.ndarray] = None
            ) -> np.ndarray:
    """An opaque RGB image: ``rgba`` over a colour ``(r, g, b)`` or an RGB(A) image of its size.

    An RGBA background image is itself flattened onto white first: an opaque output needs
    a colour everywhere.

    Examples
    --------
    >>> flatten(np.array([[[255, 0, 0, 64]]], np.uint8), (255, 255, 255))[0, 0].tolist()
    [255, 191, 191]
    """
    if not has_alpha(rgba):
        return rgba if out is None else np.copyto(out, rgba) or out
    bg = np.asarray(background, np.uint8)
    if bg.ndim == 1:
        bg = np.broadcast_to(bg[:3], rgba.shape[:2] + (3,))
    elif has_alpha(bg):
        bg = over(bg, np.full(bg.shape[:2] + (3,), 255, np.uint8))
    return over(rgba, bg, out)


def warp_rgba(image: np.ndarray, inverse_map: np.ndarray, *, interpolation: int = cv2.INTER_LINEAR
              ) -> np.ndarray:
    """:func:`cv2.remap` of a straight RGBA image, resampled premultiplied (edges repeated).

    Examples
    --------
    >>> from lipsync.morphing.warp import identity_grid
    >>> img = np.random.default_rng(0).integers(0, 256, (5, 6, 4), dtype=np.uint8); img[..., 3] = 255
    >>> bool((warp_rgba(img, identity_grid(img.shape[:2])) == img).all())
    True
    """
    p = premultiply(image)
    m = np.ascontiguousarray(inverse_map, np.float32)
    warped = cv2.remap(p, m, None, interpolation, borderMode=cv2.BORDER_REPLICATE)
    return unpremultiply(warped)


def resize_rgba(image: np.ndarray, size: Tuple[int, int], *, interpolation: int = cv2.INTER_AREA) -> np.ndarray:
    """:func:`cv2.resize` of a straight RGBA image to ``size`` = (width, height), premultiplied.

    Examples
    --------
    >>> img = np.zeros((4, 4, 4), np.uint8); img[:, :2] = (255, 0, 0, 255)
    >>> resize_rgba(img, (2, 2))[0].tolist()     # no dark edge where red meets nothing
    [[255, 0, 0, 255], [0, 0, 0, 0]]
    """
    return unpremultiply(cv2.resize(premultiply(image), tuple(int(v) for v in size), interpolation=interpolation))


#: Named colours ``--background`` accepts, besides ``#rrggbb`` and ``r,g,b``.
COLOURS = {"white": (255, 255, 255), "black": (0, 0, 0), "grey": (128, 128, 128), "gray": (128, 128, 128),
           "green": (0, 255, 0), "blue": (0, 0, 255), "red": (255, 0, 0), "magenta": (255, 0, 255)}


def parse_colour(text: str) -> Optional[Tuple[int, int, int]]:
    """``#rrggbb``, ``#rgb``, ``r,g,b`` (0-255) or a name in :data:`COLOURS`; None if it is none of these.

    Examples
    --------
    >>> parse_colour("#ff8000"), parse_colour("0,128,255"), parse_colour("white"), parse_colour("x.png")
    ((255, 128, 0), (0, 128, 255), (255, 255, 255), None)
    """
    s = text.strip().lower()
    if s in COLOURS:
        return COLOURS[s]
    if s.startswith("#") and len(s) in (4, 7):
        digits = s[1:] if len(s) == 7 else "".join(ch * 2 for ch in s[1:])
        try:
            return tuple(int(digits[i:i + 2], 16) for i in (0, 2, 4))  # type: ignore[return-value]
        except ValueError:
            return None
    parts = s.split(",")
    if len(parts) == 3:
        try:
            vals = tuple(int(p) for p in parts)
        except ValueError:
            return None
        if all(0 <= v <= 255 for v in vals):
            return vals  # type: ignore[return-value]
    return None
