"""The sequencer's rule 4 (drop short segments) is n log n and plans exactly as the
quadratic loop it replaced did: that loop is kept below as the reference, and both plan the
same seeded random timelines (short and long segments, gaps, closures, rest, ties)."""

from __future__ import annotations

import random

import pytest

from lipsync.motion.frames import base_track, merge
from lipsync.motion._plan_kernel import plan_arrays
from lipsync.motion.sequencer import ARRAY_PLAN_FROM, MAX_HELD_PAUSE_S, MIN_SEGMENT_S, plan_segments
from lipsync.motion.timeline import Segment, Timeline

REST = "X"


def reference_plan(visemes, *, rest, closures=(), max_held_pause=MAX_HELD_PAUSE_S, min_segment=MIN_SEGMENT_S,
                   duration=None, start=0.0):
    """plan_segments as it was up to round 4 (quadratic: a list scan and a merge per drop)."""
    closure_set = set(closures)
    segs = base_track(visemes, rest=rest, duration=duration, start=start)
    held = []
    for i, s in enumerate(segs):
        inner = 0 < i < len(segs) - 1
        if s.label == rest and inner and s.duration < max_held_pause:
            held.append(Segment(s.start, s.end, held[-1].label))
        else:
            held.append(s)
    segs = merge(held)
    while len(segs) > 1:
        candidates = [i for i, s in enumerate(segs)
                      if s.duration < min_segment and s.label not in closure_set and s.label != rest]
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


def random_timeline(rng, n, labels, *, gap_p, quantum):
    t, rows = rng.choice([0.0, 0.02, 0.3]), []
    for _ in range(n):
        if rng.random() < gap_p:
            t += quantum * rng.randint(1, 30)
        # durations on a grid make ties (equal durations) common, as real cue files have
        d = quantum * rng.choice([1, 1, 2, 3, 4, 5, 8, 20, 40])
        rows.append(Segment(round(t, 6), round(t + d, 6), rng.choice(labels)))
        t = round(t + d, 6)
    return Timeline(tuple(rows), kind="viseme")


CASES = [(seed, labels, gap_p, quantum)
         for seed in range(12)
         for labels, gap_p, quantum in ((["A", "B"], 0.0, 0.01), (["A", "B", "X", "P"], 0.2, 0.01),
                                        (list("ABCDEFGHX"), 0.1, 0.013), (["A", "P", "X"], 0.4, 0.025))]


@pytest.mark.parametrize("seed,labels,gap_p,quantum", CASES)
def test_plan_equals_the_quadratic_reference(seed, labels, gap_p, quantum):
    rng = random.Random(seed)
    tl = random_timeline(rng, rng.randint(1, 400), labels, gap_p=gap_p, quantum=quantum)
    duration = tl.duration + rng.choice([0.0, 0.0, 0.5])
    closures = rng.choice([(), ("P",), ("P", "B")])
    got = plan_segments(tl, rest=REST, closures=closures, duration=duration)
    assert got == reference_plan(tl, rest=REST, closures=closures, duration=duration)
    # the plan covers the track without gaps or overlaps
    assert got[0][0] == 0.0 and got[-1][1] == duration
    assert all(a[1] == b[0] and a[2] != b[2] for a, b in zip(got, got[1:]))


@pytest.mark.parametrize("seed", range(6))
def test_plan_from_a_cut_point_equals_the_reference(seed):
    # the live animator plans from a start inside the track, with other rule constants
    rng = random.Random(100 + seed)
    tl = random_timeline(rng, 200, list("ABPX"), gap_p=0.2, quantum=0.01)
    cut = round(tl.duration * rng.random(), 3)
    segs = Timeline(tuple(s for s in tl if s.start >= cut), kind="viseme")
    kw = dict(rest=REST, closures=("P",), start=cut, duration=tl.duration, min_segment=0.07, max_held_pause=0.1)
    assert plan_segments(segs, **kw) == reference_plan(segs, **kw)


def test_alternating_10ms_cues_plan_as_the_reference():
    # the case: Rhubarb cues alternating every 10 ms (the quadratic loop's worst case)
    tl = Timeline(tuple(Segment(i / 100, (i + 1) / 100, "AB"[i % 2]) for i in range(1500)), kind="viseme")
    assert plan_segments(tl, rest=REST) == reference_plan(tl, rest=REST)


def test_edge_tracks():
    for rows in ([], [(0, 0.01, "A")], [(0, 0.01, "A"), (0.01, 0.02, "B")], [(0.5, 0.51, "A")]):
        tl = Timeline(tuple(Segment(*r) for r in rows), kind="viseme")
        assert plan_segments(tl, rest=REST, duration=1.0) == reference_plan(tl, rest=REST, duration=1.0)


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("seed,labels,gap_p,quantum", CASES[::3])
def test_array_plan_equals_the_reference(compiled, seed, labels, gap_p, quantum):
    # long tracks are planned on arrays (numpy rules 1-3, numba rule 4): the same plan
    rng = random.Random(seed)
    tl = random_timeline(rng, rng.randint(1, 600), labels, gap_p=gap_p, quantum=quantum)
    duration = tl.duration + rng.choice([0.0, 0.5])
    closures = rng.choice([(), ("P",)])
    kw = dict(rest=REST, closures=closures, max_held_pause=MAX_HELD_PAUSE_S, min_segment=MIN_SEGMENT_S)
    got = plan_arrays(tl, total=duration, start=0.0, compiled=compiled, **kw)
    assert got == reference_plan(tl, duration=duration, **kw)


@pytest.mark.parametrize("compiled", [False, True])
def test_array_plan_from_a_cut_point_and_edges(compiled):
    rng = random.Random(7)
    tl = random_timeline(rng, 300, list("ABPX"), gap_p=0.2, quantum=0.01)
    cut = round(tl.duration / 3, 3)
    segs = Timeline(tuple(s for s in tl if s.start >= cut), kind="viseme")
    kw = dict(rest=REST, closures={"P"}, min_segment=0.07, max_held_pause=0.1)
    assert (plan_arrays(segs, total=tl.duration, start=cut, compiled=compiled, **kw)
            == reference_plan(segs, duration=tl.duration, start=cut, **kw))
    for rows in ([], [(0, 0.01, "A")], [(0, 0.01, "A"), (0.01, 0.02, "B")], [(0.5, 0.51, "A")], [(0, 2, "A")]):
        tl = Timeline(tuple(Segment(*r) for r in rows), kind="viseme")
        kw = dict(rest=REST, closures=(), min_segment=MIN_SEGMENT_S, max_held_pause=MAX_HELD_PAUSE_S)
        assert plan_arrays(tl, total=1.0, start=0.0, compiled=compiled, **kw) == reference_plan(tl, duration=1.0, **kw)


def test_plan_segments_takes_the_array_path_on_long_tracks(monkeypatch):
    # the quadratic reference takes minutes at this length: the segment-by-segment heap path
    # (checked against it above) is the reference here
    import lipsync.motion.sequencer as sequencer
    n = ARRAY_PLAN_FROM + 10
    tl = Timeline(tuple(Segment(i / 100, (i + 1) / 100, "ABP"[i % 3]) for i in range(n)), kind="viseme")
    arrays = plan_segments(tl, rest=REST, closures=("P",))
    monkeypatch.setattr(sequencer, "ARRAY_PLAN_FROM", 10 ** 9)
    assert arrays == plan_segments(tl, rest=REST, closures=("P",))


def test_json_array_lines_counted_on_equal_counting_from_the_start():
    # the reader's element lines (for messages) are counted on from the element before
    # (counting from the start for each element made a 40,000-cue Rhubarb JSON quadratic)
    import json

    from lipsync.readers._common import json_array_lines

    rng = random.Random(3)
    cues = [{"start": i / 100, "end": (i + 1) / 100, "value": "AB"[i % 2]} for i in range(300)]
    text = json.dumps({"mouthCues": cues}, indent=rng.choice([1, 2, 4]))
    text = text.replace("},", "}," + "\n" * rng.randint(0, 2))   # blank lines between the elements
    pos = text.index("[") + 1
    starts, depth, naive = [], 0, []
    for i, ch in enumerate(text[pos:], pos):   # the naive count: each element's first "{"
        if ch == "{":
            if depth == 0:
                naive.append(text.count("\n", 0, i) + 1)
            depth += 1
        elif ch == "}":
            depth -= 1
    assert len(naive) == 300 and json_array_lines(text, "mouthCues") == naive
