"""Speech audio as a timeline: aligned with pocketsphinx (:mod:`lipsync.speech`) on reading.

Any audio file ffmpeg reads becomes the phone timeline of its speech, so every command that
reads timelines (render, timeline, cues, batch, serve) accepts audio through the same stage.
The transcript travels as the reader option ``text`` (a file path or the text itself; none:
the words are recognised). ``tier="words"`` gives the words instead of the phones. Labels
are ARPAbet without stress digits, as the other readers give them; silence is gaps.
"""

from __future__ import annotations

from ..motion.timeline import Timeline
from .base import READERS, Reader, ReadOptions

# Magic numbers at the start of the audio containers people save speech in.
_MAGIC = (b"RIFF", b"RF64", b"fLaC", b"OggS", b"ID3", b"\x1a\x45\xdf\xa3", b"FORM", b"caff",
          b"#!AMR", b"\x30\x26\xb2\x75")


#: MPEG program stream (a .mpg/.vob: video with its sound), pack header start code.
_MPEG_PS = b"\x00\x00\x01\xba"


def sniff(head: bytes) -> bool:
    if head.startswith(b"RIFF") or head.startswith(b"RF64"):
        return head[8:12] in (b"WAVE", b"AVI ")
    if head.startswith(_MPEG_PS):
        return True
    if head.startswith(_MAGIC):
        return True
    if head[4:8] == b"ftyp":  # mp4 / m4a
        return True
    # A bare MPEG layer III or ADTS AAC frame (sync bits, then version/layer). Only these
    # second bytes: FF FE is a UTF-16 byte-order mark, which text timelines start with.
    return len(head) >= 2 and head[0] == 0xFF and head[1] in _FRAME_SYNC


_FRAME_SYNC = frozenset({0xFA, 0xFB, 0xF2, 0xF3, 0xE2, 0xE3, 0xF1, 0xF9})


def is_audio_input(path, format=None) -> bool:
    """True if reading ``path`` as a timeline (with ``format``) would read it as audio.

    Examples
    --------
    >>> is_audio_input("speech.flac"), is_audio_input("speech.phn"), is_audio_input("x.dat", "audio")
    (True, False, True)
    """
    import os

    from ..speech.audio import is_audio_path

    if format is not None:
        return format.lower() == "audio"
    if is_audio_path(path):
        return True
    try:
        with open(os.fspath(path), "rb") as f:
            return sniff(f.read(16))
    except OSError:
        return False


def read(path: str, data: bytes, options: ReadOptions) -> Timeline:
    from ..speech.align import align
    from .textgrid import normalise_label

    alignment = align(path, getattr(options, "text", None), quiet=getattr(options, "quiet", True),
                      lang=getattr(options, "lang", None))
    if (options.tier or "phones") == "words":
        return alignment.words
    return alignment.phones.replace(segments=tuple(
        type(s)(s.start, s.end, normalise_label(s.label)) for s in alignment.phones))


def _extensions():
    from ..speech.audio import AUDIO_EXTENSIONS

    return AUDIO_EXTENSIONS


READERS.register("audio", Reader("audio", read, sniff, "speech audio (any format ffmpeg reads), "
                                                      "aligned with pocketsphinx"),
                 extensions=_extensions())
