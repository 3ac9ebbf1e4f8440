"""Pronunciations: CMUdict (as pocketsphinx ships it) first, letter-to-sound rules after.

:func:`pronounce` gives the ARPAbet phones of a word with a stress digit on every vowel.
The dictionary pocketsphinx ships (``cmudict-en-us.dict``, 135k words) has no stress
marks, so stress is *estimated* by :func:`_add_stress` (primary on the first full vowel,
reduced vowels 0): the digits are for readers that expect them (MFA-style TextGrids); no
mouth shape depends on them.

A word the dictionary lacks gets a pronunciation by analogy first (the word covered by the
fewest dictionary words, each at least :data:`_MIN_PIECE` letters: "lipsync" = lip + sync)
and letter-to-sound rules (:data:`_RULES`) for the letters no piece covers. It is never
dropped and never empty when it has a letter; :func:`lookup_missing` lists such words so
callers can warn once.

Examples
--------
>>> pronounce("hello")
('HH', 'AH0', 'L', 'OW1')
>>> pronounce("lipsyncing")[:3]
('L', 'IH1', 'P')
>>> lookup_missing(["hello", "zorbleflax", "hello"])
['zorbleflax']
"""

from __future__ import annotations

import functools
import os
import re
from typing import Dict, Iterable, List, Tuple

from .text import normalise_transcript

__all__ = ["pronounce", "pronunciations", "lookup_missing", "normalise_transcript", "dictionary_path",
           "in_dictionary", "VOWELS"]

#: ARPAbet vowels (the phones that carry a stress digit).
VOWELS = frozenset("AA AE AH AO AW AY EH ER EY IH IY OW OY UH UW".split())

# Vowels that are usually reduced when unstressed; primary stress goes to the first vowel
# not in this set (English words mostly stress a full vowel), else to the first vowel.
_REDUCED = frozenset({"AH", "IH", "ER"})


def dictionary_path() -> str:
    """Path of the CMUdict file pocketsphinx ships.

    Examples
    --------
    >>> os.path.basename(dictionary_path())
    'cmudict-en-us.dict'
    """
    from pocketsphinx import get_model_path

    return os.path.join(get_model_path(), "en-us", "cmudict-en-us.dict")


@functools.lru_cache(maxsize=1)
def _entries() -> Dict[str, List[Tuple[str, Tuple[str, ...]]]]:
    # word -> [(entry name, phones)] in the file's order: "white", then "white(2)" ...
    entries: Dict[str, List[Tuple[str, Tuple[str, ...]]]] = {}
    with open(dictionary_path(), encoding="utf-8") as f:
        for line in f:
            parts = line.split()
            if len(parts) < 2:
                continue
            entries.setdefault(parts[0].split("(")[0], []).append((parts[0], tuple(parts[1:])))
    return entries


@functools.lru_cache(maxsize=1)
def _dictionary() -> Dict[str, Tuple[str, ...]]:
    # First pronunciation of each word only (the variants: :func:`pronunciations`).
    return {word: variants[0][1] for word, variants in _entries().items()}


def in_dictionary(word: str) -> bool:
    """True if CMUdict has ``word`` (lowercase).

    Examples
    --------
    >>> in_dictionary("hello"), in_dictionary("zorbleflax")
    (True, False)
    """
    return word.lower() in _dictionary()


def _add_stress(phones: Iterable[str]) -> Tuple[str, ...]:
    phones = [p.rstrip("012") for p in phones]
    vowels = [i for i, p in enumerate(phones) if p in VOWELS]
    if not vowels:
        return tuple(phones)
    # A final IY ("city", "happy") is the unstressed happY vowel in all but one-vowel words.
    reduced = [i for i in vowels if phones[i] in _REDUCED
               or (phones[i] == "IY" and i == len(phones) - 1 and len(vowels) > 1)]
    full = [i for i in vowels if i not in reduced]
    primary = full[0] if full else vowels[0]
    out = list(phones)
    for i in vowels:
        if i == primary:
            out[i] = phones[i] + "1"
        elif i in reduced:
            out[i] = phones[i] + "0"
        else:
            out[i] = phones[i] + "2"
    return tuple(out)


# --- letter-to-sound rules ------------------------------------------------------------------
# (letters, phones, where) tried longest first at each position; where is "start", "end" or
# "" (anywhere). English spelling is irregular, so these only aim at a plausible mouth-shape
# sequence for names and coinages the dictionary lacks; a letter no rule knows is skipped.
_RULES: List[Tuple[str, Tuple[str, ...], str]] = [
    ("tion", ("SH", "AH", "N"), ""), ("sion", ("ZH", "AH", "N"), ""), ("ture", ("CH", "ER"), ""),
    ("ough", ("AO",), ""), ("augh", ("AO",), ""), ("eigh", ("EY",), ""), ("igh", ("AY",), ""),
    ("tch", ("CH",), ""), ("sch", ("S", "K"), ""), ("chr", ("K", "R"), ""), ("kn", ("N",), "start"),
    ("wr", ("R",), "start"), ("gh", ("G",), "start"), ("gh", (), ""), ("ph", ("F",), ""),
    ("sh", ("SH",), ""), ("ch", ("CH",), ""), ("th", ("TH",), ""), ("wh", ("W",), ""),
    ("ck", ("K",), ""), ("ng", ("NG",), ""), ("qu", ("K", "W"), ""), ("ee", ("IY",), ""),
    ("ea", ("IY",), ""), ("oo", ("UW",), ""), ("ou", ("AW",), ""), ("ow", ("OW",), ""),
    ("oi", ("OY",), ""), ("oy", ("OY",), ""), ("ai", ("EY",), ""), ("ay", ("EY",), ""),
    ("au", ("AO",), ""), ("aw", ("AO",), ""), ("ei", ("IY",), ""), ("ey", ("IY",), "end"),
    ("ey", ("EY",), ""), ("ie", ("IY",), ""), ("ue", ("UW",), ""), ("ew", ("UW",), ""),
    ("oa", ("OW",), ""), ("er", ("ER",), ""), ("ir", ("ER",), ""), ("ur", ("ER",), ""),
    ("ar", ("AA", "R"), ""), ("or", ("AO", "R"), ""), ("y", ("Y",), "start"), ("y", ("IY",), "end"),
    ("a", ("AE",), ""), ("e", ("EH",), ""), ("i", ("IH",), ""), ("o", ("AA",), ""), ("u", ("AH",), ""),
    ("y", ("IH",), ""), ("b", ("B",), ""), ("c", ("K",), ""), ("d", ("D",), ""), ("f", ("F",), ""),
    ("g", ("G",), ""), ("h", ("HH",), ""), ("j", ("JH",), ""), ("k", ("K",), ""), ("l", ("L",), ""),
    ("m", ("M",), ""), ("n", ("N",), ""), ("p", ("P",), ""), ("q", ("K",), ""), ("r", ("R",), ""),
    ("s", ("S",), ""), ("t", ("T",), ""), ("v", ("V",), ""), ("w", ("W",), ""), ("x", ("K", "S"), ""),
    ("z", ("Z",), ""),
]
_RULES.sort(key=lambda r: -len(r[0]))
# A vowel letter, one consonant and a final silent e: the vowel says its name ("bake").
_MAGIC_E = {"a": "EY", "e": "IY", "i": "AY", "o": "OW", "u": "UW"}
_SOFT = "eiy"  # c and g are soft before these letters ("city", "gem")


def _letters_to_sound(word: str) -> List[str]:
    w = re.sub(r"[^a-z]", "", word.lower())
    # Double consonants sound once ("ll", "tt").
    w = re.sub(r"([b-df-hj-np-tv-z])\1", r"\1", w)
    # A final consonant + "le" is a syllabic l ("table", "-kle"): AH L.
    if len(w) >= 2 and w.endswith("le") and (len(w) == 2 or w[-3] not in "aeiouy"):
        return _letters_to_sound(w[:-2]) + ["AH", "L"]
    silent_e = len(w) > 2 and w.endswith("e") and w[-2] not in "aeiouy"
    magic = (silent_e and len(w) > 3 and w[-3] in _MAGIC_E and w[-4] not in "aeiou")
    body = w[:-1] if silent_e else w
    phones: List[str] = []
    i = 0
    while i < len(body):
        if magic and i == len(body) - 2:
            phones.append(_MAGIC_E[body[i]])
            i += 1
            continue
        ch = body[i]
        if ch in "cg" and i + 1 < len(w) and w[i + 1] in _SOFT:
            phones.append("S" if ch == "c" else "JH")
            i += 1
            continue
        for letters, out, where in _RULES:
            if not body.startswith(letters, i):
                continue
            if where == "start" and i != 0 or where == "end" and i + len(letters) != len(body):
                continue
            phones.extend(out)
            i += len(letters)
            break
        else:
            i += 1
    return phones


# Dictionary pieces shorter than this are not used for analogy: two-letter entries
# ("ab", "co") would turn any word into a string of abbreviations.
_MIN_PIECE = 3
# The cost of a letter read by rules, against 1 per dictionary piece: a piece of three or more
# letters always beats reading them by rule.
_RULE_LETTER_COST = 0.6


# Longer "words" (a run of letters pasted without spaces) are read by the rules alone: the
# analogy search looks up every substring, so its cost grows with the square of the length.
_MAX_ANALOGY_LETTERS = 40


def _by_analogy(word: str) -> List[str]:
    d = _dictionary()
    w = re.sub(r"[^a-z']", "", word.lower())
    n = len(w)
    if n > _MAX_ANALOGY_LETTERS:
        return _letters_to_sound(w)
    best = [0.0] + [float("inf")] * n
    back: List[Tuple[int, bool]] = [(0, False)] * (n + 1)
    for i in range(1, n + 1):
        if best[i - 1] + _RULE_LETTER_COST < best[i]:
            best[i], back[i] = best[i - 1] + _RULE_LETTER_COST, (i - 1, False)
        for j in range(0, i - _MIN_PIECE + 1):
            if best[j] + 1 < best[i] and w[j:i] in d:
                best[i], back[i] = best[j] + 1, (j, True)
    pieces: List[Tuple[str, bool]] = []
    i = n
    while i > 0:
        j, is_word = back[i]
        if not is_word and pieces and not pieces[-1][1]:
            pieces[-1] = (w[j:i] + pieces[-1][0], False)
        else:
            pieces.append((w[j:i], is_word))
        i = j
    phones: List[str] = []
    for text, is_word in reversed(pieces):
        phones += list(d[text]) if is_word else _letters_to_sound(text)
    return phones


@functools.lru_cache(maxsize=65536)
def pronounce(word: str) -> Tuple[str, ...]:
    """ARPAbet phones of a word, with (estimated) stress digits on the vowels.

    Parameters
    ----------
    word : str
        One word, as :func:`normalise_transcript` gives it (case is ignored).

    Returns
    -------
    tuple of str
        CMUdict's first pronunciation; for a word it lacks, one made by analogy with
        dictionary words and letter-to-sound rules. Empty only if ``word`` has no letters.

    Examples
    --------
    >>> pronounce("Balloons")
    ('B', 'AH0', 'L', 'UW1', 'N', 'Z')
    >>> pronounce("snarkle")  # not in CMUdict: "snark" + letter-to-sound "le"
    ('S', 'N', 'AA1', 'R', 'K', 'AH0', 'L')
    """
    w = word.lower()
    phones = _dictionary().get(w)
    if phones is None:
        phones = tuple(_by_analogy(w))
        if not phones and re.search(r"[a-z]", w):
            # Letters no rule reads still make a sound; a neutral vowel keeps the word timed.
            phones = ("AH",)
    return _add_stress(phones)


# Letter names as most English speakers outside the US say them, which CMUdict (American)
# lacks. Spelled letters are common in dictated codes and in the GRID corpus (British
# speakers): without these the aligner must fit "ar" or "zed" to AA R or Z IY.
_EXTRA_VARIANTS: Dict[str, Tuple[Tuple[str, ...], ...]] = {
    "r": (("AA",),),            # non-rhotic accents (England, Wales, Australia, NZ, South Africa)
    "z": (("Z", "EH", "D"),),   # "zed": everywhere but the US
}


def _is_wh_variant(phones: Tuple[str, ...], others: Iterable[Tuple[str, ...]]) -> bool:
    # "white(2)" = HH W AY T beside W AY T: "wh" said with a breath, a fading US regional
    # form. Offered to the aligner it takes a breath's length from the previous word's end
    # (measured on the GRID sentences: 60 ms of "lay" given to the HH of "white").
    return phones[:2] == ("HH", "W") and any(o == phones[1:] for o in others)


@functools.lru_cache(maxsize=65536)
def pronunciations(word: str) -> Tuple[Tuple[str, Tuple[str, ...]], ...]:
    """Every pronunciation the aligner may choose for ``word``: (dictionary entry name, phones).

    CMUdict's variants in its order ("with" = W IH DH, "with(2)" = W IH TH), without the
    ones that only add a breath before "wh" (HH W); for spelled letters also the names
    English speakers outside the US say ("r" = AA, "z" = Z EH D), named after CMUdict's
    own entries ("r(2)"). A word CMUdict lacks has one: :func:`pronounce`'s. Phones carry
    no stress digits (the aligner's dictionary has none).

    Parameters
    ----------
    word : str
        One normalised word (case is ignored).

    Returns
    -------
    tuple of (str, tuple of str)
        Entry names (``word`` first) and their phones; empty if ``word`` has no letters.

    Examples
    --------
    >>> [name for name, _ in pronunciations("white")]     # HH W AY T is left out
    ['white']
    >>> pronunciations("z")
    (('z', ('Z', 'IY')), ('z(2)', ('Z', 'EH', 'D')))
    >>> pronunciations("a")
    (('a', ('AH',)), ('a(2)', ('EY',)))
    """
    w = word.lower()
    entries = _entries().get(w)
    if entries is None:
        phones = tuple(p.rstrip("012") for p in pronounce(w))
        return ((w, phones),) if phones else ()
    all_phones = [phones for _, phones in entries]
    out = [(name, phones) for name, phones in entries if not _is_wh_variant(phones, all_phones)]
    for k, phones in enumerate(_EXTRA_VARIANTS.get(w, ()), len(entries) + 1):
        if phones not in all_phones:
            out.append((f"{w}({k})", phones))
    return tuple(out)


def lookup_missing(words: Iterable[str]) -> List[str]:
    """The distinct words (in first-seen order) that CMUdict lacks and the fallback pronounces.

    Examples
    --------
    >>> lookup_missing(["the", "Qwzx", "the", "qwzx"])
    ['qwzx']
    """
    d = _dictionary()
    seen: Dict[str, None] = {}
    for word in words:
        w = word.lower()
        if w not in d and w not in seen:
            seen[w] = None
    return list(seen)
