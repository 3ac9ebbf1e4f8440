"""Papagayo and Papagayo-NG projects (``.pgo``): the animator's own, hand-tuned breakdown.

The file (written by Papagayo's ``LipsyncDoc::Save`` and Papagayo-NG's ``LipsyncDoc.save``),
one value a line, indented with tabs that mean nothing::

    lipsync version 1
    example1.wav                  sound file, relative to the project
    24                            frames per second
    71                            length of the sound in frames
    1                             number of voices; then, per voice:
        Voice 1                     its name
        Short term treasury ...     its text ('|' for line breaks)
        1                           number of phrases; then, per phrase:
            Short term ...            its text
            1                         first frame
            70                        last frame (inclusive)
            6                         number of words; then, per word:
                Short 1 7 4             text, first frame, last frame, number of phonemes
                    1 etc               per phoneme: its frame and its name
                    3 O

Frames count from 0 and frame ``f`` is shown at ``f / fps``. What the mouth shows at a
frame is what Papagayo's ``GetPhonemeAtFrame`` says: inside a word (clipped to its
phrase), the last phoneme whose frame is at or before it; elsewhere, rest (a gap here). So a
phoneme lasts from its frame to the next phoneme's frame or the end of its word.

Phoneme names. Papagayo-NG writes the names of the project's phoneme set, and the file does
not say which set; they are told apart by their names, the default set first:

==============  ==========================================  ======================================
set             names                                       read as
==============  ==========================================  ======================================
preston_blair   AI O E U etc L WQ MBP FV rest               visemes, as Moho files (the maps'
                (Papagayo's default, and all of Papagayo)   aliases turn them into the map's
                                                            shapes: MBP -> A, etc -> B, ...)
rhubarb         A B C D E F G H rest                        visemes; rest is Rhubarb's X
fleming_dobbs   MBP NLTDR FV TH GK SH O EHSZ AA IY rest     phonemes: each group as the phone
                                                            that stands for it (:data:`FLEMING_DOBBS`)
CMU_39          ARPAbet (AA AE ... ZH) and rest             phonemes; rest is silence
==============  ==========================================  ======================================

A file whose names fit several sets is read in the first of them (``E`` and ``rest`` alone
are Preston Blair's E, not Rhubarb's E); names outside every set are kept as viseme names,
so a bank named after the project's own mouth set renders them directly.

Voices: a project may hold several characters. The first voice is read; ``tier`` (``--tier
NAME`` on the command line, the option that picks a TextGrid tier) picks another by name,
and an unknown name is an error listing the voices.

Text encoding: Papagayo-NG writes UTF-8; the original Papagayo wrote the system's 8-bit
code page. Only numbers and phoneme names (ASCII) are used, so a file that is not UTF-8 is
read as Latin-1 rather than refused for an accented word.
"""

from __future__ import annotations

import codecs
import warnings
from typing import Dict, List, Tuple

from ..errors import TimelineError
from ..motion.timeline import PHONEME, VISEME, Timeline
from .base import READERS, Reader, ReadOptions
from ._common import build, decode_text, first_nonblank, parse_number, sniff_text

MAGIC = "lipsync version 1"

#: Frame rates a project may state. Papagayo clamps to 1..120 when it opens a file;
#: Papagayo-NG takes any whole number. 1000 leaves room for hand-edited projects while a
#: value like 1e308 (which would make every time zero) is refused.
FPS_RANGE = (1.0, 1000.0)

#: Largest frame number accepted: over 115 hours at 24 fps, longer than any sound Papagayo
#: can load. A larger number is a damaged file, not a long one.
MAX_FRAME = 10_000_000

# --- phoneme sets (Papagayo-NG's phonemes/*.json), in the order they are tried ------------

PRESTON_BLAIR = frozenset({"AI", "O", "E", "U", "etc", "L", "WQ", "MBP", "FV", "rest"})
RHUBARB = frozenset({"A", "B", "C", "D", "E", "F", "G", "H", "rest"})
#: Fleming & Dobbs groups as ARPAbet phones. Each group is named after the sounds it covers;
#: the phone chosen gives the shape most of them share (checked against the maps: with
#: english-to-rhubarb these are A, B, G, B, B, B, E, C, D, B).
FLEMING_DOBBS: Dict[str, str] = {
    "MBP": "M",      # lips closed
    "NLTDR": "N",    # tongue tip up, teeth nearly together (N, T, D; L and R are the minority)
    "FV": "F",       # lower lip to upper teeth
    "TH": "TH",      # tongue between the teeth
    "GK": "K",       # back of the tongue, mouth barely open
    "SH": "SH",      # teeth together, lips pushed out
    "O": "AO",       # rounded vowels (AO, OW, UW, ER in Papagayo-NG's table); AO is the open one
    "EHSZ": "EH",    # front vowels and S, Z (AE, EH, EY, HH, S, Z); the vowel shapes the mouth
    "AA": "AA",      # open
    "IY": "IY",      # spread
}
CMU_39 = frozenset({
    "AA", "AE", "AH", "AO", "AW", "AY", "B", "CH", "D", "DH", "EH", "ER", "EY", "F", "G", "HH",
    "IH", "IY", "JH", "K", "L", "M", "N", "NG", "OW", "OY", "P", "R", "S", "SH", "T", "TH",
    "UH", "UW", "V", "W", "Y", "Z", "ZH", "rest"})
REST = "rest"


def phoneme_set(labels) -> str:
    """The Papagayo-NG phoneme set a file's names belong to (first fit), or ``"custom"``.

    Examples
    --------
    >>> phoneme_set({"MBP", "etc", "rest"}), phoneme_set({"A", "C", "rest"}), phoneme_set({"NLTDR"})
    ('preston_blair', 'rhubarb', 'fleming_dobbs')
    >>> phoneme_set({"AA", "K"}), phoneme_set({"E", "rest"}), phoneme_set({"smile"})
    ('CMU_39', 'preston_blair', 'custom')
    """
    labels = set(labels)
    for name, names in (("preston_blair", PRESTON_BLAIR), ("rhubarb", RHUBARB),
                        ("fleming_dobbs", frozenset(FLEMING_DOBBS) | {REST}), ("CMU_39", CMU_39)):
        if labels <= names:
            return name
    return "custom"


class _Lines:
    """The file's lines with a cursor; every error names the line it is about."""

    def __init__(self, path: str, text: str):
        self.path = path
        self.lines = text.split("\n")
        if self.lines and self.lines[-1] == "":
            self.lines.pop()  # the newline ending the last line does not start another
        self.i = 0  # index of the next line

    def next(self, what: str) -> Tuple[str, int]:
        if self.i >= len(self.lines):
            raise TimelineError(f"the file ends here, where {what} should follow (a count above is too "
                                f"large, or the file is cut short)", path=self.path, line=len(self.lines))
        raw = self.lines[self.i]
        self.i += 1
        return raw.strip(), self.i

    def number(self, what: str, *, whole: bool = True, low: float = 0, high: float = MAX_FRAME) -> int:
        text, n = self.next(what)
        return _number(text, self.path, n, what, whole=whole, low=low, high=high)


def _number(text: str, path: str, line: int, what: str, *, whole: bool = True, low: float = 0,
            high: float = MAX_FRAME):
    value = parse_number(text, path, line, what) if text else None
    if value is None:
        raise TimelineError(f"expected {what}, found an empty line", path=path, line=line)
    if whole and value != int(value):
        raise TimelineError(f"{what} {text!r} is not a whole number", path=path, line=line)
    if not (low <= value <= high):
        raise TimelineError(f"{what} {text} is outside {low:g}..{high:g}", path=path, line=line)
    return int(value) if whole else value


# One voice as read: (name, [(first, last, [(frame, label, line)], word line)], phrase ranges)
Word = Tuple[int, int, List[Tuple[int, str, int]], int]


def _read_voice(lines: _Lines) -> Tuple[str, List[Tuple[int, int, Word]]]:
    name, _ = lines.next("the voice's name")
    lines.next("the voice's text")
    words: List[Tuple[int, int, Word]] = []
    for _ in range(lines.number("the number of phrases")):
        lines.next("the phrase's text")
        p0 = lines.number("the phrase's first frame")
        p1 = lines.number("the phrase's last frame")
        for _ in range(lines.number("the number of words")):
            text, n = lines.next("a word line ('text first last count')")
            fields = text.split()
            if len(fields) != 4:
                raise TimelineError(f"expected 'word first-frame last-frame phoneme-count', got {text[:60]!r}",
                                    path=lines.path, line=n)
            w0, w1, count = (_number(f, lines.path, n, what) for f, what in
                             zip(fields[1:], ("the word's first frame", "the word's last frame",
                                              "the word's phoneme count")))
            phonemes = []
            for _ in range(count):
                ptext, pn = lines.next("a phoneme line ('frame name')")
                pf = ptext.split()
                if len(pf) != 2:
                    raise TimelineError(f"expected 'frame phoneme', got {ptext[:60]!r}", path=lines.path, line=pn)
                frame = _number(pf[0], lines.path, pn, "phoneme frame")
                if phonemes and frame < phonemes[-1][0]:
                    raise TimelineError(f"phoneme frame {frame} is before the one above ({phonemes[-1][0]})",
                                        path=lines.path, line=pn)
                phonemes.append((frame, pf[1], pn))
            words.append((p0, p1, (w0, w1, phonemes, n)))
    return name, words


def _rows(words: List[Tuple[int, int, Word]], fps: float) -> List[Tuple[float, float, str, int]]:
    """Papagayo's GetPhonemeAtFrame as intervals: each phoneme until the next or its word's end."""
    rows = []
    for p0, p1, (w0, w1, phonemes, _) in words:
        lo, hi = max(w0, p0), min(w1, p1) + 1  # frames [lo, hi) of the word inside its phrase
        for k, (frame, label, line) in enumerate(phonemes):
            start = max(frame, lo)
            end = min(phonemes[k + 1][0] if k + 1 < len(phonemes) else hi, hi)
            if end > start:
                rows.append((start / fps, end / fps, label, line))
    return rows


def read(path: str, data: bytes, options: ReadOptions) -> Timeline:
    """Read one voice of a Papagayo project (the first, or the one ``options.tier`` names)."""
    try:
        text = decode_text(path, data)
    except TimelineError as exc:
        if "UTF-8" not in str(exc) or data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
            raise
        text = data.decode("latin-1").replace("\r\n", "\n").replace("\r", "\n")  # see the module notes
    lines = _Lines(path, text)
    lineno, first = first_nonblank(text)
    if first.lower() != MAGIC:
        raise TimelineError(f"first line must be {MAGIC!r}, not {first[:40]!r}", path=path, line=lineno or 1)
    lines.i = lineno
    lines.next("the sound file's name")
    fps = lines.number("the frame rate", whole=False, low=FPS_RANGE[0], high=FPS_RANGE[1])
    length = lines.number("the sound's length in frames")
    voices = []
    for _ in range(lines.number("the number of voices")):
        voices.append(_read_voice(lines))
    for rest in lines.lines[lines.i:]:
        if rest.strip():
            raise TimelineError(f"unexpected text after the last voice: {rest.strip()[:40]!r} "
                                f"(a count above is too small)", path=path, line=lines.lines.index(rest, lines.i) + 1)
    if not voices:
        raise TimelineError("the project has no voices", path=path, line=lineno + 4)
    names = [name for name, _ in voices]
    if options.tier is not None:
        if options.tier not in names:
            raise TimelineError(f"no voice named {options.tier!r}; voices: "
                                f"{', '.join(repr(n) for n in names)}", path=path)
        words = voices[names.index(options.tier)][1]
    else:
        words = voices[0][1]
        if len(voices) > 1:
            warnings.warn(f"{path}: {len(voices)} voices ({', '.join(repr(n) for n in names)}); reading the "
                          f"first, {names[0]!r} (--tier NAME reads another)", stacklevel=2)
    rows = _rows(words, float(fps))
    kind, rows = _labels(rows)
    return build(path, rows, kind, stated_end=length / float(fps))


def read_words(path, tier=None) -> Timeline:
    """The words of one voice of a Papagayo project (the first, or the one named ``tier``).

    Each word lasts from its first frame to the end of its last frame (clipped to its
    phrase); ``lipsync edit-timeline`` reads a project's word tier so.

    Examples
    --------
    >>> import os, tempfile
    >>> p = os.path.join(tempfile.mkdtemp(), "hi.pgo")
    >>> _ = open(p, "w").write("lipsync version 1\\nhi.wav\\n25\\n25\\n1\\nVoice 1\\nhi\\n1\\nhi\\n5\\n14\\n1\\n"
    ...                        "hi 5 14 2\\n5 HH\\n8 AY\\n")
    >>> [(w.label, w.start, w.end) for w in read_words(p)]
    [('hi', 0.2, 0.6)]
    """
    from .._files import read_input_bytes

    name = str(path)
    data = read_input_bytes(name, "a Papagayo project", error=TimelineError)
    try:
        text = decode_text(name, data)
    except TimelineError:
        text = data.decode("latin-1").replace("\r\n", "\n").replace("\r", "\n")
    lines = _Lines(name, text)
    lineno, first = first_nonblank(text)
    if first.lower() != MAGIC:
        raise TimelineError(f"first line must be {MAGIC!r}, not {first[:40]!r}", path=name, line=lineno or 1)
    lines.i = lineno
    lines.next("the sound file's name")
    fps = float(lines.number("the frame rate", whole=False, low=FPS_RANGE[0], high=FPS_RANGE[1]))
    length = lines.number("the sound's length in frames")
    voices = [_read_voice(lines) for _ in range(lines.number("the number of voices"))]
    if not voices:
        raise TimelineError("the project has no voices", path=name)
    names = [n for n, _ in voices]
    if tier is not None and tier not in names:
        raise TimelineError(f"no voice named {tier!r}; voices: {', '.join(map(repr, names))}", path=name)
    words = voices[names.index(tier) if tier is not None else 0][1]
    rows = []
    for p0, p1, (w0, w1, phonemes, line) in words:
        lo, hi = max(w0, p0), min(w1, p1) + 1
        if hi > lo:
            rows.append((lo / fps, hi / fps, lines.lines[line - 1].split()[0], line))
    return build(name, rows, PHONEME, stated_end=length / fps)


def _labels(rows) -> Tuple[str, list]:
    """The timeline kind and labels for the file's phoneme set (see the module notes)."""
    used = {label for _, _, label, _ in rows}
    found = phoneme_set(used)
    if found == "rhubarb":
        return VISEME, [(a, b, "X" if v == REST else v, n) for a, b, v, n in rows]
    if found == "fleming_dobbs":
        return PHONEME, [(a, b, FLEMING_DOBBS.get(v, ""), n) for a, b, v, n in rows]
    if found == "CMU_39":
        return PHONEME, [(a, b, "" if v == REST else v, n) for a, b, v, n in rows]
    return VISEME, rows  # Preston Blair (as Moho files), or the project's own names


def sniff(head: bytes) -> bool:
    return first_nonblank(sniff_text(head))[1].lower() == MAGIC


READERS.register("pgo", Reader("pgo", read, sniff, "Papagayo / Papagayo-NG project (lipsync version 1)"),
                 extensions=(".pgo",), aliases=("papagayo-ng", "papagayo-project"))
