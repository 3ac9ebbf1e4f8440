"""Phones as IPA segments with articulatory features, and the visemes they show.

The room below the phoneme maps (:mod:`lipsync.phonemes`): it knows sounds, not files.

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

from .english import closest_english, english_phones
from .features import FEATURES, Features, features
from .notations import NOTATIONS, SILENCE, detect, to_ipa
from .segments import Part, Phone, canonical, parse, split
from .visemes import RULESETS, compile_rules, compiled, ipa_visemes, label_visemes

__all__ = ["FEATURES", "Features", "features", "Part", "Phone", "parse", "split", "canonical", "NOTATIONS",
           "SILENCE", "detect", "to_ipa", "RULESETS", "compile_rules", "compiled", "label_visemes",
           "ipa_visemes", "closest_english", "english_phones"]
