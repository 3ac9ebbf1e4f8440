"""Timeline readers, one module per file format; each registers itself in ``READERS``.

The order of :data:`MODULES` is the content-sniffing order: formats with an unmistakable
signature (TextGrid, MohoSwitch1, JSON keys) come before the plain-text tables whose
sniffing is a guess.

Reader lookup (the same order as imageio's plugins): an explicit ``format`` first, then the
file extension, then content sniffing of the first bytes; an unknown format name raises
:class:`~lipsync.errors.UnknownNameError` listing the valid ones.

Examples
--------
>>> import os, tempfile
>>> d = tempfile.mkdtemp()
>>> p = os.path.join(d, "hi.phn")
>>> _ = open(p, "w").write("0 1600 h#\\n1600 4800 hh\\n4800 8000 ay\\n")
>>> tl = read_timeline(p)
>>> tl.kind, len(tl), tl[1].label, tl.duration
('phoneme', 3, 'hh', 0.5)
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from typing import Optional

from .._files import read_input_bytes
from ..errors import InputError, TimelineError
from ..motion.timeline import PathLike, Timeline
from .base import READERS, Reader, ReadOptions

__all__ = ["MODULES", "READERS", "Reader", "ReadOptions", "load_all", "read_timeline"]

# Audio comes last: its sniffing checks binary magic numbers no text format has.
MODULES = ["textgrid", "papagayo", "gentle", "rhubarb", "polly", "azure", "words", "moho", "timit", "audacity", "grid",
           "audio"]

_loaded = False


def load_all() -> None:
    """Import every reader module once (each registers itself in :data:`READERS`)."""
    global _loaded
    if _loaded:
        return
    _loaded = True
    for name in MODULES:
        importlib.import_module(f".{name}", __name__)


_SNIFF_BYTES = 4096


def read_timeline(path: PathLike, format: Optional[str] = None, *, tier: Optional[str] = None,
                  sample_rate: float = 16000, fps: float = 24.0, text: Optional[str] = None,
                  quiet: bool = True, lang: Optional[str] = None) -> Timeline:
    """Read a phoneme or viseme timeline from any supported file.

    Parameters
    ----------
    path : path-like
        The timeline file.
    format : str, optional
        A name from ``READERS.names()``; default: by extension, then by content.
    tier : str, optional
        TextGrid tier to read (default ``phones``, as the Montreal Forced Aligner writes it).
    sample_rate : float
        Samples per second of TIMIT ``.phn`` times (16000 for TIMIT itself).
    fps : float
        Frame rate of a Moho switch ``.dat`` file (frames are 1-based).
    text : str, optional
        For audio: its transcript, or a file holding it (default: the words are recognised).
    quiet : bool
        For audio: no progress bar while aligning.
    lang : str, optional
        For audio: its language (BCP 47; default English), see :func:`lipsync.speech.align.align`.

    Returns
    -------
    Timeline
        Labels normalised by the reader (stress digits and Gentle's position suffixes removed).

    Raises
    ------
    TimelineError
        The file cannot be read as a timeline; the message names the file and line.
    UnknownNameError
        ``format`` is not a known format name.

    Examples
    --------
    >>> import os, tempfile
    >>> p = os.path.join(tempfile.mkdtemp(), "cues.txt")
    >>> _ = open(p, "w").write("0.00\\tX\\n0.12\\tB\\n0.40\\tX\\n")
    >>> tl = read_timeline(p, "rhubarb-tsv")
    >>> tl.kind, tl.labels(), tl.duration
    ('viseme', ['X', 'B'], 0.4)
    """
    name = os.fspath(path)
    if format is not None:
        reader = READERS.get(format)
    else:
        reader = None
    if sample_rate is None or not (0 < float(sample_rate) < float("inf")):
        raise InputError(f"sample rate must be a positive number, not {sample_rate!r}")
    if fps is None or not (0 < float(fps) < float("inf")):
        raise InputError(f"frame rate must be a positive number, not {fps!r}")
    if (reader.name if reader is not None else READERS.name_for_extension(Path(name).suffix)) == "audio":
        # ffmpeg decodes audio from the file itself: only the first bytes are read here
        data = read_input_bytes(name, "a timeline file", error=TimelineError, limit=_SNIFF_BYTES)
        if len(data) > _SNIFF_BYTES and reader is None and not READERS.get("audio").sniff(data):
            data = read_input_bytes(name, "a timeline file", error=TimelineError)  # not audio after all
    else:
        data = read_input_bytes(name, "a timeline file", error=TimelineError)  # at most 64 MB
    if not data.strip():
        raise TimelineError("empty file", path=name, line=1)
    if reader is None:
        reader = _choose_reader(name, data)
    options = ReadOptions(tier=tier, sample_rate=float(sample_rate), fps=float(fps), text=text, quiet=bool(quiet),
                          lang=lang)
    return reader.read(name, data, options)


def _choose_reader(name: str, data: bytes) -> Reader:
    ext_name = READERS.name_for_extension(Path(name).suffix)
    head = data[:_SNIFF_BYTES]
    # Several formats share ".txt" / ".json" (Rhubarb TSV vs Audacity, Rhubarb JSON vs
    # Gentle JSON), so an extension match is confirmed by sniffing when the content disagrees.
    if ext_name is not None:
        reader = READERS.get(ext_name)
        if reader.sniff(head):
            return reader
    for _, reader in READERS.items():
        if reader.sniff(head):
            return reader
    # JSON the first bytes did not give away: recognised by its structure, or an error
    # listing the JSON formats (rather than one format's complaint about missing keys).
    from .jsonkind import json_reader_for
    reader = json_reader_for(name, data)
    if reader is not None:
        return reader
    if ext_name is not None:
        return READERS.get(ext_name)  # its own errors say what is wrong with the content
    from ._common import looks_binary
    if looks_binary(data):
        raise TimelineError("binary data, not a timeline file", path=name, line=1)
    raise TimelineError(
        "cannot tell the timeline format from the name or content; give it explicitly "
        f"(valid: {', '.join(READERS.names())})", path=name, line=1)


# Every reader is registered when this package is imported, so READERS is complete for
# whoever uses it (CLI choices, sniffing).
load_all()
