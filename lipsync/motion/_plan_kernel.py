"""Rules 1-4 of the sequencer on arrays, for long tracks (:func:`lipsync.motion.sequencer.plan_segments`).

The same rules as the sequencer's segment-by-segment code, which stays the reference for
short tracks (the live animator plans a few seconds at a time, and numba's import costs
~0.3 s): rules 1-3 are numpy over the whole track, rule 4's shortest-first drop is a heap
over a linked list compiled with numba (a 10-hour track of 10 ms cues has 3.6 million
segments: the interpreted loop took about 50 s of it, this well under a second). The
arithmetic is the same operations in the same order, so the plans are equal to the float
(tests/test_sequencer_scaling.py checks it against the round-4 loop).
"""

from __future__ import annotations

import heapq
from typing import List, Sequence, Tuple

import numpy as np


def base_arrays(starts: np.ndarray, ends: np.ndarray, codes: np.ndarray, *, rest_code: int, total: float,
                start: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rules 1-2 (:func:`lipsync.motion.frames.base_track`) on arrays of the segments' times and label codes."""
    keep = np.flatnonzero(starts > total)
    n = int(keep[0]) if len(keep) else len(starts)   # base_track stops at the first segment past the end
    starts, ends, codes = starts[:n], ends[:n], codes[:n]
    clipped_end = np.minimum(ends, total)
    t_before = np.concatenate([[float(start)], clipped_end[:-1]]) if n else np.zeros(0)
    gap = starts > t_before
    # interleave (gap before segment k, segment k), then the trailing rest
    lo = np.empty(2 * n + 1)
    hi = np.empty(2 * n + 1)
    lab = np.empty(2 * n + 1, dtype=np.int64)
    ok = np.zeros(2 * n + 1, dtype=bool)
    lo[0:2 * n:2], hi[0:2 * n:2], lab[0:2 * n:2], ok[0:2 * n:2] = t_before, starts, rest_code, gap
    lo[1:2 * n:2], hi[1:2 * n:2], lab[1:2 * n:2] = np.maximum(starts, t_before), clipped_end, codes
    ok[1:2 * n:2] = True
    t = clipped_end[-1] if n else float(start)
    lo[-1], hi[-1], lab[-1], ok[-1] = t, total, rest_code, t < total
    ok &= (hi - lo) > 0
    return merge_arrays(lo[ok], hi[ok], lab[ok])


def merge_arrays(lo: np.ndarray, hi: np.ndarray, lab: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rule 2 on arrays: runs of equal labels become one segment (first start, last end)."""
    if len(lab) == 0:
        return lo, hi, lab
    first = np.concatenate([[True], lab[1:] != lab[:-1]])
    idx = np.flatnonzero(first)
    last = np.concatenate([idx[1:] - 1, [len(lab) - 1]])
    return lo[idx], hi[last], lab[idx]


def hold_short_pauses(lo: np.ndarray, hi: np.ndarray, lab: np.ndarray, *, rest_code: int, max_held_pause: float):
    """Rule 3 on arrays: an inner rest shorter than ``max_held_pause`` takes the label before it."""
    n = len(lab)
    inner = np.zeros(n, dtype=bool)
    inner[1:n - 1] = True
    held = inner & (lab == rest_code) & ((hi - lo) < max_held_pause)
    lab = lab.copy()
    idx = np.flatnonzero(held)
    lab[idx] = lab[idx - 1]   # merged input: the one before a rest is never a rest
    return merge_arrays(lo, hi, lab)


def drop_short(lo, hi, lab, droppable, min_segment):  # pragma: no cover - compiled (run by tests uncompiled too)
    """Rule 4 (:func:`lipsync.motion.sequencer._drop_short`) on arrays, in place; returns the kept mask.

    ``droppable[code]`` is False for rest and closures. A segment keeps its index (a merge
    keeps the left one's), so the kept ones, in index order, are the track.
    """
    n = len(lo)
    prev = np.arange(-1, n - 1)
    nxt = np.arange(1, n + 1)
    if n:
        nxt[n - 1] = -1
    version = np.zeros(n, np.int64)   # bumped when a segment changes; -1 once it is gone
    heap = [(0.0, 0, 0)]               # typed for numba, emptied below
    heap.pop()
    for i in range(n):
        if hi[i] - lo[i] < min_segment and droppable[lab[i]]:
            heap.append((hi[i] - lo[i], i, 0))
    heapq.heapify(heap)
    alive = n
    while alive > 1 and len(heap) > 0:
        _, i, ver = heapq.heappop(heap)
        if ver != version[i]:
            continue
        version[i] = -1
        alive -= 1
        a, b = prev[i], nxt[i]
        if a < 0:
            lo[b] = lo[i]
        elif b < 0:
            hi[a] = hi[i]
        else:
            mid = 0.5 * (lo[i] + hi[i])
            hi[a] = mid
            lo[b] = mid
        if a >= 0:
            nxt[a] = b
        if b >= 0:
            prev[b] = a
        if a >= 0 and b >= 0 and lab[a] == lab[b]:
            hi[a] = hi[b]
            nxt[a] = nxt[b]
            if nxt[b] >= 0:
                prev[nxt[b]] = a
            version[b] = -1
            alive -= 1
        for j in (a, b):
            if j >= 0 and version[j] >= 0:
                version[j] += 1
                if hi[j] - lo[j] < min_segment and droppable[lab[j]]:
                    heapq.heappush(heap, (hi[j] - lo[j], j, version[j]))
    return version >= 0


_compiled = None


def compiled_drop_short():
    """:func:`drop_short` compiled with numba (once, cached on disk)."""
    global _compiled
    if _compiled is None:
        import numba
        _compiled = numba.njit(cache=True, nogil=True)(drop_short)
    return _compiled


def plan_arrays(segments: Sequence, *, rest: str, closures, max_held_pause: float, min_segment: float,
                total: float, start: float, compiled: bool = True) -> List[Tuple[float, float, str]]:
    """Rules 1-4 on a long track: the same plan as the sequencer's reference code."""
    names: dict = {rest: 0}
    codes = np.fromiter((names.setdefault(s.label, len(names)) for s in segments), dtype=np.int64,
                        count=len(segments))
    starts = np.fromiter((s.start for s in segments), dtype=np.float64, count=len(segments))
    ends = np.fromiter((s.end for s in segments), dtype=np.float64, count=len(segments))
    lo, hi, lab = base_arrays(starts, ends, codes, rest_code=0, total=total, start=start)
    lo, hi, lab = hold_short_pauses(lo, hi, lab, rest_code=0, max_held_pause=max_held_pause)
    label_of = list(names)
    droppable = np.array([name != rest and name not in closures for name in label_of], dtype=np.bool_)
    lo, hi = lo.copy(), hi.copy()
    kernel = compiled_drop_short() if compiled else drop_short
    kept = kernel(lo, hi, lab, droppable, float(min_segment))
    return list(zip(lo[kept].tolist(), hi[kept].tolist(), [label_of[c] for c in lab[kept].tolist()]))
