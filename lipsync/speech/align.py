"""Forced alignment with pocketsphinx: speech (and optionally its transcript) -> words and phones.

The stages, each a function over plain values::

    load_audio -> _frame_energy -> [_plan_chunks: cut at the quietest places]
    -> per chunk: [_recognise] or [_fitting_words] -> _force_align (words, then phones)
    -> Alignment (words and phones timelines over the whole audio)

* With a transcript, the words are normalised (:func:`normalise_transcript`), words the
  dictionary lacks get a pronunciation from :func:`pronounce` (listed in one warning), and
  pocketsphinx aligns them (its align search, then a state-level second pass for phones).
* Without one, the words are recognised first with pocketsphinx's US-English language
  model (in chunks of :data:`RECOGNITION_CHUNK_S`, in worker processes when there are
  several), then their phones are aligned inside the recognised word boundaries.
* pocketsphinx's alignment search grows faster than linearly with utterance length
  (measured: 0.42 s for 27 s of speech, 9.3 s for 214 s), so a transcribed recording longer
  than :data:`MAX_CHUNK_S` is cut at its quietest places into chunks, and each chunk takes
  the next transcript words that fit it (:func:`_align_long`). Time and memory then grow
  linearly with the audio.
* A transcript that does not fit: a second search may skip any of its words
  (:func:`_fitting_words`); if even that fails, the recognised words are used. Either way
  a warning gives a confidence figure. Silence-only audio gives empty timelines spanning
  the audio.

Examples
--------
>>> import numpy as np
>>> al = align(np.zeros(8000, np.int16))         # half a second of digital silence
>>> al.duration, len(al.words), len(al.phones)
(0.5, 0, 0)
"""

from __future__ import annotations

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
#: A chunk is cut no earlier than this share of its longest length: the quietest place is
#: looked for in the last 60% of the window, so chunks do not become tiny.
MIN_CHUNK_FRACTION = 0.4
#: Width of the window whose energy picks a cut: about one short pause between words.
CUT_WINDOW_S = 0.2

#: Audio whose loudest 10 ms frame is below this level (dB re full scale) holds no speech:
#: quiet room tone sits around -60 dBFS and even whispered speech peaks above -40 dBFS.
SILENCE_DBFS = -50.0

#: Shift added to every boundary pocketsphinx reports, in seconds: none. Measured: against
#: the espeak-ng samples' exact phone times the median boundary is 9.5 and 11.1 ms early
#: (about one frame: a boundary reported at frame i lies between the centres of frames i-1
#: and i, which sit 7.8 ms later with 25.6 ms windows), but against MFA, whose Kaldi frames
#: follow the same convention, the median is 0 and a +10 ms shift raises the mean error from
#: 17.7 to about 23 ms. A mouth 10 ms ahead of its sound is also far below what viewers
#: notice (ITU-R BT.1359: sound lagging picture is detected from about 125 ms), so the
#: frame-centre correction is not applied.
BOUNDARY_OFFSET_S = 0.0

#: Below this confidence a transcript is reported as not fitting the audio.
LOW_CONFIDENCE = 0.5
#: Share of a long transcript's words that may go unfound without a warning.
SKIPPED_SHARE_OK = 0.08
#: Frames within this many dB of the loudest are counted as speech by the confidence check:
#: vowels and voiced consonants sit within 25 dB of a recording's peak, breaths and room
#: noise in pauses below it.
SPEECH_BELOW_PEAK_DB = 25.0
#: Chunk length for recognition. Longer chunks give the language model more context: on
#: the MFA recording 6 s chunks gave 76.6% of frames the right mouth shape, 10 s 79.9%,
#: 14 s 82.6%; 15 s still splits half a minute of speech between two cores.
RECOGNITION_CHUNK_S = 15.0
#: From this many chunks on, they are decoded in worker processes: a worker's start and
#: model load (about 1 s) is small against 15 s of recognition (about 4 s of CPU).
MIN_CHUNKS_FOR_WORKERS = 2

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

    Examples
    --------
    >>> from lipsync.timeline import Segment, Timeline
    >>> al = Alignment(Timeline((Segment(0.1, 0.4, "hi"),)), Timeline((Segment(0.1, 0.4, "AY1"),)), 0.5)
    >>> al.words.labels(), round(al.phones[0].duration, 2)
    (['hi'], 0.3)
    """

    words: Timeline
    phones: Timeline
    duration: float
    transcript: Tuple[str, ...] = ()
    recognised: bool = False
    confidence: Optional[float] = None
    missing: Tuple[str, ...] = field(default=())


# --- decoders (one of each kind per process, loading the model takes ~0.5 s) --------------

#: Forced-alignment settings. topn is how many Gaussians of each senone's mixture are scored
#: per frame: pocketsphinx's default of 4 is tuned for recognition speed; 8 brought the mean
#: boundary error against MFA from 18.9 to 17.7 ms (and frames with MFA's mouth shape from
#: 87.1 to 87.9%) for 30% more CPU; 16 and 32 were no better.
ALIGNER_SETTINGS = dict(topn=8)


@functools.lru_cache(maxsize=1)
def _aligner():
    from pocketsphinx import Decoder

    return Decoder(lm=None, loglevel="FATAL", **ALIGNER_SETTINGS)


@functools.lru_cache(maxsize=1)
def _recogniser():
    from pocketsphinx import Decoder

    return Decoder(loglevel="FATAL", **RECOGNISER_SETTINGS)


def _ensure_words(decoder, words: Sequence[str]) -> None:
    for w in lookup_missing(words):
        if decoder.lookup_word(w) is None:
            decoder.add_word(w, " ".join(p.rstrip("012") for p in pronounce(w)), True)


def _decode(decoder, pcm: np.ndarray) -> None:
    # Fresh feature state for every utterance: pocketsphinx's noise removal carries its noise
    # estimate over from the previous utterance, so without this the same audio decoded
    # twice (or after another chunk) gave different words.
    decoder.reinit_feat()
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


def _plan_chunks(energy: np.ndarray, max_s: float = MAX_CHUNK_S) -> List[Tuple[int, int]]:
    """(start, end) frame ranges of at most ``max_s``, cut at the quietest CUT_WINDOW_S."""
    n = len(energy)
    max_f, min_f = int(max_s / FRAME_S), int(max_s * MIN_CHUNK_FRACTION / FRAME_S)
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


def _timings(al) -> List[_WordTiming]:
    out: List[_WordTiming] = []
    for w in al:
        name = _VARIANT.sub("", w.name).lower()
        if name in _NON_SPEECH_WORDS:
            continue
        phones = [(p.name, p.start, p.start + p.duration) for p in w if p.name not in _NON_SPEECH_PHONES]
        if phones:
            out.append((name, w.start, w.start + w.duration, phones))
    return out


def _force_align(pcm: np.ndarray, words: Sequence[str]) -> Optional[List[_WordTiming]]:
    """Word and phone frames of ``words`` in ``pcm``, or None if the search finds no path."""
    if not words:
        return []
    d = _aligner()
    _ensure_words(d, words)
    try:
        d.set_align_text(" ".join(words))
        # end_utt raises when the align search reaches the end of the audio without
        # reaching the end of the words: the transcript does not fit this audio.
        _decode(d, pcm)
        if d.hyp() is None:
            return None
        d.set_alignment()  # second pass: phone and state boundaries within the words found
        _decode(d, pcm)
    except RuntimeError:
        return None
    al = d.get_alignment()
    return None if al is None else _timings(al)


#: Probability of skipping a transcript word in the tolerant pass (:func:`_fitting_words`).
#: Low, so that a word that is spoken is kept; measured on the MFA recording with 10% of its
#: words replaced: 51 of 59 words kept, 82% of frames still show MFA's mouth shape.
SKIP_PROB = 0.02


#: In a window search (:func:`_fitting_words` with ``prefix=True``), the probability of
#: ending after any word: small, so that the search prefers to use words over leaving them.
END_PROB = 1e-4


def _fitting_words(pcm: np.ndarray, words: Sequence[str], *, prefix: bool = False) -> List[int]:
    """Indices of the transcript words that fit the audio, found by a search that may skip any word.

    A grammar in which every word is optional (with :data:`SKIP_PROB`) keeps the order of
    the transcript but lets words that are not spoken fall out; extra speech is absorbed by
    pocketsphinx's noise and silence fillers. With ``prefix``, the grammar may also end
    after any word: the words of a long transcript that this stretch of audio holds.
    """
    if not words:
        return []
    d = _aligner()
    _ensure_words(d, words)
    n = len(words)
    transitions = []
    for i, w in enumerate(words):
        transitions += [(i, i + 1, 1.0 - SKIP_PROB, w), (i, i + 1, SKIP_PROB)]
        if prefix and i > 0:
            transitions.append((i, n, END_PROB))
    try:
        d.add_fsg("fit", d.create_fsg("fit", 0, n, transitions))
        d.activate_search("fit")
        _decode(d, pcm)
        heard = [w for w in (_VARIANT.sub("", s.word).lower() for s in d.seg()) if w not in _NON_SPEECH_WORDS]
    except (RuntimeError, ValueError, TypeError):
        return []
    kept, i = [], 0
    for w in heard:  # the grammar keeps order, so each heard word is the next such word
        while i < n and words[i] != w:
            i += 1
        if i < n:
            kept.append(i)
            i += 1
    return kept


def _align_words(pcm: np.ndarray, words: Sequence[str]) -> Tuple[Optional[List[_WordTiming]], int]:
    """(timings, words skipped): strict alignment, else alignment of the words that fit."""
    got = _force_align(pcm, words)
    if got is not None or not words:
        return got, 0
    kept = [words[i] for i in _fitting_words(pcm, words)]
    got = _force_align(pcm, kept) if kept else None
    return got, len(words) - len(kept)


def _recognise(pcm: np.ndarray) -> Tuple[List[str], List[_WordTiming]]:
    """Words pocketsphinx hears in ``pcm`` (language-model search), and their phone alignment.

    The second pass aligns the phones inside the recognised word boundaries (the same state
    alignment as for a transcript), so recognised words never fail to align.
    """
    d = _recogniser()
    try:
        _decode(d, pcm)
        hyp = d.hyp()
        if hyp is None or not hyp.hypstr.strip():
            return [], []
        heard = [w for w in (_VARIANT.sub("", s).lower() for s in hyp.hypstr.split())
                 if w not in _NON_SPEECH_WORDS]
        try:
            d.set_alignment()
            _decode(d, pcm)
            al = d.get_alignment()
        except RuntimeError:
            al = None
        if al is None:
            # no phone pass: word times from the search, phones shared evenly within each
            return heard, [_even_phones(s.word, s.start_frame, s.end_frame + 1) for s in d.seg()
                           if _VARIANT.sub("", s.word).lower() not in _NON_SPEECH_WORDS]
        return heard, _timings(al)
    finally:
        d.activate_search("_default")  # back to the language model for the next chunk


def _even_phones(word: str, start: int, end: int) -> _WordTiming:
    word = _VARIANT.sub("", word).lower()
    phones = [p.rstrip("012") for p in pronounce(word)] or ["AH"]
    edges = np.linspace(start, end, len(phones) + 1).round().astype(int)
    return word, start, end, [(p, int(a), int(b)) for p, a, b in zip(phones, edges[:-1], edges[1:])]


def _chunk_job(job):
    """One chunk's work, ("recognise", pcm): runs in a worker process."""
    return _recognise(job[1])


def _can_fork() -> bool:
    """True if worker processes may be forked: a POSIX main thread with no other threads.

    Forking copies only the calling thread, so a lock another thread holds (a server's, a
    logging handler's) stays locked in the child forever. tqdm's monitor thread is allowed:
    the children never touch tqdm. spawn and forkserver are not used instead because they
    re-run the caller's main script in each worker, which breaks scripts that embed lipsync
    without an ``if __name__ == "__main__"`` guard.
    """
    import multiprocessing
    import threading

    from tqdm import tqdm

    if "fork" not in multiprocessing.get_all_start_methods():
        return False
    if threading.current_thread() is not threading.main_thread():
        return False
    monitor = getattr(tqdm, "monitor", None)
    return all(t is threading.main_thread() or t is monitor for t in threading.enumerate())


def _run_jobs(jobs: list, workers: int, bar) -> list:
    """Results of :func:`_chunk_job` in order, in ``workers`` processes when it pays and is safe."""
    if workers <= 1 or len(jobs) <= 1 or not _can_fork():
        out = []
        for job in jobs:
            out.append(_chunk_job(job))
            bar.update()
        return out
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    # Forked workers start in milliseconds with the modules (and any decoder this process
    # already loaded) in place; pocketsphinx decoders are not shared, each has its copy.
    from .._proc import die_with_parent

    context = multiprocessing.get_context("fork")
    results: list = [None] * len(jobs)
    # A worker killed with its parent still decodes its chunk, then waits on the task queue
    # for ever: it ends with the parent instead (issue 19). Forked from the main thread
    # (_can_fork), which PR_SET_PDEATHSIG watches.
    with ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=context,
                             initializer=die_with_parent, initargs=(os.getpid(),)) as pool:
        futures = {pool.submit(_chunk_job, job): i for i, job in enumerate(jobs)}
        from concurrent.futures import as_completed

        for fut in as_completed(futures):
            results[futures[fut]] = fut.result()
            bar.update()
    return results


#: A chunk of a long transcribed recording is searched for the next words of the transcript
#: in a window of this many times the words expected at the recording's speaking rate, plus
#: :data:`WINDOW_MARGIN` words: room for a speaker who speeds up, without making the search
#: (and its time) grow with the transcript.
WINDOW_FACTOR = 2.0
WINDOW_MARGIN = 20


def _align_long(piece, chunks, transcript, energy, bar):
    """Align a long transcript chunk by chunk, each taking the next words that fit it.

    Returns (timings per chunk, words skipped, words that could not be aligned).
    """
    loud = energy > max(float(energy.max()) - SPEECH_BELOW_PEAK_DB, SILENCE_DBFS)
    rate = len(transcript) / max(float(loud.sum()) * FRAME_S, 1.0)  # words per second of speech
    bar.total = len(chunks)
    bar.refresh()
    per_chunk, pointer, skipped, failed = [], 0, 0, 0
    for i, (a, b) in enumerate(chunks):
        last = i == len(chunks) - 1
        speech_s = float(loud[a:b].sum()) * FRAME_S
        size = len(transcript) if last else int(WINDOW_FACTOR * rate * speech_s) + WINDOW_MARGIN
        window = transcript[pointer: pointer + size]
        kept_at = _fitting_words(piece(a, b), window, prefix=not last)
        consumed = kept_at[-1] + 1 if kept_at else 0
        skipped += consumed - len(kept_at)
        pointer += consumed
        kept = [window[j] for j in kept_at]
        got = _force_align(piece(a, b), kept) if kept else []
        if got is None:  # the words found do not align after all: what is heard there
            failed += len(kept)
            got = _recognise(piece(a, b))[1]
        per_chunk.append(got)
        bar.update()
    skipped += len(transcript) - pointer
    return per_chunk, skipped, failed


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
                  path: Optional[str] = None, jobs: Optional[int] = None) -> Alignment:
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
    jobs : int, optional
        Processes for long or untranscribed audio (default: all cores).

    Returns
    -------
    Alignment

    Warns
    -----
    MissingWordsWarning
        Transcript words not in the dictionary (one warning listing them all).
    AlignmentWarning
        The transcript does not fit the audio; gives the confidence figure.

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
    workers = max(1, jobs if jobs is not None else (os.cpu_count() or 1))
    transcript = tuple(normalise_transcript(text)) if text is not None else ()
    has_text = bool(transcript)  # blank or punctuation only: no words, so recognise
    missing = tuple(lookup_missing(transcript))
    if missing:
        warnings.warn(f"{path or 'transcript'}: {len(missing)} word(s) not in the dictionary, "
                      f"pronounced by letter-to-sound rules: {', '.join(missing)}",
                      MissingWordsWarning, stacklevel=2)
    energy = _frame_energy(pcm)
    if len(energy) == 0 or float(energy.max()) < SILENCE_DBFS:
        return Alignment(_timeline((), duration, path), _timeline((), duration, path), duration,
                         transcript=transcript, recognised=not has_text, missing=missing)
    pcm = _dither(pcm)
    spf = _SAMPLES_PER_FRAME

    def piece(a: int, b: int) -> np.ndarray:
        return pcm[a * spf: b * spf]

    timings: List[_WordTiming] = []
    failed = skipped = 0
    bar = tqdm(total=1, desc="align", unit="chunk", disable=quiet, leave=False)
    try:
        whole = None
        if has_text and duration <= MAX_CHUNK_S:
            whole, skipped = _align_words(pcm, transcript)
        strict_failed = has_text and skipped > 0
        if whole is not None:
            timings = whole
            bar.update()
        else:
            if has_text and duration > MAX_CHUNK_S:
                chunks = _plan_chunks(energy, MAX_CHUNK_S)
                per_chunk, skipped, failed = _align_long(piece, chunks, transcript, energy, bar)
            else:
                # No transcript, or a short one that does not fit at all: recognise chunk by
                # chunk (in parallel when there are enough), then align what was heard.
                chunks = _plan_chunks(energy, RECOGNITION_CHUNK_S)
                bar.total = len(chunks)
                bar.refresh()
                workers = workers if len(chunks) >= MIN_CHUNKS_FOR_WORKERS else 1
                per_chunk = [t for _, t in _run_jobs([("recognise", piece(a, b)) for a, b in chunks], workers, bar)]
                failed, skipped = len(transcript), 0
            for (a, _), got in zip(chunks, per_chunk):
                timings += [(w, ws + a, we + a, [(p, ps + a, pe + a) for p, ps, pe in ph])
                            for w, ws, we, ph in got]
    finally:
        bar.close()

    confidence = None
    if has_text:
        fitted = 1.0 - (failed + skipped) / len(transcript)
        confidence = min(fitted, _speech_in_words(energy, timings))
        # In a long recording a few words at chunk cuts may go unfound even when the
        # transcript is right (12 of 236 on the MFA recording four times over), so there
        # only a larger share counts as not fitting.
        if failed or strict_failed or skipped > SKIPPED_SHARE_OK * len(transcript) or confidence < LOW_CONFIDENCE:
            what = "does not fit the audio"
            if skipped:
                what += f": {skipped} of its {len(transcript)} words were not found and were left out"
            if failed:
                what += (f"{',' if skipped else ':'} {failed} of its {len(transcript)} words could not be "
                         "aligned, and the words recognised there were used instead")
            if not (failed or skipped):
                what = "fits the audio poorly; the alignment is a best effort"
            warnings.warn(f"{path or 'audio'}: the transcript {what} (confidence {confidence:.2f}: the "
                          "smaller of the share of its words found and the share of the speech they cover)",
                          AlignmentWarning, stacklevel=2)
    return _to_alignment(timings, duration, path, transcript if has_text else tuple(w for w, *_ in timings),
                         recognised=not has_text or failed > 0, confidence=confidence, missing=missing)


def _speech_in_words(energy: np.ndarray, timings: List[_WordTiming]) -> float:
    """Share of the loud frames (speech) that lie inside aligned words.

    A transcript that fits covers nearly all speech with words (0.88 on the MFA corpus
    recording, whose pauses hold breaths; 0.99 on the espeak samples); half a transcript
    covers 0.32, one word of a sentence 0.07. Measured with :data:`SPEECH_BELOW_PEAK_DB`.
    """
    speech = energy > max(float(energy.max()) - SPEECH_BELOW_PEAK_DB, SILENCE_DBFS)
    inside = np.zeros(len(energy), bool)
    for _, ws, we, _ in timings:
        inside[ws:we] = True
    return float(inside[speech].mean()) if speech.any() else 1.0


def align(audio: Union[PathLike, np.ndarray], text: Optional[str] = None, *, quiet: bool = True,
          jobs: Optional[int] = None) -> Alignment:
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
    jobs : int, optional
        Processes for long or untranscribed audio (default: all cores).

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
    return align_samples(pcm, read_transcript(text), quiet=quiet, path=path, jobs=jobs)


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


