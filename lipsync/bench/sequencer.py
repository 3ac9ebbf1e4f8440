"""Sequencer planning figure (issue 38): how long rules 1-4 take on long cue files.

Rhubarb JSON with 10 ms cues alternating between two mouth shapes is the worst case of
rule 4 (every cue is too short and is dropped, shortest first). Measured side by side:
the round-4 loop (a list scan and a merge per drop, quadratic; copied here as the
baseline), the segment-by-segment heap (what short tracks and the live animator use) and
the array path (numpy rules 1-3, a numba-compiled rule 4; tracks of
:data:`~lipsync.motion.sequencer.ARRAY_PLAN_FROM` segments or more). The 10-hour row is a
10 ms timeline of 3.6 million cues, built in memory (reading such a file is the readers'
figure, not this one). ``python -m lipsync.bench --only sequencer``.
"""

from __future__ import annotations

import time
from typing import List

from . import FIGURES, Context


def _alternating(n: int):
    from ..motion.timeline import Segment, Timeline
    return Timeline(tuple(Segment(i / 100, (i + 1) / 100, "AB"[i % 2]) for i in range(n)), kind="viseme")


def _quadratic(visemes, *, rest: str):
    """plan_segments' rule 4 as it was in round 4 (the baseline)."""
    from ..motion.frames import base_track, merge
    from ..motion.sequencer import MIN_SEGMENT_S
    from ..motion.timeline import Segment
    segs = base_track(visemes, rest=rest)  # no pauses in these tracks: rule 3 has nothing to do
    while len(segs) > 1:
        candidates = [i for i, s in enumerate(segs) if s.duration < MIN_SEGMENT_S and s.label != rest]
        if not candidates:
            break
        i = min(candidates, key=lambda k: segs[k].duration)
        s = segs[i]
        if i == 0:
            segs[1] = Segment(s.start, segs[1].end, segs[1].label)
        elif i == len(segs) - 1:
            segs[i - 1] = Segment(segs[i - 1].start, s.end, segs[i - 1].label)
        else:
            segs[i - 1] = Segment(segs[i - 1].start, s.mid, segs[i - 1].label)
            segs[i + 1] = Segment(s.mid, segs[i + 1].end, segs[i + 1].label)
        del segs[i]
        segs = merge(segs)
    return [(s.start, s.end, s.label) for s in segs]


def _seconds(fn) -> float:
    t = time.perf_counter()
    fn()
    return round(time.perf_counter() - t, 3)


@FIGURES.decorator("sequencer")
def sequencer_figure(ctx: Context, rows: List[dict]) -> None:
    import lipsync.motion.sequencer as sq
    from ..motion._plan_kernel import compiled_drop_short

    compiled_drop_short()  # numba's compile (or cache load) is not the plan's time
    sizes = [5_000, 10_000, 40_000] + ([] if ctx.quick else [3_600_000])
    for n in sizes:
        tl = _alternating(n)
        row = {"figure": "sequencer", "cues": n, "hours": round(n / 100 / 3600, 3)}
        if n <= 10_000:
            row["round4_s"] = _seconds(lambda: _quadratic(tl, rest="X"))
        if n <= 40_000:
            saved, sq.ARRAY_PLAN_FROM = sq.ARRAY_PLAN_FROM, 10 ** 12
            try:
                row["heap_s"] = _seconds(lambda: sq.plan_segments(tl, rest="X"))
            finally:
                sq.ARRAY_PLAN_FROM = saved
        cpu = time.process_time()
        row["plan_s"] = _seconds(lambda: sq.plan_segments(tl, rest="X"))
        row["plan_cpu_s"] = round(time.process_time() - cpu, 3)   # steadier than wall time on a shared machine
        if "round4_s" in row:
            row["round4_over_plan"] = round(row["round4_s"] / max(row["plan_s"], 1e-6), 1)
        rows.append(row)
