"""``make_bank``: the steps of ``lipsync init OUTDIR --video VIDEO ...`` in order.

::

    sources (probe, transcripts) -> speech (align, map) -> faces (track) -> stabilise
    (reference pose, per-frame similarity) -> select (candidates, ranking, finalists)
    -> framing (crop, scale) -> cut (decode again, warp finalists) -> sharpness, choice
    -> colour (exposure, white balance) -> lines (face_features) -> write (PNGs, bank.yaml,
    report, preview, flows) in a staging folder -> renamed into place
"""

from __future__ import annotations

import os
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence

import numpy as np

from ..errors import InputError, PathLike
from .config import VideoBankConfig
from .select import Candidate


@dataclass(frozen=True)
class VideoBankResult:
    """What :func:`make_bank` made.

    Attributes
    ----------
    path : Path
        The bank folder.
    chosen : dict
        Viseme → the :class:`~lipsync.videobank.select.Candidate` frame its picture shows.
    missing : dict
        Viseme the videos never showed → the viseme whose picture it borrowed.
    size : (int, int)
        ``(W, H)`` of the pictures.
    symmetric : bool
        Whether the bank uses ``symmetry: true``.
    seconds : dict
        Wall time per step.
    report : dict
        What was written to ``init-report.json``.
    """

    path: Path
    chosen: Dict[str, Candidate]
    missing: Dict[str, str]
    size: tuple
    symmetric: bool
    seconds: Dict[str, float] = field(default_factory=dict)
    report: dict = field(default_factory=dict)

    def summary(self) -> str:
        w, h = self.size
        total = sum(self.seconds.values())
        text = (f"wrote {self.path}: {len(self.chosen) + len(self.missing)} visemes, {w}x{h}, "
                f"symmetry {'on' if self.symmetric else 'off'}, in {total:.1f} s")
        if self.missing:
            text += "; borrowed: " + ", ".join(f"{v} <- {u}" for v, u in self.missing.items())
        return text


def _viseme_order(pmap) -> List[str]:
    """The map's visemes in its naming system's order (the toon's A..H, X), else sorted, rest last."""
    from ..banks.names import SYSTEMS

    names = pmap.visemes()
    for table in SYSTEMS.values():
        if all(v in table for v in names):
            return [v for v in table if v in names]
    return sorted(v for v in names if v != pmap.silence) + [pmap.silence]


def _what_to_record(visemes: Sequence[str], pmap) -> str:
    """``"G (F V), H (L)"``: each viseme with the sounds that show it."""
    parts = []
    for v in visemes:
        phones = sorted(p for p, t in pmap.map.items() if v in ([t] if isinstance(t, str) else t))
        parts.append(f"{v} ({' '.join(phones)})" if phones else v)
    return ", ".join(parts)


def make_bank(outdir: PathLike, videos: Sequence[PathLike], *, text: Optional[str] = None,
              texts: Optional[Mapping[PathLike, str]] = None, config: Optional[VideoBankConfig] = None,
              **options) -> VideoBankResult:
    """Make a viseme bank of the speaker in ``videos`` (``lipsync init OUTDIR --video ...``).

    Parameters
    ----------
    outdir : path-like
        The bank folder to make (absent or empty, or anything with ``force``).
    videos : sequence of path-like
        Videos of one speaker talking, with sound (any container ffmpeg reads).
    text : str, optional
        The transcript of a single video (or a file holding it).
    texts : mapping, optional
        Video → transcript, for several videos (else ``NAME.txt``/``NAME.lab`` beside each,
        else the words are recognised).
    config : VideoBankConfig, optional
        The options; or give them as keywords (``map=``, ``size=``, ``force=``, ``quiet=``,
        ``jobs=``, ``flows=``).

    Returns
    -------
    VideoBankResult

    Raises
    ------
    lipsync.errors.InputError
        A non-empty ``outdir`` without ``force``; a video that is missing, unreadable or
        has no sound; no face in a video; no silence to take the rest shape from.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> out = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (out / "notes.txt").write_text("mine")
    >>> make_bank(out, ["talk.mp4"])      # checked before any work is done
    Traceback (most recent call last):
    ...
    lipsync.errors.InputError: ...: is not empty; use --force to replace what is there with the new bank

    With the three GRID clips in ``tests/data/grid-s1`` (about 10 s on two cores)::

        from lipsync.bench.grid import grid_dir, transcript
        clips = [grid_dir() / f"{c}.mpg" for c in ("bbwm5s", "lwae8n", "prap6p")]
        r = make_bank("me", clips, texts={p: transcript(p.stem) for p in clips})
        print(r.summary())
    """
    from tqdm import tqdm

    from ..bank import Bank
    from ..face.compare import mouth_box
    from ..face.lines import SYMMETRIC_BELOW, face_asymmetry, face_features
    from ..face.landmarks import FaceMesh
    from ..face.track import track_frames
    from ..face.video import read_video
    from ..phonemes import load_map
    from . import colour, select, stabilise, write
    from .cut import RAW_BUDGET_BYTES, grab_frames, warp_frame
    from .sources import find_sources
    from .speech import transcribe

    cfg = config or VideoBankConfig(**options)
    if config is not None and options:
        raise TypeError("give either config or keyword options, not both")
    outdir = Path(os.fspath(outdir))
    write.check_outdir(outdir, cfg.force)
    seconds: Dict[str, float] = {}

    def lap(name: str, t0: float) -> float:
        t = time.perf_counter()
        seconds[name] = seconds.get(name, 0.0) + t - t0
        return t

    t = time.perf_counter()
    pmap = load_map(cfg.map)
    rest = pmap.silence
    order = _viseme_order(pmap)
    sources = find_sources(videos, text, texts=texts)
    names = ", ".join(s.name for s in sources)
    t = lap("probe", t)

    speeches, tracks = [], []
    mesh = FaceMesh()  # the models loaded once for every video
    # one bar over every video's frames: each is aligned (its sound, ~1/3 of the time) and tracked
    total = sum(max(s.info.frame_count, 1) for s in sources)
    with tqdm(total=2 * total, desc="speech and faces", unit="frame", disable=cfg.quiet, leave=False) as bar:
        for s in sources:
            bar.set_postfix_str(s.name)
            speeches.append(transcribe(s, pmap, quiet=True, jobs=cfg.jobs))
            bar.update(max(s.info.frame_count, 1))
            t = lap("align", t)
            tracks.append(track_frames(read_video(s.path, info=s.info), fps=s.info.fps, size=s.info.size,
                                       source=str(s.path), mesh=mesh, progress=bar.update))
            t = lap("track", t)

    # --- stabilise: one reference pose for all videos
    ref = stabilise.reference_pose([tr.points[tr.found][:, stabilise._STILL] for tr in tracks])
    regs = [stabilise.register_track(tr.points, tr.found, ref) for tr in tracks]

    # --- select: candidates and their ranking
    measures = [select.FrameMeasures.of(tr.points, tr.fps, reg.residual) for tr, reg in zip(tracks, regs)]
    cands: List[Candidate] = []
    for i, (sp, tr) in enumerate(zip(speeches, tracks)):
        cands += select.candidates(sp.visemes, video=i, fps=tr.fps, found=tr.found, rest=rest)
    ranked = select.rank(cands, measures)
    if rest not in ranked:
        raise InputError(f"no silence to take the rest shape ({rest}) from: leave a second of silence, mouth "
                         f"closed and relaxed, before or after speaking", path=names)
    finalists = {v: r[:select.FINALISTS] for v, r in ranked.items()}
    t = lap("select", t)

    # --- framing, cut and sharpness: the finalists in a crop they all fill, at the bank's scale
    flat = [c for fs in finalists.values() for c in fs]
    scale = float(np.median([1.0 / abs(regs[c.video].c[c.frame]) for c in flat]))

    def framing_for(cands: List[Candidate]) -> "stabilise.Framing":
        return stabilise.framing([(regs[c.video], c.frame, sources[c.video].info.size) for c in cands],
                                 [regs[c.video].to_unit(c.frame, tracks[c.video].points[c.frame]) for c in cands],
                                 source_scale=scale, size=cfg.size, max_side=cfg.max_side)

    def out_points(fr, c: Candidate) -> np.ndarray:
        return fr.points(regs[c.video], c.frame, tracks[c.video].points[c.frame])

    frame = framing_for(flat)
    w, h = frame.size
    keep_raw = sum(int(np.prod(sources[c.video].info.size)) * 3 for c in flat) <= RAW_BUDGET_BYTES
    raw: Dict[tuple, np.ndarray] = {}
    pictures: Dict[tuple, np.ndarray] = {}
    for i, s in enumerate(sources):
        wanted = sorted({c.frame for c in flat if c.video == i})
        if not wanted:
            continue
        for f, img in grab_frames(s.path, wanted).items():
            if keep_raw:
                raw[(i, f)] = img
            pictures[(i, f)] = warp_frame(img, frame.matrix(regs[i], f), (w, h))
    chosen: Dict[str, Candidate] = {}
    for v, fs in finalists.items():
        sharp = [select.sharpness(pictures[(c.video, c.frame)], mouth_box(out_points(frame, c), (h, w))) for c in fs]
        chosen[v] = select.with_sharpness(fs, sharp)[0]

    # --- the final crop: as much room as the chosen frames' pictures give (more of the neck
    # and shoulders for the template's anchors than the finalists all had)
    picked = list({(c.video, c.frame): c for c in chosen.values()}.values())
    final = framing_for(picked)
    if final != frame:
        frame = final
        w, h = frame.size
        for i, s in enumerate(sources):
            wanted = sorted({c.frame for c in picked if c.video == i})
            got = {f: raw[(i, f)] for f in wanted} if keep_raw else grab_frames(s.path, wanted) if wanted else {}
            for f, img in got.items():
                pictures[(i, f)] = warp_frame(img, frame.matrix(regs[i], f), (w, h))
    raw.clear()
    if frame.cut:
        warnings.warn(f"{names}: the picture cuts the head at the {' and '.join(frame.cut)} (keep the whole head "
                      f"and the neck in view, with some room around them); the bank is cropped tighter",
                      UserWarning, stacklevel=2)
    points_out = {(c.video, c.frame): out_points(frame, c) for c in picked}
    t = lap("cut", t)

    # --- visemes never shown: the nearest shape shown
    shown = [v for v in order if v in chosen]
    missing = {v: select.nearest_available(v, shown, fallback=pmap.fallback) for v in order if v not in chosen}
    if missing:
        warnings.warn(f"{names}: never shows {_what_to_record(list(missing), pmap)}; using the closest shape "
                      f"shown ({', '.join(f'{v} <- {u}' for v, u in missing.items())}). Record these sounds too "
                      f"(reading samples/record-script.txt aloud shows every shape)", UserWarning, stacklevel=2)
    source_of = {v: chosen[v] if v in chosen else chosen[missing[v]] for v in order}

    # --- colour: the chosen pictures matched on the still skin
    keys = list(dict.fromkeys((c.video, c.frame) for c in chosen.values()))
    masks = {k: colour.still_skin_mask(points_out[k], (h, w)) for k in keys}
    matched, gains = colour.match_colour({k: pictures[k] for k in keys}, masks, where=names)

    # --- lines from each picture's face
    pts = {v: points_out[(c.video, c.frame)] for v, c in source_of.items()}
    asym = face_asymmetry(list(pts.values()))
    symmetric = asym < SYMMETRIC_BELOW
    features = face_features(pts, (h, w), axis=frame.axis)
    t = lap("choose", t)

    files = write.image_names(order)
    report = {
        "made_by": "lipsync init --video",
        "map": pmap.name,
        "rest": rest,
        "size": [w, h],
        "pixels_per_eye_distance": round(frame.scale, 3),
        "symmetry": symmetric,
        "asymmetry": round(asym, 4),
        "cropped_short": list(frame.cut),
        "videos": [{
            "video": s.name, "fps": s.info.fps, "frames": len(tr), "size": list(s.info.size),
            "transcript": s.text_from, "words": list(sp.words), "recognised": sp.recognised,
            "confidence": None if sp.confidence is None else round(sp.confidence, 3),
            "face_found": round(float(tr.found.mean()), 4),
            "residual_median": round(float(np.nanmedian(reg.residual)), 4),
        } for s, sp, tr, reg in zip(sources, speeches, tracks, regs)],
        "visemes": {},
        "missing": {v: {"uses": u, "record": _what_to_record([v], pmap)} for v, u in missing.items()},
    }
    for v in order:
        c = source_of[v]
        report["visemes"][v] = dict(image=files[v], video=sources[c.video].name, **c.report(),
                                    candidates=len(ranked.get(v, [])), borrowed_from=missing.get(v),
                                    colour_gain=list(gains[(c.video, c.frame)]))

    header = [f"# Written by lipsync init --video from {len(sources)} video(s) ({names[:200]}): one frame "
              f"per viseme, lines placed from the face; the choice is in {write.REPORT_NAME}."]
    with write.Staging(outdir, force=cfg.force) as tmp:
        images = {}
        for v in order:
            c = source_of[v]
            if files[v] not in images:
                images[files[v]] = matched[(c.video, c.frame)]
                write.write_png(tmp / files[v], images[files[v]])
        text_yaml = write.bank_text(outdir.resolve().name, rest, files, features, symmetric=symmetric, header=header)
        Bank.from_text(text_yaml, tmp, images=images)  # never write a bank that would not load
        from ..banks.yamlio import write_bank_text

        write_bank_text(tmp / "bank.yaml", text_yaml)
        bank = Bank.load(tmp)
        write.write_preview(tmp / write.PREVIEW_NAME, bank)
        t = lap("write", t)
        if cfg.flows:
            from ..preprocess import preprocess

            preprocess(bank, jobs=cfg.jobs, quiet=cfg.quiet)
            t = lap("flows", t)
        report["seconds"] = {k: round(x, 2) for k, x in seconds.items()}
        write.write_report(tmp / write.REPORT_NAME, report)
    return VideoBankResult(path=outdir, chosen=chosen, missing=missing, size=(w, h), symmetric=symmetric,
                           seconds=seconds, report=report)
