"""Articulatory features of every IPA letter: a literal table, one row per symbol.

Why a table and not panphon: panphon (MIT) gives 24 binary SPE features (``cor``, ``ant``,
``distr``, ...) from which place and manner must be re-derived, and would add a dependency
(with ``unicodecsv`` and ``regex``) for a few hundred rows. The mouth needs exactly the
chart's own terms -- place, manner, voicing, height, backness, rounding -- so the chart is
written down here, each row with the sound it is and, where the row is not read straight
off the IPA chart, the reason.

Terms (the IPA chart's):

* place: ``bilabial labiodental linguolabial dental alveolar postalveolar retroflex
  alveolo-palatal palatal velar uvular pharyngeal epiglottal glottal labial-velar
  labial-palatal palatal-velar``
* manner: ``stop nasal trill flap fricative approximant click``; ``lateral`` is its own flag
  (``ɬ`` is a lateral fricative, ``l`` a lateral approximant); implosives are stops with
  ``airstream="implosive"``, clicks have ``airstream="click"``, ejectives come from the
  ``ʼ`` modifier (:mod:`lipsync.phonetics.segments`).
* height: ``close near-close close-mid mid open-mid near-open open``;
  backness: ``front central back``.

Examples
--------
>>> f = FEATURES["ʁ"]
>>> f.kind, f.place, f.manner, f.voiced
('consonant', 'uvular', 'fricative', True)
>>> v = FEATURES["y"]
>>> v.kind, v.height, v.backness, v.rounded
('vowel', 'close', 'front', True)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Tuple

CONSONANT = "consonant"
VOWEL = "vowel"

PLACES = ("bilabial", "labiodental", "linguolabial", "dental", "alveolar", "postalveolar", "retroflex",
          "alveolo-palatal", "palatal", "velar", "uvular", "pharyngeal", "epiglottal", "glottal",
          "labial-velar", "labial-palatal", "palatal-velar")
MANNERS = ("stop", "nasal", "trill", "flap", "fricative", "approximant", "click")
HEIGHTS = ("close", "near-close", "close-mid", "mid", "open-mid", "near-open", "open")
BACKNESS = ("front", "central", "back")


@dataclass(frozen=True)
class Features:
    """The articulatory features of one segment.

    Consonants have ``place`` and ``manner``; vowels ``height``, ``backness`` and
    ``rounded``. ``nasal`` is true for nasal stops and nasalised sounds, ``lateral`` for
    the l-sounds, ``rhotic`` for r-coloured vowels (``ɚ``) and sounds marked ``˞``.

    Examples
    --------
    >>> Features(VOWEL, height="open", backness="front").rounded
    False
    """

    kind: str
    place: str = ""
    manner: str = ""
    voiced: bool = True
    height: str = ""
    backness: str = ""
    rounded: bool = False
    nasal: bool = False
    lateral: bool = False
    rhotic: bool = False
    airstream: str = "pulmonic"

    @property
    def is_vowel(self) -> bool:
        return self.kind == VOWEL


def _c(place: str, manner: str, voiced: bool, *, lateral: bool = False, airstream: str = "pulmonic",
       rounded: bool = False) -> Features:
    return Features(CONSONANT, place=place, manner=manner, voiced=voiced, nasal=manner == "nasal",
                    lateral=lateral, airstream=airstream, rounded=rounded)


def _v(height: str, backness: str, rounded: bool, *, rhotic: bool = False) -> Features:
    return Features(VOWEL, height=height, backness=backness, rounded=rounded, rhotic=rhotic)


# --- consonants ---------------------------------------------------------------------------
# symbol: features              # the sound (and why, where the row is not the chart's own)
CONSONANTS: Dict[str, Features] = {
    # Pulmonic stops (plosives)
    "p": _c("bilabial", "stop", False),
    "b": _c("bilabial", "stop", True),
    "t": _c("alveolar", "stop", False),
    "d": _c("alveolar", "stop", True),
    "ʈ": _c("retroflex", "stop", False),
    "ɖ": _c("retroflex", "stop", True),
    "c": _c("palatal", "stop", False),
    "ɟ": _c("palatal", "stop", True),
    "k": _c("velar", "stop", False),
    "ɡ": _c("velar", "stop", True),     # U+0261, the IPA letter
    "g": _c("velar", "stop", True),     # U+0067: what most tools (espeak-ng, X-SAMPA, typing) write
    "q": _c("uvular", "stop", False),
    "ɢ": _c("uvular", "stop", True),
    "ʡ": _c("epiglottal", "stop", False),  # "other symbols": epiglottal plosive
    "ʔ": _c("glottal", "stop", False),
    # Nasals
    "m": _c("bilabial", "nasal", True),
    "ɱ": _c("labiodental", "nasal", True),
    "n": _c("alveolar", "nasal", True),
    "ɳ": _c("retroflex", "nasal", True),
    "ɲ": _c("palatal", "nasal", True),
    "ŋ": _c("velar", "nasal", True),
    "ɴ": _c("uvular", "nasal", True),
    # Trills
    "ʙ": _c("bilabial", "trill", True),
    "r": _c("alveolar", "trill", True),
    "ʀ": _c("uvular", "trill", True),
    # Taps and flaps
    "ⱱ": _c("labiodental", "flap", True),
    "ɾ": _c("alveolar", "flap", True),
    "ɽ": _c("retroflex", "flap", True),
    "ɺ": _c("alveolar", "flap", True, lateral=True),  # "other symbols": alveolar lateral flap
    # Fricatives
    "ɸ": _c("bilabial", "fricative", False),
    "β": _c("bilabial", "fricative", True),
    "f": _c("labiodental", "fricative", False),
    "v": _c("labiodental", "fricative", True),
    "θ": _c("dental", "fricative", False),
    "ð": _c("dental", "fricative", True),
    "s": _c("alveolar", "fricative", False),
    "z": _c("alveolar", "fricative", True),
    "ʃ": _c("postalveolar", "fricative", False),
    "ʒ": _c("postalveolar", "fricative", True),
    "ʂ": _c("retroflex", "fricative", False),
    "ʐ": _c("retroflex", "fricative", True),
    "ɕ": _c("alveolo-palatal", "fricative", False),  # "other symbols"
    "ʑ": _c("alveolo-palatal", "fricative", True),   # "other symbols"
    "ç": _c("palatal", "fricative", False),
    "ʝ": _c("palatal", "fricative", True),
    "x": _c("velar", "fricative", False),
    "ɣ": _c("velar", "fricative", True),
    "χ": _c("uvular", "fricative", False),
    "ʁ": _c("uvular", "fricative", True),
    "ħ": _c("pharyngeal", "fricative", False),
    "ʕ": _c("pharyngeal", "fricative", True),
    "ʜ": _c("epiglottal", "fricative", False),  # "other symbols"
    "ʢ": _c("epiglottal", "fricative", True),   # "other symbols"
    "h": _c("glottal", "fricative", False),
    "ɦ": _c("glottal", "fricative", True),
    "ɧ": _c("palatal-velar", "fricative", False),  # Swedish sj-sound: postalveolar and velar at once
    "ɬ": _c("alveolar", "fricative", False, lateral=True),
    "ɮ": _c("alveolar", "fricative", True, lateral=True),
    # Approximants
    "ʋ": _c("labiodental", "approximant", True),
    "ɹ": _c("alveolar", "approximant", True),
    "ɻ": _c("retroflex", "approximant", True),
    "j": _c("palatal", "approximant", True),
    "ɰ": _c("velar", "approximant", True),
    "w": _c("labial-velar", "approximant", True, rounded=True),   # "other symbols": lips round
    "ʍ": _c("labial-velar", "fricative", False, rounded=True),    # "other symbols": voiceless w
    "ɥ": _c("labial-palatal", "approximant", True, rounded=True),  # "other symbols": French huit
    # Lateral approximants
    "l": _c("alveolar", "approximant", True, lateral=True),
    "ɭ": _c("retroflex", "approximant", True, lateral=True),
    "ʎ": _c("palatal", "approximant", True, lateral=True),
    "ʟ": _c("velar", "approximant", True, lateral=True),
    "ɫ": _c("alveolar", "approximant", True, lateral=True),  # velarised (dark) l, one code point
    # Non-pulmonic: clicks (place of the front closure)
    "ʘ": _c("bilabial", "click", False, airstream="click"),
    "ǀ": _c("dental", "click", False, airstream="click"),
    "ǃ": _c("alveolar", "click", False, airstream="click"),
    "ǂ": _c("palatal", "click", False, airstream="click"),  # palatoalveolar: tongue blade on the palate
    "ǁ": _c("alveolar", "click", False, lateral=True, airstream="click"),
    # Non-pulmonic: voiced implosives
    "ɓ": _c("bilabial", "stop", True, airstream="implosive"),
    "ɗ": _c("alveolar", "stop", True, airstream="implosive"),
    "ʄ": _c("palatal", "stop", True, airstream="implosive"),
    "ɠ": _c("velar", "stop", True, airstream="implosive"),
    "ʛ": _c("uvular", "stop", True, airstream="implosive"),
    # Withdrawn or non-IPA letters that tools still write
    "ɼ": _c("alveolar", "trill", True),       # old IPA: alveolar fricative trill (Czech ř is r̝ today)
    "ƫ": _c("palatal", "stop", False),        # old IPA: palatalised t (ASCII-era dictionaries)
    "ȵ": _c("alveolo-palatal", "nasal", True),  # Sinological: alveolo-palatal n (Chinese dictionaries)
    "ȶ": _c("alveolo-palatal", "stop", False),  # Sinological: alveolo-palatal t
    "ȡ": _c("alveolo-palatal", "stop", True),   # Sinological: alveolo-palatal d
    "ȴ": _c("alveolo-palatal", "approximant", True, lateral=True),  # Sinological: alveolo-palatal l
}

# --- vowels -------------------------------------------------------------------------------
VOWELS: Dict[str, Features] = {
    # Close
    "i": _v("close", "front", False),
    "y": _v("close", "front", True),
    "ɨ": _v("close", "central", False),
    "ʉ": _v("close", "central", True),
    "ɯ": _v("close", "back", False),
    "u": _v("close", "back", True),
    # Near-close
    "ɪ": _v("near-close", "front", False),
    "ʏ": _v("near-close", "front", True),
    "ʊ": _v("near-close", "back", True),
    # Close-mid
    "e": _v("close-mid", "front", False),
    "ø": _v("close-mid", "front", True),
    "ɘ": _v("close-mid", "central", False),
    "ɵ": _v("close-mid", "central", True),
    "ɤ": _v("close-mid", "back", False),
    "o": _v("close-mid", "back", True),
    # Mid
    "ə": _v("mid", "central", False),
    # Open-mid
    "ɛ": _v("open-mid", "front", False),
    "œ": _v("open-mid", "front", True),
    "ɜ": _v("open-mid", "central", False),
    "ɞ": _v("open-mid", "central", True),
    "ʌ": _v("open-mid", "back", False),
    "ɔ": _v("open-mid", "back", True),
    # Near-open
    "æ": _v("near-open", "front", False),
    "ɐ": _v("near-open", "central", False),
    # Open
    "a": _v("open", "front", False),
    "ɶ": _v("open", "front", True),
    "ɑ": _v("open", "back", False),
    "ɒ": _v("open", "back", True),
    # r-coloured vowels (one code point each; also written ə˞)
    "ɚ": _v("mid", "central", False, rhotic=True),
    "ɝ": _v("open-mid", "central", False, rhotic=True),
    # Non-IPA letters that dictionaries, espeak-ng and MFA write
    "ᵻ": _v("near-close", "central", False),  # barred small capital i (espeak-ng, Oxford): between ɪ and ə
    "ᵿ": _v("near-close", "central", True),   # barred upsilon: rounded ᵻ
    "ɩ": _v("near-close", "front", False),    # withdrawn IPA letter for ɪ
    "ɷ": _v("near-close", "back", True),      # withdrawn IPA letter for ʊ
    "ɿ": _v("close", "central", False),       # Sinological apical vowel after z c s (pinyin "zi"): spread lips
    "ʅ": _v("close", "central", False),       # Sinological retroflex apical vowel after zh ch sh r (pinyin "zhi")
    "ʮ": _v("close", "central", True),        # Sinological rounded apical vowel
    "ʯ": _v("close", "central", True),        # Sinological rounded retroflex apical vowel
    "ε": _v("open-mid", "front", False),      # Greek epsilon U+03B5: espeak-ng's Danish writes it for ɛ
}

FEATURES: Dict[str, Features] = {**CONSONANTS, **VOWELS}

# Letters written with a ligature or a compatibility form -> their plain spelling.
LIGATURES: Dict[str, str] = {
    "ʦ": "ts", "ʣ": "dz", "ʧ": "tʃ", "ʤ": "dʒ", "ʨ": "tɕ", "ʥ": "dʑ", "ʪ": "ls", "ʫ": "lz",
    "ǝ": "ə",   # U+01DD turned e (a Latin letter, not IPA) looks like schwa and is typed for it
    "α": "ɑ",   # Greek alpha U+03B1, typed for the IPA open back vowel
    "∫": "ʃ",   # integral sign U+222B, typed for esh
    "ɜ˞": "ɝ",  # r-coloured open-mid central vowel written with the hook
    "ə˞": "ɚ",  # r-coloured schwa written with the hook
}


def features(symbol: str) -> Features:
    """The features of one base letter (no diacritics).

    Raises
    ------
    KeyError
        ``symbol`` is not a letter of the table.

    Examples
    --------
    >>> features("ɲ").place, features("ɲ").nasal
    ('palatal', True)
    """
    return FEATURES[symbol]


def is_letter(symbol: str) -> bool:
    """True if ``symbol`` is one base letter of the table.

    Examples
    --------
    >>> is_letter("ʁ"), is_letter("ʁʷ"), is_letter("Q")
    (True, False, False)
    """
    return symbol in FEATURES


def vowel_height_index(height: str) -> int:
    """0 for close ... 6 for open (for distances).

    Examples
    --------
    >>> vowel_height_index("open") - vowel_height_index("close")
    6
    """
    return HEIGHTS.index(height)


__all__: Tuple[str, ...] = ("Features", "FEATURES", "CONSONANTS", "VOWELS", "LIGATURES", "features",
                            "is_letter", "CONSONANT", "VOWEL", "PLACES", "MANNERS", "HEIGHTS", "BACKNESS")
