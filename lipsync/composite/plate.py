"""The lower face onto a plate: a morphed mouth moved onto a frame of real video and blended in.

A *plate* is a frame of the speaker's own video: the bank's idle stretch (``lipsync render``
of a bank made from video, bank.yaml ``plate:``) or the video being re-voiced
(``lipsync dub``). Everything on it stays (eyes, blinks, brows, hair, background, the
head's own small motion) except the lower face, which comes from the morphed bank frame::

    morphed bank frame --pose (bank pixels -> plate pixels), lower-face box only-->
    warped mouth --colour LUT--> --feathered mask blend--> plate frame (in place)

Per frame only the rectangle the lower-face mask covers on the plate is touched: the
bank-pixel box of the mask is mapped by the frame's pose, and one affine warp
(``cv2.warpAffine`` with the inverse map, bilinear) fills that rectangle from the bank
frame, one more warps the mask, a look-up table applies the colour match, and one
``cv2.blendLinear`` writes the rectangle of the plate. The mask, its box, the colour table
and the scratch buffers are made once (:class:`PlateCompositor`); the pose is a 2x3 matrix
per frame.

Examples
--------
>>> import numpy as np
>>> mask = np.zeros((40, 60), np.float32); mask[20:36, 10:50] = 1.0
>>> c = PlateCompositor(mask)
>>> mouth = np.full((40, 60, 3), 200, np.uint8)
>>> plate = np.zeros((80, 120, 3), np.uint8)
>>> pose = np.array([[1.0, 0.0, 30.0], [0.0, 1.0, 10.0]])     # the bank 30 px right, 10 down
>>> out = c.apply(mouth, plate, pose)
>>> int(out[38, 60, 0]), int(out[10, 60, 0]), int(out[38, 5, 0])
(200, 0, 0)
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

import cv2
import numpy as np

__all__ = ["Plate", "PlateCompositor", "load_plate", "pingpong", "pose_inverse", "compose", "colour_lut",
           "plate_colour"]

#: Mask values below this count as outside (the feather's last sliver is invisible, and the
#: box it would add is pure cost).
MASK_FLOOR = 1.0 / 255.0
#: Plate frames the colour match is measured on, spread over the plate or video: more only
#: average the same light.
COLOUR_SAMPLES = 5


def pingpong(i: int, n: int) -> int:
    """The plate frame shown at output frame ``i`` of a plate of ``n`` frames, played
    forwards then backwards (``0 1 .. n-1 n-2 .. 1 0 1 ..``): no frame repeats at the turns,
    so there is no loop seam and no held frame.

    Examples
    --------
    >>> [pingpong(i, 4) for i in range(10)]
    [0, 1, 2, 3, 2, 1, 0, 1, 2, 3]
    >>> [pingpong(i, 1) for i in range(3)]
    [0, 0, 0]
    """
    if n <= 1:
        return 0
    period = 2 * (n - 1)
    k = i % period
    return k if k < n else period - k


def pose_inverse(m: np.ndarray) -> np.ndarray:
    """The inverse of a 2x3 affine matrix.

    Examples
    --------
    >>> m = np.array([[2.0, 0.0, 4.0], [0.0, 2.0, -2.0]])
    >>> (pose_inverse(m) + 0.0).tolist()
    [[0.5, 0.0, -2.0], [0.0, 0.5, 1.0]]
    """
    return cv2.invertAffineTransform(np.asarray(m, np.float64))


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a`` after ``b`` (2x3 affine matrices): the point ``p`` goes to ``a(b(p))``.

    Examples
    --------
    >>> a = np.array([[1.0, 0.0, 5.0], [0.0, 1.0, 0.0]]); b = np.array([[2.0, 0.0, 0.0], [0.0, 2.0, 1.0]])
    >>> compose(a, b).tolist()
    [[2.0, 0.0, 5.0], [0.0, 2.0, 1.0]]
    """
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.hstack([a[:, :2] @ b[:, :2], (a[:, :2] @ b[:, 2] + a[:, 2])[:, None]])


def colour_lut(gains: Sequence[float], offsets: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """A ``cv2.LUT`` table ``(1, 256, 3)``: ``gain * value + offset`` per channel (rounded,
    clipped), :func:`lipsync.composite.face.apply_colour`'s table, applied in place.

    Examples
    --------
    >>> colour_lut([1.0, 0.5, 2.0], [0, 1, 0])[0, 100].tolist()
    [100, 51, 200]
    """
    v = (np.arange(256, dtype=np.float64)[:, None] * np.asarray(gains, np.float64)[None, :]
         + np.asarray(offsets, np.float64)[None, :])
    return np.clip(np.round(v), 0, 255).astype(np.uint8)[None]


@dataclass(frozen=True)
class Prepared:
    """One pose's share of :meth:`PlateCompositor.apply`, made by :meth:`PlateCompositor.prepare`."""

    roi: Tuple[int, int, int, int]
    map1: np.ndarray   # cv2.remap's fixed-point maps (CV_16SC2 + interpolation table)
    map2: np.ndarray
    mask: np.ndarray   # float32, the mask warped onto the ROI
    rest: np.ndarray   # 1 - mask


class PlateCompositor:
    """Blends a morphed bank frame's lower face onto plate frames (see the module docstring).

    Parameters
    ----------
    mask : numpy.ndarray
        float32 ``(H, W)`` in bank pixels, 1 where the morphed frame is shown, 0 where the
        plate is, feathered between (the lower-face mask of
        :mod:`lipsync.composite.face`).
    lut : numpy.ndarray, optional
        ``(1, 256, 3)`` colour table applied to the morphed pixels (:func:`colour_lut`):
        the bank's colour matched to the plate's on the skin around the mask.

    Notes
    -----
    :meth:`apply` may run on several threads at once (scratch is per thread).
    """

    def __init__(self, mask: np.ndarray, *, lut: Optional[np.ndarray] = None):
        mask = np.ascontiguousarray(mask, np.float32)
        ys, xs = np.nonzero(mask >= MASK_FLOOR)
        if ys.size == 0:
            raise ValueError("the lower-face mask is empty")
        #: ``(x0, y0, x1, y1)``: the mask's box in bank pixels (exclusive ends).
        self.box = (int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1)
        x0, y0, x1, y1 = self.box
        self.mask = mask
        self._mask_box = np.ascontiguousarray(mask[y0:y1, x0:x1])
        from ..morphing.store import Crop

        #: The same box as a :class:`lipsync.morphing.store.Crop`: all a renderer need make of a frame.
        self.region = Crop(y0, y1, x0, x1)
        self.lut = lut
        self._local = threading.local()

    def roi(self, pose: np.ndarray, plate_shape: Tuple[int, int]) -> Optional[Tuple[int, int, int, int]]:
        """``(x0, y0, x1, y1)`` of the plate pixels the mask reaches under ``pose``, clipped
        to the plate (None when it falls outside)."""
        x0, y0, x1, y1 = self.box
        corners = np.array([[x0 - 0.5, y0 - 0.5], [x1 - 0.5, y0 - 0.5], [x0 - 0.5, y1 - 0.5], [x1 - 0.5, y1 - 0.5]])
        p = corners @ np.asarray(pose, np.float64)[:, :2].T + np.asarray(pose, np.float64)[:, 2]
        h, w = plate_shape[:2]
        # one pixel of margin: bilinear sampling reaches half a pixel past a corner
        rx0, ry0 = max(0, int(np.floor(p[:, 0].min())) - 1), max(0, int(np.floor(p[:, 1].min())) - 1)
        rx1, ry1 = min(w, int(np.ceil(p[:, 0].max())) + 2), min(h, int(np.ceil(p[:, 1].max())) + 2)
        if rx0 >= rx1 or ry0 >= ry1:
            return None
        return rx0, ry0, rx1, ry1

    def _scratch(self, h: int, w: int, channels: int):
        s = getattr(self._local, "bufs", None)
        if s is None or s[0].shape[0] < h or s[0].shape[1] < w:
            # grown to fit, with room: a head moving nearer the camera does not reallocate
            # every frame
            hh, ww = int(h * 1.25) + 8, int(w * 1.25) + 8
            s = self._local.bufs = (np.empty((hh, ww, channels), np.uint8), np.empty((hh, ww), np.float32),
                                    np.empty((hh, ww), np.float32))
        return s

    def prepare(self, pose: np.ndarray, plate_shape) -> Optional["Prepared"]:
        """Everything :meth:`apply` works out from ``pose`` alone, made once: the ROI, the
        warp as fixed-point ``cv2.remap`` maps and the warped mask and its complement. A
        plate of N frames shown again and again (the idle plate) pays this N times, not
        once per output frame (about half of :meth:`apply`'s work at the bank's size)."""
        r = self.roi(pose, plate_shape)
        if r is None:
            return None
        inv = self._inverse(pose, r)
        rx0, ry0, rx1, ry1 = r
        h, w = ry1 - ry0, rx1 - rx0
        xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        mx = (inv[0, 0] * xs + inv[0, 1] * ys + inv[0, 2]).astype(np.float32)
        my = (inv[1, 0] * xs + inv[1, 1] * ys + inv[1, 2]).astype(np.float32)
        m1, m2 = cv2.convertMaps(mx, my, cv2.CV_16SC2)
        m = cv2.remap(self._mask_box, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        return Prepared(roi=r, map1=m1, map2=m2, mask=m, rest=np.subtract(1.0, m))

    def apply_prepared(self, mouth: np.ndarray, plate: np.ndarray, prep: Optional["Prepared"]) -> np.ndarray:
        """:meth:`apply` with the pose's work done by :meth:`prepare`."""
        if prep is None:
            return plate
        rx0, ry0, rx1, ry1 = prep.roi
        h, w = ry1 - ry0, rx1 - rx0
        bx0, by0, bx1, by1 = self.box
        img = self._scratch(h, w, plate.shape[2])[0][:h, :w]
        cv2.remap(mouth[by0:by1, bx0:bx1], prep.map1, prep.map2, cv2.INTER_LINEAR, dst=img,
                  borderMode=cv2.BORDER_REPLICATE)
        if self.lut is not None:
            cv2.LUT(img, self.lut, dst=img)
        dst = plate[ry0:ry1, rx0:rx1]
        cv2.blendLinear(img, dst, prep.mask, prep.rest, dst=dst)
        return plate

    def _inverse(self, pose: np.ndarray, r) -> np.ndarray:
        """Plate ROI pixels -> bank-box pixels: the inverse pose, shifted by both origins."""
        bx0, by0 = self.box[:2]
        return compose(np.array([[1.0, 0.0, -bx0], [0.0, 1.0, -by0]]),
                       compose(pose_inverse(pose), np.array([[1.0, 0.0, r[0]], [0.0, 1.0, r[1]]])))

    def geometry(self, pose: np.ndarray, plate_shape) -> Optional[tuple]:
        """``(roi, inverse)``: the pose's rectangle on the plate and the 2x3 map from it back
        to the mask's box, for :meth:`apply` (a dub works them out for every video frame
        before the first is composited: matrix arithmetic in Python costs as much per frame
        as a tenth of the pixel work at 360x288)."""
        r = self.roi(pose, plate_shape)
        return None if r is None else (r, self._inverse(pose, r))

    def apply(self, mouth: np.ndarray, plate: np.ndarray, pose: np.ndarray, geometry=None) -> np.ndarray:
        """Write the lower face of ``mouth`` (a bank frame, RGB) onto ``plate`` in place and
        return ``plate``.

        Parameters
        ----------
        mouth : numpy.ndarray
            ``(H, W, 3)`` morphed bank frame (only the mask's box is read).
        plate : numpy.ndarray
            ``(Hp, Wp, 3)`` writable plate frame; only :meth:`roi` is written.
        pose : numpy.ndarray
            2x3 matrix taking bank pixels to plate pixels.
        geometry : tuple, optional
            :meth:`geometry` of ``pose`` on this plate's shape, if made beforehand.
        """
        g = self.geometry(pose, plate.shape) if geometry is None else geometry
        if g is None:
            return plate
        (rx0, ry0, rx1, ry1), inv = g
        h, w = ry1 - ry0, rx1 - rx0
        bx0, by0, bx1, by1 = self.box
        img, m, m1 = self._scratch(h, w, plate.shape[2])
        img, m, m1 = img[:h, :w], m[:h, :w], m1[:h, :w]
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        src = mouth[by0:by1, bx0:bx1]
        cv2.warpAffine(src, inv, (w, h), dst=img, flags=flags, borderMode=cv2.BORDER_REPLICATE)
        cv2.warpAffine(self._mask_box, inv, (w, h), dst=m, flags=flags, borderMode=cv2.BORDER_CONSTANT,
                       borderValue=0.0)
        if self.lut is not None:
            cv2.LUT(img, self.lut, dst=img)
        np.subtract(1.0, m, out=m1)
        dst = plate[ry0:ry1, rx0:rx1]
        cv2.blendLinear(img, dst, m, m1, dst=dst)
        return plate


def plate_colour(image: np.ndarray, mesh: np.ndarray, mask: np.ndarray, frames, poses) -> np.ndarray:
    """The per-channel gains (for :func:`colour_lut`) taking ``image`` (a bank picture with face mesh
    ``mesh`` and lower-face ``mask``, bank pixels) to the colour of plate ``frames``: one gain
    per channel, the ratio of the mean colours of the **skin where the two pictures meet** --
    inside the mask's outline above the upper lip (the skin under the nose and the cheeks
    beside it: skin in every frame, whatever the mouth does) -- each plate frame brought into
    bank pixels by its pose; the median over the frames.

    Measured there rather than on the forehead: light falls differently on the lower face
    (another session's pictures matched on the forehead still left a step of ~10 grey levels
    at the mask's top edge on GRID). A gain rather than a least-squares gain and offset:
    on pixels that are not exactly aligned (another moment's face moved by a similarity) a
    regression's gain shrinks toward 0 with the misalignment and flattens the face.

    Examples
    --------
    >>> img = np.full((40, 40, 3), 100, np.uint8)
    >>> mesh = np.zeros((468, 2)); mesh[0] = (20, 30)
    >>> mask = np.zeros((40, 40), np.float32); mask[10:38, 5:35] = 1
    >>> plate = np.full((40, 40, 3), 120, np.uint8)
    >>> plate_colour(img, mesh, mask, [plate], [np.array([[1.0, 0, 0], [0, 1.0, 0]])]).round(3).tolist()
    [1.2, 1.2, 1.2]
    """
    from .face import GAIN_RANGE

    h, w = image.shape[:2]
    top_of_lip = float(np.asarray(mesh, np.float64)[0, 1])  # mesh point 0: the upper lip's top, midline
    where = (mask > 0) & (np.arange(h)[:, None] < top_of_lip)
    if not where.any():
        return np.ones(3)
    ours = image[..., :3][where].astype(np.float64).mean(axis=0)
    gains = [cv2.warpAffine(np.ascontiguousarray(f), np.asarray(p, np.float64), (w, h),
                            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)[where].astype(np.float64).mean(axis=0)
             / np.maximum(ours, 1.0) for f, p in zip(frames, poses)]
    return np.clip(np.median(gains, axis=0), *GAIN_RANGE)


class Plate:
    """A bank's idle plate in memory: frames, each frame's pose, and the compositor.

    Attributes
    ----------
    frames : numpy.ndarray
        ``(N, H, W, 3)`` RGB, the bank's size (decoded once).
    poses : numpy.ndarray
        ``(N, 2, 3)``: bank pixels -> plate frame pixels.
    fps : float
        The plate's frame rate (the source video's).
    compositor : PlateCompositor
    """

    def __init__(self, frames: np.ndarray, poses: np.ndarray, fps: float, compositor: PlateCompositor,
                 eyes: Optional[np.ndarray] = None):
        self.frames, self.poses, self.fps, self.compositor = frames, poses, float(fps), compositor
        self._prepared = None if compositor is None else [compositor.prepare(p, frames.shape[1:]) for p in poses]
        #: The box of the morphed frame the compositor reads (a :class:`lipsync.morphing.store.Crop`).
        self.region = None if compositor is None else compositor.region
        #: Eye opening per frame (:func:`lipsync.face.measure.eye_opening`), for the blinks.
        self.eyes = None if eyes is None else np.asarray(eyes, np.float64)
        self._times = None
        self._default_line = None
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def times(self):
        """The plate's :class:`lipsync.composite.plate_time.PlateTimes` (made once): joins
        judged on the pixels above the lower-face mask (grey, 4x smaller), blinks on
        :attr:`eyes`."""
        with self._lock:
            if self._times is None:
                from .plate_time import PlateTimes

                top = self.compositor.box[1] if self.compositor is not None else self.frames.shape[1] // 2
                grey = self.frames[:, :max(top, 1), :, 1].astype(np.float32)
                size = (max(1, grey.shape[2] // 4), max(1, grey.shape[1] // 4))
                small = np.stack([cv2.resize(g, size, interpolation=cv2.INTER_AREA) for g in grey])
                eyes = self.eyes if self.eyes is not None and len(self.eyes) == len(self) else np.ones(len(self))
                self._times = PlateTimes(small.reshape(len(self), -1), eyes, self.fps)
            return self._times

    def timeline(self, start: float = 0.0):
        """A clip's :class:`lipsync.composite.plate_time.PlateTimeline` starting at
        ``start`` seconds on the plate (wrapped to its length)."""
        from .plate_time import PlateTimeline

        return PlateTimeline(self.times, start=(float(start) * self.fps / max(len(self), 1)) % 1.0)

    def index(self, i: int, fps: float, timeline=None) -> int:
        """The plate frame shown at output frame ``i`` of a render at ``fps``: output time
        ``i / fps`` on the plate's own clock, along ``timeline`` (a
        :class:`~lipsync.composite.plate_time.PlateTimeline`; default: one from the plate's
        start) -- straight on, then joined where the plate's frames match, never ping-pong.

        Examples
        --------
        >>> p = Plate(np.zeros((3, 2, 2, 3), np.uint8), np.zeros((3, 2, 3)), 25.0, None)
        >>> [p.index(i, 25.0) for i in range(3)], p.index(2, 50.0)
        ([0, 1, 2], 1)
        """
        k = int(np.floor(i * self.fps / fps + 1e-9))
        if timeline is None:
            if self._default_line is None:
                self._default_line = self.timeline(0.0)
            timeline = self._default_line
        return timeline.frame(k)

    def render_into(self, i: int, fps: float, mouth: np.ndarray, out: np.ndarray, timeline=None) -> np.ndarray:
        """Output frame ``i``: plate frame :meth:`index` with ``mouth``'s lower face on it."""
        j = self.index(i, fps, timeline)
        np.copyto(out, self.frames[j])
        return self.compositor.apply_prepared(mouth, out, self._prepared[j])


def load_plate(bank) -> Optional[Plate]:
    """The bank's plate (bank.yaml ``plate:``), or None when it has none or it is switched off.

    Raises
    ------
    lipsync.errors.BankError
        A plate file that does not read (names it).
    """
    import json

    from ..errors import BankError
    from ..face.video import read_video

    files = getattr(bank, "plate", None)
    if files is None or not files.enabled:
        return None
    h, w = bank.shape
    try:
        doc = json.loads(files.poses.read_text(encoding="utf-8"))
        poses = np.asarray(doc["poses"], np.float64).reshape(-1, 2, 3)
        fps = float(doc["fps"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise BankError(f"plate poses do not read ({exc})", path=files.poses) from None
    frames = np.stack([f for f in read_video(files.video)])
    if frames.shape[1:3] != (h, w) or len(frames) != len(poses) or not np.isfinite(poses).all():
        raise BankError(f"plate: {len(frames)} frames of {frames.shape[2]}x{frames.shape[1]} against "
                        f"{len(poses)} poses and a {w}x{h} bank", path=files.video)
    grey = cv2.imread(str(files.mask), cv2.IMREAD_GRAYSCALE)
    if grey is None or grey.shape != (h, w):
        raise BankError(f"plate mask must be a {w}x{h} picture", path=files.mask)
    mask = grey.astype(np.float32) / 255.0
    mesh = np.asarray(doc.get("rest_mesh", []), np.float64).reshape(-1, 2)
    if len(mesh) == 468:
        # the plate brought to the bank's colour once, rather than every morphed frame to the
        # plate's (a look-up per frame: a fifth of the compositing)
        pick = np.linspace(0, len(frames) - 1, min(COLOUR_SAMPLES, len(frames))).round().astype(int)
        gains = plate_colour(bank.images[bank.rest], mesh, mask, frames[pick], poses[pick])
        if np.abs(gains - 1.0).max() > 0.5 / 255:
            lut = colour_lut(1.0 / gains)
            for f in frames:
                cv2.LUT(f, lut, dst=f)
    eyes = doc.get("eyes")
    if isinstance(eyes, list) and len(eyes) == len(frames):
        eyes = np.array([np.nan if e is None else e for e in eyes], np.float64)
    else:
        eyes = plate_eyes(frames)  # a bank made before plate.json kept them
    return Plate(frames, poses, fps, PlateCompositor(mask), eyes=eyes)


def plate_eyes(frames: np.ndarray) -> np.ndarray:
    """Eye opening of every plate frame (:func:`lipsync.face.measure.eye_opening` of the face
    mesh tracked through them; NaN without a face): what blinks are found from."""
    import warnings

    from ..face.measure import eye_opening
    from ..face.track import track_frames

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tr = track_frames(iter(frames), fps=25.0, smooth=False)
    except Exception:  # no face to be found: no blinks known, joins still judged on pixels
        return np.full(len(frames), np.nan)
    out = eye_opening(tr.points)
    out[~tr.found] = np.nan
    return out
