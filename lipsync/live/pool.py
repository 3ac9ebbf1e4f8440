"""A small pool of renderers that many live animators (server sessions) share.

A :class:`lipsync.morphing.render.Renderer` keeps per-pair state (ROI-sized flows, Jacobians, maps:
a few MB per viseme pair) and is not thread-safe. One renderer per live session would cost
memory per session; one shared renderer would serialise all rendering. A pool of ``size``
renderers (default: one per core) over one normalised bank bounds both: at most ``size``
frames are made at once, whatever the number of sessions.

Examples
--------
>>> from lipsync import Bank
>>> from lipsync._data import default_bank_dir
>>> pool = RendererPool(Bank.load(default_bank_dir()), size=2)
>>> pool.render("X", "D", 0.5).shape
(512, 512, 3)
"""

from __future__ import annotations

import os
import queue
from typing import Optional

import numpy as np

from ..morphing.render import Renderer
from ..morphing.store import FlowStore


class RendererPool:
    """``size`` Renderers of one bank; :meth:`render` is thread-safe.

    Parameters
    ----------
    bank : Bank or NormalisedBank
        The subject (normalised once, shared by every renderer of the pool).
    method : str
        Renderer method.
    store : FlowStore, optional
        Flow store (default: the bank's).
    size : int, optional
        Renderers in the pool (default: the number of cores).
    """

    def __init__(self, bank, *, method: str = "flow", store: Optional[FlowStore] = None, size: Optional[int] = None):
        first = Renderer(bank, method=method, store=store)
        self.nb, self.store, self.method, self.shape = first.nb, first.store, first.method, first.shape
        self.channels = first.channels
        self.bank = first.bank
        self.size = max(1, int(size or os.cpu_count() or 1))
        self._free: "queue.Queue[Renderer]" = queue.Queue()
        self._free.put(first)
        for _ in range(self.size - 1):
            self._free.put(Renderer(self.nb, method=method, store=self.store))

    def render(self, from_viseme: str, to_viseme: str, alpha: float, *, out: Optional[np.ndarray] = None
               ) -> np.ndarray:
        """The frame at ``alpha`` between two visemes, into ``out`` (a new array if None)."""
        if out is None:
            out = np.empty(self.shape + (self.channels,), np.uint8)
        renderer = self._free.get()
        try:
            return renderer.render(from_viseme, to_viseme, alpha, out=out)
        finally:
            self._free.put(renderer)

    def warm(self, pairs) -> None:
        """Make every renderer's state for the ``(from, to)`` viseme ``pairs`` now.

        A pair's first in-between frame allocates its buffers and solves its anchors; a
        server that warms the pairs its speech uses keeps that off the live path.
        """
        renderers = [self._free.get() for _ in range(self.size)]
        try:
            out = np.empty(self.shape + (self.channels,), np.uint8)
            for r in renderers:
                for a, b in pairs:
                    r.render(a, b, 0.5, out=out)
        finally:
            for r in renderers:
                self._free.put(r)
