"""Stage 1 of a batch: read a manifest and check every row before anything runs.

A manifest lists one clip per row, as CSV with a header or as JSON lines (one object per
line). Fields (:data:`FIELDS`): ``input`` and ``output`` are required; ``bank``, ``text``,
``audio``, ``fps``, ``map``, ``timing`` and ``method`` are optional (an empty CSV cell is
the default). Relative paths are relative to the manifest's folder; ``output`` is a name
under the output folder and may not leave it.

Every row is checked (files exist, names are known, banks and map files load) and all the
problems are reported together, each with its line number, as one :class:`ManifestError`.
A timeline's *content* is not read here: reading may mean aligning audio, which is the
work the cluster is for, so a bad timeline fails its own clip and the others go on.
"""

from __future__ import annotations

import csv
import io
import json
import os
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Dict, List, Optional, Tuple, Union

from .._files import read_input_bytes, refuse_output_over_input
from ..errors import InputError
from ..motion.frames import DEFAULT_FPS

PathLike = Union[str, "os.PathLike[str]"]

#: The fields a row may have, and why each is there.
FIELDS = {
    "input": "timeline file in any format a reader takes (audio too, where a reader takes it, with text)",
    "output": "file name under OUTDIR (.mp4, .mkv, .webm, .mov, .webp, .gif); subfolders allowed",
    "bank": "viseme bank folder, or a shipped subject's name (toon, grid-s1; default: the toon)",
    "text": "transcript for audio input: the text itself, or a file holding it",
    "audio": "speech to mux into the video",
    "fps": f"frames per second (default: {DEFAULT_FPS:g})",
    "map": "phoneme map: a shipped name or a YAML file",
    "timing": "timing name: a transition curve or dominance (default: the bank's, else sqrt-fast-middle)",
    "method": "in-between method name",
}
REQUIRED = ("input", "output")
#: A manifest past this size is not a list of clips (1 M rows of ~100 bytes fit with room).
MAX_MANIFEST_BYTES = 256 << 20
#: Beside each output, what it was made from (see :mod:`lipsync.batch.sidecar`).
SIDECAR_SUFFIX = ".lipsync.json"


class ManifestError(InputError):
    """Rows of a manifest that cannot run, each with its line number.

    Attributes
    ----------
    problems : list of (int, str)
        ``(line, message)`` for every bad row, in file order.
    """

    def __init__(self, path: PathLike, problems: List[Tuple[Optional[int], str]]):
        self.problems = list(problems)
        first_line = self.problems[0][0] if self.problems else None
        super().__init__(self.problems[0][1] if self.problems else "bad manifest", path=path, line=first_line)
        where = os.fspath(path)
        self._text = "\n".join(f"{where}:{line}: {msg}" if line is not None else f"{where}: {msg}"
                               for line, msg in self.problems)

    def __str__(self) -> str:
        return self._text


@dataclass(frozen=True)
class ClipJob:
    """One checked manifest row, paths resolved.

    Attributes
    ----------
    line : int
        Its line in the manifest (1-based; the header is line 1 of a CSV).
    input : Path
        The timeline (or audio) file.
    output : str
        The output's name under OUTDIR, POSIX separators, normalised.
    bank : Path
        The bank folder.
    text : str or None
        Transcript text given literally.
    text_file : Path or None
        Transcript file (when ``text`` named an existing file).
    audio : Path or None
        Audio to mux.
    fps : float
    map : str
        A shipped map name, or (when ``map_file`` is set) the name as written.
    map_file : Path or None
        A map YAML file.
    timing, method : str
    """

    line: int
    input: Path
    output: str
    bank: Path
    text: Optional[str] = None
    text_file: Optional[Path] = None
    audio: Optional[Path] = None
    fps: float = DEFAULT_FPS
    map: str = ""
    map_file: Optional[Path] = None
    timing: str = ""
    method: str = "flow"


def _rows(path: Path, text: str) -> List[Tuple[int, Dict[str, object]]]:
    """(line, raw row) pairs from CSV or JSON lines; format from the extension, then content."""
    ext = path.suffix.lower()
    stripped = text.lstrip()
    is_json = ext in (".jsonl", ".ndjson", ".json") or (ext != ".csv" and stripped.startswith("{"))
    problems: List[Tuple[Optional[int], str]] = []
    rows: List[Tuple[int, Dict[str, object]]] = []
    if is_json:
        for n, raw in enumerate(text.splitlines(), 1):
            if not raw.strip():
                continue
            try:
                obj = json.loads(raw)
            except (ValueError, RecursionError) as exc:
                problems.append((n, f"not a JSON object: {str(exc)[:80]}"))
                continue
            if not isinstance(obj, dict):
                problems.append((n, f"expected a JSON object per line, got {type(obj).__name__}"))
                continue
            rows.append((n, obj))
    else:
        reader = csv.reader(io.StringIO(text, newline=""))
        try:
            header = next(reader, None)
            if header is None:
                raise ManifestError(path, [(1, "empty manifest")])
            header = [h.strip() for h in header]
            unknown = [h for h in header if h not in FIELDS]
            if unknown:
                raise ManifestError(path, [(1, f"unknown column {unknown[0]!r}; valid: {', '.join(FIELDS)}")])
            missing = [f for f in REQUIRED if f not in header]
            if missing:
                raise ManifestError(path, [(1, f"header lacks the {missing[0]!r} column "
                                               f"(a CSV manifest starts with a header row)")])
            start = reader.line_num + 1
            for cells in reader:
                n, start = start, reader.line_num + 1
                if not any(c.strip() for c in cells):
                    continue
                if len(cells) != len(header):
                    problems.append((n, f"{len(cells)} cells but the header has {len(header)} columns"))
                    continue
                rows.append((n, {h: c for h, c in zip(header, cells) if c.strip() != ""}))
        except csv.Error as exc:
            problems.append((reader.line_num, f"CSV: {exc}"))
    if problems:
        raise ManifestError(path, problems)
    if not rows:
        raise ManifestError(path, [(1, "no clips in the manifest")])
    return rows


def output_name(name: str) -> str:
    """``name`` normalised as a relative POSIX path inside OUTDIR; ValueError if it escapes.

    Examples
    --------
    >>> output_name("a/./b.mp4"), output_name("a\\\\b.mp4")
    ('a/b.mp4', 'a/b.mp4')
    >>> output_name("../x.mp4")
    Traceback (most recent call last):
    ...
    ValueError: output '../x.mp4' leaves OUTDIR (names are relative, without '..')
    """
    text = name.strip().replace("\\", "/")
    p = PurePosixPath(text)
    if (not text or p.is_absolute() or ".." in p.parts or (len(text) > 1 and text[1] == ":")
            or "\0" in text):
        raise ValueError(f"output {name!r} leaves OUTDIR (names are relative, without '..')")
    norm = str(p)
    if norm in (".", ""):
        raise ValueError(f"output {name!r} is not a file name")
    return norm


def read_manifest(path: PathLike, outdir: Optional[PathLike] = None) -> List[ClipJob]:
    """Read and check a manifest; every bad row is reported (with its line) in one error.

    Parameters
    ----------
    path : path-like
        The manifest (CSV with a header, or JSON lines).
    outdir : path-like, optional
        The output folder: outputs that would land outside it through a symbolic link
        already in it are refused too.

    Returns
    -------
    list of ClipJob
        In manifest order.

    Raises
    ------
    ManifestError
        Listing ``manifest:line: problem`` for every bad row.

    Examples
    --------
    >>> import os, tempfile
    >>> d = tempfile.mkdtemp()
    >>> _ = open(os.path.join(d, "a.tsv"), "w").write("0.00\\tX\\n0.40\\tD\\n0.80\\tX\\n")
    >>> _ = open(os.path.join(d, "clips.csv"), "w").write("input,output,fps\\na.tsv,one.mp4,30\\n")
    >>> [(j.line, j.input.name, j.output, j.fps) for j in read_manifest(os.path.join(d, "clips.csv"))]
    [(2, 'a.tsv', 'one.mp4', 30.0)]
    """
    from .._data import default_bank_dir, shipped_banks
    from ..banks.bank import Bank
    from ..encode import format_for
    from ..phonetics.phonemes import DEFAULT_MAP, MAPS, load_map
    from ..morphing.render import METHODS
    from ..motion.sequencer import check_fps
    from ..motion.timing import CURVES, MODELS, timing_names

    path = Path(path)
    data = read_input_bytes(path, "a manifest", limit=MAX_MANIFEST_BYTES, missing="no such manifest")
    if len(data) > MAX_MANIFEST_BYTES:
        size = path.stat().st_size
        raise ManifestError(path, [(None, f"{size} bytes; a manifest is at most {MAX_MANIFEST_BYTES}")])
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start})", path=path) from None
    base = path.resolve().parent
    out_real = Path(outdir).resolve() if outdir is not None else None
    rows = _rows(path, text)

    problems: List[Tuple[Optional[int], str]] = []
    jobs: List[ClipJob] = []
    seen_outputs: Dict[str, int] = {}
    bank_ok: Dict[Path, Optional[str]] = {}   # bank folder -> None or its error
    map_ok: Dict[Path, Optional[str]] = {}

    def local(value: str) -> Path:
        p = Path(os.path.expanduser(value))
        return p if p.is_absolute() else base / p

    for line, row in rows:
        errs: List[str] = []

        def field(name: str) -> Optional[str]:
            v = row.get(name)
            if v is None:
                return None
            if isinstance(v, bool) or not isinstance(v, (str, int, float)):
                errs.append(f"{name}: expected text or a number, got {type(v).__name__}")
                return None
            v = str(v).strip()
            return v or None

        unknown = [k for k in row if k not in FIELDS]
        if unknown:
            errs.append(f"unknown field {unknown[0]!r}; valid: {', '.join(FIELDS)}")
        for name in REQUIRED:
            if field(name) is None:
                errs.append(f"missing {name!r}")
        def existing_file(name: str) -> Optional[Path]:
            value = field(name)
            if value is None:
                return None
            if not local(value).is_file():
                errs.append(f"{name} {value!r}: no such file")
            return local(value)

        input_path = existing_file("input")
        out = field("output")
        out_name = None
        if out is not None:
            try:
                out_name = output_name(out)
                if out_name.endswith(SIDECAR_SUFFIX):
                    raise ValueError(f"output {out!r} ends with {SIDECAR_SUFFIX}, the sidecar suffix")
                if format_for(out_name) == "png":  # one file per clip: every format but a PNG folder
                    raise ValueError(f"output {out!r}: batch writes video files (.mp4, .mkv, .webm, .mov, "
                                     f".webp, .gif)")
                if out_real is not None:
                    real = (out_real / out_name).resolve()
                    if out_real not in real.parents:
                        raise ValueError(f"output {out!r} leads outside OUTDIR through a symbolic link")
                if out_name in seen_outputs:
                    raise ValueError(f"output {out!r} is also written by line {seen_outputs[out_name]}")
                seen_outputs[out_name] = line
            except InputError as exc:
                errs.append(f"output {out!r}: {exc}")
                out_name = None
            except ValueError as exc:
                errs.append(str(exc))
                out_name = None

        bank_field = field("bank")
        bank_dir = local(bank_field) if bank_field else default_bank_dir()
        if bank_field and not bank_dir.exists() and bank_field in shipped_banks():  # a shipped subject's name
            bank_dir = shipped_banks()[bank_field]
        if bank_dir not in bank_ok:
            try:
                Bank.load(bank_dir)
                bank_ok[bank_dir] = None
            except InputError as exc:
                bank_ok[bank_dir] = str(exc)
        if bank_ok[bank_dir] is not None:
            errs.append(f"bank {bank_field!r}: {bank_ok[bank_dir]}")

        text_value = field("text")
        text_file = None
        if text_value is not None and local(text_value).is_file():
            text_file, text_value = local(text_value), None
        audio_path = existing_file("audio")

        fps = DEFAULT_FPS
        if field("fps") is not None:
            try:
                fps = check_fps(field("fps"))
            except InputError as exc:
                errs.append(f"fps: {exc}")
        map_value = field("map") or DEFAULT_MAP
        map_file = None
        if map_value not in MAPS:
            candidate = local(map_value)
            if not candidate.is_file():
                errs.append(f"map {map_value!r}: neither a shipped map ({', '.join(MAPS.names())}) nor a file")
            else:
                if candidate not in map_ok:
                    try:
                        load_map(candidate)
                        map_ok[candidate] = None
                    except InputError as exc:
                        map_ok[candidate] = str(exc)
                if map_ok[candidate] is not None:
                    errs.append(f"map {map_value!r}: {map_ok[candidate]}")
                map_file = candidate
        timing = field("timing") or ""   # empty: the bank's timing (bank.yaml), else the default curve
        if timing and not (timing in CURVES or timing in MODELS):
            errs.append(f"timing {timing!r}: unknown; valid: {', '.join(timing_names())}")
        method = field("method") or "flow"
        if method not in METHODS:
            errs.append(f"method {method!r}: unknown; valid: {', '.join(METHODS.names())}")

        if out_name is not None and out_real is not None:
            try:   # issue 38: an output never replaces one of its row's inputs (by inode: links too)
                refuse_output_over_input([out_real / out_name], [input_path, audio_path, text_file, map_file, path])
            except InputError as exc:
                errs.append(f"output {out!r}: {str(exc).split(': ', 1)[-1]}")
        if errs:
            problems.extend((line, e) for e in errs)
            continue
        jobs.append(ClipJob(line=line, input=input_path, output=out_name, bank=bank_dir.resolve(),
                            text=text_value, text_file=text_file, audio=audio_path, fps=fps,
                            map=map_value, map_file=map_file, timing=timing, method=method))
    if problems:
        raise ManifestError(path, problems)
    return jobs
