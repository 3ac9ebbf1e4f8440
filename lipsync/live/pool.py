"""A small pool of renderers that many live animators (server sessions) share, and the idle
plate they composite onto, decoded once per process (:func:`shared_plate`).

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

import hashlib
import os
import queue
import threading
import weakref
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

    def render(self, from_viseme: str, to_viseme: str, alpha: float, *, out: Optional[np.ndarray] = None,
               region=None) -> np.ndarray:
        """The frame at ``alpha`` between two visemes, into ``out`` (a new array if None);
        with ``region`` (a :class:`lipsync.morphing.store.Crop`) only that box need be right
        (:meth:`lipsync.morphing.render.Renderer.render`)."""
        if out is None:
            out = np.empty(self.shape + (self.channels,), np.uint8)
        renderer = self._free.get()
        try:
            return renderer.render(from_viseme, to_viseme, alpha, out=out, region=region)
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


# --- the idle plate, shared --------------------------------------------------------------------
#: Plates decoded in this process, by what they are made from (:func:`_plate_key`); weak, so a
#: plate no animator or pool holds any more is freed (a server's sessions of one bank hold the
#: same one: ~30 MB for grid-s1's 4 s at its size, decoded once, not once per session).
_PLATES: "weakref.WeakValueDictionary" = weakref.WeakValueDictionary()
_PLATES_LOCK = threading.Lock()


def _plate_key(bank) -> tuple:
    """What a loaded plate depends on: its three files (path, size, modification time), the
    bank's size and its rest picture (the plate is brought to that picture's colour)."""
    files = bank.plate
    stats = []
    for path in (files.video, files.poses, files.mask):
        st = os.stat(path)
        stats.append((os.path.realpath(path), st.st_size, st.st_mtime_ns))
    rest = np.ascontiguousarray(bank.images[bank.rest])
    return tuple(stats) + (tuple(bank.shape), hashlib.blake2b(rest.tobytes(), digest_size=16).hexdigest())


def shared_plate(bank):
    """The bank's idle plate (:func:`lipsync.composite.plate.load_plate`), decoded once per
    process and shared by every caller while any holds it; None when the bank has none, it
    is switched off, or the bank is transparent (plates are RGB).

    Its frames are read-only to callers: :meth:`lipsync.composite.plate.Plate.render_into`
    copies a frame before it draws on it.

    Examples
    --------
    >>> from lipsync import Bank
    >>> from lipsync._data import default_bank_dir
    >>> bank = Bank.load(default_bank_dir().parent / "grid-s1")
    >>> a = shared_plate(bank); b = shared_plate(Bank.load(default_bank_dir().parent / "grid-s1"))
    >>> a is b, len(a) > 0, shared_plate(Bank.load(default_bank_dir())) is None
    (True, True, True)
    """
    if getattr(bank, "plate", None) is None or not bank.plate.enabled or bank.channels != 3:
        return None
    from ..composite.plate import load_plate

    key = _plate_key(bank)
    with _PLATES_LOCK:   # held while decoding: two sessions starting at once decode it once
        plate = _PLATES.get(key)
        if plate is None:
            plate = load_plate(bank)
            if plate is None:  # pragma: no cover - load_plate returns None only when disabled
                return None
            plate.frames.setflags(write=False)
            _PLATES[key] = plate
        return plate
