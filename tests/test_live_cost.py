"""A long live session with mouth samples costs per frame what a short one does (issue 35,
round 5's live costs).

* Each look-ahead window's target takes the samples' per-phone medians from a memo kept per
  samples object (:func:`lipsync.selection.select._groups`): the same medians as computing
  them afresh, so a session fixes the same samples and renders the same pixels.
* A clock told it is 24 h in restarts the plate's plan near that step
  (:meth:`lipsync.composite.plate_time.PlateTimeline.restarting`) rather than planning 2.16
  million steps; ordinary playback is the continuous plan.
* The running audio features keep exact running statistics and only the rows windows still
  read (:meth:`lipsync.speech.features.RunningFeatures.forget`): an hour holds a bounded
  number of rows, and the last frames' features are the whole hour's normalisation.
* A session mixing audio and pushed phoneme events gives the samples' target the events'
  phones where they lie (as their visemes win over the audio's), the audio's elsewhere.
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

from live_session import audio_session

AUDIO = Path(__file__).resolve().parent / "data" / "grid-s1-audio"
GRID_BANK = default_bank_dir().parent / "grid-s1"


@pytest.fixture(scope="module")
def bank():
    return Bank.load(GRID_BANK)


@pytest.fixture(scope="module")
def pcm():
    return load_audio(AUDIO / "bram2n.flac")[:int(2.4 * RATE)]


def _audio_session(bank, pcm):
    return audio_session(bank, pcm, prepare=False, samples="on")


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


def test_a_long_live_plan_keeps_its_last_steps_and_plays_as_the_continuous_one(bank, monkeypatch):
    """A live plan drops the plate frames of old steps (KEEP_S, here 10 s): played step by
    step for 10 000 steps it shows the continuous plan's frames, holding at most 2 KEEP_S
    and a run of them; a step older than those kept is a far jump back (a restart)."""
    import lipsync.composite.plate_time as P

    monkeypatch.setattr(P, "KEEP_S", 10.0)
    times = LiveAnimator(bank, fps=25, prepare=False, samples="off").plate.times
    plain = P.PlateTimeline(times, start=0.61).frames(10000)
    line = P.PlateTimeline(times, start=0.61).restarting()
    held = []
    for k in range(10000):
        assert line.frame(k) == plain[k], k
        held.append(line.planned)
    keep = int(10.0 * times.fps)
    assert max(held) <= 2 * keep + times.n + 1 and line._seg[0] > 10000 - 2 * keep - times.n
    assert 0 < len(line.joins) <= line.planned // times.min_run + 1 and line.joins[0][0] > line._seg[0]
    line.frame(100)                               # long dropped: planned afresh from its grid step
    assert line._seg[0] == 100 - 100 % int(P.RESTART_S * times.fps)


# --- live audio features keep only the rows the windows read ------------------------------

@pytest.mark.slow
def test_an_hour_of_running_features_holds_bounded_rows_and_exact_statistics():
    """An hour of synthetic speech-like audio fed in blocks of about a minute, rows older than
    the last 4 s forgotten after each block: the stream holds a bounded number of rows (not
    the hour's 90 000), and the normalised features of its last frames are those of every
    row the stream produced normalised at once (numpy's two-pass mean and standard deviation
    over all 90 000 rows) within 1e-9. (4 kHz: an hour's frames at a quarter of 16 kHz's
    analysis cost; the rows and statistics are per video frame whatever the rate.)"""
    from lipsync.speech.features import RunningFeatures, normalised

    sr, fps = 4000, 25.0
    rng = np.random.default_rng(7)
    run = RunningFeatures(sr, fps)
    every, held = [], []
    fed = 0
    while fed < 3600 * sr:
        n = min(int(rng.integers(40, 80)) * sr, 3600 * sr - fed)
        t = np.arange(fed, fed + n) / sr
        loud = 0.5 + 0.5 * np.sin(2 * np.pi * rng.uniform(0.5, 4.0) * t) ** 2         # syllable-like envelope
        tone = np.sin(2 * np.pi * rng.uniform(90, 250) * t) * (rng.random(n // 400 + 1).repeat(400)[:n] < 0.6)
        x = (3000 * loud * (tone + 0.3 * rng.standard_normal(n))).astype(np.int16)
        before = len(run)
        run.add(x)
        every.append(run.rows(before, len(run)).copy())
        run.forget(len(run) - int(4 * fps))
        held.append(run.held)
        fed += n
    rows = np.concatenate(every)
    assert len(run) == len(rows) and len(rows) >= 3600 * fps - 1
    # bounded: the rows of a block and the 4 s kept (the buffer never grew past it)
    assert max(held) <= 4096 and held[-1] == max(held) and run.first > len(run) - 4096
    reference = normalised(rows)[-50:]
    assert np.abs(run.normalised(len(run) - 50, len(run)) - reference).max() < 1e-9
    assert np.abs(reference).max() > 0.5          # the features do vary
    with pytest.raises(IndexError):
        run.rows(0, 10)                            # the first rows were dropped


def test_a_session_dropping_old_feature_rows_fixes_the_samples_it_fixed_keeping_them(bank, monkeypatch):
    """Three sentences fed as one session (7.5 s), feature rows kept only 0.4 s behind what
    the windows read (at most 2 s in all): the same samples as a session keeping every row,
    from fewer rows held."""
    from lipsync.live import samples as LS

    pcm = np.concatenate([load_audio(AUDIO / f"{n}.flac") for n in ("bram2n", "lgwg3s", "lray6p")])[:int(7.5 * RATE)]
    paths, helds = [], []
    for behind, keep in ((0.4, 2.0), (1e9, 1e9)):
        monkeypatch.setattr(LS, "FEATURES_BEHIND_S", behind)
        monkeypatch.setattr(LS, "FEATURES_KEEP_S", keep)
        live = LiveAnimator(bank, fps=25, prepare=False, samples="on")
        for i in range(0, len(pcm), BLOCK):
            for n in live.feed_audio(pcm[i:i + BLOCK], RATE):
                live.sample(n)
        paths.append(list(live.samples.selection.path))
        f = live.samples.features
        helds.append((f.first, f.held, len(f)))
    assert len(paths[0]) >= 180 and paths[0] == paths[1]
    (first, held, n), (first_all, held_all, _) = helds
    assert first_all == 0 and held_all >= n and first > 0 and held < held_all


# --- a session mixing audio and pushed events: the events' phones in the samples' target ---

def _mixed(bank, pcm, push):
    """Feed 0.5 s, ``push(live)``, feed the rest; record the phones every window saw."""
    live = LiveAnimator(bank, fps=25, prepare=False, samples="on")
    seen = []
    fix = live.samples.fix

    def record(specs_of, phones, kind, stop, key):
        seen.append(list(phones))
        return fix(specs_of, phones, kind, stop, key)
    live.samples.fix = record
    live.feed_audio(pcm[:RATE // 2], RATE)
    push(live)
    for i in range(RATE // 2, len(pcm), BLOCK):
        for n in live.feed_audio(pcm[i:i + BLOCK], RATE):
            live.sample(n)
    for n in live.finish_audio():
        live.sample(n)
    return live, seen


def _within(phones, a, b):
    return [p for p in phones if p[1] > a + 1e-9 and p[0] < b - 1e-9]


def test_phoneme_events_pushed_into_an_audio_session_are_the_samples_phones_where_they_lie(bank, pcm):
    events = [(1.0, 1.16, "M"), (1.16, 1.4, "AE1"), (1.4, 1.52, "P")]
    live, seen = _mixed(bank, pcm, lambda lv: [lv.push(a, b, p, kind="phoneme") for a, b, p in events])
    heard, heard_seen = _mixed(bank, pcm, lambda lv: None)
    # every window reaching the events' span saw the events' phones there, and only them
    reaching = [ph for ph in seen if _within(ph, 1.0, 1.52)]
    assert len(reaching) >= 10
    assert all(_within(ph, 1.0, 1.52) == events for ph in reaching if ph[-1][1] >= 1.52)
    assert any(_within(ph, 1.0, 1.52) != events for ph in heard_seen)      # the audio's phones differ there
    # outside it, the audio's phones as a session without events hears them
    assert _within(live._phones, 0.0, 0.9) == _within(heard._phones, 0.0, 0.9)
    assert _within(live._phones, 1.0, 1.52) == events
    # the samples fixed in the span follow the events: closed lips on M and P (their visemes
    # win, as before)
    from lipsync.selection.select import CLOSED

    s = live.samples.shared.samples
    path = live.samples.selection.path
    assert all(s.opening[path[n]] <= CLOSED for n in (26, 27, 36, 37))


def test_viseme_events_leave_the_audios_phones_under_them(bank, pcm):
    live, _ = _mixed(bank, pcm, lambda lv: lv.push(1.0, 1.4, "F", kind="viseme"))
    heard, _ = _mixed(bank, pcm, lambda lv: None)
    assert live._phones == heard._phones and _within(live._phones, 1.0, 1.4)
    assert [live.spec(k).shown for k in range(28, 34)] == ["F"] * 6        # the visemes still win
