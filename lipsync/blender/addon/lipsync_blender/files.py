"""Reading what lipsync wrote, and the frame rule; no bpy here (the tests load this module alone).

The rule that lines a lipsync clip up with a Blender scene, used for every import and key:

* Blender frame ``f`` shows the scene time ``t = (f - frame_start) / scene_fps``
  (``scene_fps = render.fps / render.fps_base``; ``frame_start`` is the start the operator
  was given, the scene's ``frame_start`` unless set);
* lipsync frame ``k`` (``frame_000000.png`` is k = 0, ``frames.json``'s ``frames[k]``)
  shows the time ``[k / fps, (k + 1) / fps)`` of the clip, so Blender frame ``f`` shows
  lipsync frame ``k = floor(t * fps)``, clamped to the clip;
* a cue starting at ``s`` seconds shows from the first Blender frame whose time is ``>= s``.

Equal rates give ``k = f - frame_start``: ``frame_000000.png`` is Blender frame 1 when
``frame_start`` is 1. Different rates are matched by time, never by index, so the mouth
keeps to the speech (a 25 fps clip in a 24 fps scene skips one lipsync frame a second).
Keys are placed at the fractional frame where a lipsync frame or cue begins, with constant
interpolation; Blender evaluates them at whole frames, which gives exactly the rule above.
"""

from __future__ import annotations

import json
import math
import os
import re
import xml.etree.ElementTree as ET
from typing import List, NamedTuple, Optional, Sequence, Tuple

#: Keys sit this many frames before the exact time a frame or cue begins: a time that falls
#: on a whole frame (25 fps frame 25 in a 24 fps scene is frame 24.0) must count as reached
#: there, whatever the float rounding of ``k * scene_fps / fps`` (fcurves hold float32).
KEY_LEAD = 1e-3

FRAME_RE = re.compile(r"frame_(\d{6,})\.png\Z")
#: The Rhubarb shapes in their order: the default order of the integer a cue property takes.
RHUBARB_SHAPES = "ABCDEFGHX"
#: Largest JSON or cue file read (a wrong file must not be read whole): 64 MB.
MAX_BYTES = 64 << 20


class LipsyncFileError(ValueError):
    """A file lipsync did not write, or wrote differently; the message names it."""


class PngSequence(NamedTuple):
    """A PNG sequence: its folder, the frame numbers in order and their file names."""

    folder: str
    numbers: Tuple[int, ...]
    files: Tuple[str, ...]


class AtlasClip(NamedTuple):
    """An atlas (its JSON as a dict, with ``folder``) and a frames.json's fps and cells."""

    atlas: dict
    folder: str
    fps: float
    frames: Tuple[int, ...]
    duration: float


class Cues(NamedTuple):
    """Mouth cues: ``(start seconds, shape)`` in order, and the end of the last cue."""

    starts: Tuple[Tuple[float, str], ...]
    end: float


def scene_time(frame: float, *, frame_start: int, scene_fps: float) -> float:
    """The time in seconds Blender frame ``frame`` shows."""
    return (frame - frame_start) / scene_fps


def lipsync_frame(frame: float, *, frame_start: int, scene_fps: float, fps: float, count: int) -> int:
    """The lipsync frame (0-based) Blender frame ``frame`` shows: ``floor(t * fps)``, clamped.

    >>> lipsync_frame(1, frame_start=1, scene_fps=24, fps=24, count=10)
    0
    >>> [lipsync_frame(f, frame_start=1, scene_fps=24, fps=25, count=100) for f in (24, 25, 26)]
    [23, 25, 26]
    """
    t = scene_time(frame, frame_start=frame_start, scene_fps=scene_fps)
    k = math.floor(t * fps + KEY_LEAD * fps / scene_fps)
    return min(max(k, 0), count - 1)


def key_frame(seconds: float, *, frame_start: int, scene_fps: float) -> float:
    """The (fractional) Blender frame where something beginning at ``seconds`` is keyed."""
    return frame_start + seconds * scene_fps - KEY_LEAD


def _read_text(path: str) -> str:
    try:
        size = os.path.getsize(path)
        if size > MAX_BYTES:
            raise LipsyncFileError(f"{path}: {size} bytes is larger than any lipsync file ({MAX_BYTES})")
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise LipsyncFileError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    for enc in ("utf-8-sig", "utf-16"):
        try:
            return data.decode(enc)
        except UnicodeDecodeError:
            continue
    raise LipsyncFileError(f"{path}: not UTF-8 or UTF-16 text")


def _read_json(path: str) -> dict:
    try:
        doc = json.loads(_read_text(path))
    except json.JSONDecodeError as exc:
        raise LipsyncFileError(f"{path}: line {exc.lineno}: not JSON ({exc.msg})") from None
    if not isinstance(doc, dict):
        raise LipsyncFileError(f"{path}: a JSON {type(doc).__name__}, not an object")
    return doc


def png_sequence(path: str) -> PngSequence:
    """The lipsync PNG sequence in ``path`` (a folder, or any of its frames).

    Frames are ``frame_NNNNNN.png`` numbered from 0 without gaps, as ``lipsync render -o
    FOLDER/`` writes them; a gap would shift every later frame, so it is refused.
    """
    folder = path if os.path.isdir(path) else os.path.dirname(path)
    try:
        names = os.listdir(folder or ".")
    except OSError as exc:
        raise LipsyncFileError(f"{folder}: cannot list it ({exc.strerror or exc})") from None
    found = sorted((int(m.group(1)), n) for n in names if (m := FRAME_RE.match(n)))
    if not found:
        raise LipsyncFileError(f"{folder}: no lipsync frames here (frame_000000.png, ...: "
                               "`lipsync render ... -o FOLDER/`)")
    numbers = tuple(n for n, _ in found)
    for i, n in enumerate(numbers):
        if n != numbers[0] + i:
            raise LipsyncFileError(f"{folder}: frame {numbers[0] + i} is missing (the frames after it would "
                                   "show at the wrong time)")
    return PngSequence(os.path.abspath(folder), numbers, tuple(n for _, n in found))


def atlas_clip(frames_path: str) -> AtlasClip:
    """A ``frames.json`` (``lipsync cues --format atlas``) and the atlas it names."""
    doc = _read_json(frames_path)
    if doc.get("format") != "lipsync-atlas-frames":
        raise LipsyncFileError(f"{frames_path}: not a lipsync frames.json (format {doc.get('format')!r}; "
                               "`lipsync cues ... --format atlas --atlas ATLAS.json` writes one)")
    if int(doc.get("version", 0)) > 1:
        raise LipsyncFileError(f"{frames_path}: version {doc.get('version')} is newer than this add-on reads (1)")
    folder = os.path.dirname(os.path.abspath(frames_path))
    atlas_path = os.path.join(folder, str(doc.get("atlas", "")))
    atlas = _read_json(atlas_path)
    if atlas.get("format") != "lipsync-atlas" or int(atlas.get("version", 0)) > 1:
        raise LipsyncFileError(f"{atlas_path}: not a lipsync atlas of version 1 (`lipsync atlas` writes one)")
    cells = atlas.get("cells") or []
    frames = tuple(int(c) for c in doc.get("frames") or [])
    if not frames:
        raise LipsyncFileError(f"{frames_path}: no frames")
    bad = [i for i, c in enumerate(frames) if not 0 <= c < len(cells)]
    if bad:
        raise LipsyncFileError(f"{frames_path}: frame {bad[0]} names cell {frames[bad[0]]}, the atlas has "
                               f"{len(cells)}")
    fps = float(doc.get("fps") or 0)
    if not fps > 0:
        raise LipsyncFileError(f"{frames_path}: no fps")
    return AtlasClip(atlas, os.path.dirname(atlas_path), fps, frames,
                     float(doc.get("duration") or len(frames) / fps))


# ---- cues -----------------------------------------------------------------------------------

def _cue_list(path: str, rows: Sequence[Tuple[float, float, str]], end: Optional[float]) -> Cues:
    rows = sorted(rows, key=lambda r: r[0])
    if not rows:
        raise LipsyncFileError(f"{path}: no mouth cues")
    for (a, _, _), (b, _, _) in zip(rows, rows[1:]):
        if b < a:
            raise LipsyncFileError(f"{path}: cues out of order at {b:.3f} s")
    last = max(r[1] for r in rows)
    return Cues(tuple((a, v) for a, _, v in rows), end if end is not None else last)


def _num(path: str, line: int, text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise LipsyncFileError(f"{path}: line {line}: {text!r} is not a time in seconds") from None
    if not math.isfinite(x) or x < 0:
        raise LipsyncFileError(f"{path}: line {line}: time {text!r} is out of range")
    return x


def _tsv(path: str, text: str) -> Cues:
    # Rhubarb TSV: "start<TAB>shape", the last line the end with X.
    rows: List[Tuple[float, str]] = []
    for i, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        parts = line.split("\t")
        if len(parts) != 2:
            raise LipsyncFileError(f"{path}: line {i}: expected 'start<TAB>shape' (Rhubarb TSV)")
        rows.append((_num(path, i, parts[0]), parts[1].strip()))
    if not rows:
        raise LipsyncFileError(f"{path}: no mouth cues")
    end = rows[-1][0] if len(rows) > 1 else None
    body = rows[:-1] if len(rows) > 1 else rows
    spans = [(a, (body[j + 1][0] if j + 1 < len(body) else end or a), v) for j, (a, v) in enumerate(body)]
    return _cue_list(path, spans, end)


def _audacity(path: str, text: str) -> Cues:
    rows = []
    for i, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.startswith("\\"):  # "\" lines: spectral selections
            continue
        parts = line.split("\t")
        if len(parts) != 3:
            raise LipsyncFileError(f"{path}: line {i}: expected 'start<TAB>end<TAB>label' (Audacity labels)")
        rows.append((_num(path, i, parts[0]), _num(path, i, parts[1]), parts[2].strip()))
    return _cue_list(path, rows, None)


def _rhubarb_json(path: str, text: str) -> Cues:
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise LipsyncFileError(f"{path}: line {exc.lineno}: not JSON ({exc.msg})") from None
    cues = doc.get("mouthCues") if isinstance(doc, dict) else None
    if not isinstance(cues, list):
        raise LipsyncFileError(f"{path}: no 'mouthCues' list (Rhubarb JSON)")
    try:
        rows = [(float(c["start"]), float(c["end"]), str(c["value"])) for c in cues]
    except (KeyError, TypeError, ValueError):
        raise LipsyncFileError(f"{path}: a mouth cue without start, end and value") from None
    duration = (doc.get("metadata") or {}).get("duration")
    return _cue_list(path, rows, float(duration) if duration is not None else None)


def _rhubarb_xml(path: str, text: str) -> Cues:
    try:
        root = ET.fromstring(text.encode("utf-8"))
    except ET.ParseError as exc:
        raise LipsyncFileError(f"{path}: line {exc.position[0]}: not XML") from None
    rows = []
    for cue in root.iter("mouthCue"):
        try:
            rows.append((float(cue.get("start")), float(cue.get("end")), (cue.text or "").strip()))
        except (TypeError, ValueError):
            raise LipsyncFileError(f"{path}: a mouthCue without start and end") from None
    duration = root.findtext("metadata/duration")
    return _cue_list(path, rows, float(duration) if duration else None)


_TG_TIER = re.compile(r'class\s*=\s*"IntervalTier"\s*name\s*=\s*"([^"]*)"(.*?)(?=class\s*=|\Z)', re.S)
_TG_INTERVAL = re.compile(r'xmin\s*=\s*([-\d.eE+]+)\s*xmax\s*=\s*([-\d.eE+]+)\s*text\s*=\s*"((?:[^"]|"")*)"')


def _textgrid(path: str, text: str) -> Cues:
    # Praat's long text form as `lipsync cues -o x.TextGrid` writes it: tier "visemes", else the first.
    tiers = [(m.group(1), m.group(2)) for m in _TG_TIER.finditer(text)]
    if not tiers:
        raise LipsyncFileError(f"{path}: no interval tier (a long-form Praat TextGrid)")
    name, body = next((t for t in tiers if t[0] == "visemes"), tiers[0])
    rows = [(float(a), float(b), v.replace('""', '"').strip()) for a, b, v in _TG_INTERVAL.findall(body)]
    return _cue_list(path, [r for r in rows if r[2]] or rows, max(r[1] for r in rows) if rows else None)


def _moho(path: str, text: str, fps: float) -> Cues:
    # MohoSwitch1, then "frame name" at the export's fps, 1-based; the last key is the end.
    lines = text.splitlines()
    if not lines or lines[0].strip() != "MohoSwitch1":
        raise LipsyncFileError(f"{path}: line 1: not 'MohoSwitch1' (a Moho switch file)")
    keys = []
    for i, line in enumerate(lines[1:], 2):
        if not line.strip():
            continue
        parts = line.split()
        if len(parts) != 2 or not parts[0].isdigit() or int(parts[0]) < 1:
            raise LipsyncFileError(f"{path}: line {i}: expected 'frame name' with frames from 1")
        keys.append(((int(parts[0]) - 1) / fps, parts[1]))
    spans = [(a, keys[j + 1][0] if j + 1 < len(keys) else a, v) for j, (a, v) in enumerate(keys)]
    return _cue_list(path, spans, None)


def read_cues(path: str, *, moho_fps: float = 24.0) -> Cues:
    """Mouth cues from any file ``lipsync cues`` writes (and Rhubarb's own output).

    Rhubarb TSV (``.tsv``), JSON (``.json``), XML (``.xml``), Praat TextGrid (the
    ``visemes`` tier, ``.TextGrid``), Audacity labels (``.txt``) and Moho switch files
    (``.dat``, frames at ``moho_fps``), chosen by the extension.
    """
    ext = os.path.splitext(path)[1].lower()
    readers = {".tsv": _tsv, ".json": _rhubarb_json, ".xml": _rhubarb_xml, ".textgrid": _textgrid,
               ".txt": _audacity, ".dat": lambda p, text: _moho(p, text, moho_fps)}
    if ext not in readers:
        raise LipsyncFileError(f"{path}: unknown cue file type {ext or '(no extension)'} (.tsv, .json, .xml, "
                               ".TextGrid, .txt, .dat: the files `lipsync cues` writes)")
    return readers[ext](path, _read_text(path))


def cue_at(cues: Cues, seconds: float) -> str:
    """The shape shown at ``seconds``: the last cue starting at or before it (the first before any)."""
    shown = cues.starts[0][1]
    for start, shape in cues.starts:
        if start > seconds:
            break
        shown = shape
    return shown
