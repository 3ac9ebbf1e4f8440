"""``lipsync dub VIDEO --audio SPEECH``: a video of a speaker re-voiced by new speech.

The video's own frames are the plate: its head motion, blinks, expressions and background
stay; its lower face is replaced by the speaker's bank morphed to the new speech::

    VIDEO --probe--> fps, size          SPEECH --probe--> samples (a file without sound: exit 2)
    VIDEO --track (face mesh, cached)--> each frame's still points --> pose (bank -> frame)
    bank (--bank, else made from VIDEO by lipsync init --video and cached)
        --face mesh of its pictures--> lower-face mask (union over the visemes), still points
    SPEECH (+ --text) --aligner--> phones --Animator (map, timing)--> one FrameSpec per frame
    frame i: plate = VIDEO frame from --plate-start on (default its start), played straight;
        when the speech is longer, on along a plate timeline that joins the video to itself
        where its frames match, never mid-blink (lipsync.composite.plate_time); cut when
        shorter --PlateCompositor (morphed lower face, ROI only)-->
        --> encoder (H.264 + the new speech as AAC) --> OUT (renamed into place)

Frames where the tracker lost the face are written as they are, with one warning naming
them (frame numbers and times). Caches live under the user's cache folder
(``$XDG_CACHE_HOME/lipsync/dub``), one entry per video content (sha256 of its bytes): the
face track and, per phoneme map, transcript and language of the video, the bank made from it;
their rules (checked entries, no links followed, killed runs' leftovers removed, an unwritable
cache) and the temporary store of frames are :mod:`lipsync.pipeline.cache`'s.
"""

from __future__ import annotations

import errno
import hashlib
import os
import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np

from ..errors import InputError, PathLike
from ..composite.plate import PlateCompositor, colour_lut, plate_colour
from .cache import cache_root

__all__ = ["dub", "DubReport", "DubWarning", "cache_root", "lost_frames_text"]

#: Cache format: bump when what an entry holds changes (older entries are then misses).
#: 3: the video turned upright before tracking; the bank's key has the video's language; the
#: frames of a variable-frame-rate video are those shown at a constant rate.
CACHE_VERSION = 3


#: Output formats with a sound track (lipsync.encode): H.264 + AAC, VP9 + Opus, ProRes + PCM.
SOUND_FORMATS = ("mp4", "webm", "mov")


class DubWarning(UserWarning):
    """Something the dub could not do everywhere (frames without a face, ...)."""


@dataclass(frozen=True)
class DubReport:
    """What :func:`dub` made.

    Attributes
    ----------
    output : str
    frames : int
        Frames written (the speech's length at the video's frame rate).
    fps : float
    size : (int, int)
        ``(W, H)``, the video's.
    video_frames : int
        Frames of the input video (the plate).
    lost : tuple of int
        Output frames written as they were (no face in the plate frame).
    bank : str
        The bank used (a cached one when made from the video).
    seconds : dict
        Wall time per step.
    """

    output: str
    frames: int
    fps: float
    size: Tuple[int, int]
    video_frames: int
    lost: Tuple[int, ...]
    bank: str
    seconds: dict

    def summary(self) -> str:
        w, h = self.size
        total = sum(self.seconds.values())
        steps = ", ".join(f"{k} {v:.1f}" for k, v in self.seconds.items())
        return (f"wrote {self.output}: {self.frames} frames ({self.frames / self.fps:.2f} s at {self.fps:g} fps), "
                f"{w}x{h}, over {self.video_frames} video frames; {total:.1f} s ({steps})")


def _digest(path: Path) -> str:
    h = hashlib.sha256(f"lipsync-dub-{CACHE_VERSION}".encode())
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:32]


def lost_frames_text(lost, fps: float, limit: int = 8) -> str:
    """``"3-5 (0.12-0.20 s), 9 (0.36 s)"``: runs of frame numbers with their times.

    Examples
    --------
    >>> lost_frames_text([3, 4, 5, 9], 25.0)
    '3-5 (0.12-0.20 s), 9 (0.36 s)'
    """
    idx = sorted(int(i) for i in lost)
    runs: List[List[int]] = []
    for i in idx:
        if runs and i == runs[-1][1] + 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    parts = [f"{a} ({a / fps:.2f} s)" if a == b else f"{a}-{b} ({a / fps:.2f}-{b / fps:.2f} s)"
             for a, b in runs[:limit]]
    return ", ".join(parts) + (", ..." if len(runs) > limit else "")


# --------------------------------------------------------------------------- caches

def video_track(video: Path, info, *, entry: Optional[Path], quiet: bool, mesh=None):
    """The face track of every frame of ``video`` (from the cache entry when it loads)."""
    from ..face.track import track_frames
    from ..face.video import read_video
    from tqdm import tqdm

    from .cache import load_track, save_track

    cached = entry / "track.npz" if entry is not None else None
    if cached is not None:
        track = load_track(cached, info)  # None: a miss (a damaged entry is removed)
        if track is not None:
            return track
    with tqdm(total=info.frame_count or None, desc="face", unit="frame", disable=quiet, leave=False) as bar:
        with warnings.catch_warnings():
            # the lost frames are named once, by dub, in output frames
            from ..face.landmarks import FaceWarning

            warnings.simplefilter("ignore", FaceWarning)
            track = track_frames(read_video(video, info=info), fps=info.fps, size=info.size, source=str(video),
                                 mesh=mesh, progress=bar.update)
    if cached is not None:
        save_track(cached, track)  # a cache that cannot be written costs time, not the result
    return track


def bank_key(map=None, text: Optional[str] = None, lang: Optional[str] = None) -> str:
    """The cache name of a bank made from a video: its phoneme map, transcript and the
    language of its speech (English and no language given are one, as are the default map
    and none given).

    Examples
    --------
    >>> bank_key(lang="es") == bank_key(lang="es"), bank_key(lang="es") == bank_key(), bank_key(lang="en") == bank_key()
    (True, False, True)
    """
    from ..phonetics.g2p import is_english
    from ..phonetics.phonemes import DEFAULT_MAP

    lang = None if lang is None or is_english(lang) else lang
    map = DEFAULT_MAP if map is None else map  # the command line's default and the API's are one map
    return hashlib.sha256(repr((os.fspath(map) if map is not None else None, text, lang)).encode()).hexdigest()[:12]


def _align_speech(audio: Path, text: Optional[str], lang: Optional[str]):
    """The new speech's words and phones (:func:`lipsync.speech.align.align`, as
    :meth:`lipsync.Animator.from_audio` aligns them)."""
    from ..speech.align import MissingWordsWarning, align

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MissingWordsWarning)  # words spelt out: the alignment says so
        return align(audio, text, lang=lang)


def bank_from_video(video: Path, *, entry: Path, map=None, text: Optional[str] = None, jobs=None,
                    quiet: bool = True, track=None, lang: Optional[str] = None):
    """The bank ``lipsync init OUT --video VIDEO [--text TEXT] [--lang LANG]`` makes, cached
    in ``entry`` (one per map, transcript and language of the video's speech)."""
    from ..banks.bank import Bank
    from ..videobank import make_bank

    from .cache import load_bank

    folder = entry / f"bank-{bank_key(map, text, lang)}"
    cached = load_bank(folder)  # None: a miss (a broken entry, or a link, is removed)
    if cached is not None:
        return cached
    options = {"map": os.fspath(map)} if map is not None else {}
    if lang is not None:
        options["lang"] = lang
    # Made in place by make_bank, which writes into a hidden staging folder beside it
    # (.bank-KEY.partial-PID-XXXX, removed by the next run if this one is killed) and renames
    # it into place: two dubs of one video at once must not replace a bank the other is
    # reading, so no --force: the first rename wins and the other keeps that bank.
    try:
        make_bank(folder, [video], text=text, quiet=quiet, jobs=jobs,
                  tracks={video: track} if track is not None else None, **options)
    except InputError:
        cached = load_bank(folder)
        if cached is None:
            raise
        return cached
    return Bank.load(folder)


# --------------------------------------------------------------------------- the bank's face

def bank_face(bank, *, mesh=None):
    """The lower-face mask of a bank of a real face (float32, bank pixels: the union over its
    visemes' face lines, :func:`lipsync.composite.face.mask_from_lines`) and the rest
    picture's face mesh (``(468, 3)``, what each video frame's pose is fitted to)."""
    from ..face.track import Tracker
    from ..composite.face import mask_from_lines

    from ..face.landmarks import FaceMesh

    pts = Tracker(mesh or FaceMesh(), source=f"{bank.path} {bank.rest}").step(
        np.ascontiguousarray(bank.images[bank.rest][..., :3]))
    if pts is None:
        raise InputError(f"no face found in the rest picture ({bank.rest}): dub needs a bank of a real face "
                         f"(lipsync init --video)", path=bank.yaml_path)
    try:
        mask = mask_from_lines([bank.features[v] for v in bank.names], bank.shape)
    except (KeyError, ValueError):
        from ..composite.face import mask_from_mesh

        mask = mask_from_mesh([pts], bank.shape)  # a bank whose lines are not a face template's
    return mask, pts


def plate_poses(bank_mesh: np.ndarray, track) -> np.ndarray:
    """2x3 matrices ``(N, 2, 3)`` taking bank pixels to each video frame's pixels
    (:func:`lipsync.composite.face.pose_onto`; NaN where the face was lost)."""
    from ..composite.face import pose_onto

    out = np.full((len(track), 2, 3), np.nan)
    for i in np.nonzero(track.found)[0]:
        out[i] = pose_onto(bank_mesh, track.points[i])
    return out


def colour_table(bank, video: Path, track, poses: np.ndarray, bank_mesh: np.ndarray, mask: np.ndarray):
    """The colour table (or None: the colours agree) taking the bank's rest picture to the
    video's colour (:func:`~lipsync.composite.plate.plate_colour` over frames spread through
    the video)."""
    from ..videobank.cut import grab_frames
    from ..composite.plate import COLOUR_SAMPLES

    found = np.nonzero(track.found)[0]
    frames = sorted({int(found[int(k)]) for k in np.linspace(0, found.size - 1, min(COLOUR_SAMPLES, found.size))})
    got = grab_frames(video, frames)
    gains = plate_colour(bank.images[bank.rest], bank_mesh, mask, [got[f] for f in frames], [poses[f] for f in frames])
    # a bank made from this video has its colour already: no table to apply every frame
    return None if np.abs(gains - 1.0).max() * 255 < 0.5 else colour_lut(gains)


# --------------------------------------------------------------------------- plate frames

class _PlateReader:
    """The video's frames by index for render threads: decoded once, in order; when the
    speech outlasts the video (the video joined to itself), all ``count`` of them are kept in a
    :class:`~lipsync.pipeline.cache.FrameStore` (the temporary folder; its room checked
    here, before any work is done on it)."""

    def __init__(self, video: Path, info, *, keep: bool, count: int):
        from ..face.video import read_video
        from .cache import FrameStore

        self._store = FrameStore(count, (info.size[1], info.size[0], 3), what=f"the {count} frames of {video.name} "
                                 f"joined to itself") if keep else None
        self._gen = read_video(video, info=info)
        self._lock = threading.Lock()
        self._next = 0
        self._recent = {}

    def get(self, j: int) -> np.ndarray:
        with self._lock:
            if j < self._next:
                if j in self._recent:
                    return self._recent.pop(j)
                return self._store.get(j)
            while self._next <= j:
                frame = next(self._gen)
                if self._store is not None:
                    self._store.put(self._next, frame)
                self._recent[self._next] = frame
                self._next += 1
            # frames asked for once, in order (render threads run a few frames apart)
            for k in [k for k in self._recent if k < j - 64]:
                del self._recent[k]
            return self._recent.pop(j)

    def close(self):
        self._gen.close()
        if self._store is not None:
            self._store.close()


def _refuse_silence(samples: np.ndarray, audio: Path) -> None:
    """A digitally silent speech file (its loudest 10 ms below the aligner's silence) has
    nothing to dub: exit 2 rather than a still mouth."""
    from ..speech.align import SILENCE_DBFS

    n = len(samples) // 160
    x = samples[:max(n, 1) * 160].astype(np.float32) / 32768.0
    if x.size < 160:
        x = np.pad(x, (0, 160 - x.size))
    loudest = float(20 * np.log10(np.sqrt((x.reshape(-1, 160) ** 2).mean(axis=1)).max() + 1e-12))
    if loudest < SILENCE_DBFS:
        raise InputError(f"is silent (loudest {loudest:.0f} dBFS; speech is above {SILENCE_DBFS:g}): there is no "
                         f"speech to dub with", path=audio)


def video_frames_for(track, n: int, start: float = 0.0) -> np.ndarray:
    """The video frame shown at each of ``n`` output frames: from ``start`` seconds on,
    straight to (nearly) its end; then along a plate timeline
    (:class:`lipsync.composite.plate_time.PlateTimeline`) that joins it to itself where the
    face above the nose matches (face-mesh points, :func:`~lipsync.composite.plate_time.upper_face_features`)
    and never inside a blink (eye opening of the face mesh).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> t = SimpleNamespace(points=np.zeros((10, 468, 3)), found=np.ones(10, bool), fps=25.0)
    >>> video_frames_for(t, 4, start=0.2).tolist()
    [5, 6, 7, 8]
    """
    from ..composite.plate_time import PlateTimeline, PlateTimes, upper_face_features
    from ..face.measure import eye_opening

    nv = len(track.points)
    first = int(round(start * track.fps)) % max(nv, 1)
    if first + n <= nv:
        return np.arange(first, first + n)
    eyes = eye_opening(track.points)
    eyes[~np.asarray(track.found, bool)] = np.nan
    times = PlateTimes(upper_face_features(track.points, track.found), eyes, track.fps)
    # the video played through first (joins only from its last MIN_RUN_S)
    return PlateTimeline(times, start=first / nv, straight=nv - first - times.min_run).frames(n)


# --------------------------------------------------------------------------- the pipeline

def dub(video: PathLike, audio: PathLike, output: PathLike, *, text: Optional[str] = None, bank=None,
        video_text: Optional[str] = None, map=None, timing=None, crf: int = 18, preset: Optional[str] = None,
        store=None, jobs: Optional[int] = None, quiet: bool = False, cache: Optional[PathLike] = None,
        lang: Optional[str] = None, video_lang: Optional[str] = None,
        plate_start: Optional[float] = None, samples=None) -> DubReport:
    """Re-voice ``video`` with the speech in ``audio`` (``lipsync dub``).

    Parameters
    ----------
    video : path-like
        A video of one speaker facing the camera (any container ffmpeg reads).
    audio : path-like
        The new speech (any file with an audio stream ffmpeg reads; a video's sound too).
    output : path-like
        The video to write (.mp4); written under a temporary name and renamed when complete.
    text : str, optional
        The new speech's transcript (or a file holding it); else its words are recognised.
    bank : Bank or path-like, optional
        The speaker's bank; default: one made from ``video`` itself
        (:func:`lipsync.videobank.make_bank`, cached).
    video_text : str, optional
        What is said in ``video`` (for making its bank; else ``NAME.txt``/``NAME.lab``
        beside it, else recognised).
    map, timing
        As for :class:`lipsync.Animator` (the bank's timing by default).
    crf, preset
        x264 quality and preset (default: :data:`lipsync.pipeline.clip.DEFAULT_PRESET`).
    store : FlowStore or path-like, optional
        Flow store (default: the bank's own).
    jobs : int, optional
        Processes for computing flows.
    quiet : bool
        No progress bars.
    cache : path-like, optional
        Cache folder (default :func:`cache_root`).
    lang : str, optional
        The language of the new speech (BCP 47; default English), as ``--lang``
        (:func:`lipsync.speech.align.align`).
    video_lang : str, optional
        The language of what is said in ``video`` (default English), used only to make its
        bank; when its words cannot be recognised there the bank is made from the phones
        heard, or from the lips alone (:func:`lipsync.videobank.speech.transcribe`).
    plate_start : float, optional
        Seconds into ``video`` where the output starts (default 0: the video as it is).
    samples : {None, "on", "off"} or bool
        A bank with mouth samples shows a selected real sample per frame
        (:mod:`lipsync.pipeline.samplepath`); ``"off"``: one picture per viseme morphed.

    Returns
    -------
    DubReport

    Raises
    ------
    lipsync.errors.InputError
        ``video`` is missing or not a video, or shows no face, or a face no way up;
        ``audio`` is missing, has no sound or is silent (the message names the file).

    Warns
    -----
    lipsync.speech.align.TranscriptMismatchWarning
        ``text`` does not fit the new speech at all (``lipsync dub`` stops on it with exit
        2 unless ``--allow-mismatch``, as ``lipsync render`` does).

    Examples
    --------
    >>> dub("missing.mp4", "speech.wav", "out.mp4")
    Traceback (most recent call last):
    ...
    lipsync.errors.InputError: missing.mp4: no such file

    With the GRID clips in ``tests/data/grid-s1`` (a bank is made from the first clip and
    cached; about 15 s on two cores the first time)::

        from lipsync import dub
        from lipsync.bench.grid import grid_dir, transcript
        d = grid_dir()
        print(dub(d / "bbwm5s.mpg", d / "prap6p.mpg", "dubbed.mp4", text=transcript("prap6p")).summary())
    """
    sample_option = samples  # the name is the audio's below
    from tqdm import tqdm

    from .animator import Animator
    from ..banks.bank import Bank
    from .clip import DEFAULT_PRESET, SINGLE_ENCODER_THREAD_CORES, render_parallel
    from ..encode import format_for, open_writer
    from ..encode.mp4 import check_preset
    from ..face.landmarks import FaceMesh
    from ..face.video import probe_video
    from ..speech.audio import load_audio
    from .._files import refuse_output_over_input
    from ..morphing.store import FlowStore

    refuse_output_over_input([output], [video, audio, text, video_text])   # issue 38: -o the video replaced it

    seconds = {}
    t = time.perf_counter()
    preset = preset or DEFAULT_PRESET
    check_preset(preset)
    if not 0 <= crf <= 51:
        raise InputError(f"--crf must be 0..51, got {crf}")
    video, audio, output = Path(os.fspath(video)), Path(os.fspath(audio)), Path(os.fspath(output))
    out_format = format_for(output)
    if out_format not in SOUND_FORMATS:
        raise InputError(f"a dub is a video with sound: write {', '.join('.' + f for f in SOUND_FORMATS)} "
                         f"(got {out_format})", path=output)
    info = probe_video(video)
    if info.variable is not None:  # read at a constant rate (lipsync.face.video.constant_rate)
        warnings.warn(f"{video}: variable frame rate ({info.variable[0]:.3g} to {info.variable[1]:.3g} fps): dubbed "
                      f"at a constant {info.fps:g} fps, each frame the one the video shows at that time",
                      DubWarning, stacklevel=2)
    samples = load_audio(audio)  # AudioError (an InputError) naming a file without sound
    if samples.size == 0:
        raise InputError("has no sound to dub with (0 samples)", path=audio)
    _refuse_silence(samples, audio)
    if plate_start is not None and not (np.isfinite(plate_start) and plate_start >= 0):
        raise InputError(f"--plate-start must be a number of seconds, 0 or more (got {plate_start})")
    from .cache import open_entry

    cache_entry = open_entry(_digest(video), cache)  # a temporary one is removed when dub ends
    entry = cache_entry.path
    seconds["probe"] = time.perf_counter() - t

    t = time.perf_counter()
    alignment = _align_speech(audio, text, lang)  # first: a transcript that does not fit stops before the long work
    seconds["align"] = time.perf_counter() - t

    t = time.perf_counter()
    mesh = FaceMesh()
    from ..videobank.sources import find_upright

    info = find_upright(video, info, mesh)  # as init --video does: a sideways face turned, or refused
    track = video_track(video, info, entry=entry, quiet=quiet, mesh=mesh)
    seconds["track"] = time.perf_counter() - t

    t = time.perf_counter()
    if bank is None:
        bank = bank_from_video(video, entry=entry, map=map, text=video_text, jobs=jobs, quiet=quiet, track=track,
                               lang=video_lang)
    elif not isinstance(bank, Bank):
        bank = Bank.load(bank)
    seconds["bank"] = time.perf_counter() - t

    t = time.perf_counter()
    mask, bank_mesh = bank_face(bank, mesh=mesh)
    poses = plate_poses(bank_mesh, track)
    compositor = PlateCompositor(mask, lut=colour_table(bank, video, track, poses, bank_mesh, mask))
    seconds["face"] = time.perf_counter() - t

    t = time.perf_counter()
    if not isinstance(store, FlowStore):
        store = FlowStore.for_bank(bank, store)
    anim = Animator(bank, alignment.phones, fps=info.fps, map=map, timing=timing, store=store, still=True)
    anim.alignment = alignment
    n = len(anim)
    if n == 0:
        raise InputError("the speech lasts 0 s: there is no frame to write", path=audio)
    from ..morphing.preprocess import all_pairs, preprocess

    nb = anim.renderer.nb
    if any(not store.pair_path(store.pair_key(bank, a, b, nb.axis)).exists() for a, b in all_pairs(bank.names)):
        preprocess(bank, store=store, jobs=jobs, quiet=quiet, normalised=nb)
    sample_path = _sample_path(bank, anim, sample_option, compositor, store, samples)
    seconds["align"] += time.perf_counter() - t

    t = time.perf_counter()
    nv = len(track)
    plate_of = video_frames_for(track, n, plate_start or 0.0)
    lost = tuple(i for i in range(n) if not track.found[plate_of[i]])
    if lost:
        warnings.warn(f"{video}: no face in the video at output frame(s) {lost_frames_text(lost, info.fps)}; "
                      f"those frames are written as they are", DubWarning, stacklevel=2)
    anim.renderer.frame_threads = 1  # whole frames run in parallel instead
    bank_shape = anim.renderer.shape + (anim.renderer.channels,)
    scratch = threading.local()
    output.parent.mkdir(parents=True, exist_ok=True)
    straight = bool(np.all(np.diff(plate_of) == 1)) if n > 1 else True
    reader = _PlateReader(video, info, keep=not straight, count=nv)
    shape = (info.size[1], info.size[0], 3)
    geometry = [compositor.geometry(p, shape) if found else None for p, found in zip(poses, track.found)]
    sample_geometry = geometry if sample_path is None else [
        sample_path.compositor.plate.geometry(p, shape) if found else None for p, found in zip(poses, track.found)]

    def render_into(i: int, buf: np.ndarray) -> None:
        j = plate_of[i]
        np.copyto(buf, reader.get(j))
        if not track.found[j]:
            return
        mouth = getattr(scratch, "frame", None)
        if mouth is None:
            mouth = scratch.frame = np.empty(bank_shape, np.uint8)
        if sample_path is not None:
            sample_path.render_onto(i, buf, poses[j], geometry=sample_geometry[j])
            return
        s = anim.specs[i]  # only the lower face's box of the morph is read: only that box is rendered
        anim.renderer.render(s.from_viseme, s.to_viseme, s.alpha, out=mouth, region=compositor.region)
        compositor.apply(mouth[..., :3], buf, poses[j], geometry[j])

    w, h = info.size
    encoder_threads = 1 if (os.cpu_count() or 1) <= SINGLE_ENCODER_THREAD_CORES else None
    try:
        with open_writer(output, fps=info.fps, size=(w, h), format=out_format, audio=audio, crf=crf, preset=preset,
                         quiet=True, frames=n, threads=encoder_threads) as writer:
            with tqdm(total=n, desc="dub", unit="frame", disable=quiet, leave=False) as bar:
                render_parallel(render_into, n, (h, w, 3), writer.write_prepared, progress=lambda d: bar.update(1),
                                prepare=writer.prepare)
    except OSError as exc:
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):  # the encoder has removed its partial output
            raise InputError("cannot write: disk full (nothing was written)", path=output) from None
        raise
    finally:
        reader.close()
    seconds["render"] = time.perf_counter() - t
    return DubReport(output=str(output), frames=n, fps=float(info.fps), size=(w, h), video_frames=nv, lost=lost,
                     bank=str(bank.path), seconds=seconds)


def _sample_path(bank, anim, option, compositor, store, speech=None):
    """The dub's :class:`~lipsync.pipeline.samplepath.SamplePath` (None: the bank has no samples
    or they are off); ``speech``: the new speech's 16 kHz samples (the audio target's)."""
    from .samplepath import SamplePath, bank_samples

    got = bank_samples(bank, option)
    if got is None or not anim.specs:
        return None
    return SamplePath(got, anim.specs, anim.phones, anim.fps, anim.pmap, bank.rest, lut=compositor.lut, store=store,
                      timing=anim.timing, audio=speech)
