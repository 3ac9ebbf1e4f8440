"""The live audio front-end: a sample stream -> a voice gate and phones, causally, in fixed blocks.

:class:`AudioFrontEnd` takes samples as they arrive (any chunk size, ``int16`` or float,
any rate from :data:`MIN_RATE` to :data:`MAX_RATE`) and keeps, for the audio heard so far:

* the samples at 16 kHz (:class:`Resampler`: a windowed-sinc interpolator whose every output
  sample is a function of the input samples alone, so no chunking changes it);
* a **voice gate** (:class:`VoiceGate`) per 10 ms frame: open around *voiced* frames
  (loud enough above the noise floor and periodic at a speaking pitch), with a pre-roll
  before the voice (an onset consonant: "s", "p") and a hangover after it (a final "s",
  "t"). Breath, hiss and hum-free noise are not periodic, so they never open it; pauses
  close it;
* **phones** from pocketsphinx's free phone loop (``allphone``: any context-independent
  phone may follow any other; no word list, no language model, so it hears any language's
  sounds as the acoustic model's nearest phones). It decodes incrementally
  (``start_utt`` / ``process_raw`` / ``seg``): the best path so far, whose recent phones may
  still change as more audio comes.

The stream is processed in blocks of :data:`BLOCK_S` (20 ms) of 16 kHz audio whatever the
chunks fed: everything the front-end reports after block ``k`` is a function of the first
``k`` blocks of samples only. That is the invariance :meth:`lipsync.LiveAnimator.feed_audio`
guarantees (and ``lipsync render --live`` relies on).

Examples
--------
>>> import numpy as np
>>> fe = AudioFrontEnd()
>>> blocks = fe.feed(np.zeros(8000, np.int16), 16000)    # half a second of silence
>>> len(blocks), round(fe.time, 2), fe.phones()
(25, 0.5, [])
"""

from __future__ import annotations

import math
from typing import Callable, List, Optional, Tuple

import numpy as np

from ..errors import InputError
from ..speech.align import DITHER_STEPS
# the voice gate lives with the speech room (the untranscribed phone loop uses it too); its
# names stay importable from here
from ..speech.voice import (  # noqa: F401
    DIGITAL_SILENCE_DBFS, FLOOR_RISE_DB, HANGOVER_S, INITIAL_FLOOR_DBFS, MIN_VOICED_FRAMES, PERIODICITY_WINDOW_S,
    PITCH_HZ, PRE_ROLL_S, VOICED_ABOVE_FLOOR_DB, VOICED_MIN_DBFS, VOICED_PERIODICITY, VoiceGate)

#: The recogniser's rate (pocketsphinx's en-us acoustic model).
RATE = 16000
#: Seconds per block: what a WebSocket client sends at a time, and half a video frame at 25
#: fps, so a frame never waits for more than one block to be ready.
BLOCK_S = 0.02
BLOCK = int(RATE * BLOCK_S)
#: The recogniser's frame (pocketsphinx's 100 frames a second); gate and phones use it.
FRAME_S = 0.01
FRAME = int(RATE * FRAME_S)
#: Input rates accepted: telephone audio to studio audio.
MIN_RATE, MAX_RATE = 8000, 192000

# --- the recogniser -------------------------------------------------------------------------
#: An utterance of the phone loop is ended (and a new one started) when the gate has been
#: closed this long and the utterance is at least UTTERANCE_MIN_S long: the search's
#: history and its backtrace (asked every block) grow with the utterance.
RESTART_PAUSE_S = 0.3
UTTERANCE_MIN_S = 2.0
#: ... and always after this long, pause or not (a minute of speech without a pause does
#: not happen; a stuck gate on music could).
UTTERANCE_MAX_S = 30.0
#: pocketsphinx's labels that are not speech sounds.
NON_SPEECH = frozenset({"SIL", "+NSN+", "+SPN+", "+BREATH+", "+NOISE+", "+UH+", "+UM+", "<s>", "</s>", "<sil>"})
#: Recogniser settings: topn 4 (pocketsphinx's default, the fastest; the aligner's 8 buys
#: boundary precision for forced alignment, not phone choice in a free loop).
RECOGNISER_SETTINGS = dict(topn=4)


def _dither(pcm: np.ndarray, block: int) -> np.ndarray:
    """Block ``block`` with the aligner's dither added (:data:`lipsync.speech.align.DITHER_STEPS`:
    digital silence has no spectrum, and its log(0) features derail pocketsphinx's noise
    removal and mean normalisation), seeded by the block's number so that the stream's
    samples alone decide it."""
    noise = np.random.default_rng(block).integers(-DITHER_STEPS, DITHER_STEPS + 1, len(pcm), dtype=np.int32)
    return np.clip(pcm.astype(np.int32) + noise, -32768, 32767).astype(np.int16)


def as_int16(samples, *, what: str = "audio") -> np.ndarray:
    """Samples as ``int16``: integers as they are, floats in [-1, 1] scaled by 32768.

    A float stream that is ``int16 / 32768`` gives back exactly those integers.

    Examples
    --------
    >>> as_int16(np.array([0.0, 0.5, -1.0, 2.0])).tolist()
    [0, 16384, -32768, 32767]
    """
    x = np.asarray(samples)
    if x.ndim != 1:
        raise InputError(f"{what}: samples must be one channel (a 1-D array), got shape {x.shape}")
    if x.dtype == np.int16:
        return x
    if np.issubdtype(x.dtype, np.floating):
        if not np.all(np.isfinite(x)):
            raise InputError(f"{what}: samples must be finite numbers")
        return np.clip(np.round(x.astype(np.float64) * 32768.0), -32768, 32767).astype(np.int16)
    if np.issubdtype(x.dtype, np.integer):
        return np.clip(x, -32768, 32767).astype(np.int16)
    raise InputError(f"{what}: samples must be int16 or float, got {x.dtype}")


class Resampler:
    """Any rate to 16 kHz, streaming: output sample ``k`` is the input at ``k * rate / 16000``
    by a Hann-windowed sinc of :data:`TAPS` zero crossings, low-passed below both Nyquist
    rates. Each output sample is computed once every input sample it needs has come, so the
    output does not depend on how the input was chunked.

    Examples
    --------
    >>> r = Resampler(48000)
    >>> x = np.sin(2 * np.pi * 440 * np.arange(4800) / 48000)
    >>> y = np.concatenate([r.feed(x[:1000]), r.feed(x[1000:])])
    >>> ref = np.sin(2 * np.pi * 440 * np.arange(len(y)) / 16000)
    >>> len(y) > 1580, float(np.abs(y[20:] - ref[20:]).max()) < 0.01
    (True, True)
    """

    #: Zero crossings of the sinc on each side: 16 keeps the pass band flat to 0.1 dB below
    #: 7 kHz and costs 32-100 multiplications an output sample.
    TAPS = 16

    def __init__(self, rate: int):
        self.rate = int(rate)
        self.k = 0                  # next output sample
        self.base = 0               # absolute index of self.buf[0]
        self.buf = np.zeros(0)
        scale = min(1.0, RATE / self.rate)          # cutoff relative to the input rate
        self.scale = scale
        self.half = int(math.ceil(self.TAPS / scale))

    def feed(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, np.float64)
        if self.rate == RATE:
            return x
        self.buf = np.concatenate([self.buf, x])
        total = self.base + len(self.buf)
        # output k needs input up to floor(k * rate / RATE) + half
        last = ((total - 1 - self.half) * RATE) // self.rate     # the last k computable
        if last < self.k:
            return np.zeros(0)
        ks = np.arange(self.k, last + 1, dtype=np.int64)
        centre = (ks * self.rate) // RATE
        frac = (ks * self.rate - centre * RATE) / RATE
        offs = np.arange(-self.half + 1, self.half + 1)
        idx = centre[:, None] + offs[None, :]                  # absolute input indices
        d = offs[None, :] - frac[:, None]                       # distance in input samples
        w = self.scale * np.sinc(self.scale * d) * (0.5 + 0.5 * np.cos(np.pi * d / (self.half + 1)))
        src = idx - self.base
        vals = np.where(src >= 0, self.buf[np.clip(src, 0, None)], 0.0)  # before the start: 0
        y = np.sum(vals * w, axis=1)
        self.k = last + 1
        keep = (self.k * self.rate) // RATE - self.half
        if keep > self.base:
            self.buf = self.buf[keep - self.base:]
            self.base = keep
        return y


def _decoder():
    from pocketsphinx import Decoder

    d = Decoder(lm=None, loglevel="FATAL", **RECOGNISER_SETTINGS)
    d.add_allphone_file("loop", None)
    d.activate_search("loop")
    return d


class PhoneStream:
    """pocketsphinx's phone loop over a 16 kHz stream, decoded block by block.

    ``phones()`` is the best path so far as ``(start_frame, end_frame, phone)`` (end
    exclusive, 10 ms frames from the stream's start); finished utterances are final, the
    current one's phones may still change.
    """

    def __init__(self):
        self.d = _decoder()
        self.done: List[Tuple[int, int, str]] = []   # phones of finished utterances
        self.utt_start = 0                           # frame the current utterance starts at
        self.frames = 0                              # frames fed
        self._cur: List[Tuple[int, int, str]] = []
        self._dirty = False
        self.d.start_utt()

    def feed(self, pcm: np.ndarray) -> None:
        self.d.process_raw(np.ascontiguousarray(pcm, np.int16).tobytes(), False, False)
        self.frames += len(pcm) // FRAME
        self._dirty = True

    def restart(self) -> None:
        """End the utterance here (its phones become final) and start the next."""
        self.d.end_utt()
        self.done.extend(self._segments(self.frames))
        self.d.start_utt()
        self.utt_start = self.frames
        self._cur = []
        self._dirty = False

    def _segments(self, stop: int) -> List[Tuple[int, int, str]]:
        out = []
        for s in self.d.seg() or ():
            a, b = self.utt_start + max(s.start_frame, 0), self.utt_start + s.end_frame + 1
            a, b = max(a, self.utt_start), min(b, stop)
            if b > a:
                out.append((a, b, s.word))
        if out:  # the phone in progress runs to the audio heard (its end is not decided yet)
            out[-1] = (out[-1][0], stop, out[-1][2])
        return out

    def current(self) -> List[Tuple[int, int, str]]:
        if self._dirty:
            self._cur = self._segments(self.frames)
            self._dirty = False
        return self._cur

    def close(self) -> None:
        """End the utterance and free the decoder (its ~30 MB acoustic model); the phones
        found stay readable."""
        if self.d is None:
            return
        self.current()   # the phones so far, kept (read without the decoder from now on)
        try:
            self.d.end_utt()
        except RuntimeError:  # pragma: no cover - no utterance running
            pass
        self.d = None


class AudioFrontEnd:
    """Resampler, voice gate and phone loop over one audio stream (module docstring).

    Parameters
    ----------
    rate : int, optional
        The stream's sample rate; may also be given with the first :meth:`feed`. A stream
        keeps one rate.
    """

    def __init__(self, rate: Optional[int] = None):
        self.rate: Optional[int] = None
        self._resampler: Optional[Resampler] = None
        if rate is not None:
            self._set_rate(rate)
        self.gate = VoiceGate()
        self.rec = PhoneStream()
        self._pending = np.zeros(0, np.float64)   # 16 kHz samples not yet in a block
        self.blocks = 0
        self._closed_since: Optional[int] = None   # frame since which the gate is closed
        self.samples_in = 0
        self.ended = False
        #: Called with each 16 kHz int16 block as it is processed (the silence that completes
        #: the last one included), e.g. a session's audio lip target; None for none.
        self.on_block: Optional[Callable[[np.ndarray], None]] = None

    def _set_rate(self, rate) -> None:
        if isinstance(rate, bool) or not isinstance(rate, (int, np.integer)) and not (
                isinstance(rate, float) and rate.is_integer()):
            raise InputError(f"sample rate must be a whole number of Hz, got {rate!r}")
        rate = int(rate)
        if not MIN_RATE <= rate <= MAX_RATE:
            raise InputError(f"sample rate must be {MIN_RATE}..{MAX_RATE} Hz, got {rate}")
        if self.rate is not None and rate != self.rate:
            raise InputError(f"sample rate changed from {self.rate} to {rate} Hz within one stream")
        if self.rate is None:
            self.rate = rate
            self._resampler = Resampler(rate)

    @property
    def time(self) -> float:
        """Seconds of audio processed (whole blocks)."""
        return self.blocks * BLOCK_S

    @property
    def frames(self) -> int:
        return self.blocks * (BLOCK // FRAME)

    def add(self, samples, rate: Optional[int] = None) -> None:
        """Add samples (not processed yet: :meth:`step` processes them a block at a time)."""
        if self.ended:
            raise InputError("the audio has ended; a new stream needs a new front-end")
        self._set_rate(rate if rate is not None else self.rate if self.rate is not None else RATE)
        x = as_int16(samples).astype(np.float64)
        self.samples_in += len(x)
        y = self._resampler.feed(x)
        if self.rate != RATE:
            y = np.clip(np.round(y), -32768, 32767)
        self._pending = np.concatenate([self._pending, y]) if len(self._pending) else y

    @property
    def duration(self) -> float:
        """Seconds of audio fed (every sample, whether or not processed yet)."""
        return self.samples_in / self.rate if self.rate else 0.0

    def end(self) -> None:
        """The stream has ended: the resampler's held-back samples are made (the input
        continued by silence, as a whole-file resampler sees its end) and the last partial
        block is completed with silence and processed, so that :attr:`time` covers every
        sample fed; then the phone loop's utterance is ended (its phones final).

        Examples
        --------
        >>> fe = AudioFrontEnd()
        >>> _ = fe.feed(np.zeros(16000 + 100, np.int16), 16000)
        >>> round(fe.time, 2), fe.end(), round(fe.time, 2)
        (1.0, None, 1.02)
        """
        if self.ended:
            return
        self.ended = True
        if self.rate is not None and self.rate != RATE:
            want = int(math.ceil(self.samples_in * RATE / self.rate))      # 16 kHz samples the audio covers
            have = self.blocks * BLOCK + len(self._pending)
            tail = self._resampler.feed(np.zeros(self._resampler.half + 2))[:max(0, want - have)]
            tail = np.clip(np.round(tail), -32768, 32767)
            self._pending = np.concatenate([self._pending, tail])
        if len(self._pending) % BLOCK:
            self._pending = np.concatenate([self._pending, np.zeros(BLOCK - len(self._pending) % BLOCK)])
        while self.step():
            pass
        self.rec.restart()

    def step(self) -> bool:
        """Process the next whole block, if one has come; True if it did."""
        if len(self._pending) < BLOCK:
            return False
        block = self._pending[:BLOCK].astype(np.int16)
        self._pending = self._pending[BLOCK:]
        self._block(block)
        if self.on_block is not None:
            self.on_block(block)
        return True

    def feed(self, samples, rate: Optional[int] = None) -> List[int]:
        """Add samples and process every whole block; returns the numbers of the blocks done."""
        self.add(samples, rate)
        done = []
        while self.step():
            done.append(self.blocks - 1)
        return done

    def _block(self, pcm: np.ndarray) -> None:
        self.gate.feed(pcm)
        self.rec.feed(_dither(pcm, self.blocks))
        self.blocks += 1
        f = self.frames
        # restart the phone loop's utterance in a long enough pause (module constants)
        open_now = bool(self.gate.gate(f, f - 1)[0]) if f else False
        if open_now:
            self._closed_since = None
        elif self._closed_since is None:
            self._closed_since = f - 1
        utt = (f - self.rec.utt_start) * FRAME_S
        if utt >= UTTERANCE_MAX_S or (utt >= UTTERANCE_MIN_S and self._closed_since is not None
                                      and (f - self._closed_since) * FRAME_S >= RESTART_PAUSE_S):
            self.rec.restart()

    def phones(self, start: int = 0) -> List[Tuple[int, int, str]]:
        """The gated phone track from frame ``start`` to the audio heard: ``(start, end, phone)``
        in 10 ms frames, speech sounds only (pauses, noise and closed-gate time are gaps)."""
        stop = self.frames
        if stop <= start:
            return []
        labels = np.full(stop - start, "", dtype=object)
        for a, b, p in self.rec.done[self._first_done(start):] + self.rec.current():
            a, b = max(a, start), min(b, stop)
            if b > a and p not in NON_SPEECH:
                labels[a - start:b - start] = p
        labels[~self.gate.gate(stop, start)] = ""
        out: List[Tuple[int, int, str]] = []
        run = 0
        for i in range(1, len(labels) + 1):
            if i == len(labels) or labels[i] != labels[run]:
                if labels[run]:
                    out.append((start + run, start + i, labels[run]))
                run = i
        return out

    def _first_done(self, start: int) -> int:
        done = self.rec.done
        lo, hi = 0, len(done)
        while lo < hi:
            mid = (lo + hi) // 2
            if done[mid][1] <= start:
                lo = mid + 1
            else:
                hi = mid
        return lo

    def forget(self, before: int) -> None:
        """Drop finished phones that end before frame ``before`` (they were committed)."""
        self.rec.done = self.rec.done[self._first_done(before):]

    def close(self) -> None:
        self.rec.close()


def trim_memory() -> bool:
    """Give the C heap's free pages back to the system (glibc's ``malloc_trim``); True if done.

    A recogniser (:func:`_decoder`) allocates ~30 MB in many pieces on whichever thread made
    it; freed, glibc keeps those pages in that thread's arena for reuse, so a server whose
    audio sessions have all closed still held ~30 MB per session it ever had at once
    (issue 38: 387 MB -> 2330 MB at 64 sessions, 2204 MB after all closed). Trimming after
    a recogniser is freed returns them (measured in ``python -m lipsync.bench --only
    serve_memory``). No-op (False) where the C library is not glibc.

    Examples
    --------
    >>> trim_memory() in (True, False)
    True
    """
    global _MALLOC_TRIM
    if _MALLOC_TRIM is None:
        _MALLOC_TRIM = False
        try:
            import ctypes
            import ctypes.util

            name = ctypes.util.find_library("c")
            trim = getattr(ctypes.CDLL(name), "malloc_trim", None) if name else None
            if trim is not None:
                trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
                _MALLOC_TRIM = trim
        except OSError:  # pragma: no cover - no C library to load
            pass
    if _MALLOC_TRIM is False:
        return False
    _MALLOC_TRIM(0)
    return True


_MALLOC_TRIM = None


def offline_phones(pcm: np.ndarray) -> List[Tuple[int, int, str]]:
    """The phone loop over a whole recording at once, gated by the whole recording's voice gate:
    what the live front-end hears with every sound's future known (the baseline the live
    figures compare with, ``python -m lipsync.bench --only live_audio``).

    ``pcm`` is 16 kHz ``int16``; returns ``(start_frame, end_frame, phone)`` runs like
    :meth:`AudioFrontEnd.phones`.

    Examples
    --------
    >>> offline_phones(np.zeros(16000, np.int16))
    []
    """
    pcm = as_int16(pcm)
    n = len(pcm) // BLOCK * BLOCK
    fe = AudioFrontEnd(RATE)
    fe.gate.feed(pcm[:n])
    fe.blocks = n // BLOCK
    d = fe.rec.d
    blocks = [_dither(pcm[i:i + BLOCK], i // BLOCK) for i in range(0, n, BLOCK)]
    d.process_raw(np.ascontiguousarray(np.concatenate(blocks) if blocks else pcm[:0]).tobytes(), False, True)
    fe.rec.frames = fe.frames
    fe.rec.restart()
    fe.close()
    return fe.phones(0)
