"""A face followed through a video: the mesh in every frame, smoothed without lag.

**Tracking.** The detector runs only when there is no face to follow (the first frame, or
after the face was lost): each frame's mesh gives the region the next frame's mesh looks in
(:meth:`~lipsync.face.landmarks.Roi.from_landmarks`), as MediaPipe's face-mesh graph does.
That costs one mesh inference a frame. When the mesh's face score drops below
:data:`~lipsync.face.landmarks.MIN_MESH_SCORE` the detector looks again in that same frame.

**Smoothing.** A mesh placed frame by frame jitters by a few tenths of a pixel. A One Euro
filter (Casiez, Roussel & Vogel 2012) smooths strongly while a point is still and hardly at
all while it moves fast, which is what lips need. A causal filter still lags a moving point
a little; a video is processed whole, so the filter is run forwards and backwards and the
two are averaged: their lags cancel (zero phase), so the smoothed lips are not late.

Examples
--------
>>> import numpy as np
>>> t = np.arange(100) / 25.0
>>> x = 0.05 * np.sin(2 * np.pi * 4.0 * t)[:, None]   # lips at 4 Hz, 25 fps
>>> y = smooth(x, 25.0)
>>> float(np.abs(y - x)[10:-10].max()) < 0.005       # followed closely, no lag
True
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, List, Optional, Tuple

import numpy as np

from ..errors import PathLike
from .landmarks import MIN_MESH_SCORE, FaceMesh, FaceWarning, NoFaceError, Roi
from .measure import eye_distance
from .video import probe_video, read_video

#: One Euro parameters, in units of the eye distance (so the same on any face size), chosen
#: on a 3 Hz lip-sized motion (0.05 eye distances) with mesh-sized jitter (0.005, what the mesh
#: shows on GRID's still points): the error against the clean motion drops below the raw
#: points' while a 4 Hz motion keeps 94 % of its amplitude and 6 Hz 86 %.
#: MIN_CUTOFF_HZ: the cutoff of a still point: jitter goes, a slow head drift passes.
MIN_CUTOFF_HZ = 1.5
#: BETA: how fast the cutoff rises with speed (per eye distance per second): lips moving at
#: speech rates (~1 eye distance a second) lift it past 30 Hz, i.e. no smoothing.
BETA = 30.0
#: D_CUTOFF_HZ: cutoff of the speed estimate. The filter's usual 1 Hz is too slow for
#: speech: the speed estimate of a 4 Hz motion lagged so far that its peaks were flattened
#: to half (measured: 46 % of the amplitude kept, three times the raw error).
D_CUTOFF_HZ = 5.0


def _alpha(cutoff, dt: float):
    tau = 1.0 / (2 * np.pi * cutoff)
    return 1.0 / (1.0 + tau / dt)


def one_euro(x: np.ndarray, fps: float, *, min_cutoff: float = MIN_CUTOFF_HZ, beta: float = BETA,
             d_cutoff: float = D_CUTOFF_HZ) -> np.ndarray:
    """The causal One Euro filter along axis 0 of ``x`` (every other axis filtered alike).

    Parameters
    ----------
    x : numpy.ndarray
        ``(N, ...)`` samples at ``fps``.
    fps : float
    min_cutoff, beta, d_cutoff : float
        The filter's parameters (Hz, per unit of ``x`` per second, Hz).

    Returns
    -------
    numpy.ndarray
        float64, the shape of ``x``.

    Examples
    --------
    >>> one_euro(np.array([0.0, 0.0, 1.0, 1.0]), 25.0).round(3).tolist()
    [0.0, 0.0, 0.991, 1.0]
    """
    x = np.asarray(x, np.float64)
    out = np.empty_like(x)
    if len(x) == 0:
        return out
    dt = 1.0 / fps
    a_d = _alpha(d_cutoff, dt)
    prev = out[0] = x[0]
    dprev = np.zeros_like(x[0])
    for i in range(1, len(x)):
        dx = (x[i] - prev) / dt
        dprev = dprev + a_d * (dx - dprev)
        a = _alpha(min_cutoff + beta * np.abs(dprev), dt)
        prev = out[i] = prev + a * (x[i] - prev)
    return out


def smooth(x: np.ndarray, fps: float, **params) -> np.ndarray:
    """Zero-phase One Euro: the mean of the filter run forwards and backwards along axis 0."""
    x = np.asarray(x, np.float64)
    return 0.5 * (one_euro(x, fps, **params) + one_euro(x[::-1], fps, **params)[::-1])


def _runs(found: np.ndarray) -> List[Tuple[int, int]]:
    """``[start, stop)`` of each run of True."""
    edges = np.diff(np.concatenate([[0], found.astype(np.int8), [0]]))
    return list(zip(np.nonzero(edges == 1)[0].tolist(), np.nonzero(edges == -1)[0].tolist()))


def smooth_points(points: np.ndarray, found: np.ndarray, fps: float) -> np.ndarray:
    """Smooth a track's points (``(N, 468, C)``) run by run of found frames, in eye distances."""
    out = np.full(points.shape, np.nan)
    for a, b in _runs(found):
        seg = points[a:b].astype(np.float64)
        d = float(np.median(eye_distance(seg)))
        out[a:b] = smooth(seg / d, fps) * d
    return out


@dataclass(frozen=True)
class FaceTrack:
    """The face mesh in every frame of a video.

    Attributes
    ----------
    points : numpy.ndarray
        float32 ``(N, 468, 3)``, smoothed (:func:`smooth_points`); NaN where no face was found.
    raw : numpy.ndarray
        The same, unsmoothed.
    found : numpy.ndarray
        bool ``(N,)``.
    fps : float
    size : tuple of int
        ``(W, H)``.
    source : str
        The video's path (for messages).
    """

    points: np.ndarray
    raw: np.ndarray
    found: np.ndarray
    fps: float
    size: Tuple[int, int]
    source: str

    def __len__(self) -> int:
        return len(self.found)

    def times(self) -> np.ndarray:
        """Each frame's time in seconds (frame n shows n / fps)."""
        return np.arange(len(self)) / self.fps


class Tracker:
    """Follows one face from frame to frame (see module docstring).

    Parameters
    ----------
    mesh : FaceMesh, optional
        Reuse loaded models (one per thread).
    source : str, optional
        For warnings ("clip.mp4").
    """

    def __init__(self, mesh: Optional[FaceMesh] = None, *, source: Optional[str] = None):
        self.mesh = mesh or FaceMesh()
        self.source = source or "video"
        self._roi: Optional[Roi] = None
        self._warned_several = False

    def step(self, frame: np.ndarray, index: int = 0) -> Optional[np.ndarray]:
        """The mesh points in ``frame`` (``(468, 3)``), or None when there is no face."""
        if self._roi is not None:
            pts, score = self.mesh.landmarks_in(frame, self._roi)
            if score >= MIN_MESH_SCORE:
                self._roi = Roi.from_landmarks(pts)
                return pts
        dets = self.mesh.detect(frame)
        if not dets:
            self._roi = None
            return None
        if len(dets) > 1 and not self._warned_several:
            self._warned_several = True
            warnings.warn(f"{self.source} frame {index}: {len(dets)} faces; following the largest",
                          FaceWarning, stacklevel=2)
        pts, score = self.mesh.landmarks_in(frame, Roi.from_detection(dets[0]))
        if score < MIN_MESH_SCORE:
            self._roi = None
            return None
        # The detector's region is looser than the tracking region: refine once, as the
        # next frame would, so a (re)acquired frame is as precise as a tracked one.
        again, again_score = self.mesh.landmarks_in(frame, Roi.from_landmarks(pts))
        if again_score >= MIN_MESH_SCORE:
            pts = again
        self._roi = Roi.from_landmarks(pts)
        return pts


def track_frames(frames: Iterable[np.ndarray], *, fps: float, size: Optional[Tuple[int, int]] = None,
                 source: Optional[str] = None, mesh: Optional[FaceMesh] = None, smooth: bool = True,
                 progress=None) -> FaceTrack:
    """Track the face through frames (RGB ``uint8``), see :class:`Tracker`.

    Parameters
    ----------
    frames : iterable of numpy.ndarray
    fps : float
    size : tuple of int, optional
        ``(W, H)``; taken from the first frame when not given.
    source : str, optional
        Name for messages.
    mesh : FaceMesh, optional
    smooth : bool
        Smooth the points (zero-phase One Euro); ``raw`` keeps them as placed.
    progress : callable, optional
        Called with 1 after each frame (a tqdm's ``update``).

    Returns
    -------
    FaceTrack

    Raises
    ------
    NoFaceError
        No face in any frame (the message names the source). Frames without a face give one
        :class:`~lipsync.face.landmarks.FaceWarning` naming them.
    """
    tracker = Tracker(mesh, source=source)
    pts: List[Optional[np.ndarray]] = []
    for i, frame in enumerate(frames):
        if size is None:
            size = (frame.shape[1], frame.shape[0])
        pts.append(tracker.step(frame, i))
        if progress is not None:
            progress(1)
    name = source or "video"
    found = np.array([p is not None for p in pts], dtype=bool)
    if not found.any():
        raise NoFaceError(f"no face found in any of its {len(pts)} frames", path=name)
    raw = np.full((len(pts), 468, 3), np.nan, np.float32)
    for i, p in enumerate(pts):
        if p is not None:
            raw[i] = p
    lost = np.nonzero(~found)[0]
    if lost.size:
        runs = _runs(~found)
        shown = ", ".join(f"{a}" if b - a == 1 else f"{a}-{b - 1}" for a, b in runs[:8])
        warnings.warn(f"{name}: no face in {lost.size} of {len(pts)} frames ({shown}"
                      f"{', ...' if len(runs) > 8 else ''})", FaceWarning, stacklevel=2)
    points = smooth_points(raw, found, fps).astype(np.float32) if smooth else raw.copy()
    return FaceTrack(points=points, raw=raw, found=found, fps=float(fps), size=tuple(size or (0, 0)),
                     source=name)


def track_video(path: PathLike, *, smooth: bool = True, quiet: bool = True,
                mesh: Optional[FaceMesh] = None) -> FaceTrack:
    """Track the face through every frame of a video file.

    Parameters
    ----------
    path : path-like
        Any video ffmpeg reads.
    smooth : bool
        See :func:`track_frames`.
    quiet : bool
        No progress bar.
    mesh : FaceMesh, optional

    Returns
    -------
    FaceTrack

    Examples
    --------
    >>> from lipsync.face.track import track_video
    >>> track_video("missing.mp4")
    Traceback (most recent call last):
    ...
    lipsync.errors.InputError: missing.mp4: no such file
    """
    from tqdm import tqdm

    info = probe_video(path)
    name = os.fspath(path)
    with tqdm(total=info.frame_count or None, desc=f"face {Path(name).name}", unit="frame", disable=quiet,
              leave=False) as bar:
        return track_frames(read_video(path, info=info), fps=info.fps, size=info.size, source=name, mesh=mesh,
                            smooth=smooth, progress=bar.update)
