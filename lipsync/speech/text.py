"""Transcript normalisation: the words a speaker says, as dictionary words.

A transcript as people write it ("Dr. Smith paid $5 in 1999 -- well-known!") becomes the
list of lowercase words the pronouncing dictionary knows (``doctor smith paid five in
nineteen ninety-nine well known``): Unicode folded to ASCII letters, punctuation dropped,
numbers spelled out (num2words), hyphens split, apostrophes kept only inside words.

Examples
--------
>>> normalise_transcript("Hello, World! It's 2 o'clock in 1999.")
['hello', 'world', "it's", 'two', "o'clock", 'in', 'nineteen', 'ninety', 'nine']
"""

from __future__ import annotations

import re
import unicodedata
from typing import List

__all__ = ["normalise_transcript", "number_words"]

# Typographic quotes and dashes people paste from word processors, folded to ASCII first so
# the rules below see one apostrophe and one hyphen.
_FOLD = str.maketrans({"\u2019": "'", "\u2018": "'", "\u02bc": "'", "\u00b4": "'", "`": "'",
                       "\u201c": '"', "\u201d": '"', "\u2010": "-", "\u2011": "-", "\u2012": "-",
                       "\u2013": "-", "\u2014": "-", "\u2212": "-"})

# Symbols that are spoken (the rest is punctuation and is dropped).
_SPOKEN_SYMBOLS = {"&": "and", "%": "percent", "+": "plus", "@": "at", "=": "equals"}

# Abbreviations whose written form is never what is said; only unambiguous ones ("St." can be
# saint or street, so it is left to the dictionary).
_ABBREVIATIONS = {"mr": "mister", "mrs": "missus", "dr": "doctor", "vs": "versus", "etc": "etcetera",
                  "prof": "professor", "approx": "approximately"}

# A number: digits with optional thousands commas and decimals, an optional ordinal suffix.
_TOKEN = re.compile(r"""
    (?P<num>\d{1,3}(?:,\d{3})+(?:\.\d+)?|\d+(?:\.\d+)?)(?P<ord>st|nd|rd|th)?(?![A-Za-z])
  | (?P<word>[A-Za-z](?:[A-Za-z']*[A-Za-z])?'?)
  | (?P<sym>[&%+@=])
""", re.X | re.I)

# Four-digit numbers in this range are read as years ("nineteen ninety-nine"), as speakers
# say them; 2000-2009 are said as cardinals ("two thousand five") and num2words' year form
# would say the same, so the range needs no hole.
_YEARS = range(1100, 2100)


def number_words(text: str, ordinal: bool = False) -> List[str]:
    """Spoken words of a number written in digits.

    Parameters
    ----------
    text : str
        Digits, optionally with thousands commas and a decimal part (``"1,250"``, ``"3.5"``).
    ordinal : bool
        Say it as an ordinal (``"21"`` -> twenty-first).

    Returns
    -------
    list of str
        Lowercase words (hyphenated numbers split).

    Examples
    --------
    >>> number_words("1999"), number_words("21", ordinal=True), number_words("3.5")
    (['nineteen', 'ninety', 'nine'], ['twenty', 'first'], ['three', 'point', 'five'])
    """
    from num2words import num2words

    grouped = "," in text
    plain = text.replace(",", "")
    if "." in plain:
        whole, frac = plain.split(".", 1)
        # "3.14" is said digit by digit after the point ("three point one four").
        words = number_words(whole or "0") + ["point"]
        for d in frac:
            words += number_words(d)
        return words
    n = int(plain)
    if ordinal:
        spoken = num2words(n, lang="en", to="ordinal")
    elif n in _YEARS and not grouped and len(plain) == 4:
        spoken = num2words(n, lang="en", to="year")
    elif len(plain) > 1 and plain.startswith("0"):
        # "007", "0800": leading zeros are read as digits.
        return [w for d in plain for w in number_words(d)]
    else:
        spoken = num2words(n, lang="en")
    return re.findall(r"[a-z]+", spoken.lower())


def _ascii_letters(text: str) -> str:
    # é -> e, ß -> ss: decompose and drop combining marks, so names with accents still find
    # their dictionary form (or at least letters the fallback can read).
    text = unicodedata.normalize("NFKD", text.translate(_FOLD))
    text = "".join(c for c in text if not unicodedata.combining(c))
    return text.replace("\u00df", "ss").replace("\u00e6", "ae").replace("\u0153", "oe").replace("\u00f8", "o")


def normalise_transcript(text: str) -> List[str]:
    """The words of a transcript, lowercase, as the pronouncing dictionary spells them.

    Rules (each for a reason): punctuation is not spoken and is dropped; case carries no
    sound; numbers are spelled out (four-digit numbers from 1100 to 2099 as years, ``1st``
    as ordinals, decimals digit by digit after "point"); hyphenated words are separate words
    ("well-known" -> well, known) because the dictionary lists the parts; an apostrophe is
    kept inside a word ("don't", "o'clock") and dropped at its edges (quotes, "James'");
    a few unambiguous abbreviations are expanded ("Dr." -> doctor); ``&``, ``%``, ``+``,
    ``@`` and ``=`` are spoken as words.

    Parameters
    ----------
    text : str
        The transcript as written.

    Returns
    -------
    list of str
        The words in order; empty for a transcript with no words.

    Examples
    --------
    >>> normalise_transcript("Well-known 'quotes' & 50% of the 1st 1,000 -- Dr. O’Neil.")
    ['well', 'known', 'quotes', 'and', 'fifty', 'percent', 'of', 'the', 'first', 'one', 'thousand', 'doctor', "o'neil"]
    >>> normalise_transcript("  ...  ")
    []
    """
    words: List[str] = []
    for m in _TOKEN.finditer(_ascii_letters(text)):
        if m.group("num"):
            words += number_words(m.group("num"), ordinal=bool(m.group("ord")))
        elif m.group("sym"):
            words.append(_SPOKEN_SYMBOLS[m.group("sym")])
        else:
            w = m.group("word").lower().strip("'")
            if w:
                words.append(_ABBREVIATIONS.get(w, w))
    return words
