"""Forced alignment with pocketsphinx: speech (and optionally its transcript) -> words and phones.

The stages, each a function over plain values::

    load_audio -> _frame_energy -> [_plan_chunks: cut at the quietest places]
    -> per chunk: [_recognise] or [_fitting_words] -> _force_align (words, then phones)
    -> [_phone_loop_scores -> _acoustic_fit: does the transcript fit?]
    -> _cap_pause_closures -> Alignment (words and phones timelines over the whole audio)

* With a transcript, the words are normalised (:func:`normalise_transcript`), words the
  dictionary lacks get a pronunciation from :func:`pronounce` (listed in one warning), and
  pocketsphinx aligns them: a grammar of exactly the transcript's words, each with its
  pronunciations (:func:`~lipsync.speech.lexicon.pronunciations`), silence and noise
  allowed between them, which cannot return other words (:func:`_force_align`); then a
  state-level second pass places the phones inside the words found.
* How well the transcript fits is measured against what the audio holds without it: the
  acoustic score of the aligned words per frame against a free phone loop's over the same
  frames (:func:`_acoustic_fit`). A transcript that aligns keeps its alignment, and the
  confidence figure says how well it fits; only one that really does not fit (no path, or
  a fit below :data:`NOT_FIT_CONFIDENCE`) goes the relaxed way below. The phone loop costs
  nearly as much CPU as the alignment, so it is decoded only when the words' scores in
  their own search leave doubt (:data:`FIT_WITHOUT_LOOP`), and then in a forked worker
  beside the phone pass when there are two or more jobs (:class:`_PhoneLoop`).
  (Recordings longer than :data:`MAX_CHUNK_S` are judged by the share of their words found
  instead.)
* Without one, the words are recognised first with pocketsphinx's US-English language
  model (in chunks of :data:`RECOGNITION_CHUNK_S`, in worker processes when there are
  several), then their phones are aligned inside the recognised word boundaries.
* pocketsphinx's alignment search grows faster than linearly with utterance length
  (measured: 0.42 s for 27 s of speech, 9.3 s for 214 s), so a transcribed recording longer
  than :data:`MAX_CHUNK_S` is cut at its quietest places into chunks, and each chunk takes
  the next transcript words that fit it (:func:`_align_long`). Time and memory then grow
  linearly with the audio.
* A transcript that does not fit: a second search may skip any of its words
  (:func:`_fitting_words`; the warning names the words left out); if even that fails, the
  recognised words are used. Either way a warning gives a confidence figure. Silence-only
  audio gives empty timelines spanning the audio.
* A stop (P B T D K G) after a pause starts with a silent closure that no aligner can tell
  from the pause; its length is capped (:data:`MAX_PAUSE_CLOSURE_S`).

Examples
--------
>>> import numpy as np
>>> al = align(np.zeros(8000, np.int16))         # half a second of digital silence
>>> al.duration, len(al.words), len(al.phones)
(0.5, 0, 0)
"""

from __future__ import annotations

import contextvars
import functools
import os
import re
import warnings
from dataclasses import dataclass, field
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

from ..errors import TranscriptMismatch
from ..motion.timeline import PHONEME, Segment, Timeline
from .audio import SAMPLE_RATE, load_audio
from .lexicon import _add_stress, lookup_missing, normalise_transcript, pronounce, pronunciations

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["Alignment", "align", "align_samples", "AlignmentWarning", "TranscriptMismatchWarning", "MissingWordsWarning",
           "read_transcript", "VERSION"]

#: Bumped when alignment results change (part of any cache key).
VERSION = 3

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
#: The same shift for languages other than English: one frame (10 ms) later. Their words
#: are aligned with approximate units, and their figures are measured against espeak-ng's
#: exact phoneme times in 20 languages (``make bench``'s languages figure): the median
#: boundary there is 10.2 ms early, as for English, and at 25 fps this frame decides which
#: mouth shape a frame shows (mean agreement 0.735 unshifted, see the figure's
#: ``text_frames_agree_unshifted`` column). English keeps 0 for its measured reasons above.
BOUNDARY_OFFSET_OTHER_S = 0.01

#: Below this confidence a transcript is reported as not fitting the audio.
LOW_CONFIDENCE = 0.5
#: Below this confidence, with words of it not found, the transcript does not fit at all
#: (TranscriptMismatchWarning; an error on the command line without --allow-mismatch). A
#: transcript all of whose words were found but that covers little of the speech (a
#: partial one) stays an AlignmentWarning. GRID s1, 40 sentences: their own transcripts
#: score 0.60 and up (none refused); another sentence's transcript (one each) is refused 31
#: times of 40 (median confidence 0.00, highest 0.41); one word added 4, the letter left
#: out 1, the first two words alone 0 (those stay warnings: a transcript that is nearly
#: right, or right but partial, is still worth aligning).
NO_FIT_CONFIDENCE = 0.25
#: Below this acoustic fit (:func:`_acoustic_fit`) a transcript whose words all aligned is
#: taken as not what was said, and the relaxed search looks for the words that are there.
#: A fit of 0.2 is a score 6 units a frame below :data:`FIT_LLR_CENTRE` (17 below the free
#: phone loop's); the 40 GRID sentences with their own transcripts measured -8.9 to 4.5
#: against the loop (fit 0.6 to 1), the MFA recording -2.0, the espeak samples -4.9 and -0.5.
NOT_FIT_CONFIDENCE = 0.2
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
_NON_SPEECH_WORDS = frozenset({"<s>", "</s>", "<sil>", "[noise]", "[speech]", "<unk>", "(null)"})
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


class TranscriptMismatchWarning(AlignmentWarning, TranscriptMismatch):
    """The transcript does not fit the audio at all (confidence below :data:`NO_FIT_CONFIDENCE`):
    another recording's script, or the wrong file. ``lipsync`` commands stop on it (exit 2)
    unless ``--allow-mismatch`` is given."""


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
        For a transcript, how well it fits the audio (0..1): the smallest of the share of
        its words found, the share of the speech they cover, and how well their sounds
        match the audio against free phones (:func:`_acoustic_fit`; asked only when the
        words' own scores leave doubt, :data:`FIT_WITHOUT_LOOP`). Below
        :data:`LOW_CONFIDENCE` the transcript is reported as not fitting.
    missing : tuple of str
        Transcript words that needed the letter-to-sound fallback.
    skipped : tuple of str
        Transcript words that were not found in the audio and were left out (in order).

    Examples
    --------
    >>> from lipsync.motion.timeline import Segment, Timeline
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
    skipped: Tuple[str, ...] = field(default=())


# --- decoders (one of each kind per process, loading the model takes ~0.5 s) --------------

#: Forced-alignment settings.
#:
#: * topn is how many Gaussians of each senone's mixture are scored per frame: pocketsphinx's
#:   default of 4 is tuned for recognition speed; 8 brought the mean boundary error against
#:   MFA from 18.9 to 17.7 ms (and frames with MFA's mouth shape from 87.1 to 87.9%) for 30%
#:   more CPU; 16 and 32 were no better.
#: * bestpath off: the word segmentation is the grammar search's own Viterbi path, not a
#:   best path through its lattice. The lattice path begins with a one-frame ``<s>`` at
#:   frame 0 overlapping the first silence whenever that path is chosen, and the phone pass
#:   built from it cannot fit a silence model into one frame ("Failed to reach final state
#:   in alignment"): 5 of the 40 GRID sentences (issue 20) failed so and were replaced by
#:   recognised words; with the search's own path all 40 align.
#: * fsgusealtpron off: the grammars list each word's pronunciations themselves
#:   (:func:`~lipsync.speech.lexicon.pronunciations`: CMUdict's but "wh" = HH W, plus
#:   letter names as said outside the US).
ALIGNER_SETTINGS = dict(topn=8, bestpath=False, fsgusealtpron=False)

#: Name of the fit check's free phone recogniser in the aligner (:func:`_phone_loop_scores`).
_LOOP = "loop"


#: Beams of the aligner for languages other than English (:mod:`lipsync.speech.languages`),
#: whose sounds the en-us models fit less well. Measured on the 26 recordings of ``make
#: bench``'s languages figures (20 espeak-ng sentences, 6 real recordings) with their own
#: transcripts: with pocketsphinx's default beams (1e-48) the grammar search pruned every
#: path of the transcript's words in 9 (all synthetic: no alignment at all), with 1e-80 in
#: 4, with 1e-120 and 1e-200 in none; the search ran at 83, 72, 66 and 63 times real time.
#: 1e-200 leaves a margin (the fit rules below were measured with it).
WIDE_BEAMS = dict(beam=1e-200, pbeam=1e-200, wbeam=1e-200)
#: True while another language is aligned: :func:`_aligner` gives the wide-beam decoder and
#: the fit check takes the other languages' rules (:func:`_fit_rules`).
_WIDE = contextvars.ContextVar("lipsync_other_language", default=False)
#: Probability of a pause: pocketsphinx's optional silence, which every grammar allows
#: before, between and after the words (its ``silprob``, read when a grammar is added).
#: pocketsphinx's own value; a language may set its own
#: (:data:`lipsync.speech.languages.PAUSE_PROB`).
PAUSE_PROB = 0.005
_PAUSE_PROB = contextvars.ContextVar("lipsync_pause_prob", default=PAUSE_PROB)


def _aligner():
    return _aligner_for(_WIDE.get())


@functools.lru_cache(maxsize=2)
def _aligner_for(wide: bool):
    from pocketsphinx import Decoder

    d = Decoder(lm=None, loglevel="FATAL", **ALIGNER_SETTINGS, **(WIDE_BEAMS if wide else {}))
    # pocketsphinx's phone recogniser with no phone language model: any context-independent
    # phone may follow any other (allphone_ci is pocketsphinx's default). Until issue 20's
    # third round the loop was a grammar of the 39 one-phone words, whose cross-word
    # triphones cost 47 ms of CPU per second of audio against 29 for this, and separated
    # right from wrong transcripts no better (see FIT_LLR_CENTRE).
    d.add_allphone_file(_LOOP, None)
    return d


@functools.lru_cache(maxsize=1)
def _recogniser():
    from pocketsphinx import Decoder

    return Decoder(loglevel="FATAL", **RECOGNISER_SETTINGS)


#: Pronunciations (en-us acoustic units) of the words of other languages, by their decoder
#: names (:mod:`lipsync.speech.languages` makes them: ``ipa_`` and a digest of the word and
#: its units, so one name never has two pronunciations in a decoder's dictionary).
_CUSTOM: dict = {}


def _ensure_words(decoder, words: Sequence[str]) -> None:
    for w in lookup_missing([w for w in words if w not in _CUSTOM]):
        if decoder.lookup_word(w) is None:
            decoder.add_word(w, " ".join(p.rstrip("012") for p in pronounce(w)), True)


def _arcs(decoder, word: str) -> List[str]:
    """The decoder's dictionary names of ``word``'s pronunciations (added when missing)."""
    if word in _CUSTOM:
        if decoder.lookup_word(word) is None:
            decoder.add_word(word, " ".join(_CUSTOM[word]), True)
        return [word]
    names = []
    for name, phones in pronunciations(word):
        if decoder.lookup_word(name) is None:
            decoder.add_word(name, " ".join(phones), True)
        names.append(name)
    return names


def _use_grammar(decoder, name: str, final: int, transitions) -> None:
    decoder.config["silprob"] = _PAUSE_PROB.get()
    decoder.add_fsg(name, decoder.create_fsg(name, 0, final, transitions))
    decoder.activate_search(name)


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


@dataclass
class _Forced:
    """A forced alignment: word timings and the grammar search's acoustic score of every frame.

    ``frames`` has every frame's score on the search's path (words, silence and noise
    alike), ``words`` marks the frames of the transcript's words (both None when the search
    gave no segmentation).
    """

    timings: List[_WordTiming]
    frames: Optional[np.ndarray] = None
    words: Optional[np.ndarray] = None


def _search_frame_scores(decoder, n_frames: int) -> Tuple[Optional[np.ndarray], np.ndarray]:
    """(acoustic score of every frame on the last search's path, mask of its speech words' frames).

    Each segment's acoustic score (pocketsphinx reports it as a probability; its log, in
    the decoder's log units) is spread evenly over the segment's frames. None when a
    segment's score underflowed, which leaves nothing to compare.
    """
    per, words = np.zeros(n_frames), np.zeros(n_frames, bool)
    logmath = decoder.get_logmath()
    for seg in decoder.seg():
        a, b = max(seg.start_frame, 0), min(seg.end_frame + 1, n_frames)
        if b <= a:
            continue
        if not seg.ascore > 0.0:
            return None, words
        per[a:b] = logmath.log(seg.ascore) / (b - a)
        if _VARIANT.sub("", seg.word).lower() not in _NON_SPEECH_WORDS:
            words[a:b] = True
    return per, words


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


def _heard(decoder) -> List[Tuple[str, int, int]]:
    """(word, start frame, end frame exclusive) of the last search's speech words."""
    out = []
    for seg in decoder.seg():
        name = _VARIANT.sub("", seg.word).lower()
        if name not in _NON_SPEECH_WORDS:
            out.append((name, seg.start_frame, seg.end_frame + 1))
    return out


def _force_align(pcm: np.ndarray, words: Sequence[str], searched=None) -> Optional[_Forced]:
    """Word and phone frames of ``words`` in ``pcm``, or None if the search finds no path.

    The grammar is exactly the words in order, each with its pronunciations, with
    pocketsphinx's silence and noise fillers allowed before, between and after them: it
    cannot return other words. If the phone pass fails after the words were found, the
    words keep their times and share them evenly among their phones. ``searched(frames,
    in_words)``, if given, is called with the search's frame scores (:class:`_Forced`)
    once every word was found, before the phone pass.
    """
    if not words:
        return _Forced([])
    d = _aligner()
    _ensure_words(d, words)
    transitions = [(i, i + 1, 1.0, name) for i, w in enumerate(words) for name in _arcs(d, w)]
    try:
        _use_grammar(d, "exact", len(words), transitions)
        _decode(d, pcm)
        heard = _heard(d) if d.hyp() is not None else []
    except RuntimeError:
        return None
    if [w for w, _, _ in heard] != list(words):
        return None  # the search ended without reaching the last word: no path
    # scored here, by the search, as the phone loop is (:func:`_acoustic_fit`)
    frames, in_words = _search_frame_scores(d, len(pcm) // _SAMPLES_PER_FRAME + 2)
    if searched is not None:
        searched(frames, in_words)
    try:
        d.set_alignment()  # second pass: phone and state boundaries within the words found
        _decode(d, pcm)
        al = d.get_alignment()
    except RuntimeError:
        al = None
    if al is not None:
        got = _timings(al)
        if [w for w, *_ in got] == list(words):
            return _Forced(got, frames, in_words)
    return _Forced([_even_phones(w, a, b) for w, a, b in heard], frames, in_words)


def _phone_loop_scores(pcm: np.ndarray) -> Optional[np.ndarray]:
    """Acoustic score of every 10 ms frame on the best path of a free phone loop.

    Any context-independent phone may follow any other, with silence and noise between:
    what the audio holds with no transcript at all. Scored by the search itself, like the
    transcript's grammar search in :func:`_force_align`, so the two compare frame by frame.
    (Until issue 20's second round both were re-scored by a state-level pass; for the loop
    that pass cost 40% of the fit check and, measured on the GRID sentences, separated right
    from wrong transcripts no better.)
    """
    d = _aligner()
    try:
        d.activate_search(_LOOP)
        _decode(d, pcm)
        if d.hyp() is None:
            return None
        return _search_frame_scores(d, len(pcm) // _SAMPLES_PER_FRAME + 2)[0]
    except RuntimeError:
        return None


#: Scale of :func:`_acoustic_fit`: a transcript whose sounds score this many units a frame
#: (pocketsphinx's log scale) above :data:`FIT_LLR_CENTRE` fits at 1, as many below at 0.
#: Measured on the 40 GRID sentences (issue 20, third round): with their own transcripts the
#: words scored -8.9 to 4.5 against the free phone loop (median -0.3), with another
#: sentence's transcript -44 to -10.5 (median -25).
FIT_LLR_SPAN = 10.0
#: Score a frame against the free phone loop at which a transcript fits at 0.5: halfway
#: between the lowest right transcript of the GRID sentences (-8.9) and the highest wrong
#: one (-10.5), a little towards the wrong ones, since telling a user that the right
#: transcript does not fit is the worse mistake. The loop's context-independent phones score
#: about as well as the transcript's triphones, so a right transcript lands near 0. Measured
#: on the cases of ``make bench``'s align-grid figure whose transcript aligned (issue 20,
#: third round; the loop of one-phone words used before at its centre of 3.5 in brackets):
#: below the centre 82 of 83 other sentences' transcripts (80), 3 of 40 with a letter left
#: out (1), 11 of 18 with a word added (8), none of the 40 right ones (none); right ones at
#: least 2.1 above it (3.1), the MFA recording 9.0 (7.7), the espeak samples 6.1 and 10.5
#: (11.1 and 17.7).
FIT_LLR_CENTRE = -11.0


def _acoustic_fit(loop: Optional[np.ndarray], forced: Optional[_Forced],
                  speech: Optional[np.ndarray] = None) -> Optional[float]:
    """How well the aligned transcript explains its audio, 0..1 (0.5: :data:`FIT_LLR_CENTRE` below free phones).

    Two log likelihood ratios per frame of the transcript's grammar search against the free
    phone loop's (:func:`_phone_loop_scores`), each mapped linearly around
    :data:`FIT_LLR_CENTRE` with :data:`FIT_LLR_SPAN`, and the smaller one taken: over the
    frames of the words (words forced onto other sounds score far worse than the loop),
    and over the ``speech`` frames, words and the silence and noise between them alike
    (speech the transcript leaves to silence scores far worse too). A transcript that was
    said scores about as well as the loop: its triphones are sharper models than the
    loop's context-independent phones, but it may not choose its phones. None when a score
    is missing.
    """
    if loop is None or forced is None or forced.frames is None or not forced.timings:
        return None
    n = min(len(loop), len(forced.frames))
    ratio = _lower_mean(forced.frames[:n] - loop[:n], (forced.words, speech))
    if ratio is None:
        return None
    return float(np.clip(0.5 + (ratio - _fit_rules()[1]) / (2 * FIT_LLR_SPAN), 0.0, 1.0))


def _lower_mean(values: np.ndarray, masks) -> Optional[float]:
    """The lower of the means of ``values`` over each mask's frames (masks that are None or
    mark no frame are left out; None when none is left)."""
    masks = [m for m in masks if m is not None]
    if not masks:
        return None
    n = min(len(values), *(len(m) for m in masks))
    means = [float(values[:n][m[:n]].mean()) for m in masks if m[:n].any()]
    return min(means) if means else None


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
        transitions += [(i, i + 1, 1.0 - SKIP_PROB, name) for name in _arcs(d, w)]
        transitions.append((i, i + 1, SKIP_PROB))
        if prefix and i > 0:
            transitions.append((i, n, END_PROB))
    try:
        _use_grammar(d, "fit", n, transitions)
        _decode(d, pcm)
        # a skipped word is a null transition, which the segmentation lists as "(NULL)"
        heard = [w for w, _, _ in _heard(d)]
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


#: A transcript whose words score at least this much a frame in their own grammar search
#: (pocketsphinx's log units; over the frames of the words and over the speech frames, the
#: lower taken, as :func:`_acoustic_fit` takes them) fits without asking the free phone
#: loop, whose search costs almost as much CPU as the alignment itself (issue 20). The
#: search's scores are relative to the best of the senones it keeps active, silence and
#: noise among them, so words forced onto other sounds score far lower. Measured on the
#: cases of ``make bench``'s align-grid figure: the 40 GRID sentences' own transcripts
#: -25.1 to -10.9 (34 of 40 at -20 or above), the MFA recording -13.4, the espeak samples
#: -23.3 and -25.3 (so the loop judges them), another sentence's transcript at most -27.4
#: (83 that aligned), and every transcript the loop finds not fitting (another sentence's,
#: a letter left out, a word added) below -20: so the loop is asked only where it can
#: change the answer.
FIT_WITHOUT_LOOP = -20.0


#: The fit check's rules for languages other than English, whose words are spelled in the
#: closest en-us units and so score lower against the free phone loop than English words
#: do. Measured on ``make bench``'s languages figures (the grammar search's score a frame
#: against the loop's, the lower of words and speech frames; in brackets the search's own
#: score): the six real recordings with their own transcripts -24.4 to -8.8 (-38.1 to
#: -22.0); the 20 espeak-ng sentences with theirs -27.9 to -11.2 (-51.1 to -29.8: synthetic
#: voices fit the en-us models worse); each real recording with the synthetic sentence of
#: its language as transcript -50.2, -44.1, -40.9, -36.7, -35.7 and -31.5 (-64.1 to -45.2),
#: and each synthetic sentence with the real recording's transcript no path at all. So:
#: the loop is skipped from an own score of -41.5 (between -38.1 and -45.2); the centre -28
#: lies between the lowest right real transcript and the highest wrong one, so every right
#: one (synthetic ones too) fits at 0.5 or more and every wrong one at most 0.33 (a
#: warning); and the relaxed search, which may leave words out, runs only below a fit of
#: 0.1 (a ratio of -36): for four of the six wrong transcripts, and none of the right ones.
FIT_WITHOUT_LOOP_OTHER = -41.5
FIT_LLR_CENTRE_OTHER = -28.0
NOT_FIT_CONFIDENCE_OTHER = 0.1


def _fit_rules() -> Tuple[float, float, float]:
    """(score that skips the loop, fit centre, fit below which words may be left out) for
    the language being aligned."""
    if _WIDE.get():
        return FIT_WITHOUT_LOOP_OTHER, FIT_LLR_CENTRE_OTHER, NOT_FIT_CONFIDENCE_OTHER
    return FIT_WITHOUT_LOOP, FIT_LLR_CENTRE, NOT_FIT_CONFIDENCE


def _own_score(frames: Optional[np.ndarray], in_words: Optional[np.ndarray],
               speech: Optional[np.ndarray]) -> Optional[float]:
    """The grammar search's mean score a frame over the words' frames and over the speech
    frames, the lower (None when there is none)."""
    if frames is None or in_words is None:
        return None
    return _lower_mean(frames, (in_words, speech))


def _align_words(pcm: np.ndarray, words: Sequence[str], loop: "_PhoneLoop", speech: Optional[np.ndarray] = None
                 ) -> Tuple[Optional[List[_WordTiming]], List[str], Optional[float]]:
    """(timings, words left out, acoustic fit) of a transcript in one stretch of audio.

    The strict alignment when it finds every word and either scores at least
    :data:`FIT_WITHOUT_LOOP` in its own search (fit None: not asked) or fits at least at
    :data:`NOT_FIT_CONFIDENCE` against the free phone loop; else the words a tolerant
    search finds, aligned (timings None when even those do not align). ``loop`` gives the
    phone loop's frame scores (started beside the phone pass when it will be asked),
    ``speech`` marks the frames that are speech.
    """
    clear = False

    def searched(frames, in_words) -> None:
        nonlocal clear
        score = _own_score(frames, in_words, speech)
        clear = score is not None and score >= _fit_rules()[0]
        if not clear:
            loop.start()

    forced = _force_align(pcm, words, searched=searched)
    if forced is not None and clear:
        return forced.timings, [], None
    loop.start()
    fit = _acoustic_fit(loop(), forced, speech) if forced is not None else None
    if forced is not None and (fit is None or fit >= _fit_rules()[2]):
        return forced.timings, [], fit
    kept_at = set(_fitting_words(pcm, words))
    kept = [w for i, w in enumerate(words) if i in kept_at]
    relaxed = _force_align(pcm, kept) if kept else None
    if relaxed is None and forced is not None:
        # every word aligned, if badly, but no subset does: the transcript's alignment
        return forced.timings, [], fit
    left_out = [w for i, w in enumerate(words) if i not in kept_at]
    if relaxed is None:
        return None, left_out, fit
    # the transcript's fit is its own (when all its words aligned), not only its kept words'
    fits = [f for f in (fit, _acoustic_fit(loop(), relaxed, speech)) if f is not None]
    return relaxed.timings, left_out, min(fits) if fits else None


#: Longest silent closure kept for a stop (P B T D K G) that follows a pause. A stop's
#: closure is silence, so after a pause the aligner can stretch it over any part of the
#: pause (measured: "place" began 0.19 to 0.24 s before its burst in 3 of 10 GRID
#: sentences). GRID's own aligner starts these words 30 to 100 ms before the stop's end
#: (median 55 ms), and lips close about that long before a release.
MAX_PAUSE_CLOSURE_S = 0.08
_STOPS = frozenset({"P", "B", "T", "D", "K", "G"})


def _cap_pause_closures(timings: List[_WordTiming]) -> List[_WordTiming]:
    cap = int(round(MAX_PAUSE_CLOSURE_S / FRAME_S))
    out: List[_WordTiming] = []
    for w, ws, we, ph in timings:
        after_pause = not out or out[-1][2] < ws
        if after_pause and ph and ph[0][0].rstrip("012") in _STOPS and ph[0][2] - ph[0][1] > cap:
            first = (ph[0][0], ph[0][2] - cap, ph[0][2])
            ws, ph = first[1], [first] + ph[1:]
        out.append((w, ws, we, ph))
    return out


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
    phones = list(_CUSTOM[word]) if word in _CUSTOM else [p.rstrip("012") for p in pronounce(word)] or ["AH"]
    edges = np.linspace(start, end, len(phones) + 1).round().astype(int)
    return word, start, end, [(p, int(a), int(b)) for p, a, b in zip(phones, edges[:-1], edges[1:])]


#: A pause the free phone loop hears inside speech (silence or noise between two speech
#: phones) at most this many 10 ms frames long ...
LOOP_CLOSURE_MAX_FRAMES = 20
#: ... through which the voice goes on (at least this share of its frames voiced, by
#: :class:`~lipsync.speech.voice.VoiceGate`: the murmur of an m, the voice bar of a b) ...
LOOP_CLOSURE_VOICED = 0.1
#: ... and which is quieter (mean dBFS) than both phones around it by at least this, is a lip
#: closure and becomes the loop's M. The en-us loop hears the quiet murmur of a bilabial nasal
#: or voiced stop as silence; a t or k closure is silent (unvoiced), so it stays a pause.
#: Measured with ``python -m lipsync.bench --only languages`` (84 espeak-ng sentences in 20
#: languages: mean frame agreement of the mouth shapes with the truth's, languages at 0.50 or
#: more, bilabials shown closed) and on the six real recordings (mouth without the transcript
#: against the mouth with it; the Mandarin clip's against its TextGrid phones):
#:
#: ========================================== ===== ===== ========= ===== ===========
#: short pauses made M                        mean  >=.5  bilabials real  zh TextGrid
#: ========================================== ===== ===== ========= ===== ===========
#: none                                       0.470 7/20  0.32      0.622 0.559
#: every one up to 20 frames                  0.507 13/20 0.58      0.603
#: voiced (0.3)                               0.502 13/20 0.53      0.618 0.529
#: voiced (0.3) and quieter (0 dB)            0.494 12/20 0.48      0.622 0.559
#: voiced (0.3) and 3 / 6 / 10 dB quieter     0.489 / 0.484 / 0.480 (8, 8, 7 of 20)
#: with voiced pauses shared (``_close_voiced_pauses`` of :mod:`lipsync.speech.languages`):
#: voiced (0.3) and quieter (0 dB)            0.509 13/20 0.48      0.622 0.559
#: voiced (0.1) and quieter (0 dB): used      0.512 13/20 0.52      0.622 0.559
#: voiced (0.1), up to 6 / 10 dB louder       0.512 / 0.512, bilabials 0.55 / 0.56; real 0.622 / 0.618
#: ========================================== ===== ===== ========= ===== ===========
#:
#: Turning every short pause into M scored best on espeak-ng's voices but cost the real
#: recordings; so did a pause up to 10 dB louder than its neighbours (the Mandarin clip
#: 0.559 -> 0.529). The rule used helps synthetic speech and leaves the real recordings as
#: they were.
LOOP_CLOSURE_QUIETER_DB = 0.0


def _loop_phones(pcm: np.ndarray) -> Tuple[List[str], List[_WordTiming]]:
    """Phones the free phone loop hears in ``pcm`` (any language), each as a nameless word.

    pocketsphinx's en-us context-independent phones, any one after any other (the fit
    check's search, :func:`_phone_loop_scores`): what Rhubarb Lip Sync's "phonetic"
    recogniser does for speech in languages it has no model for. Then, by the voice gate
    (:func:`_voiced_loop`): a short voiced pause inside speech is a lip closure (M), and
    phones where the gate is closed (breath, noise, pauses) are dropped, so the mouth rests.
    """
    d = _aligner()
    try:
        d.activate_search(_LOOP)
        _decode(d, pcm)
        if d.hyp() is None:
            return [], []
        segs = [(s.word, s.start_frame, s.end_frame + 1) for s in d.seg()]
    except RuntimeError:
        return [], []
    return [], [("", a, b, [(p, a, b)]) for p, a, b in _voiced_loop(segs, pcm)]


def _voiced_loop(segs: Sequence[Tuple[str, int, int]], pcm: np.ndarray) -> List[Tuple[str, int, int]]:
    """The loop's speech phones ``(phone, start, end)`` (10 ms frames), with each short, voiced,
    quieter pause inside speech made an M (:data:`LOOP_CLOSURE_QUIETER_DB`), and cut to the
    voice gate.

    The gate (as live audio's, :class:`~lipsync.speech.voice.VoiceGate`) changed the
    synthetic figure by nothing (espeak-ng's pauses are digital silence) and the real
    recordings' agreement with their transcript-aligned mouth by less than 0.005; it is kept
    because it rests the mouth on breath and noise between phrases, as live audio does.
    """
    from .voice import VoiceGate

    gate = VoiceGate()
    gate.feed(pcm)
    voiced = np.asarray(gate.voiced, bool)
    is_open = gate.gate(len(voiced))
    energy = _frame_energy(pcm)
    speech = [(p, a, b) for p, a, b in segs if p not in _NON_SPEECH_PHONES and b > a]
    filled: List[Tuple[str, int, int]] = []
    for p, a, b in speech:
        if filled:
            gap = (filled[-1][2], a)
            if 0 < gap[1] - gap[0] <= LOOP_CLOSURE_MAX_FRAMES and gap[0] < len(voiced) \
                    and voiced[gap[0]:gap[1]].mean() >= LOOP_CLOSURE_VOICED \
                    and b <= len(energy) \
                    and energy[gap[0]:gap[1]].mean() <= min(energy[filled[-1][1]:gap[0]].mean(),
                                                            energy[a:b].mean()) - LOOP_CLOSURE_QUIETER_DB:
                filled.append(("M", gap[0], gap[1]))
        filled.append((p, a, b))
    out: List[Tuple[str, int, int]] = []
    for p, a, b in filled:
        inside = np.concatenate([[False], is_open[a:b], [False]]) if a < len(is_open) else np.zeros(2, bool)
        edges = np.flatnonzero(np.diff(inside.astype(np.int8)))
        out += [(p, a + int(x), a + int(y)) for x, y in zip(edges[::2], edges[1::2])]
    return out


def _chunk_job(job):
    """One chunk's work, ("recognise" or "loop", pcm): runs in a worker process."""
    return _loop_phones(job[1]) if job[0] == "loop" else _recognise(job[1])


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
    # a daemonic process (serve's job worker, a pool's worker) may not start children
    if multiprocessing.current_process().daemon:
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


def _loop_worker(conn, pcm: np.ndarray, parent: int) -> None:
    """A forked worker's work: the phone loop's scores of ``pcm``, sent down ``conn``."""
    from .._proc import die_with_parent

    die_with_parent(parent)
    try:
        conn.send(_phone_loop_scores(pcm))
    finally:
        conn.close()


class _PhoneLoop:
    """The fit check's phone loop scores of ``pcm`` (:func:`_phone_loop_scores`), on call.

    :meth:`start` decodes the loop in a forked worker, beside the transcript's alignment in
    this process, when ``workers`` is 2 or more and forking is safe (:func:`_can_fork`):
    the loop's search takes about as long as the phone pass it then runs beside (on the
    MFA recording 29 ms of CPU per second of audio for the loop, 24 for the phone pass),
    so on two cores the check adds little to the wall-clock time. Otherwise, or if the
    worker fails, it is decoded here on the first call. :meth:`close` ends a worker whose
    result was not wanted.
    """

    def __init__(self, pcm: np.ndarray, workers: int):
        self._pcm, self._workers, self._proc, self._conn, self._done = pcm, workers, None, None, False
        self._scores: Optional[np.ndarray] = None

    def start(self) -> None:
        """Begin decoding in a worker, if there may be one (else :meth:`__call__` decodes)."""
        if self._proc is not None or self._done or self._workers < 2 or not _can_fork():
            return
        import multiprocessing

        _aligner()  # loaded once, here, so the worker starts with it in place
        context = multiprocessing.get_context("fork")
        self._conn, send = context.Pipe(duplex=False)
        proc = context.Process(target=_loop_worker, args=(send, self._pcm, os.getpid()), daemon=True,
                               name="lipsync-phone-loop")
        proc.start()
        self._proc = proc   # only once started: _end joins it
        send.close()

    def __call__(self) -> Optional[np.ndarray]:
        if not self._done:
            scores, got = None, False
            if self._conn is not None:
                try:
                    scores, got = self._conn.recv(), True
                except (EOFError, OSError):   # the worker died: decode here instead
                    pass
                self._end(kill=False)
            self._scores = scores if got else _phone_loop_scores(self._pcm)
            self._done = True
        return self._scores

    def close(self) -> None:
        """End the worker: its result is not wanted (or was received)."""
        self._end(kill=True)

    def _end(self, *, kill: bool) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._proc is not None:
            if kill and self._proc.is_alive():
                self._proc.kill()
            self._proc.join()
            self._proc = None


#: A chunk of a long transcribed recording is searched for the next words of the transcript
#: in a window of this many times the words expected at the recording's speaking rate, plus
#: :data:`WINDOW_MARGIN` words: room for a speaker who speeds up, without making the search
#: (and its time) grow with the transcript.
WINDOW_FACTOR = 2.0
WINDOW_MARGIN = 20


def _align_long(piece, chunks, transcript, energy, bar, recogniser: str = "recognise"):
    """Align a long transcript chunk by chunk, each taking the next words that fit it.

    Returns (timings per chunk, words skipped, number of words that could not be aligned).
    """
    loud = energy > max(float(energy.max()) - SPEECH_BELOW_PEAK_DB, SILENCE_DBFS)
    rate = len(transcript) / max(float(loud.sum()) * FRAME_S, 1.0)  # words per second of speech
    bar.total = len(chunks)
    bar.refresh()
    per_chunk, pointer, skipped, failed = [], 0, [], 0
    for i, (a, b) in enumerate(chunks):
        last = i == len(chunks) - 1
        speech_s = float(loud[a:b].sum()) * FRAME_S
        size = len(transcript) if last else int(WINDOW_FACTOR * rate * speech_s) + WINDOW_MARGIN
        window = transcript[pointer: pointer + size]
        kept_at = _fitting_words(piece(a, b), window, prefix=not last)
        consumed = kept_at[-1] + 1 if kept_at else 0
        skipped += [window[j] for j in range(consumed) if j not in set(kept_at)]
        pointer += consumed
        kept = [window[j] for j in kept_at]
        forced = _force_align(piece(a, b), kept) if kept else _Forced([])
        if forced is None:  # the words found do not align after all: what is heard there
            failed += len(kept)
            got = _chunk_job((recogniser, piece(a, b)))[1]
        else:
            got = forced.timings
        per_chunk.append(got)
        bar.update()
    skipped += list(transcript[pointer:])
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
    from ..errors import InputError
    from .text import MAX_TRANSCRIPT_CHARS, looks_like_path, not_a_transcript

    if text is None:
        return None
    too_long = (f"is over {MAX_TRANSCRIPT_CHARS:,} characters, the limit for a transcript (a 90-minute film's "
                f"dialogue is ~80,000): split the speech into clips")
    if len(text) < 4096 and "\n" not in text and os.path.isfile(text):
        try:
            with open(text, "rb") as f:
                raw = f.read(4 * MAX_TRANSCRIPT_CHARS + 4)   # UTF-8: at most 4 bytes a character
                if f.read(1):
                    raise InputError(f"transcript {too_long}", path=text)
            path, text = text, raw.decode("utf-8-sig")
        except UnicodeDecodeError:
            raise InputError("transcript is not UTF-8 text (binary data?)", path=text) from None
        except OSError as exc:
            raise InputError(f"cannot read transcript: {exc.strerror or exc}", path=text) from None
        if len(text) > MAX_TRANSCRIPT_CHARS:
            raise InputError(f"transcript {too_long}", path=path)
        what = not_a_transcript(text)
        if what:
            raise InputError(f"given as a transcript, but this looks like {what}", path=path)
    elif len(text) < 4096 and looks_like_path(text):
        if not os.path.exists(text):
            raise InputError("no such transcript file (a --text value that names a file must exist; "
                             "words with spaces are read as the transcript itself)", path=text)
        # /dev/zero, /dev/stdin, a fifo, a folder: not a file to read words from
        raise InputError("is not a regular file (a device, pipe or folder); give a text file or the words",
                         path=text)
    elif len(text) > MAX_TRANSCRIPT_CHARS:
        raise InputError(f"the --text transcript {too_long}")
    return text if text.strip() else None


def align_samples(pcm: np.ndarray, text: Optional[str] = None, *, quiet: bool = True,
                  path: Optional[str] = None, jobs: Optional[int] = None, lang: Optional[str] = None) -> Alignment:
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
        Processes for long or untranscribed audio, and from 2 on a second one that checks
        a transcript's fit beside its alignment (default: all cores; 1: none).
    lang : str, optional
        The language (BCP 47: ``fr``, ``pt-BR``, ``zh``); None or English: CMUdict and
        ARPAbet phones. Any other: :func:`lipsync.speech.languages.align_language` (IPA
        phones; needs the optional espeak-ng extra).

    Returns
    -------
    Alignment

    Raises
    ------
    lipsync.errors.InputError
        An English transcript with no word in Latin letters (Cyrillic, Chinese, ...): the
        message names the script and the ``--lang`` to pass; an unknown ``lang``.

    Warns
    -----
    MissingWordsWarning
        Transcript words not in the dictionary (one warning listing them all).
    AlignmentWarning
        The transcript does not fit the audio; gives the confidence figure and names the
        words left out.

    Examples
    --------
    >>> import numpy as np
    >>> al = align_samples(np.zeros(16000, np.int16), "hello")   # one second of silence
    >>> len(al.words), len(al.phones), al.duration
    (0, 0, 1.0)
    """
    from ..errors import InputError
    from ..phonetics.g2p import is_english
    from .text import MAX_TRANSCRIPT_CHARS, shown_words

    if text is not None and len(text) > MAX_TRANSCRIPT_CHARS:   # the API's text=, read_transcript's callers
        raise InputError(f"the transcript is over {MAX_TRANSCRIPT_CHARS:,} characters, the limit for a "
                         f"transcript: split the speech into clips", path=path)
    if not is_english(lang):
        from .scripts import OTHER_LANGUAGES

        return OTHER_LANGUAGES.get("espeak-ipa")(pcm, text, lang, quiet=quiet, path=path, jobs=jobs)
    pcm = _as_pcm(pcm)
    transcript = tuple(normalise_transcript(text)) if text is not None else ()
    if text is not None:
        from .scripts import check_english_script

        check_english_script(text, transcript, path=path)
    missing = tuple(lookup_missing(transcript))
    if missing:
        warnings.warn(f"{path or 'transcript'}: {len(missing)} word(s) not in the dictionary, "
                      f"pronounced by letter-to-sound rules: {shown_words(missing)}",
                      MissingWordsWarning, stacklevel=2)
    return _align_pcm(pcm, transcript, quiet=quiet, path=path, jobs=jobs, missing=missing)


def _as_pcm(pcm) -> np.ndarray:
    """16-bit samples of int16 or -1..1 float input, flat."""
    pcm = np.asarray(pcm)
    if pcm.dtype.kind == "f":
        pcm = np.clip(np.round(pcm * 32767.0), -32768, 32767).astype(np.int16)
    return pcm.astype(np.int16, copy=False).reshape(-1)


def _align_pcm(pcm: np.ndarray, transcript: Tuple[str, ...], *, quiet: bool, path: Optional[str],
               jobs: Optional[int], missing: Tuple[str, ...] = (), recogniser: str = "recognise",
               shown=None) -> Alignment:
    """:func:`align_samples` once the transcript is words the decoder can name.

    ``recogniser`` is what listens where no transcript fits ("recognise": US-English words;
    "loop": free phones, for other languages); ``shown`` turns decoder names into the
    words the messages show.
    """
    from tqdm import tqdm

    show = shown or (lambda w: w)
    duration = len(pcm) / SAMPLE_RATE
    workers = max(1, jobs if jobs is not None else (os.cpu_count() or 1))
    has_text = bool(transcript)  # blank or punctuation only: no words, so recognise
    energy = _frame_energy(pcm)
    if len(energy) == 0 or float(energy.max()) < SILENCE_DBFS:
        if has_text:  # never dropped without a word (issue 32)
            warnings.warn(f"{path or 'audio'}: the audio is silent; the transcript was not used", AlignmentWarning,
                          stacklevel=2)
        return Alignment(_timeline((), duration, path), _timeline((), duration, path), duration,
                         transcript=transcript, recognised=not has_text, missing=missing)
    pcm = _dither(pcm)
    spf = _SAMPLES_PER_FRAME

    def piece(a: int, b: int) -> np.ndarray:
        return pcm[a * spf: b * spf]

    timings: List[_WordTiming] = []
    failed, skipped, fit = 0, [], None
    bar = tqdm(total=1, desc="align", unit="chunk", disable=quiet, leave=False)
    loop = _PhoneLoop(pcm, workers if has_text and duration <= MAX_CHUNK_S else 0)
    try:
        whole = None
        if has_text and duration <= MAX_CHUNK_S:
            whole, skipped, fit = _align_words(pcm, transcript, loop, _speech_frames(energy))
        strict_failed = has_text and bool(skipped)
        if whole is not None:
            timings = whole
            bar.update()
        else:
            if has_text and duration > MAX_CHUNK_S:
                chunks = _plan_chunks(energy, MAX_CHUNK_S)
                per_chunk, skipped, failed = _align_long(piece, chunks, transcript, energy, bar, recogniser)
            else:
                # No transcript, or a short one that does not fit at all: recognise chunk by
                # chunk (in parallel when there are enough), then align what was heard.
                chunks = _plan_chunks(energy, RECOGNITION_CHUNK_S)
                bar.total = len(chunks)
                bar.refresh()
                workers = workers if len(chunks) >= MIN_CHUNKS_FOR_WORKERS else 1
                per_chunk = [t for _, t in _run_jobs([(recogniser, piece(a, b)) for a, b in chunks], workers, bar)]
                failed, skipped = len(transcript), []
            for (a, _), got in zip(chunks, per_chunk):
                timings += [(w, ws + a, we + a, [(p, ps + a, pe + a) for p, ps, pe in ph])
                            for w, ws, we, ph in got]
    finally:
        loop.close()
        bar.close()
    timings = _cap_pause_closures(timings)

    confidence = None
    if has_text:
        fitted = 1.0 - (failed + len(skipped)) / len(transcript)
        confidence = min(fitted, _speech_in_words(energy, timings), 1.0 if fit is None else fit)
        # In a long recording a few words at chunk cuts may go unfound even when the
        # transcript is right (12 of 236 on the MFA recording four times over), so there
        # only a larger share counts as not fitting.
        if (failed or strict_failed or len(skipped) > SKIPPED_SHARE_OK * len(transcript)
                or confidence < LOW_CONFIDENCE):
            what = "does not fit the audio"
            mismatch = confidence < NO_FIT_CONFIDENCE and (failed or skipped)
            if skipped:
                what += (f": {len(skipped)} of its {len(transcript)} words were not found "
                         + ("(going on leaves them out: " if mismatch else "and were left out (")
                         + f"{_some([show(w) for w in skipped])})")
            if failed:
                # a mismatch stops the command line (exit 2) unless --allow-mismatch: say what
                # going on does, not that it was done (issue 38)
                what += (f"{',' if skipped else ':'} {failed} of its {len(transcript)} words could not be "
                         + ("aligned (going on uses the words recognised there instead)" if mismatch else
                            "aligned, and the words recognised there were used instead"))
            if not (failed or skipped):
                what = "fits the audio poorly; the alignment is a best effort"
            warnings.warn(f"{path or 'audio'}: the transcript {what} (confidence {confidence:.2f}: the "
                          "smallest of the share of its words found, the share of the speech they cover "
                          "and how well they match the sounds)",
                          # all its words found but little of the speech covered: a partial
                          # transcript, worth aligning; words not found as well: the wrong one
                          TranscriptMismatchWarning if mismatch else AlignmentWarning,
                          stacklevel=3)
    return _to_alignment(timings, duration, path, transcript if has_text else tuple(w for w, *_ in timings),
                         recognised=not has_text or failed > 0, confidence=confidence, missing=missing,
                         skipped=tuple(skipped) if has_text else ())


def _some(words: Sequence[str], most: int = 8) -> str:
    shown = ", ".join(words[:most])
    return shown + (f" and {len(words) - most} more" if len(words) > most else "")


def _speech_frames(energy: np.ndarray) -> np.ndarray:
    """The frames that are speech: within :data:`SPEECH_BELOW_PEAK_DB` of the loudest."""
    return energy > max(float(energy.max()) - SPEECH_BELOW_PEAK_DB, SILENCE_DBFS)


def _speech_in_words(energy: np.ndarray, timings: List[_WordTiming]) -> float:
    """Share of the loud frames (speech) that lie inside aligned words.

    A transcript that fits covers nearly all speech with words (0.88 on the MFA corpus
    recording, whose pauses hold breaths; 0.99 on the espeak samples); half a transcript
    covers 0.32, one word of a sentence 0.07. Measured with :data:`SPEECH_BELOW_PEAK_DB`.
    """
    speech = _speech_frames(energy)
    inside = np.zeros(len(energy), bool)
    for _, ws, we, _ in timings:
        inside[ws:we] = True
    return float(inside[speech].mean()) if speech.any() else 1.0


def align(audio: Union[PathLike, np.ndarray], text: Optional[str] = None, *, quiet: bool = True,
          jobs: Optional[int] = None, lang: Optional[str] = None) -> Alignment:
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
        Processes for long or untranscribed audio, and from 2 on a second one that checks
        a transcript's fit beside its alignment (default: all cores; 1: none).
    lang : str, optional
        The language of the speech (BCP 47), see :func:`align_samples`.

    Returns
    -------
    Alignment

    Raises
    ------
    lipsync.speech.audio.AudioError
        The audio file cannot be read (the message names it).
    lipsync.errors.InputError
        A transcript the language cannot read; an unknown ``lang``.

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
    return align_samples(pcm, read_transcript(text), quiet=quiet, path=path, jobs=jobs, lang=lang)


def _timeline(segments, duration: float, path: Optional[str]) -> Timeline:
    return Timeline(tuple(segments), kind=PHONEME, path=path, stated_end=duration)


def _to_alignment(timings: List[_WordTiming], duration: float, path: Optional[str], transcript,
                  **kw) -> Alignment:
    offset = BOUNDARY_OFFSET_OTHER_S if _WIDE.get() else BOUNDARY_OFFSET_S

    def t(frame: int) -> float:
        # rounded to 1 us so files show 0.82, not 0.8200000000000001 (frames are 10 ms)
        return min(max(round(frame * FRAME_S + offset, 6), 0.0), duration)

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


