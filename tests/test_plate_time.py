"""Plate time (issue 36 items 3 and 4): where a clip starts on the plate, and how a plate
shorter than the output is extended (lipsync.composite.plate_time) -- on synthetic plates
whose frames, blinks and motion are known, and on the shipped grid-s1 bank's real plate."""

from __future__ import annotations

import numpy as np
import pytest

from lipsync.composite.plate_time import (BLINK_MARGIN, MIN_JUMP_S, PlateTimeline, PlateTimes, blink_runs,
                                          default_start)

FPS = 25.0


def _plate(n=80, blinks=((20, 24), (55, 58)), seed=0):
    """A head that sways (a slow random walk, 2 coordinates per point) and blinks at ``blinks``."""
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(0, 0.01, (n, 2)), axis=0)
    feats = np.concatenate([walk + rng.normal(0, 0.001, (n, 2)) for _ in range(8)], axis=1)
    eyes = np.full(n, 0.3) + rng.normal(0, 0.003, n)
    for a, b in blinks:
        eyes[a:b] = 0.1
    return feats, eyes


def _joins(plan):
    return [k for k in range(1, len(plan)) if plan[k] != plan[k - 1] + 1]


def _showings(plan, start):
    """Output steps where the plate frame ``start`` (a blink's first frame) begins to show."""
    return [k for k in range(len(plan)) if plan[k] == start and (k == 0 or plan[k - 1] != start)]


def test_blink_runs_are_found_below_the_share_of_the_median():
    e = np.array([1.0, 1.0, 0.75, 0.5, 1.0, np.nan, 0.79, 1.0, 1.0, 1.0, 1.0])  # median 1
    assert blink_runs(e) == [(2, 4), (6, 7)]
    assert blink_runs(np.full(4, np.nan)) == []


def test_a_long_timeline_never_joins_into_or_out_of_a_blink_and_shows_each_one_whole():
    feats, eyes = _plate()
    times = PlateTimes(feats, eyes, FPS)
    assert times.blinks == [(20, 24), (55, 58)]
    plan = PlateTimeline(times, start=0.3).frames(1500)  # a minute of a 3.2 s plate
    busy = set()
    for a, b in times.blinks:
        busy |= set(range(a - BLINK_MARGIN, b + BLINK_MARGIN))
    joins = _joins(plan)
    assert len(joins) > 15
    for k in joins:
        assert plan[k - 1] not in busy and plan[k] not in busy, (k, plan[k - 1], plan[k])
        # a join is a jump, never a stutter of a frame or two (ping-pong's turn is one)
        assert abs(int(plan[k]) - int(plan[k - 1] + 1)) >= round(MIN_JUMP_S * FPS)
    for a, b in times.blinks:  # every showing of a blink plays all its frames in order
        for k in _showings(plan, a):
            assert list(plan[k:k + b - a]) == list(range(a, b))


def test_no_blink_is_shown_again_within_four_seconds():
    feats, eyes = _plate()
    plan = PlateTimeline(PlateTimes(feats, eyes, FPS), start=0.0).frames(1500)
    every = []
    for a, _ in [(20, 24), (55, 58)]:
        shown = _showings(plan, a)
        every += shown
        assert len(shown) == 1 or min(np.diff(shown)) >= 4 * FPS, shown
    # blinks keep coming (people blink every 2-10 s): at least one per 10 s of the minute
    assert len(every) >= 6 and max(np.diff(sorted(every + [len(plan)]))) <= 12 * FPS, sorted(every)
    # ping-pong (every dub and render before) shows them again at every turn, 2.4-3.2 s apart
    from lipsync.composite.plate import pingpong

    pp = [pingpong(i, 80) for i in range(1500)]
    assert min(np.diff(_showings(pp, 20))) < 4 * FPS


def test_joins_land_where_the_frames_match():
    # a head nodding with a period of 20 frames: a join lands on the same phase of the nod
    n = 90
    phase = np.arange(n) * 2 * np.pi / 20
    feats = np.stack([np.sin(phase), np.cos(phase)], axis=1) + np.random.default_rng(1).normal(0, 0.01, (n, 2))
    times = PlateTimes(feats, np.ones(n), FPS)
    plan = PlateTimeline(times, start=0.0).frames(1000)
    joins = _joins(plan)
    assert joins
    for k in joins:  # the frame shown is the one that would have come next, 20 frames away
        assert (int(plan[k]) - int(plan[k - 1] + 1)) % 20 in (0, 1, 19), (plan[k - 1], plan[k])


def test_the_plan_is_reproducible_and_the_start_moves_it():
    feats, eyes = _plate()
    times = PlateTimes(feats, eyes, FPS)
    a, b = PlateTimeline(times, 0.4).frames(300), PlateTimeline(times, 0.4).frames(300)
    c = PlateTimeline(times, 0.75).frames(300)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert a[0] == 32 and c[0] == 60  # 0.4 and 0.75 of 80 frames
    # a start inside a blink moves back to its beginning: a blink is never cut in half
    assert PlateTimeline(times, 22 / 80).frame(0) == 20 - BLINK_MARGIN


def test_default_start_follows_the_content():
    assert default_start([(0.0, 0.5, "A")]) == default_start([(0.0, 0.5, "A")])
    starts = [default_start([(0.0, 0.5, v)]) for v in "ABCDEFGH"]
    assert all(0 <= s < 1 for s in starts) and len(set(starts)) == 8
    assert np.std(starts) > 0.1  # spread over the plate, not bunched at its start


@pytest.fixture(scope="module")
def grid_bank():
    from lipsync._data import shipped_banks
    from lipsync.banks.bank import Bank

    return Bank.load(shipped_banks()["grid-s1"])


def test_two_sentences_on_grid_s1_differ_above_the_nose_and_one_sentence_is_reproducible(grid_bank):
    from lipsync.motion.timeline import Segment, Timeline
    from lipsync.pipeline.animator import Animator

    one = Timeline((Segment(0.2, 0.4, "B"), Segment(0.4, 0.7, "AA"), Segment(0.7, 0.9, "N")), kind="phoneme")
    two = Timeline((Segment(0.3, 0.5, "P"), Segment(0.5, 0.8, "L"), Segment(0.8, 1.0, "EY")), kind="phoneme")
    a, a2, b = (Animator(grid_bank, t, fps=25) for t in (one, one, two))
    assert a.plate_start == a2.plate_start != b.plate_start
    top = min(a.plate.compositor.roi(p, a.plate.frames.shape[1:])[1] for p in a.plate.poses)
    n = min(len(a), len(b))
    same = [np.array_equal(a.frame(i)[:top], a2.frame(i)[:top]) for i in range(0, n, 3)]
    diff = [np.abs(a.frame(i)[:top].astype(np.int16) - b.frame(i)[:top]).mean() for i in range(0, n, 3)]
    assert all(same)
    assert min(diff) > 0.3, diff  # above the nose every frame shows another moment of the plate
    # --plate-start given: both at one place, the same frames above the nose
    c, d = Animator(grid_bank, one, fps=25, plate_start=1.0), Animator(grid_bank, two, fps=25, plate_start=1.0)
    assert all(np.array_equal(c.frame(i)[:top], d.frame(i)[:top]) for i in range(0, n, 3))
    assert c.plate.index(0, 25.0, c.plate_line) == 25


def test_render_takes_plate_start_and_refuses_a_negative_one(tmp_path, capsys):
    from lipsync.cli import main

    assert main(["render", "samples/hello.TextGrid", "--bank", "grid-s1", "--plate-start", "-1",
                 "-o", str(tmp_path / "o.mp4"), "-q"]) == 2
    assert "--plate-start must be a number of seconds" in capsys.readouterr().err
    assert not (tmp_path / "o.mp4").exists()


def test_a_live_render_follows_a_plate_timeline_too(grid_bank):
    # render --live (LiveClip) starts the plate where a live session does (its start), on the
    # plate timeline Plate.index follows by default
    from pathlib import Path

    from lipsync.pipeline.liveclip import LiveClip

    wav = Path(__file__).parents[1] / "samples" / "hello.wav"
    clip = LiveClip(grid_bank, wav, fps=25)
    again = LiveClip(grid_bank, wav, fps=25)
    assert clip.plate_line is not None and clip.plate_start == again.plate_start == 0.0
    assert [clip.plate.index(i, 25.0, clip.plate_line) for i in range(len(clip))] == \
        [clip.plate.index(i, 25.0) for i in range(len(clip))]
    top = min(clip.plate.compositor.roi(p, clip.plate.frames.shape[1:])[1] for p in clip.plate.poses)
    for i in (0, 30, len(clip) - 1):
        j = clip.plate.index(i, 25.0, clip.plate_line)
        assert np.array_equal(clip.frame(i)[:top], clip.plate.frames[j][:top])
