"""What the English aligner can read, and who aligns the rest.

The English aligner (:mod:`.align`) reads Latin letters; a transcript in another script is
refused or its words named (:func:`check_english_script`), never dropped silently. Speech in
other languages is aligned by :mod:`.languages`, which builds on the English aligner's search:
it registers itself in :data:`OTHER_LANGUAGES` (imported with :mod:`lipsync.speech`), so
that the aligner reaches it without importing it (the two would import each other).
"""

from __future__ import annotations

import unicodedata
import warnings
from typing import Dict, Optional, Sequence, Tuple

from ..errors import InputError
from ..registry import Registry

__all__ = ["OTHER_LANGUAGES", "UnreadWordsWarning", "check_english_script", "script_of"]

#: name -> aligner(pcm, text, lang, *, quiet, path, jobs) for languages other than English
#: (:func:`lipsync.speech.languages.align_language` as ``"espeak-ipa"``).
OTHER_LANGUAGES: Registry = Registry("aligner for other languages")


class UnreadWordsWarning(UserWarning):
    """Transcript words the language's letters-to-sounds cannot read were left out."""


#: Scripts named by the first word of their letters' Unicode names, with the language to
#: suggest for each (a user who pastes Cyrillic most likely means Russian; the message says
#: "for example").
_SCRIPTS: Dict[str, Tuple[str, str]] = {
    "CYRILLIC": ("Cyrillic", "ru"), "CJK": ("Chinese (Han)", "zh"), "HIRAGANA": ("Japanese (kana)", "ja"),
    "KATAKANA": ("Japanese (kana)", "ja"), "HANGUL": ("Korean (Hangul)", "ko"), "ARABIC": ("Arabic", "ar"),
    "GREEK": ("Greek", "el"), "DEVANAGARI": ("Devanagari", "hi"), "HEBREW": ("Hebrew", "he"),
    "THAI": ("Thai", "th"), "GEORGIAN": ("Georgian", "ka"), "ARMENIAN": ("Armenian", "hy"),
    "BENGALI": ("Bengali", "bn"), "TAMIL": ("Tamil", "ta"), "ETHIOPIC": ("Ethiopic", "am"),
}


def script_of(word: str) -> Optional[str]:
    """The Unicode script name (first word of the letters' names) of a word's first non-Latin letter.

    Examples
    --------
    >>> script_of("привет"), script_of("héllo"), script_of("经")
    ('CYRILLIC', None, 'CJK')
    """
    for ch in word:
        if unicodedata.category(ch).startswith("L"):
            script = unicodedata.name(ch, "UNKNOWN").split(" ")[0]
            if script != "LATIN":
                return script
    return None


def check_english_script(text: str, words: Sequence[str], *, path: Optional[str] = None) -> None:
    """Refuse or warn about transcript words in scripts the English aligner cannot read.

    The English transcript is folded to Latin letters (:func:`~lipsync.speech.text.normalise_transcript`),
    which drops every word written in another script. A transcript none of whose words
    survive would be silently replaced by recognised English words, so it is refused; a
    few such words among English ones are named in a warning.

    Raises
    ------
    lipsync.errors.InputError
        No word is left: the message names the script and a ``--lang`` to pass.

    Warns
    -----
    UnreadWordsWarning
        Some words were left out (named, with the ``--lang`` to pass).

    Examples
    --------
    >>> check_english_script("привет мир", [])
    Traceback (most recent call last):
    ...
    lipsync.errors.InputError: the transcript is written in Cyrillic letters, which the English aligner cannot read: pass the language, for example --lang ru
    """
    from .text import shown_words

    unread = [t for t in text.split() if script_of(t)]
    if not unread:
        if text.strip() and not words:
            # emoji, symbols or punctuation alone: recognising words instead would hide the
            # wrong file or paste (issue 38: an emoji-only transcript went by with exit 0)
            raise InputError(f"the transcript has no words to say, only symbols or punctuation "
                             f"({shown_words(text.split(), limit=4)}); give the words spoken, or no --text "
                             f"to recognise them", path=path)
        return
    by_script: Dict[str, list] = {}
    for t in unread:   # every script named, in order of appearance (Han and Arabic are not Cyrillic)
        by_script.setdefault(script_of(t), []).append(t)
    named = [_SCRIPTS.get(k, (k.title(), "CODE")) for k in by_script]
    scripts = " and ".join(dict.fromkeys(name for name, _ in named))
    suggestion = " or ".join(dict.fromkeys(f"--lang {code}" for _, code in named))
    if not words:
        raise InputError(f"the transcript is written in {scripts} letters, which the English aligner cannot read: "
                         f"pass the language, for example {suggestion}", path=path)
    warnings.warn(f"{path or 'transcript'}: {len(unread)} word(s) in {scripts} letters cannot be read by the "
                  f"English aligner and were left out ({shown_words(unread)}); pass the language, for example "
                  f"{suggestion}", UnreadWordsWarning, stacklevel=3)
