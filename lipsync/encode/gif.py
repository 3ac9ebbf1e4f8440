"""Animated GIF, for previews where nothing newer plays: 256 colours, 1-bit transparency, no audio.

One palette for the whole clip (``palettegen`` over every frame, one slot reserved for
transparency, then ``paletteuse``): a talking mouth uses few colours, so one palette keeps
them steady from frame to frame. GIF transparency is on or off: pixels with alpha below
:data:`GIF_ALPHA_THRESHOLD` become transparent, the rest opaque.
"""

from __future__ import annotations

from typing import List, Tuple

from .base import ENCODERS
from .ffmpeg import RgbPipeWriter

__all__ = ["GifWriter"]

#: Alpha at or above which a pixel is drawn (GIF has no partial transparency): half way.
GIF_ALPHA_THRESHOLD = 128


class GifWriter(RgbPipeWriter):
    """Animated GIF (one palette, looping) via the bundled ffmpeg.

    palettegen needs every frame before the first is written, so ffmpeg holds the clip in
    memory: fine for previews, not for long clips (use WebM or a PNG sequence).

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> out = os.path.join(tempfile.mkdtemp(), "a.gif")
    >>> with GifWriter(out, fps=10, size=(32, 16), channels=4, quiet=True) as w:
    ...     w.write(np.zeros((16, 32, 4), np.uint8))
    >>> open(out, "rb").read(6)
    b'GIF89a'
    """

    extension = ".gif"
    alpha = True
    audio_track = False

    def _container(self, ext: str) -> Tuple[str, bool]:
        return "gif", False

    def _codec_args(self) -> List[str]:
        graph = ("split[a][b];[a]palettegen=reserve_transparent=1:stats_mode=full[p];"
                 f"[b][p]paletteuse=dither=bayer:bayer_scale=3:alpha_threshold={GIF_ALPHA_THRESHOLD}")
        return ["-vf", graph, "-c:v", "gif", "-loop", "0"]  # one input, one output: a -vf graph


ENCODERS.register("gif", GifWriter, extensions=(".gif",))
