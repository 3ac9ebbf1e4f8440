"""Phones as IPA segments with articulatory features, and the visemes they show.

The room below the phoneme maps (:mod:`lipsync.phonetics.phonemes`): it knows sounds, not files.

* :mod:`~lipsync.phonetics.features` -- every letter of the IPA chart with its place,
  manner, voicing, height, backness, rounding, nasality, laterality (a literal table);
* :mod:`~lipsync.phonetics.segments` -- labels read into base letters + modifiers, tone
  and stress set apart (:func:`parse`, :func:`split`);
* :mod:`~lipsync.phonetics.notations` -- ARPAbet, TIMIT, X-SAMPA, pinyin, espeak-ng and
  MFA spellings into IPA (:func:`to_ipa`), and a timeline's notation (:func:`detect`);
* :mod:`~lipsync.phonetics.visemes` -- viseme rules on features (Rhubarb's A-H/X and the
  15 Oculus visemes): :func:`label_visemes`, :func:`ipa_visemes`;
* :mod:`~lipsync.phonetics.english` -- the nearest en-us phone of any segment
  (:func:`closest_english`), for aligning other languages with the en-us model.

Examples
--------
>>> from lipsync import phonetics
>>> phonetics.label_visemes("y"), phonetics.closest_english("y"), phonetics.to_ipa("AW1", "arpabet")
(['F'], 'UW', 'aʊ')
>>> phonetics.ipa_visemes("ˈola", "oculus")
[('o', ['O']), ('l', ['nn']), ('a', ['aa'])]
"""

from __future__ import annotations

import importlib
from typing import Any

# Public names and the module of each, imported on first use: the timeline readers import
# one module of this room, and `import lipsync` stays cheap.
_EXPORTS = {
    "FEATURES": "features", "Features": "features", "features": "features",
    "Part": "segments", "Phone": "segments", "parse": "segments", "split": "segments", "canonical": "segments",
    "NOTATIONS": "notations", "SILENCE": "notations", "detect": "notations", "to_ipa": "notations",
    "RULESETS": "visemes", "compile_rules": "visemes", "compiled": "visemes", "ipa_visemes": "visemes",
    "label_visemes": "visemes",
    "closest_english": "english", "english_phones": "english",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    raise AttributeError(f"module 'lipsync.phonetics' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_EXPORTS))
