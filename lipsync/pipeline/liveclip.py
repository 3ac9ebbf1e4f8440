"""What a live session fed a recording shows, offline: ``lipsync render AUDIO --live`` and
``lipsync cues AUDIO --live``.

The recording is fed to a :class:`~lipsync.live.animator.LiveAnimator` in 20 ms chunks of
16 kHz samples, as a client streaming it in real time would (:func:`live_specs`); each frame
is the one the session fixed when the audio reached the look-ahead past it, and the frames
of the last look-ahead (no audio follows them) come from the whole recording
(:meth:`~lipsync.live.animator.LiveAnimator.finish_audio`).

Examples
--------
>>> import os
>>> from lipsync._data import default_bank_dir
>>> wav = os.path.join(default_bank_dir(), "..", "..", "samples", "hello.wav")
>>> specs = live_specs(wav, default_bank_dir())
>>> len(specs), specs[0].shown
(75, 'X')
"""

from __future__ import annotations

import os
from typing import List, Optional, Tuple, Union

import numpy as np

from .animator import Animator
from ..banks.bank import Bank
from ..errors import InputError
from ..motion.frames import DEFAULT_FPS, frame_count
from ..morphing.render import Renderer
from ..motion.sequencer import FrameSpec
from ..live.audio import BLOCK, RATE

PathLike = Union[str, "os.PathLike[str]"]


def _samples(audio) -> np.ndarray:
    if isinstance(audio, np.ndarray):
        return audio
    from ..readers.audio import is_audio_input
    from ..speech.audio import load_audio

    if not is_audio_input(audio, None):
        raise InputError("--live needs speech audio (wav, flac, mp3, ...), not a timeline", path=os.fspath(audio))
    return load_audio(audio)


def live_specs(audio, bank, *, fps: float = DEFAULT_FPS, lookahead: Optional[float] = None, map=None,
               timing=None, quiet: bool = True) -> List[FrameSpec]:
    """The FrameSpecs a live session fed ``audio`` in real-time 20 ms chunks shows.

    Parameters
    ----------
    audio : path-like or numpy.ndarray
        An audio file (any format ffmpeg reads), or 16 kHz mono samples (int16 or float).
    bank : Bank or path-like
        The subject.
    fps, map, timing
        As for :class:`~lipsync.live.animator.LiveAnimator`.
    lookahead : float, optional
        The audio look-ahead in seconds (default
        :data:`~lipsync.live.animator.AUDIO_LOOKAHEAD_S`).
    quiet : bool
        No progress bar.

    Returns
    -------
    list of FrameSpec
        One per frame of the recording (``ceil(duration * fps)``).
    """
    from tqdm import tqdm

    from ..live.animator import LiveAnimator

    pcm = _samples(audio)
    live = LiveAnimator(bank, fps=fps, map=map, timing=timing, prepare=False, audio_lookahead=lookahead)
    with tqdm(total=len(pcm), desc="live", unit="sample", unit_scale=True, disable=quiet, leave=False) as bar:
        for i in range(0, len(pcm), BLOCK):
            live.feed_audio(pcm[i:i + BLOCK], RATE)
            bar.update(min(BLOCK, len(pcm) - i))
    live.finish_audio()
    return [live.spec(n) for n in range(frame_count(len(pcm) / RATE, live.fps))]


def live_cues(specs: List[FrameSpec], fps: float) -> List[Tuple[float, float, str]]:
    """Mouth cues of live frames: each frame's nearer viseme (``from`` below alpha 0.5),
    runs merged, frame n covering ``[n / fps, (n + 1) / fps)``.

    Examples
    --------
    >>> live_cues([FrameSpec("X", "X", 0.0), FrameSpec("X", "D", 0.7), FrameSpec("D", "D", 0.0)], 10)
    [(0.0, 0.1, 'X'), (0.1, 0.3, 'D')]
    """
    cues: List[Tuple[float, float, str]] = []
    for n, s in enumerate(specs):
        v = s.from_viseme if s.alpha < 0.5 else s.to_viseme
        if cues and cues[-1][2] == v:
            cues[-1] = (cues[-1][0], round((n + 1) / fps, 6), v)
        else:
            cues.append((round(n / fps, 6), round((n + 1) / fps, 6), v))
    return cues


class LiveClip(Animator):
    """An :class:`~lipsync.pipeline.animator.Animator` whose frames are a live session's
    (:func:`live_specs`): what ``render_clip(..., live=...)`` renders."""

    def __init__(self, bank, audio, fps: float = DEFAULT_FPS, *, lookahead: Optional[float] = None, map=None,
                 method: str = "flow", timing=None, store=None, quiet: bool = True, still: bool = False):
        self.bank = bank if isinstance(bank, Bank) else Bank.load(bank)
        self.specs = live_specs(audio, self.bank, fps=fps, lookahead=lookahead, map=map, timing=timing, quiet=quiet)
        self.fps = float(fps)
        self.renderer = Renderer(self.bank, method=method, store=store)
        self._attach_plate(still)
