"""H.264 in an mp4 (or .m4v/.mkv, or with ``--format mp4`` a .mov) container: the default output.

The ffmpeg binary bundled with imageio-ffmpeg reads raw ``yuv420p`` frames on stdin,
converted from RGB in this process (:mod:`lipsync.encode.yuv`, BT.709 limited range): H.264
(libx264), tagged BT.709 matrix, primaries and transfer and tv range (the matrix web players
assume for untagged RGB-sourced video), ``-movflags +faststart``, ``-crf`` and ``-preset``
(x264's presets, or a name from :data:`X264_PRESETS`). yuv420p needs even dimensions: an odd
width or height is padded by one pixel that repeats the last column/row (padding rather than
cropping keeps every drawn pixel; repeating the edge avoids a dark seam bleeding into
chroma). Audio is AAC (see :mod:`lipsync.encode.ffmpeg` for how it is cut and padded).
"""

from __future__ import annotations

from typing import Dict, List, Optional, Tuple

import numpy as np

from ..errors import InputError, PathLike
from .base import ENCODERS
from .ffmpeg import PipeWriter

__all__ = ["Mp4Writer", "X264_PRESETS", "X264_OWN_PRESETS", "check_preset"]

#: Named encoder settings beyond x264's own presets: name -> (x264 preset, -x264-params).
#: Any other ``preset`` is passed to x264 as it is.
#:
#: ``talking-head``: ultrafast's cheap analysis (diamond search, subme 0, one reference)
#: plus the tools that pay on mostly-static frames: CABAC, 3 B-frames, the macroblock tree
#: over a short lookahead, deblocking and 8x8 transforms. b-adapt 0 and a 5-frame lookahead
#: were both faster *and* smaller here than b-adapt 1 / 10 frames. x264 alone, one thread,
#: crf 18, the 26.7 s benchmark clip (video only):
#:
#: ==============  ===================  ===================
#: clip            veryfast CPU s / MB  talking-head
#: ==============  ===================  ===================
#: face 512x512    0.90 / 0.21          0.52 / 0.26
#: toon 512x512    1.05 / 0.33          0.58 / 0.47
#: face 1280x720   3.62 / 0.70          1.80 / 0.56
#: ==============  ===================  ===================
#:
#: PSNR-Y against the source within 0.9 dB of veryfast's (51.4 vs 51.9, 50.0 vs 49.5, 50.8
#: vs 51.6 dB): all far above visible loss. ultrafast itself is as fast but 3-8x larger
#: (1.5 / 1.9 / 6.4 MB with audio); superfast 2-6x larger.
X264_PRESETS: Dict[str, Tuple[str, Optional[str]]] = {
    "talking-head": ("ultrafast", "cabac=1:bframes=3:b-adapt=0:mbtree=1:rc-lookahead=5:deblock=1:"
                                  "8x8dct=1:partitions=i8x8,i4x4"),
}

#: x264's own speed presets (``x264 --fullhelp``), fastest first.
X264_OWN_PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower",
                    "veryslow", "placebo")


def check_preset(preset: str) -> str:
    """``preset`` if x264 (or :data:`X264_PRESETS`) knows it, else InputError listing the valid ones.

    Checked before any work: an unknown preset used to surface only when ffmpeg, started
    after the flows were computed, refused it (exit 1 and a page of its output).

    Examples
    --------
    >>> check_preset("veryfast"), check_preset("talking-head")
    ('veryfast', 'talking-head')
    """
    if preset not in X264_PRESETS and preset not in X264_OWN_PRESETS:
        raise InputError(f"--preset {preset!r} is not an x264 preset; valid: "
                         f"{', '.join(list(X264_PRESETS) + list(X264_OWN_PRESETS))}")
    return preset


# ffmpeg muxer for each container extension the "mp4" encoder accepts, and whether the
# container takes +faststart (moov atom first so playback starts before download ends).
CONTAINERS = {
    ".mp4": ("mp4", True),
    ".m4v": ("mp4", True),
    ".mov": ("mov", True),
    ".mkv": ("matroska", False),
}


class Mp4Writer(PipeWriter):
    """H.264 in an mp4 (or .m4v/.mov/.mkv) container via the bundled ffmpeg.

    Use :func:`~lipsync.encode.open_writer` rather than this class directly.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from lipsync.encode import probe
    >>> out = os.path.join(tempfile.mkdtemp(), "odd.mp4")
    >>> with Mp4Writer(out, fps=25, size=(33, 21), quiet=True) as w:
    ...     w.write(np.zeros((21, 33, 3), np.uint8))
    >>> probe(out)["width"], probe(out)["height"]   # padded to even
    (34, 22)
    """

    extension = ".mp4"
    options = ("frames", "crf", "preset", "threads")
    # mp4, not mkv: matroska rounds timestamps to 1 ms, which would make 60 or 29.97 fps
    # video slightly variable-rate after the stream copy of the audio mux.
    intermediate = (".mp4", "mp4")

    def __init__(self, out: PathLike, *, fps: float, size: Tuple[int, int], audio: Optional[PathLike] = None,
                 crf: int = 18, preset: str = "medium", quiet: bool = False, total: Optional[int] = None,
                 frames: Optional[int] = None, threads: Optional[int] = None, channels: int = 3):
        self.crf = int(crf)
        self.preset = check_preset(str(preset))
        self.threads = None if threads is None else max(1, int(threads))
        super().__init__(out, fps=fps, size=size, audio=audio, quiet=quiet, total=total, frames=frames,
                         channels=channels)

    def _container(self, ext: str) -> Tuple[str, bool]:
        return CONTAINERS.get(ext, ("mp4", True))

    def _input_args(self) -> List[str]:
        from .yuv import rgb_to_yuv420p

        width, height = self.size
        self._pad = (width % 2, height % 2)
        pw, ph = width + self._pad[0], height + self._pad[1]
        self._to_yuv = rgb_to_yuv420p
        self._payload_bytes = pw * ph + 2 * (pw // 2) * (ph // 2)
        # Frames arrive already converted (lipsync.encode.yuv, on the writing thread): see
        # prepare(). Tagged on input too, so ffmpeg sees nothing to convert.
        return ["-f", "rawvideo", "-pix_fmt", "yuv420p", "-color_range", "tv", "-colorspace", "bt709",
                "-color_primaries", "bt709", "-color_trc", "bt709", "-s", f"{pw}x{ph}"]

    def _codec_args(self) -> List[str]:
        # Tagged so players convert back to RGB the way the frames were converted.
        cmd = ["-color_primaries", "bt709", "-color_trc", "bt709", "-colorspace", "bt709", "-color_range", "tv",
               "-c:v", "libx264", "-crf", str(self.crf)]
        x264_preset, x264_params = X264_PRESETS.get(self.preset, (self.preset, None))
        cmd += ["-preset", x264_preset]
        if x264_params:
            cmd += ["-x264-params", x264_params]
        if self.threads is not None:
            cmd += ["-threads", str(self.threads)]
        return cmd

    def prepare(self, frame: np.ndarray, out=None) -> np.ndarray:
        """The yuv420p bytes of ``frame`` (padded to even size), into ``out`` when given.

        Converted here rather than by swscale in ffmpeg: half the bytes through the pipe and
        a quarter of the CPU (1.1 ms vs 2.4 ms a 1280x720 frame; lipsync/yuv.py).
        """
        if any(self._pad):
            frame = np.pad(frame, ((0, self._pad[1]), (0, self._pad[0]), (0, 0)), mode="edge")
        return self._to_yuv(frame, out)


# .mov itself belongs to the "mov" format (ProRes 4444, with alpha); H.264 in a MOV is
# still there with --format mp4.
ENCODERS.register("mp4", Mp4Writer, extensions=tuple(e for e in CONTAINERS if e != ".mov"), aliases=("h264", "mkv"))
