"""A long live session with mouth samples costs per frame what a short one does (issue 35,
round 5's live costs).

* Each look-ahead window's target takes the samples' per-phone medians from a memo kept per
  samples object (:func:`lipsync.selection.select._groups`): the same medians as computing
  them afresh, so a session fixes the same samples and renders the same pixels.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lipsync import Bank
from lipsync._data import default_bank_dir
from lipsync.live import LiveAnimator
from lipsync.live.audio import BLOCK, RATE
from lipsync.selection import select as S
from lipsync.speech.audio import load_audio

AUDIO = Path(__file__).resolve().parent / "data" / "grid-s1-audio"
GRID_BANK = default_bank_dir().parent / "grid-s1"


@pytest.fixture(scope="module")
def bank():
    return Bank.load(GRID_BANK)


@pytest.fixture(scope="module")
def pcm():
    return load_audio(AUDIO / "bram2n.flac")[:int(2.4 * RATE)]


def _audio_session(bank, pcm):
    live = LiveAnimator(bank, fps=25, prepare=False, samples="on")
    frames = {}
    for i in range(0, len(pcm), BLOCK):
        for n in live.feed_audio(pcm[i:i + BLOCK], RATE):
            frames[n] = live.frame(n).copy()
    for n in live.finish_audio():
        frames[n] = live.frame(n).copy()
    return live, frames


def test_memoised_medians_fix_the_same_samples_and_pixels_as_computing_them_afresh(bank, pcm, monkeypatch):
    monkeypatch.setattr(S, "MEMO_MEDIANS", False)
    plain, plain_frames = _audio_session(bank, pcm)
    monkeypatch.setattr(S, "MEMO_MEDIANS", True)
    memo, memo_frames = _audio_session(bank, pcm)
    assert len(plain_frames) >= 55 and sorted(memo_frames) == sorted(plain_frames)
    assert memo.samples.selection.windows >= 50
    assert memo.samples.selection.path == plain.samples.selection.path
    assert all(np.array_equal(memo_frames[n], plain_frames[n]) for n in plain_frames)
    # the memo is the bank's: a second session reads the medians the first one computed
    proxy = memo.samples.selection._samples
    again = LiveAnimator(bank, fps=25, prepare=False, samples="on")
    assert again.samples.selection._samples is proxy
    assert S._groups(proxy) is S._groups(again.samples.selection._samples)


def test_phone_schedule_from_the_memo_equals_the_medians_afresh(bank, monkeypatch):
    """A timeline with phones the footage said (closures among them), phones it never said
    (their viseme's samples) and silence: the memo's schedule is the one computed afresh
    with :func:`lipsync.selection.select._medians`, value for value."""
    from lipsync.motion.timeline import Segment, Timeline

    live = LiveAnimator(bank, fps=25, prepare=False, samples="on")
    sel = live.samples.selection.selector
    said = set(sel.samples.labels.tolist())
    phones = ["B", "AE1", "ZH", "M", "OY1", "T", "UW1", "P", "NG"]
    assert {"B", "P", "AE1", "UW1"} <= said and not {"ZH", "OY1", "M", "NG"} & said     # said, and never said
    tl = Timeline(tuple(Segment(0.1 + 0.12 * k, 0.22 + 0.12 * k, p) for k, p in enumerate(phones)), kind="phoneme")
    n = 35
    args = (tl, n, 25.0, sel.pmap, sel.rest, sel.closures)
    monkeypatch.setattr(S, "MEMO_MEDIANS", False)
    afresh = S.phone_schedule(sel.samples, *args)
    monkeypatch.setattr(S, "MEMO_MEDIANS", True)
    memo = S.phone_schedule(sel.samples, *args)
    again = S.phone_schedule(sel.samples, *args)
    for a, b, c in zip(afresh, memo, again):
        assert a.shape == (n,) and np.array_equal(a, b) and np.array_equal(b, c)
    # the closures' medians are of closed lips (M, never said, its viseme's closed samples):
    # the schedule is lower on B, M and P than on the vowels around them
    at = {p: int((0.16 + 0.12 * k) * 25) for k, p in enumerate(phones)}
    assert max(afresh[0][at[p]] for p in "BMP") < min(afresh[0][at[p]] for p in ("AE1", "OY1"))


# --- a far jump of the clock restarts the plate's plan ------------------------------------

def test_a_far_jump_shows_the_restarted_plans_plate_frame_without_planning_the_way(bank):
    """A session told its clock is 24 h in: the plate's plan restarts near that step (at
    most RESTART_S of steps planned, where planning the way was 2.16 million steps), and the
    frame shows the plate frame the restarted plan gives for it, above the mouth exactly."""
    from lipsync.composite.plate_time import RESTART_S, PlateTimeline

    live = LiveAnimator(bank, fps=25, prepare=False, samples="on")
    for n in range(5):
        live.frame(n)
    line, plate = live._plate_line, live.plate
    k = int(round(86400 * plate.fps))               # the plate's step at 24 h
    got = live.frame_at(86400.0)
    step = int(round(RESTART_S * plate.fps))
    assert line._seg[0] == k - k % step and line.planned <= step + 2 * len(plate)
    top = min(plate.compositor.roi(p, plate.frames.shape[1:])[1] for p in plate.poses)
    assert top > 0.4 * plate.frames.shape[1]
    j = line.frame(k)
    assert np.array_equal(got[:top], plate.frames[j][:top])
    # the restart is a function of the clip's start and the step: another session there agrees
    other = PlateTimeline(plate.times, start=(live.plate_start * plate.fps / len(plate)) % 1.0).restarting()
    assert other.frame(k) == j and other.planned == line.planned
    # and going back to the start plans the plate from the start again: a fresh session's
    # plate frames (the mouth of a frame before a jump is the morph's rest: never fixed)
    fresh = LiveAnimator(bank, fps=25, prepare=False, samples="on")
    assert all(np.array_equal(live.frame(n)[:top], fresh.frame(n)[:top]) for n in (0, 1, 2, 60))
    assert line._seg[0] == 0


def test_ordinary_playback_with_restarts_on_is_the_continuous_plan(bank):
    """Steps asked in order, some skipped (a player that drops frames) but none by
    RESTART_S: the plan of a timeline that restarts at far jumps is the continuous one."""
    from lipsync.composite.plate_time import RESTART_S, PlateTimeline

    live = LiveAnimator(bank, fps=25, prepare=False, samples="off")
    times = live.plate.times
    plain = PlateTimeline(times, start=0.37).frames(3000)
    line = PlateTimeline(times, start=0.37).restarting()
    skip = int(RESTART_S * times.fps) - 1
    ahead = np.cumsum(np.random.default_rng(3).choice([1, 1, 1, 2, 7, skip], 120))
    asked = [0, 1, 2] + [int(k) for k in ahead if k < 3000] + [2999, 1500, 0]     # then back within the plan
    assert max(np.diff(asked[:-2])) == skip and len(asked) > 40
    assert [line.frame(k) for k in asked] == plain[asked].tolist()
    assert line._seg[0] == 0 and 3000 <= line.planned < 3000 + len(live.plate)   # (whole runs)
    assert len(set(plain.tolist())) > 0.5 * len(live.plate)     # the plan does move over the plate
