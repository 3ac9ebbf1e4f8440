#!/usr/bin/env python3
"""Regenerate samples/: spoken sentences with timelines that match their audio exactly.

espeak-ng is driven through its C library (ctypes), which reports a phoneme
event, with its position in the synthesised audio, for every phoneme it
speaks.  Audio and events come out of the same synthesis call, so the timeline
is exactly the one the speech was made from -- no forced alignment involved.

Only this script needs espeak-ng (``apt-get install espeak-ng sox``); the files it
writes are committed and nothing else in the project depends on espeak-ng.

Usage::

    python3 tools/make_samples.py            # rewrite samples/
    python3 tools/make_samples.py --check    # print per-phone RMS, write nothing

For each sentence NAME it writes, into samples/:

* NAME.wav       16 kHz mono 16-bit PCM
* NAME.phn       TIMIT: "begin end label", sample numbers at 16 kHz
* NAME.TextGrid  Praat long text form, tiers "words" and "phones" (MFA style)
* NAME.json      Gentle-style alignment
* NAME.txt       Audacity label track, "start<TAB>end<TAB>label" in seconds
* NAME.lab       the sentence text
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import wave
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
SAMPLES_DIR = REPO / "samples"

# name -> sentence.  "hello" is what `make demo` renders.  "balloons" is chosen for
# varied mouth shapes: bilabial closures (b, p, m), labiodentals (f, v), rounded
# vowels (blue, pool, over), l in several positions, and a comma pause in the middle.
SENTENCES = {
    "hello": "Hello, I am a talking head made by lipsync.",
    "balloons": "Five blue balloons floated over the warm pool, while my mother played lovely music.",
}

VOICE = b"en-us"
OUT_RATE = 16000  # TIMIT's rate; what aligners (MFA, Gentle) work at

# espeak starts speaking at its first sample; a real recording has some room tone
# before and after the speech, and the h# segments of TIMIT exist to hold it.
# A quarter second on each side is enough to see the face at rest.
LEAD_SILENCE_S = 0.25
TRAIL_SILENCE_S = 0.25

# A phone espeak reports with (almost) no duration -- it folds a post-vocalic l into
# the glide out of the vowel before a pause, and reports the l at the pause -- would
# be an empty interval, which Praat refuses.  Such phones take this much from the end
# of the phone before them; 30 ms is short enough not to disturb the vowel and about
# the shortest phone espeak itself produces.
MIN_PHONE_S = 0.030

# espeak's phoneme event for a stop (or affricate) comes at the release burst; the
# closure -- silence, when the lips or tongue are shut -- is spoken at the end of the
# phone before.  TIMIT (bcl b) and MFA count the closure as part of the stop, and a
# face must show the lips shut during it, so the stop is moved back to where that
# silence begins.  Found from the audio: a run of CLOSURE_FRAME_S frames all quieter
# than CLOSURE_LEVEL (about -54 dBFS; espeak's closures are digital zero).
STOP_MNEMONICS = frozenset({"p", "b", "t", "d", "k", "g", "tS", "dZ", "t2", "t#", "d#", "?"})
CLOSURE_FRAME_S = 0.001
CLOSURE_LEVEL = 64

# constants from speak_lib.h
AUDIO_OUTPUT_SYNCHRONOUS = 2
ESPEAK_INITIALIZE_PHONEME_EVENTS = 0x0001
ESPEAK_CHARS_UTF8 = 1
POS_CHARACTER = 1
EVENT_LIST_TERMINATED = 0
EVENT_WORD = 1
EVENT_PHONEME = 7

# espeak-ng English phoneme mnemonic -> ARPAbet phone(s), without stress.  Entries
# with two phones are one espeak phoneme (a vowel with an r or schwa offglide, or a
# syllabic consonant) that ARPAbet writes as two; see SPLIT_FIRST_SHARE.
ESPEAK_TO_ARPABET = {
    # --- vowels ---
    "@": ("AH",),      # schwa; ARPAbet writes unstressed schwa as AH0
    "@2": ("AH",),     # schwa of "the" before a consonant
    "@5": ("AH",),     # schwa of weak "to"
    "@L": ("AH", "L"),  # syllabic l ("bottle"): CMU writes AH0 L
    "3": ("ER",),      # unstressed r-coloured schwa (en-us "mother")
    "3:": ("ER",),     # stressed r-coloured vowel ("bird")
    "a": ("AE",),      # trap vowel
    "aa": ("AE",),     # bath vowel; en-us says it like trap
    "a#": ("AH",),     # reduced a of weak forms ("a", "am") and "about"
    "a2": ("AH",),     # another reduced a
    "A:": ("AA",),     # palm
    "A@": ("AA", "R"),  # start ("car")
    "A#": ("AE",),     # en-us: bath words said with the trap vowel
    "0": ("AA",),      # lot; en-us has the unrounded ɑ
    "02": ("AA",),     # lot variant
    "0#": ("AA",),     # lot variant
    "O": ("AO",),      # short thought vowel
    "O:": ("AO",),     # thought ("talk")
    "O2": ("AO",),     # thought variant
    "O@": ("AO", "R"),  # north ("warm")
    "o@": ("AO", "R"),  # force ("more")
    "o:": ("OW",),     # long o (loan words)
    "OI": ("OY",),     # choice
    "aI": ("AY",),     # price
    "aI@": ("AY", "ER"),  # fire: CMU F AY1 ER0
    "aI3": ("AY", "ER"),  # fire, en-us variant
    "aU": ("AW",),     # mouth
    "aU@": ("AW", "ER"),  # hour: CMU AW1 ER0
    "E": ("EH",),      # dress
    "E2": ("EH",),     # dress variant
    "E#": ("EH",),     # dress variant
    "e@": ("EH", "R"),  # square ("air")
    "eI": ("EY",),     # face
    "I": ("IH",),      # kit
    "I2": ("IH",),     # unstressed kit vowel
    "I#": ("IH",),     # unstressed i of "-ed", "-es"
    "I2#": ("IH",),    # unstressed i variant
    "i": ("IY",),      # happy-tensing: final y of "lovely" (CMU IY0)
    "i:": ("IY",),     # fleece
    "i@": ("IH", "R"),  # near; CMU writes it IH1 R ("near") or IY1 R ("here")
    "i@3": ("IH", "R"),  # near, en-us variant
    "IR": ("IH", "R"),  # near before a vowel
    "oU": ("OW",),     # goat
    "oU#": ("OW",),    # goat variant
    "u:": ("UW",),     # goose
    "U": ("UH",),      # foot
    "U@": ("UH", "R"),  # cure: CMU K Y UH1 R
    "V": ("AH",),      # strut; stressed AH in ARPAbet
    "VR": ("AH", "R"),  # strut before r ("hurry")
    "e#": ("EH",),     # rare dress variant
    "e:": ("EY",),     # long e (loan words)
    "@#": ("AH",),     # schwa variant
    "a#2": ("AH",),    # reduced a variant
    # --- consonants ---
    "p": ("P",), "b": ("B",), "t": ("T",), "d": ("D",), "k": ("K",), "g": ("G",),
    "f": ("F",), "v": ("V",), "s": ("S",), "z": ("Z",), "h": ("HH",),
    "m": ("M",), "n": ("N",), "l": ("L",), "r": ("R",), "w": ("W",),
    "T": ("TH",),      # thin
    "D": ("DH",),      # this
    "S": ("SH",),      # ship
    "Z": ("ZH",),      # measure
    "tS": ("CH",),     # church
    "dZ": ("JH",),     # judge
    "N": ("NG",),      # sing
    "j": ("Y",),       # yes; espeak follows IPA j
    "t#": ("T",),      # en-us flap ("floated"); CMU has no DX, MFA writes T
    "t2": ("T",),      # t variant
    "d#": ("D",),      # flapped d
    "z#": ("Z",),      # z variant of plural/verb endings
    "w#": ("W",),      # w of "wh" words
    "r-": ("R",),      # r variant
    "r/": ("R",),      # en-us r
    "l/": ("L",),      # dark l
    "n-": ("AH", "N"),  # syllabic n ("button"): CMU AH0 N
    "m-": ("AH", "M"),  # syllabic m
    "?": ("T",),       # glottal stop for t ("button"); MFA writes T
    "x": ("K",),       # loch; English speakers say k
}

# How a two-phone entry's time is split: the vowel keeps the larger part and the
# offglide or consonant the rest.  espeak renders these as one continuous glide, so
# any split is a convention; 60/40 keeps the vowel recognisable on screen.
SPLIT_FIRST_SHARE = 0.6

ARPABET_VOWELS = frozenset(
    "AA AE AH AO AW AY EH ER EY IH IY OW OY UH UW".split()
)

# Vowels espeak uses only unstressed.  A vowel with no stress mark in espeak's
# transcription is 0 when it is one of these, or when its word has a primary stress
# elsewhere; otherwise it is a monosyllable's vowel and gets 1, as in the CMU
# dictionary that MFA's English models use ("by" B AY1).
REDUCED = frozenset({"@", "@2", "@5", "@#", "@L", "3", "a#", "a#2", "a2", "I2", "I#", "I2#", "i", "n-", "m-"})

# espeak's stress marks in its phoneme text -> ARPAbet stress digit.
STRESS_MARKS = {"'": "1", ",": "2"}

# espeak's pause phonemes ("_", "_:", "_!"), as they may prefix a phoneme in its text
PAUSE_PREFIX = re.compile(r"^(?:_[:!]?)+")

WORD_RE = re.compile(r"[A-Za-z]+(?:'[A-Za-z]+)?")


# ----------------------------------------------------------------------------------
# espeak-ng through ctypes


class _EventId(ctypes.Union):
    _fields_ = [("number", ctypes.c_int), ("name", ctypes.c_char_p), ("string", ctypes.c_char * 8)]


class _Event(ctypes.Structure):
    _fields_ = [
        ("type", ctypes.c_int),
        ("unique_identifier", ctypes.c_uint),
        ("text_position", ctypes.c_int),
        ("length", ctypes.c_int),
        ("audio_position", ctypes.c_int),
        ("sample", ctypes.c_int),
        ("user_data", ctypes.c_void_p),
        ("id", _EventId),
    ]


_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int, ctypes.POINTER(_Event))


@dataclass
class PhonemeEvent:
    mnemonic: str
    text_position: int  # 1-based character position of the word it belongs to
    sample: int  # position in espeak's audio, samples at espeak's rate


class Espeak:
    """The few calls of libespeak-ng that this script needs."""

    def __init__(self, voice: bytes = VOICE):
        self.lib = ctypes.CDLL("libespeak-ng.so.1")
        self.rate = self.lib.espeak_Initialize(
            AUDIO_OUTPUT_SYNCHRONOUS, 0, None, ESPEAK_INITIALIZE_PHONEME_EVENTS
        )
        if self.rate <= 0:
            raise RuntimeError("espeak_Initialize failed")
        if self.lib.espeak_SetVoiceByName(voice) != 0:
            raise RuntimeError(f"espeak-ng has no voice {voice!r}")
        self.lib.espeak_TextToPhonemes.restype = ctypes.c_char_p
        self.lib.espeak_TextToPhonemes.argtypes = [ctypes.POINTER(ctypes.c_char_p), ctypes.c_int, ctypes.c_int]
        self._chunks: list[np.ndarray] = []
        self._events: list[PhonemeEvent] = []
        self._n = 0
        # keep a reference: the C side holds only the raw pointer
        self._cb = _CALLBACK(self._on_synth)
        self.lib.espeak_SetSynthCallback(self._cb)

    def _on_synth(self, wav, n, events):
        i = 0
        while events[i].type != EVENT_LIST_TERMINATED:
            ev = events[i]
            if ev.type == EVENT_PHONEME:
                name = bytes(ev.id.string).split(b"\0")[0].decode("utf-8")
                # `sample` is marked "internal use"; it is the exact sample count behind
                # audio_position (ms, truncated).  Use it only while the two agree.
                exact = ev.sample * 1000 // self.rate
                sample = ev.sample if abs(exact - ev.audio_position) <= 1 else round(ev.audio_position * self.rate / 1000)
                self._events.append(PhonemeEvent(name, ev.text_position, sample))
            i += 1
        if wav and n > 0:
            self._chunks.append(np.ctypeslib.as_array(wav, (n,)).copy())
            self._n += n
        return 0

    def synth(self, text: str) -> tuple[np.ndarray, list[PhonemeEvent]]:
        """Speak `text`; return int16 audio at self.rate and its phoneme events."""
        self._chunks, self._events, self._n = [], [], 0
        data = text.encode("utf-8") + b"\0"
        err = self.lib.espeak_Synth(data, len(data), 0, POS_CHARACTER, 0, ESPEAK_CHARS_UTF8, None, None)
        if err != 0:
            raise RuntimeError(f"espeak_Synth failed ({err})")
        self.lib.espeak_Synchronize()
        audio = np.concatenate(self._chunks).astype(np.int16)
        return audio, list(self._events)

    def transcribe(self, text: str) -> list[list[str]]:
        """espeak's phoneme text for `text`: words, each a list of phonemes with stress marks."""
        sep = ord("|")  # bits 8-23 of phonememode: the separator between phonemes
        buf = ctypes.c_char_p(text.encode("utf-8"))
        ptr = ctypes.pointer(buf)
        words: list[list[str]] = []
        while buf.value:
            clause = self.lib.espeak_TextToPhonemes(ptr, ESPEAK_CHARS_UTF8, sep << 8).decode("utf-8")
            for w in clause.split():
                # pauses are not phonemes here; espeak glues "_!" to the next phoneme
                phs = [PAUSE_PREFIX.sub("", p) for p in w.split("|")]
                phs = [p for p in phs if p]
                if phs:
                    words.append(phs)
        return words


# ----------------------------------------------------------------------------------
# building the timeline


@dataclass
class Phone:
    start: int  # samples at OUT_RATE
    end: int
    label: str | None  # ARPAbet with stress digit; None for silence
    word: int | None  # index into the word list; None for silence


@dataclass
class Word:
    text: str
    offset: int  # 0-based character offset in the sentence


def split_mark(ph: str) -> tuple[str, str]:
    """"'oU" -> ("'", "oU"): an espeak phoneme split into stress mark ('' if none) and mnemonic."""
    mark = ""
    while ph and ph[0] in "',":
        mark = ph[0] if not mark else mark
        ph = ph[1:]
    return mark, ph


def stress_digits(transcription: list[list[str]]) -> list[str]:
    """ARPAbet stress digit for every phoneme of `transcription` ('' for consonants)."""
    out = []
    for word in transcription:
        marks = [split_mark(p) for p in word]
        has_primary = any(m == "'" for m, _ in marks)
        for mark, mn in marks:
            if mark:
                out.append(STRESS_MARKS[mark])
            elif mn in REDUCED or has_primary:
                out.append("0")
            else:
                out.append("1")
    return out


def to_arpabet(mnemonic: str, stress: str) -> list[str]:
    try:
        phones = ESPEAK_TO_ARPABET[mnemonic]
    except KeyError:
        raise SystemExit(f"no ARPAbet entry for espeak phoneme {mnemonic!r}; add it to ESPEAK_TO_ARPABET")
    out = []
    for i, p in enumerate(phones):
        if p in ARPABET_VOWELS:
            # the second vowel of a split entry (AY ER of "fire") is unstressed
            out.append(p + ((stress or "1") if i == 0 else "0"))
        else:
            out.append(p)
    return out


def words_of(text: str) -> list[Word]:
    return [Word(m.group(0), m.start()) for m in WORD_RE.finditer(text)]


def closure_start(raw: np.ndarray, release: int, floor: int, rate: int) -> int:
    """Start of the silent closure that ends at a stop's release (samples at `rate`).

    Scans back from `release` in CLOSURE_FRAME_S steps while the audio stays below
    CLOSURE_LEVEL, but not before `floor`.
    """
    frame = max(1, round(CLOSURE_FRAME_S * rate))
    s = release
    while s - frame >= floor and np.abs(raw[s - frame:s].astype(np.int32)).max() < CLOSURE_LEVEL:
        s -= frame
    return s


def build_timeline(text: str, raw: np.ndarray, events: list[PhonemeEvent], transcription: list[list[str]],
                   espeak: Espeak) -> tuple[list[Phone], list[Word]]:
    """Turn espeak's phoneme events into phones with ARPAbet labels on the output clock."""
    in_rate = espeak.rate
    audio_len = len(raw)
    lead = round(LEAD_SILENCE_S * OUT_RATE)
    total = lead + round(audio_len * OUT_RATE / in_rate) + round(TRAIL_SILENCE_S * OUT_RATE)

    def clock(s: int) -> int:
        return lead + round(s * OUT_RATE / in_rate)

    # each event lasts until the next one; the last ends with the audio
    starts = [ev.sample for ev in events]
    # espeak reports a stop at its release and speaks the closure silence at the end
    # of the phone before (see STOP_MNEMONICS): move the stop's start back over it
    min_in = round(MIN_PHONE_S * in_rate)
    for i in range(1, len(events)):
        if events[i].mnemonic in STOP_MNEMONICS and not events[i - 1].mnemonic.startswith("_"):
            starts[i] = closure_start(raw, starts[i], starts[i - 1] + min_in, in_rate)
    spans = []
    for i, ev in enumerate(events):
        end = starts[i + 1] if i + 1 < len(events) else audio_len
        spans.append((ev, starts[i], end))

    spoken = [s for s in spans if not s[0].mnemonic.startswith("_")]
    flat = [split_mark(p)[1] for w in transcription for p in w]
    if [s[0].mnemonic for s in spoken] != flat:
        raise SystemExit(f"phoneme events and espeak's transcription differ:\n{[s[0].mnemonic for s in spoken]}\n{flat}")
    digits = stress_digits(transcription)

    # Words: phones are grouped by the text position espeak gives them.  espeak
    # sometimes speaks two words as one dictionary entry ("I am"); such a group is
    # split by the phoneme counts of its words spoken alone.
    words = words_of(text)
    group_pos = sorted({s[0].text_position for s in spoken})
    word_of_phone: list[int] = []
    for gi, pos in enumerate(group_pos):
        lo = pos - 1
        hi = group_pos[gi + 1] - 1 if gi + 1 < len(group_pos) else len(text)
        members = [wi for wi, w in enumerate(words) if lo <= w.offset < hi]
        n = sum(1 for s in spoken if s[0].text_position == pos)
        if not members:
            raise SystemExit(f"no word at text position {pos} of {text!r}")
        if len(members) == 1:
            word_of_phone += members * n
            continue
        counts = [sum(len(w) for w in espeak.transcribe(words[wi].text)) for wi in members]
        if sum(counts) != n:
            raise SystemExit(f"cannot split {text[lo:hi]!r} ({n} phonemes) into words {counts}")
        for wi, c in zip(members, counts):
            word_of_phone += [wi] * c

    # the leading silence runs up to espeak's first event (espeak starts with a few ms of silence)
    phones: list[Phone] = [Phone(0, clock(spans[0][1]), None, None)]
    k = 0
    for ev, s0, s1 in spans:
        a, b = clock(s0), clock(s1)
        if ev.mnemonic.startswith("_"):
            if b > a:
                phones.append(Phone(a, b, None, None))
            continue
        labels = to_arpabet(ev.mnemonic, digits[k])
        if len(labels) == 1:
            phones.append(Phone(a, b, labels[0], word_of_phone[k]))
        else:
            mid = a + round((b - a) * SPLIT_FIRST_SHARE)
            phones.append(Phone(a, mid, labels[0], word_of_phone[k]))
            phones.append(Phone(mid, b, labels[1], word_of_phone[k]))
        k += 1
    phones.append(Phone(phones[-1].end, total, None, None))

    # give too-short phones MIN_PHONE_S from the phone before (see MIN_PHONE_S)
    min_len = round(MIN_PHONE_S * OUT_RATE)
    for i in range(1, len(phones)):
        p, prev = phones[i], phones[i - 1]
        if p.label is not None and p.end - p.start < min_len:
            take = min_len - (p.end - p.start)
            if prev.label is None or prev.end - prev.start - take < min_len:
                raise SystemExit(f"cannot lengthen {p.label} at {p.start}: the phone before is too short")
            prev.end -= take
            p.start -= take

    # merge adjacent silences
    merged: list[Phone] = []
    for p in phones:
        if p.end <= p.start:
            continue
        if merged and p.label is None and merged[-1].label is None:
            merged[-1].end = p.end
        else:
            merged.append(p)
    return merged, words


# ----------------------------------------------------------------------------------
# audio


def resample(audio: np.ndarray, in_rate: int) -> np.ndarray:
    """Resample int16 audio to OUT_RATE with sox and pad the lead/trail silence."""
    if shutil.which("sox") is None:
        raise SystemExit("sox is needed: apt-get install sox")
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.wav", Path(tmp) / "out.wav"
        write_wav(src, audio, in_rate)
        # -D: no dither, so the output is deterministic and silence stays zero;
        # sox's rate effect is linear-phase, so the timing is kept.
        subprocess.run(["sox", "-D", str(src), "-r", str(OUT_RATE), "-b", "16", "-c", "1", str(dst)], check=True)
        with wave.open(str(dst), "rb") as w:
            out = np.frombuffer(w.readframes(w.getnframes()), dtype="<i2")
    want = round(len(audio) * OUT_RATE / in_rate)
    out = np.pad(out, (0, max(0, want - len(out))))[:want]
    lead = np.zeros(round(LEAD_SILENCE_S * OUT_RATE), np.int16)
    trail = np.zeros(round(TRAIL_SILENCE_S * OUT_RATE), np.int16)
    return np.concatenate([lead, out, trail]).astype(np.int16)


def write_wav(path: Path, audio: np.ndarray, rate: int) -> None:
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(audio.astype("<i2").tobytes())


# ----------------------------------------------------------------------------------
# writers


def secs(samples: int) -> float:
    return samples / OUT_RATE


def fmt(samples: int) -> str:
    """Seconds, exact: every multiple of 1/16000 s has at most 7 decimals."""
    return f"{samples / OUT_RATE:.7f}".rstrip("0").rstrip(".") or "0"


def strip_stress(label: str) -> str:
    return label.rstrip("012")


def phn_text(phones: list[Phone]) -> str:
    lines = []
    for i, p in enumerate(phones):
        if p.label is None:
            lab = "h#" if i in (0, len(phones) - 1) else "pau"
        else:
            lab = strip_stress(p.label).lower()
        lines.append(f"{p.start} {p.end} {lab}\n")
    return "".join(lines)


def word_intervals(phones: list[Phone], words: list[Word]) -> list[tuple[int, int, str]]:
    """Word tier: each word from its first phone's start to its last phone's end; gaps silent."""
    spans: dict[int, list[int]] = {}
    for p in phones:
        if p.word is not None:
            s = spans.setdefault(p.word, [p.start, p.end])
            s[1] = p.end
    out = []
    t = 0
    for wi in sorted(spans):
        a, b = spans[wi]
        if a > t:
            out.append((t, a, ""))
        out.append((a, b, words[wi].text.lower()))
        t = b
    total = phones[-1].end
    if total > t:
        out.append((t, total, ""))
    return out


def textgrid_text(phones: list[Phone], words: list[Word]) -> str:
    total = phones[-1].end
    tiers = [
        ("words", word_intervals(phones, words)),
        ("phones", [(p.start, p.end, p.label or "") for p in phones]),
    ]
    out = [
        'File type = "ooTextFile"\n',
        'Object class = "TextGrid"\n',
        "\n",
        "xmin = 0 \n",
        f"xmax = {fmt(total)} \n",
        "tiers? <exists> \n",
        f"size = {len(tiers)} \n",
        "item []: \n",
    ]
    for ti, (name, ivs) in enumerate(tiers, 1):
        out += [
            f"    item [{ti}]:\n",
            '        class = "IntervalTier" \n',
            f'        name = "{name}" \n',
            "        xmin = 0 \n",
            f"        xmax = {fmt(total)} \n",
            f"        intervals: size = {len(ivs)} \n",
        ]
        for ii, (a, b, lab) in enumerate(ivs, 1):
            out += [
                f"        intervals [{ii}]:\n",
                f"            xmin = {fmt(a)} \n",
                f"            xmax = {fmt(b)} \n",
                f'            text = "{lab}" \n',
            ]
    return "".join(out)


def gentle_json(text: str, phones: list[Phone], words: list[Word]) -> str:
    by_word: dict[int, list[Phone]] = {}
    for p in phones:
        if p.word is not None:
            by_word.setdefault(p.word, []).append(p)
    out_words = []
    for wi, w in enumerate(words):
        ps = by_word[wi]
        n = len(ps)
        entries = []
        for j, p in enumerate(ps):
            # Gentle's position suffixes: Begin, Inside, End of a word, or Single
            suffix = "S" if n == 1 else "B" if j == 0 else "E" if j == n - 1 else "I"
            entries.append({"duration": secs(p.end - p.start), "phone": f"{strip_stress(p.label).lower()}_{suffix}"})
        out_words.append({
            "alignedWord": w.text.lower(),
            "case": "success",
            "end": secs(ps[-1].end),
            "endOffset": w.offset + len(w.text),
            "phones": entries,
            "start": secs(ps[0].start),
            "startOffset": w.offset,
            "word": w.text,
        })
    return json.dumps({"transcript": text, "words": out_words}, indent=2) + "\n"


def audacity_text(phones: list[Phone]) -> str:
    # Audacity writes six decimals; silences carry "sil" so the track spans the audio
    return "".join(f"{secs(p.start):.6f}\t{secs(p.end):.6f}\t{p.label or 'sil'}\n" for p in phones)


def write_atomic(path: Path, data: bytes | str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        os.chmod(tmp, 0o644)  # mkstemp makes 0600; these are ordinary repository files
        with os.fdopen(fd, "wb") as f:
            f.write(data.encode("utf-8") if isinstance(data, str) else data)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def wav_bytes(audio: np.ndarray) -> bytes:
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "a.wav"
        write_wav(p, audio, OUT_RATE)
        return p.read_bytes()


# ----------------------------------------------------------------------------------
# checks


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x.astype(np.float64) ** 2))) if len(x) else 0.0


def onset_offset(audio: np.ndarray, frame: int = 160, rel: float = 0.02) -> tuple[int, int]:
    """First and last 10 ms frame whose RMS exceeds `rel` of the loudest frame (samples)."""
    n = len(audio) // frame
    fr = np.sqrt(np.mean(audio[: n * frame].astype(np.float64).reshape(n, frame) ** 2, axis=1))
    on = np.flatnonzero(fr > rel * fr.max())
    return int(on[0] * frame), int((on[-1] + 1) * frame)


def report(name: str, audio: np.ndarray, phones: list[Phone]) -> None:
    print(f"== {name}: {len(audio) / OUT_RATE:.3f} s")
    for p in phones:
        print(f"  {secs(p.start):7.3f} {secs(p.end):7.3f} {p.label or '-':5s} rms {rms(audio[p.start:p.end]):8.1f}")
    on, off = onset_offset(audio)
    first = next(p for p in phones if p.label)
    last = [p for p in phones if p.label][-1]
    print(f"  audio onset {secs(on):.3f} s vs first phone {secs(first.start):.3f} s "
          f"(diff {1000 * secs(on - first.start):+.0f} ms)")
    print(f"  audio offset {secs(off):.3f} s vs last phone end {secs(last.end):.3f} s "
          f"(diff {1000 * secs(off - last.end):+.0f} ms)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="print per-phone RMS only; write nothing")
    ap.add_argument("--out", type=Path, default=SAMPLES_DIR)
    args = ap.parse_args(argv)

    espeak = Espeak()
    for name, text in SENTENCES.items():
        raw, events = espeak.synth(text)
        transcription = espeak.transcribe(text)
        phones, words = build_timeline(text, raw, events, transcription, espeak)
        audio = resample(raw, espeak.rate)
        assert len(audio) == phones[-1].end, (len(audio), phones[-1].end)
        report(name, audio, phones)
        if args.check:
            continue
        args.out.mkdir(parents=True, exist_ok=True)
        write_atomic(args.out / f"{name}.wav", wav_bytes(audio))
        write_atomic(args.out / f"{name}.phn", phn_text(phones))
        write_atomic(args.out / f"{name}.TextGrid", textgrid_text(phones, words))
        write_atomic(args.out / f"{name}.json", gentle_json(text, phones, words))
        write_atomic(args.out / f"{name}.txt", audacity_text(phones))
        write_atomic(args.out / f"{name}.lab", text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
