"""How every ffmpeg process opens a file a user (or a client of ``lipsync serve``) named.

ffmpeg's probe picks a demuxer from the file's bytes and extension, and some demuxers open
*other* files: an HLS playlist (``#EXTM3U`` ... ``/any/file.ts``), a concat list
(``ffconcat version 1.0``), DASH and IMF manifests, image-sequence patterns; protocols such as
``subfile:``, ``concat:``, ``data:``, ``crypto:`` or ``http:`` do the same from a name. Fed an
upload, any of them reads a file outside the job folder and its sound comes back in the
rendered video. So a user's file is opened only

* as ``file:`` + its absolute path (a name like ``concat:a|b`` is never a protocol),
* with ``-protocol_whitelist file`` (no network, no nested protocols), and
* with ``-format_whitelist`` :data:`MEDIA_DEMUXERS`: containers of sound and pictures that
  hold their own data. ffmpeg still probes the bytes (the extension does not matter), but
  refuses anything it recognises as a format outside the list.

Examples
--------
>>> args = input_args("talk.wav")
>>> args[:2], args[-2], args[-1].startswith("file:/")
(['-protocol_whitelist', 'file'], '-i', True)
"""

from __future__ import annotations

import os
from typing import List, Optional, Sequence, Union

PathLike = Union[str, "os.PathLike[str]"]

#: ffmpeg demuxers a user's audio or video may be opened as, with what they read. None of
#: them follows a reference to another file (the mov demuxer's external data references,
#: ``enable_drefs``, are off unless asked for). Playlists and lists -- hls, concat, dash,
#: imf, image2 patterns, webm_dash_manifest, sdp/rtp/rtsp -- are left out on purpose.
MEDIA_DEMUXERS = (
    "wav",            # .wav, RF64 (also what most recorders write)
    "w64",            # Sony Wave64 (long recordings)
    "mp3",            # .mp3, MPEG audio layer I/II/III
    "flac",           # .flac
    "ogg",            # .ogg/.oga/.opus (Vorbis, Opus, Theora)
    "mov",            # .mp4/.m4a/.m4v/.mov/.3gp (ffmpeg's name list: mov,mp4,m4a,3gp,3g2,mj2)
    "matroska",       # .mkv/.mka/.webm (matroska,webm)
    "aac",            # .aac (ADTS)
    "aiff",           # .aif/.aiff
    "caf",            # .caf (Apple Core Audio)
    "amr",            # .amr (phones' voice memos)
    "asf",            # .wma/.wmv
    "avi",            # .avi
    "mpeg",           # .mpg/.mpeg program streams (GRID's videos)
    "mpegts",         # .ts/.m2ts transport streams (cameras, broadcasts)
    "flv",            # .flv
    "au",             # .au/.snd
    "yuv4mpegpipe",   # .y4m raw video
)

#: What :func:`lipsync.encode.probe` may also read back: the animations lipsync writes.
OUTPUT_DEMUXERS = MEDIA_DEMUXERS + ("gif", "webp_anim", "apng")

#: Words ffmpeg says when the whitelist refused the file (its probe found another format).
REFUSED_MARKER = "not on whitelist"

#: What an error says about a refused file.
REFUSED_TEXT = ("not a sound or video container lipsync reads (playlists, concat lists and other files that "
                "point at other files are refused; wav, mp3, flac, ogg, mp4/m4a/mov, mkv/webm, aac, aiff, caf, "
                "amr, wma, avi, mpg and ts are read)")


def input_args(path: PathLike, *, demuxers: Optional[Sequence[str]] = None) -> List[str]:
    """ffmpeg arguments that open ``path`` as one of ``demuxers`` (default
    :data:`MEDIA_DEMUXERS`) and nothing else: ``[... "-i", "file:/abs/path"]``.

    Parameters
    ----------
    path : path-like
        The user's file.
    demuxers : sequence of str, optional
        ffmpeg demuxer names allowed.

    Returns
    -------
    list of str
        To put where ``["-i", path]`` would go.

    Examples
    --------
    >>> input_args("/tmp/a.mp3", demuxers=("mp3",))
    ['-protocol_whitelist', 'file', '-format_whitelist', 'mp3', '-i', 'file:/tmp/a.mp3']
    """
    return ["-protocol_whitelist", "file", "-format_whitelist", ",".join(demuxers or MEDIA_DEMUXERS),
            "-i", file_url(path)]


def file_url(path: PathLike) -> str:
    """``file:`` and the absolute path: what ffmpeg opens only as a plain file.

    Examples
    --------
    >>> file_url("/a/concat:b|c")
    'file:/a/concat:b|c'
    """
    return "file:" + os.path.abspath(os.fspath(path))


def refused(stderr: str) -> bool:
    """Whether ffmpeg's ``stderr`` says the whitelist refused the file.

    Examples
    --------
    >>> refused("[in#0] Format not on whitelist 'wav,mp3'"), refused("Invalid data found")
    (True, False)
    """
    return REFUSED_MARKER in stderr
