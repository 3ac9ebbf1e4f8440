"""Audio in: decoding, transcript normalisation, pronunciations and forced alignment.

One stage per module: :mod:`.audio` (any file ffmpeg reads -> 16 kHz mono samples),
:mod:`.text` (transcript -> dictionary words), :mod:`.lexicon` (word -> ARPAbet phones),
:mod:`.align` (samples + words -> a words/phones timeline with pocketsphinx).
"""

from . import languages  # noqa: F401  (plugs the other languages' aligner into .align: scripts.OTHER_LANGUAGES)
from .lexicon import lookup_missing, normalise_transcript, pronounce

__all__ = ["normalise_transcript", "pronounce", "lookup_missing"]
