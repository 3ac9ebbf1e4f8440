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
from . import select, stabilise
from .config import VideoBankConfig
from .select import Candidate
from .sources import Source
from .speech import Speech


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


@dataclass(frozen=True)
class Footage:
    """What the videos show, per video: the source, its speech, its face track, and each
    frame's mapping onto the reference pose."""

    sources: List[Source]
    speeches: List[Speech]
    tracks: list
    regs: List["stabilise.Registration"]

    @property
    def names(self) -> str:
        return ", ".join(s.name for s in self.sources)


@dataclass(frozen=True)
class Pictures:
    """The chosen frames cut out at the bank's framing."""

    chosen: Dict[str, Candidate]
    framing: "stabilise.Framing"
    images: Dict[tuple, np.ndarray]   # (video, frame) -> RGB picture
    points: Dict[tuple, np.ndarray]   # (video, frame) -> mesh in the picture's pixels
    plate: Optional[tuple] = None     # (video, frame) of the plate every picture shares (one face)


#: How a real face's mouth moves when a render does not say (bank.yaml ``timing``): the
#: coarticulation model (issue 21), measured closer to real lips than the rule-based
#: sequencer on GRID s1's held-out sentences, rendered with a bank from this function
#: (``python -m lipsync.bench --only coarticulation_rendered``). Its default constants:
#: fitting them to the speaker (lipsync.motion.coarticulation.fit_speaker) measured no better there.
TIMING = "dominance"

#: Median stabilisation residual (eye distances) of the chosen frames above which the head
#: moved too much between them: GRID s1's chosen frames measure 0.003-0.017 (median 0.006);
#: a webcam speaker looking down at a keyboard now and then (tools/other_face.py, Debian's
#: movie-hello.mp4) median 0.07, and the rendered eyes then step by 0.1 eye distances a frame
#: (p95; GRID 0.01); kphotoalbum's demo clip of a speaker facing the camera, no warning. This
#: is the residual select.RESIDUAL_SCALE prices as one typical spread of mouth shapes (the
#: head turned about 3 degrees).
MOVED_RESIDUAL = 0.03
#: The viseme pictures' resample (cv2 flag) from the video: bilinear, as they were always cut,
#: so that ``--samples off`` renders a bank as before (the one-picture morph is the baseline
#: the mouth samples are measured against, and it resamples its pictures at every frame
#: anyway). The plate and the samples keep the footage's pixels (lipsync.videobank.cut).
PICTURE_INTERPOLATION = 1  # cv2.INTER_LINEAR (cv2 is imported only where frames are cut)


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
              tracks: Optional[Mapping[PathLike, object]] = None, **options) -> VideoBankResult:
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
    tracks : mapping, optional
        Video → its :class:`~lipsync.face.track.FaceTrack`, when the caller has tracked it
        already (``lipsync dub`` has): not tracked again.

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
    >>> make_bank(out, ["talk.mp4"], force=True)      # checked before any work is done
    Traceback (most recent call last):
    ...
    lipsync.errors.InputError: ...: is not empty and is not a bank (no bank.yaml); --force replaces only a bank: give a new or empty folder

    With the three GRID clips in ``tests/data/grid-s1`` (about 10 s on two cores)::

        from lipsync.bench.grid import grid_dir, transcript
        clips = [grid_dir() / f"{c}.mpg" for c in ("bbwm5s", "lwae8n", "prap6p")]
        r = make_bank("me", clips, texts={p: transcript(p.stem) for p in clips})
        print(r.summary())
    """
    cfg = config or VideoBankConfig(**options)
    if config is not None and options:
        raise TypeError("give either config or keyword options, not both")
    outdir = Path(os.fspath(outdir))
    from . import write
    from ..phonetics.phonemes import load_map
    from .sources import find_sources

    inputs = _inputs(videos, text)
    write.check_outdir(outdir, cfg.force, inputs)
    write.check_writable(outdir)
    seconds: Dict[str, float] = {}
    t0 = time.perf_counter()
    pmap = load_map(cfg.map)
    sources = find_sources(videos, text, texts=texts)
    from ..speech.languages import check_transcript

    for s in sources:  # a transcript nothing reads is refused before the long work (issue 32)
        if s.text is not None:
            check_transcript(s.text, cfg.lang, path=s.text_from if s.text_from != "--text" else "--text")
    seconds["probe"] = time.perf_counter() - t0

    footage = observe(sources, pmap, cfg, seconds, tracks=tracks)
    t = time.perf_counter()
    ranked = select.rank(_candidates(footage, pmap.silence),
                         [select.FrameMeasures.of(tr.points, tr.fps, reg.residual)
                          for tr, reg in zip(footage.tracks, footage.regs)],
                         closures=pmap.closures, rest=pmap.silence, span=select.SPAN_GAIN if cfg.span else 1.0)
    if pmap.silence not in ranked:
        raise InputError(f"no face in the pauses to take the rest shape ({pmap.silence}) from", path=footage.names)
    if cfg.one_face:
        ranked[pmap.silence] = select.for_plate(ranked[pmap.silence])
    seconds["select"] = time.perf_counter() - t
    t = time.perf_counter()
    pictures = cut_and_choose(footage, {v: r[:select.FINALISTS] for v, r in ranked.items()}, cfg,
                              plate=pmap.silence if cfg.one_face else None)
    seconds["cut"] = time.perf_counter() - t
    return assemble(outdir, footage, ranked, pictures, pmap, cfg, seconds, inputs=inputs)


#: Narrowest picture, in eye distances, in which the face room still finds the face: crops
#: of bank pictures (init --video of bbwm5s.mpg, 46 px between the eyes) centred on the face
#: were found down to 1.5 eye distances wide (lip points within 0.023 eye distances of the
#: whole picture's), and 2 of 3 were not at 1.2. A head at the frame's edge gave 40x234.
MIN_PICTURE_EYE_DISTANCES = 1.5


def _check_trackable(names: str, w: int, h: int, scale: float) -> None:
    """Refuse a bank the face room could not find the face in again (editor, dub, init DIR)."""
    from .sources import MIN_EYE_DISTANCE_PX

    if scale < MIN_EYE_DISTANCE_PX:
        raise InputError(f"the bank's pictures ({w}x{h}) would have {scale:.0f} px between the eyes; at least "
                         f"{MIN_EYE_DISTANCE_PX:g} are needed to place the lips (a larger --size)", path=names)
    if min(w, h) < MIN_PICTURE_EYE_DISTANCES * scale:
        raise InputError(f"the face is cut: the bank's pictures would be {w}x{h} px, {min(w, h) / scale:.1f} eye "
                         f"distances across, and the face needs {MIN_PICTURE_EYE_DISTANCES:g} (keep the whole head "
                         f"in view)", path=names)


def _lips_inside(points: np.ndarray, w: int, h: int) -> bool:
    """Whether the outer lip contour of ``points`` lies inside a ``w`` x ``h`` picture."""
    from ..face import topology as T

    lips = np.asarray(points)[list(T.LIP_OUTER_UPPER + T.LIP_OUTER_LOWER), :2]
    return bool((lips >= 0).all() and (lips[:, 0] <= w - 1).all() and (lips[:, 1] <= h - 1).all())


def _inputs(videos: Sequence[PathLike], text: Optional[str]) -> List[PathLike]:
    """The files a bank is made from (the bank's folder may not hold them)."""
    return list(videos) + ([text] if text is not None and os.path.isfile(text) else [])


def _candidates(footage: Footage, rest: str) -> List[Candidate]:
    out: List[Candidate] = []
    for i, (sp, tr) in enumerate(zip(footage.speeches, footage.tracks)):
        out += select.candidates(sp.visemes, video=i, fps=tr.fps, found=tr.found, rest=rest)
    return out


def observe(sources: List[Source], pmap, cfg: VideoBankConfig, seconds: Dict[str, float], *,
            tracks: Optional[Mapping[PathLike, object]] = None) -> Footage:
    """Align each video's speech, refuse footage without a pause for the rest shape, track
    the face in every frame, and map every frame onto one reference pose."""
    from tqdm import tqdm

    from ..face.landmarks import FaceMesh
    from ..face.track import track_frames
    from ..face.video import read_video
    from .speech import transcribe

    names = ", ".join(s.name for s in sources)
    known = {Path(os.fspath(k)).resolve(): v for k, v in (tracks or {}).items()}
    speeches, tracks = [], []
    mesh = FaceMesh()  # the models loaded once for every video
    # one bar over every video's frames: each is aligned (its sound) and then tracked
    counts = [max(s.info.frame_count, 1) for s in sources]
    with tqdm(total=2 * sum(counts), desc="speech and faces", unit="frame", disable=cfg.quiet, leave=False) as bar:
        t = time.perf_counter()
        for s, n in zip(sources, counts):
            bar.set_postfix_str(s.name)
            speeches.append(transcribe(s, pmap, quiet=True, jobs=cfg.jobs, lang=cfg.lang))
            bar.update(n)
        seconds["align"] = time.perf_counter() - t
        # before the longer work: is there a pause long enough to show the rest shape? (speech
        # read off the face is checked once the face is tracked)
        if not any(sp.from_face for sp in speeches) and not any(select.rest_frames(sp.visemes, i, s.info.fps, n)
                   for sp, s, n in zip(speeches, sources, counts)
                   for i, span in enumerate(sp.visemes) if span.label == pmap.silence):
            raise InputError(f"no silence to take the rest shape ({pmap.silence}) from: leave a second of "
                             f"silence, mouth closed and relaxed, before or after speaking", path=names)
        t = time.perf_counter()
        for s in sources:
            bar.set_postfix_str(s.name)
            given = known.get(Path(s.path).resolve())
            tracks.append(given if given is not None else
                          track_frames(read_video(s.path, info=s.info), fps=s.info.fps, size=s.info.size,
                                       source=str(s.path), mesh=mesh, progress=bar.update))
        seconds["track"] = time.perf_counter() - t
    speeches = _label_from_face(speeches, tracks, pmap)
    ref = stabilise.reference_pose([tr.points[tr.found] for tr in tracks])
    regs = [stabilise.register_track(tr.points, tr.found, ref) for tr in tracks]
    return Footage(sources=sources, speeches=speeches, tracks=tracks, regs=regs)


def _label_from_face(speeches: List[Speech], tracks: list, pmap) -> List[Speech]:
    """Speech whose sound named nothing, labelled by lip shape (:func:`.speech.from_face`),
    with a warning saying so; then the rest shape's pause is checked."""
    from .speech import from_face

    out = []
    for sp, tr in zip(speeches, tracks):
        if sp.from_face:
            warnings.warn(f"{sp.source.name}: nothing in its sound could be recognised as speech (no words or "
                          f"phones); the pictures are chosen by lip shape alone", UserWarning, stacklevel=4)
            sp = from_face(sp, tr.points, tr.found, tr.fps, pmap)
            if not any(select.rest_frames(sp.visemes, i, tr.fps, len(tr))
                       for i, span in enumerate(sp.visemes) if span.label == pmap.silence):
                raise InputError(f"no quiet stretch to take the rest shape ({pmap.silence}) from: leave a second of "
                                 f"silence, mouth closed and relaxed, before or after speaking", path=sp.source.path)
        out.append(sp)
    return out


def cut_and_choose(footage: Footage, finalists: Dict[str, List[Candidate]], cfg: VideoBankConfig, *,
                   plate: Optional[str] = None) -> Pictures:
    """Cut the finalists out of the videos, choose each viseme's sharpest best, and cut the
    chosen frames again at a framing fitted to them alone (more room for the neck and
    shoulders than all finalists share).

    With ``plate`` (the rest viseme: one face), each chosen frame is cut on the plate's pose
    around the mouth (:func:`lipsync.composite.face.pose_onto`: the similarity left between
    its nose base and upper cheeks and the plate's, after the stabilisation), composed into
    the one warp of the cut: each picture is resampled once from the video."""
    from ..face.compare import mouth_box
    from .cut import RAW_BUDGET_BYTES, grab_frames, warp_frame

    src, regs, tracks = footage.sources, footage.regs, footage.tracks
    flat = [c for fs in finalists.values() for c in fs]
    scale = float(np.median([1.0 / abs(regs[c.video].c[c.frame]) for c in flat]))

    def framing_for(cands: List[Candidate]) -> "stabilise.Framing":
        return stabilise.framing([(regs[c.video], c.frame, src[c.video].info.size) for c in cands],
                                 [regs[c.video].to_unit(c.frame, tracks[c.video].points[c.frame]) for c in cands],
                                 source_scale=scale, size=cfg.size, max_side=cfg.max_side)

    def points(fr: "stabilise.Framing", c: Candidate) -> np.ndarray:
        return fr.points(regs[c.video], c.frame, tracks[c.video].points[c.frame])

    def cut(fr: "stabilise.Framing", cands: List[Candidate], raw: Dict[tuple, np.ndarray], keep: bool,
            fix: Optional[Dict[tuple, np.ndarray]] = None):
        out = {}
        for i, s in enumerate(src):
            wanted = sorted({c.frame for c in cands if c.video == i})
            got = {f: raw[(i, f)] for f in wanted} if all((i, f) in raw for f in wanted) else (
                grab_frames(s.path, wanted, info=s.info) if wanted else {})
            for f, img in got.items():
                if keep:
                    raw[(i, f)] = img
                m = fr.matrix(regs[i], f)
                if fix is not None:
                    m = _compose(fix[(i, f)], m)
                out[(i, f)] = warp_frame(img, m, fr.size, interpolation=PICTURE_INTERPOLATION)
        return out

    frame = framing_for(flat)
    w, h = frame.size
    raw: Dict[tuple, np.ndarray] = {}
    keep = sum(int(np.prod(src[c.video].info.size)) * 3 for c in flat) <= RAW_BUDGET_BYTES
    # a frame that cuts the face can leave the mouth out of the picture (no sharpness to
    # measure, lines off the picture): such finalists are dropped, or the footage refused
    inside = {(c.video, c.frame): _lips_inside(points(frame, c), w, h) for c in flat}
    if sum(inside.values()) < len(inside) / 2 or not all(any(inside[(c.video, c.frame)] for c in fs)
                                                         for fs in finalists.values()):
        raise InputError(f"the mouth is outside the picture in {len(inside) - sum(inside.values())} of the "
                         f"{len(inside)} frames chosen from: the frame cuts the face (keep the whole head in view)",
                         path=footage.names)
    finalists = {v: [c for c in fs if inside[(c.video, c.frame)]] for v, fs in finalists.items()}
    images = cut(frame, flat, raw, keep)
    chosen: Dict[str, Candidate] = {}
    for v, fs in finalists.items():
        sharp = [select.sharpness(images[(c.video, c.frame)], mouth_box(points(frame, c), (h, w))) for c in fs]
        chosen[v] = select.with_sharpness(fs, sharp)[0]
    picked = list({(c.video, c.frame): c for c in chosen.values()}.values())
    final = framing_for(picked)
    pts = {(c.video, c.frame): points(final, c) for c in picked}
    key = None
    if plate is not None and plate in chosen:
        from ..composite.face import pose_onto

        key = (chosen[plate].video, chosen[plate].frame)
        fix = {k: pose_onto(p, pts[key]) for k, p in pts.items()}
        fix[key] = np.array([[1.0, 0, 0], [0, 1.0, 0]])
        images = cut(final, picked, raw, False, fix)
        pts = {k: p[..., :2] @ fix[k][:, :2].T + fix[k][:, 2] if p.shape[-1] == 2 else
               np.concatenate([p[..., :2] @ fix[k][:, :2].T + fix[k][:, 2],
                               p[..., 2:] * float(np.hypot(*fix[k][:, 0]))], axis=-1) for k, p in pts.items()}
    elif final != frame:
        images = cut(final, picked, raw, False)
    if final.cut:
        warnings.warn(f"{footage.names}: the picture cuts the head at the {' and '.join(final.cut)} (keep the whole "
                      f"head and the neck in view, with some room around them); the bank is cropped tighter",
                      UserWarning, stacklevel=3)
    return Pictures(chosen=chosen, framing=final, images={(c.video, c.frame): images[(c.video, c.frame)] for c in picked},
                    points=pts, plate=key)


def _compose(first: np.ndarray, m: np.ndarray) -> np.ndarray:
    """The 2x3 affine doing ``m`` first, then ``first``."""
    return first[:, :2] @ m + np.array([[0, 0, first[0, 2]], [0, 0, first[1, 2]]])


def assemble(outdir: Path, footage: Footage, ranked: Dict[str, List[Candidate]], pictures: Pictures, pmap,
             cfg: VideoBankConfig, seconds: Dict[str, float], inputs: Sequence[PathLike] = ()) -> VideoBankResult:
    """Borrow shapes for visemes never shown, match the colour, place the lines, and write
    the bank (PNGs, bank.yaml, report, preview, flows) all at once."""
    from ..banks.bank import Bank
    from ..banks.yamlio import write_bank_text
    from ..face.lines import SYMMETRIC_BELOW, face_asymmetry, face_features
    from . import colour, write

    t = time.perf_counter()
    names, chosen, frame = footage.names, pictures.chosen, pictures.framing
    w, h = frame.size
    _check_trackable(names, w, h, frame.scale)
    order = _viseme_order(pmap)
    shown = [v for v in order if v in chosen]
    missing = {v: select.nearest_available(v, shown, fallback=pmap.fallback) for v in order if v not in chosen}
    if missing:
        warnings.warn(f"{names}: never shows {_what_to_record(list(missing), pmap)}; using the closest shape "
                      f"shown ({', '.join(f'{v} <- {u}' for v, u in missing.items())}). Record these sounds too "
                      f"(reading samples/record-script.txt aloud shows every shape)", UserWarning, stacklevel=3)
    source_of = {v: chosen[v] if v in chosen else chosen[missing[v]] for v in order}
    moved = float(np.median([c.residual for c in chosen.values()]))
    if moved > MOVED_RESIDUAL:
        warnings.warn(f"{names}: the head turns or nods between the chosen frames (their still points disagree "
                      f"by {moved:.2f} eye distances, against {MOVED_RESIDUAL:g} at most on a still speaker); the "
                      f"rendered head will wobble. Record facing the camera with the head still, or more of it "
                      f"to choose from", UserWarning, stacklevel=3)

    keys = list(pictures.images)
    points = dict(pictures.points)
    if pictures.plate is not None:
        # one face: every picture is the plate outside its lower face (composite.face)
        from ..composite.face import onto_plate

        plate, plate_points = pictures.images[pictures.plate], pictures.points[pictures.plate]
        matched, gains = {pictures.plate: plate}, {pictures.plate: (1.0, 1.0, 1.0)}
        for k in keys:
            if k != pictures.plate:
                pasted = onto_plate(plate, plate_points, pictures.images[k], pictures.points[k])
                matched[k], points[k] = pasted.image, pasted.points
                gains[k] = tuple(round(float(x), 4) for x in pasted.gain)
    else:
        # the chosen pictures matched on the still skin
        masks = {k: colour.still_skin_mask(pictures.points[k], (h, w)) for k in keys}
        matched, gains = colour.match_colour(pictures.images, masks, where=names)

    # lines from each picture's own face (one face: the plate's above the mouth)
    pts = {v: points[(c.video, c.frame)] for v, c in source_of.items()}
    asym = face_asymmetry(list(pts.values()))
    symmetric = asym < SYMMETRIC_BELOW
    features = face_features(pts, (h, w), axis=frame.axis)

    files = write.image_names(order)
    report = {
        "made_by": "lipsync init --video",
        "map": pmap.name,
        "rest": pmap.silence,
        "size": [w, h],
        "pixels_per_eye_distance": round(frame.scale, 3),
        "symmetry": symmetric,
        "asymmetry": round(asym, 4),
        "cropped_short": list(frame.cut),
        "videos": [{
            "video": s.name, "fps": s.info.fps, "frames": len(tr), "size": list(s.info.size),
            # a transcript that did not fit was not what the words came from (issue 32)
            "transcript": s.text_from if not (sp.recognised and s.text is not None)
            else f"{s.text_from} (not used: it does not fit the speech; the words were recognised)",
            "lang": cfg.lang or "en", "words": list(sp.words), "recognised": sp.recognised,
            # what the mouth shapes' times came from: words, phones heard without words
            # (recognition in other languages), or the lips alone (nothing could be named)
            "shapes_from": "lip shape" if sp.from_face else ("words" if sp.words else "phones"),
            "confidence": None if sp.confidence is None else round(sp.confidence, 3),
            "face_found": round(float(tr.found.mean()), 4),
            "residual_median": round(float(np.nanmedian(reg.residual)), 4),
        } for s, sp, tr, reg in zip(footage.sources, footage.speeches, footage.tracks, footage.regs)],
        "visemes": {},
        "missing": {v: {"uses": u, "record": _what_to_record([v], pmap)} for v, u in missing.items()},
        "timing": TIMING,
    }
    if pictures.plate is not None:
        pc = next(c for c in chosen.values() if (c.video, c.frame) == pictures.plate)
        report["face_plate"] = {"video": footage.sources[pc.video].name, "frame": pc.frame, "time": round(pc.time, 3),
                                "viseme": pc.viseme, "eyes": round(pc.eyes, 4),
                                "what": "every picture shows this frame outside its lower face"}
    for v in order:
        c = source_of[v]
        report["visemes"][v] = dict(image=files[v], video=footage.sources[c.video].name, **c.report(),
                                    candidates=len(ranked.get(v, [])), borrowed_from=missing.get(v),
                                    colour_gain=list(gains[(c.video, c.frame)]))
    seconds["choose"] = time.perf_counter() - t

    header = [f"# Written by lipsync init --video from {len(footage.sources)} video(s) ({names[:200]}): one "
              f"frame per viseme, lines placed from the face; the choice is in {write.REPORT_NAME}."]
    with write.Staging(outdir, force=cfg.force, inputs=inputs) as tmp:
        t = time.perf_counter()
        images = {}
        for v in order:
            c = source_of[v]
            images[files[v]] = matched[(c.video, c.frame)]
            write.write_png(tmp / files[v], images[files[v]])
        text_yaml = write.bank_text(outdir.resolve().name, pmap.silence, files, features, symmetric=symmetric,
                                    header=header, timing=TIMING)
        from .plate import write_plate
        text_yaml += write_plate(tmp, footage, pictures.framing, pts, pmap.silence)  # the idle plate (issue 28)
        if cfg.samples and pictures.plate is not None:  # the real mouth samples (issue 35)
            from ..samples.build import write_samples

            text_yaml += write_samples(tmp, footage, pictures.framing, pts[pmap.silence], images[files[pmap.silence]],
                                       pictures={v: pts[v] for v in order}, quiet=cfg.quiet)
        Bank.from_text(text_yaml, tmp, images=images)  # never write a bank that would not load
        write_bank_text(tmp / "bank.yaml", text_yaml)
        bank = Bank.load(tmp)
        write.write_preview(tmp / write.PREVIEW_NAME, bank)
        seconds["write"] = time.perf_counter() - t
        if cfg.flows:
            from ..morphing.preprocess import preprocess

            t = time.perf_counter()
            preprocess(bank, jobs=cfg.jobs, quiet=cfg.quiet)
            seconds["flows"] = time.perf_counter() - t
        report["seconds"] = {k: round(x, 2) for k, x in seconds.items()}
        write.write_report(tmp / write.REPORT_NAME, report)
    return VideoBankResult(path=outdir, chosen=chosen, missing=missing, size=(w, h), symmetric=symmetric,
                           seconds=seconds, report=report)
