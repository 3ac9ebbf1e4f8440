"""Praat TextGrid files (long and short text forms; UTF-8, or UTF-16 with a byte-order mark).

The tier read is ``tier`` if given, else ``phones`` (the Montreal Forced Aligner's name),
else the only tier whose name ends in "phones" (older MFA writes "<speaker> - phones"),
else a ``visemes`` tier (what ``lipsync cues`` writes; its labels are read as visemes).
A missing tier is an error that lists the tiers present.

praatio parses the file. Alongside it, a small token scan (:func:`_scan`) walks the same
structure to know the line of every interval (praatio keeps none), to check the structure
and report the line where it breaks, and to keep the sign of times (praatio's long-form
parser drops a leading minus). Empty intervals are gaps; ARPAbet stress digits (``AH0``)
are removed; IPA labels are read by :func:`lipsync.phonetics.canonical` (Unicode NFC,
ligatures written out: ``ʧ`` is ``tʃ``); other digits are kept, since in pinyin (``ing1``)
and IPA tone numbers they tell the notation apart (the maps drop tone).
"""

from __future__ import annotations

import re
import unicodedata
from typing import List, NamedTuple, Optional, Tuple

from ..errors import TimelineError
from ..phonetics.notations import ARPABET_VOWELS, detect
from ..phonetics.segments import canonical
from ..motion.timeline import PHONEME, VISEME, Timeline
from .base import READERS, Reader, ReadOptions
from ._common import build, decode_text, sniff_text

DEFAULT_TIER = "phones"
# The tier lipsync's own cue writer (lipsync.writers.textgrid) writes: read as visemes, and
# chosen when a file has no phones tier.
VISEME_TIER = "visemes"

_STRESS = re.compile(r"^([A-Za-z]{2})[0-2]$")  # ARPAbet's vowels are two letters: AH0, ow1

_TOKEN = re.compile(r'''
    (?P<str>"(?:[^"]|"")*")
  | (?P<key>[A-Za-z][^"=\n<\[]*=)                   # "xmin =", "intervals: size ="
  | (?P<head>[A-Za-z][^"=\n<\[]*\[\s*\d*\s*\]\s*:?)  # "item [1]:", "intervals [2]:"
  | (?P<flag><[A-Za-z]+>)
  | (?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?![\w.]))
  | (?P<word>[A-Za-z][\w?]*)                         # "tiers?" before <exists>
  | (?P<ws>\s+)
  | (?P<junk>[^\s"]+)
''', re.X)


class _Tok(NamedTuple):
    kind: str
    text: str
    line: int


class _Tier(NamedTuple):
    cls: str
    name: str
    xmin: float
    xmax: float
    line: int
    entries: List[Tuple[float, float, str, int]]


def normalise_label(label: str) -> str:
    """NFC, and ARPAbet stress digits removed: ``"AH0"`` -> ``"AH"``; IPA in one spelling.

    Examples
    --------
    >>> normalise_label("AH0"), normalise_label("tʲ"), normalise_label(""), normalise_label("ing1"), normalise_label("ʦ")
    ('AH', 'tʲ', '', 'ing1', 'ts')
    """
    label = unicodedata.normalize("NFC", label.strip())
    m = _STRESS.match(label)
    if m and m.group(1).upper() in ARPABET_VOWELS:
        return m.group(1)
    return canonical(label) if not label.isascii() else label


def _tokens(path: str, text: str) -> List[_Tok]:
    out: List[_Tok] = []
    line = 1
    after_key = False
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:  # an unterminated string
            raise TimelineError("unterminated text string", path=path, line=line)
        kind, value = m.lastgroup, m.group()
        if kind == "word" and after_key:
            kind = "junk"  # "xmin = abc": a value that is not a number or string
        if kind in ("str", "num", "flag", "junk"):
            out.append(_Tok(kind, value, line))
        if kind != "ws":
            after_key = kind == "key"
        line += value.count("\n")
        pos = m.end()
    return out


class _Stream:
    def __init__(self, path: str, toks: List[_Tok]):
        self.path, self.toks, self.i = path, toks, 0

    def _next(self, what: str) -> _Tok:
        if self.i >= len(self.toks):
            last = self.toks[-1].line if self.toks else 1
            raise TimelineError(f"file ends early: expected {what}", path=self.path, line=last)
        tok = self.toks[self.i]
        self.i += 1
        return tok

    def num(self, what: str) -> Tuple[float, int]:
        tok = self._next(what)
        if tok.kind != "num":
            raise TimelineError(f"expected {what} (a number), found {tok.text[:30]!r}", path=self.path, line=tok.line)
        return float(tok.text), tok.line

    def str(self, what: str) -> Tuple[str, int]:
        tok = self._next(what)
        if tok.kind != "str":
            raise TimelineError(f"expected {what} (a quoted text), found {tok.text[:30]!r}",
                                path=self.path, line=tok.line)
        return tok.text[1:-1].replace('""', '"'), tok.line

    def flag(self) -> bool:
        tok = self._next("<exists>")
        if tok.kind != "flag":
            self.i -= 1
            return True
        return tok.text == "<exists>"


# Largest tier or interval count accepted; a corrupt size field must not make us loop for ever.
_MAX_COUNT = 10_000_000


def _scan(path: str, text: str) -> Tuple[float, float, List[_Tier]]:
    """Walk the TextGrid token structure (same for long and short forms)."""
    s = _Stream(path, _tokens(path, text))
    file_type, line = s.str("File type")
    if file_type not in ("ooTextFile", "ooTextFile short"):
        raise TimelineError(f"File type is {file_type!r}, not ooTextFile", path=path, line=line)
    cls, line = s.str("Object class")
    if cls != "TextGrid":
        raise TimelineError(f"Object class is {cls!r}, not TextGrid", path=path, line=line)
    xmin, _ = s.num("xmin")
    xmax, _ = s.num("xmax")
    tiers: List[_Tier] = []
    if not s.flag():
        return xmin, xmax, tiers
    size, line = s.num("number of tiers")
    # Range first (found by fuzzing): int() of an infinite size ("1e999") raised OverflowError.
    if not 0 <= size <= _MAX_COUNT or size != int(size):
        raise TimelineError(f"bad number of tiers {size:g}", path=path, line=line)
    for _ in range(int(size)):
        tcls, tline = s.str("tier class")
        name, _ = s.str("tier name")
        txmin, _ = s.num("tier xmin")
        txmax, _ = s.num("tier xmax")
        count, cline = s.num("number of intervals")
        if not 0 <= count <= _MAX_COUNT or count != int(count):  # range first, as above
            raise TimelineError(f"bad interval count {count:g}", path=path, line=cline)
        entries = []
        for _ in range(int(count)):
            if tcls == "IntervalTier":
                a, aline = s.num("interval xmin")
                b, _ = s.num("interval xmax")
            elif tcls == "TextTier":
                a, aline = s.num("point time")
                b = a
            else:
                raise TimelineError(f"unknown tier class {tcls!r}", path=path, line=tline)
            label, _ = s.str("text")
            entries.append((a, b, label, aline))
        tiers.append(_Tier(tcls, name, txmin, txmax, tline, entries))
    return xmin, xmax, tiers


def _praatio_tiers(text: str) -> Optional[dict]:
    """Tier name -> list of (start, end, label) parsed by praatio, or None if it fails."""
    from praatio.utilities import textgrid_io

    try:
        doc = textgrid_io.parseTextgridStr(text, includeEmptyIntervals=True)
        return {t["name"]: [(float(e[0]), float(e[-2] if len(e) == 3 else e[0]), str(e[-1]))
                            for e in t["entries"]] for t in doc["tiers"]}
    except Exception:  # noqa: BLE001 - any praatio failure falls back to the token scan
        return None


def _pick_tier(path: str, tiers: List[_Tier], wanted: Optional[str]) -> _Tier:
    names = [t.name for t in tiers]
    listing = ", ".join(repr(n) for n in names) or "none"
    if wanted is not None:
        for t in tiers:
            if t.name == wanted:
                return t
        raise TimelineError(f"no tier named {wanted!r}; tiers present: {listing}", path=path)
    for t in tiers:
        if t.name == DEFAULT_TIER:
            return t
    ending = [t for t in tiers if t.name.strip().lower().endswith(DEFAULT_TIER)]
    if len(ending) == 1:
        return ending[0]
    for t in tiers:
        if t.name == VISEME_TIER:
            return t
    raise TimelineError(f"no tier named {DEFAULT_TIER!r} (choose one with --tier); tiers present: {listing}",
                        path=path)


def read(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read one interval tier of a TextGrid as a phoneme timeline."""
    text = decode_text(path, data)
    xmin, xmax, tiers = _scan(path, text)
    tier = _pick_tier(path, tiers, options.tier)
    if tier.cls != "IntervalTier":
        raise TimelineError(f"tier {tier.name!r} is a point tier; a timeline needs an interval tier",
                            path=path, line=tier.line)
    parsed = _praatio_tiers(text)
    entries = tier.entries
    if parsed is not None and len(parsed.get(tier.name, ())) == len(entries):
        # praatio's labels (it strips and unescapes them); our times keep their sign.
        entries = [(a, b, p[2], line) for (a, b, _, line), p in zip(entries, parsed[tier.name])]
    # A pinyin tier (ing1, ao1, er2) keeps its tone digits: "ao1" is pinyin ao, not ARPAbet AO1.
    pinyin = detect(label for _, _, label, _ in entries) == "pinyin"
    rows = [(a, b, unicodedata.normalize("NFC", label.strip()) if pinyin else normalise_label(label), line)
            for a, b, label, line in entries]
    end = tier.xmax if tier.xmax > 0 else xmax
    return build(path, rows, VISEME if tier.name == VISEME_TIER else PHONEME, stated_end=end)


def sniff(head: bytes) -> bool:
    text = sniff_text(head)
    return "ooTextFile" in text and "TextGrid" in text


READERS.register("textgrid", Reader("textgrid", read, sniff, "Praat TextGrid (long/short, MFA)"),
                 extensions=(".textgrid",), aliases=("praat", "mfa"))
