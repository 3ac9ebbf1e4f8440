"""The idle plate: a stretch of the speaker's own video kept in the bank, so renders live.

A bank's pictures are stills; a person is not. ``lipsync render`` of a bank with a plate
shows, at every frame, one frame of this stretch (played forwards, and joined to itself
where its frames match, never mid-blink: :mod:`lipsync.composite.plate_time`) with the morphed lower
face moved onto it (:class:`lipsync.composite.plate.PlateCompositor`): the blinks, the
glances and the small head motion are the speaker's own.

Chosen here (:func:`choose_stretch`), from the frames :func:`lipsync.videobank.make_bank`
has already tracked and registered: the window of :data:`PLATE_SECONDS` (or the whole
video, if shorter) in which the **lower face moves least** (the jaw's drop and the lips'
opening, frame to frame, in eye distances: speech there would show around the mask's
edge), the **face above the nose moves as the speaker's does** (not stiller: within
:data:`NATURAL_BAND` of the footage's mean, :func:`upper_motion`), the **head moves least** (the still points' centre, frame to frame, and how far it
wanders over the window) and turns least (the stabilisation residual), with the face found
in every frame; shorter windows (down to 1.5 s) when no 4 s one keeps the head still.
The frames are cut by **one** transform for the whole stretch (stabilised: the crop does
not jitter with the tracker, while the head keeps its own motion inside it): the footage's
own pixels, a whole-pixel window about where the stretch's mean pose puts the bank's
picture (:func:`plate_cut`; a bank of another size is resampled at the mean pose), and each
frame's own pose is stored as the 2x3 matrix taking bank pixels to that plate frame's pixels.

Written into the bank (bank.yaml ``plate: {video: plate.mp4, poses: plate.json, mask:
plate-mask.png}``):

* ``plate.mp4`` — the frames at the bank's size (H.264, crf :data:`PLATE_CRF`);
* ``plate.json`` — ``fps``, per-frame ``poses``, where the stretch came from;
* ``plate-mask.png`` — the lower-face mask in bank pixels (the union over the visemes'
  pictures: the widest jaw stays inside it), grey 0-255.

Examples
--------
>>> import numpy as np
>>> motion = np.array([5, 5, 0, 0, 0, 0, 5, 5], float)
>>> best_window(motion, 3)
(2, 5)
>>> head = np.array([[0, 0], [0, 0], [0, 0], [0, 0], [9, 0], [9, 0], [9, 0], [9, 0]], float)
>>> best_window(motion, 3, head)       # the head jumps at frame 4: the window before it
(1, 4)
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Tuple

import numpy as np

#: bank.yaml's file names.
VIDEO_NAME, POSES_NAME, MASK_NAME = "plate.mp4", "plate.json", "plate-mask.png"
#: Length of the idle stretch: long enough to hold a blink or two (people blink every
#: 2-10 s) and a few glances; longer output joins it to itself (lipsync.composite.plate_time).
PLATE_SECONDS = 4.0
#: Lengths tried, longest first, until one is idle (:data:`IDLE_SPREAD`).
PLATE_LENGTHS = (PLATE_SECONDS, 3.0, 2.0, 1.5)
#: Shorter lengths tried only when no window of PLATE_LENGTHS has the face in every frame
#: (a face that leaves the picture every second, issue 38): a short plate is extended by
#: joins (lipsync.composite.plate_time), and 0.5 s still holds a blink's whole 0.2-0.4 s.
SHORT_LENGTHS = (1.0, 0.5)
#: A stretch whose head wanders more than this (standard deviation of the still points'
#: centre, eye distances) is not idle: the 2-D pose cannot follow a head that turns, and
#: the pasted lower face then shows it (a webcam speaker looking down at a keyboard,
#: tools/other_face.py: 0.3-0.5 over 4 s; GRID's still speaker under 0.03).
IDLE_SPREAD = 0.05
#: The plate is the footage's own pixels, a whole-pixel window (:func:`plate_cut`), when the
#: stretch's mean pose scales it by at most this share: the window then holds the framing's
#: field to within 10 % (the eye line to the crop's bottom, stabilise.BOTTOM's 3.0 eye
#: distances, stays above BOTTOM_NEEDED's 2.3; the sides' 2.6 above 1.3), while the resample
#: it saves would keep only 0.92-0.97 of the mouth's Laplacian variance even with Lanczos4
#: (lipsync.videobank.cut.INTERPOLATION) and 0.52-0.66 with the bilinear warp the plate had.
#: A bank asked for another size (``--size``) or shrunk to ``max_side`` is resampled.
PLATE_SCALE_BAND = 0.1
#: x264 quality of plate.mp4: near-transparent (the plate is shown as it is in every frame,
#: so its own compression would add to the render's).
PLATE_CRF = 12
#: A head pose residual (eye distances, lipsync.videobank.stabilise) counts this much
#: against a window per unit of lower-face motion: 0.01 eye distances of head turn weigh as
#: much as the jaw moving 0.01 eye distances a frame.
RESIDUAL_WEIGHT = 1.0
#: The head's own steps (the eyes' centre, eye distances per frame) count this much: a step
#: of the whole head is seen all over the picture, a jaw's only around the mask's edge.
HEAD_WEIGHT = 2.0
#: The plate moves as the speaker does, not less (issue 36: grid-s1's stillest clip moved a
#: quarter as much above the nose as the speaker's footage): a stretch whose motion above the
#: nose (:func:`upper_motion`, mean) is within this share of the footage's own is natural;
#: one outside it loses to any inside it (after idleness and length).
NATURAL_BAND = 0.4
#: Within a video, each frame's distance from the footage's typical motion above the nose
#: (eye distances per frame) counts this much in the window's cost: still frames cost too.
NATURAL_WEIGHT = 2.0


@dataclass(frozen=True)
class Stretch:
    """The chosen frames: ``video`` (index), ``[start, stop)``, with what they scored."""

    video: int
    start: int
    stop: int
    motion: float      # mean lower-face motion, eye distances per frame
    residual: float    # median pose residual, eye distances
    spread: float = 0.0  # how far the head wanders in it (SD of the still points' centre), eye distances
    natural: float = 1.0  # its motion above the nose over the footage's (upper_motion, means)

    def __len__(self) -> int:
        return self.stop - self.start


def best_window(cost: np.ndarray, length: int, spread=None) -> Tuple[int, int]:
    """``(start, stop)`` of the ``length``-frame window of least mean ``cost`` (NaN: not
    allowed) plus, when given, ``spread`` ``(N, 2)``'s standard deviation over the window
    (its points' distance from their mean: how far the head wanders in it).

    Returns ``(0, 0)`` when no window is free of NaN.
    """
    c = np.asarray(cost, np.float64)
    bad = ~np.isfinite(c)
    c = np.where(bad, 0.0, c)
    if len(c) < length or length < 1:
        return 0, 0
    s = np.concatenate([[0.0], np.cumsum(c)])
    b = np.concatenate([[0], np.cumsum(bad)])
    score = (s[length:] - s[:-length]) / length
    if spread is not None:
        x = np.where(bad[:, None], 0.0, np.asarray(spread, np.float64))
        s1 = np.concatenate([np.zeros((1, 2)), np.cumsum(x, axis=0)])
        s2 = np.concatenate([np.zeros((1, 2)), np.cumsum(x * x, axis=0)])
        m1 = (s1[length:] - s1[:-length]) / length
        m2 = (s2[length:] - s2[:-length]) / length
        score = score + np.sqrt(np.maximum((m2 - m1 * m1).sum(axis=1), 0.0))
    score[(b[length:] - b[:-length]) > 0] = np.inf
    i = int(np.argmin(score))
    if not np.isfinite(score[i]):
        return 0, 0
    return i, i + length


def head_motion(points: np.ndarray) -> np.ndarray:
    """Per frame, how far the still points' centre (eye corners, nose bridge: not the lids,
    so a blink is not a move) went since the frame before, eye distances (0 for frame 0, NaN
    without a face): a head that nods or turns to look at a keyboard is not idle, however
    still its jaw."""
    from ..face import topology as T
    from ..face.measure import eye_distance

    p = np.asarray(points, np.float64)
    c = p[:, list(T.STILL_POINTS), :2].mean(axis=1)
    out = np.zeros(len(p))
    out[1:] = np.hypot(*np.diff(c, axis=0).T) / eye_distance(p)[1:]
    return out


def upper_motion(points: np.ndarray) -> np.ndarray:
    """Per frame, how far the face-mesh points above the nose tip (brows, lids, eyes, the
    nose's bridge) moved since the frame before, mean over the points, eye distances (0 for
    frame 0, NaN without a face): the head's motion and the eyes' together, as they are seen."""
    from ..face.measure import eye_distance

    p = np.asarray(points, np.float64)[..., :2]
    ref = np.nanmedian(p, axis=0)
    above = np.nonzero(ref[:, 1] < ref[4, 1])[0]  # point 4: the nose tip
    out = np.zeros(len(p))
    if above.size and len(p) > 1:
        out[1:] = np.linalg.norm(np.diff(p[:, above], axis=0), axis=-1).mean(axis=-1) / eye_distance(p)[1:]
    return out


def lower_face_motion(points: np.ndarray) -> np.ndarray:
    """Per frame, how far the jaw and lips moved since the frame before, eye distances (NaN
    where either frame lacks a face; frame 0 is 0)."""
    from ..face import measure as M

    jaw = _jaw_drop(points)
    opening = M.lip_opening(points)
    out = np.zeros(len(points))
    out[1:] = np.abs(np.diff(jaw)) + np.abs(np.diff(opening))
    return out


def _jaw_drop(points: np.ndarray) -> np.ndarray:
    """Chin (152) below the nose tip (4), over the eye distance."""
    from ..face.measure import eye_distance

    p = np.asarray(points, np.float64)
    return np.hypot(*(p[:, 152, :2] - p[:, 4, :2]).T) / eye_distance(p)


def choose_stretch(footage) -> Stretch:
    """The best idle stretch of the footage (see the module docstring)."""
    from ..face import topology as T
    from ..face.measure import eye_distance

    best = None
    ups = [upper_motion(tr.points) for tr in footage.tracks]
    for u, tr in zip(ups, footage.tracks):
        u[~tr.found] = np.nan
        u[1:][~tr.found[:-1]] = np.nan  # a step from a frame without a face is no step
    everything = np.concatenate(ups)
    # the speaker's own motion above the nose
    typical = float(np.nanmean(everything)) if np.isfinite(everything).any() else 0.0
    for v, (tr, reg) in enumerate(zip(footage.tracks, footage.regs)):
        n = len(tr)
        cost = lower_face_motion(tr.points) + HEAD_WEIGHT * head_motion(tr.points) + RESIDUAL_WEIGHT * reg.residual
        cost = cost + NATURAL_WEIGHT * np.abs(np.nan_to_num(ups[v], nan=typical) - typical)
        cost[~tr.found] = np.nan
        # where the head is (the still points' centre, eye distances): a window in which it
        # wanders far is not idle, even if it moves slowly
        d = float(np.nanmedian(eye_distance(tr.points)))
        where = tr.points[:, list(T.STILL_POINTS), :2].mean(axis=1) / d * HEAD_WEIGHT
        for seconds in PLATE_LENGTHS + SHORT_LENGTHS:
            length = min(n, int(round(seconds * tr.fps)))
            a, b = best_window(cost, length, where)
            if b == 0:
                continue  # the face lost somewhere in every window: shorter
            spread = float(np.sqrt(np.nansum(np.nanvar(where[a:b] / HEAD_WEIGHT, axis=0))))
            if spread <= IDLE_SPREAD or seconds <= PLATE_LENGTHS[-1] or length == n:
                break
        if b == 0:
            continue
        natural = float(np.nanmean(ups[v][a + 1:b])) / max(typical, 1e-9) if b - a > 1 else 1.0
        s = Stretch(video=v, start=a, stop=b, motion=float(np.nanmean(lower_face_motion(tr.points)[a:b])),
                    residual=float(np.nanmedian(reg.residual[a:b])), spread=spread, natural=natural)
        # idle first, then longer (more life), then moving as the speaker does, then the cost
        key = (spread > IDLE_SPREAD, -len(s), max(0.0, abs(natural - 1.0) - NATURAL_BAND),
               float(np.mean(cost[a:b])) + spread)
        if best is None or key < best[0]:
            best = (key, s)
    if best is None:
        from ..errors import InputError

        raise InputError(f"no {SHORT_LENGTHS[-1]:g} s of video with the face in every frame, for the idle plate "
                         f"(the face leaves the picture, or is lost, too often: film it in view)",
                         path=footage.names)
    return best[1]


def _eyes(points: np.ndarray, found: np.ndarray) -> np.ndarray:
    from ..face.measure import eye_opening

    e = eye_opening(points)
    e[~np.asarray(found, bool)] = np.nan
    return e


def plate_cut(matrix: np.ndarray, size: Tuple[int, int], source_size: Tuple[int, int]) -> np.ndarray:
    """The plate's cut (2x3, video pixels -> plate pixels): the footage's own pixels, a
    whole-pixel window of ``size`` (W, H) about where the stretch's mean pose ``matrix``
    puts the plate's centre, kept inside the video's ``source_size`` picture -- unless the
    mean pose scales by more than :data:`PLATE_SCALE_BAND` (or the picture is smaller than
    the plate): then ``matrix`` itself (one resample, :data:`lipsync.videobank.cut.INTERPOLATION`).

    The plate is shown as it is in every rendered frame, so a resample here would soften
    every mouth pasted on it; the head's roll and the few per cent of scale the mean pose
    would have taken out go into the per-frame poses instead (bank -> plate pixels), which
    every paste and morph applies anyway.

    Examples
    --------
    >>> m = np.array([[0.97, -0.02, -30.3], [0.02, 0.97, -20.6]])
    >>> plate_cut(m, (100, 80), (360, 288)).tolist()
    [[1.0, 0.0, -34.0], [0.0, 1.0, -21.0]]
    >>> plate_cut(m * 0.5, (100, 80), (360, 288)).tolist() == (m * 0.5).tolist()   # half the size: resampled
    True
    """
    from ..composite.plate import pose_inverse

    m = np.asarray(matrix, np.float64)
    (w, h), (sw, sh) = size, source_size
    scale = float(np.sqrt(abs(np.linalg.det(m[:, :2]))))
    if abs(scale - 1.0) > PLATE_SCALE_BAND or w > sw or h > sh:
        return m
    centre = pose_inverse(m) @ np.array([(w - 1) / 2.0, (h - 1) / 2.0, 1.0])
    x = min(max(int(np.floor(centre[0] - (w - 1) / 2.0 + 0.5)), 0), sw - w)
    y = min(max(int(np.floor(centre[1] - (h - 1) / 2.0 + 0.5)), 0), sh - h)
    return np.array([[1.0, 0.0, -float(x)], [0.0, 1.0, -float(y)]])


def stretch_poses(framing, reg, start: int, stop: int, source_size=None) -> Tuple[np.ndarray, np.ndarray]:
    """The plate's cut (2x3, video pixels -> plate pixels, one for the whole stretch: its
    mean pose; with the video's ``source_size`` (W, H), :func:`plate_cut`'s whole-pixel
    window where it can) and each frame's pose (``(N, 2, 3)``, bank pixels -> plate pixels,
    through that cut)."""
    from ..composite.plate import compose, pose_inverse
    from .stabilise import Registration

    idx = np.arange(start, stop)
    mean = Registration(c=np.array([reg.c[idx].mean()]), t=np.array([reg.t[idx].mean()]),
                        residual=np.zeros(1))
    cut = framing.matrix(mean, 0)
    if source_size is not None:
        cut = plate_cut(cut, framing.size, source_size)
    poses = np.stack([compose(cut, pose_inverse(framing.matrix(reg, int(f)))) for f in idx])
    return cut, poses


def write_plate(folder: Path, footage, framing, meshes, rest: str) -> str:
    """Write the plate files into ``folder`` and return the bank.yaml lines that name them.

    ``framing`` is the bank pictures' (:class:`~lipsync.videobank.stabilise.Framing`),
    ``meshes`` each viseme's face mesh in its picture's pixels, ``rest`` the rest viseme.
    """
    import cv2

    from ..composite.face import mask_from_mesh
    from ..encode import open_writer
    from .cut import grab_frames, warp_frame
    from .write import write_png

    s = choose_stretch(footage)
    src, tr, reg = footage.sources[s.video], footage.tracks[s.video], footage.regs[s.video]
    w, h = framing.size
    frames = grab_frames(src.path, range(s.start, s.stop))
    sh, sw = frames[s.start].shape[:2]
    cut, poses = stretch_poses(framing, reg, s.start, s.stop, (sw, sh))
    with open_writer(folder / VIDEO_NAME, fps=tr.fps, size=(w, h), format="mp4", crf=PLATE_CRF,
                     preset="talking-head", quiet=True, frames=len(s)) as writer:
        for f in range(s.start, s.stop):
            writer.write(warp_frame(frames[f], cut, (w, h)))
    mask = mask_from_mesh(list(meshes.values()), (h, w))
    write_png(folder / MASK_NAME, cv2.cvtColor(np.round(mask * 255).astype(np.uint8), cv2.COLOR_GRAY2RGB))
    doc = {"fps": tr.fps, "frames": len(s), "size": [w, h],
           "source": {"video": src.name, "start_frame": s.start, "stop_frame": s.stop,
                      "lower_face_motion": round(s.motion, 5), "pose_residual": round(s.residual, 5),
                      "head_spread": round(s.spread, 5), "motion_above_nose_vs_footage": round(s.natural, 3),
                      # the cut from the video's pixels (plate_cut: a whole-pixel window, or a resample)
                      "cut": [round(float(x), 5) for x in cut.ravel()]},
           "poses": [[round(float(x), 5) for x in p.ravel()] for p in poses],
           # each frame's eye opening (face mesh, lipsync.face.measure): where its blinks are, which
           # the plate's timeline never joins into or out of (lipsync.composite.plate_time)
           "eyes": [None if not np.isfinite(e) else round(float(e), 5)
                    for e in _eyes(tr.points[s.start:s.stop], tr.found[s.start:s.stop])],
           # the rest picture's face mesh (bank pixels): the plate's colour is matched on its still skin
           "rest_mesh": [[round(float(x), 3) for x in p[:2]] for p in meshes[rest]]}
    (folder / POSES_NAME).write_text(json.dumps(doc) + "\n", encoding="utf-8")
    return f"plate: {{video: {VIDEO_NAME}, poses: {POSES_NAME}, mask: {MASK_NAME}}}\n"
