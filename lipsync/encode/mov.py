"""QuickTime MOV for editors: ProRes 4444 with alpha (``mov``), or QuickTime Animation (``qtrle``).

``mov``: Apple ProRes 4444 (``prores_ks``, profile 4444), stored as ``yuva444p12le`` for
RGBA frames -- full-resolution chroma and a 16-bit alpha plane, what After Effects,
Premiere, Final Cut and DaVinci Resolve take as a transparent intermediate -- or
``yuv444p12le`` for opaque frames; BT.709, tagged. (The frames reach ffmpeg as 10-bit
``yuva444p10le``/``yuv444p10le``; ProRes 4444 itself is 12-bit, which is what a player
or ``ffprobe`` reports.) ``qtrle``: QuickTime Animation, lossless run-length RGB(A)
(``argb``): larger, but exact, and older tools read it.

Audio is 16-bit PCM (lossless, what editors expect in a MOV), cut and padded to the video
like mp4's. H.264 in a .mov is still there: ``--format mp4 -o OUT.mov``.
"""

from __future__ import annotations

from typing import List, Tuple

from .base import ENCODERS
from .ffmpeg import RgbPipeWriter, to_yuv

__all__ = ["ProresWriter", "AnimationWriter"]

#: ProRes quantiser (prores_ks -qscale:v, 1 best .. 32): 9 is about what Apple's encoder
#: gives 4444 at its nominal bitrate; lower only grows the file.
PRORES_QSCALE = 9


class _MovWriter(RgbPipeWriter):
    extension = ".mov"
    alpha = True
    audio_args = ("-c:a", "pcm_s16le")

    def _container(self, ext: str) -> Tuple[str, bool]:
        return "mov", True


class ProresWriter(_MovWriter):
    """ProRes 4444 (+ alpha) and PCM audio in a MOV via the bundled ffmpeg.

    Use :func:`~lipsync.encode.open_writer` rather than this class directly.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from lipsync.encode import probe
    >>> out = os.path.join(tempfile.mkdtemp(), "a.mov")
    >>> with ProresWriter(out, fps=25, size=(32, 16), channels=4, quiet=True) as w:
    ...     w.write(np.zeros((16, 32, 4), np.uint8))
    >>> probe(out)["video_codec"]
    'prores'
    """

    def _codec_args(self) -> List[str]:
        cmd = to_yuv("yuva444p10le" if self.channels == 4 else "yuv444p10le")
        cmd += ["-c:v", "prores_ks", "-profile:v", "4444", "-qscale:v", str(PRORES_QSCALE), "-vendor", "apl0"]
        if self.channels == 4:
            cmd += ["-alpha_bits", "16"]
        return cmd


class AnimationWriter(_MovWriter):
    """QuickTime Animation (lossless RLE, ``argb``) and PCM audio in a MOV.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from lipsync.encode import probe
    >>> out = os.path.join(tempfile.mkdtemp(), "a.mov")
    >>> with AnimationWriter(out, fps=25, size=(32, 16), channels=4, quiet=True) as w:
    ...     w.write(np.zeros((16, 32, 4), np.uint8))
    >>> probe(out)["video_codec"]
    'qtrle'
    """

    def _codec_args(self) -> List[str]:
        return ["-pix_fmt", "argb" if self.channels == 4 else "rgb24", "-c:v", "qtrle"]


ENCODERS.register("mov", ProresWriter, extensions=(".mov",), aliases=("prores", "prores4444"))
ENCODERS.register("qtrle", AnimationWriter, aliases=("animation", "quicktime-animation"))
