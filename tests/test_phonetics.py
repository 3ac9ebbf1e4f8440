"""Phones as IPA with features (issue 29, part 1): lipsync.phonetics and the maps built on it."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest

from lipsync import phonetics
from lipsync.errors import MapError
from lipsync.phonetics.phonemes import UnknownLabelWarning, bank_viseme_timeline, load_map, map_timeline
from lipsync.phonetics.features import FEATURES
from lipsync.phonetics.segments import parse_sequence
from lipsync.phonetics.visemes import compiled, parts_visemes
from lipsync.readers import read_timeline
from lipsync.motion.timeline import Segment, Timeline

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data" / "phonetics"
MAPS = ("english-to-rhubarb", "english-to-oculus")


def tl(labels, step=0.1):
    return Timeline(tuple(Segment(i * step, (i + 1) * step, lab) for i, lab in enumerate(labels)))


def mapped(labels, name="rhubarb", notation=None):
    """Visemes per label (a label's split parts joined with '+'), and the labels that warned."""
    out = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pmap = load_map(name)
        vt = map_timeline(tl(labels), pmap, notation=notation)
    # Each label is 0.1 s; its visemes are the segments inside its interval.
    for i, _ in enumerate(labels):
        out.append("+".join(s.label for s in vt if i * 0.1 - 1e-9 <= s.start < (i + 1) * 0.1 - 1e-9))
    warned = [str(w.message) for w in caught if issubclass(w.category, UnknownLabelWarning)]
    return out, warned


# --- English unchanged -----------------------------------------------------------------


def test_english_timelines_give_the_same_cues_as_before():
    """Every timeline in tests/data and samples/ through both English maps: the cues main
    gave before issue 29 (recorded by tools/phonetics_baseline.py at 1e75df3)."""
    import sys

    sys.path.insert(0, str(ROOT / "tools"))
    try:
        from phonetics_baseline import cues, timeline_files
    finally:
        sys.path.pop(0)
    old = json.loads((DATA / "english_cues.json").read_text(encoding="utf-8"))
    files = [p for p in timeline_files()]
    assert len(files) >= 30
    for path in files:
        key = str(path.relative_to(ROOT))
        assert cues(path) == old.get(key), key
    assert set(old) - {"labels"} == {str(p.relative_to(ROOT)) for p in files if cues(p) is not None}


def test_every_english_label_maps_as_before_except_ipa_e_and_o():
    old = json.loads((DATA / "english_cues.json").read_text(encoding="utf-8"))["labels"]
    # Issue 29: IPA e and o alone are monophthongs (one shape), not English's EY and OW.
    changed = {"english-to-rhubarb": {"e": ["C"], "o": ["E"]}, "english-to-oculus": {"e": ["E"], "o": ["O"]}}
    for name in MAPS:
        pmap = load_map(name)
        assert len(old[name]) > 250
        for label, before in old[name].items():
            assert pmap.targets(label) == changed[name].get(label, before), (name, label)


def test_english_written_in_ipa_has_the_arpabet_shapes():
    """aʊ oʊ eɪ aɪ ɔɪ (espeak-ng's and dictionaries' spelling) fell back to C before."""
    ipa, warned = mapped(["aʊ", "oʊ", "eɪ", "aɪ", "ɔɪ", "ɹ", "ɚ", "tʃ", "dʒ", "ŋ", "θ"])
    arpa, _ = mapped(["AW", "OW", "EY", "AY", "OY", "R", "ER", "CH", "JH", "NG", "TH"])
    assert warned == [] and ipa == arpa == ["D+F", "E+F", "C+B", "D+B", "E+B", "E", "E", "B", "B", "B", "B"]
    ipa, _ = mapped(["aʊ", "oʊ", "eɪ", "aɪ", "ɔɪ", "ɹ", "ɚ"], "oculus")
    arpa, _ = mapped(["AW", "OW", "EY", "AY", "OY", "R", "ER"], "oculus")
    assert ipa == arpa == ["aa+U", "O+U", "E+I", "aa+I", "O+I", "RR", "RR"]


# --- the wrong-without-warning cases --------------------------------------------


def test_french_mfa_textgrid_maps_with_no_fallback():
    """An MFA French TextGrid (IPA phones tier): y rounded, e and o one shape each, ʁ ɥ œ̃ ø œ ɲ
    known. Expected shapes written here from the phones' articulation."""
    path = DATA / "french_mfa_ipa.TextGrid"
    timeline = read_timeline(str(path))
    assert timeline.labels()[:5] == ["b", "ɔ̃", "ʒ", "u", "ʁ"]
    expected = {
        "english-to-rhubarb": {"b": "A", "ɔ̃": "E", "ʒ": "B", "u": "F", "ʁ": "B", "ə": "C", "s": "B", "ɥ": "F",
                               "i": "B", "œ̃": "E", "œ": "E", "f": "G", "l": "H", "ø": "E", "e": "C", "a": "D",
                               "ɲ": "B", "o": "E", "d": "B", "y": "F"},
        "english-to-oculus": {"b": "PP", "ɔ̃": "O", "ʒ": "CH", "u": "U", "ʁ": "kk", "ə": "aa", "s": "SS",
                              "ɥ": "U", "i": "I", "œ̃": "O", "œ": "O", "f": "FF", "l": "nn", "ø": "O", "e": "E",
                              "a": "aa", "ɲ": "nn", "o": "O", "d": "DD", "y": "U"},
    }
    for name in MAPS:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            vt = map_timeline(timeline, load_map(name))
        assert not [w for w in caught if issubclass(w.category, UnknownLabelWarning)]
        got = {}
        for seg in timeline:
            inside = [v.label for v in vt if seg.start - 1e-9 <= v.start < seg.end - 1e-9]
            assert len(inside) == 1, (seg.label, inside)  # no French phone is split
            got[seg.label] = inside[0]
        assert got == expected[name]


def test_not_a_phone_still_warns_in_an_ipa_timeline():
    out, warned = mapped(["b", "ɔ̃", "zz", "ʁ", "???"])
    assert out == ["A", "E", "C", "B", "C"]
    assert len(warned) == 2 and "'zz'" in warned[0] and "'???'" in warned[1]


def test_y_r_q_read_by_the_timeline_notation():
    # ARPAbet/TIMIT timeline: Y is the glide (B), R English r (E), q TIMIT's glottal stop (C).
    assert mapped(["y", "uw", "r", "q"])[0] == ["B", "F", "E", "C"]
    # IPA timeline: y the rounded vowel (F), r a trill (B), q a uvular stop (B).
    assert mapped(["y", "ʁ", "r", "q"])[0] == ["F", "B", "B", "B"]


def test_tone_stress_and_length_are_dropped():
    plain, _ = mapped(["a", "i", "ə", "u", "o"])
    for variant in (["a˥˩", "i˧˥", "ə˨˩˦", "u˩", "o˦˥"], ["a55", "i35", "ə214", "u1", "o5"],
                    ["ˈa", "ˌi", "ə", "ˈuː", "oˑ"], ["aː˥", "iː", "ə", "uː˨ˀ˥", "oː"]):
        got, warned = mapped(variant)
        assert got == plain == ["D", "B", "C", "F", "E"] and warned == []


# --- every phone of espeak-ng and MFA ------------------------------------------------------


def test_espeak_ng_phoneme_inventory_has_no_fallback():
    data = json.loads((DATA / "espeak_inventory.json").read_text(encoding="utf-8"))
    words = sorted({w for ws in data["tables"].values() for w in ws})
    assert len(data["tables"]) >= 100 and len(words) > 450
    for rules in ("rhubarb", "oculus"):
        for word in words:
            ipa = phonetics.to_ipa(word, "espeak")
            assert ipa is not None, word
            assert parts_visemes(parse_sequence(ipa), compiled(rules)), (word, ipa)
    # The same labels as a timeline through the maps: not one warning.
    for name in MAPS:
        _, warned = mapped(words, name, notation="espeak")
        assert warned == [], warned[:5]


def test_espeak_ng_sentences_in_34_languages_have_no_fallback():
    data = json.loads((DATA / "espeak_inventory.json").read_text(encoding="utf-8"))
    assert len(data["texts"]) >= 30
    for lang, text in data["texts"].items():
        segments = phonetics.split(" ".join(phonetics.to_ipa(w, "espeak") or "?" for w in text.split()))
        assert len(segments) >= 10, lang
        for rules in ("rhubarb", "oculus"):
            for seg in segments:
                assert phonetics.label_visemes(seg, rules), (lang, seg)


def test_mfa_published_phone_sets_have_no_fallback():
    data = json.loads((DATA / "mfa_phonesets.json").read_text(encoding="utf-8"))["sets"]
    assert len(data) >= 20
    notations = {name: phonetics.detect(s["phones"]) for name, s in data.items()}
    assert notations["mandarin_pinyin"] == "pinyin" and notations["english_us_arpa"] == "english"
    assert {n for k, n in notations.items() if k not in ("mandarin_pinyin", "english_us_arpa")} == {"ipa"}
    for name, s in data.items():
        for m in MAPS:
            _, warned = mapped(s["phones"], m)
            assert warned == [], (name, m, warned[:3])


# --- notations -----------------------------------------------------------------------


def test_xsampa_spot_checks():
    cases = {"tS": "tʃ", "{": "æ", "r\\": "ɹ", "9~": "œ̃", "p_h": "pʰ", "E:": "ɛː", "@U": "əʊ", "J\\": "ɟ",
             "s`": "ʂ", "x\\": "ɧ", "b_<": "ɓ", "k_>": "kʼ", "O\\": "ʘ", "n=": "n̩", "a_T": "a˥", '"a': "ˈa"}
    assert {k: phonetics.to_ipa(k, "xsampa") for k in cases} == cases
    assert mapped(["S", "y", "2", "9~", "R", "p\\", "H"], notation="xsampa")[0] == ["B", "F", "E", "E", "B", "A", "F"]


def test_pinyin_spot_checks():
    cases = {"zhong1": "ʈʂʊŋ", "xue2": "ɕɥɛ", "ri4": "ʐʅ", "si4": "sɿ", "lv4": "ly", "j": "tɕ", "q": "tɕʰ",
             "x": "ɕ", "h": "x", "r": "ʐ", "c": "tsʰ", "iii4": "ʅ", "ii1": "ɿ", "uang3": "wɑŋ", "er2": "ɚ",
             "ye3": "jɛ", "yan2": "jɛn", "you3": "joʊ", "yi1": "i", "yu2": "y", "yuan2": "ɥɛn", "wo3": "wo",
             "wei4": "weɪ", "ju4": "tɕy", "gui4": "kweɪ", "liu2": "ljoʊ", "nü3": "ny"}
    assert {k: phonetics.to_ipa(k, "pinyin") for k in cases} == cases


def test_aishell3_pinyin_textgrid_maps_with_no_fallback():
    timeline = read_timeline(str(DATA / "aishell3_SSB00050015.TextGrid"))
    # The tone digits stay on the labels (ing1 is pinyin, not "ing").
    assert timeline.labels()[:11] == ["[SIL]", "j", "ing1", "g", "uang3", "zh", "ou1", "r", "iii4", "b", "ao4"]
    got, warned = mapped(timeline.labels()[:11])
    assert warned == []
    # [SIL] rest; j=tɕ B; ing=iŋ B; g=k B; uang=wɑŋ F D B; zh=ʈʂ B; ou=oʊ E F; r=ʐ B; iii=ʅ B; b=p A; ao=ɑʊ D F
    assert got == ["X", "B", "B", "B", "F+D+B", "B", "E+F", "B", "B", "A", "D+F"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        map_timeline(timeline, load_map("oculus"))
    assert not [w for w in caught if issubclass(w.category, UnknownLabelWarning)]


def test_arpabet_and_timit_to_ipa():
    assert [phonetics.to_ipa(x, "arpabet") for x in ["AY1", "er0", "JH", "NG", "Y"]] == ["aɪ", "ɝ", "dʒ", "ŋ", "j"]
    assert [phonetics.to_ipa(x, "timit") for x in ["ax-h", "dx", "nx", "q", "h#", "bcl"]] == [
        "ə̥", "ɾ", "ɾ̃", "ʔ", "", "b"]


# --- segments and features ------------------------------------------------------------


def test_every_symbol_of_the_ipa_chart_has_features():
    pulmonic = "p b t d ʈ ɖ c ɟ k ɡ q ɢ ʔ m ɱ n ɳ ɲ ŋ ɴ ʙ r ʀ ⱱ ɾ ɽ ɸ β f v θ ð s z ʃ ʒ ʂ ʐ ç ʝ x ɣ χ ʁ ħ ʕ h ɦ " \
               "ɬ ɮ ʋ ɹ ɻ j ɰ l ɭ ʎ ʟ"
    non_pulmonic = "ʘ ǀ ǃ ǂ ǁ ɓ ɗ ʄ ɠ ʛ"
    other = "ʍ w ɥ ʜ ʢ ʡ ɕ ʑ ɺ ɧ"
    vowels = "i y ɨ ʉ ɯ u ɪ ʏ ʊ e ø ɘ ɵ ɤ o ə ɛ œ ɜ ɞ ʌ ɔ æ ɐ a ɶ ɑ ɒ"
    for sym in (pulmonic + " " + non_pulmonic + " " + other + " " + vowels).split():
        assert sym in FEATURES, sym
        assert phonetics.label_visemes(sym, "rhubarb") and phonetics.label_visemes(sym, "oculus"), sym


def test_features_read_off_the_chart():
    f = FEATURES
    assert (f["ɮ"].place, f["ɮ"].manner, f["ɮ"].voiced, f["ɮ"].lateral) == ("alveolar", "fricative", True, True)
    assert (f["ʛ"].place, f["ʛ"].airstream) == ("uvular", "implosive")
    assert (f["ǂ"].place, f["ǂ"].airstream) == ("palatal", "click")
    assert (f["ɥ"].place, f["ɥ"].rounded) == ("labial-palatal", True)
    assert (f["ɶ"].height, f["ɶ"].backness, f["ɶ"].rounded) == ("open", "front", True)
    assert (f["ɤ"].height, f["ɤ"].backness, f["ɤ"].rounded) == ("close-mid", "back", False)
    assert f["ŋ"].nasal and not f["ɡ"].nasal and f["ɚ"].rhotic


def test_parser_modifiers_ties_and_non_phones():
    def mods(label):
        return [(p.base, sorted(p.modifiers)) for p in phonetics.parse(label).parts]

    assert mods("kʷʼ") == [("k", ["ejective", "labialised"])]
    assert mods("ɛ̃ː") == [("ɛ", ["long", "nasalised"])]
    assert mods("r̝̊") == [("r", ["devoiced", "raised"])]
    assert mods("dˤ") == [("d", ["pharyngealised"])]
    assert mods("k͈") == [("k", ["fortis"])]
    assert mods("aɪ̯") == [("a", []), ("ɪ", ["non-syllabic"])]
    assert mods("t͡s") == mods("ts") == mods("ʦ") == [("t", []), ("s", [])]
    assert mods("ẽ") == [("e", ["nasalised"])]
    assert phonetics.parse("k͜p").tied and phonetics.parse("n̩").parts[0].features.kind == "consonant"
    assert phonetics.parse("ŋ̍˧˥").tone == "˧˥" and phonetics.parse("ˈa").stress == "primary"
    assert phonetics.parse("ʃʲ").parts[0].features.place == "postalveolar"
    assert phonetics.parse("ɔ̃").parts[0].features.nasal
    for not_phone in ["zz", "qq", "xyz", "hello", "", "5", "AH", "a b", "t͡", "ʰ"]:
        assert phonetics.parse(not_phone) is None, not_phone


def test_diphthongs_and_affricates_split_long_vowels_do_not():
    for label, rhubarb in {"aɪ": ["D", "B"], "pf": ["A", "G"], "ts": ["B"], "aː": ["D"], "tːs": ["B"],
                           "ɔʏ": ["E", "F"], "iə": ["B", "C"], "ŋm": ["B", "A"], "mb": ["A"]}.items():
        assert phonetics.label_visemes(label, "rhubarb") == rhubarb, label


def test_closest_english_spot_checks():
    cases = {"ʁ": "R", "y": "UW", "ɲ": "N", "β": "B", "ʃ": "SH", "ɕ": "SH", "x": "HH", "ɾ": "D", "ʎ": "L",
             "œ̃": "AO", "ɯ": "UW", "e": "EY", "o": "OW", "ɑ̃ː": "AA", "tʃ": "CH", "t͡ɕʰ": "CH", "ɫ": "L",
             "ɛ": "EH", "ɪ": "IH", "kʷ": "K", "ɡʲ": "G", "ʂ": "SH", "ʐ": "ZH", "v": "V", "ð": "DH",
             "a": "AA", "ä": "AA", "ɐ": "AA", "æ": "AE", "ʌ": "AH", "ə": "AH"}
    assert {k: phonetics.closest_english(k) for k in cases} == cases
    assert phonetics.english_phones("pf") == ("P", "F") and phonetics.english_phones("aɪ") == ("AY",)
    with pytest.raises(ValueError, match="english_phones"):
        phonetics.closest_english("ts")
    with pytest.raises(ValueError, match="not IPA"):
        phonetics.english_phones("zz#")


def test_ipa_visemes_of_a_transcription():
    got = phonetics.ipa_visemes("ʒə- syˌiz œ̃ ɡʁˈɑ̃t ˈœf", "rhubarb")
    assert got == [("ʒ", ["B"]), ("ə", ["C"]), ("s", ["B"]), ("y", ["F"]), ("i", ["B"]), ("z", ["B"]),
                   ("œ̃", ["E"]), ("ɡ", ["B"]), ("ʁ", ["B"]), ("ɑ̃", ["D"]), ("t", ["B"]), ("œ", ["E"]),
                   ("f", ["G"])]


# --- map files: rules -----------------------------------------------------------------


def test_map_rules_inline_shipped_inferred_and_none(tmp_path):
    own = tmp_path / "own.yaml"
    own.write_text("name: own\nsilence: rest\nfallback: open\nmap: {AA: open, M: shut}\n"
                   "rules:\n  - {place: bilabial, viseme: shut, why: lips together}\n"
                   "  - {kind: vowel, rounded: true, viseme: round}\n  - {kind: vowel, viseme: open}\n"
                   "  - {kind: consonant, viseme: teeth}\n", encoding="utf-8")
    pmap = load_map(str(own))
    assert set(pmap.visemes()) == {"open", "shut", "rest", "round", "teeth"}
    assert map_timeline(tl(["AA", "ɓ", "y", "ʁ", "ɑ̃"]), pmap).labels() == ["open", "shut", "round", "teeth", "open"]

    # No rules named, Rhubarb's visemes: the rhubarb rules; other visemes: none (a warning).
    old_style = tmp_path / "old.yaml"
    old_style.write_text("name: old\nsilence: X\nfallback: C\nmap: {AA: D, B: A, F: G, L: H, UW: F, AO: E, IY: B}\n",
                         encoding="utf-8")
    assert mapped_with(load_map(str(old_style)), ["ɥ", "ʁ", "ɸ"]) == (["F", "B", "A"], 0)
    custom = tmp_path / "custom.yaml"
    custom.write_text("name: c\nsilence: rest\nfallback: open\nmap: {AA: open}\n", encoding="utf-8")
    assert mapped_with(load_map(str(custom)), ["ʁ"]) == (["open"], 1)
    none = tmp_path / "none.yaml"
    none.write_text("name: n\nsilence: X\nfallback: C\nrules: none\nmap: {AA: D, B: A, F: G, L: H, UW: F, AO: E}\n",
                    encoding="utf-8")
    assert mapped_with(load_map(str(none)), ["ʁ"]) == (["C"], 1)

    bad = tmp_path / "bad.yaml"
    bad.write_text("name: b\nsilence: X\nfallback: C\nmap: {AA: D}\nrules:\n  - {place: lips, viseme: A}\n",
                   encoding="utf-8")
    with pytest.raises(MapError) as info:
        load_map(str(bad))
    assert info.value.line == 5 and "place 'lips'" in str(info.value)
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text("name: u\nsilence: X\nfallback: C\nmap: {AA: D}\nrules: klingon\n", encoding="utf-8")
    with pytest.raises(MapError, match="unknown rule set 'klingon'"):
        load_map(str(unknown))


def mapped_with(pmap, labels):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = map_timeline(tl(labels), pmap).labels()
    return out, len([w for w in caught if issubclass(w.category, UnknownLabelWarning)])


def test_rules_follow_a_bank_with_preston_blair_names():
    pb = ["MBP", "etc", "E", "AI", "O", "U", "FV", "L", "rest"]
    vt, pmap = bank_viseme_timeline(tl(["b", "y", "ʁ", "a", "ɥ", "f"]), load_map("rhubarb"), pb)
    assert vt.labels() == ["MBP", "U", "etc", "AI", "U", "FV"]
    assert set(pmap.visemes()) <= set(pb)


def test_feature_rules_agree_with_the_english_maps_on_every_english_phone():
    """The rule sets reproduce english-to-rhubarb and english-to-oculus on the IPA of every
    ARPAbet phone, so English in IPA and English in ARPAbet show the same mouth. The one
    difference is Oculus's affricates: the rules split them in time (t: DD, ʃ: CH) while the
    English map shows CH for all of CH and JH (and keeps doing so: tʃ and dʒ are in its phone set)."""
    from lipsync.phonetics.notations import ARPABET

    for name, rules in (("english-to-rhubarb", "rhubarb"), ("english-to-oculus", "oculus")):
        pmap = load_map(name)
        differ = {a for a, ipa in ARPABET.items() if pmap.targets(a) != phonetics.label_visemes(ipa, rules)}
        assert differ == (set() if rules == "rhubarb" else {"CH", "JH"}), (name, differ)
        assert pmap.targets("tʃ", notation="ipa") == pmap.targets("CH")
