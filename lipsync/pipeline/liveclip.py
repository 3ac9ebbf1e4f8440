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


def live_session(audio, bank, *, fps: float = DEFAULT_FPS, lookahead: Optional[float] = None, map=None,
                 timing=None, quiet: bool = True, samples="off"):
    """A :class:`~lipsync.live.animator.LiveAnimator` fed ``audio`` in real-time 20 ms chunks
    and ended (:meth:`~lipsync.live.animator.LiveAnimator.finish_audio`): every frame of the
    recording fixed, ``(animator, frame count)`` with the count ``ceil(duration * fps)``.

    Parameters are those of :func:`live_specs`; ``samples`` as for
    :class:`~lipsync.live.animator.LiveAnimator` (default off: only the frames' specs are wanted).

    Examples
    --------
    >>> import numpy as np
    >>> from lipsync._data import default_bank_dir
    >>> live, n = live_session(np.zeros(8000, np.int16), default_bank_dir())
    >>> n, live.spec(n - 1).shown, live.cue(n - 1)
    (13, 'X', 'X')
    """
    from tqdm import tqdm

    from ..live.animator import LiveAnimator

    pcm = _samples(audio)
    live = LiveAnimator(bank, fps=fps, map=map, timing=timing, prepare=False, audio_lookahead=lookahead,
                        samples=samples)
    fixed = 0
    with tqdm(total=len(pcm), desc="live", unit="sample", unit_scale=True, disable=quiet, leave=False) as bar:
        for i in range(0, len(pcm), BLOCK):
            fixed += len(live.feed_audio(pcm[i:i + BLOCK], RATE))
            bar.update(min(BLOCK, len(pcm) - i))
    fixed += len(live.finish_audio())
    # every frame came from feed_audio or finish_audio, as a streaming session delivers them
    # (with no look-ahead a frame is due as its interval starts: one past the end may come)
    return live, min(fixed, frame_count(len(pcm) / RATE, live.fps))


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
        One per frame of the recording (``ceil(duration * fps)``: the frames
        :meth:`~lipsync.live.animator.LiveAnimator.feed_audio` made due and those
        :meth:`~lipsync.live.animator.LiveAnimator.finish_audio` delivered at the end).
    """
    live, n = live_session(audio, bank, fps=fps, lookahead=lookahead, map=map, timing=timing, quiet=quiet)
    return [live.spec(k) for k in range(n)]


def live_shapes(audio, bank, *, fps: float = DEFAULT_FPS, lookahead: Optional[float] = None, map=None,
                timing=None, quiet: bool = True) -> List[str]:
    """The mouth shape (cue) of each frame a live session fed ``audio`` shows
    (:meth:`~lipsync.live.animator.LiveAnimator.cue`): what ``lipsync cues AUDIO --live``
    writes. Parameters as :func:`live_specs`.

    Examples
    --------
    >>> import numpy as np
    >>> from lipsync._data import default_bank_dir
    >>> set(live_shapes(np.zeros(8000, np.int16), default_bank_dir()))
    {'X'}
    """
    live, n = live_session(audio, bank, fps=fps, lookahead=lookahead, map=map, timing=timing, quiet=quiet)
    return [live.cue(k) for k in range(n)]


def live_cues(frames, fps: float) -> List[Tuple[float, float, str]]:
    """Mouth cues of live frames, runs merged, frame n covering ``[n / fps, (n + 1) / fps)``:
    each frame's shape (:func:`live_shapes`, a viseme name) or, for a FrameSpec, its nearer
    viseme (``from`` below alpha 0.5).

    Examples
    --------
    >>> live_cues([FrameSpec("X", "X", 0.0), FrameSpec("X", "D", 0.7), FrameSpec("D", "D", 0.0)], 10)
    [(0.0, 0.1, 'X'), (0.1, 0.3, 'D')]
    >>> live_cues(["X", "B", "B"], 10)
    [(0.0, 0.1, 'X'), (0.1, 0.3, 'B')]
    """
    cues: List[Tuple[float, float, str]] = []
    for n, s in enumerate(frames):
        v = s if isinstance(s, str) else s.from_viseme if s.alpha < 0.5 else s.to_viseme
        if cues and cues[-1][2] == v:
            cues[-1] = (cues[-1][0], round((n + 1) / fps, 6), v)
        else:
            cues.append((round(n / fps, 6), round((n + 1) / fps, 6), v))
    return cues


class LiveClip(Animator):
    """An :class:`~lipsync.pipeline.animator.Animator` whose frames are a live session's
    (:func:`live_specs`; on a bank with samples, the samples the session fixed within its
    look-ahead, unless ``samples="off"``): what ``render_clip(..., live=...)`` renders."""

    def __init__(self, bank, audio, fps: float = DEFAULT_FPS, *, lookahead: Optional[float] = None, map=None,
                 method: str = "flow", timing=None, store=None, quiet: bool = True, still: bool = False,
                 plate_start: float = 0.0, samples=None):
        self.bank = bank if isinstance(bank, Bank) else Bank.load(bank)
        live, n = live_session(audio, self.bank, fps=fps, lookahead=lookahead, map=map, timing=timing, quiet=quiet,
                               samples="off" if still else samples)
        self.specs = [live.spec(k) for k in range(n)]
        self.fps = float(fps)
        self.renderer = Renderer(self.bank, method=method, store=store)
        # the plate timeline a live session started at plate_start follows (default 0,
        # LiveAnimator's): render --live shows what the session shows
        self._attach_plate(still, plate_start=plate_start)
        if live.samples is not None and self.plate is not None:
            from ..live.samples import FixedPath

            # the samples the session fixed, frame by frame within its look-ahead
            self.sample_path = FixedPath(live.samples, n)
