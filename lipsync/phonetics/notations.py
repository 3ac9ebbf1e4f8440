"""Other phone notations into IPA: ARPAbet, TIMIT, X-SAMPA, pinyin, espeak-ng, MFA.

:func:`to_ipa` turns one label of a notation into IPA (a string :func:`parse` reads);
:func:`detect` guesses a timeline's notation from its labels, because one label alone can
be ambiguous: ``y`` is a glide in ARPAbet/TIMIT and a rounded vowel in IPA, ``r`` English r
or a trill, ``q`` TIMIT's glottal stop or IPA's uvular stop, and pinyin ``j q x zh`` are
sounds of their own.

Examples
--------
>>> to_ipa("AY1", "arpabet"), to_ipa("axr", "timit"), to_ipa('"s{n', "xsampa")
('aɪ', 'ɚ', 'ˈsæn')
>>> to_ipa("uang3", "pinyin"), to_ipa("zh", "pinyin"), to_ipa("iii4", "pinyin")
('wɑŋ', 'ʈʂ', 'ʅ')
>>> detect(["sil", "b", "ɔ̃", "ʒ", "u", "ʁ"]), detect(["HH", "AH0", "L", "OW1"]), detect(["j", "ing1", "g", "uang3"])
('ipa', 'english', 'pinyin')
"""

from __future__ import annotations

import re
import unicodedata
from typing import Dict, Iterable, Optional

from .segments import parse, parse_sequence

NOTATIONS = ("ipa", "english", "arpabet", "timit", "xsampa", "pinyin", "espeak", "mfa")

# --- ARPAbet (CMUdict's 39 phones) and TIMIT's 61 labels ----------------------------------
# IPA of each ARPAbet phone in General American, as CMUdict's documentation gives it.
ARPABET: Dict[str, str] = {
    "AA": "ɑ", "AE": "æ", "AH": "ʌ", "AO": "ɔ", "AW": "aʊ", "AY": "aɪ", "EH": "ɛ", "ER": "ɝ", "EY": "eɪ",
    "IH": "ɪ", "IY": "i", "OW": "oʊ", "OY": "ɔɪ", "UH": "ʊ", "UW": "u",
    "B": "b", "CH": "tʃ", "D": "d", "DH": "ð", "F": "f", "G": "ɡ", "HH": "h", "JH": "dʒ", "K": "k", "L": "l",
    "M": "m", "N": "n", "NG": "ŋ", "P": "p", "R": "ɹ", "S": "s", "SH": "ʃ", "T": "t", "TH": "θ", "V": "v",
    "W": "w", "Y": "j", "Z": "z", "ZH": "ʒ",
}
# The phones that carry CMUdict's stress digits (AH0, OW1).
ARPABET_VOWELS = frozenset({"AA", "AE", "AH", "AO", "AW", "AY", "EH", "ER", "EY", "IH", "IY", "OW", "OY", "UH", "UW"})

# TIMIT's labels beyond ARPAbet's (TIMIT phonetic transcription conventions, phoncode.doc).
# Closures are the stop's own articulation held (bcl: the lips already closed for b).
TIMIT: Dict[str, str] = {
    "ax": "ə", "ax-h": "ə̥", "axr": "ɚ", "ix": "ɨ", "ux": "ʉ", "el": "l̩", "em": "m̩", "en": "n̩",
    "eng": "ŋ̍", "nx": "ɾ̃", "dx": "ɾ", "hv": "ɦ", "q": "ʔ",
    "bcl": "b", "dcl": "d", "gcl": "ɡ", "pcl": "p", "tcl": "t", "kcl": "k",
}
TIMIT_SILENCE = frozenset({"h#", "pau", "epi"})

# --- X-SAMPA (Wells 1995), longest symbols first ------------------------------------------
XSAMPA: Dict[str, str] = {
    # Letters
    "b_<": "ɓ", "d_<": "ɗ", "g_<": "ɠ", "G\\_<": "ʛ", "J\\_<": "ʄ",
    "r\\`": "ɻ", "||\\": "ǁ",
    "d`": "ɖ", "l`": "ɭ", "n`": "ɳ", "r`": "ɽ", "s`": "ʂ", "t`": "ʈ", "z`": "ʐ",
    "@\\": "ɘ", "3\\": "ɞ", "?\\": "ʕ", "<\\": "ʢ", ">\\": "ʡ", "!\\": "ǃ", "|\\": "ǀ", "=\\": "ǂ",
    "B\\": "ʙ", "G\\": "ɢ", "H\\": "ʜ", "I\\": "ᵻ", "J\\": "ɟ", "K\\": "ɮ", "L\\": "ʟ", "M\\": "ɰ",
    "N\\": "ɴ", "O\\": "ʘ", "R\\": "ʀ", "U\\": "ᵿ", "X\\": "ħ", "h\\": "ɦ", "j\\": "ʝ", "l\\": "ɺ",
    "p\\": "ɸ", "r\\": "ɹ", "s\\": "ɕ", "v\\": "ʋ", "x\\": "ɧ", "z\\": "ʑ", "-\\": "‿",
    "A": "ɑ", "B": "β", "C": "ç", "D": "ð", "E": "ɛ", "F": "ɱ", "G": "ɣ", "H": "ɥ", "I": "ɪ", "J": "ɲ",
    "K": "ɬ", "L": "ʎ", "M": "ɯ", "N": "ŋ", "O": "ɔ", "P": "ʋ", "Q": "ɒ", "R": "ʁ", "S": "ʃ", "T": "θ",
    "U": "ʊ", "V": "ʌ", "W": "ʍ", "X": "χ", "Y": "ʏ", "Z": "ʒ",
    "@": "ə", "{": "æ", "}": "ʉ", "1": "ɨ", "2": "ø", "3": "ɜ", "4": "ɾ", "5": "ɫ", "6": "ɐ", "7": "ɤ",
    "8": "ɵ", "9": "œ", "&": "ɶ", "?": "ʔ", "g": "ɡ",
    # Diacritics and suprasegmentals
    "_h": "ʰ", "_j": "ʲ", "_w": "ʷ", "_G": "ˠ", "_?\\": "ˤ", "_~": "\u0303", "~": "\u0303", "_0": "\u0325",
    "_v": "\u032c", "_=": "\u0329", "=": "\u0329", "_^": "\u032f", "_t": "\u0324", "_k": "\u0330",
    "_d": "\u032a", "_a": "\u033a", "_m": "\u033b", "_+": "\u031f", "_-": "\u0320", '_"': "\u0308",
    "_x": "\u033d", "_r": "\u031d", "_o": "\u031e", "_A": "\u0318", "_q": "\u0319", "_O": "\u0339",
    "_c": "\u031c", "_N": "\u033c", "_}": "\u031a", "_n": "ⁿ", "_l": "ˡ", "_e": "\u0334", "_>": "ʼ",
    "`": "\u02de", "'": "ʲ", ":\\": "ˑ", ":": "ː", '"': "ˈ", "%": "ˌ", ".": ".",
    "_T": "˥", "_H": "˦", "_M": "˧", "_L": "˨", "_B": "˩", "_": "\u0361",
}
_XSAMPA_KEYS = sorted(XSAMPA, key=len, reverse=True)

# --- pinyin (Hanyu Pinyin, as AISHELL-3's and MFA's Mandarin phone tiers write it) --------
# Initials, and finals with their tone digit 1-5 after them. IPA after Duanmu, "The
# Phonology of Standard Chinese" (2007), broad transcription.
PINYIN_INITIALS: Dict[str, str] = {
    "b": "p", "p": "pʰ", "m": "m", "f": "f", "d": "t", "t": "tʰ", "n": "n", "l": "l",
    "g": "k", "k": "kʰ", "h": "x", "j": "tɕ", "q": "tɕʰ", "x": "ɕ",
    "zh": "ʈʂ", "ch": "ʈʂʰ", "sh": "ʂ", "r": "ʐ", "z": "ts", "c": "tsʰ", "s": "s", "y": "j", "w": "w",
}
PINYIN_FINALS: Dict[str, str] = {
    "a": "a", "o": "o", "e": "ɤ", "ê": "ɛ", "ai": "aɪ", "ei": "eɪ", "ao": "ɑʊ", "ou": "oʊ",
    "an": "an", "en": "ən", "ang": "ɑŋ", "eng": "əŋ", "ong": "ʊŋ", "er": "ɚ",
    "i": "i", "ia": "ja", "ie": "jɛ", "iao": "jɑʊ", "iu": "joʊ", "iou": "joʊ", "ian": "jɛn", "in": "in",
    "iang": "jɑŋ", "ing": "iŋ", "iong": "jʊŋ",
    "u": "u", "ua": "wa", "uo": "wo", "uai": "waɪ", "ui": "weɪ", "uei": "weɪ", "uan": "wan", "un": "wən",
    "uen": "wən", "uang": "wɑŋ", "ueng": "wəŋ",
    "ü": "y", "v": "y", "üe": "ɥɛ", "ve": "ɥɛ", "ue": "ɥɛ", "üan": "ɥɛn", "van": "ɥɛn", "ün": "yn", "vn": "yn",
    "ii": "ɿ", "iii": "ʅ",  # AISHELL-3 / MFA: the apical vowels of zi ci si and zhi chi shi ri
    "ir": "ʅ", "iz": "ɿ",
    # MFA's pinyin dictionary splits a final's nasal coda off (ian = ia + n, üan = va + n):
    "io": "jo", "va": "ɥɛ", "ng": "ŋ",
}
_PINYIN_FINAL_TONE = re.compile(r"^([a-zêüv]+?)([1-5])$")

# --- espeak-ng: its IPA output and its mnemonics -------------------------------------------
# `espeak-ng -q --ipa` writes IPA, but a phoneme whose table gives no IPA is printed as its
# ASCII mnemonic pushed through a character table, so its output also carries espeak's own
# marks: Mandarin's "ts.h" (retroflex, aspirated), "i." (apical vowel), "n^" (palatal),
# "t`" (retroflex), "d[" (dental), "l#" (a variant), tone digits, "(en)" language switches.
# Rows apply in order: (pattern, replacement, the mark's meaning in espeak-ng's phoneme files).
ESPEAK_MARKS = (
    (r"\([a-z-]+\)", "", "a language switch: (en) ... (cmn)"),
    (r"[ˈˌ',%=]", "", "stress"),
    (r"ts\.", "ʈʂ", "retroflex affricate (cmn zh)"),
    (r"dz\.", "ɖʐ", "voiced retroflex affricate"),
    (r"s\.", "ʂ", "retroflex fricative (cmn sh)"),
    (r"z\.", "ʐ", "voiced retroflex fricative (cmn r)"),
    (r"i\.", "ʅ", "the apical vowel after zh ch sh r (cmn shi)"),
    (r"r\.", "ɻ", "retroflex approximant"),
    (r"n\.", "ɳ", "retroflex nasal"),
    (r"l\.", "ɭ", "retroflex lateral"),
    (r"t\.", "ʈ", "retroflex stop"),
    (r"d\.", "ɖ", "voiced retroflex stop"),
    (r"^h([ptkcsʃɕʂθfx])", r"\1", "a leading h on a voiceless consonant: preaspiration (my hs, ht)"),
    (r"([ptkcqbdɡgʈɖɟ]|ts|dz|tɕ|tʃ|ʈʂ|tɬ)h", r"\1ʰ", "h after a stop: aspiration (cmn ph th kh tsh tɕh)"),
    (r"_h", "ʰ", "aspiration"),
    (r"n\^", "ɲ", "palatal nasal"),
    (r"l\^", "ʎ", "palatal lateral"),
    (r"\^", "ʲ", "palatalised"),
    (r"t`", "ʈ", "retroflex"), (r"d`", "ɖ", "retroflex"), (r"n`", "ɳ", "retroflex"), (r"s`", "ʂ", "retroflex"),
    (r"z`", "ʐ", "retroflex"), (r"l`", "ɭ", "retroflex"), (r"r`", "ɽ", "retroflex"),
    (r"([aeiouyæɑɒɔəɛɜɪʊʌø])`", "\\1\u02de", "r-coloured vowel"),
    (r"`", "", "retroflex on a letter without a retroflex form (p` k` q`): the letter itself"),
    (r"\[", "\u032a", "dental"),
    (r'"', "\u0308", "centralised (ru, mi u\")"),
    (r"\?", "ʔ", "glottal stop"),
    (r"ε", "ɛ", "Greek epsilon (da)"),
    (r"Φ", "ɸ", "Greek capital phi: espeak's character for the bilabial fricative (smj, om)"),
    (r"[-#+_.|!]", "", "variants, syllable and word boundaries"),
)
# ASCII letters left after the marks, in a word with IPA letters: espeak's character table
# for mnemonics (dictionary.c, ipa1[]): A is ɑ, N ŋ, S ʃ, ... ; digits there are tones.
ESPEAK_ASCII: Dict[str, str] = {
    "A": "ɑ", "B": "β", "C": "ç", "D": "ð", "E": "ɛ", "G": "ɢ", "H": "ħ", "I": "ɪ", "J": "ɟ", "K": "ɬ",
    "L": "ɫ", "M": "ɱ", "N": "ŋ", "O": "ɔ", "P": "ɸ", "Q": "ɣ", "R": "ʀ", "S": "ʃ", "T": "θ", "U": "ʊ",
    "V": "ʌ", "W": "œ", "X": "χ", "Y": "ø", "Z": "ʒ", "&": "æ", "@": "ə", "*": "ɾ", "g": "ɡ", "~": "\u0303",
    ":": "ː", ";": "ʲ",
}
# The same table's digits, which only an all-ASCII word (espeak-ng -x) uses as letters.
_ESPEAK_DIGITS = {"0": "ɒ", "3": "ɜ", "8": "ɵ"}
_SUPERSCRIPT_BASE = {"ⁿ": "n", "ᵐ": "m", "ᵑ": "ŋ", "ʰ": "h", "ʲ": "j", "ʷ": "w", "ᶮ": "ɲ"}
_ESPEAK_RES = tuple((re.compile(p), r) for p, r, _ in ESPEAK_MARKS)


def _longest_match(text: str, table: Dict[str, str], keys) -> Optional[str]:
    out, i = [], 0
    while i < len(text):
        for k in keys:
            if text.startswith(k, i):
                out.append(table[k])
                i += len(k)
                break
        else:
            return None
    return "".join(out)


def xsampa_to_ipa(label: str) -> Optional[str]:
    """One X-SAMPA string -> IPA; None if a character is not X-SAMPA.

    Examples
    --------
    >>> xsampa_to_ipa("t_hOI"), xsampa_to_ipa("r\\\\`"), xsampa_to_ipa("9~"), xsampa_to_ipa("p_>")
    ('tʰɔɪ', 'ɻ', 'œ̃', 'pʼ')
    """
    lowers = {c: c for c in "abcdefhijklmnopqrstuvwxyz"}
    table = {**lowers, **XSAMPA}
    keys = sorted(table, key=len, reverse=True)
    return _longest_match(label.strip(), table, keys)


def pinyin_to_ipa(label: str) -> Optional[str]:
    """A pinyin initial, final (tone digit optional) or whole syllable -> IPA; None if not pinyin.

    The tone is dropped (it does not shape the mouth). ``i`` after z c s and zh ch sh r is
    the apical vowel, ``u`` after j q x y is ü.

    Examples
    --------
    >>> pinyin_to_ipa("j"), pinyin_to_ipa("ing1"), pinyin_to_ipa("zhong1"), pinyin_to_ipa("shi4"), pinyin_to_ipa("xue2")
    ('tɕ', 'iŋ', 'ʈʂʊŋ', 'ʂʅ', 'ɕɥɛ')
    """
    text = unicodedata.normalize("NFC", label.strip().lower())
    m = _PINYIN_FINAL_TONE.match(text)
    if m:
        text = m.group(1)
    if not text:
        return None
    if text in PINYIN_FINALS and not (text in PINYIN_INITIALS and not m):
        return PINYIN_FINALS[text]
    if text in PINYIN_INITIALS:
        return PINYIN_INITIALS[text]
    for n in (2, 1):  # a whole syllable: initial + final
        ini, fin = text[:n], text[n:]
        if ini in PINYIN_INITIALS and fin:
            if fin == "i" and ini in ("z", "c", "s"):
                return PINYIN_INITIALS[ini] + "ɿ"
            if fin == "i" and ini in ("zh", "ch", "sh", "r"):
                return PINYIN_INITIALS[ini] + "ʅ"
            if ini in ("j", "q", "x", "y") and fin.startswith("u"):
                fin = "ü" + fin[1:]
            if ini in ("y", "w"):  # yi, wu, yu: the glide letter only spells the vowel
                if fin in ("i", "in", "ing", "ü", "üe", "üan", "ün", "u"):
                    return PINYIN_FINALS.get(fin if ini == "y" or fin != "u" else "u")
                if ini == "y" and "i" + fin in PINYIN_FINALS:  # ye yan yang yao you yong: the i- finals
                    return PINYIN_FINALS["i" + fin]
            if fin in PINYIN_FINALS:
                return PINYIN_INITIALS[ini] + PINYIN_FINALS[fin]
    return None


def espeak_to_ipa(label: str) -> Optional[str]:
    """espeak-ng output -> IPA: its ``--ipa`` words (with espeak's own marks) or ``-x`` mnemonics.

    Stress, boundaries, tone digits and language switches such as ``(en)`` are dropped; a
    letter written twice (espeak-ng's long vowels ``aa``) is one long letter.

    Examples
    --------
    >>> espeak_to_ipa("bO~Z'ur"), espeak_to_ipa("hˌaʊ"), espeak_to_ipa("hˈεlʔo")
    ('bɔ̃ʒur', 'haʊ', 'hɛlʔo')
    >>> espeak_to_ipa("ts.h"), espeak_to_ipa("s.ˈi.5"), espeak_to_ipa("n^"), espeak_to_ipa("aa"), espeak_to_ipa("ᵐ")
    ('ʈʂʰ', 'ʂʅ', 'ɲ', 'aː', 'm')
    """
    text = unicodedata.normalize("NFC", label.strip())
    if text in _SUPERSCRIPT_BASE:
        return _SUPERSCRIPT_BASE[text]
    mnemonic = text.isascii()
    for pattern, repl in _ESPEAK_RES:
        text = pattern.sub(repl, text)
    out = []
    for ch in text:
        if ch.isdigit():
            if mnemonic and ch in _ESPEAK_DIGITS:
                out.append(_ESPEAK_DIGITS[ch])
            continue  # a tone (IPA output) or a variant number (iz2)
        out.append(ESPEAK_ASCII.get(ch, ch))
    text = "".join(out).lstrip("ʰˀ")  # preaspiration, preglottalisation: the letter after is the sound
    if text and text[0] in _SUPERSCRIPT_BASE:  # prenasalised: ⁿd is n + d
        text = _SUPERSCRIPT_BASE[text[0]] + text[1:]
    half = len(text) // 2
    if half and len(text) % 2 == 0 and text[:half] == text[half:]:
        text = text[:half] + "ː" if half == 1 else text[:half]  # aa -> aː; əiəi -> əi
    text = re.sub(r"(\w)\1", "\\1ː", text)
    return text if text and parse_sequence(text) is not None else None


def arpabet_to_ipa(label: str) -> Optional[str]:
    """ARPAbet (stress digit optional, any case) or TIMIT -> IPA; None if neither.

    Examples
    --------
    >>> arpabet_to_ipa("ow1"), arpabet_to_ipa("dcl"), arpabet_to_ipa("h#")
    ('oʊ', 'd', '')
    """
    text = label.strip()
    if text.lower() in TIMIT_SILENCE:
        return ""
    if text.lower() in TIMIT:
        return TIMIT[text.lower()]
    up = text.upper()
    if len(up) > 1 and up[-1] in "012" and up[:-1] in ARPABET_VOWELS:
        up = up[:-1]
    return ARPABET.get(up)


# MFA's own spellings that are not plain IPA letters (its dictionaries' phone sets).
MFA: Dict[str, str] = {
    "g": "ɡ",      # some MFA 1.x dictionaries wrote the ASCII letter
}


def mfa_to_ipa(label: str) -> Optional[str]:
    """An MFA phone (any of its languages' IPA phone sets) -> IPA; None if not a phone.

    MFA's phone sets are IPA with ties left out (``tʃ``, ``ts``, ``ʈʂ``), tone letters on
    Mandarin/Vietnamese/Thai vowels (``a˥˩``), length ``ː`` and diacritics; all of it is read
    by :func:`~lipsync.phonetics.segments.parse` directly.

    Examples
    --------
    >>> mfa_to_ipa("ʈʂʰ"), mfa_to_ipa("a˥˩"), mfa_to_ipa("spn")
    ('ʈʂʰ', 'a˥˩', None)
    """
    text = MFA.get(label.strip(), label.strip())
    return text if parse(text) is not None else None


_CONVERTERS = {
    "arpabet": arpabet_to_ipa, "english": arpabet_to_ipa, "timit": arpabet_to_ipa, "xsampa": xsampa_to_ipa,
    "pinyin": pinyin_to_ipa, "espeak": espeak_to_ipa, "mfa": mfa_to_ipa,
    "ipa": lambda s: s.strip() if parse_sequence(s) is not None else None,
}


def to_ipa(label: str, notation: str = "ipa") -> Optional[str]:
    """One label of ``notation`` -> IPA, ``""`` for silence, None if not a phone of it.

    Parameters
    ----------
    label : str
    notation : str
        One of :data:`NOTATIONS` (``english`` means ARPAbet or TIMIT).

    Examples
    --------
    >>> to_ipa("JH", "arpabet"), to_ipa("J", "xsampa"), to_ipa("j", "pinyin"), to_ipa("j", "ipa")
    ('dʒ', 'ɲ', 'tɕ', 'j')
    """
    try:
        conv = _CONVERTERS[notation]
    except KeyError:
        raise ValueError(f"unknown notation {notation!r}; one of {', '.join(NOTATIONS)}") from None
    return conv(label)


# --- detection ----------------------------------------------------------------------------
_ENGLISH_NAMES = frozenset([k.lower() for k in ARPABET] + list(TIMIT) + ["oov"])
# Labels that mean silence in any of the notations (compared case-insensitively).
SILENCE = frozenset(["", "sil", "sp", "spn", "h#", "pau", "epi", "<sil>", "<eps>", "silence", "#", "-", "_",
                     "[sil]", "[sp]", "<sp>", "sil_b", "sil_e"])


def _english_label(label: str) -> bool:
    low = label.lower()
    if low in _ENGLISH_NAMES:
        return True
    return len(low) > 1 and low[-1] in "012" and low[:-1].upper() in ARPABET_VOWELS


def detect(labels: Iterable[str]) -> str:
    """The notation of a timeline's labels: ``"pinyin"``, ``"ipa"`` or ``"english"``.

    ``pinyin``: two or more distinct lower-case pinyin finals with a tone digit (``ing1``,
    ``ao4``) and no upper-case ARPAbet. ``ipa``: any label outside ARPAbet and TIMIT that
    reads as IPA (``ʁ``, ``a``, ``ts``). Otherwise ``english`` (ARPAbet or TIMIT; also for
    an empty timeline), which is what the English map has always read.

    Examples
    --------
    >>> detect(["Y", "UW1"]), detect(["y", "ʁ"]), detect(["sil", "q", "r"])
    ('english', 'ipa', 'english')
    """
    tone_finals = set()
    ipa = False
    upper_arpabet = False
    for label in set(labels):  # a timeline repeats a few dozen labels thousands of times
        text = label.strip()
        low = text.lower()
        if low in SILENCE:
            continue
        if text != low and _english_label(text):
            upper_arpabet = True
        m = _PINYIN_FINAL_TONE.match(text)
        if m and m.group(1) in PINYIN_FINALS and not _english_label(text):
            tone_finals.add(text)
            continue
        if not ipa and not _english_label(text) and parse(unicodedata.normalize("NFC", text)) is not None:
            ipa = True
    if len(tone_finals) >= 2 and not upper_arpabet:
        return "pinyin"
    return "ipa" if ipa else "english"
