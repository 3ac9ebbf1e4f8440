"""Selection for frames that are fixed one at a time, as a live session shows them.

A live session cannot wait for the end of the utterance: frame c must be shown when it
falls due, knowing only the frames up to the end of the data (the look-ahead). For each
frame to fix, :meth:`Incremental.fix` runs the offline selection's dynamic programme --
the same candidates (:meth:`~lipsync.selection.select.Selector.candidates`), target cost
(:func:`~lipsync.selection.select.make_target`, :meth:`~lipsync.selection.select.Selector.target_cost`)
and join cost -- over the window from frame c to the end of the data, starting from the
sample already fixed at frame c - 1 (a single candidate of cost 0: the path stays
continuous, and a fixed frame is never retracted), and fixes the window's first frame.
The window's path is kept (a *plan*) and its next frames are fixed from it while the data
it was made from is unchanged (the caller's ``key``); new data makes a new plan.

So when all the data is there before the first frame, the first plan is the offline
selection over the whole utterance and every frame is fixed from it: the live path *is*
the offline path. With a short look-ahead the plan is remade as data arrives.

What each fixed frame shows (a sample as it is, or the morph across a join) is
:func:`~lipsync.selection.plan.frame_plan` on the fixed path's last frames, as offline.

Examples
--------
>>> import numpy as np
>>> from types import SimpleNamespace
>>> selector = SimpleNamespace(succ=np.array([1, 2, -1, 4, -1]), samples=SimpleNamespace(labels=None),
...                            pmap=SimpleNamespace(targets=None))
>>> inc = Incremental(selector, fps=25)
>>> inc.path, inc.exact = [0, 1, 3], [False, False, False]     # fixed: a run, then a join
>>> [tuple(round(float(x), 2) for x in inc.shows(n, join_frames=1)) for n in range(3)]   # a join morphed
[(0.0, 0.0, 1.0), (1.0, 1.0, 1.0), (2.0, 3.0, 0.5)]
>>> inc.shows(2, join_frames=0)                                     # cut
(3, 3, 1.0)
"""

from __future__ import annotations

import threading
import time
import weakref
from dataclasses import dataclass
from typing import Hashable, List, Optional, Sequence, Tuple

import numpy as np

from .plan import JOIN_FRAMES, frame_plan
from .viterbi import Viterbi


@dataclass
class Plan:
    """A window's chosen samples: frames ``first .. first + len(ids) - 1``, made from data ``key``."""

    first: int
    ids: np.ndarray
    exact: np.ndarray      # bool: closed or at rest (never morphed)
    key: Hashable

    def covers(self, n: int) -> bool:
        return self.first <= n < self.first + len(self.ids)


class _Memo:
    """An object seen through a proxy that remembers ``methods``' results per argument and
    ``attributes``' values: the target is made for every window from the same bank and map,
    and these answer the same every time (a phone's viseme, the samples' labels)."""

    def __init__(self, obj, methods=(), attributes=()):
        self._obj = obj
        for name in methods:
            setattr(self, name, self._remember(getattr(obj, name)))
        for name in attributes:
            setattr(self, name, getattr(obj, name))

    @staticmethod
    def _remember(fn):
        seen: dict = {}

        def call(*args, **kwargs):
            key = (args, tuple(sorted(kwargs.items())))
            if key not in seen:
                seen[key] = fn(*args, **kwargs)
            return seen[key]
        return call

    def __getattr__(self, name):
        return getattr(self._obj, name)


_PROXIES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
_PROXIES_LOCK = threading.Lock()


def _proxies(selector):
    """The selector's samples and map seen through :class:`_Memo`, one pair per selector
    (per bank and map: every stream of the bank shares it, and with it the samples' medians
    that :func:`~lipsync.selection.select.phone_schedule` remembers per samples object)."""
    def made():
        return _Memo(selector.samples, attributes=("labels",)), _Memo(selector.pmap, methods=("targets",))

    try:
        with _PROXIES_LOCK:
            got = _PROXIES.get(selector)
            if got is None:
                got = _PROXIES[selector] = made()
            return got
    except TypeError:   # a selector that takes no weak reference: the stream's own
        return made()


class Incremental:
    """The selection of one live stream, fixed frame by frame (see the module docstring).

    Parameters
    ----------
    selector : lipsync.selection.Selector
        The bank's samples made ready (built once per bank and map, shared by streams).
    fps : float
    params : DominanceParams, optional
        The dominance model's constants (the predicted opening's), as offline.

    Attributes
    ----------
    path : list of int
        The sample fixed for each frame so far.
    exact : list of bool
        Whether each fixed frame must be shown exactly (closed lips, rest).
    windows : int
        Plans made (dynamic programmes run).
    seconds : float
        Time spent making them (by :attr:`clock`: wall time; a benchmark may count CPU).
    """

    #: What :attr:`seconds` is measured with.
    clock = staticmethod(time.perf_counter)

    def __init__(self, selector, fps: float, params=None):
        self.selector, self.fps, self.params = selector, float(fps), params
        #: The frame ``path[0]`` is fixed for (0 unless :meth:`restart` moved it on).
        self.first = 0
        self.path: List[int] = []
        self.exact: List[bool] = []
        self.plan: Optional[Plan] = None
        self.windows = 0
        self.seconds = 0.0
        self.window_frames = 0
        # the same values as the selector's, looked up once (each window's target reads them)
        self._samples, self._pmap = _proxies(selector)

    def __len__(self) -> int:
        """The next frame to fix (every frame before it from :attr:`first` on is fixed)."""
        return self.first + len(self.path)

    def restart(self, frame: int) -> None:
        """Fix frames from ``frame`` on, afresh (a stream that jumped ahead: the frames
        skipped were never shown with a sample)."""
        self.first, self.path, self.exact, self.plan = int(frame), [], [], None

    def sample(self, n: int) -> int:
        """The sample fixed for frame ``n``."""
        if not self.first <= n < len(self):
            raise IndexError(f"frame {n} is not fixed ({self.first}..{len(self) - 1})")
        return self.path[n - self.first]

    def fix(self, specs: Sequence, timeline, base: int, key: Hashable, audio: Optional[np.ndarray] = None,
            share: float = 0.0) -> int:
        """Fix the next frame, ``c = len(self)``, and return its sample.

        Parameters
        ----------
        specs : sequence of FrameSpec
            The sequencer's frames ``base .. E`` (``base <= c <= E``): what the data says
            up to the end of the window.
        timeline : Timeline
            The phones (or visemes), timed so that 0 is frame ``base``'s time.
        base : int
            The first frame of ``specs`` (frames before ``c`` only give the target its
            context: the phones' dominance reaches back).
        key : hashable
            What the data is: while it is the same and the plan covers frame c, the plan's
            frame is fixed without a new programme (``audio`` must then be the same too).
        audio : ndarray, optional
            ``(len(specs), 2)``: the opening and width the speech predicts for the window's
            frames (:class:`lipsync.live.samples.LiveSamples`), blended into the target's
            opening by ``share`` as :func:`~lipsync.selection.select.with_audio` does offline.
        """
        c = len(self)
        if not (base <= c < base + len(specs)):
            raise ValueError(f"frame {c} is not in the window {base}..{base + len(specs) - 1}")
        if self.plan is None or self.plan.key != key or not self.plan.covers(c):
            self.plan = self._window(specs, timeline, base, key, audio, share)
        k = c - self.plan.first
        self.path.append(int(self.plan.ids[k]))
        self.exact.append(bool(self.plan.exact[k]))
        return self.path[-1]

    def _window(self, specs, timeline, base: int, key, audio=None, share: float = 0.0) -> Plan:
        """The cheapest path over frames ``c .. base + len(specs) - 1`` from the fixed frame ``c - 1``."""
        from .select import make_target

        t0 = self.clock()
        sel = self.selector
        c = len(self)
        tg = make_target(self._samples, specs, timeline, self.fps, self._pmap, sel.rest, sel.closures, self.params)
        if audio is not None and share > 0 and len(specs):
            tg = heard(tg, audio, share)
        codes = tuple(sel.encode(x) for x in (tg.phone, tg.prev, tg.next, tg.viseme))
        v = Viterbi()
        if self.path:   # the start constraint: the sample already shown
            v.step(np.array([self.path[-1]], np.int64), np.zeros(1))
        for t in range(c - base, len(specs)):
            ids = sel.candidates(tg, t, v)
            v.step(ids, sel.target_cost(ids, tg, t, codes), None if len(v) == 0 else sel.join_cost(v.last, ids))
        ids = np.array(v.path()[1 if self.path else 0:], np.int64)
        exact = (tg.closed | tg.rest)[c - base:]
        self.windows += 1
        self.window_frames += len(ids)
        self.seconds += self.clock() - t0
        return Plan(first=c, ids=ids, exact=exact, key=key)

    def shows(self, n: int, join_frames: Optional[int] = None) -> Tuple[int, int, float]:
        """``(src, dst, alpha)`` of fixed frame ``n``: the sample as it is, or the morph
        across a join (:func:`~lipsync.selection.plan.frame_plan` over the frames that can
        reach it, so exactly as offline for the same path)."""
        join_frames = JOIN_FRAMES if join_frames is None else join_frames
        if not self.first <= n < len(self):
            raise IndexError(f"frame {n} is not fixed ({self.first}..{len(self) - 1})")
        lo, hi = max(0, n - self.first - join_frames), n - self.first + 1
        src, dst, alpha = frame_plan(np.array(self.path[lo:hi], np.int64), self.selector.succ,
                                     np.array(self.exact[lo:hi], bool), join_frames)
        return int(src[-1]), int(dst[-1]), float(alpha[-1])


def heard(tg, audio: np.ndarray, share: float):
    """Target ``tg`` with the speech's predicted opening (``audio``, ``(frames, 2)``) blended
    in by ``share``: :func:`~lipsync.selection.select.with_audio`'s rule (the prediction's
    excursion scaled by ``AUDIO_GAIN``, the opening term weighed ``AUDIO_OPEN_WEIGHT``) with
    a share of the caller's (a live session's phones are not the offline alignment's)."""
    from dataclasses import replace

    from . import select as S

    a = np.asarray(audio, np.float64)[:len(tg.opening), 0]
    a = a.mean() + S.AUDIO_GAIN * (a - a.mean())
    return replace(tg, opening=(1.0 - share) * tg.opening + share * a, open_weight=S.AUDIO_OPEN_WEIGHT)
