"""The voice gate: which 10 ms frames of 16 kHz speech are voiced, and a gate around them.

Shared by the live front-end (:mod:`lipsync.live.audio`, which re-exports it) and the free
phone loop of untranscribed speech in other languages (:func:`lipsync.speech.align._loop_phones`):
a frame is voiced when it is periodic at a speaking pitch and loud enough above the noise
floor; the gate opens around runs of voiced frames (a pre-roll before, a hangover after), so
breath, hiss and pauses keep the mouth at rest.

Examples
--------
>>> import numpy as np
>>> g = VoiceGate()
>>> g.feed(np.zeros(1600, np.int16))
>>> len(g.voiced), any(g.voiced)
(10, False)
"""

from __future__ import annotations

import math
from typing import List

import numpy as np

#: The recogniser's rate (pocketsphinx's en-us acoustic model).
RATE = 16000
#: The recogniser's frame (pocketsphinx's 100 frames a second); the gate uses it.
FRAME_S = 0.01
FRAME = int(RATE * FRAME_S)

# --- the voice gate --------------------------------------------------------------------------
#: A frame counts as voiced when its periodicity (normalised autocorrelation peak at a lag
#: of a speaking pitch) is at least this: vowels and voiced consonants score 0.6-0.95,
#: white and breath-like noise under 0.3 (measured on the MFA recording and synthetic
#: noise in tests/test_live_audio.py).
VOICED_PERIODICITY = 0.5
#: Pitch range searched, Hz: low male voices to children; above mains hum (50/60 Hz).
PITCH_HZ = (70.0, 400.0)
#: Analysis window of the periodicity, seconds: two periods of the lowest pitch.
PERIODICITY_WINDOW_S = 0.032
#: A voiced frame must also be this many dB above the noise floor ...
VOICED_ABOVE_FLOOR_DB = 9.0
#: ... and at least this loud (dBFS): a distant radio is periodic but quiet.
VOICED_MIN_DBFS = -50.0
#: The noise floor falls to any quieter frame at once and rises this many dB per frame
#: (1 dB a second): it follows a room getting louder without taking speech for noise.
FLOOR_RISE_DB = 0.01
#: Frames quieter than this are digital silence (editors' and synthesisers' zeros, a
#: recording's first samples): not a noise floor, which would make any noise look loud.
DIGITAL_SILENCE_DBFS = -70.0
#: The floor before any sound: a quiet room. Speech that starts the stream (a TTS's first
#: word) is then loud against it; a noisier room lowers nothing but is found within a
#: second as the floor falls to its quietest frames.
INITIAL_FLOOR_DBFS = -60.0
#: Consecutive voiced frames that make a voice (50 ms: a vowel's length): one to four periodic
#: frames are clicks, lip smacks and the odd periodic stretch of room noise. Measured, mouth
#: shapes of the phone loop against the transcript-aligned track (frames agreeing, toon bank):
#: four GRID sentences 0.723 with no gate, 0.747 with 3 frames, 0.773 with 5, 0.793 with 7;
#: the MFA recording (noisier, shorter pauses) 0.712, 0.700, 0.679, 0.668.
MIN_VOICED_FRAMES = 5
#: The gate opens this long before a voice (onset consonants: "s", "f", a stop's burst are
#: unvoiced and come before it). The gate of a frame is known once the audio reaches this
#: far past it.
PRE_ROLL_S = 0.15
#: ... and stays open this long after one (word-final "s", "t", "k"); longer gaps close it,
#: so the mouth rests in pauses.
HANGOVER_S = 0.25


class VoiceGate:
    """Voiced frames, and the gate around them (module docstring), per 10 ms frame at 16 kHz.

    Examples
    --------
    >>> g = VoiceGate()
    >>> t = np.arange(16000) / 16000
    >>> tone = (8000 * np.sin(2 * np.pi * 150 * t)).astype(np.int16)
    >>> g.feed(np.concatenate([np.zeros(8000, np.int16), tone]))
    >>> gate = g.gate(len(g.voiced))
    >>> int(gate[:35].sum()), bool(gate[45:140].all())
    (0, True)
    """

    def __init__(self):
        self.win = int(PERIODICITY_WINDOW_S * RATE)
        self.lags = (int(RATE / PITCH_HZ[1]), int(RATE / PITCH_HZ[0]))
        self.nfft = 1 << int(math.ceil(math.log2(2 * self.win)))
        self._window = np.hanning(self.win)
        wac = np.fft.irfft(np.abs(np.fft.rfft(self._window, self.nfft)) ** 2, self.nfft)
        self._wac = np.maximum(wac / wac[0], 1e-3)
        self.hist = np.zeros(self.win, np.float64)  # the last window of samples
        self.floor = INITIAL_FLOOR_DBFS
        self.voiced: List[bool] = []                # per frame: a voiced frame
        self._run = 0
        self.core: List[bool] = []                  # per frame: part of a voice (>= MIN_VOICED_FRAMES run)
        self._pre = int(round(PRE_ROLL_S / FRAME_S))
        self._hang = int(round(HANGOVER_S / FRAME_S))

    def feed(self, pcm: np.ndarray) -> None:
        """Whole 10 ms frames of 16 kHz samples."""
        x = np.asarray(pcm, np.float64) / 32768.0
        n = len(x) // FRAME
        if n == 0:
            return
        allx = np.concatenate([self.hist, x[: n * FRAME]])
        self.hist = allx[-self.win:]
        # windows ending at each frame's end
        ends = self.win + FRAME * np.arange(1, n + 1)
        idx = ends[:, None] - self.win + np.arange(self.win)[None, :]
        w = allx[idx] * self._window[None, :]
        spec = np.fft.rfft(w, self.nfft, axis=1)
        ac = np.fft.irfft(spec.real ** 2 + spec.imag ** 2, self.nfft, axis=1)
        # Boersma's normalisation: divided by the window's own autocorrelation, a periodic
        # signal scores near 1 at its period whatever the lag
        r = ac[:, :self.lags[1] + 2] / (ac[:, :1] + 1e-12) / self._wac[None, :self.lags[1] + 2]
        mid = r[:, self.lags[0]:self.lags[1] + 1]
        # a true period is a peak inside the range: noise's autocorrelation falls from lag 0,
        # so its largest value sits at the shortest lag, and mains hum's at 60 Hz is outside
        peak = (mid > r[:, self.lags[0] - 1:self.lags[1]]) & (mid >= r[:, self.lags[0] + 1:self.lags[1] + 2])
        period = np.where(peak, mid, 0.0).max(axis=1)
        frames = x[: n * FRAME].reshape(n, FRAME)
        db = 10 * np.log10(np.mean(frames * frames, axis=1) + 1e-12)
        for e, p in zip(db.tolist(), period.tolist()):
            if e >= DIGITAL_SILENCE_DBFS:
                self.floor = e if e < self.floor else self.floor + FLOOR_RISE_DB
            v = p >= VOICED_PERIODICITY and e >= VOICED_MIN_DBFS \
                and e >= self.floor + VOICED_ABOVE_FLOOR_DB
            self.voiced.append(v)
            self._run = self._run + 1 if v else 0
            self.core.append(False)
            if self._run >= MIN_VOICED_FRAMES:
                for j in range(len(self.core) - self._run, len(self.core)):
                    self.core[j] = True

    def gate(self, stop: int, start: int = 0) -> np.ndarray:
        """Gate of frames ``start .. stop - 1`` from the frames heard so far (bool array)."""
        n = len(self.core)
        lo, hi = max(0, start - self._hang), min(n, stop + self._pre)
        core = np.zeros(stop - start + self._hang + self._pre, bool)
        seg = np.asarray(self.core[lo:hi], bool)
        core[lo - (start - self._hang): lo - (start - self._hang) + len(seg)] = seg
        # open at f when a core frame lies in [f - hang, f + pre]
        c = np.concatenate([[0], np.cumsum(core)])
        f = np.arange(stop - start)
        return (c[f + self._hang + self._pre + 1] - c[f]) > 0
