"""Phone sets and phoneme-to-viseme maps."""

from __future__ import annotations

import warnings

import pytest
import yaml

from lipsync._data import data_dir
from lipsync.errors import MapError, UnknownNameError
from lipsync.phonetics.phonemes import MAPS, UnknownLabelWarning, canonical_viseme_timeline, check_map_against, load_map, load_phoneset, map_timeline, resolve_visemes
from lipsync.motion.timeline import Segment, Timeline

RHUBARB = list("ABCDEFGHX")
OCULUS = "sil PP FF TH DD kk CH SS nn RR aa E I O U".split()
PRESTON_BLAIR = ["MBP", "etc", "E", "AI", "O", "U", "FV", "L", "rest"]


def tl(*rows, kind="phoneme"):
    return Timeline(tuple(Segment(s, e, lab) for s, e, lab in rows), kind=kind)


def test_shipped_maps_registered_and_valid():
    assert {"english-to-rhubarb", "english-to-oculus"} <= set(MAPS.names())
    assert set(load_map("rhubarb").visemes()) == set(RHUBARB)
    assert set(load_map("oculus").visemes()) == set(OCULUS)
    assert load_map().name == "english-to-rhubarb"


@pytest.mark.parametrize("name", ["english-to-rhubarb", "english-to-oculus"])
def test_every_canonical_phone_is_mapped(name):
    pmap = load_map(name)
    phones = load_phoneset("english").phones
    assert set(phones) <= set(pmap.map)


def test_phoneset_aliases_point_to_canonical_phones():
    raw = yaml.safe_load((data_dir("configs") / "phonesets" / "english.yaml").read_text(encoding="utf-8"))
    assert set(raw["aliases"].values()) <= set(raw["phones"])
    ps = load_phoneset("english")
    cases = {"AH0": "AH", "ah": "AH", "ax-h": "AH", "bcl": "B", "pcl": "P", "tʲ": "T", "ɫ": "L", "aj": "AY",
             "ɚ": "ER", "ɒ": "AO", "iː": "IY", "pʰ": "P", "ɡ": "G", "oov": "OOV", "h#": "", "": "", "SIL": ""}
    assert {k: ps.normalise(k) for k in cases} == cases
    assert ps.normalise("xyz") is None


def test_rhubarb_map_known_shapes():
    pmap = load_map("rhubarb")
    got = {p: pmap.targets(p) for p in ["P", "b", "M", "F", "V", "L", "AA", "UW", "AY1", "ow", "sil", "sp"]}
    assert got == {"P": ["A"], "b": ["A"], "M": ["A"], "F": ["G"], "V": ["G"], "L": ["H"], "AA": ["D"],
                   "UW": ["F"], "AY1": ["D", "B"], "ow": ["E", "F"], "sil": ["X"], "sp": ["X"]}
    assert pmap.closures == ["A"]


def test_oculus_map_known_shapes():
    pmap = load_map("oculus")
    got = {p: pmap.targets(p)[0] for p in ["p", "f", "th", "t", "k", "ch", "s", "n", "r", "aa", "eh", "iy", "ao", "uw"]}
    assert got == dict(zip(got, ["PP", "FF", "TH", "DD", "kk", "CH", "SS", "nn", "RR", "aa", "E", "I", "O", "U"]))
    assert pmap.closures == ["PP"]


def test_map_timeline_silence_rest_split_and_gaps():
    pmap = load_map("rhubarb")
    src = tl((0.0, 0.1, "sil"), (0.1, 0.2, "M"), (0.3, 0.6, "AY1"), (0.6, 0.7, "h#"))
    out = map_timeline(src, pmap, rest="neutral")
    assert out.kind == "viseme"
    assert [(s.start, s.end, s.label) for s in out] == [
        (0.0, 0.1, "neutral"), (0.1, 0.2, "A"), (0.2, 0.3, "neutral"), (0.3, pytest.approx(0.45), "D"),
        (pytest.approx(0.45), 0.6, "B"), (0.6, 0.7, "neutral")]
    assert [s.label for s in map_timeline(src, pmap)][0] == "X"  # default: the map's silence viseme
    # A leading gap and the time up to the file's stated end are silence too.
    late = Timeline((Segment(0.5, 0.6, "AA"),), stated_end=1.0)
    assert [(s.start, s.end, s.label) for s in map_timeline(late, pmap)] == [
        (0.0, 0.5, "X"), (0.5, 0.6, "D"), (0.6, 1.0, "X")]


def test_unknown_labels_warn_once_per_label():
    pmap = load_map("rhubarb")
    src = tl((0, 1, "zz"), (1, 2, "qq"), (2, 3, "zz"), (3, 4, "AA"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = map_timeline(src, pmap)
    assert out.labels() == ["C", "C", "C", "D"]
    msgs = [str(w.message) for w in caught if issubclass(w.category, UnknownLabelWarning)]
    assert len(msgs) == 2 and "'zz'" in msgs[0] and "'qq'" in msgs[1]


def test_viseme_timelines_pass_through():
    v = tl((0, 1, "A"), (1, 2, "X"), kind="viseme")
    assert map_timeline(v, load_map("oculus")) is v


def test_preston_blair_aliases_resolve_consistently():
    pmap = load_map("rhubarb")
    names, missing = resolve_visemes(pmap, PRESTON_BLAIR)
    assert missing == []
    assert names == {"A": "MBP", "B": "etc", "C": "E", "D": "AI", "E": "O", "F": "U", "G": "FV", "H": "L", "X": "rest"}
    # A bank with Rhubarb's own names resolves to itself (E stays E).
    assert resolve_visemes(pmap, RHUBARB)[0]["E"] == "E"
    v = tl((0, 1, "rest"), (1, 2, "WQ"), (2, 3, "E"), kind="viseme")
    assert canonical_viseme_timeline(v, pmap).labels() == ["X", "F", "C"]
    v2 = tl((0, 1, "X"), (1, 2, "E"), kind="viseme")
    assert canonical_viseme_timeline(v2, pmap).labels() == ["X", "E"]


def test_check_map_against_bank():
    assert check_map_against(load_map("oculus"), OCULUS)["PP"] == "PP"
    with pytest.raises(MapError) as info:
        check_map_against(load_map("rhubarb"), ["A", "B", "C", "D", "X"], path="m.yaml")
    assert "E, F, G, H" in str(info.value) and str(info.value).startswith("m.yaml: ")


def test_custom_map_file_and_errors(tmp_path):
    good = tmp_path / "mine.yaml"
    good.write_text("name: mine\nsilence: rest\nfallback: open\nmap: {AA: open, M: shut, OW: [open, round]}\n"
                    "closures: [shut]\n")
    pmap = load_map(str(good))
    out = map_timeline(tl((0, 1, "AA1"), (1, 2, "m"), (2, 3, "pau"), (3, 4, "ow")), pmap)
    assert out.labels() == ["open", "shut", "rest", "open", "round"]

    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nsilence: rest\nfallback: open\nmap:\n  AA: open\n  M: []\n")
    with pytest.raises(MapError) as info:
        load_map(str(bad))
    assert str(info.value).startswith(f"{bad}:") and "maps to no viseme" in str(info.value)

    typo = tmp_path / "typo.yaml"
    typo.write_text("name: t\nsilence: rest\nfallback: open\nmap: {AA: open}\nclosure: [open]\n")
    with pytest.raises(MapError) as info:
        load_map(str(typo))
    assert info.value.line == 5 and "closure" in str(info.value)

    broken = tmp_path / "broken.yaml"
    broken.write_text("name: b\nmap: {AA: [open\n")
    with pytest.raises(MapError) as info:
        load_map(str(broken))
    assert info.value.line is not None and "YAML" in str(info.value)

    closures = tmp_path / "closures.yaml"
    closures.write_text("name: c\nsilence: rest\nfallback: open\nmap: {AA: open}\nclosures: [shut]\n")
    with pytest.raises(MapError, match="closures"):
        load_map(str(closures))

    with pytest.raises(UnknownNameError, match="english-to-rhubarb"):
        load_map("klingon")
    with pytest.raises(MapError, match="no such file"):
        load_map(str(tmp_path / "missing.yaml"))
