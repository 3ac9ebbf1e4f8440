"""Cue writers: golden files, Rhubarb's structure checked by independent parsers, round trips.

Golden cases live in tests/data/cues/ (see its README): ``NAME.tsv`` (a viseme track) and
``NAME.FORMAT.expected`` per writer, worked out by hand. Round trips: for random cue tracks,
every format is written and read back by our readers cue for cue (to the precision the
format stores; Moho to whole frames, at most half a frame from the written time).
"""

from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from lipsync.errors import InputError, UnknownNameError
from lipsync.phonetics.phonemes import canonical_viseme_timeline, load_map
from lipsync.motion.timeline import Segment, Timeline
from lipsync.readers import read_timeline
from lipsync.writers import WRITERS, cue_track, format_for, write_cues
from lipsync.writers.moho import frame_of

CUES = Path(__file__).parent / "data" / "cues"
GOLDEN = sorted(CUES.glob("*.expected"))
SHAPES = "ABCDEFGHX"
PRESTON_BLAIR = {"A": "MBP", "B": "etc", "C": "E", "D": "AI", "E": "O", "F": "U", "G": "FV", "H": "L",
                 "X": "rest"}


def test_registry_names_and_extensions():
    assert WRITERS.names() == ["rhubarb-tsv", "rhubarb-json", "rhubarb-xml", "moho", "textgrid", "audacity", "atlas"]
    # every cue format has its extension; atlas frames are JSON too, so only --format names them
    assert [format_for(f"a{e}") for e in (".tsv", ".json", ".xml", ".dat", ".TextGrid", ".txt")] == \
        WRITERS.names()[:-1]
    with pytest.raises(InputError) as info:
        format_for("cues.mp4")
    for name in WRITERS.names():
        assert name in str(info.value)
    with pytest.raises(UnknownNameError, match="valid: rhubarb-tsv"):
        WRITERS.get("papagayo2")


@pytest.mark.parametrize("expected", GOLDEN, ids=[p.name for p in GOLDEN])
def test_golden_through_cli(expected: Path, tmp_path):
    from lipsync.cli import main

    stem, fmt = expected.name[: -len(".expected")].split(".", 1)
    source = CUES / f"{stem}.tsv"
    out = tmp_path / "out.cues"
    # Rhubarb's soundFile is the recording (--audio), not the timeline (issue 31)
    audio = Path(__file__).resolve().parents[1] / "samples" / "hello.wav"
    assert main(["cues", str(source), "-o", str(out), "--format", fmt, "--quiet", "--audio", str(audio)]) == 0
    want = expected.read_text(encoding="utf-8").replace("@INPUT@", str(audio))
    assert out.read_text(encoding="utf-8") == want


def _track(cues):
    return Timeline(tuple(Segment(a, b, v) for a, b, v in cues), kind="viseme")


RULES_TRACK = [(0.0, 0.2, "X"), (0.2, 0.23, "A"), (0.23, 0.71, "D"), (0.71, 1.0, "E"), (1.0, 1.5, "X")]


def test_rhubarb_json_structure_read_by_json_module(tmp_path):
    out = tmp_path / "c.json"
    write_cues(_track(RULES_TRACK), out, sound_file='C:\\a "b".wav')
    doc = json.loads(out.read_text())
    assert list(doc) == ["metadata", "mouthCues"]
    assert doc["metadata"] == {"soundFile": 'C:\\a "b".wav', "duration": 1.5}
    assert [list(c) for c in doc["mouthCues"]] == [["start", "end", "value"]] * 5
    assert [(c["start"], c["end"], c["value"]) for c in doc["mouthCues"]] == RULES_TRACK


def test_rhubarb_xml_structure_read_by_elementtree(tmp_path):
    out = tmp_path / "c.xml"
    write_cues(_track(RULES_TRACK), out, sound_file="a<&>.wav")
    root = ET.parse(out).getroot()
    assert root.tag == "rhubarbResult"
    assert [c.tag for c in root] == ["metadata", "mouthCues"]
    assert root.find("metadata/soundFile").text == "a<&>.wav"
    assert float(root.find("metadata/duration").text) == 1.5
    cues = [(float(c.get("start")), float(c.get("end")), c.text) for c in root.find("mouthCues")]
    assert cues == RULES_TRACK


def test_textgrid_read_by_praatio(tmp_path):
    from praatio import textgrid

    out = tmp_path / "c.TextGrid"
    write_cues(_track(RULES_TRACK), out, tier="mouth")
    tg = textgrid.openTextgrid(str(out), includeEmptyIntervals=True)
    tier = tg.getTier("mouth")
    assert [(e.start, e.end, e.label) for e in tier.entries] == RULES_TRACK
    assert tg.maxTimestamp == 1.5


def test_gaps_become_rest_and_track_covers_duration():
    track, total = cue_track(_track([(0.1, 0.2, "A"), (0.5, 0.6, "D")]), rest="X", duration=1.0)
    assert track == [(0.0, 0.1, "X"), (0.1, 0.2, "A"), (0.2, 0.5, "X"), (0.5, 0.6, "D"), (0.6, 1.0, "X")]
    assert total == 1.0


def test_moho_frames_are_nearest_one_based_and_end_with_rest(tmp_path):
    out = tmp_path / "c.dat"
    # 30 fps: 0.2 s -> 6 frames in -> frame 7; 0.23 s -> 6.9 -> frame 8; 0.71 -> 21.3 -> 22;
    # 1.0 -> 31; end 1.5 -> 46.
    write_cues(_track(RULES_TRACK), out, fps=30)
    assert out.read_text().split("\n") == ["MohoSwitch1", "1 X", "7 A", "8 D", "22 E", "31 X", "46 X", ""]
    # 25 fps: 0.019 s is 0.475 frames (frame 1); 0.02 and 0.1 s are 0.5 and 2.5 (halves round up).
    assert [frame_of(t, 25) for t in (0.0, 0.019, 0.02, 0.1, 0.3)] == [1, 1, 2, 4, 9]


def test_moho_same_frame_keeps_the_longest_cue(tmp_path):
    out = tmp_path / "c.dat"
    # At 10 fps the 20 ms B and the 60 ms C both start on frame 3 (0.2 s); C is longer.
    write_cues(_track([(0, 0.2, "X"), (0.2, 0.22, "B"), (0.22, 0.28, "C"), (0.28, 0.6, "X")]), out, fps=10)
    assert out.read_text().split("\n")[1:-1] == ["1 X", "3 C", "4 X", "7 X"]


def test_rhubarb_refuses_shapes_it_has_not(tmp_path):
    out = tmp_path / "c.tsv"
    with pytest.raises(InputError, match="Rhubarb's mouth shapes.*PP"):
        write_cues(_track([(0, 0.5, "sil"), (0.5, 1.0, "PP")]), out, rest="sil")
    assert not out.exists()
    assert os.listdir(tmp_path) == []  # no temporary file left either


def test_failed_write_keeps_the_old_file(tmp_path):
    out = tmp_path / "c.json"
    out.write_text("old")
    with pytest.raises(InputError):
        write_cues(_track([(0, 0.5, "PP")]), out, rest="sil")
    assert out.read_text() == "old"
    assert os.listdir(tmp_path) == ["c.json"]


def test_moho_refuses_names_with_spaces(tmp_path):
    with pytest.raises(InputError, match="spaces"):
        write_cues(_track([(0, 0.5, "open mouth")]), tmp_path / "c.dat")


# --- round trips ----------------------------------------------------------------------------

# Cue lengths on a 1 ms grid from 5 ms (shorter than any frame) to 1 s; neighbours differ, as
# in every track the sequencer plans (equal neighbours merge).
@st.composite
def tracks(draw, min_ms=5):
    n = draw(st.integers(1, 25))
    lengths = draw(st.lists(st.integers(min_ms, 1000), min_size=n, max_size=n))
    labels = [draw(st.sampled_from(SHAPES))]
    for _ in range(n - 1):
        labels.append(draw(st.sampled_from([s for s in SHAPES if s != labels[-1]])))
    t, cues = 0, []
    for ms, v in zip(lengths, labels):
        cues.append((t / 1000, (t + ms) / 1000, v))
        t += ms
    return cues


def _read_back(path, fmt, fps=24.0):
    tl = read_timeline(path, fmt, fps=fps, tier="visemes" if fmt == "textgrid" else None)
    return canonical_viseme_timeline(tl, load_map("rhubarb")) if fmt == "moho" else tl


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(cues=tracks())
@pytest.mark.parametrize("fmt", ["rhubarb-tsv", "rhubarb-json", "rhubarb-xml", "textgrid", "audacity"])
def test_round_trip_cue_for_cue(tmp_path_factory, fmt, cues):
    out = tmp_path_factory.mktemp("rt") / "cues"
    write_cues(_track(cues), out, fmt)
    back = _read_back(out, fmt)
    tol = WRITERS.get(fmt).resolution / 2 + 1e-9
    assert back.labels() == [v for _, _, v in cues]
    for s, (a, b, _) in zip(back, cues):
        assert abs(s.start - a) <= tol and abs(s.end - b) <= tol
    assert abs(back.duration - cues[-1][1]) <= tol


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(cues=tracks(min_ms=43), fps=st.sampled_from([24.0, 25.0, 30.0]))
def test_round_trip_moho_to_frames(tmp_path_factory, cues, fps):
    # Cues of at least one frame (43 ms > 1/24 s) start on distinct frames, so every cue
    # comes back with its own key, each boundary at most half a frame from where it was.
    out = tmp_path_factory.mktemp("rt") / "cues.dat"
    write_cues(_track(cues), out, fps=fps, names=PRESTON_BLAIR)
    back = list(_read_back(out, "moho", fps))
    end_marker = back.pop()  # the rest key Moho files end with, shown for one frame
    assert end_marker.label == "X" and end_marker.duration == pytest.approx(1 / fps)
    assert [s.label for s in back] == [v for _, _, v in cues]
    half = 0.5 / fps + 1e-9
    for s, (a, b, _) in zip(back, cues):
        assert abs(s.start - a) <= half and abs(s.end - b) <= half
        assert s.start == pytest.approx((frame_of(a, fps) - 1) / fps)
    assert end_marker.start == pytest.approx((frame_of(cues[-1][1], fps) - 1) / fps, abs=1e-9)


def test_moho_closure_keeps_its_frame_and_the_next_cue_moves_one(tmp_path):
    out = tmp_path / "c.dat"
    # 10 fps: the 30 ms closure A (0.2 s, frame 3) and the 370 ms D (0.23 s, also frame 3).
    cues = [(0, 0.2, "X"), (0.2, 0.23, "A"), (0.23, 0.6, "D"), (0.6, 1.0, "X")]
    write_cues(_track(cues), out, fps=10, closures=["A"])
    assert out.read_text().split("\n")[1:-1] == ["1 X", "3 A", "4 D", "7 X", "11 X"]
    # Without closures the longer D takes the frame and the lips never close.
    write_cues(_track(cues), out, fps=10)
    assert out.read_text().split("\n")[1:-1] == ["1 X", "3 D", "7 X", "11 X"]


def test_moho_cue_with_no_frame_inside_it_is_dropped(tmp_path):
    out = tmp_path / "c.dat"
    # 10 fps: C (0.2-0.24) and B (0.24-0.25) both round to frame 3; C is longer and keeps it;
    # B's next frame (4, at 0.3 s) starts after B ends, so B has no key; X (0.25 s) is frame 4.
    write_cues(_track([(0, 0.2, "X"), (0.2, 0.24, "C"), (0.24, 0.25, "B"), (0.25, 0.6, "X")]), out, fps=10)
    assert out.read_text().split("\n")[1:-1] == ["1 X", "3 C", "4 X", "7 X"]
