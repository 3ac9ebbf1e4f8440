"""The sequencer's rules, each on literal timelines, plus seeded random timelines for the invariants."""

from __future__ import annotations

import math
import random

import pytest

from lipsync.errors import InputError
from lipsync.motion.sequencer import HOLD_HALF_WIDTH_S, MAX_HELD_PAUSE_S, MAX_TRANSITION_S, MIN_SEGMENT_S, RULES, FrameSpec, frame_count, plan_segments, plan_transitions, sequence
from lipsync.motion.timeline import Segment, Timeline
from lipsync.motion.timing import get_curve

REST = "X"


def vt(*rows, end=None):
    return Timeline(tuple(Segment(s, e, v) for s, e, v in rows), kind="viseme", stated_end=end)


def shown(specs):
    return [f.shown for f in specs]


def test_rule_constants_are_consistent_with_the_issue():
    # A 200 ms segment is exactly the shortest that holds +-HOLD_HALF_WIDTH around its middle.
    assert MAX_TRANSITION_S + 2 * HOLD_HALF_WIDTH_S == pytest.approx(0.2)
    assert HOLD_HALF_WIDTH_S >= 1 / 25  # one frame at 25 fps either side of the midpoint
    assert all(len(r) == 3 and all(r) for r in RULES)


@pytest.mark.parametrize("duration,fps", [(1.0, 24), (1.01, 24), (1.358685, 25), (0.5, 1), (2.0, 120), (0.01, 30)])
def test_frame_count_is_ceil_of_duration_times_fps(duration, fps):
    specs = sequence(vt((0, duration, "A")), fps=fps, rest=REST)
    assert len(specs) == frame_count(duration, fps) == math.ceil(round(duration * fps, 9))


def test_stated_end_and_explicit_duration_extend_with_rest():
    specs = sequence(vt((0.0, 0.5, "D"), end=1.0), fps=10, rest=REST)
    assert len(specs) == 10 and shown(specs)[:4] == ["D"] * 4 and shown(specs)[-3:] == ["X"] * 3
    assert len(sequence(vt((0.0, 0.5, "D")), fps=10, rest=REST, duration=2.0)) == 20


@pytest.mark.parametrize("fps", [0, 0.5, 121, float("nan"), float("inf"), -24, "abc"])
def test_fps_outside_1_to_120_is_input_error(fps):
    with pytest.raises(InputError):
        sequence(vt((0, 1, "A")), fps=fps, rest=REST)


@pytest.mark.parametrize("fps", [1, 120])
def test_fps_limits_are_valid(fps):
    assert len(sequence(vt((0, 1, "A")), fps=fps, rest=REST)) == fps


def test_phoneme_timeline_is_refused():
    with pytest.raises(InputError, match="map"):
        sequence(Timeline((Segment(0, 1, "AA"),), kind="phoneme"), fps=24, rest=REST)


def test_gaps_are_rest():
    assert plan_segments(vt((0.2, 0.5, "D"), (0.9, 1.2, "F")), rest=REST) == [
        (0.0, 0.2, "X"), (0.2, 0.5, "D"), (0.5, 0.9, "X"), (0.9, 1.2, "F")]


def test_adjacent_equal_visemes_merge_into_one_hold():
    tl = vt((0.0, 0.3, "D"), (0.3, 0.35, "D"), (0.35, 0.7, "D"))
    assert plan_segments(tl, rest=REST) == [(0.0, 0.7, "D")]
    assert set(shown(sequence(tl, fps=120, rest=REST))) == {"D"}


def test_short_pause_holds_long_pause_rests():
    short = vt((0.0, 0.3, "D"), (0.3, 0.3 + MAX_HELD_PAUSE_S - 0.01, "X"), (0.49, 0.8, "D"))
    assert set(shown(sequence(short, fps=60, rest=REST))) == {"D"}
    gap = vt((0.0, 0.3, "D"), (0.45, 0.8, "C"))  # a 150 ms gap is a short pause too
    assert plan_segments(gap, rest=REST) == [(0.0, 0.45, "D"), (0.45, 0.8, "C")]
    long = vt((0.0, 0.3, "D"), (0.3, 0.6, "X"), (0.6, 0.9, "D"))
    specs = sequence(long, fps=25, rest=REST)
    assert specs[round(0.45 * 25)].shown == "X"
    # Leading and trailing silence stays rest however short.
    edges = plan_segments(vt((0.02, 0.5, "D"), end=0.53), rest=REST)
    assert edges[0] == (0.0, 0.02, "X") and edges[-1] == (0.5, 0.53, "X")


def test_short_non_closure_segments_are_dropped_closures_kept():
    tl = vt((0.0, 0.4, "D"), (0.4, 0.43, "B"), (0.43, 0.8, "F"))
    assert plan_segments(tl, rest=REST) == [(0.0, pytest.approx(0.415), "D"), (pytest.approx(0.415), 0.8, "F")]
    assert "B" not in {v for f in sequence(tl, fps=120, rest=REST) for v in (f.from_viseme, f.to_viseme)}
    closure = vt((0.0, 0.4, "D"), (0.4, 0.43, "A"), (0.43, 0.8, "F"))
    assert [v for _, _, v in plan_segments(closure, rest=REST, closures=["A"])] == ["D", "A", "F"]


@pytest.mark.parametrize("fps", [1, 5, 12, 24, 25, 30, 60, 120])
def test_short_closure_is_shown_fully_on_some_frame(fps):
    # A 30 ms closure placed between two frame times still closes the lips on one frame.
    start = (10.5 / fps) if fps <= 30 else 0.4
    tl = vt((0.0, start, "D"), (start, start + 0.03, "A"), (start + 0.03, start + 0.6, "D"))
    specs = sequence(tl, fps=fps, rest=REST, closures=["A"])
    assert "A" in shown(specs)
    without = sequence(tl, fps=fps, rest=REST)  # not declared a closure: dropped, never shown
    assert "A" not in shown(without)


def test_transition_follows_timing_curve_centred_on_boundary():
    tl = vt((0.0, 1.0, "X"), (1.0, 2.0, "D"))
    fps = 100
    for name in ("linear", "sqrt-fast-middle", "sqrt-fast-ends", "smoothstep"):
        f = get_curve(name)
        specs = sequence(tl, fps=fps, rest=REST, timing=name)
        t0 = 1.0 - MAX_TRANSITION_S / 2
        for n, spec in enumerate(specs):
            t = n / fps
            u = (t - t0) / MAX_TRANSITION_S
            if 0 < u < 1 and 0 < f(u) < 1:
                assert (spec.from_viseme, spec.to_viseme) == ("X", "D")
                # sqrt curves have unbounded slope at u = 1/2: float noise in u of 1e-16
                # becomes 1e-8 in alpha there.
                assert spec.alpha == pytest.approx(f(u), abs=1e-6)
            else:
                assert spec.shown == ("X" if t < 1.0 else "D")


def test_callable_timing_is_accepted():
    specs = sequence(vt((0.0, 1.0, "X"), (1.0, 2.0, "D")), fps=100, rest=REST, timing=lambda u: u ** 2)
    assert specs[100].alpha == pytest.approx(0.25)  # t = 1.0 is half-way: 0.5 ** 2


def test_alpha_zero_shows_from_and_alpha_one_to():
    f = FrameSpec("A", "D", 0.0)
    assert f.shown == "A" and FrameSpec("A", "D", 1.0).shown == "D" and FrameSpec("A", "D", 0.5).shown is None


def test_transition_windows_reach_target_by_its_middle():
    segs = [(0.0, 0.5, "X"), (0.5, 0.56, "A"), (0.56, 0.66, "D"), (0.66, 1.5, "F")]
    w = plan_transitions(segs)
    mids = [(s + e) / 2 for s, e, _ in segs]
    for k, (t0, t1) in enumerate(w):
        assert mids[k] <= t0 < t1 <= mids[k + 1]
        assert t1 - t0 <= MAX_TRANSITION_S + 1e-12


def _random_timeline(rng: random.Random, n: int):
    rows, t = [], 0.0
    names = list("ABCDEFGH")
    for _ in range(n):
        length = rng.choice([0.01, 0.03, 0.06, 0.09, 0.15, 0.2, 0.25, 0.4, 0.9]) * rng.uniform(0.8, 1.25)
        if rng.random() < 0.15:
            t += length  # a gap
            continue
        rows.append((t, t + length, rng.choice(names + ["X"])))
        t += length
    return vt(*rows, end=t + 0.1)


@pytest.mark.parametrize("fps", [24, 25, 30, 60])
def test_invariants_on_random_timelines(fps):
    rng = random.Random(fps)
    for _ in range(60):
        tl = _random_timeline(rng, 25)
        specs = sequence(tl, fps=fps, rest=REST, closures=["A"])
        assert len(specs) == frame_count(tl.duration, fps)
        segs = plan_segments(tl, rest=REST, closures=["A"])
        windows = plan_transitions(segs)
        for f in specs:
            assert 0.0 <= f.alpha <= 1.0
        for i, (s, e, v) in enumerate(segs):
            mid = (s + e) / 2
            frames = [n for n in range(len(specs)) if s <= n / fps < e]
            # Long segments show exactly their viseme from mid - 1 frame to mid + 1 frame (at 25 fps).
            if e - s >= 0.2:
                for n in frames:
                    if abs(n / fps - mid) <= 1 / 25 + 1e-9:
                        assert specs[n].shown == v, (i, segs[i], n, specs[n])
            # Reached by the middle: from the midpoint until the next transition starts, the frame is v.
            nxt = windows[i][0] if i < len(windows) else e
            for n in frames:
                if mid <= n / fps < nxt:
                    assert specs[n].shown == v or v == "A"
            # Every morph frame lies inside a transition window, between adjacent segments.
        for n, f in enumerate(specs):
            if f.shown is None:
                t = n / fps
                k = next(k for k, (t0, t1) in enumerate(windows) if t0 <= t <= t1)
                assert (f.from_viseme, f.to_viseme) == (segs[k][2], segs[k + 1][2])
        # Closures: every closure segment is shown exactly on at least one frame.
        for s, e, v in segs:
            if v == "A" and e > 0 and s < len(specs) / fps:
                assert any(f.shown == "A" and abs(n / fps - (s + e) / 2) <= max(e - s, 1 / fps)
                           for n, f in enumerate(specs))
        # No one-frame pop of a non-closure: a viseme shown exactly on one frame whose
        # neighbours are exact, different visemes, with no morph toward or away from it.
        for n in range(1, len(specs) - 1):
            v = specs[n].shown
            if v is None or v == "A":
                continue
            before, after = specs[n - 1], specs[n + 1]
            involved = {before.from_viseme, before.to_viseme, after.from_viseme, after.to_viseme}
            assert v in involved, (n, specs[n - 1: n + 2])


def test_empty_timeline_with_duration_is_all_rest():
    specs = sequence(vt(end=0.5), fps=24, rest=REST)
    assert len(specs) == 12 and set(shown(specs)) == {"X"}


def test_min_segment_constant_is_respected():
    just_above = vt((0.0, 0.5, "D"), (0.5, 0.5 + MIN_SEGMENT_S + 0.005, "B"), (0.555, 1.0, "D"))
    assert [v for _, _, v in plan_segments(just_above, rest=REST)] == ["D", "B", "D"]
