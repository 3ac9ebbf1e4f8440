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
from typing import List, Optional

__all__ = ["normalise_transcript", "number_words", "not_a_transcript", "looks_like_path", "shown_words",
           "MAX_TRANSCRIPT_CHARS"]

#: Longest transcript accepted (``--text``, a NAME.txt beside a video, the API's ``text=``),
#: in characters. A long real script fits: a 90-minute film's dialogue is 12-15 thousand
#: words (~80,000 characters), an hour of audiobook ~9,000 words; past that the aligner's
#: memory grows with the words (issue 38: 1 MB took 2.7 GB, 10 MB over 5.9 GB) for speech
#: nobody renders in one clip. ``lipsync serve`` keeps its own, smaller cap (20,000).
MAX_TRANSCRIPT_CHARS = 100_000

#: Words a message names at most, and characters of each: a transcript's words are echoed
#: in warnings, and one 10 MB "word" must not become a 10 MB warning.
SHOWN_WORDS = 8
SHOWN_WORD_CHARS = 40


def shown_words(words, limit: int = SHOWN_WORDS, width: int = SHOWN_WORD_CHARS) -> str:
    """Words for a message: the first ``limit``, each cut to ``width`` characters, and how many more.

    Examples
    --------
    >>> shown_words(["a", "b" * 50, "c"], limit=2, width=5)
    'a, bbbb… and 1 more'
    """
    words = list(words)
    cut = [w if len(w) <= width else w[:width - 1] + "\u2026" for w in words[:limit]]
    more = f" and {len(words) - limit} more" if len(words) > limit else ""
    return ", ".join(cut) + more

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
# Longer whole numbers are read digit by digit (credit card, phone and serial numbers).
_MAX_SPOKEN_DIGITS = 15


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
    if len(plain.split(".")[0]) > _MAX_SPOKEN_DIGITS:
        # Nobody says a 30-digit number as one (num2words stops at 10**300): digit by digit.
        return [w for d in plain if d != "." for w in number_words(d)]
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


# --- what a --text value is -------------------------------------------------------------------

# Files people pass as a transcript by mistake, each recognised by how it starts or by every
# line's shape, with what to say. Their numbers and markup would otherwise be read as words
# (an Audacity label track of samples/hello.lab's sentence read as 539 "words").
_TIMED_LINE = re.compile(r"^\s*[-+]?\d+(?:\.\d+)?(?:\t|\s+[-+]?\d+(?:\.\d+)?(?:\s|$))")
_NOT_TRANSCRIPTS = (
    # (test on the text's start, stripped, case-folded; what the file looks like)
    (lambda t: t.startswith('file type = "ootextfile"') or t.startswith("file type = \"ootextfile\""),
     "a Praat TextGrid (a timeline: give it as the input, not as --text)"),
    (lambda t: t.startswith("lipsync version"), "a Papagayo project (.pgo; a timeline, not a transcript)"),
    (lambda t: t.startswith("mohoswitch"), "Moho switch data (.dat; a timeline, not a transcript)"),
    (lambda t: t.startswith("webvtt") , "WebVTT subtitles (give the words alone)"),
    (lambda t: t.startswith("<?xml") or t.startswith("<"), "XML or HTML markup (give the words alone)"),
    (lambda t: t.startswith("{") or t.startswith("["), "JSON (a timeline or word timings: give it as the "
                                                       "input, or the words alone as --text)"),
)


def not_a_transcript(text: str) -> Optional[str]:
    r"""What ``text`` (a file's contents) looks like when it is not a transcript, else None.

    Label tracks, TextGrids, JSON, XML, Papagayo and Moho files, subtitles and binary data
    are refused by ``--text`` rather than read as words.

    Examples
    --------
    >>> not_a_transcript("Hello, I am a talking head.") is None
    True
    >>> not_a_transcript("0.000000\t0.300000\thello\n0.300000\t0.600000\tthere\n")
    'an Audacity label track or other timed lines (start and end times before each label: a timeline, not a transcript)'
    >>> not_a_transcript('{"words": []}')
    'JSON (a timeline or word timings: give it as the input, or the words alone as --text)'
    """
    if "\0" in text:
        return "binary data, not text"
    head = text.lstrip("\ufeff \t\r\n")[:64].casefold()
    for test, what in _NOT_TRANSCRIPTS:
        if test(head):
            return what
    lines = [line for line in text.splitlines() if line.strip()]
    if lines and all(_TIMED_LINE.match(line) for line in lines) and (len(lines) > 1 or "\t" in lines[0]):
        return ("an Audacity label track or other timed lines (start and end times before each label: "
                "a timeline, not a transcript)")
    if any("-->" in line for line in lines[:4]) and any(_TIMED_LINE.match(line) for line in lines[:4]):
        return "SRT subtitles (give the words alone)"
    return None


# A --text value that names a file rather than saying words: one token with a folder part or
# a file extension people keep transcripts (or mistake for them) in.
_PATH_PREFIXES = ("/", "./", "../", "~/", ".\\", "..\\")
_TEXT_EXTENSIONS = {"txt", "lab", "text", "textgrid", "json", "srt", "vtt", "csv", "tsv", "md", "xml",
                    "pgo", "dat", "phn", "rtf", "doc", "docx", "odt", "wav", "mp3", "mp4"}
_EXTENSION = re.compile(r"\.([A-Za-z0-9]{1,9})$")


def looks_like_path(value: str) -> bool:
    """Whether a ``--text`` value is meant as a file name (so a missing one is an error).

    Examples
    --------
    >>> looks_like_path("media/missing.txt"), looks_like_path("hello.lab"), looks_like_path("./script")
    (True, True, True)
    >>> looks_like_path("Hello there."), looks_like_path("and/or"), looks_like_path("e.g.")
    (False, False, False)
    """
    if not value or any(c.isspace() for c in value):
        return False
    if value.startswith(_PATH_PREFIXES):
        return True
    ext = _EXTENSION.search(value)
    return bool(ext) and (ext.group(1).lower() in _TEXT_EXTENSIONS or "/" in value or "\\" in value)
