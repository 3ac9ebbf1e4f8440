"""What every timeline reader shares: :class:`ReadOptions`, :class:`Reader` and the
:data:`READERS` registry. Each reader module registers itself here; :mod:`lipsync.readers`
imports them all. Separate from the package so that reader modules import it and the
package imports them, and nothing imports in a circle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

from ..registry import Registry
from ..motion.timeline import Timeline


@dataclass(frozen=True)
class ReadOptions:
    """What a reader may need besides the file: chosen tier, TIMIT sample rate, Moho frame rate,
    an audio file's transcript (``text``: the text or a file holding it), and whether reading
    (aligning audio) may show a progress bar (``quiet=False``)."""

    tier: Optional[str] = None
    sample_rate: float = 16000
    fps: float = 24.0
    text: Optional[str] = None
    quiet: bool = True
    lang: Optional[str] = None


@dataclass(frozen=True)
class Reader:
    """A timeline file format.

    ``read(path, data, options)`` gets the raw bytes and returns a Timeline; ``sniff(head)``
    gets the first bytes and says whether they look like this format.
    """

    name: str
    read: Callable[[str, bytes, ReadOptions], Timeline]
    sniff: Callable[[bytes], bool]
    description: str = ""


READERS: Registry[Reader] = Registry("timeline format")
