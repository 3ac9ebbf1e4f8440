"""Huge finite times (issue 19, item 2).

``1e308`` is a finite float, but times a frame rate it is infinity, and every place that
turns time into a frame number overflowed (``render``, ``timeline --frames``, the Moho cue
writer, serve's render jobs, ``frame_at``). Times are bounded where they enter: the readers
refuse any time past :data:`lipsync.motion.timeline.MAX_TIMELINE_S` (24 hours) naming the file and
line, a Timeline refuses one built by code, and ``frame_at`` of both animators takes any
number (NaN is refused: a broken clock, not a time).
"""

from __future__ import annotations

import json
import math
import time

import httpx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import synthetic
from lipsync import Animator, Bank
from lipsync.cli import main
from lipsync.errors import InputError, TimelineError
from lipsync.live import LiveAnimator
from lipsync.readers import read_timeline
from lipsync.motion.sequencer import frame_count, sequence
from lipsync.motion.timeline import MAX_TIMELINE_S, Segment, Timeline
from lipsync.writers import write_cues

#: The issue's files: (name, text, the line holding the huge time).
HUGE = [
    ("t.tsv", "0\tA\n1e308\tX\n", 2),
    ("r.json", '{"mouthCues": [{"start": 0, "end": 1e308, "value": "A"}]}', 1),
    ("a.txt", "0\t1e308\taa\n", 1),
    ("m.dat", "MohoSwitch1\n1 MBP\n1000000000000 rest\n", 3),
    ("p.phn", "0 16000 h#\n16000 1e300 aa\n", 2),
]


@pytest.mark.parametrize("name, text, line", HUGE)
@pytest.mark.parametrize("command", ["render", "timeline", "cues"])
def test_commands_refuse_a_huge_time_naming_file_and_line(tmp_path, capsys, name, text, line, command):
    path = tmp_path / name
    path.write_text(text)
    args = {"render": ["render", str(path), "-o", str(tmp_path / "o.mp4"), "--quiet", "--method", "dissolve"],
            "timeline": ["timeline", str(path), "--frames"],
            "cues": ["cues", str(path), "-o", str(tmp_path / "x.dat")]}[command]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert f"{path}:{line}:" in err and "Traceback" not in err, err
    assert not (tmp_path / "o.mp4").exists() and not (tmp_path / "x.dat").exists()


@settings(max_examples=60, deadline=None)
@given(t=st.floats(MAX_TIMELINE_S, 1.7e308, exclude_min=True), fmt=st.sampled_from(["tsv", "txt", "TextGrid"]))
def test_any_time_past_the_limit_is_a_reader_error(tmp_path_factory, t, fmt):
    path = tmp_path_factory.mktemp("huge") / f"x.{fmt}"
    if fmt == "tsv":
        path.write_text(f"0\tA\n{t!r}\tX\n")
    elif fmt == "txt":
        path.write_text(f"0.5\t{t!r}\taa\n")
    else:
        path.write_text('File type = "ooTextFile"\nObject class = "TextGrid"\n\nxmin = 0\n'
                        f'xmax = {t!r}\ntiers? <exists>\nsize = 1\nitem []:\n    item [1]:\n'
                        '        class = "IntervalTier"\n        name = "phones"\n        xmin = 0\n'
                        f'        xmax = {t!r}\n        intervals: size = 1\n        intervals [1]:\n'
                        f'            xmin = 0\n            xmax = {t!r}\n            text = "aa"\n')
    with pytest.raises(TimelineError) as info:
        read_timeline(path)
    assert str(path) in str(info.value) and "limit" in str(info.value)


def test_code_built_timelines_and_durations_are_bounded_too(tmp_path):
    with pytest.raises(TimelineError, match="past the limit"):
        Timeline((Segment(0.0, 1e308, "A"),), kind="viseme")
    with pytest.raises(TimelineError):
        Timeline((Segment(0.0, 1.0, "A"),), kind="viseme", stated_end=1e308)
    ok = Timeline((Segment(0.0, 1.0, "A"),), kind="viseme")
    for bad in (1e308, math.inf, math.nan):
        with pytest.raises(InputError):
            sequence(ok, fps=25, rest="X", duration=bad)
        with pytest.raises(InputError):
            frame_count(bad, 25)
        with pytest.raises(InputError):
            write_cues(ok, tmp_path / "x.dat", duration=bad)
    assert frame_count(MAX_TIMELINE_S, 120) == int(MAX_TIMELINE_S * 120)
    assert not (tmp_path / "x.dat").exists()


@pytest.fixture(scope="module")
def bank(tmp_path_factory):
    return Bank.load(synthetic.write_bank(tmp_path_factory.mktemp("huge") / "bank", synthetic.RHUBARB_SHAPES))


@pytest.fixture(scope="module")
def animators(bank):
    tl = Timeline((Segment(0.0, 0.3, "X"), Segment(0.3, 0.7, "D"), Segment(0.7, 1.0, "X")), kind="viseme")
    anim = Animator(bank, tl, fps=25, method="dissolve")
    live = LiveAnimator(bank, fps=25, method="dissolve", prepare=False)
    live.push(0.0, 0.3, "X")
    live.push(0.3, 0.7, "D")
    return anim, live


@settings(max_examples=200, deadline=None)
@given(t=st.floats(allow_nan=False))
def test_frame_at_takes_any_number(animators, t):
    anim, live = animators
    frame = anim.frame_at(t)
    # before the start: frame 0; past the end: the last frame; else the frame holding t
    n = 0 if t <= 0 else min(len(anim) - 1, int(math.floor(t * 25 + 1e-9))) if t < len(anim) / 25 else len(anim) - 1
    assert np.array_equal(frame, anim.frame(n))
    got = live.frame_at(t)
    assert got.shape == frame.shape and got.dtype == np.uint8
    if t > 10:  # far past the pushed data: rest
        assert np.array_equal(got, anim.frame(len(anim) - 1))


def test_frame_at_refuses_nan_and_a_frameless_animator_shows_rest(bank, animators):
    anim, live = animators
    for f in (anim.frame_at, live.frame_at, live.spec_at):
        with pytest.raises(InputError, match="nan"):
            f(math.nan)
    empty = Animator(bank, Timeline((), kind="viseme"), fps=25, method="dissolve")
    assert len(empty) == 0
    rest = anim.frame(0)  # the timeline starts at rest (X)
    assert np.array_equal(empty.frame_at(3.0), rest) and np.array_equal(empty.frame_at(-1e308), rest)


def test_live_push_past_the_limit_is_refused(bank):
    live = LiveAnimator(bank, fps=25, method="dissolve", prepare=False)
    with pytest.raises(InputError, match="limit"):
        live.push(1e308, 1e308, "X")
    with pytest.raises(InputError, match="limit"):
        live.push(MAX_TIMELINE_S, MAX_TIMELINE_S + 1, "X")
    live.push(0.0, 0.2, "X")  # still usable
    assert live.frame_at(1e308).shape[2] == 3


def test_serve_render_job_with_a_huge_time_is_an_error_not_a_crash():
    from lipsync.server import LiveServer, ServeConfig
    from lipsync.web import Session, start_in_thread

    session = Session.open("127.0.0.1", 0)
    server = LiveServer(ServeConfig(method="dissolve"), session=session)
    handle = start_in_thread(server.app, session)
    try:
        r = httpx.post(session.url("/api/render") + "&name=t.tsv", content=b"0\tA\n1e308\tX\n")
        assert r.status_code == 202
        job = r.json()["job"]
        deadline = time.monotonic() + 60
        while (state := httpx.get(session.url(f"/api/jobs/{job}")).json())["state"] in ("queued", "running"):
            assert time.monotonic() < deadline
            time.sleep(0.05)
        assert state["state"] == "error" and "t.tsv:2:" in state["error"] and "limit" in state["error"], state
        assert "render failed" not in state["error"]
        assert httpx.get(session.url("/api/status")).status_code == 200
    finally:
        handle.stop()
        server.close()
        session.close()
