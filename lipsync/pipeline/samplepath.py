"""The sample path of a render or a dub: select a real mouth sample per frame, paste it.

Used by :class:`lipsync.Animator` (``lipsync render``, ``batch``, ``serve``, the Python API)
when its bank has samples (bank.yaml ``samples:``, :mod:`lipsync.samples`) and a plate,
and by :func:`lipsync.dub`::

    bank samples (loaded once per process) --Selector (cKDTree per viseme, once per map)-->
    specs + phones --Viterbi--> a sample per frame --frame_plan--> paste or morph per frame
    --SampleCompositor--> plate frame

``samples`` options everywhere: None (bank.yaml's ``samples: {enabled: ...}``, on when the
bank has them), ``"on"``/True, ``"off"``/False (one picture per viseme, as before).

Examples
--------
>>> wanted("off"), wanted(None), wanted(True)
(False, None, True)
"""

from __future__ import annotations

import hashlib
import os
import threading
from typing import Optional

import numpy as np

from ..samples import samples_wanted

#: Banks' samples kept decoded in this process (a serve or a batch worker renders many
#: clips of a few banks; each is the bank's crops, ~20 MB for GRID s1's).
KEEP_BANKS = 2
_cache: dict = {}
_lock = threading.Lock()


#: ``--samples on|off`` as True, False or None (kept under the name callers used).
wanted = samples_wanted


def bank_samples(bank, option=None):
    """The bank's :class:`~lipsync.samples.Samples` if the render uses them, else None (cached
    per table file and its modification time)."""
    from ..samples import load_samples

    files = getattr(bank, "samples", None)
    on = wanted(option)
    if files is None or on is False or (on is None and not files.enabled):
        return None
    st = os.stat(files.table), os.stat(files.video)
    key = (os.fspath(files.table), st[0].st_mtime_ns, st[0].st_size, st[1].st_mtime_ns, st[1].st_size)
    with _lock:
        if key in _cache:
            return _cache[key]
    import dataclasses

    got = load_samples(dataclasses.replace(bank, samples=dataclasses.replace(files, enabled=True)))
    with _lock:
        _cache[key] = got
        while len(_cache) > KEEP_BANKS:
            _cache.pop(next(iter(_cache)))
    return got


class SamplePath:
    """A render's selection and what each frame shows (see the module docstring).

    Parameters
    ----------
    samples : lipsync.samples.Samples
    specs : list of FrameSpec
        The sequencer's frames (the dominance model's schedule: the predicted opening).
    timeline : Timeline
        The phones (or visemes) rendered.
    fps : float
    pmap : PhonemeMap
    rest : str
    lut : numpy.ndarray, optional
        The colour table onto the plate (a dub's).
    store : FlowStore, optional
        Where the join flows are kept.
    timing : DominanceParams, optional
        The render's dominance constants (the bank's fitted ones): the predicted lip opening's.
    audio : path-like or numpy.ndarray, optional
        The speech rendered (a file, or 16 kHz mono samples): where the bank has an audio lip
        model (:mod:`lipsync.samples.lipmodel`), the target follows what the sound predicts.
    """

    def __init__(self, samples, specs, timeline, fps: float, pmap, rest: str, *, lut=None, store=None,
                 timing=None, audio=None):
        from ..composite.samples import SampleCompositor
        from ..selection import Selector, frame_plan

        self.samples = samples
        self.selector = _selector(samples, pmap, rest)
        from ..motion.coarticulation import DominanceParams

        #: ``(frames, 2)``: the opening and width the speech predicts (None: no sound or no model).
        self.audio_prediction = speech_prediction(samples, audio, fps, len(specs))
        self.selection = self.selector.select(specs, timeline, fps,
                                              timing if isinstance(timing, DominanceParams) else None,
                                              audio=self.audio_prediction)
        tg = self.selection.target
        self.src, self.dst, self.alpha = frame_plan(self.selection.samples, self.selector.succ, tg.closed | tg.rest)
        tag = hashlib.sha256(samples.affine.tobytes() + samples.lips.tobytes()).digest()
        self.compositor = SampleCompositor(samples, samples.mask.astype(np.float32) / 255.0, lut=lut, store=store,
                                           tag=tag)
        self._prepared: dict = {}

    def prepared(self, j: int, pose: np.ndarray, shape):
        """The mask's ROI and warp for plate frame ``j`` under ``pose``, made once per plate frame."""
        got = self._prepared.get(j)
        if got is None:
            got = self._prepared[j] = self.compositor.plate.prepare(pose, shape)
        return got

    def __len__(self) -> int:
        return len(self.dst)

    def render_onto(self, i: int, plate: np.ndarray, pose: np.ndarray, prepared=None, geometry=None) -> np.ndarray:
        """Frame ``i``'s mouth onto ``plate`` (in place) under ``pose``; returns ``plate``."""
        return self.compositor.render(int(self.src[i]), int(self.dst[i]), float(self.alpha[i]), plate, pose,
                                      prepared=prepared, geometry=geometry)


def speech_prediction(samples, audio, fps: float, frames: int) -> Optional[np.ndarray]:
    """``(frames, 2)``: the opening and width the bank's audio lip model predicts from ``audio``
    (a file or 16 kHz mono samples); None without sound or without a model.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> speech_prediction(SimpleNamespace(table={}), np.zeros(16000, np.int16), 25.0, 25) is None
    True
    """
    from ..samples.lipmodel import LipModel
    from ..speech.audio import SAMPLE_RATE, load_audio

    model = LipModel.from_table(samples.table)
    if model is None or audio is None or frames <= 0:
        return None
    pcm = audio if isinstance(audio, np.ndarray) else load_audio(audio)
    if not pcm.size:
        return None
    return model.predict(pcm, SAMPLE_RATE, fps, frames)


def _selector(samples, pmap, rest):
    """The :class:`~lipsync.selection.Selector` of these samples under ``pmap`` (built once)."""
    from ..selection import Selector

    key = (pmap.name, repr(sorted(pmap.map.items(), key=str)), tuple(pmap.closures), rest)
    cache = samples.__dict__.setdefault("_selectors", {})
    if key not in cache:
        cache[key] = Selector(samples, pmap, rest, closures=pmap.closures)
    return cache[key]
