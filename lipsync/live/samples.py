"""Real mouth samples in a live session: selected within the look-ahead, pasted as offline.

A :class:`~lipsync.live.animator.LiveAnimator` of a bank with mouth samples (bank.yaml
``samples:``, banks made from video; ``samples="off"`` or bank.yaml's ``enabled: false``
keep the one-picture-per-viseme morph) fixes one sample per frame as the frame falls due::

    phones pushed / heard + the sequencer's frames up to the end of the data
      --Incremental.fix (the offline Viterbi, costs and candidates over [frame .. end of
        data], starting from the sample fixed for the frame before)--> the frame's sample
      --frame_plan (joins morphed as offline)--> SampleCompositor onto the plate frame of
        the session's clock

A fed audio stream fixes the sample with the frame (when the audio reaches the look-ahead
past it: :meth:`LiveAnimator.feed_audio`), so it depends only on the audio; pushed events
fix it when a frame is first rendered, from what was pushed by then. A fixed sample is
never changed. When the whole utterance is pushed before the first frame, the path is
the offline render's (:mod:`lipsync.selection.incremental`).

The bank's samples, their :class:`~lipsync.selection.Selector` and the compositor are made
once per process and shared by every session of the bank (:func:`shared_samples`); a
session holds only its path.

Examples
--------
>>> from lipsync import Bank
>>> from lipsync._data import default_bank_dir
>>> shared_samples(Bank.load(default_bank_dir()), None, None, None) is None   # a drawn bank has none
True
"""

from __future__ import annotations

import hashlib
import math
import os
import threading
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np

from ..samples import samples_wanted
from ..motion.frames import frame_count

#: Phones before a window kept as its target's context: the dominance model reaches back
#: well under 1 s (its carryover: under 0.4 s with the default constants), and positions
#: within a phone need the phone's start; older phones do not change the window's targets,
#: and leaving them out keeps a window's cost independent of how long the session has run.
CONTEXT_S = 1.0
#: Share of a live window's target opening taken from the speech's own prediction (the
#: bank's audio lip model, :mod:`lipsync.samples.lipmodel`) when the session is fed audio;
#: offline's is lipsync.selection.select.AUDIO_SHARE. Chosen on held_out()[18:30] (see
#: lipsync.bench.live_samples; 12 sentences, grid-s1's bank, ``render --live`` sessions fed
#: the clip's audio): the chosen samples' opening (joins blended as shown) had r 0.628
#: without the prediction, 0.705 / 0.721 / 0.738 / 0.747 / 0.740 / 0.708 at share 0.3 / 0.4
#: / 0.5 / 0.6 / 0.7 / 1. More than offline's 0.3: the live phones come from the phone loop
#: (no transcript) and err more, the sound's prediction does not depend on them.
LIVE_AUDIO_SHARE = 0.6
#: Audio feature rows kept behind the earliest row a window read (seconds): a later window
#: reaches back at most a recogniser's revision further (its phones are fixed COMMIT_AFTER_S,
#: 0.6 s, behind the frame, and a window's context is CONTEXT_S before its first phone), so
#: 5 s is thrice that; older rows are dropped (the running statistics keep them).
FEATURES_BEHIND_S = 5.0
#: At most this many seconds of feature rows are kept whatever the windows read (a phone
#: the recogniser held for minutes): memory stays bounded, ~0.3 MB at 25 fps; a window
#: reaching before the rows kept reads the first kept one for the frames before it.
FEATURES_KEEP_S = 60.0
#: Banks' samples kept decoded in this process for live sessions (each is the bank's crops,
#: ~20 MB for grid-s1's).
KEEP_BANKS = 2

_SHARED: dict = {}
_LOCK = threading.Lock()


class SharedSamples:
    """A bank's samples made ready for live sessions under one map: the selector, the
    compositor (thread-safe) and each plate frame's prepared mask (made once)."""

    def __init__(self, samples, pmap, rest: str, store=None):
        from ..composite.samples import SampleCompositor
        from ..selection import Selector

        self.samples = samples
        self.selector = Selector(samples, pmap, rest, closures=pmap.closures)
        tag = hashlib.sha256(samples.affine.tobytes() + samples.lips.tobytes()).digest()
        self.compositor = SampleCompositor(samples, samples.mask.astype(np.float32) / 255.0, store=store, tag=tag)
        self._prepared: dict = {}

    def prepared(self, j: int, pose: np.ndarray, shape):
        """The compositor's ROI and mask for plate frame ``j`` (pose ``pose``), made once."""
        key = (j, tuple(shape))
        got = self._prepared.get(key)
        if got is None:
            got = self._prepared[key] = self.compositor.plate.prepare(pose, shape)
        return got

    def render_onto(self, shows: Tuple[int, int, float], plate: np.ndarray, pose: np.ndarray, j: int) -> np.ndarray:
        """``(src, dst, alpha)`` onto ``plate`` (a copy of plate frame ``j``, in place)."""
        src, dst, alpha = shows
        return self.compositor.render(src, dst, alpha, plate, pose, prepared=self.prepared(j, pose, plate.shape))


def shared_samples(bank, option, pmap, store) -> Optional[SharedSamples]:
    """The bank's :class:`SharedSamples` under ``pmap`` if sessions use samples (``option``:
    None as bank.yaml says, ``"on"``, ``"off"``), else None; made once per process."""
    from dataclasses import replace

    on = samples_wanted(option)
    files = getattr(bank, "samples", None)
    if files is None or on is False or (on is None and not files.enabled):
        return None
    if getattr(bank, "plate", None) is None or not bank.plate.enabled or bank.channels != 3:
        return None   # samples are pasted onto the plate: without one, the pictures
    from ..samples import load_samples

    st = os.stat(files.table), os.stat(files.video)
    key = (os.path.realpath(files.table), st[0].st_mtime_ns, st[0].st_size, st[1].st_mtime_ns, st[1].st_size,
           pmap.name, repr(sorted(pmap.map.items(), key=str)), tuple(pmap.closures), bank.rest)
    with _LOCK:   # held while loading: sessions starting at once decode the crops once
        got = _SHARED.get(key)
        if got is None:
            samples = load_samples(replace(bank, samples=replace(files, enabled=True)))
            got = _SHARED[key] = SharedSamples(samples, pmap, bank.rest, store)
            while len(_SHARED) > KEEP_BANKS:
                _SHARED.pop(next(iter(_SHARED)))
        return got


class LiveSamples:
    """One session's selection: the samples fixed so far (see the module docstring).

    Parameters
    ----------
    shared : SharedSamples
    fps : float
    params : DominanceParams, optional
        The session's dominance constants (the predicted opening's), as offline.
    """

    def __init__(self, shared: SharedSamples, fps: float, params=None):
        from ..selection import Incremental

        from ..samples.lipmodel import LipModel

        self.shared = shared
        self.fps = float(fps)
        self.selection = Incremental(shared.selector, fps, params)
        #: The bank's audio lip model (None: the phones' target alone).
        self.model = LipModel.from_table(shared.samples.table)
        #: The fed audio's features (:meth:`hear`; None until audio comes or without a model).
        self.features = None

    def hear(self, pcm: np.ndarray, sample_rate: int = 16000) -> None:
        """Audio the session was fed (its 16 kHz blocks, in order): its features are kept
        for the windows' targets (nothing without a lip model or with share 0)."""
        from ..speech.features import RunningFeatures

        if self.model is None or LIVE_AUDIO_SHARE <= 0:
            return
        if self.features is None:
            self.features = RunningFeatures(sample_rate, self.fps)
        self.features.add(pcm)

    def prediction(self, a: int, b: int) -> Optional[np.ndarray]:
        """``(b - a, 2)``: the opening and width the lip model predicts for frames ``a .. b - 1``
        from the audio heard (features normalised by the running statistics; a frame's
        context past the last final frame repeats it, as offline at an utterance's end);
        None before any frame is final."""
        f = self.features
        if f is None or len(f) == 0 or b <= a:
            return None
        ctx = self.model.context
        lo, hi = max(f.first, a - ctx), min(len(f), b + ctx)
        if lo >= hi:
            lo = hi - 1
        rows = f.normalised(lo, hi)
        at = np.clip(np.arange(a, b)[:, None] + np.arange(-ctx, ctx + 1)[None, :], lo, hi - 1) - lo
        f.forget(max(lo - int(round(FEATURES_BEHIND_S * self.fps)), len(f) - int(round(FEATURES_KEEP_S * self.fps))))
        return rows[at].reshape(b - a, -1) @ self.model.weights + self.model.bias

    def __len__(self) -> int:
        return len(self.selection)

    def base(self, c: int, phones: Sequence[Tuple[float, float, str]]) -> int:
        """The first frame a window from frame ``c`` needs: where the first phone ending
        within :data:`CONTEXT_S` before ``c`` starts (frame 0 early in a stream)."""
        t = c / self.fps - CONTEXT_S
        if t <= 0:
            return 0
        for s, e, _ in phones:
            if e > t:
                return min(c, int(math.floor(s * self.fps + 1e-9)))
        return c

    def fix(self, specs_of: Callable[[int, int], List], phones: Sequence[Tuple[float, float, str]], kind: str,
            stop: int, key) -> int:
        """Fix the next frame from a window ending before frame ``stop``: ``specs_of(a, b)``
        gives the sequencer's frames ``a .. b - 1``, ``phones`` the phone segments (or
        visemes: ``kind``) so far. Returns the frame's sample."""
        from ..motion.timeline import Segment, Timeline

        c = len(self.selection)
        stop = max(stop, c + 1)
        b = self.base(c, phones)
        off = b / self.fps
        segs = tuple(Segment(max(0.0, s - off), e - off, lab) for s, e, lab in phones
                     if e > off and e - off > max(0.0, s - off))
        tl = Timeline(segs, kind=kind)
        specs = specs_of(b, stop)
        audio = self.prediction(b, b + len(specs))
        return self.selection.fix(specs, tl, b, key, audio, LIVE_AUDIO_SHARE if audio is not None else 0.0)

    def shows(self, n: int) -> Tuple[int, int, float]:
        """``(src, dst, alpha)`` of fixed frame ``n``."""
        return self.selection.shows(n)

    def render(self, n: int, plate, line, out: np.ndarray, shows: Optional[int] = None) -> np.ndarray:
        """Frame ``n`` onto ``plate``'s frame of the clock (``line``) at ``fps``, into ``out``:
        what fixed frame ``shows`` (default ``n``) shows."""
        j = plate.index(n, self.fps, line)
        np.copyto(out, plate.frames[j])
        return self.shared.render_onto(self.shows(n if shows is None else shows), out, plate.poses[j], j)


class FixedPath:
    """A finished session's fixed samples as a render's sample path (what
    :class:`lipsync.pipeline.animator.Animator` calls: ``prepared``, ``render_onto``):
    ``lipsync render --live`` writes the frames the session showed.

    Examples
    --------
    >>> FixedPath.__name__
    'FixedPath'
    """

    def __init__(self, live: LiveSamples, n: int):
        self.live, self.n = live, int(n)
        self.compositor = live.shared.compositor

    def __len__(self) -> int:
        return self.n

    def prepared(self, j: int, pose: np.ndarray, shape):
        return self.live.shared.prepared(j, pose, shape)

    def render_onto(self, i: int, plate: np.ndarray, pose: np.ndarray, prepared=None, geometry=None) -> np.ndarray:
        src, dst, alpha = self.live.shows(i)
        return self.compositor.render(src, dst, alpha, plate, pose, prepared=prepared, geometry=geometry)


def frames_heard(seconds: float, fps: float) -> int:
    """Frames whose time lies before ``seconds`` (the window's end: the data reaches them).

    Examples
    --------
    >>> frames_heard(0.2, 25), frames_heard(0.0, 25)
    (5, 0)
    """
    return frame_count(seconds, fps)
