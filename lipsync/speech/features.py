"""Per video frame audio features: what the speech sounds like at each frame's time.

For the audio-driven lip target (:mod:`lipsync.samples.lipmodel`): the samples are cut into
25 ms Hann windows every 10 ms (:data:`WINDOW`, :data:`HOP`), each window gives
:data:`MELS` log mel-band energies, its log energy and a voicing degree (the normalised
autocorrelation's peak at a pitch lag, over the window's); video frame ``i`` (time ``i / fps`` to
``(i + 1) / fps``) takes the mean of the windows centred in its span. :func:`normalised`
removes each column's mean and scales it by its standard deviation over the utterance (so a
louder recording or another voice gives features on the same scale) and :func:`stacked`
puts each frame's neighbours beside it (the lips lead and trail the sound).

Examples
--------
>>> import numpy as np
>>> sr = 16000
>>> pcm = np.zeros(sr, np.float32)
>>> pcm[8000:12000] = 0.5 * np.sin(2 * np.pi * 440 * np.arange(4000) / sr)
>>> f = frame_features(pcm, sr, fps=25)
>>> f.shape, int(np.argmax(f[:, ENERGY])) in range(12, 19)
((25, 26), True)
"""

from __future__ import annotations

import functools

from typing import Optional

import numpy as np

#: Analysis window and hop, seconds: the usual speech analysis frame (25 ms holds two to
#: three pitch periods of a low voice; 10 ms steps resolve a plosive's burst).
WINDOW, HOP = 0.025, 0.010
#: Mel bands and their range, Hz: 24 bands (as many as a 16 kHz speech front end keeps)
#: from 100 Hz (above mains hum) to 7600 Hz (below 16 kHz's Nyquist).
MELS, FMIN, FMAX = 24, 100.0, 7600.0
#: Columns: the mel bands, then log energy, then voicing.
ENERGY, VOICING = MELS, MELS + 1
#: Pitch lags searched for voicing, Hz: a low man's voice to a child's (lags up to half the
#: window: beyond it the window's own autocorrelation is too small to divide by).
PITCH = (80.0, 400.0)
#: Power floor under the logs (a digital silence gives finite features).
FLOOR = 1e-10


def _mel(hz):
    return 2595.0 * np.log10(1.0 + np.asarray(hz, np.float64) / 700.0)


def mel_filters(sample_rate: int, nfft: int, bands: int = MELS) -> np.ndarray:
    """``(bands, nfft // 2 + 1)`` triangular mel filters (HTK's mel scale, peaks of 1).

    Examples
    --------
    >>> m = mel_filters(16000, 512, 24)
    >>> m.shape, bool((m.sum(axis=1) > 0).all())
    ((24, 257), True)
    """
    top = min(FMAX, sample_rate / 2.0)
    edges = 700.0 * (10 ** (np.linspace(_mel(FMIN), _mel(top), bands + 2) / 2595.0) - 1.0)
    hz = np.arange(nfft // 2 + 1) * sample_rate / nfft
    lo, mid, hi = edges[:-2, None], edges[1:-1, None], edges[2:, None]
    return np.maximum(0.0, np.minimum((hz - lo) / (mid - lo), (hi - hz) / (hi - mid)))


def frame_features(pcm: np.ndarray, sample_rate: int, fps: float, frames: Optional[int] = None) -> np.ndarray:
    """``(frames, MELS + 2)`` float64: per video frame the log mel energies, log energy and
    voicing of ``pcm`` (int16, or floats in -1..1) averaged over the frame's span; frames
    past the sound's end (``frames`` longer than it) repeat silence's features.

    Examples
    --------
    >>> frame_features(np.zeros(1600, np.int16), 16000, fps=25, frames=6).shape
    (6, 26)
    """
    x = np.asarray(pcm)
    x = x.astype(np.float64) / 32768.0 if x.dtype.kind in "iu" else x.astype(np.float64)
    win, hop = int(round(WINDOW * sample_rate)), int(round(HOP * sample_rate))
    n = int(frames) if frames is not None else int(np.ceil(len(x) / sample_rate * fps))
    need = int(np.ceil(n / fps * sample_rate)) + win
    x = np.pad(x, (win // 2, max(0, need - len(x))))  # window k centred at sample k * hop
    count = max(1, (len(x) - win) // hop + 1)
    idx = np.arange(count)[:, None] * hop + np.arange(win)[None, :]
    per_window = window_features(x[idx], sample_rate)
    which = np.floor(np.arange(count) * hop / sample_rate * fps).astype(np.int64)
    keep = which < n
    out = np.zeros((n, per_window.shape[1]))
    np.add.at(out, which[keep], per_window[keep])
    got = np.bincount(which[keep], minlength=n).astype(np.float64)
    empty = got == 0
    out[~empty] /= got[~empty, None]
    if empty.any():  # a frame shorter than a hop: its nearest window's
        near = np.minimum(np.round(np.nonzero(empty)[0] / fps * sample_rate / hop).astype(np.int64), count - 1)
        out[empty] = per_window[near]
    return out


@functools.lru_cache(maxsize=8)
def _analysis(sample_rate: int, win: int):
    """The window, mel filters, the window's own autocorrelation and the pitch lags for one
    window length: a live session analyses every 20 ms block with the same ones, and
    building them was a third of its feature cost."""
    nfft = 1 << int(np.ceil(np.log2(win)))
    hann = np.hanning(win)
    # over the window's own autocorrelation (Boersma 1993): a periodic sound scores near 1
    # whatever its lag, where the bare Hann-windowed peak falls with the lag
    wac = np.fft.irfft(np.abs(np.fft.rfft(hann, n=2 * nfft)) ** 2)
    lags = slice(int(sample_rate / PITCH[1]), min(int(sample_rate / PITCH[0]), win // 2) + 1)
    arrays = (hann, mel_filters(sample_rate, nfft), wac)
    for a in arrays:
        a.setflags(write=False)
    return arrays + (lags,)


def window_features(seg: np.ndarray, sample_rate: int) -> np.ndarray:
    """``(count, MELS + 2)``: the log mel energies, log energy and voicing of each row of
    ``seg`` (``(count, window)`` float samples: one analysis window each).

    Examples
    --------
    >>> window_features(np.zeros((3, 400)), 16000).shape
    (3, 26)
    """
    win = seg.shape[1]
    hann, filters, wac, lags = _analysis(int(sample_rate), int(win))
    seg = np.diff(seg, axis=1, prepend=seg[:, :1]) * 0.97 + seg * 0.03  # pre-emphasis, per window
    nfft = filters.shape[1] * 2 - 2
    spec = np.fft.rfft(seg * hann, n=2 * nfft)  # doubled: the autocorrelation does not wrap
    power = np.abs(spec) ** 2
    mel = np.log(power[:, ::2] @ filters.T + FLOOR)
    energy = np.log(power.sum(axis=1) / (2 * nfft) + FLOOR)
    ac = np.fft.irfft(power, axis=1)
    voicing = np.clip((ac[:, lags] / wac[lags]).max(axis=1) * wac[0] / np.maximum(ac[:, 0], FLOOR), 0.0, 1.0)
    return np.c_[mel, energy, voicing]


def normalised(features: np.ndarray) -> np.ndarray:
    """Each column less its mean over the rows, over its standard deviation (a flat column: 0).

    Examples
    --------
    >>> normalised(np.array([[1.0, 5.0], [3.0, 5.0]])).tolist()
    [[-1.0, 0.0], [1.0, 0.0]]
    """
    f = np.asarray(features, np.float64)
    sd = f.std(axis=0)
    return (f - f.mean(axis=0)) / np.where(sd > 1e-9, sd, np.inf)


def stacked(features: np.ndarray, context: int) -> np.ndarray:
    """``(T, D * (2 * context + 1))``: each row with the rows ``-context .. +context`` from it
    beside it (the first and last rows repeated past the ends).

    Examples
    --------
    >>> stacked(np.array([[1.0], [2.0], [3.0]]), 1).tolist()
    [[1.0, 1.0, 2.0], [1.0, 2.0, 3.0], [2.0, 3.0, 3.0]]
    """
    f = np.asarray(features, np.float64)
    t = len(f)
    rows = np.clip(np.arange(t)[:, None] + np.arange(-context, context + 1)[None, :], 0, max(t - 1, 0))
    return f[rows].reshape(t, -1)


class RunningFeatures:
    """:func:`frame_features` of a stream, computed as its audio arrives, and their running
    mean and standard deviation (for a live session: no frame is computed twice).

    Each analysis window is computed once, when the audio reaches its end; a frame's row is
    final once its last window is (the last window centred in the frame ends half a window
    after its centre: at 25 fps, 2.5 ms after the frame's end). The rows are
    the offline rows of the same audio (the same windows, averaged the same way).
    :meth:`normalised` scales rows by the mean and standard deviation of every row final so
    far: over the whole utterance, once it has all been heard, exactly
    :func:`normalised`'s; before that, the statistics of what has been heard.

    The statistics are kept as they go (Welford's update: exact over any number of rows, a
    constant column stays exactly flat), so rows no reader needs again can be dropped
    (:meth:`forget`): a session of hours holds the rows of its last seconds, not 19 MB an
    hour.

    Parameters
    ----------
    sample_rate : int
    fps : float

    Examples
    --------
    >>> sr = 16000
    >>> pcm = np.random.default_rng(0).integers(-3000, 3000, sr).astype(np.int16)
    >>> run = RunningFeatures(sr, 25)
    >>> for i in range(0, sr, 320):
    ...     run.add(pcm[i:i + 320])
    >>> run.finish(25)
    >>> bool(np.allclose(run.normalised(0, 25), normalised(frame_features(pcm, sr, 25)), atol=1e-9))
    True
    >>> run.forget(20); run.add(np.zeros(8000, np.int16)); run.first <= 20 < len(run)
    True
    """

    def __init__(self, sample_rate: int, fps: float):
        self.sr, self.fps = int(sample_rate), float(fps)
        self.win, self.hop = int(round(WINDOW * self.sr)), int(round(HOP * self.sr))
        self._buf = np.zeros(self.win // 2)   # padded samples from window self._k's start on
        self._k = 0                           # the next window to compute
        self._rows = np.zeros((64, MELS + 2))    # final rows of frames self._first ..
        self._first = 0
        self._drop = 0                       # frames before this may be dropped (forget)
        self._last = np.zeros(MELS + 2)      # the last final row
        self._sum = np.zeros(MELS + 2)       # of the rows in the frame being filled
        self._got = 0
        self._frame = 0                      # the frame being filled (rows before it are final)
        self._mean = np.zeros(MELS + 2)      # over the final rows (Welford: mean, sum of squared deviations)
        self._m2 = np.zeros(MELS + 2)

    def __len__(self) -> int:
        """Frames whose row is final."""
        return self._frame

    @property
    def first(self) -> int:
        """The first frame whose row is still held (:meth:`forget`)."""
        return self._first

    @property
    def held(self) -> int:
        """Rows held in memory (the buffer's capacity)."""
        return len(self._rows)

    def forget(self, before: int) -> None:
        """Rows of frames before ``before`` will not be read again: they may be dropped
        (the running statistics keep counting them)."""
        self._drop = max(self._drop, int(before))

    def _which(self, k: np.ndarray) -> np.ndarray:
        return np.floor(k * self.hop / self.sr * self.fps).astype(np.int64)   # as frame_features

    def add(self, pcm: np.ndarray) -> None:
        """More samples (int16, or floats in -1..1, at ``sample_rate``)."""
        x = np.asarray(pcm)
        x = x.astype(np.float64) / 32768.0 if x.dtype.kind in "iu" else x.astype(np.float64)
        self._buf = np.concatenate([self._buf, x])
        count = (len(self._buf) - self.win) // self.hop + 1
        if count <= 0:
            return
        idx = np.arange(count)[:, None] * self.hop + np.arange(self.win)[None, :]
        per_window = window_features(self._buf[idx], self.sr)
        which = self._which(np.arange(self._k, self._k + count))
        starts = np.r_[0, np.flatnonzero(np.diff(which)) + 1]   # each frame's windows, summed at once
        sums = np.add.reduceat(per_window, starts, axis=0)
        for f, total, got in zip(which[starts].tolist(), sums, np.diff(np.r_[starts, count]).tolist()):
            while f > self._frame:   # the frame is complete: its row is final
                self._close()
            self._sum += total
            self._got += got
        self._k += count
        self._buf = self._buf[count * self.hop:]
        while self._which(np.array([self._k]))[0] > self._frame:   # no later window is this frame's
            self._close()

    def _slot(self) -> int:
        """The buffer row for frame ``self._frame``: forgotten rows dropped, or the buffer
        doubled, when it is full."""
        i = self._frame - self._first
        if i >= len(self._rows):
            drop = min(self._drop, self._frame) - self._first
            if drop >= len(self._rows) // 4:   # amortised: a quarter of the buffer moves at most 3 times
                self._rows[:i - drop] = self._rows[drop:i]
                self._first += drop
                i -= drop
            else:
                self._rows = np.vstack([self._rows, np.zeros_like(self._rows)])
        return i

    def _close(self) -> None:
        i = self._slot()
        if self._got:
            row = self._sum / self._got
        else:   # a frame shorter than a hop: the window after it (frame_features takes the nearest)
            row = self._last.copy()
        self._rows[i] = row
        self._last = row
        self._frame += 1
        delta = row - self._mean
        self._mean += delta / self._frame
        self._m2 += delta * (row - self._mean)
        self._sum = np.zeros(MELS + 2)
        self._got = 0

    def finish(self, frames: int) -> None:
        """The audio has ended: the stream's first ``frames`` rows are made final (the sound
        continued by silence, as :func:`frame_features` pads it)."""
        while len(self) < frames:
            self.add(np.zeros(self.hop))

    def rows(self, a: int, b: int) -> np.ndarray:
        """Rows ``a .. b - 1`` as computed (final ones, held: ``a >= first``)."""
        if a < self._first:
            raise IndexError(f"rows before frame {self._first} were dropped (asked from {a})")
        return self._rows[a - self._first:max(a, min(b, self._frame)) - self._first]

    def normalised(self, a: int, b: int) -> np.ndarray:
        """Rows ``a .. b - 1`` (final ones, held) less the running mean, over the running
        standard deviation (a flat column: 0)."""
        sd = np.sqrt(self._m2 / max(self._frame, 1))
        return (self.rows(a, b) - self._mean) / np.where(sd > 1e-9, sd, np.inf)
