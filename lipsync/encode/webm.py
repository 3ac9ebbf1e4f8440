"""WebM: VP9 with an alpha channel (``yuva420p``) and Opus audio, for the web and editors.

RGBA frames keep their transparency: libvpx-vp9 codes the alpha plane as a second stream
beside the colour (Chrome, Firefox and Edge play it transparent; ffmpeg reads it back only
with ``-c:v libvpx-vp9``, its native VP9 decoder ignores the alpha side data). Opaque frames
give plain ``yuv420p`` VP9. Colours are converted with the BT.709 matrix and tagged so.
Audio is Opus (WebM allows only Opus or Vorbis), cut and padded to the video like mp4's.
"""

from __future__ import annotations

from typing import List, Tuple

from .base import ENCODERS
from .ffmpeg import RgbPipeWriter, to_yuv

__all__ = ["WebmWriter"]

#: VP9 quality: constant quality (``-b:v 0``) at crf 30 -- libvpx's scale is 0-63 and the
#: WebM project recommends 31 for 720p; drawn mouths at 512x512 show no visible loss at 30.
VP9_CRF = 30
#: libvpx speed: the realtime deadline at cpu-used 8 encodes a 512x512 RGBA frame several
#: times faster than the "good" deadline at cpu-used 4, at a somewhat larger file (see the
#: bench figure alpha_encode); row-mt spreads a frame over the cores.
VP9_SPEED = ["-deadline", "realtime", "-cpu-used", "8", "-row-mt", "1"]
#: Opus at 96 kb/s is transparent for speech.
OPUS_BITRATE = "96k"


class WebmWriter(RgbPipeWriter):
    """VP9 (+ alpha) and Opus in WebM via the bundled ffmpeg.

    Use :func:`~lipsync.encode.open_writer` rather than this class directly.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from lipsync.encode import probe
    >>> out = os.path.join(tempfile.mkdtemp(), "a.webm")
    >>> with WebmWriter(out, fps=25, size=(32, 16), channels=4, quiet=True) as w:
    ...     w.write(np.zeros((16, 32, 4), np.uint8))
    >>> probe(out)["video_codec"]
    'vp9'
    """

    extension = ".webm"
    alpha = True
    options = ("frames", "threads")
    audio_args = ("-c:a", "libopus", "-b:a", OPUS_BITRATE)

    def __init__(self, *args, threads=None, **kwargs):
        self.threads = None if threads is None else max(1, int(threads))
        super().__init__(*args, **kwargs)

    def _container(self, ext: str) -> Tuple[str, bool]:
        return "webm", False

    def _codec_args(self) -> List[str]:
        cmd = to_yuv("yuva420p" if self.channels == 4 else "yuv420p")
        cmd += ["-c:v", "libvpx-vp9", "-crf", str(VP9_CRF), "-b:v", "0", *VP9_SPEED]
        if self.threads is not None:
            cmd += ["-threads", str(self.threads)]
        return cmd


ENCODERS.register("webm", WebmWriter, extensions=(".webm",), aliases=("vp9",))
