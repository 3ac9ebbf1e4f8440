"""Forced alignment with pocketsphinx: speech (and optionally its transcript) -> words and phones.

The stages, each a function over plain values::

    load_audio -> _frame_energy -> _plan_chunks (cut at the quietest places)
    -> per chunk: [recognise] -> forced word alignment -> phone alignment
    -> Alignment (words and phones timelines over the whole audio)

* With a transcript, the words are normalised (:func:`normalise_transcript`), words the
  dictionary lacks get a pronunciation from :func:`pronounce` (listed in one warning), and
  pocketsphinx aligns them (its align search, then a state-level second pass for phones).
* Without one, the words are recognised first with pocketsphinx's US-English language
  model, then aligned the same way.
* pocketsphinx's alignment search grows faster than linearly with utterance length
  (measured: 0.42 s for 27 s of speech, 9.3 s for 214 s), so audio longer than
  :data:`MAX_CHUNK_S` is cut at its quietest places into chunks of bounded length; the
  transcript is shared out among the chunks by matching it against what recognition heard
  in each. Time and memory then grow linearly with the audio.
* Silence-only audio gives empty timelines spanning the audio. A transcript that cannot be
  aligned (it does not fit the audio) falls back to the recognised words, with a warning
  giving a confidence figure.

Examples
--------
>>> import numpy as np
>>> al = align(np.zeros(8000, np.int16))         # half a second of digital silence
>>> al.duration, len(al.words), len(al.phones)
(0.5, 0, 0)
"""

from __future__ import annotations

import difflib
import functools
import os
import re
import warnings
from dataclasses import dataclass, field
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

from ..timeline import PHONEME, Segment, Timeline
from .audio import SAMPLE_RATE, load_audio
from .lexicon import _add_stress, lookup_missing, normalise_transcript, pronounce

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["Alignment", "align", "align_samples", "AlignmentWarning", "MissingWordsWarning",
           "read_transcript", "VERSION"]

#: Bumped when alignment results change (part of any cache key).
VERSION = 1

#: pocketsphinx's frame shift (its -frate is 100 frames per second).
FRAME_S = 0.01
_SAMPLES_PER_FRAME = int(SAMPLE_RATE * FRAME_S)

#: Longest stretch aligned in one search. Measured on 2 cores: 27 s align in 0.4 s, 107 s in
#: 2.8 s, 214 s in 9.3 s (quadratic); 30 s keeps each search near its linear regime while
#: leaving few cuts (each cut risks splitting a word when a speaker never pauses).
MAX_CHUNK_S = 30.0
#: A chunk is cut no earlier than this, so that the quietest place is looked for in the
#: last (MAX - MIN) seconds and chunks do not become tiny.
MIN_CHUNK_S = 10.0
#: Width of the window whose energy picks a cut: about one short pause between words.
CUT_WINDOW_S = 0.2

#: Audio whose loudest 10 ms frame is below this level (dB re full scale) holds no speech:
#: quiet room tone sits around -60 dBFS and even whispered speech peaks above -40 dBFS.
SILENCE_DBFS = -50.0

#: Shift added to every boundary pocketsphinx reports, in seconds. See
#: :func:`_boundary_offset` for the measurement and reasoning.
BOUNDARY_OFFSET_S = 0.0

#: Below this confidence a transcript is reported as not fitting the audio.
LOW_CONFIDENCE = 0.5

# pocketsphinx's names for silence and noise: words and phones that are not speech.
_NON_SPEECH_WORDS = frozenset({"<s>", "</s>", "<sil>", "[noise]", "[speech]", "<unk>"})
_NON_SPEECH_PHONES = frozenset({"SIL", "+NSN+", "+SPN+", "+BREATH+", "+NOISE+"})
_VARIANT = re.compile(r"\(\d+\)$")

# Recognition (no transcript) search settings, chosen on the MFA corpus recording for
# speed at unchanged viseme agreement (see lipsync/bench/align.py): the second flat-lexicon
# pass (fwdflat) costs about half the time and changed few words; the lattice best path
# adds little; narrower beams than pocketsphinx's defaults (1e-48) prune hopeless paths.
RECOGNISER_SETTINGS = dict(fwdflat=False, bestpath=True, beam=1e-40, pbeam=1e-40, wbeam=1e-30,
                           maxhmmpf=10000)


class AlignmentWarning(UserWarning):
    """The transcript does not fit the audio well (the message gives a confidence figure)."""


class MissingWordsWarning(UserWarning):
    """Words missing from the dictionary were given letter-to-sound pronunciations."""


@dataclass(frozen=True)
class Alignment:
    """Words and phones of a recording, with times in seconds.

    Attributes
    ----------
    words : Timeline
        Lowercase words; silence is gaps.
    phones : Timeline
        ARPAbet phones with (estimated) stress digits; silence is gaps.
    duration : float
        Seconds of audio (both timelines state it as their end).
    transcript : tuple of str
        The words that were aligned (normalised transcript, or what was recognised).
    recognised : bool
        True if the words came from recognition (no transcript, or one that did not fit).
    confidence : float or None
        For a transcript: the share of its words that fit the audio (0..1).
    missing : tuple of str
        Transcript words that needed the letter-to-sound fallback.
    """

    words: Timeline
    phones: Timeline
    duration: float
    transcript: Tuple[str, ...] = ()
    recognised: bool = False
    confidence: Optional[float] = None
    missing: Tuple[str, ...] = field(default=())


# --- decoders (one of each kind per process, loading the model takes ~0.5 s) --------------

@functools.lru_cache(maxsize=1)
def _aligner():
    from pocketsphinx import Decoder

    return Decoder(lm=None, loglevel="FATAL")


@functools.lru_cache(maxsize=1)
def _recogniser():
    from pocketsphinx import Decoder

    return Decoder(loglevel="FATAL", **RECOGNISER_SETTINGS)


def _ensure_words(decoder, words: Sequence[str]) -> None:
    for w in lookup_missing(words):
        if decoder.lookup_word(w) is None:
            decoder.add_word(w, " ".join(p.rstrip("012") for p in pronounce(w)), True)


def _decode(decoder, pcm: np.ndarray) -> None:
    decoder.start_utt()
    decoder.process_raw(np.ascontiguousarray(pcm, dtype=np.int16).tobytes(), full_utt=True)
    decoder.end_utt()


# --- audio analysis -------------------------------------------------------------------------

def _frame_energy(pcm: np.ndarray) -> np.ndarray:
    """dBFS of every 10 ms frame."""
    n = len(pcm) // _SAMPLES_PER_FRAME
    if n == 0:
        return np.zeros(0)
    x = pcm[: n * _SAMPLES_PER_FRAME].astype(np.float32).reshape(n, _SAMPLES_PER_FRAME) / 32768.0
    rms = np.sqrt(np.mean(x * x, axis=1) + 1e-12)
    return 20 * np.log10(rms)


def _plan_chunks(energy: np.ndarray) -> List[Tuple[int, int]]:
    """(start, end) frame ranges of at most MAX_CHUNK_S, cut at the quietest CUT_WINDOW_S."""
    n = len(energy)
    max_f, min_f = int(MAX_CHUNK_S / FRAME_S), int(MIN_CHUNK_S / FRAME_S)
    win = max(1, int(CUT_WINDOW_S / FRAME_S))
    # mean power in a window starting at each frame (cumulative sums: linear time)
    power = np.concatenate([[0.0], np.cumsum(10 ** (energy / 10))])
    chunks, start = [], 0
    while n - start > max_f:
        lo, hi = start + min_f, start + max_f - win
        sums = power[lo + win: hi + win + 1] - power[lo: hi + 1]
        cut = lo + int(np.argmin(sums)) + win // 2
        chunks.append((start, cut))
        start = cut
    chunks.append((start, n))
    return chunks


#: Amplitude (in 16-bit steps) of the noise added before decoding. Digital silence (exact
#: zeros, as synthesisers and editors write it) has no spectrum: its features are log(0)
#: clamps that derail pocketsphinx's noise removal and mean normalisation, and the align
#: search then fails on clean speech (measured on samples/hello.wav). Two steps (-84 dBFS)
#: is far below any recording's noise floor; a fixed seed keeps results reproducible.
DITHER_STEPS = 2


def _dither(pcm: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(0)
    noise = rng.integers(-DITHER_STEPS, DITHER_STEPS + 1, len(pcm), dtype=np.int32)
    return np.clip(pcm.astype(np.int32) + noise, -32768, 32767).astype(np.int16)


# --- one chunk ------------------------------------------------------------------------------

_WordTiming = Tuple[str, int, int, List[Tuple[str, int, int]]]  # word, start, end (frames), phones


def _force_align(pcm: np.ndarray, words: Sequence[str]) -> Optional[List[_WordTiming]]:
    """Word and phone frames of ``words`` in ``pcm``, or None if the search finds no path."""
    if not words:
        return []
    d = _aligner()
    _ensure_words(d, words)
    try:
        d.set_align_text(" ".join(words))
    except RuntimeError:
        return None
    try:
        # end_utt raises when the align search reaches the end of the audio without
        # reaching the end of the words: the transcript does not fit this audio.
        _decode(d, pcm)
        if d.hyp() is None:
            return None
        d.set_alignment()
        _decode(d, pcm)
    except RuntimeError:
        return None
    al = d.get_alignment()
    if al is None:
        return None
    out: List[_WordTiming] = []
    for w in al:
        name = _VARIANT.sub("", w.name).lower()
        if name in _NON_SPEECH_WORDS:
            continue
        phones = [(p.name, p.start, p.start + p.duration) for p in w if p.name not in _NON_SPEECH_PHONES]
        if phones:
            out.append((name, w.start, w.start + w.duration, phones))
    return out


def _recognise(pcm: np.ndarray) -> List[str]:
    """Words pocketsphinx hears in ``pcm`` (language-model search)."""
    d = _recogniser()
    _decode(d, pcm)
    hyp = d.hyp()
    if hyp is None:
        return []
    return [w for w in (_VARIANT.sub("", s).lower() for s in hyp.hypstr.split()) if w not in _NON_SPEECH_WORDS]


def _share_words(transcript: Sequence[str], heard: Sequence[Sequence[str]]) -> List[List[str]]:
    """Share the transcript's words among chunks by matching them to the words heard in each.

    Matched words go to the chunk they were heard in; unmatched ones go with the matched
    word before them (or, at the start, after them), so word order is kept.
    """
    flat = [(w, c) for c, ws in enumerate(heard) for w in ws]
    owner: List[Optional[int]] = [None] * len(transcript)
    sm = difflib.SequenceMatcher(None, list(transcript), [w for w, _ in flat], autojunk=False)
    for a, b, size in sm.get_matching_blocks():
        for k in range(size):
            owner[a + k] = flat[b + k][1]
    last = next((o for o in owner if o is not None), 0)
    shared: List[List[str]] = [[] for _ in heard]
    for w, o in zip(transcript, owner):
        last = o if o is not None and o >= last else last
        shared[last].append(w)
    return shared


def _heard_share(transcript: Sequence[str], heard: Sequence[str]) -> float:
    if not transcript:
        return 1.0
    sm = difflib.SequenceMatcher(None, list(transcript), list(heard), autojunk=False)
    return sum(size for _, _, size in sm.get_matching_blocks()) / len(transcript)


# --- the public functions -------------------------------------------------------------------

def read_transcript(text: Optional[str]) -> Optional[str]:
    """The transcript a ``--text`` value names: a file's contents if it is a file, else itself.

    An empty or blank transcript is None (no transcript: words are recognised).

    Examples
    --------
    >>> read_transcript("Hello there."), read_transcript("   "), read_transcript(None)
    ('Hello there.', None, None)
    """
    if text is None:
        return None
    if len(text) < 4096 and "\n" not in text and os.path.isfile(text):
        from ..errors import InputError

        try:
            with open(text, "rb") as f:
                raw = f.read()
            text = raw.decode("utf-8-sig")
        except UnicodeDecodeError:
            raise InputError("transcript is not UTF-8 text", path=text) from None
        except OSError as exc:
            raise InputError(f"cannot read transcript: {exc.strerror or exc}", path=text) from None
    return text if text.strip() else None


def align_samples(pcm: np.ndarray, text: Optional[str] = None, *, quiet: bool = True,
                  path: Optional[str] = None) -> Alignment:
    """Align 16 kHz mono int16 samples with an optional transcript.

    Parameters
    ----------
    pcm : numpy.ndarray
        Samples at :data:`~lipsync.speech.audio.SAMPLE_RATE` (int16, or floats in -1..1).
    text : str, optional
        The transcript as written; None or blank: recognise the words.
    quiet : bool
        No progress bar.
    path : str, optional
        Name used in messages and in the timelines.

    Returns
    -------
    Alignment

    Examples
    --------
    >>> import numpy as np
    >>> al = align_samples(np.zeros(16000, np.int16), "hello")   # one second of silence
    >>> len(al.words), len(al.phones), al.duration
    (0, 0, 1.0)
    """
    from tqdm import tqdm

    pcm = np.asarray(pcm)
    if pcm.dtype.kind == "f":
        pcm = np.clip(np.round(pcm * 32767.0), -32768, 32767).astype(np.int16)
    pcm = pcm.astype(np.int16, copy=False).reshape(-1)
    duration = len(pcm) / SAMPLE_RATE
    text = text if text is not None and text.strip() else None
    transcript = tuple(normalise_transcript(text)) if text is not None else ()
    if text is not None and not transcript:
        text = None  # punctuation only: no words to align
    missing = tuple(lookup_missing(transcript))
    if missing:
        warnings.warn(f"{path or 'transcript'}: {len(missing)} word(s) not in the dictionary, "
                      f"pronounced by letter-to-sound rules: {', '.join(missing)}",
                      MissingWordsWarning, stacklevel=2)
    energy = _frame_energy(pcm)
    empty = Alignment(_timeline((), duration, path), _timeline((), duration, path), duration,
                      transcript=transcript, recognised=text is None, missing=missing)
    if len(energy) == 0 or float(energy.max()) < SILENCE_DBFS:
        return empty

    chunks = _plan_chunks(energy)
    pcm = _dither(pcm)
    spf = _SAMPLES_PER_FRAME
    bar = tqdm(total=len(chunks) * (2 if (text is None or len(chunks) > 1) else 1), desc="align",
               unit="step", disable=quiet, leave=False)
    try:
        heard: List[List[str]] = []
        if text is None or len(chunks) > 1:
            for a, b in chunks:
                heard.append(_recognise(pcm[a * spf: b * spf]))
                bar.update()
        if text is None:
            words_per_chunk = heard
        elif len(chunks) == 1:
            words_per_chunk = [list(transcript)]
        else:
            words_per_chunk = _share_words(transcript, heard)
        timings: List[_WordTiming] = []
        failed: List[int] = []
        for i, ((a, b), words) in enumerate(zip(chunks, words_per_chunk)):
            got = _force_align(pcm[a * spf: b * spf], words)
            if got is None and text is not None:
                failed.append(i)
                if not heard:
                    heard = [_recognise(pcm[a * spf: b * spf])]
                got = _force_align(pcm[a * spf: b * spf], heard[i]) or []
            for w, ws, we, phones in got or []:
                timings.append((w, ws + a, we + a, [(p, ps + a, pe + a) for p, ps, pe in phones]))
            bar.update()
    finally:
        bar.close()

    confidence = None
    if text is not None:
        if heard:
            confidence = _heard_share(transcript, [w for ws in heard for w in ws])
        else:
            confidence = 1.0
        if failed:
            # Chunks whose transcript share could not be aligned count as not fitting at all.
            fitted = sum(len(words_per_chunk[i]) for i in range(len(chunks)) if i not in failed)
            confidence = min(confidence, fitted / max(1, len(transcript)))
        if failed or confidence < LOW_CONFIDENCE:
            where = "" if len(chunks) == 1 else f" in {len(failed)} of {len(chunks)} chunks"
            what = (f"could not be aligned{where}; the words recognised there were used instead"
                    if failed else "fits the audio poorly; the alignment is a best effort")
            warnings.warn(f"{path or 'audio'}: the transcript {what} (confidence {confidence:.2f}: "
                          "the share of its words that fit the audio)", AlignmentWarning, stacklevel=2)
    return _to_alignment(timings, duration, path, transcript if text is not None else
                         tuple(w for w, *_ in timings), recognised=text is None or bool(failed),
                         confidence=confidence, missing=missing)


def align(audio: Union[PathLike, np.ndarray], text: Optional[str] = None, *, quiet: bool = True) -> Alignment:
    """Words and phones of a recording, with or without its transcript.

    Parameters
    ----------
    audio : path-like or numpy.ndarray
        Any file ffmpeg reads (converted to 16 kHz mono), or 16 kHz mono samples.
    text : str, optional
        The transcript, or a path to a UTF-8 text file holding it. None or blank: the words
        are recognised first.
    quiet : bool
        No progress bar.

    Returns
    -------
    Alignment

    Raises
    ------
    lipsync.speech.audio.AudioError
        The audio file cannot be read (the message names it).

    Examples
    --------
    >>> import os, warnings
    >>> from lipsync._data import default_bank_dir
    >>> wav = os.path.join(default_bank_dir(), "..", "..", "samples", "hello.wav")
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")       # "lipsync" is not in the dictionary
    ...     al = align(wav, "Hello, I am a talking head made by lipsync.")
    >>> al.words.labels()
    ['hello', 'i', 'am', 'a', 'talking', 'head', 'made', 'by', 'lipsync']
    >>> al.phones.labels()[:4]
    ['HH', 'AH0', 'L', 'OW1']
    """
    path = None
    if isinstance(audio, np.ndarray):
        pcm = audio
    else:
        path = os.fspath(audio)
        pcm = load_audio(path)
    return align_samples(pcm, read_transcript(text), quiet=quiet, path=path)


def _timeline(segments, duration: float, path: Optional[str]) -> Timeline:
    return Timeline(tuple(segments), kind=PHONEME, path=path, stated_end=duration)


def _to_alignment(timings: List[_WordTiming], duration: float, path: Optional[str], transcript,
                  **kw) -> Alignment:
    def t(frame: int) -> float:
        # rounded to 1 us so files show 0.82, not 0.8200000000000001 (frames are 10 ms)
        return min(max(round(frame * FRAME_S + BOUNDARY_OFFSET_S, 6), 0.0), duration)

    words, phones = [], []
    for w, ws, we, ph in timings:
        start, end = t(ws), t(we)
        if end > start and (not words or start >= words[-1].end):
            words.append(Segment(start, end, w))
        stressed = _add_stress([p for p, _, _ in ph])
        for label, (_, ps, pe) in zip(stressed, ph):
            s, e = t(ps), t(pe)
            if phones:
                s = max(s, phones[-1].end)
            if e > s:
                phones.append(Segment(s, e, label))
    return Alignment(_timeline(words, duration, path), _timeline(phones, duration, path), duration,
                     transcript=tuple(transcript), **kw)


