"""IPA labels -> segments: base letters with their modifiers, tone and stress set apart.

A *label* is what one interval of a phone tier says (``"tʃ"``, ``"aɪ"``, ``"œ̃"``, ``"pʰ"``,
``"a˥˩"``, ``"ˈeː"``). :func:`parse` reads it into a :class:`Phone`: one :class:`Part`
per base letter (an affricate or a diphthong has two), each with the modifiers written
after it (length, nasalisation, aspiration, ...), plus the tone and stress, which are
kept apart because they do not shape the mouth. :func:`split` cuts a whole transcription
(``"bɔ̃ʒˈuʁ"``, espeak-ng's output) into labels of one segment each.

What counts as one phone: one base letter; two or three vowels (a diphthong or
triphthong, ``aɪ``, ``aɪə``); a vowel and a glide (MFA's ``aj``, ``ow``); a stop or nasal
followed by a fricative, trill or approximant of another letter (affricates and prenasalised
stops: ``ts``, ``pf``, ``tʃ``, ``mb``), two different stops or nasals (``kp``, ``ŋm``:
labial-velar); or any
two letters joined by a tie (``t͡s``, ``k͡p``). Anything else (``zz``, ``qq``, ``xyz``) is not
a phone, so a label such as ``"zz"`` still warns as unknown rather than passing for IPA.

Examples
--------
>>> p = parse("t͡ʃʰ")
>>> [part.base for part in p.parts], sorted(p.parts[-1].modifiers)
(['t', 'ʃ'], ['aspirated'])
>>> q = parse("ˈa˥˩ː")
>>> q.parts[0].base, q.parts[0].long, q.tone, q.stress
('a', True, '˥˩', 'primary')
>>> parse("zz") is None
True
>>> split("bɔ̃ʒˈuʁ")
['b', 'ɔ̃', 'ʒ', 'u', 'ʁ']
"""

from __future__ import annotations

import dataclasses
import functools
import re
import unicodedata
from dataclasses import dataclass
from typing import Dict, FrozenSet, List, Optional, Tuple

from .features import CONSONANT, FEATURES, LIGATURES, VOWEL, Features

# --- modifiers ----------------------------------------------------------------------------
# Spacing and combining marks written after a letter -> the modifier's name. Reason: the
# IPA chart's "diacritics" and "suprasegmentals" boxes; the names are the chart's.
MODIFIERS: Dict[str, str] = {
    "ː": "long", "ˑ": "half-long", "\u0306": "extra-short", ":": "long",  # ASCII colon: typed for ː
    "\u0303": "nasalised", "ⁿ": "nasal-release", "ˡ": "lateral-release",
    "ʰ": "aspirated", "ʱ": "breathy", "\u0324": "breathy", "\u0330": "creaky",
    "ʲ": "palatalised", "ʷ": "labialised", "ᶣ": "labio-palatalised", "ˠ": "velarised",
    "ˤ": "pharyngealised", "\u0334": "velarised", "ˀ": "glottalised",
    "\u0329": "syllabic", "\u030d": "syllabic", "\u032f": "non-syllabic", "\u0311": "non-syllabic",
    "\u0325": "devoiced", "\u030a": "devoiced", "\u032c": "voiced",
    "ʼ": "ejective", "\u02de": "rhotic",
    "\u032a": "dental", "\u033a": "apical", "\u033b": "laminal", "\u033c": "linguolabial",
    "\u031f": "advanced", "\u0320": "retracted", "\u0308": "centralised", "\u033d": "mid-centralised",
    "\u031d": "raised", "˔": "raised", "\u031e": "lowered", "˕": "lowered",
    "\u0318": "advanced-tongue-root", "\u0319": "retracted-tongue-root",
    "\u0339": "more-rounded", "\u031c": "less-rounded", "\u031a": "unreleased",
    "\u0348": "fortis", "\u0349": "lenis",  # Korean tense (k͈) and lax stops (MFA Korean)
    "\u0327": "fronted",  # a cedilla on a letter other than ç (rare; ç itself is a base letter)
    "ᵝ": "labialised", "ᵊ": "schwa-release", "ᶿ": "dental-release",
}
# Ties join two letters into one sound (an affricate, a doubly articulated stop).
TIES = frozenset("\u0361\u035c‿")
# Stress marks (not the mouth's business).
STRESS = {"ˈ": "primary", "ˌ": "secondary"}
# Chao tone letters (both stem sides) and tone diacritics on vowels; all dropped for the
# mouth. Combining acute/grave/macron/caron/circumflex over a vowel are tone marks in IPA.
TONE_LETTERS = frozenset("˥˦˧˨˩꜒꜓꜔꜕꜖꜈꜉꜊꜋꜌ꜜꜛ↗↘")
TONE_DIACRITICS = frozenset("\u0301\u0300\u0304\u030b\u030f\u030c\u0302\u1dc4\u1dc5\u1dc6\u1dc7\u1dc8\u1dc9")
# Separators a transcription may carry between segments: syllable break, linking,
# espeak-ng's word-joining hyphen and pause marks, X-SAMPA's / Kirshenbaum's boundaries.
SEPARATORS = frozenset(".-_|‖ \t")

_TONE_NUMBER = re.compile(r"[0-9]+$")
# Glides that may follow a vowel in a one-phone diphthong spelling (MFA's aj, ow, ɔj).
_GLIDES = frozenset("jwɥɰ")
_STOPS = frozenset({"stop", "nasal", "click"})
_RELEASES = frozenset({"fricative", "approximant", "trill", "flap"})


@dataclass(frozen=True)
class Part:
    """One base letter and the modifiers written on it.

    ``features`` are the letter's (:data:`lipsync.phonetics.features.FEATURES`) with the
    modifiers applied: ``nasalised`` sets ``nasal``, ``devoiced``/``voiced`` the voicing,
    ``rhotic`` the r-colouring, ``ejective`` the airstream, ``syllabic`` on a consonant keeps
    it a consonant (the mouth of ``n̩`` is the mouth of ``n``).

    Examples
    --------
    >>> parse("ɔ̃").parts[0].features.nasal
    True
    """

    base: str
    modifiers: FrozenSet[str]
    features: Features

    @property
    def long(self) -> bool:
        """Written long (``ː``) or half-long (``ˑ``)."""
        return "long" in self.modifiers or "half-long" in self.modifiers

    @property
    def is_vowel(self) -> bool:
        return self.features.kind == VOWEL

    def ipa(self) -> str:
        """The part written back in IPA (base letter + its modifiers in a fixed order)."""
        marks = {name: mark for mark, name in reversed(list(MODIFIERS.items())) if mark != ":"}
        return self.base + "".join(marks[m] for m in sorted(self.modifiers) if m in marks)


@dataclass(frozen=True)
class Phone:
    """A parsed label: its parts, tone and stress.

    Examples
    --------
    >>> p = parse("aɪ")
    >>> p.kind, len(p.parts)
    ('diphthong', 2)
    """

    label: str
    parts: Tuple[Part, ...]
    tone: str = ""
    stress: str = ""
    tied: bool = False

    @property
    def kind(self) -> str:
        """``vowel``, ``consonant``, ``diphthong`` (vowel + vowel or glide),
        ``affricate`` (two consonants: also prenasalised and doubly articulated stops) or
        ``sequence``."""
        if len(self.parts) == 1:
            return self.parts[0].features.kind
        vowels = [p.is_vowel for p in self.parts]
        if all(vowels) or (vowels[0] and all(p.is_vowel or p.base in _GLIDES for p in self.parts)):
            return "diphthong"
        if not any(vowels) and len(self.parts) == 2:
            return "affricate"
        return "sequence"

    def ipa(self) -> str:
        """The segments without tone and stress, in IPA.

        Examples
        --------
        >>> parse("ˈa˥ː").ipa(), parse("t͡sʰ").ipa()
        ('aː', 'tsʰ')
        """
        return "".join(p.ipa() for p in self.parts)


def _apply(features: Features, modifiers: FrozenSet[str]) -> Features:
    changes = {}
    if "nasalised" in modifiers:
        changes["nasal"] = True
    if "devoiced" in modifiers:
        changes["voiced"] = False
    if "voiced" in modifiers:
        changes["voiced"] = True
    if "rhotic" in modifiers:
        changes["rhotic"] = True
    if "ejective" in modifiers:
        changes["airstream"] = "ejective"
    if "more-rounded" in modifiers and features.kind == VOWEL:
        changes["rounded"] = True
    return dataclasses.replace(features, **changes) if changes else features


def _expand(text: str) -> str:
    """NFC, ligatures spelled out, precomposed letters not in the table decomposed."""
    text = unicodedata.normalize("NFC", text)
    for lig, plain in LIGATURES.items():
        if lig in text:
            text = text.replace(lig, plain)
    out = []
    for ch in text:
        if ch in FEATURES or ch in MODIFIERS or not unicodedata.decomposition(ch):
            out.append(ch)
        else:  # ẽ, ã, ï, é...: the letter and its marks
            out.append(unicodedata.normalize("NFD", ch))
    return "".join(out)


def _scan(text: str) -> Optional[Tuple[List[Tuple[str, set, bool]], str, str]]:
    """(parts as [base, modifiers, tied-to-previous], tone, stress) or None if not IPA."""
    parts: List[Tuple[str, set, bool]] = []
    tone, stress = [], ""
    tie_next = False
    m = _TONE_NUMBER.search(text)
    if m and m.start() > 0:  # tone numbers: "a55", "ma3" (Chao digits or a tone's index)
        tone.append(m.group())
        text = text[: m.start()]
    for ch in _expand(text):
        if ch in FEATURES:
            parts.append([ch, set(), tie_next])
            tie_next = False
        elif ch in MODIFIERS:
            if not parts:
                return None
            parts[-1][1].add(MODIFIERS[ch])
        elif ch in TIES:
            if not parts:
                return None
            tie_next = True
        elif ch in STRESS:
            stress = stress or STRESS[ch]
        elif ch in TONE_LETTERS or ch in TONE_DIACRITICS:
            tone.append(ch)
        else:
            return None
    if not parts or tie_next:
        return None
    return [(b, m, t) for b, m, t in parts], "".join(tone), stress


def _one_phone(parts: List[Tuple[str, set, bool]]) -> bool:
    """Whether the letters of one label can be one phone (see the module docstring)."""
    if len(parts) == 1:
        return True
    if len(parts) == 2 and parts[1][2]:  # tied
        return True
    feats = [FEATURES[b] for b, _, _ in parts]
    bases = [b for b, _, _ in parts]
    if len(set(bases)) < len(bases):
        return False  # "zz", "aa": a letter written twice is a typo or a word, not one phone
    if all(f.kind == VOWEL for f in feats):
        return len(parts) <= 3
    if feats[0].kind == VOWEL:  # aj, ow, ɔj, aɪ̯ + glide
        return len(parts) <= 3 and all(f.kind == VOWEL or b in _GLIDES for f, b in zip(feats, bases))
    if len(parts) == 2 and all(f.kind == CONSONANT for f in feats):
        first, second = feats
        if first.manner in _STOPS and second.manner in _RELEASES:
            return True  # affricate or prenasalised stop: ts pf tʃ tɕ ʈʂ kx mb nd
        if first.manner == "stop" and second.manner == "stop":
            return True  # doubly articulated stop: kp ɡb
        if first.manner == "nasal" and second.manner in ("stop", "nasal"):
            return True  # prenasalised stop (mb nd ŋɡ), doubly articulated nasal (Vietnamese ŋm)
    return False


@functools.lru_cache(maxsize=4096)
def parse(label: str) -> Optional[Phone]:
    """Read one IPA label; None if it is not one phone in IPA.

    Parameters
    ----------
    label : str
        One interval's label: letters of the IPA chart (and the non-IPA letters of
        :data:`~lipsync.phonetics.features.FEATURES`), with diacritics, ties, stress
        marks, tone letters or a trailing tone number.

    Returns
    -------
    Phone or None

    Examples
    --------
    >>> [(p.base, sorted(p.modifiers)) for p in parse("kʷʼ").parts]
    [('k', ['ejective', 'labialised'])]
    >>> parse("ŋ̍").parts[0].features.manner, parse("ə5").tone
    ('nasal', '5')
    >>> parse("e") .kind, parse("ts").kind, parse("aj").kind
    ('vowel', 'affricate', 'diphthong')
    """
    text = label.strip()
    if not text:
        return None
    scanned = _scan(text)
    if scanned is None:
        return None
    raw, tone, stress = scanned
    if not _one_phone(raw):
        return None
    parts = tuple(Part(b, frozenset(m), _apply(FEATURES[b], frozenset(m))) for b, m, _ in raw)
    return Phone(label, parts, tone=tone, stress=stress, tied=any(t for _, _, t in raw))


def parse_sequence(text: str) -> Optional[Tuple[Part, ...]]:
    """The parts of any run of IPA letters (no one-phone check); None if not IPA.

    Examples
    --------
    >>> [p.base for p in parse_sequence("jɛn")]
    ['j', 'ɛ', 'n']
    """
    scanned = _scan(text.strip()) if text.strip() else None
    if scanned is None:
        return None
    return tuple(Part(b, frozenset(m), _apply(FEATURES[b], frozenset(m))) for b, m, _ in scanned[0])


def split(transcription: str) -> List[str]:
    """Cut an IPA transcription into one label per segment.

    Stress, tone, syllable and word boundaries and punctuation are dropped; a tie keeps
    its two letters in one label (``t͡ʃ``); each letter keeps the modifiers written after
    it. Characters that are not IPA (digits inside a word, Latin punctuation) separate
    segments and are otherwise skipped.

    Examples
    --------
    >>> split("ʒə- syˌiz œ̃ yˈi ɡʁˈɑ̃t")
    ['ʒ', 'ə', 's', 'y', 'i', 'z', 'œ̃', 'y', 'i', 'ɡ', 'ʁ', 'ɑ̃', 't']
    >>> split("t͡sa˥˩ː")
    ['t͡s', 'aː']
    """
    out: List[str] = []
    current = ""
    tie = False
    for ch in _expand(transcription):
        if ch in FEATURES:
            if current and not tie:
                out.append(current)
                current = ""
            current += ch
            tie = False
        elif ch in MODIFIERS and ch != ":":
            if current:
                current += ch
        elif ch in TIES:
            if current:
                current += ch
                tie = True
        else:  # stress, tone, boundaries, anything else: not part of a segment
            if ch in STRESS or ch in TONE_LETTERS or ch in TONE_DIACRITICS:
                continue
            if current:
                out.append(current)
                current = ""
            tie = False
    if current:
        out.append(current)
    return [unicodedata.normalize("NFC", s) for s in out]


def canonical(label: str) -> str:
    """A label in one spelling: NFC, ligatures written out (``ʧ`` -> ``tʃ``); otherwise as written.

    Used by the timeline readers so that the same sound typed two ways is one label.

    Examples
    --------
    >>> canonical("ʧ"), canonical("tʲ"), canonical("e\\u0303") == "ẽ"
    ('tʃ', 'tʲ', True)
    """
    text = unicodedata.normalize("NFC", label.strip())
    for lig, plain in LIGATURES.items():
        if lig in text:
            text = text.replace(lig, plain)
    return text
