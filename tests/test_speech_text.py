"""Transcript normalisation and pronunciations (lipsync.speech.text / lexicon)."""

import pytest

from lipsync.speech import lookup_missing, normalise_transcript, pronounce
from lipsync.speech.lexicon import VOWELS, in_dictionary


@pytest.mark.parametrize("text, words", [
    ("Hello, World!", ["hello", "world"]),
    ("I have 2 cats.", ["i", "have", "two", "cats"]),
    ("In 1999 we met.", ["in", "nineteen", "ninety", "nine", "we", "met"]),
    ("the 21st of May", ["the", "twenty", "first", "of", "may"]),
    ("1,250 people", ["one", "thousand", "two", "hundred", "and", "fifty", "people"]),
    ("pi is 3.14", ["pi", "is", "three", "point", "one", "four"]),
    ("well-known state-of-the-art", ["well", "known", "state", "of", "the", "art"]),
    ("Don't say \u2018hi\u2019 \u2014 it\u2019s James' turn", ["don't", "say", "hi", "it's", "james", "turn"]),
    ("Caf\u00e9 na\u00efve", ["cafe", "naive"]),
    ("Dr. Who & 50%", ["doctor", "who", "and", "fifty", "percent"]),
    ("", []),
    (" ... !!! ", []),
])
def test_normalise_transcript(text, words):
    assert normalise_transcript(text) == words


def test_every_output_word_is_plain_lowercase():
    words = normalise_transcript("MIXED case, R2-D2's 007 \u00c6sop \u00df")
    assert words and all(w == w.lower() and w.replace("'", "").isalpha() for w in words)
    assert words[-1] == "ss"


def test_pronounce_dictionary_words_match_cmudict_phones():
    from lipsync.speech.lexicon import dictionary_path

    entries = {}
    with open(dictionary_path(), encoding="utf-8") as f:
        for line in f:
            w, *ph = line.split()
            entries.setdefault(w, ph)
    for w in ["hello", "balloons", "music", "the", "lovely"]:
        got = pronounce(w)
        assert [p.rstrip("012") for p in got] == entries[w]
        # a stress digit on every vowel, one primary stress per word
        assert all(p[-1] in "012" for p in got if p.rstrip("012") in VOWELS)
        assert sum(p.endswith("1") for p in got) == 1


def test_pronounce_missing_words_has_phones_and_is_listed():
    words = ["hello", "zorbleflax", "lipsync", "Zorbleflax", "qxz"]
    assert lookup_missing(words) == ["zorbleflax", "lipsync", "qxz"]
    for w in ["zorbleflax", "lipsync", "qxz", "aaaa", "brrr"]:
        assert not in_dictionary(w)
        ph = pronounce(w)
        assert ph and all(p.rstrip("012").isalpha() and p.rstrip("012").isupper() for p in ph)
    # analogy: "lipsync" reads as the dictionary's "lip" followed by "sync"
    assert [p.rstrip("012") for p in pronounce("lipsync")] == ["L", "IH", "P", "S", "IH", "NG", "K"]
    # letter-to-sound rules: silent final e, magic e, digraphs
    assert [p.rstrip("012") for p in pronounce("blakeshore")][:4] == ["B", "L", "EY", "K"]
    assert pronounce("...") == ()
