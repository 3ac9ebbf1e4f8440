"""Timeline readers, one module per file format; each registers itself in ``READERS``.

The order of :data:`MODULES` is the content-sniffing order: formats with an unmistakable
signature (TextGrid, MohoSwitch1, JSON keys) come before the plain-text tables whose
sniffing is a guess.
"""

from __future__ import annotations

import importlib

# Audio comes last: its sniffing checks binary magic numbers no text format has.
MODULES = ["textgrid", "papagayo", "gentle", "rhubarb", "polly", "azure", "words", "moho", "timit", "audacity", "grid",
           "audio"]

_loaded = False


def load_all() -> None:
    """Import every reader module once (each registers itself in ``lipsync.timeline.READERS``)."""
    global _loaded
    if _loaded:
        return
    _loaded = True
    for name in MODULES:
        importlib.import_module(f".{name}", __name__)
