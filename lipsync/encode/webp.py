"""Animated WebP, for previews (a chat, an issue, a web page): loops, keeps alpha, no audio."""

from __future__ import annotations

from typing import List, Tuple

from .base import ENCODERS
from .ffmpeg import RgbPipeWriter

__all__ = ["WebpWriter"]

#: libwebp quality (0-100) for the lossy colour; alpha is coded losslessly beside it. 80 is
#: libwebp's own recommendation for photos and looks clean on drawn mouths.
WEBP_QUALITY = 80


class WebpWriter(RgbPipeWriter):
    """Animated WebP (lossy colour, lossless alpha, looping) via the bundled ffmpeg.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> out = os.path.join(tempfile.mkdtemp(), "a.webp")
    >>> with WebpWriter(out, fps=10, size=(32, 16), channels=4, quiet=True) as w:
    ...     w.write(np.zeros((16, 32, 4), np.uint8))
    >>> open(out, "rb").read(4) == b"RIFF"
    True
    """

    extension = ".webp"
    alpha = True
    audio_track = False

    def _container(self, ext: str) -> Tuple[str, bool]:
        return "webp", False

    def _codec_args(self) -> List[str]:
        # libwebp_anim takes bgra (RGB input has alpha 255 added) and converts to YUV itself
        return ["-vf", "format=bgra", "-c:v", "libwebp_anim", "-quality", str(WEBP_QUALITY), "-loop", "0"]


ENCODERS.register("webp", WebpWriter, extensions=(".webp",))
