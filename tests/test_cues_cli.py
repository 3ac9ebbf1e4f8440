"""``lipsync cues``: the track `lipsync timeline` prints, written for other tools; bad input exits 2."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from lipsync.cli import main
from lipsync.phonetics.phonemes import canonical_viseme_timeline, load_map
from lipsync.readers import read_timeline

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "samples"
TIMELINES = ROOT / "tests" / "data" / "timelines"


def _timeline_track(capsys, *args):
    """The viseme track as `lipsync timeline` prints it (start, end, viseme; 3 decimals)."""
    assert main(["timeline", *args]) == 0
    rows = [line.split("\t") for line in capsys.readouterr().out.splitlines() if not line.startswith("#")]
    return [(float(a), float(b), v) for a, b, v in rows]


@pytest.mark.parametrize("source", ["hello.phn", "hello.TextGrid", "balloons.json"])
@pytest.mark.parametrize("ext", [".tsv", ".json", ".xml", ".TextGrid", ".txt"])
def test_cues_equal_the_timeline_command_track(capsys, tmp_path, source, ext):
    out = tmp_path / f"cues{ext}"
    assert main(["cues", str(SAMPLES / source), "-o", str(out), "-q"]) == 0
    want = _timeline_track(capsys, str(SAMPLES / source))
    got = read_timeline(out)
    # Audacity labels carry no kind: the reader takes them as phonemes, as it always has.
    assert got.kind == ("phoneme" if ext == ".txt" else "viseme")
    assert got.labels() == [v for _, _, v in want]
    for s, (a, b, _) in zip(got, want):
        assert s.start == pytest.approx(a, abs=1e-3) and s.end == pytest.approx(b, abs=1e-3)


def test_moho_uses_preston_blair_names_at_the_given_fps(capsys, tmp_path):
    out = tmp_path / "cues.dat"
    assert main(["cues", str(SAMPLES / "hello.phn"), "-o", str(out), "--fps", "30", "-q"]) == 0
    want = _timeline_track(capsys, str(SAMPLES / "hello.phn"))
    lines = out.read_text().splitlines()
    assert lines[0] == "MohoSwitch1"
    names = {line.split()[1] for line in lines[1:]}
    assert names <= {"MBP", "etc", "E", "AI", "O", "U", "FV", "L", "rest"}
    back = canonical_viseme_timeline(read_timeline(out, fps=30), load_map("rhubarb"))
    # Every cue of hello.phn is longer than a frame at 30 fps, so each keeps its own key.
    assert min(b - a for a, b, _ in want) > 1 / 30
    assert back.labels()[:-1] == [v for _, _, v in want]
    for s, (a, _, _) in zip(back, want):
        assert abs(s.start - a) <= 0.5 / 30 + 1e-9


def test_format_option_beats_extension(tmp_path):
    out = tmp_path / "cues.txt"
    assert main(["cues", str(SAMPLES / "hello.phn"), "-o", str(out), "--format", "rhubarb-tsv", "-q"]) == 0
    assert read_timeline(out, "rhubarb-tsv").labels()[0] == "X"
    assert out.read_text().splitlines()[-1].endswith("\tX")  # Rhubarb's end line


def test_bank_option_gives_the_same_track_for_the_toon(tmp_path):
    from lipsync._data import default_bank_dir

    a, b = tmp_path / "a.tsv", tmp_path / "b.tsv"
    assert main(["cues", str(SAMPLES / "hello.phn"), "-o", str(a), "-q"]) == 0
    assert main(["cues", str(SAMPLES / "hello.phn"), "-o", str(b), "--bank", str(default_bank_dir()), "-q"]) == 0
    assert a.read_text() == b.read_text()


def test_other_map_in_textgrid_and_refused_by_rhubarb(tmp_path, capsys):
    tg = tmp_path / "cues.TextGrid"
    assert main(["cues", str(SAMPLES / "hello.phn"), "-o", str(tg), "--map", "oculus", "-q"]) == 0
    labels = set(read_timeline(tg).labels())
    assert "PP" in labels and "sil" in labels
    out = tmp_path / "cues.tsv"
    assert main(["cues", str(SAMPLES / "hello.phn"), "-o", str(out), "--map", "oculus", "-q"]) == 2
    assert "Rhubarb's mouth shapes" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("bad", ["error_overlap.phn", "error_bad_json.json", "error_moho_header.dat"])
def test_bad_input_exits_2_naming_the_file_and_writes_nothing(tmp_path, capsys, bad):
    out = tmp_path / "cues.tsv"
    assert main(["cues", str(TIMELINES / bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(TIMELINES / bad) in err
    assert os.listdir(tmp_path) == []


def test_unknown_extension_and_missing_file_exit_2(tmp_path, capsys):
    assert main(["cues", str(SAMPLES / "hello.phn"), "-o", str(tmp_path / "cues.mp4")]) == 2
    assert "rhubarb-tsv" in capsys.readouterr().err
    assert main(["cues", str(tmp_path / "nope.phn"), "-o", str(tmp_path / "c.tsv")]) == 2
    assert "nope.phn" in capsys.readouterr().err
    assert main(["cues", str(SAMPLES / "hello.phn"), "-o", str(tmp_path)]) == 2
    assert main(["cues", str(SAMPLES / "hello.phn"), "-o", str(tmp_path / "c.dat"), "--fps", "0"]) == 2
    assert os.listdir(tmp_path) == []


def test_bank_with_preston_blair_names_writes_the_same_cues(tmp_path):
    import re
    import shutil

    from lipsync._data import default_bank_dir

    bank = tmp_path / "pb"
    shutil.copytree(default_bank_dir(), bank, ignore=shutil.ignore_patterns(".lipsync"))
    pb = {"A": "MBP", "B": "etc", "C": "E", "D": "AI", "E": "O", "F": "U", "G": "FV", "H": "L", "X": "rest"}
    text = (bank / "bank.yaml").read_text()
    text = re.sub(r"^  ([A-HX]):$", lambda m: f"  {pb[m.group(1)]}:", text, flags=re.M)
    (bank / "bank.yaml").write_text(text.replace("rest: X", "rest: rest"))
    for ext in (".tsv", ".dat"):
        a, b = tmp_path / f"a{ext}", tmp_path / f"b{ext}"
        assert main(["cues", str(SAMPLES / "hello.phn"), "-o", str(a), "-q"]) == 0
        assert main(["cues", str(SAMPLES / "hello.phn"), "-o", str(b), "--bank", str(bank), "-q"]) == 0
        assert a.read_text() == b.read_text()
