"""Fuzzing the readers and loaders: bad files fail with the documented error, never otherwise.

Every timeline reader (by explicit format name or alias, and by extension and content
sniffing), the bank loader and the phoneme-map loader get three kinds of input:

* near-valid files generated from random content in the format's own shape, sometimes with
  odd values (huge, negative, non-finite or non-numeric numbers, odd labels);
* mutations of real files (the MFA and Gentle conformance files, the samples, the golden
  test files, the shipped bank and maps): bit flips, byte changes, truncations, line
  deletions, duplications and swaps, number perturbations, re-encodings (UTF-16 with and
  without a BOM, Latin-1, CR/CRLF line ends), inserted junk;
* random bytes and random text.

The contract checked for each case: either the call returns a valid value (a timeline that
obeys the Timeline rules, a bank or map that obeys its documented invariants), or it raises
an :class:`~lipsync.errors.InputError` subclass whose message names the file (and any line
it names lies inside the file). Any other exception fails the test. A watchdog (SIGALRM)
fails a case that runs longer than :data:`HANG_S`, and the process's peak memory may not
grow by more than :data:`RSS_HEADROOM_MB` over the run; separate tests measure with
tracemalloc that huge frame, sample and time numbers allocate nothing per frame.

Case counts come from tests/hypothesis_profiles.py: a quick deterministic profile in
``make test`` and ``make fuzz`` (``HYPOTHESIS_PROFILE=fuzz``) with 10,000 cases per reader
and per loader.
"""

from __future__ import annotations

import copy
import json
import math
import re
import resource
import shutil
import signal
import struct
import time
import tracemalloc
from contextlib import contextmanager
from pathlib import Path
from typing import Dict, List, Optional
from xml.sax.saxutils import escape as xml_escape

import cv2
import numpy as np
import pytest
import yaml
from hypothesis import given, note
from hypothesis import settings as hypothesis_settings
from hypothesis import strategies as st

import synthetic
from hypothesis_profiles import FUZZ, PROFILE
from lipsync._data import data_dir, default_bank_dir
from lipsync.banks.bank import MAX_IMAGE_PIXELS, MAX_LINES, MAX_VISEMES, Bank
from lipsync.errors import BankError, InputError, MapError, TimelineError
from lipsync.phonetics.phonemes import PhonemeMap, load_map
from lipsync.motion.timeline import Timeline
from lipsync.readers import READERS, read_timeline

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data"
SAMPLES = ROOT / "samples"

#: Most CPU time a single case may take. Every input here is at most a few tens of kB, which
#: every reader handles in milliseconds (the slowest, 5000 nested YAML brackets, ~5 s); 10 s
#: is far beyond any honest parse, so only a hang (or runaway work) trips it. This is a hang
#: guard, not a speed test. CPU time, not wall time: with the suite on both cores (xdist) and
#: other jobs beside it, that 5 s case took 34 s of wall time and tripped a wall-clock guard.
HANG_S = 10.0
#: Wall-time backstop for a case that hangs without using CPU (blocked on something).
HANG_WALL_S = 120.0
#: How far the process's peak resident memory may rise during the fuzz tests. No input is
#: over ~100 kB, so tens of MB already mean something is allocated per frame or per
#: claimed item; 512 MB leaves room for OpenCV's and numpy's own pools.
RSS_HEADROOM_MB = 512
#: Largest generated or mutated input, so one case never becomes a test of disk speed.
MAX_INPUT_BYTES = 200_000


# --------------------------------------------------------------------------- the contract

class Hang(Exception):
    """A case ran past HANG_S (raised by the watchdog; never an expected outcome)."""


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


#: The process's peak when the first fuzz case starts -- not when this file is imported:
#: tests that run earlier in the same session (numba's JIT, the face models) raise the
#: peak on their own, and only growth during the fuzzing is this file's business.
_RSS_START_MB = None


@pytest.fixture(autouse=True)
def _rss_baseline():
    global _RSS_START_MB
    if _RSS_START_MB is None:
        _RSS_START_MB = _rss_mb()
    yield


@contextmanager
def watchdog(what: str):
    """Fail a case that hangs: SIGPROF after HANG_S of CPU time (or SIGALRM after HANG_WALL_S
    of wall time) interrupts it with :class:`Hang`."""

    def on_cpu(signum, frame):
        raise Hang(f"{what}: still running after {HANG_S} s of CPU time")

    def on_wall(signum, frame):
        raise Hang(f"{what}: still running after {HANG_WALL_S} s")

    old_prof, old_alrm = signal.signal(signal.SIGPROF, on_cpu), signal.signal(signal.SIGALRM, on_wall)
    signal.setitimer(signal.ITIMER_PROF, HANG_S)
    signal.setitimer(signal.ITIMER_REAL, HANG_WALL_S)
    t0 = time.process_time()
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGPROF, old_prof)
        signal.signal(signal.SIGALRM, old_alrm)
    # Also caught when code swallowed the Hang (a broad ``except Exception`` around it).
    assert time.process_time() - t0 < HANG_S, f"{what}: took longer than {HANG_S} s of CPU time"


def newline_bound(data: bytes) -> int:
    """Upper bound on the lines of ``data`` in any encoding the readers accept."""
    return data.count(b"\n") + data.count(b"\r") + 1


def expect_clean(call, path: Path, data: bytes, error_type=InputError):
    """Run ``call()``: return its value, or the InputError it raised after checking it.

    Any exception other than ``error_type`` propagates and fails the test.
    """
    try:
        with watchdog(str(path)):
            result = call()
    except error_type as exc:
        assert isinstance(exc, InputError) and isinstance(exc, ValueError)
        assert str(path) in str(exc), f"message does not name the file: {exc}"
        if exc.line is not None:
            assert 1 <= exc.line <= newline_bound(data), f"line {exc.line} outside the file: {exc}"
        result = exc
    grown = _rss_mb() - _RSS_START_MB
    assert grown < RSS_HEADROOM_MB, f"peak memory grew by {grown:.0f} MB while reading {path}"
    return result


def check_timeline(tl, path: Path) -> None:
    """The Timeline invariants every successful read must satisfy."""
    assert isinstance(tl, Timeline)
    assert tl.kind in ("phoneme", "viseme")
    prev_end = 0.0
    for seg in tl:
        assert math.isfinite(seg.start) and math.isfinite(seg.end)
        assert 0.0 <= seg.start <= seg.end
        assert seg.start >= prev_end - 1e-4  # the documented float-noise tolerance
        assert isinstance(seg.label, str) and seg.label and seg.label == seg.label.strip()
        prev_end = seg.end
    assert math.isfinite(tl.duration) and tl.duration >= tl.end


# --------------------------------------------------------------------------- real files

def _files(*patterns: str) -> List[Path]:
    out: List[Path] = []
    for pattern in patterns:
        out += sorted(p for p in ROOT.glob(pattern) if p.is_file())
    return out


#: Real files of each format: conformance files from other tools, samples, golden inputs.
SEED_FILES: Dict[str, List[Path]] = {
    "textgrid": _files("tests/data/conformance/mfa/*.TextGrid", "samples/*.TextGrid",
                       "tests/data/timelines/[!e]*.TextGrid"),
    "gentle": _files("tests/data/conformance/gentle/*.json", "samples/*.json",
                     "tests/data/timelines/gentle_*.json"),
    "rhubarb-tsv": _files("tests/data/timelines/rhubarb_*.tsv"),
    "rhubarb-json": _files("tests/data/timelines/rhubarb_*.json"),
    "rhubarb-xml": _files("tests/data/timelines/rhubarb_*.xml"),
    "moho": _files("tests/data/timelines/*.dat"),
    "pgo": _files("tests/data/conformance/papagayo/*.pgo", "tests/data/timelines/papagayo_*.pgo"),
    "timit": _files("samples/*.phn", "tests/data/timelines/timit_*.PHN", "tests/data/timelines/timit_*.phn"),
    # (samples/record-script.txt is text to read aloud, not a label track)
    "audacity": [p for p in _files("samples/*.txt", "tests/data/timelines/audacity_*.txt")
                 if p.name != "record-script.txt"],
    "polly": _files("tests/data/timelines/polly_*.txt"),
    "azure": _files("tests/data/timelines/azure_*.json"),
    "whisper": _files("tests/data/timelines/whisper_*.json"),
    "elevenlabs": _files("tests/data/timelines/elevenlabs_*.json"),
    # Speech audio: only the short silent golden file, so mutants stay quick to decode.
    "audio": _files("tests/data/timelines/silence.wav"),
    "grid": _files("tests/data/grid-s1/*.align"),
}
#: Known-bad golden inputs: good material for mutations of any format.
ERROR_FILES = [p for p in _files("tests/data/timelines/error_*") if not p.name.endswith(".error")]
SEEDS: Dict[str, List[bytes]] = {fmt: [p.read_bytes() for p in ps] for fmt, ps in SEED_FILES.items()}
ALL_SEEDS: List[bytes] = [b for bs in SEEDS.values() for b in bs] + [p.read_bytes() for p in ERROR_FILES]

#: Extensions and aliases each format is documented to answer to (lipsync/readers/*).
EXTENSIONS = {"textgrid": [".TextGrid", ".textgrid"], "gentle": [".json"], "rhubarb-tsv": [".tsv"],
              "rhubarb-json": [".json"], "rhubarb-xml": [".xml"], "moho": [".dat"],
              "pgo": [".pgo"], "timit": [".phn", ".PHN"], "audacity": [".txt", ".labels"],
              "polly": [".marks", ".jsonl"], "azure": [".json"], "whisper": [".json"], "elevenlabs": [".json"],
              "audio": [".wav", ".flac", ".mp3", ".m4a", ".ogg"], "grid": [".align"]}
ALIASES = {"textgrid": ["praat", "mfa", "TextGrid"], "gentle": ["GENTLE"], "rhubarb-tsv": ["tsv"],
           "rhubarb-json": ["Rhubarb-JSON"], "rhubarb-xml": ["xml"], "moho": ["dat", "papagayo"],
           "pgo": ["papagayo-ng", "papagayo-project"], "timit": ["phn"], "audacity": ["labels"],
           "polly": ["speech-marks"], "azure": ["azure-visemes"], "whisper": ["words", "whisper.cpp"],
           "elevenlabs": ["character-alignment"], "audio": ["AUDIO"], "grid": ["grid-align"]}
ALL_EXTENSIONS = sorted({e for es in EXTENSIONS.values() for e in es}) + [".lab", ".bin", ".yaml", ""]


def test_every_reader_is_fuzzed_with_real_files():
    assert sorted(SEED_FILES) == sorted(READERS.names())
    for fmt, files in SEED_FILES.items():
        assert files, f"no real {fmt} file to mutate"
        for ext in EXTENSIONS[fmt]:
            owner = READERS.name_for_extension(ext)
            assert owner is not None and READERS.get(owner).sniff is not None
        for alias in ALIASES[fmt]:
            assert READERS.get(alias) is READERS.get(fmt)
    assert len(SEEDS["textgrid"]) >= 5 and len(SEEDS["gentle"]) >= 3


# --------------------------------------------------------------------------- generators

#: Number texts that break naive parsers: non-finite, enormous (more digits than Python's
#: int-from-str limit of 4300), hex, locale commas, exponents without digits, non-ASCII digits.
WEIRD_NUMBERS = ["-1", "-0", "0", "1e400", "-1e400", "1e-400", "nan", "NaN", "inf", "-inf", "Infinity",
                 "1" + "0" * 400, "9" * 5000, "0x1F", "1,5", "", "1.2.3", "+.5", ".", "1e", "--1",
                 "\u0661\u0662", "\u00bd", "1_000", "1e308", "4.9e-324", "18446744073709551617"]
#: JSON values of the wrong kind or size where a time belongs.
WEIRD_JSON = [None, True, False, "1.5", "x", "", [], {}, 10 ** 400, -(10 ** 30), -1, -1e-9,
              float("inf"), float("-inf"), float("nan"), 1e308, [1.0], {"start": 1}]
LABELS = ["AA1", "AH0", "HH", "sil", "sp", "spn", "h#", "pau", "B", "M", "ay", "ah_I", "hh_B", "oov",
          "t\u0283", "\u0250", "i\u02d0", "", " ", "X", "A", "D", "rest", "MBP", "etc", "<sil>"]

label_st = st.one_of(st.sampled_from(LABELS), st.text(max_size=8))
time_st = st.one_of(st.floats(0, 3, allow_nan=False), st.sampled_from([0.0, 1e-9, 1e-4, 1e6, 1e300]))


#: While True, the generators write every number and count as a file would (no weird
#: numbers, no wrong counts): the quick check that they make valid files sets it (see
#: :func:`test_generators_also_make_files_the_readers_accept`). The fuzz tests never do.
_TAME = False


def number_text(draw, value: float, *, integer: bool = False) -> str:
    """``value`` as a file would write it; one time in 15 a weird number instead."""
    if not _TAME and draw(st.integers(0, 14)) == 0:
        return draw(st.sampled_from(WEIRD_NUMBERS))
    if integer:
        return str(int(round(value)))
    fmt = draw(st.sampled_from(["{:.3f}", "{:.6f}", "{:g}", "{!r}", "{:.17e}", "{:.0f}"]))
    return fmt.format(value)


@st.composite
def intervals(draw, max_n: int = 10):
    """(start, end, label) rows, mostly in order, sometimes overlapping or reversed."""
    rows = []
    t = draw(st.sampled_from([0.0, 0.0, 0.5]))
    for _ in range(draw(st.integers(0, max_n))):
        gap = 0.0 if _TAME else draw(st.one_of(st.just(0.0), st.floats(-0.2, 0.5, allow_nan=False)))
        dur = draw(time_st if _TAME else st.one_of(time_st, st.floats(-0.1, 0.0)))
        start = t + gap
        rows.append((start, start + dur, draw(label_st)))
        t = start + max(dur, 0.0)
    return rows


def gen_timit(draw) -> str:
    sr = draw(st.sampled_from([16000, 8000, 1]))
    return "".join(f"{number_text(draw, s * sr, integer=True)} {number_text(draw, e * sr, integer=True)} "
                   f"{lab or 'h#'}\n" for s, e, lab in draw(intervals()))


def _tg_quote(s: str) -> str:
    return '"' + s.replace('"', '""') + '"'


def gen_textgrid(draw) -> str:
    short = draw(st.booleans())
    tiers = []
    for _ in range(draw(st.integers(0, 3))):
        name = draw(st.one_of(st.sampled_from(["phones", "words", "spk - phones", "phones"]), st.text(max_size=6)))
        cls = draw(st.sampled_from(["IntervalTier", "IntervalTier", "TextTier", "Tier"]))
        tiers.append((cls, name, draw(intervals())))
    end = max([e for _, _, rows in tiers for _, e, _ in rows] + [0.0])
    n = lambda v: number_text(draw, v)  # noqa: E731
    declared = lambda k: str(k) if _TAME or draw(st.integers(0, 9)) else draw(st.sampled_from(  # noqa: E731
        ["-1", "1e999", "10000000", "2.5", str(k + 1), "x"]))
    if short:
        out = ['File type = "ooTextFile short"', '"TextGrid"', "", n(0.0), n(end), "<exists>", declared(len(tiers))]
        for cls, name, rows in tiers:
            out += [_tg_quote(cls), _tg_quote(name), n(0.0), n(end), declared(len(rows))]
            for s, e, lab in rows:
                out += [n(s)] + ([n(e)] if cls != "TextTier" else []) + [_tg_quote(lab)]
    else:
        out = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "", f"xmin = {n(0.0)} ",
               f"xmax = {n(end)} ", "tiers? <exists> ", f"size = {declared(len(tiers))} ", "item []: "]
        for i, (cls, name, rows) in enumerate(tiers, 1):
            out += [f"    item [{i}]:", f"        class = {_tg_quote(cls)} ", f"        name = {_tg_quote(name)} ",
                    f"        xmin = {n(0.0)} ", f"        xmax = {n(end)} ",
                    f"        {'points' if cls == 'TextTier' else 'intervals'}: size = {declared(len(rows))} "]
            for j, (s, e, lab) in enumerate(rows, 1):
                if cls == "TextTier":
                    out += [f"        points [{j}]:", f"            number = {n(s)} ",
                            f"            mark = {_tg_quote(lab)} "]
                else:
                    out += [f"        intervals [{j}]:", f"            xmin = {n(s)} ", f"            xmax = {n(e)} ",
                            f"            text = {_tg_quote(lab)} "]
    return "\n".join(out) + "\n"


def json_value(draw, value: float):
    return draw(st.sampled_from(WEIRD_JSON)) if not _TAME and draw(st.integers(0, 14)) == 0 else value


def gen_gentle(draw) -> str:
    words = []
    for s, e, lab in draw(intervals(max_n=6)):
        case = draw(st.sampled_from(["success", "success", "not-found-in-audio", "not-found-in-transcript", None]))
        word = {"alignedWord": lab, "case": case, "word": lab}
        if case != "not-found-in-audio":
            phones = [{"phone": f"{p}{draw(st.sampled_from(['_B', '_I', '_E', '_S', '']))}",
                       "duration": json_value(draw, draw(st.floats(-0.01, 0.3, allow_nan=False)))}
                      for p in draw(st.lists(label_st, max_size=4))]
            word.update(start=json_value(draw, s), end=json_value(draw, e), phones=phones)
        if draw(st.integers(0, 20)) == 0:
            word = draw(st.sampled_from(WEIRD_JSON))
        words.append(word)
    doc = {"transcript": " ".join(str(w) for w in words)[:80], "words": words}
    return json.dumps(doc, indent=draw(st.sampled_from([None, 2])), ensure_ascii=draw(st.booleans()))


def gen_rhubarb_tsv(draw) -> str:
    rows = draw(intervals())
    return "".join(f"{number_text(draw, s)}\t{lab or 'X'}\n" for s, _, lab in rows)


def gen_rhubarb_json(draw) -> str:
    cues = [{"start": json_value(draw, s), "end": json_value(draw, e), "value": lab if draw(st.integers(0, 20)) else 3}
            for s, e, lab in draw(intervals())]
    doc = {"metadata": {"soundFile": "a.wav", "duration": json_value(draw, 3.0)}, "mouthCues": cues}
    return json.dumps(doc, indent=draw(st.sampled_from([None, 2])))


def gen_rhubarb_xml(draw) -> str:
    cues = "".join(f'<mouthCue start="{xml_escape(number_text(draw, s))}" end="{xml_escape(number_text(draw, e))}">'
                   f"{xml_escape(lab)}</mouthCue>\n" for s, e, lab in draw(intervals()))
    head = '<?xml version="1.0" encoding="utf-8"?>\n'
    if draw(st.integers(0, 15)) == 0:  # an entity-expansion ("billion laughs") attempt
        head += ('<!DOCTYPE r [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
                 '<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">]>\n')
        cues += "<mouthCue start='0' end='1'>&c;</mouthCue>"
    return (f"{head}<rhubarbResult>\n<metadata><soundFile>a.wav</soundFile>"
            f"<duration>{xml_escape(number_text(draw, 3.0))}</duration></metadata>\n<mouthCues>\n{cues}"
            f"</mouthCues>\n</rhubarbResult>\n")


def gen_moho(draw) -> str:
    fps = draw(st.sampled_from([24, 30]))
    body = "".join(f"{number_text(draw, 1 + s * fps, integer=True)} {lab or 'rest'}\n"
                   for s, _, lab in draw(intervals()))
    return "MohoSwitch1\n" + body


PGO_LABELS = ["AI", "O", "E", "etc", "MBP", "rest", "NLTDR", "EHSZ", "A", "H", "AA", "K", "smile"]


def gen_pgo(draw) -> str:
    """A Papagayo project: voices of phrases of words of phonemes, counts sometimes wrong."""
    fps = draw(st.sampled_from([24, 30]))

    def count(n):
        return number_text(draw, n + (0 if _TAME else draw(st.sampled_from([0, 0, 0, 0, 1, -1]))), integer=True)

    out = ["lipsync version 1", "a.wav", number_text(draw, fps, integer=True)]
    voices = draw(st.integers(0, 2))
    out += [number_text(draw, 3 * fps, integer=True), count(voices)]
    for v in range(voices):
        out += [f"\tVoice {v}", "\ttext"]
        rows = draw(intervals())
        out += [count(1), "\t\ttext", "\t\t0", number_text(draw, 3 * fps, integer=True), count(len(rows))]
        for s, e, _ in rows:
            labels = draw(st.lists(st.one_of(st.sampled_from(PGO_LABELS), label_st), max_size=3))
            out.append(f"\t\t\tw {number_text(draw, s * fps, integer=True)} "
                       f"{number_text(draw, e * fps, integer=True)} {count(len(labels))}")
            out += [f"\t\t\t\t{number_text(draw, s * fps + k, integer=True)} {lab or 'rest'}"
                    for k, lab in enumerate(labels)]
    return "\n".join(out) + "\n"


def gen_audacity(draw) -> str:
    out = []
    for s, e, lab in draw(intervals()):
        if draw(st.integers(0, 4)) == 0:
            e = s  # a point label
        out.append(f"{number_text(draw, s)}\t{number_text(draw, e)}\t{lab}\n")
        if draw(st.integers(0, 6)) == 0:
            out.append("\\\t100.000000\t2000.000000\n")  # a spectral-selection line
    return "".join(out)


POLLY_VISEMES = ["p", "t", "S", "T", "f", "k", "i", "r", "s", "u", "@", "a", "e", "E", "o", "O", "sil"]


def gen_polly(draw) -> str:
    lines = []
    for s, _, lab in draw(intervals()):
        kind = draw(st.sampled_from(["viseme", "viseme", "word", "sentence", "ssml", "other"]))
        value = draw(st.sampled_from(POLLY_VISEMES)) if kind == "viseme" and draw(st.integers(0, 9)) else lab
        lines.append(json.dumps({"time": json_value(draw, round(s * 1000)), "type": kind, "value": value}))
    if draw(st.integers(0, 5)) == 0:
        return "[" + ",\n".join(lines) + "]\n"
    return "\n".join(lines) + "\n"


def gen_azure(draw) -> str:
    off, vid = draw(st.sampled_from([("AudioOffset", "VisemeId"), ("audioOffset", "visemeId"),
                                     ("audio_offset", "viseme_id"), ("offset_ms", "visemeID")]))
    events = [{off: json_value(draw, round(s * 1e7)), vid: json_value(draw, draw(st.integers(-1, 23)))}
              for s, _, _ in draw(intervals())]
    doc = draw(st.sampled_from([events, {"visemes": events},
                                {"Metadata": [{"Type": "Viseme", "Data": e} for e in events]}]))
    return json.dumps(doc, indent=draw(st.sampled_from([None, 2])))


def gen_whisper(draw) -> str:
    words = [{draw(st.sampled_from(["word", "text"])): lab, "start": json_value(draw, s), "end": json_value(draw, e)}
             for s, e, lab in draw(intervals())]
    doc = draw(st.sampled_from([{"segments": [{"start": 0, "end": 1, "text": "x", "words": words}]},
                                {"words": words}, words, [{"words": words}],
                                {"transcription": [{"offsets": {"from": w.get("start"), "to": w.get("end")},
                                                    "text": w.get("word", w.get("text"))} for w in words]}]))
    return json.dumps(doc, indent=draw(st.sampled_from([None, 2])))


def gen_elevenlabs(draw) -> str:
    chars, starts, ends = [], [], []
    for s, e, lab in draw(intervals()):
        for c in (lab or " ") + " ":
            chars.append(c if draw(st.integers(0, 30)) else draw(st.sampled_from(WEIRD_JSON)))
            starts.append(json_value(draw, s))
            ends.append(json_value(draw, e))
    if draw(st.integers(0, 10)) == 0:
        ends = ends[:-1]
    al = {"characters": chars, "character_start_times_seconds": starts, "character_end_times_seconds": ends}
    doc = draw(st.sampled_from([al, {"alignment": al}, {"normalized_alignment": al, "audio_base64": ""}]))
    return json.dumps(doc, indent=draw(st.sampled_from([None, 2])))


GENERATORS = {"textgrid": gen_textgrid, "gentle": gen_gentle, "rhubarb-tsv": gen_rhubarb_tsv,
              "rhubarb-json": gen_rhubarb_json, "rhubarb-xml": gen_rhubarb_xml, "moho": gen_moho, "pgo": gen_pgo,
              "timit": gen_timit, "audacity": gen_audacity,
              "polly": gen_polly, "azure": gen_azure, "whisper": gen_whisper, "elevenlabs": gen_elevenlabs}


# --------------------------------------------------------------------------- mutations

_NUM_RE = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_ENCODINGS = ["utf-16", "utf-16-le", "utf-16-be", "utf-8-sig", "latin-1", "cp1252", "utf-32"]


def mutate_once(draw, data: bytes) -> bytes:
    op = draw(st.sampled_from(["flip", "byte", "truncate", "delete-line", "duplicate-line", "swap-lines",
                               "number", "number", "encoding", "newlines", "insert", "delete-span"]))
    n = len(data)
    pos = draw(st.integers(0, max(n - 1, 0)))
    if op == "flip" and n:
        return data[:pos] + bytes([data[pos] ^ (1 << draw(st.integers(0, 7)))]) + data[pos + 1:]
    if op == "byte" and n:
        return data[:pos] + bytes([draw(st.integers(0, 255))]) + data[pos + 1:]
    if op == "truncate":
        return data[:pos]
    if op == "delete-span" and n:
        return data[:pos] + data[pos + draw(st.integers(1, 64)):]
    if op == "insert":
        return data[:pos] + draw(st.binary(min_size=1, max_size=16)) + data[pos:]
    if op in ("delete-line", "duplicate-line", "swap-lines"):
        lines = data.split(b"\n")
        i = draw(st.integers(0, len(lines) - 1))
        if op == "delete-line":
            del lines[i]
        elif op == "duplicate-line":
            lines.insert(i, lines[i])
        else:
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        return b"\n".join(lines)
    if op == "number":
        found = list(_NUM_RE.finditer(data))
        if not found:
            return data
        m = found[draw(st.integers(0, len(found) - 1))]
        try:
            value = float(m.group())
        except (ValueError, OverflowError):
            value = 1.0
        how = draw(st.sampled_from(["weird", "negate", "scale", "shift"]))
        if how == "weird":
            new = draw(st.sampled_from(WEIRD_NUMBERS)).encode()
        elif how == "negate":
            new = repr(-value).encode()
        elif how == "scale":
            new = repr(value * draw(st.sampled_from([0.0, 0.5, 2.0, 1e3, 1e12, 1e300, -1.0]))).encode()
        else:
            new = repr(value + draw(st.floats(-5, 5, allow_nan=False))).encode()
        return data[:m.start()] + new + data[m.end():]
    if op == "encoding":
        enc = draw(st.sampled_from(_ENCODINGS))
        text = data.decode("utf-8", errors="replace")
        return text.encode(enc, errors="replace")
    if op == "newlines":
        return data.replace(b"\n", draw(st.sampled_from([b"\r\n", b"\r", b"\n\n", b"\x85", b" "])))
    return data


@st.composite
def mutated(draw, data: bytes, max_ops: int = 4):
    for _ in range(draw(st.integers(1, max_ops))):
        data = mutate_once(draw, data)[:MAX_INPUT_BYTES]
    return data


# --------------------------------------------------------------------------- timeline readers

@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


@st.composite
def timeline_case(draw, fmt: str):
    """(file bytes, how the case was made) for a fuzz case aimed at ``fmt``."""
    source = draw(st.sampled_from(["generated", "generated", "generated+mutated", "seed", "seed",
                                   "other-seed", "random-bytes", "random-text"]))
    if source.startswith("generated"):
        data = GENERATORS[fmt](draw).encode("utf-8", errors="surrogatepass")
        if source.endswith("mutated"):
            data = draw(mutated(data))
    elif source == "seed":
        data = draw(mutated(draw(st.sampled_from(SEEDS[fmt]))))
    elif source == "other-seed":
        data = draw(mutated(draw(st.sampled_from(ALL_SEEDS))))
    elif source == "random-bytes":
        data = draw(st.binary(max_size=2000))
    else:
        data = draw(st.text(max_size=500)).encode("utf-8", errors="surrogatepass")
    return data, source


@pytest.mark.parametrize("fmt", sorted(GENERATORS))
@FUZZ
@given(data=st.data())
def test_reader_fuzz(fmt, fuzz_dir, data):
    content, source = data.draw(timeline_case(fmt), label="case")
    how = data.draw(st.sampled_from(["explicit", "alias", "extension", "sniff", "other-extension"]), label="how")
    fmt_arg: Optional[str] = None
    ext = data.draw(st.sampled_from(EXTENSIONS[fmt]))
    if how == "explicit":
        fmt_arg = fmt
    elif how == "alias":
        fmt_arg = data.draw(st.sampled_from(ALIASES[fmt]))
    elif how == "sniff":
        ext = data.draw(st.sampled_from([".bin", "", ".lab"]))
    elif how == "other-extension":
        ext = data.draw(st.sampled_from(ALL_EXTENSIONS))
    options = dict(tier=data.draw(st.one_of(st.none(), st.sampled_from(["phones", "words"]), st.text(max_size=5))),
                   sample_rate=data.draw(st.one_of(st.just(16000), st.floats(1e-3, 1e9))),
                   fps=data.draw(st.one_of(st.just(24.0), st.floats(1.0, 240.0))))
    path = fuzz_dir / f"case-{fmt}{ext}"
    path.write_bytes(content)
    note(f"{source} via {how}: {path.name} {options} {content[:300]!r}")
    result = expect_clean(lambda: read_timeline(path, fmt_arg, **options), path, content, TimelineError)
    if not isinstance(result, InputError):
        check_timeline(result, path)


@st.composite
def generated(draw, fmt: str) -> str:
    return GENERATORS[fmt](draw)


@pytest.mark.parametrize("fmt", sorted(GENERATORS))
def test_generators_also_make_files_the_readers_accept(fmt, fuzz_dir):
    """Near-valid means some cases are valid: else the fuzzing would only test refusals.

    ``make test`` searches with the weird numbers, wrong counts and gaps switched off
    (:data:`_TAME`): valid files are then common (a few to a few hundred cases, ~5 s CPU for
    all readers), where the full search needed 30-200 s for TextGrid alone, varying with
    which modules earlier tests had imported (Hypothesis draws constants from them).
    ``make fuzz`` searches as the fuzz tests draw, weird values included.
    """
    global _TAME
    from hypothesis import Phase, find, settings

    path = fuzz_dir / f"valid-{fmt}{EXTENSIONS[fmt][0]}"

    def accepted(text: str) -> bool:
        path.write_text(text, encoding="utf-8")
        try:
            return len(read_timeline(path, fmt)) >= 2
        except InputError:
            return False

    _TAME = PROFILE != "fuzz"
    try:
        text = find(generated(fmt), accepted,
                    # valid files are a minority of the near-valid ones (TextGrid's especially), and
                    # derandomized runs differ with what ran before: search widely
                    settings=settings(max_examples=10000, database=None, deadline=None, derandomize=True,
                                      phases=[Phase.generate]))
    finally:
        _TAME = False
    path.write_text(text, encoding="utf-8")
    check_timeline(read_timeline(path, fmt), path)
    assert len(read_timeline(path)) >= 2  # by extension and sniffing too


# --------------------------------------------------------------------------- bounded work for huge numbers

#: A case's Python allocations must stay below this: the inputs are a few hundred bytes, so
#: anything near it means memory proportional to a number in the file (frames, samples).
ALLOC_LIMIT_BYTES = 4 << 20

HUGE_CASES = {
    # Moho: a frame number of 10^k (1-based frames at 24 fps) must not make a per-frame array.
    "moho": lambda k: f"MohoSwitch1\n1 rest\n{10 ** k} AI\n{10 ** k + 5} rest\n",
    # Papagayo: a frame number, and a count of phrases, of 10^k.
    "pgo": lambda k: (f"lipsync version 1\na.wav\n24\n{10 ** k}\n1\n\tV\n\tt\n\t{10 ** k}\n\t\tt\n\t\t0\n"
                      f"\t\t{10 ** k}\n\t\t1\n\t\t\tw 1 {10 ** k} 2\n\t\t\t\t1 AI\n\t\t\t\t{10 ** k} MBP\n"),
    # TIMIT: a sample count of 10^k.
    "timit": lambda k: f"0 {10 ** k} h#\n{10 ** k} {2 * 10 ** k} ay\n",
    "rhubarb-tsv": lambda k: f"0.00\tX\n1e{k}\tA\n2e{k}\tX\n",
    "audacity": lambda k: f"0\t1e{k}\tAA\n1e{k}\t1e{k}\tB\n",
    "rhubarb-json": lambda k: json.dumps({"mouthCues": [{"start": 0, "end": 10 ** k, "value": "A"}],
                                          "metadata": {"duration": 10 ** k}}),
    "gentle": lambda k: json.dumps({"words": [{"case": "success", "start": 10 ** k,
                                               "phones": [{"phone": "ay_S", "duration": 10 ** k}]}]}),
    "rhubarb-xml": lambda k: (f'<rhubarbResult><metadata><duration>1e{k}</duration></metadata><mouthCues>'
                              f'<mouthCue start="0" end="1e{k}">A</mouthCue></mouthCues></rhubarbResult>'),
    # TextGrid: a tier claiming 10^k intervals (the file holds one) must not loop or reserve 10^k slots.
    "textgrid": lambda k: ('File type = "ooTextFile short"\n"TextGrid"\n0\n1\n<exists>\n1\n"IntervalTier"\n'
                           f'"phones"\n0\n1\n{10 ** min(k, 7) if k % 2 else 10 ** k}\n0\n1\n"a"\n'),
}


#: Inputs the fuzzing found to escape as other exceptions, kept as fixed regression cases.
FOUND_BY_FUZZING = [
    ("gentle", '{"words": [{"case": "success", "start": 1' + "0" * 5000 + ', "phones": []}]}'),  # int limit
    ("gentle", '{"words": [{"case": "success", "start": 1' + "0" * 400 + ', "phones": []}]}'),  # OverflowError
    ("rhubarb-json", '{"mouthCues": [], "metadata": {"duration": 1' + "0" * 400 + '}}'),
    ("textgrid", 'File type = "ooTextFile"\nObject class = "TextGrid"\nxmin = 0\nxmax = 1\n'
                 'tiers? <exists>\nsize = 1e999\n'),
    ("textgrid", 'File type = "ooTextFile short"\n"TextGrid"\n0\n1\n<exists>\n1\n"IntervalTier"\n'
                 '"phones"\n0\n1\n-1e999\n'),
]


@pytest.mark.parametrize("case", range(len(FOUND_BY_FUZZING)))
def test_fuzz_findings_are_timeline_errors(case, fuzz_dir):
    fmt, text = FOUND_BY_FUZZING[case]
    path = fuzz_dir / f"found-{case}{EXTENSIONS[fmt][0]}"
    path.write_text(text)
    for how in (fmt, None):
        result = expect_clean(lambda: read_timeline(path, how), path, text.encode(), TimelineError)
        assert isinstance(result, TimelineError)


@pytest.mark.parametrize("fmt", sorted(HUGE_CASES))
@pytest.mark.parametrize("k", [6, 12, 18, 300, 400])
def test_huge_numbers_allocate_nothing_per_frame(fmt, k, fuzz_dir):
    path = fuzz_dir / f"huge-{fmt}-{k}{EXTENSIONS[fmt][0]}"
    text = HUGE_CASES[fmt](k)
    path.write_text(text)
    tracemalloc.start()
    try:
        result = expect_clean(lambda: read_timeline(path, fmt), path, text.encode(), TimelineError)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < ALLOC_LIMIT_BYTES, f"{fmt} with 10^{k}: {peak} bytes allocated"
    if not isinstance(result, InputError):
        check_timeline(result, path)
        assert len(result) <= 3  # segments come from rows, never from frame or sample counts


# --------------------------------------------------------------------------- bank loader

#: Values of the wrong type or size for any field of bank.yaml, and image paths that must
#: be refused (leaving the folder, absolute, NUL, a folder, a symlink out) or accepted.
WEIRD_YAML_VALUES = [None, True, 0, -1, 10 ** 400, -(10 ** 30), 1e308, float("inf"), float("nan"), "",
                     "x" * 300, [], {}, [[1, 2]], [[0, 0], [0, 0]], [[1, 2], [3]], [[1, 2], [3, 4], [5, 6]],
                     [["a", "b"], ["c", "d"]], {"a": 1.0, "b": -1.0, "p": 9}, "../X.png", "/etc/passwd",
                     "sub/../X.png", "sub/X.png", "out.png", ".", "sub", "missing.png", "X.png\x00.txt",
                     "C:\\X.png", "\\\\server\\X.png", "~/X.png", "fuzz.png", "big.png", "big.jpg",
                     "X.png/", "X.png" * 1000, "é.png"]
#: YAML texts that attack the parser rather than the schema.
YAML_ATTACKS = [
    # Custom and Python tags: safe_load must refuse them.
    "name: !!python/object/apply:os.system ['echo pwned']\nrest: X\nvisemes: {}\n",
    "name: !custom toon\nrest: X\nvisemes: {}\n",
    "!!python/object:lipsync.banks.bank.Bank {}\n",
    "name: !!binary aGVsbG8=\nrest: X\nvisemes: !!set {X: null}\n",
    "name: toon\nrest: X\nvisemes: !!omap [{X: {image: X.png, lines: {a: [[0, 0], [1, 1]]}}}]\n",
    # Aliases: a "billion laughs" document (shared references, must stay small).
    "a: &a [x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
    "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
    "e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d]\nf: &f [*e, *e, *e, *e, *e, *e, *e, *e, *e]\n"
    "name: *f\nrest: *f\nvisemes: {X: {image: X.png, lines: {a: *f}}}\n",
    "base: &v {image: X.png, lines: {a: [[0, 0], [9, 9]]}}\nname: t\nrest: X\nvisemes: {X: *v, A: {<<: *v}}\n",
    "name: t\nrest: X\nvisemes: &r {X: *r}\n",
    "x: &x [*x]\nname: t\nrest: X\nvisemes: {X: {image: X.png, lines: {a: *x}}}\n",
    # Huge and odd numbers.
    "name: t\nrest: X\nwarp: {a: 1e999999, b: 0x7fffffffffffffffffff, p: .nan}\nvisemes: {}\n",
    "name: t\nrest: X\nwarp: {a: 1:30:00, b: 0o777, p: -.inf}\nvisemes: {}\n",
    # Deep nesting.
    "name: " + "[" * 5000 + "]" * 5000 + "\n",
    "visemes: " + "{a: " * 3000 + "1" + "}" * 3000 + "\n",
    # Wrong types at the top.
    "- name\n- rest\n", "just text\n", "42\n", "", "\t\tname: t\n", "name: t\nname: u\n",
    "name: t\nrest: X\nvisemes: [X, A]\n", "name: t\nrest: X\nvisemes: X\n",
    # Found by fuzzing: an integer beyond Python's 4300-digit int-from-text limit; an error
    # at the end of a file without a final newline (PyYAML marks the line after the last).
    "name: " + "9" * 5000 + "\nrest: X\nvisemes: {}\n",
    "name: synthetic\nrest: X\nvisemes:\n  X:\n    image: X.png\n    l",
]


def _png_with_header_size(width: int, height: int) -> bytes:
    """A PNG whose IHDR claims ``width`` x ``height`` (the pixel data is a 1x1 image's)."""
    ok, buf = cv2.imencode(".png", np.zeros((1, 1, 3), np.uint8))
    data = bytearray(buf.tobytes())
    data[16:24] = struct.pack(">II", width, height)
    return bytes(data)


def _jpeg_with_header_size(width: int, height: int) -> bytes:
    """A 16x16 JPEG whose frame header (SOF0) claims ``width`` x ``height``."""
    ok, buf = cv2.imencode(".jpg", np.full((16, 16, 3), 128, np.uint8))
    data = bytearray(buf.tobytes())
    i = data.find(b"\xff\xc0")
    data[i + 5:i + 9] = struct.pack(">HH", height, width)
    return bytes(data)


@pytest.fixture(scope="module")
def bank_seeds(tmp_path_factory):
    """Two bank folders to fuzz in (the synthetic subject and the shipped toon), with extras:
    a subfolder, a symlink pointing out of the bank, bomb images."""
    root = tmp_path_factory.mktemp("bankfuzz")
    synth = synthetic.write_bank(root / "synthetic")
    toon = root / "toon"
    shutil.copytree(default_bank_dir(), toon, ignore=shutil.ignore_patterns(".lipsync"))
    outside = root / "outside.png"
    shutil.copy(synth / "X.png", outside)
    seeds = []
    for folder in (synth, toon):
        (folder / "sub").mkdir()
        shutil.copy(synth / "X.png", folder / "sub" / "X.png")
        (folder / "out.png").symlink_to(outside)
        (folder / "big.png").write_bytes(_png_with_header_size(50_000, 50_000))
        (folder / "big.jpg").write_bytes(_jpeg_with_header_size(30_000, 30_000))
        text = (folder / "bank.yaml").read_text()
        seeds.append((folder, text, yaml.safe_load(text)))
    return seeds


def _paths(node, prefix=()):
    """Every key path in a nested dict/list, the root included."""
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


def _get(node, path):
    for key in path:
        node = node[key]
    return node


@st.composite
def structural_mutation(draw, spec, weird_values):
    """``spec`` with 1-3 changes at random places: a weird value, a deleted, added or renamed key."""
    spec = copy.deepcopy(spec)

    def weird():  # a fresh copy: later mutations must not change the shared table
        return copy.deepcopy(draw(st.sampled_from(weird_values)))

    for _ in range(draw(st.integers(1, 3))):
        paths = list(_paths(spec))
        path = draw(st.sampled_from(paths))
        op = draw(st.sampled_from(["value", "value", "delete", "add", "rename", "clone"]))
        if not path:
            if op == "value":
                spec = weird()
            continue
        parent, key = _get(spec, path[:-1]), path[-1]
        if op == "value":
            parent[key] = weird()
        elif op == "delete":
            del parent[key]
        elif op == "add" and isinstance(parent, dict):
            parent[draw(st.sampled_from(["extra", "X", "_l", "nose_r", "", "1"]) | st.text(max_size=5))] = \
                weird()
        elif op == "add" and isinstance(parent, list):
            parent.append(weird())
        elif op == "rename" and isinstance(parent, dict):
            parent[draw(st.text(max_size=5) | st.sampled_from(["a_l", "b_r", "X", "rest"]))] = parent.pop(key)
        elif op == "clone" and isinstance(parent, dict):
            for i in range(draw(st.integers(1, 3))):  # the limits themselves: test_cli_failures.py
                parent[f"{key}{i}"] = copy.deepcopy(parent[key])
        if not isinstance(spec, (dict, list)):
            break
    return spec


def _dump(spec) -> str:
    try:
        return yaml.safe_dump(spec, allow_unicode=True, sort_keys=False, width=120)
    except (yaml.YAMLError, RecursionError):
        return "name: unrepresentable\n"


@st.composite
def bank_case(draw, seeds):
    # The synthetic seed three times in four: the toon bank.yaml is 10x larger and PyYAML parses
    # it (twice per load) at ~30 ms, which would dominate the fuzz run.
    folder, text, spec = draw(st.sampled_from(seeds[:1] * 3 + seeds[1:]))
    source = draw(st.sampled_from(["structure", "structure", "structure+text", "text", "attack",
                                   "attack+text", "image", "random-bytes"]))
    if source.startswith("structure"):
        data = _dump(draw(structural_mutation(spec, WEIRD_YAML_VALUES))).encode("utf-8", "surrogatepass")
    elif source.startswith("attack"):
        data = draw(st.sampled_from(YAML_ATTACKS)).encode()
    elif source == "image":
        # One viseme's image replaced by a damaged copy of a real image.
        spec = copy.deepcopy(spec)
        victim = draw(st.sampled_from(sorted(spec["visemes"])))
        spec["visemes"][victim]["image"] = "fuzz.png"
        image = (folder / f"{victim}.png").read_bytes()
        (folder / "fuzz.png").write_bytes(draw(mutated(image, max_ops=2)))
        data = _dump(spec).encode()
    elif source == "random-bytes":
        data = draw(st.binary(max_size=2000))
    else:
        data = text.encode()
    if source.endswith("text"):
        data = draw(mutated(data))
    return folder, data, source


def check_bank(bank: Bank) -> None:
    assert 1 <= len(bank.names) <= MAX_VISEMES and bank.rest in bank.names
    assert 1 <= len(bank.line_names) <= MAX_LINES
    h, w = bank.shape
    assert h * w <= MAX_IMAGE_PIXELS
    for v in bank.names:
        img = bank.images[v]
        assert img.dtype == np.uint8 and img.shape == (h, w, 3)
        lines = bank.lines[v]
        assert lines.shape == (len(bank.line_names), 2, 2) and np.all(np.isfinite(lines))
        assert np.all(np.hypot(*(lines[:, 1] - lines[:, 0]).T) > 0)
    assert 0 < bank.warp.a and 0 < bank.warp.b and 0 <= bank.warp.p


@FUZZ
@given(data=st.data())
def test_bank_loader_fuzz(bank_seeds, data):
    folder, content, source = data.draw(bank_case(bank_seeds), label="case")
    yaml_path = folder / "bank.yaml"
    yaml_path.write_bytes(content)
    note(f"{source}: {content[:400]!r}")
    result = expect_clean(lambda: Bank.load(folder), yaml_path, content, BankError)
    if not isinstance(result, InputError):
        check_bank(result)
        # Every image the bank uses lies inside its folder (no ../, absolute path or symlink out).
        spec = yaml.safe_load(content)
        for v in result.names:
            real = (folder / spec["visemes"][v]["image"]).resolve()
            assert folder.resolve() in real.parents


@pytest.mark.parametrize("attack", range(len(YAML_ATTACKS)))
def test_each_yaml_attack_on_the_bank_loader(bank_seeds, attack):
    folder = bank_seeds[0][0]
    content = YAML_ATTACKS[attack].encode()
    (folder / "bank.yaml").write_bytes(content)
    result = expect_clean(lambda: Bank.load(folder), folder / "bank.yaml", content, BankError)
    assert isinstance(result, BankError)  # none of them is a valid bank


# --------------------------------------------------------------------------- phoneme-map loader

MAP_SEEDS = [p.read_text(encoding="utf-8") for p in sorted((data_dir("configs") / "maps").glob("*.yaml"))]
SMALL_MAP = {"name": "tiny", "phoneset": None, "silence": "rest", "fallback": "open",
             "map": {"M": "closed", "AY": ["open", "wide"], "AA": "open"}, "closures": ["closed"],
             "aliases": {"closed": ["MBP"]}}
WEIRD_MAP_VALUES = [None, True, 0, 10 ** 400, float("nan"), "", " ", "x" * 300, [], {}, [""], ["A", None],
                    {"A": ["B", ["C"]]}, "english", "klingon", ["closed"], ["nowhere"], {"nowhere": ["x"]}]
MAP_ATTACKS = [a.replace("visemes", "map") for a in YAML_ATTACKS] + [
    "name: m\nsilence: X\nfallback: C\nmap: !!python/name:os.system\n",
    "name: m\nsilence: X\nfallback: C\nmap: {AA: &d [D, D, D], B: *d}\nclosures: [*d]\n",
    "name: m\nsilence: X\nfallback: C\nmap: {AA: D}\nphoneset: ../../../etc/passwd\n",
]


@st.composite
def map_case(draw):
    source = draw(st.sampled_from(["structure", "structure", "text", "text", "attack", "attack+text",
                                   "random-bytes"]))
    if source == "structure":
        base = draw(st.sampled_from([SMALL_MAP] + [yaml.safe_load(t) for t in MAP_SEEDS]))
        data = _dump(draw(structural_mutation(base, WEIRD_MAP_VALUES))).encode("utf-8", "surrogatepass")
    elif source == "text":
        data = draw(mutated(draw(st.sampled_from(MAP_SEEDS)).encode()))
    elif source.startswith("attack"):
        data = draw(st.sampled_from(MAP_ATTACKS)).encode()
        if source.endswith("text"):
            data = draw(mutated(data))
    else:
        data = draw(st.binary(max_size=2000))
    return data, source


@pytest.mark.parametrize("attack", range(len(MAP_ATTACKS)))
def test_each_yaml_attack_on_the_map_loader(fuzz_dir, attack):
    path = fuzz_dir / "attack-map.yaml"
    content = MAP_ATTACKS[attack].encode()
    path.write_bytes(content)
    result = expect_clean(lambda: load_map(str(path)), path, content, MapError)
    assert isinstance(result, MapError)


@FUZZ
@given(data=st.data())
def test_map_loader_fuzz(fuzz_dir, data):
    content, source = data.draw(map_case(), label="case")
    path = fuzz_dir / "map.yaml"
    path.write_bytes(content)
    note(f"{source}: {content[:400]!r}")
    result = expect_clean(lambda: load_map(str(path)), path, content, MapError)
    if not isinstance(result, InputError):
        assert isinstance(result, PhonemeMap)
        assert result.silence and result.fallback and result.silence == result.silence.strip()
        assert set(result.closures) <= set(result.visemes())
        for label in result.map:
            assert result.targets(label) and all(isinstance(t, str) and t.strip() for t in result.targets(label))


# --------------------------------------------------------------------------- deep nesting, out of process

#: Nesting depths for YAML flow collections and block sequences ("- - - x"): 50,000 levels is
#: ~100 kB, well under the bank.yaml size limit, and deep enough to overflow the C stack of a
#: recursive parser; so it runs in a child process, where a crash is a return code, not the
#: end of the test run.
DEEP = 50_000


@pytest.mark.parametrize("loader", ["bank", "map"])
@pytest.mark.parametrize("shape", ["flow-list", "flow-map", "block-seq"])
def test_deeply_nested_yaml_is_refused_not_a_crash(loader, shape, tmp_path):
    import subprocess
    import sys

    nested = {"flow-list": "[" * DEEP + "]" * DEEP, "flow-map": "{a: " * DEEP + "1" + "}" * DEEP,
              "block-seq": "\n" + "- " * DEEP + "x"}[shape]
    target = tmp_path / ("bank.yaml" if loader == "bank" else "map.yaml")
    target.write_text(f"name: t\nrest: X\nsilence: X\nfallback: C\nmap: {nested}\nvisemes: {nested}\n")
    call = (f"from lipsync.banks.bank import Bank; Bank.load({str(tmp_path)!r})" if loader == "bank" else
            f"from lipsync.phonetics.phonemes import load_map; load_map({str(target)!r})")
    code = ("import sys\nfrom lipsync.errors import InputError\ntry:\n    " + call +
            "\nexcept InputError as exc:\n    print(exc, file=sys.stderr)\n    sys.exit(2)\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, f"exit {result.returncode}: {result.stderr[-500:]}"
    assert str(target) in result.stderr


# --------------------------------------------------------------------------- the editor's document

#: Any JSON value (NaN and the infinities included: Python's json module reads them).
json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-2**70, 2**70) | st.floats() | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=10), inner, max_size=5),
    max_leaves=25)


@st.composite
def editor_documents(draw, base: dict):
    """A bank document as the editor page sends it: random JSON, or the real one with random
    parts replaced, removed or retyped (so that validation goes deep)."""
    if draw(st.integers(0, 4)) == 0:
        return draw(st.dictionaries(st.sampled_from(["name", "rest", "warp", "symmetry", "visemes", "x"]),
                                    json_values, max_size=6))
    doc = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 4))):
        node = doc
        for _ in range(draw(st.integers(0, 5))):  # walk down a random path
            keys = list(node) if isinstance(node, dict) else list(range(len(node))) if isinstance(node, list) else []
            if not keys:
                break
            key = draw(st.sampled_from(keys))
            if not isinstance(node[key], (dict, list)) or draw(st.integers(0, 3)) == 0:
                break
            node = node[key]
        if isinstance(node, dict) and node:
            key = draw(st.sampled_from(sorted(node)))
            action = draw(st.sampled_from(["replace", "delete", "add"]))
            if action == "replace":
                node[key] = draw(json_values)
            elif action == "delete":
                del node[key]
            else:
                node[draw(st.text(max_size=8))] = draw(json_values)
        elif isinstance(node, list) and node:
            node[draw(st.integers(0, len(node) - 1))] = draw(json_values)
    return doc


@pytest.fixture(scope="module")
def editor_client(tmp_path_factory):
    from starlette.testclient import TestClient

    from lipsync.editor import Editor, make_app
    from lipsync.web import Session

    folder = synthetic.write_bank(tmp_path_factory.mktemp("editor-fuzz") / "bank")
    editor = Editor(folder)
    session = Session.open()
    client = TestClient(make_app(editor, session), base_url=session.origin, raise_server_exceptions=False)
    client.headers["X-Lipsync-Token"] = session.token
    base = client.get("/api/bank").json()["doc"]
    yield client, editor, base
    editor.close()
    session.close()


@FUZZ
@given(data=st.data())
def test_editor_document_fuzz(editor_client, data):
    """Every malformed document gets 422 with a message (never 500); a document that is
    accepted loads as a bank, and a refused save leaves bank.yaml as it was."""
    client, editor, base = editor_client
    doc = data.draw(editor_documents(base), label="doc")
    route = data.draw(st.sampled_from(["/api/draft", "/api/save"]), label="route")
    before = editor.yaml_path.read_bytes()
    with watchdog(f"POST {route}"):
        r = client.post(route, content=json.dumps({"doc": doc}, allow_nan=True))
    assert r.status_code in (200, 409, 413, 422), (r.status_code, r.text[:500])
    body = r.json()
    if r.status_code == 200:
        assert body["ok"] is True
        if route == "/api/save":
            check_bank(Bank.load(editor.folder))
    else:
        assert body["ok"] is False and body["error"]["message"].strip()
        assert editor.yaml_path.read_bytes() == before


# --------------------------------------------------------------------------- lipsync serve's query options

#: What a client might put in ``fps=``: numbers of every kind, and text that is not one.
fps_texts = st.one_of(st.floats().map(repr), st.integers(-10**6, 10**6).map(str),
                      st.sampled_from(["0", "-0", "1", "120", "121", "0.5", "nan", "NaN", "inf", "-inf", "1e308",
                                       "1e-308", "", " 25", "25 ", "0x19", "25,0", "٢٥", "1_0"]),
                      st.text(max_size=12))


@pytest.fixture(scope="module")
def serve_client(tmp_path_factory):
    from starlette.testclient import TestClient

    from lipsync.server import LiveServer, ServeConfig
    from lipsync.web import Session

    folder = synthetic.write_bank(tmp_path_factory.mktemp("serve-fuzz") / "bank", synthetic.RHUBARB_SHAPES)
    session = Session.open()
    server = LiveServer(ServeConfig(bank=str(folder), method="dissolve"), session=session)
    client = TestClient(server.app, base_url=session.origin, raise_server_exceptions=False)
    yield client, session
    server.close()
    session.close()


def _job_end(client, session, job: str) -> dict:
    deadline = time.monotonic() + 60
    while True:
        state = client.get(session.url(f"/api/jobs/{job}")).json()
        if state["state"] not in ("queued", "running"):
            return state
        assert time.monotonic() < deadline, state
        time.sleep(0.01)


@FUZZ
@given(data=st.data())
def test_serve_render_query_fuzz(serve_client, data):
    """POST /api/render with any query options: 202 only for valid ones (fps as `lipsync render
    --fps` takes it), an error status with a message otherwise, never 500; an accepted job
    ends done (at the fps asked for) or with an error naming the upload."""
    from urllib.parse import urlencode

    client, session = serve_client
    params = {}
    if data.draw(st.booleans(), label="has fps"):
        params["fps"] = data.draw(fps_texts, label="fps")
    if data.draw(st.booleans(), label="has format"):
        params["format"] = data.draw(st.sampled_from(["rhubarb-tsv", "tsv", "timit", "audio", "nope", ""])
                                     | st.text(max_size=10), label="format")
    if data.draw(st.booleans(), label="has text"):
        params["text"] = data.draw(st.text(max_size=40), label="text")
    name = data.draw(st.sampled_from(["cues.tsv", "a.phn", "x", "", "../../etc/passwd", "a.TSV", "a.b.c.tsv"])
                     | st.text(max_size=20), label="name")
    params["name"] = name
    valid_body = data.draw(st.integers(0, 5), label="body kind") == 0
    body = b"0.00\tX\n0.20\tD\n0.40\tX\n" if valid_body else data.draw(st.binary(max_size=200), label="body")
    url = session.url("/api/render") + "&" + urlencode(params)
    with watchdog("POST /api/render"):
        r = client.post(url, content=body)
    assert r.status_code in (202, 400, 404, 413, 503), (r.status_code, r.text[:300])
    if r.status_code != 202:
        assert r.json()["error"].strip()
        return
    fps = params.get("fps")
    if fps is not None:  # accepted: a finite rate within the CLI's range
        assert 1 <= float(fps) <= 120
    state = _job_end(client, session, r.json()["job"])
    assert state["state"] in ("done", "error"), state
    if state["state"] == "error":
        assert state["error"].strip() and "render failed" not in state["error"], state
    elif valid_body and params.get("format") in (None, "rhubarb-tsv", "tsv"):
        rate = 25.0 if fps is None else float(fps)
        assert state["frames"] == math.ceil(0.4 * rate - 1e-9), (state, rate)


# --- transcripts and long cue files (issue 38) -------------------------------------------------
#
# Transcripts: any text -- huge words, emoji, mixed scripts, digits, path-like values, sizes
# around the limit -- either gives lowercase dictionary-spelled words or an InputError, and
# no warning is longer than a screen. Long cue files: Rhubarb TSV files of many short cues
# read and planned: the array plan (long tracks) equals the segment-by-segment plan.

from hypothesis_profiles import PROFILE  # noqa: E402

from lipsync.speech.align import read_transcript  # noqa: E402
from lipsync.speech.scripts import check_english_script  # noqa: E402
from lipsync.speech.text import MAX_TRANSCRIPT_CHARS, normalise_transcript  # noqa: E402

_WORD_CHARS = st.sampled_from(list("abcxyzABC019'-.,!?& ") + ["é", "ß", "ж", "语", "ع", "\U0001F600", "\u0301",
                                                               "\u200b", "\t", "\n", "/", "ː"])
_TRANSCRIPTS = st.one_of(
    st.text(_WORD_CHARS, max_size=400),
    st.text(max_size=200),
    st.builds(lambda c, n: c * n, st.sampled_from(["a", "zq", "\U0001F600", "9", "ж"]), st.integers(1, 60_000)),
    st.builds(lambda n, extra: ("word " * (MAX_TRANSCRIPT_CHARS // 5 + 1))[:MAX_TRANSCRIPT_CHARS - 1 + n] + extra,
              st.integers(0, 3), st.sampled_from(["", "x"])),
    st.sampled_from(["/dev/zero", "/dev/null", "./missing.txt", "../x.lab", "~/script.txt", "e.g.", "and/or"]),
)
_MAX_MESSAGE = 1000


@FUZZ
@given(text=_TRANSCRIPTS)
def test_transcript_fuzz(text):
    import warnings

    with watchdog("transcript"), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            read = read_transcript(text)
            if read is None:
                return
            assert len(read) <= MAX_TRANSCRIPT_CHARS
            words = normalise_transcript(read)
            check_english_script(read, words, path="t.txt")
        except InputError as exc:
            assert len(str(exc)) < _MAX_MESSAGE
            return
    assert all(re.fullmatch(r"[a-z]+(?:'[a-z]+)*", w) for w in words), words[:5]
    assert all(len(str(w.message)) < _MAX_MESSAGE for w in caught)


def _cue_file(path: Path, starts, labels) -> None:
    path.write_text("".join(f"{t:.2f}\t{v}\n" for t, v in zip(starts, labels)))


#: Cues per long file: past the sequencer's array-plan threshold under ``make fuzz``.
_LONG_CUES = (20, 25_000) if PROFILE == "fuzz" else (20, 3_000)


@hypothesis_settings(FUZZ, max_examples=60 if PROFILE == "fuzz" else 15)
@given(n=st.integers(*_LONG_CUES), seed=st.integers(0, 2 ** 32 - 1), step=st.sampled_from([1, 2, 3, 7]))
def test_long_cue_file_fuzz(tmp_path_factory, n, seed, step):
    import lipsync.motion.sequencer as sq
    from lipsync.motion._plan_kernel import plan_arrays

    rng = np.random.default_rng(seed)
    hundredths = np.cumsum(rng.integers(1, step + 1, size=n))   # 10 ms cues and a few longer ones
    starts = np.concatenate([[0], hundredths[:-1]]) / 100
    labels = rng.choice(list("ABCDEFGHX"), size=n, p=[.2, .2, .1, .1, .1, .1, .05, .05, .1])
    labels[-1] = "X"
    path = tmp_path_factory.mktemp("cues") / "long.tsv"
    _cue_file(path, starts, labels)
    with watchdog("long cue file"):
        tl = read_timeline(path)
        arrays = plan_arrays(tl, rest="X", closures={"A"}, max_held_pause=sq.MAX_HELD_PAUSE_S,
                                min_segment=sq.MIN_SEGMENT_S, total=tl.duration, start=0.0)
    saved, sq.ARRAY_PLAN_FROM = sq.ARRAY_PLAN_FROM, 10 ** 12
    try:
        segment_by_segment = sq.plan_segments(tl, rest="X", closures={"A"})
    finally:
        sq.ARRAY_PLAN_FROM = saved
    assert arrays == segment_by_segment
    assert arrays[0][0] == 0.0 and arrays[-1][1] == tl.duration
    assert all(a[1] == b[0] and a[2] != b[2] for a, b in zip(arrays, arrays[1:]))
