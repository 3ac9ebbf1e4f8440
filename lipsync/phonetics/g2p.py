"""Letters to sounds in about 100 languages: espeak-ng through the optional ``espeakng-loader`` wheel.

The wheel (GPL-3, installed with ``pip install lipsync[lang]``) bundles libespeak-ng and its
data; it is loaded by ctypes only when a language other than English is asked for, so the
rest of lipsync never links it. English keeps CMUdict (:mod:`lipsync.speech.lexicon`).

* :func:`languages` lists the codes espeak-ng speaks; :func:`resolve` turns a BCP 47 tag
  (``fr``, ``pt-BR``, ``zh-Hans-CN``) into one of them, dropping subtags from the right
  until one matches, and raises :class:`UnknownLanguageError` (exit 2) listing them otherwise.
* :func:`transcribe` splits a transcript into words and gives each its IPA segments:
  words are what a reader would point at (space-separated tokens; each Han character
  where words are not spaced; Japanese words found by janome, whose readings espeak-ng
  reads, since it reads no kanji). Numbers and symbols are read by espeak-ng in the
  language. A word espeak-ng reads by switching to another language (a kanji it does not
  know is read as English "Chinese letter") is marked not read.
* :func:`synthesise` speaks a text and reports each phoneme's time as espeak-ng produces
  it (``espeakINITIALIZE_PHONEME_EVENTS``): speech whose phoneme timeline is known, for
  ``make bench``.

Examples
--------
>>> if espeak_available():
...     [w.phones for w in transcribe("bonjour", "fr")]
... else:
...     [('b', 'ɔ̃', 'ʒ', 'u', 'ʁ')]
[('b', 'ɔ̃', 'ʒ', 'u', 'ʁ')]
"""

from __future__ import annotations

import ctypes
import functools
import os
import re
import threading
import unicodedata
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

from ..errors import InputError

__all__ = ["Word", "UnknownLanguageError", "LanguageUnavailableError", "espeak_available", "languages",
           "resolve", "is_english", "transcribe", "synthesise", "SYNTH_RATE"]

#: espeak-ng's output sample rate (its voices are made at 22.05 kHz).
SYNTH_RATE = 22050

# speak_lib.h constants (espeak-ng 1.5x ABI).
_AUDIO_OUTPUT_SYNCHRONOUS = 2
_INIT_PHONEME_EVENTS = 0x0001   # report each phoneme as it is spoken
_INIT_PHONEME_IPA = 0x0002      # ... by its IPA name
_INIT_DONT_EXIT = 0x8000        # never exit() the process on a data error
_CHARS_UTF8 = 1
_PHONEMES_IPA = 0x02
_EVENT_PHONEME, _EVENT_END, _EVENT_MSG_TERMINATED, _EVENT_LIST_TERMINATED = 7, 5, 6, 0
#: Separator asked of espeak_TextToPhonemes between phonemes: a character no IPA uses.
_SEP = "_"


class UnknownLanguageError(InputError):
    """A ``--lang`` code espeak-ng does not speak (the message names the closest it does)."""


class LanguageUnavailableError(InputError):
    """A language other than English was asked for without the optional espeak-ng extra."""


@dataclass(frozen=True)
class Word:
    """One transcript word and its sounds.

    Attributes
    ----------
    text : str
        The word as written in the transcript.
    phones : tuple of str
        IPA segments, stress and tone marks removed (espeak-ng's spelling; the phonetics
        room's normaliser reads it).
    read : bool
        False when espeak-ng could not read it in the language (``phones`` is then empty).
    """

    text: str
    phones: Tuple[str, ...]
    read: bool = True


# --- the library ------------------------------------------------------------------------------

def espeak_available() -> bool:
    """True if the optional ``espeakng-loader`` wheel is installed.

    Examples
    --------
    >>> isinstance(espeak_available(), bool)
    True
    """
    try:
        import espeakng_loader  # noqa: F401
    except ImportError:
        return False
    return True


class _Event(ctypes.Structure):
    class _Id(ctypes.Union):
        _fields_ = [("number", ctypes.c_int), ("name", ctypes.c_char_p), ("string", ctypes.c_char * 8)]

    _fields_ = [("type", ctypes.c_int), ("unique_identifier", ctypes.c_uint), ("text_position", ctypes.c_int),
                ("length", ctypes.c_int), ("audio_position", ctypes.c_int), ("sample", ctypes.c_int),
                ("user_data", ctypes.c_void_p), ("id", _Id)]


_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int, ctypes.POINTER(_Event))
# libespeak-ng keeps one global state (voice, callback): every call holds this lock.
_LOCK = threading.RLock()


@functools.lru_cache(maxsize=1)
def _lib():
    try:
        import espeakng_loader
    except ImportError:
        raise LanguageUnavailableError(
            "languages other than English need the optional espeak-ng extra (GPL-3): "
            "pip install 'lipsync[lang]'") from None
    lib = ctypes.CDLL(espeakng_loader.get_library_path())
    lib.espeak_Initialize.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_int]
    lib.espeak_SetVoiceByName.argtypes = [ctypes.c_char_p]
    lib.espeak_TextToPhonemes.restype = ctypes.c_char_p
    lib.espeak_TextToPhonemes.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_int, ctypes.c_int]
    lib.espeak_SetSynthCallback.argtypes = [_CALLBACK]
    lib.espeak_Synth.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint, ctypes.c_int, ctypes.c_uint,
                                 ctypes.c_uint, ctypes.c_void_p, ctypes.c_void_p]
    rate = lib.espeak_Initialize(_AUDIO_OUTPUT_SYNCHRONOUS, 0, espeakng_loader.get_data_path().encode(),
                                 _INIT_PHONEME_EVENTS | _INIT_PHONEME_IPA | _INIT_DONT_EXIT)
    if rate <= 0:
        raise RuntimeError(f"espeak-ng did not start (espeak_Initialize returned {rate})")
    return lib


@functools.lru_cache(maxsize=1)
def _voices() -> Dict[str, Tuple[str, str]]:
    """Language code (lowercase) -> (voice name for espeak_SetVoiceByName, description).

    Read from the voice files of the wheel's data (``lang/<family>/<voice>``: ``name`` and
    ``language CODE [PRIORITY]`` lines); a code several voices claim goes to the one that
    gives it the lowest priority (espeak-ng's default is 5).
    """
    import espeakng_loader

    root = os.path.join(espeakng_loader.get_data_path(), "lang")
    best: Dict[str, Tuple[int, str, str]] = {}
    for folder, _, files in os.walk(root):
        for f in files:
            name, codes = f, []
            with open(os.path.join(folder, f), "rb") as fh:
                for raw in fh:
                    parts = raw.decode("utf-8", "replace").split()
                    if len(parts) >= 2 and parts[0] == "name":
                        name = " ".join(parts[1:])
                    elif len(parts) >= 2 and parts[0] == "language":
                        prio = int(parts[2]) if len(parts) > 2 and parts[2].isdigit() else 5
                        codes.append((parts[1].lower(), prio))
            for code, prio in codes:
                if code not in best or prio < best[code][0]:
                    best[code] = (prio, f, name)
    return {code: (voice, name) for code, (_, voice, name) in best.items()}


def languages() -> Dict[str, str]:
    """Language codes espeak-ng speaks, each with its name (needs the ``lang`` extra).

    Examples
    --------
    >>> if espeak_available():
    ...     langs = languages(); print(len(langs) > 100, langs["fr"])
    ... else:
    ...     print(True, "French (France)")
    True French (France)
    """
    _lib()
    return {code: name for code, (_, name) in sorted(_voices().items())}


#: English tags: these keep CMUdict and pocketsphinx's US-English models (the aligner's own
#: language), whatever the variety, so English output never depends on the optional extra.
_ENGLISH = re.compile(r"^en(-[a-z0-9]+)*$", re.I)


def is_english(lang: Optional[str]) -> bool:
    """True for no language or an English tag (``en``, ``en-US``, ``en-GB``).

    Examples
    --------
    >>> is_english(None), is_english("en-GB"), is_english("fr")
    (True, True, False)
    """
    return lang is None or bool(_ENGLISH.match(lang.strip().replace("_", "-")))


#: Tags people use that espeak-ng spells otherwise (its Chinese voices are cmn and yue).
_ALIASES = {"zh-hans": "cmn", "zh-hant": "cmn", "zh-cn": "cmn", "zh-tw": "cmn", "zh-sg": "cmn",
            "zh-hk": "yue", "zh-yue": "yue", "nb": "nb", "no": "nb", "iw": "he", "jp": "ja"}


def resolve(lang: str) -> str:
    """The espeak-ng language code of a BCP 47 tag (case and ``_`` ignored, subtags dropped from the right).

    Raises
    ------
    UnknownLanguageError
        No voice speaks it; the message names the closest codes (``lipsync languages`` lists all).
    LanguageUnavailableError
        The optional espeak-ng extra is not installed.

    Examples
    --------
    >>> if espeak_available():
    ...     print(resolve("pt-BR"), resolve("zh-Hans-CN"), resolve("fr-CA"))
    ... else:
    ...     print("pt-br cmn fr")
    pt-br cmn fr
    """
    tag = lang.strip().replace("_", "-").lower()
    voices = _voices() if _lib() else {}
    parts = tag.split("-")
    while parts:
        code = "-".join(parts)
        code = _ALIASES.get(code, code)
        if code in voices:
            return code
        parts.pop()
    raise UnknownLanguageError(f"unknown language {lang!r}{_closest(tag, voices)}; `lipsync languages` lists "
                               f"all {len(voices)} codes espeak-ng speaks")


#: Codes an unknown --lang's message suggests at most (the whole list, ~130 codes on one
#: line, hid the few that mattered: issue 38).
CLOSEST_CODES = 4


def _closest(tag: str, voices) -> str:
    """``"; did you mean fr (French), frp (...)"``: the codes nearest ``tag`` in spelling or name."""
    import difflib

    names = {code: voices[code][1] for code in voices}
    by_code = difflib.get_close_matches(tag, list(names), n=CLOSEST_CODES, cutoff=0.5)
    # a language's name as people type it ("german"): names starting with it, then close ones
    lowered = {name.lower(): code for code, name in sorted(names.items(), key=lambda kv: len(kv[0]))[::-1]}
    prefix = [code for name, code in sorted(lowered.items()) if len(tag) >= 3 and name.startswith(tag)]
    by_name = [lowered[n] for n in difflib.get_close_matches(tag, list(lowered), n=CLOSEST_CODES, cutoff=0.6)]
    near = list(dict.fromkeys(prefix + by_name + by_code))[:CLOSEST_CODES]
    return "; did you mean " + ", ".join(f"{c} ({names[c]})" for c in near) if near else ""


_CURRENT = [""]  # the voice set last (under _LOCK)


def _set_voice(code: str) -> None:
    voice = _voices()[code][0]
    _CURRENT[0] = voice
    if _lib().espeak_SetVoiceByName(voice.encode()) != 0:
        raise RuntimeError(f"espeak-ng cannot load its voice {voice!r}")


# --- words to phones --------------------------------------------------------------------------

# Marks that carry no mouth shape: stress, syllable and linking marks espeak-ng writes.
_DROP = re.compile(r"[ˈˌ\-‿|]")
# espeak-ng marks a switch to another language's rules as "(en)" inside a word.
_SWITCH = re.compile(r"\([a-z\-]+\)")
# Han characters (CJK ideographs and their extensions): one syllable each, no spaces between words.
_HAN = re.compile(r"[\u3400-\u4dbf\u4e00-\u9fff\uf900-\ufaff\U00020000-\U0002ffff]")
# A word: letters and marks (apostrophes and hyphens inside a word keep it whole, as in
# "l'avion", "dix-sept"), or a number with its separators, or a spoken symbol.
_JOINERS = "'\u2019-"
_SYMBOLS = "%&+@=§€$£¥"


def _tokens(text: str) -> List[str]:
    """Words of ``text``: runs of letters, marks and digits (by Unicode category, so that
    Devanagari's vowel signs stay in their word), joined across a single apostrophe or
    hyphen between two of them, and the symbols that are spoken."""
    out, cur = [], []

    def is_word(ch: str) -> bool:
        return unicodedata.category(ch)[0] in "LMN"

    for i, ch in enumerate(text):
        if is_word(ch):
            cur.append(ch)
        elif ch in _JOINERS and cur and i + 1 < len(text) and is_word(text[i + 1]):
            cur.append(ch)
        else:
            if cur:
                out.append("".join(cur))
                cur = []
            if ch in _SYMBOLS:
                out.append(ch)
    if cur:
        out.append("".join(cur))
    return out


#: Tone and syllable marks in espeak-ng's IPA for tone languages (Mandarin: 1 2 5 ɜ): a
#: phoneme holding one carries a syllable's tone, which is how syllables are counted.
_TONE = re.compile(r"[0-9ɜ˥˦˧˨˩]")


def _raw_phonemes(text: str) -> List[List[str]]:
    """espeak-ng's phonemes of ``text`` in the current voice, word by word (espeak's words)."""
    lib = _lib()
    buf = ctypes.create_string_buffer(text.encode("utf-8"))
    ptr = ctypes.c_void_p(ctypes.addressof(buf))
    words: List[List[str]] = []
    while ptr.value:
        out = lib.espeak_TextToPhonemes(ctypes.byref(ptr), _CHARS_UTF8, _PHONEMES_IPA | (ord(_SEP) << 8))
        if not out:
            break
        for w in out.decode("utf-8", "replace").split():
            words.append([p for p in w.split(_SEP) if p])
    return words


#: espeak-ng voices that write a tone after a syllable's vowel (digits, and ɜ for a rising tone).
#: Vietnamese and Thai were missing until round five: their rising tone's ɜ was read as a
#: vowel (bó as b ɔ ɜ), so the aligner placed an en-us AH that the speech lacks. With them,
#: Vietnamese with the transcript on the ``languages`` bench: frame agreement with the
#: truth's mouth shapes 0.736 -> 0.762.
_TONE_VOICES = frozenset({"cmn", "yue", "hak", "cmn-Latn-pinyin", "yue-Latn-jyutping",
                          "vi", "vi-VN-x-south", "vi-VN-x-central", "th"})
_TRAILING_TONE = re.compile(r"(?<=.)[0-9ɜ]+$")
_DIGITS = re.compile(r"[0-9]")


def _clean(phonemes: List[str]) -> Tuple[str, ...]:
    """IPA segments of espeak-ng phonemes: stress, tone and link marks dropped, espeak's own
    spellings made IPA (:func:`lipsync.phonetics.to_ipa`), and a phoneme that is more than
    one segment (Russian я is one phoneme "ja") split into its segments; diphthongs and
    affricates stay one segment (the maps split them in time)."""
    from .notations import to_ipa
    from .segments import parse, split

    # ɜ is a tone only after a tone voice's vowel (elsewhere it is the open-mid vowel)
    tones = _TRAILING_TONE if _CURRENT[0] in _TONE_VOICES else _DIGITS
    out: List[str] = []
    for p in phonemes:
        p = tones.sub("", _DROP.sub("", _SWITCH.sub("", p)))
        if not p:
            continue
        if out and all(unicodedata.category(c) in ("Lm", "Mn", "Sk") for c in p):
            out[-1] += p  # a modifier espeak-ng writes as a phoneme of its own (Polish "p_ʲ")
            continue
        ipa = to_ipa(p, "espeak") or p
        out.extend([ipa] if parse(ipa) is not None else (split(ipa) or [ipa]))
    return tuple(out)


def _read(words: List[List[str]], token: str = "") -> Tuple[Tuple[str, ...], bool]:
    """All phonemes of espeak's words (one transcript token), and whether it is read.

    espeak-ng switches to another language's rules, marking it "(en)", for a word its
    voice has no rules for. A word in Latin letters (a name or loanword, "iPhone" in a
    Chinese sentence) is then read as a speaker would say it; a character of another
    script (a kanji the Japanese voice does not know is read as the English words "Chinese
    letter") is not read at all.
    """
    flat = [p for w in words for p in w]
    switched = any(_SWITCH.search(p) for p in flat)
    read = bool(flat) and (not switched or _latin(token))
    return (_clean(flat) if read else ()), read


def _latin(token: str) -> bool:
    """True if every letter of ``token`` is a Latin letter (and it has one)."""
    letters = [c for c in token if unicodedata.category(c).startswith("L")]
    return bool(letters) and all(unicodedata.name(c, "").startswith("LATIN") for c in letters)


def _syllables(phonemes: Tuple[str, ...]) -> List[Tuple[str, ...]]:
    """Split a tone language's phonemes into syllables: one tone-bearing phoneme each, the
    consonants between two of them going to the next syllable, except a nasal coda (n, ŋ,
    the only Mandarin codas) when more consonants follow it or when it is ŋ alone."""
    nuclei = [i for i, p in enumerate(phonemes) if _TONE.search(p)]
    if not nuclei:
        return [phonemes]
    cuts = [0]
    for a, b in zip(nuclei, nuclei[1:]):
        between = list(range(a + 1, b))
        cut = a + 1
        if between and phonemes[between[0]] in ("n", "ŋ") and (len(between) > 1 or phonemes[between[0]] == "ŋ"):
            cut += 1
        cuts.append(cut)
    cuts.append(len(phonemes))
    return [phonemes[a:b] for a, b in zip(cuts, cuts[1:])]


def _han_run(run: str) -> List[Word]:
    """Words of a run of Han characters: one per character, each with its syllable of the
    run read as a whole (so a character read two ways is read as in its word); each
    character alone when the syllables do not come out one per character."""
    words = _raw_phonemes(run)
    flat = tuple(p for w in words for p in w)
    if any(_SWITCH.search(p) for p in flat):
        return [_one(c) for c in run]
    sylls = [s for w in words for s in _syllables(tuple(w))]
    if len(sylls) != len(run):
        return [_one(c) for c in run]
    return [Word(c, _clean(list(s))) for c, s in zip(run, sylls)]


def _one(token: str) -> Word:
    phones, read = _read(_raw_phonemes(token), token)
    return Word(token, phones, read)


def _in_context(tokens: List[str]) -> List[Word]:
    """Each token's phones as espeak-ng reads it in its sentence (a one-letter word alone is
    read as the letter's name: Greek "Ο" as "omicron"; French liaison joins words), when
    the sentence gives as many espeak words as the tokens alone do; else each alone."""
    alone = [_raw_phonemes(t) for t in tokens]
    whole = _raw_phonemes(" ".join(tokens))
    if len(whole) != sum(len(a) for a in alone) or not all(alone):
        return [Word(t, *_read(a, t)) for t, a in zip(tokens, alone)]
    out, k = [], 0
    for t, a in zip(tokens, alone):
        out.append(Word(t, *_read(whole[k:k + len(a)], t)))
        k += len(a)
    return out


def _japanese_tokens(text: str) -> List[Tuple[str, str]]:
    """(word as written, its reading in kana) of Japanese text, by janome's dictionary.

    espeak-ng reads kana but no kanji; janome (Apache-2.0, ships the IPA dictionary)
    finds the words and their pronunciations.
    """
    try:
        import janome.tokenizer  # noqa: F401  (part of the lang extra; without it, spaces split words)
    except ImportError:
        return [(t, t) for t in _tokens(text)]
    out = []
    for tok in _janome().tokenize(text):
        surface = tok.surface
        if not _tokens(surface):
            continue  # punctuation
        reading = tok.phonetic if tok.phonetic not in ("*", "") else surface
        out.append((surface, reading))
    return out


@functools.lru_cache(maxsize=1)
def _janome():
    from janome.tokenizer import Tokenizer

    return Tokenizer()


def transcribe(text: str, lang: str) -> List[Word]:
    """The words of a transcript in ``lang`` with their IPA segments.

    Parameters
    ----------
    text : str
        The transcript as written (numbers and symbols are read in the language).
    lang : str
        A BCP 47 tag (:func:`resolve`).

    Returns
    -------
    list of Word
        In order; a word that is not read in the language has ``read=False``.

    Examples
    --------
    >>> if espeak_available():
    ...     print([(w.text, "".join(w.phones)) for w in transcribe("Hola, 2 amigos", "es")])
    ... else:
    ...     print([('Hola', 'ola'), ('2', 'ðos'), ('amigos', 'amiɣos')])
    [('Hola', 'ola'), ('2', 'ðos'), ('amigos', 'amiɣos')]
    """
    code = resolve(lang)
    text = unicodedata.normalize("NFC", text)
    out: List[Word] = []
    voice = _voices()[code][0]
    with _LOCK:
        _set_voice(code)
        if voice == "ja":
            for surface, reading in _japanese_tokens(text):
                if _HAN.search(reading):
                    out.append(Word(surface, (), False))
                else:
                    phones, read = _read(_raw_phonemes(reading), reading)
                    out.append(Word(surface, phones, read))
            return out
        tokens = _tokens(text)
        if not (voice in _TONE_VOICES and any(_HAN.search(t) for t in tokens)):
            return _in_context(tokens)
        for token in tokens:
            if _HAN.search(token) and voice in _TONE_VOICES:
                # Han runs (possibly with kana or letters around): characters one by one
                pos = 0
                for m in re.finditer(_HAN.pattern + "+", token):
                    if m.start() > pos:
                        out.append(_one(token[pos:m.start()]))
                    out.extend(_han_run(m.group()))
                    pos = m.end()
                if pos < len(token):
                    out.append(_one(token[pos:]))
            else:
                out.append(_one(token))
    return out


# --- speech with a known phoneme timeline --------------------------------------------------

def synthesise(text: str, lang: str) -> Tuple[np.ndarray, List[Tuple[float, float, str]]]:
    """espeak-ng's speech of ``text`` and when each of its phonemes is spoken.

    Returns
    -------
    samples : numpy.ndarray
        int16 mono at :data:`SYNTH_RATE`.
    phonemes : list of (float, float, str)
        (start, end in seconds, IPA name as espeak-ng reports it with stress and tone marks
        removed), in order. espeak-ng reports the moment each phoneme starts; one ends
        where the next phoneme or pause starts (the last where the audio ends). Pauses
        (espeak's ``_`` phonemes) are left out, so they show as gaps.

    Examples
    --------
    The phonemes' exact times depend on what the process spoke before (espeak-ng keeps its
    wave generator's state; the bench speaks each sentence in a fresh process), and once in
    a test run a vowel reported at the same sample as the stop after it had no time at all,
    so the example shows what holds in any state:

    >>> if espeak_available():
    ...     pcm, ph = synthesise("papa", "fr")
    ...     print(sorted({p for _, _, p in ph}), ph[0][0] < ph[-1][1] <= len(pcm) / SYNTH_RATE + 1e-9)
    ... else:
    ...     print(['a', 'p'], True)
    ['a', 'p'] True
    """
    code = resolve(lang)
    chunks: List[np.ndarray] = []
    events: List[Tuple[int, str]] = []

    def callback(wav, n, ev) -> int:
        if n > 0:
            chunks.append(np.ctypeslib.as_array(wav, shape=(n,)).copy())
        i = 0
        while ev[i].type != _EVENT_LIST_TERMINATED:
            if ev[i].type == _EVENT_PHONEME:
                events.append((int(ev[i].sample), bytes(ev[i].id.string).split(b"\0")[0].decode("utf-8", "replace")))
            elif ev[i].type in (_EVENT_END, _EVENT_MSG_TERMINATED):
                events.append((int(ev[i].sample), "_"))
            i += 1
        return 0

    cb = _CALLBACK(callback)
    raw = text.encode("utf-8") + b"\0"
    with _LOCK:
        lib = _lib()
        _set_voice(code)
        lib.espeak_SetSynthCallback(cb)
        lib.espeak_Synth(raw, len(raw), 0, 0, 0, _CHARS_UTF8, None, None)
        lib.espeak_Synchronize()
        _CURRENT[0] = _voices()[code][0]
        names = [(sample, _clean([name]) if name != "_" else ()) for sample, name in events]
    pcm = np.concatenate(chunks).astype(np.int16) if chunks else np.zeros(0, np.int16)
    end = len(pcm) / SYNTH_RATE
    events.sort(key=lambda e: e[0])
    phonemes: List[Tuple[float, float, str]] = []
    for k, (sample, name) in enumerate(names):
        nxt = names[k + 1][0] / SYNTH_RATE if k + 1 < len(names) else end
        label = name[0] if name else ""
        if label and phonemes and all(unicodedata.category(c) in ("Lm", "Mn", "Sk") for c in label):
            a, _, prev = phonemes[-1]  # a modifier reported as a phoneme of its own (Polish "ʲ")
            phonemes[-1] = (a, min(nxt, end), prev + label)
            continue
        start = sample / SYNTH_RATE
        if label and label[0] in _CLOSURE_STOPS:
            floor = int(round(phonemes[-1][0] * SYNTH_RATE)) if phonemes else 0
            floor = max(floor, sample - int(_CLOSURE_MAX_S * SYNTH_RATE))
            closure = _closure_start(pcm, sample, floor)
            if closure < sample:
                start = closure / SYNTH_RATE
                nxt = max(nxt, sample / SYNTH_RATE)  # a stop reported with the vowel after it: its closure
                if phonemes and phonemes[-1][1] > start:
                    a, _, prev = phonemes[-1]
                    phonemes[-1] = (a, start, prev)
        if label and nxt > start:
            # a phoneme of several segments (Russian "ja") shares its time evenly among them
            edges = np.linspace(start, min(nxt, end), len(name) + 1)
            phonemes += [(float(a), float(b), seg) for a, b, seg in zip(edges[:-1], edges[1:], name)]
    return pcm, phonemes


#: Phonemes espeak-ng reports at their release (first letters of the IPA name): unvoiced
#: stops and the affricates that begin with one. Their silent closure is written as digital
#: silence at the end of the phoneme before (measured: French "appelle", 35 ms of zeros
#: before the event of p), so :func:`synthesise` gives it back to the stop, as a mouth
#: closes for the closure. Voiced stops are reported at their closure (their voice bar
#: starts at the event).
_UNVOICED_STOPS = frozenset("ptkqcʈʔ")
#: Stops whose event may come after a silent closure: the unvoiced ones, and voiced ones where
#: a voice had no bar (Vietnamese b, an implosive, is reported 20-30 ms after a run of
#: digital silence that is its closure). A voiced stop reported at its closure has no silent
#: run ending at its event, so nothing moves. A stop reported at the same sample as the
#: phoneme after it (Vietnamese đ, ɗ: 32 ms of digital silence, then its event and the
#: vowel's together) is its closure alone; until round five it had no time at all, so
#: the truth showed a pause where every đ is (9 of the 25 Vietnamese bench sentences).
_CLOSURE_STOPS = _UNVOICED_STOPS | frozenset("bdɡgɟɖɢɓɗ")
#: Shortest run of digital silence taken as a closure (shorter runs are waveform zero
#: crossings), and how far before the event the run may end.
_CLOSURE_MIN_S, _CLOSURE_SLACK_S = 0.005, 0.003
#: Longest closure: after a pause the silence before a stop is the pause's too, and lips
#: close for about this long before a release (as the aligner's MAX_PAUSE_CLOSURE_S).
_CLOSURE_MAX_S = 0.08


def _closure_start(pcm: np.ndarray, sample: int, floor: int) -> int:
    """First sample of the run of digital silence that ends at (or just before) ``sample``."""
    quiet = np.abs(pcm[max(floor, 0):sample].astype(np.int32)) <= 1
    if not len(quiet):
        return sample
    slack = int(_CLOSURE_SLACK_S * SYNTH_RATE)
    loud = np.flatnonzero(~quiet)
    # end of the run: the last quiet sample within the slack before the event
    tail = len(quiet)
    while tail > 0 and len(quiet) - tail < slack and not quiet[tail - 1]:
        tail -= 1
    before = loud[loud < tail]
    head = int(before[-1]) + 1 if len(before) else 0
    if tail - head < _CLOSURE_MIN_S * SYNTH_RATE:
        return sample
    return max(floor, 0) + head
