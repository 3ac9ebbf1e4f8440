"""Where rendered mouth frames go: onto a character's body, onto a background, or as they are.

The stage between the renderer and the encoder::

    Renderer frame (the bank's size, RGB or RGBA) --Compositor--> output frame --> encoder

* A *composite* (bank.yaml ``composite: {image: body.png, at: [x, y], scale: s}``, or
  ``lipsync render --over BODY --at X,Y --scale S``) puts the mouth, scaled by ``s``, with
  its centre at ``(x, y)`` of the body image (pixels, x right, y down, rounded to whole
  pixels): the output is the whole character talking, the body's size.
* A *background* (``--background COLOR|IMAGE``) flattens transparency: an opaque output.
  An output format without alpha (mp4) always gets an opaque picture: without a
  background, transparency is flattened onto white (:data:`DEFAULT_BACKGROUND`).
* Otherwise frames pass through untouched (an opaque bank, or a transparent one written to
  a format with alpha).

Per frame only the mouth's rectangle is touched: every output buffer starts as the
precomputed canvas (the body, already flattened when the output is opaque,
:attr:`Compositor.initial`), and :meth:`Compositor.apply` rewrites the rectangle with the
mouth over the canvas's pixels there (premultiplied "over", :mod:`lipsync.morphing.alpha`).

Examples
--------
>>> import numpy as np
>>> body = np.full((40, 60, 3), 200, np.uint8)
>>> mouth = np.zeros((10, 20, 4), np.uint8); mouth[2:8, 4:16] = (255, 0, 0, 255)
>>> c = Compositor((10, 20), 4, composite=Composite(body, at=(30.0, 25.0)), alpha_out=True)
>>> out = c.initial.copy()
>>> frame = c.apply(mouth, out)
>>> frame.shape, frame[25, 30].tolist(), frame[20, 30].tolist(), frame[0, 0].tolist()
((40, 60, 3), [255, 0, 0], [200, 200, 200], [200, 200, 200])
"""

from __future__ import annotations

import math
from typing import Optional, Tuple, Union

import cv2
import numpy as np

from ..morphing.alpha import flatten, has_alpha, over, resize_rgba
# defined beside bank.yaml's composite: key (the bank room sits below this one)
from ..banks.bank import MAX_SCALE, Composite, check_placement
from ..errors import InputError

__all__ = ["Composite", "Compositor", "DEFAULT_BACKGROUND", "MAX_SCALE", "parse_at", "check_placement"]

#: What transparency is flattened onto when the output has no alpha and nothing else was
#: asked for: white, the paper colour most drawn characters are made on (and what a
#: transparent PNG shows on in most viewers and web pages).
DEFAULT_BACKGROUND = (255, 255, 255)
Background = Union[None, Tuple[int, int, int], np.ndarray]


def parse_at(text: str) -> Tuple[float, float]:
    """``"X,Y"`` -> ``(x, y)``; raises :class:`InputError` otherwise.

    Examples
    --------
    >>> parse_at("120,84.5")
    (120.0, 84.5)
    """
    parts = text.split(",")
    try:
        x, y = (float(p) for p in parts)
    except ValueError:
        raise InputError(f"--at must be X,Y (two numbers, pixels on the body image), got {text!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise InputError(f"--at must be finite numbers, got {text!r}")
    return x, y


class Compositor:
    """Turns the renderer's frames into output frames (see the module docstring).

    Parameters
    ----------
    mouth_shape : (int, int)
        ``(H, W)`` of the rendered frames.
    mouth_channels : {3, 4}
        Their channels.
    composite : Composite, optional
        The body and the mouth's place on it.
    background : colour tuple or image, optional
        Flatten onto this (an image is scaled to the output size).
    alpha_out : bool
        Whether the output format keeps alpha; if not, transparency is flattened onto
        ``background`` or :data:`DEFAULT_BACKGROUND`.

    Attributes
    ----------
    shape : (int, int)
        Output ``(H, W)``.
    channels : int
        Output channels (4 only when the output keeps alpha and the picture has some).
    passthrough : bool
        True when output frames are the rendered frames themselves (nothing to do).
    initial : numpy.ndarray or None
        What every output buffer must hold before its first :meth:`apply`.
    flattened : bool
        Whether transparency is flattened onto a background nobody asked for (mp4 without
        ``--background``): worth telling the user.
    """

    def __init__(self, mouth_shape: Tuple[int, int], mouth_channels: int, *, composite: Optional[Composite] = None,
                 background: Background = None, alpha_out: bool = True):
        self.mouth_shape = tuple(mouth_shape)
        self.mouth_channels = mouth_channels
        self.flattened = False
        mh, mw = self.mouth_shape
        if composite is None:
            self.shape = (mh, mw)
            needs_flat = mouth_channels == 4 and (background is not None or not alpha_out)
            self.passthrough = not needs_flat
            if self.passthrough:
                self.channels, self.initial, self._rect = mouth_channels, None, None
                return
            self.flattened = background is None
            base = self._background_canvas(background, self.shape)
            self._place((mh, mw), (0, 0))
        else:
            problem = check_placement(composite.image.shape, composite.at, composite.scale)
            if problem:
                raise InputError(f"composite: {problem}", path=composite.path)
            body = composite.image
            bh, bw = body.shape[:2]
            self.shape = (bh, bw)
            self.passthrough = False
            base = body
            if has_alpha(body) and (background is not None or not alpha_out):
                self.flattened = background is None
                base = flatten(body, self._background_canvas(background, self.shape))
            elif not has_alpha(body) and background is not None:
                pass  # an opaque body covers any background
            sh, sw = max(1, round(mh * composite.scale)), max(1, round(mw * composite.scale))
            # half pixels round up (floor(v + 0.5), not Python's round-half-even)
            x0 = math.floor(composite.at[0] - (sw - 1) / 2 + 0.5)
            y0 = math.floor(composite.at[1] - (sh - 1) / 2 + 0.5)
            self._place((sh, sw), (y0, x0))
            if self._rect is None:
                raise InputError("composite: the mouth lies entirely outside the body image", path=composite.path)
        self.initial = np.ascontiguousarray(base)
        self.channels = self.initial.shape[2]

    @staticmethod
    def _background_canvas(background: Background, shape: Tuple[int, int]) -> np.ndarray:
        h, w = shape
        if background is None:
            background = DEFAULT_BACKGROUND
        if isinstance(background, np.ndarray):
            img = background
            if img.shape[:2] != (h, w):
                interp = cv2.INTER_AREA if img.shape[0] * img.shape[1] > h * w else cv2.INTER_LINEAR
                img = resize_rgba(img, (w, h), interpolation=interp) if has_alpha(img) else \
                    cv2.resize(img, (w, h), interpolation=interp)
            if has_alpha(img):
                img = flatten(img, DEFAULT_BACKGROUND)
            return np.ascontiguousarray(img)
        canvas = np.empty((h, w, 3), np.uint8)
        canvas[:] = background
        return canvas

    def _place(self, size: Tuple[int, int], origin: Tuple[int, int]) -> None:
        """The scaled mouth's ``size`` at ``origin`` (y, x), clipped to the output."""
        sh, sw = size
        y0, x0 = origin
        h, w = self.shape
        ys, xs = max(0, y0), max(0, x0)
        ye, xe = min(h, y0 + sh), min(w, x0 + sw)
        self._size = (sh, sw)
        if ys >= ye or xs >= xe:
            self._rect = None
            return
        # output rectangle, and the part of the scaled mouth that lands in it
        self._rect = (slice(ys, ye), slice(xs, xe))
        self._src = (slice(ys - y0, ye - y0), slice(xs - x0, xe - x0))

    def apply(self, mouth: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Write the output frame for the rendered ``mouth`` into ``out`` and return it.

        ``out`` must hold :attr:`initial` outside the mouth's rectangle (it does after
        being filled with it once: only the rectangle is ever written).
        """
        if self.passthrough:
            np.copyto(out, mouth)
            return out
        sh, sw = self._size
        if (sh, sw) != mouth.shape[:2]:
            shrink = sh * sw < mouth.shape[0] * mouth.shape[1]
            interp = cv2.INTER_AREA if shrink else cv2.INTER_LINEAR
            mouth = resize_rgba(mouth, (sw, sh), interpolation=interp) if has_alpha(mouth) else \
                cv2.resize(mouth, (sw, sh), interpolation=interp)
        part = mouth[self._src]
        dst = out[self._rect]
        base = self.initial[self._rect]
        if not has_alpha(part):
            np.copyto(dst, part)
        elif has_alpha(base):
            over(part, base, dst)
        else:
            # opaque canvas: (a * mouth + (255 - a) * canvas) / 255 in one SIMD pass
            a = part[..., 3].astype(np.float32)
            np.copyto(dst, cv2.blendLinear(cv2.cvtColor(part, cv2.COLOR_RGBA2RGB), base, a, 255.0 - a))
        return out
