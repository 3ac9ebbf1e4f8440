"""The dynamic programme: the cheapest path through a lattice of candidates, one set per frame.

A path picks one candidate per frame; its cost is the sum of every pick's *target* cost and
of the *join* cost between consecutive picks. :class:`Viterbi` adds one frame at a time
(the candidates of frame t may depend on the best costs so far: the selection offers the
successors of the cheapest ones) and :meth:`Viterbi.path` backtracks.

Examples
--------
>>> import numpy as np
>>> v = Viterbi()
>>> v.step(np.array([10, 11]), np.array([0.0, 1.0]))
>>> v.step(np.array([11, 12]), np.array([1.0, 0.0]), np.array([[0.0, 5.0], [5.0, 0.0]]))
>>> v.path(), v.cost
([10, 11], 1.0)
"""

from __future__ import annotations

from typing import Callable, List, Optional, Sequence

import numpy as np


class Viterbi:
    """Incremental Viterbi over per-frame candidate sets (see the module docstring)."""

    def __init__(self):
        self._ids: List[np.ndarray] = []
        self._back: List[np.ndarray] = []
        self.costs: Optional[np.ndarray] = None  # cumulative cost of the best path ending at each candidate

    def __len__(self) -> int:
        return len(self._ids)

    @property
    def last(self) -> np.ndarray:
        """The previous frame's candidate ids."""
        return self._ids[-1]

    def step(self, ids: np.ndarray, target: np.ndarray, join: Optional[np.ndarray] = None) -> None:
        """Add a frame: candidate ``ids`` ``(K,)``, their ``target`` costs ``(K,)`` and, after the
        first frame, ``join`` ``(K_prev, K)``: the cost of each previous candidate followed by each."""
        ids, target = np.asarray(ids), np.asarray(target, np.float64)
        if self.costs is None:
            self.costs = target.copy()
            self._back.append(np.full(len(ids), -1, np.int64))
        else:
            total = self.costs[:, None] + np.asarray(join, np.float64)
            best = np.argmin(total, axis=0)
            self.costs = total[best, np.arange(len(ids))] + target
            self._back.append(best)
        self._ids.append(ids)

    @property
    def cost(self) -> float:
        """The cheapest path's total cost so far."""
        return float(self.costs.min())

    def path(self) -> List:
        """The candidate ids of the cheapest path, one per frame."""
        if self.costs is None:
            return []
        k = int(np.argmin(self.costs))
        out = []
        for t in range(len(self._ids) - 1, -1, -1):
            out.append(self._ids[t][k].item())
            k = int(self._back[t][k])
        return out[::-1]


def best_path(candidates: Sequence[np.ndarray], targets: Sequence[np.ndarray],
              join: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> List:
    """The cheapest path through a fixed lattice: ``candidates[t]`` ids, ``targets[t]`` their
    costs, ``join(prev_ids, ids)`` the ``(K_prev, K)`` join costs.

    Examples
    --------
    >>> import numpy as np
    >>> c = [np.array([0, 1]), np.array([0, 1]), np.array([0, 1])]
    >>> t = [np.array([0.0, 0.5]), np.array([0.9, 0.0]), np.array([0.0, 0.9])]
    >>> best_path(c, t, lambda a, b: 0.6 * (a[:, None] != b[None, :]))
    [0, 0, 0]
    """
    v = Viterbi()
    for t, (ids, cost) in enumerate(zip(candidates, targets)):
        v.step(ids, cost, None if t == 0 else join(v.last, np.asarray(ids)))
    return v.path()
