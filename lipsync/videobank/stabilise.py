"""Step 4: one head pose for every picture — frames mapped onto a reference by the still points.

Bank images come from different moments (and clips) in which the head sat a little
differently. Morphing between them would move the whole head, so each frame is mapped onto
one **reference pose** by a similarity transform (rotation, uniform scale, shift) fitted on
points that do not move in speech (:data:`~lipsync.face.topology.STILL_POINTS`: the eye
corners and the nose bridge — never lips or jaw, which would pull the face along with the
mouth). The reference is the mean still-point shape of all frames (generalised Procrustes:
every frame fitted to a first guess, averaged, fitted again), turned so the eyes are level
and scaled so they are one unit apart: **unit coordinates**, the point between the eyes at
the origin, x to the image right, y down.

What a similarity cannot take away (the head turning or nodding: the still points then
move relative to each other) remains as the fit's **residual**, in eye distances; the
frame chooser prefers frames where it is small.

:func:`framing` then places the crop: a box around the head in unit coordinates, centred on
the face's mirror axis (so a bank's ``symmetry`` and its symmetric picture-edge lines
apply), reaching below the chin to the neck and shoulders (where the control lines' still
anchors go), cut back where the video's picture ends.

Examples
--------
>>> import numpy as np
>>> z = np.array([0, 1, 1j, 1 + 1j])
>>> c, t, res = fit_similarity(z[None], (2j * z + 3)[None])   # rotate 90 degrees, scale 2, shift
>>> np.round(c, 6).tolist(), np.round(t, 6).tolist(), float(res[0]) < 1e-9
([2j], [(3+0j)], True)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

import numpy as np

from ..face import topology as T

_STILL = list(T.STILL_POINTS)
# positions of the four eye corners within STILL_POINTS: (33, 133) and (263, 362)
_EYE_L = [T.STILL_POINTS.index(i) for i in T.EYE_CORNERS_L]
_EYE_R = [T.STILL_POINTS.index(i) for i in T.EYE_CORNERS_R]

# The crop around the head, in eye distances from the point between the eyes (adult
# proportions, checked on GRID's speaker and on photos): the crown lies ~2 eye distances
# above the eye line (hair included), the chin ~1.85 below and up to ~2.15 with the jaw wide
# open; the control-line template's neck and shoulder anchors reach 2.9 below and 2.8 out
# (lipsync.face.lines). A margin beyond them keeps the anchors' pixels in the picture.
#: Half the crop's width.
HALF_WIDTH = 2.6
#: From the eye line up to the crop's top.
TOP = 2.1
#: From the eye line down to the crop's bottom.
BOTTOM = 3.0
#: Below this (the chin with the jaw open, plus a little) the crop cuts the face: warned.
BOTTOM_NEEDED = 2.3
#: Above this (the brows and forehead the template's upper face lines follow): warned.
TOP_NEEDED = 1.3
#: Each side must keep at least the face's half width (ears, jaw angle): warned below.
HALF_WIDTH_NEEDED = 1.3


def fit_similarity(src: np.ndarray, dst: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares similarities taking each row of ``src`` onto ``dst`` (complex points).

    A 2-D similarity is ``z -> c z + t`` with complex ``c`` (rotation and scale) and ``t``
    (shift); its least-squares fit to point pairs has a closed form (Umeyama's, without
    reflections): ``c = sum(conj(a) b) / sum(|a|^2)`` over the centred points.

    Parameters
    ----------
    src : numpy.ndarray
        complex ``(N, K)``: N point sets of K points.
    dst : numpy.ndarray
        complex ``(N, K)`` or ``(K,)``.

    Returns
    -------
    c, t : numpy.ndarray
        complex ``(N,)``.
    residual : numpy.ndarray
        ``(N,)``, RMS distance of the moved points from ``dst``, in ``dst``'s units.
    """
    src = np.asarray(src, np.complex128)
    dst = np.broadcast_to(np.asarray(dst, np.complex128), src.shape)
    ms, md = src.mean(axis=1, keepdims=True), dst.mean(axis=1, keepdims=True)
    a, b = src - ms, dst - md
    c = (np.conj(a) * b).sum(axis=1) / np.maximum((np.abs(a) ** 2).sum(axis=1), 1e-300)
    t = md[:, 0] - c * ms[:, 0]
    moved = c[:, None] * src + t[:, None]
    residual = np.sqrt((np.abs(moved - dst) ** 2).mean(axis=1))
    return c, t, residual


def _complex(points: np.ndarray) -> np.ndarray:
    p = np.asarray(points, np.float64)
    return p[..., 0] + 1j * p[..., 1]


def _unit(still: np.ndarray) -> np.ndarray:
    """A still-point shape (complex ``(K,)``) turned level, eyes one apart, centred between them."""
    left, right = still[_EYE_L].mean(), still[_EYE_R].mean()
    c = 1.0 / (right - left)
    return c * (still - (left + right) / 2)


def reference_pose(meshes: Sequence[np.ndarray]) -> np.ndarray:
    """The reference still-point shape in unit coordinates, complex ``(8,)``.

    Parameters
    ----------
    meshes : sequence of numpy.ndarray
        ``(N_i, 468, 2|3)`` meshes of every frame with a face (one array per video), or
        just their still points ``(N_i, 8, 2)``.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> base = rng.normal(size=(8, 2))
    >>> a = np.stack([base * s + d for s, d in ((1, 0), (2, 5), (3, -1))])
    >>> ref = reference_pose([a])      # three frames' still points
    >>> _, _, res = fit_similarity(_complex(a), ref)
    >>> float(res.max()) < 1e-9
    True
    """
    z = np.concatenate([_complex(p[:, _STILL] if p.shape[1] == 468 else p) for p in meshes])
    ref = _unit(z[0])
    for _ in range(2):  # two rounds of generalised Procrustes settle to well below a pixel
        c, t, _ = fit_similarity(z, ref)
        ref = _unit((c[:, None] * z + t[:, None]).mean(axis=0))
    return ref


@dataclass(frozen=True)
class Registration:
    """Every frame of one video mapped onto the reference pose.

    Attributes
    ----------
    c, t : numpy.ndarray
        complex ``(N,)``: frame pixels ``z`` go to unit coordinates ``c z + t`` (NaN where
        no face was found).
    residual : numpy.ndarray
        ``(N,)`` RMS distance of the still points from the reference after the fit, in eye
        distances (NaN without a face).
    """

    c: np.ndarray
    t: np.ndarray
    residual: np.ndarray

    def to_unit(self, frame: int, points: np.ndarray) -> np.ndarray:
        """Points ``(..., 2|3)`` of ``frame`` in unit coordinates (``z`` scaled alike)."""
        p = np.asarray(points, np.float64)
        z = self.c[frame] * _complex(p) + self.t[frame]
        out = np.stack([z.real, z.imag], axis=-1)
        if p.shape[-1] > 2:
            out = np.concatenate([out, p[..., 2:] * abs(self.c[frame])], axis=-1)
        return out


def register_track(points: np.ndarray, found: np.ndarray, ref: np.ndarray) -> Registration:
    """Fit every found frame's still points (``points`` ``(N, 468, 2|3)``) onto ``ref``."""
    n = len(points)
    c = np.full(n, np.nan + 0j)
    t = np.full(n, np.nan + 0j)
    residual = np.full(n, np.nan)
    idx = np.nonzero(found)[0]
    if idx.size:
        c[idx], t[idx], residual[idx] = fit_similarity(_complex(points[idx][:, _STILL]), ref)
    return Registration(c=c, t=t, residual=residual)


@dataclass(frozen=True)
class Framing:
    """Where the bank's pictures are cut from unit coordinates, and at what scale.

    Attributes
    ----------
    origin : complex
        Unit coordinates of the crop's top-left corner (the outer edge of pixel (0, 0)).
    scale : float
        Output pixels per eye distance.
    size : (int, int)
        ``(W, H)`` of the bank's images.
    cut : tuple of str
        Which sides the video's picture cut short of the wanted margin (for a warning).
    """

    origin: complex
    scale: float
    size: Tuple[int, int]
    cut: Tuple[str, ...] = ()

    @property
    def axis(self) -> float:
        """The face's mirror axis in output pixels: the crop's middle column."""
        return (self.size[0] - 1) / 2

    def matrix(self, reg: Registration, frame: int) -> np.ndarray:
        """The 2x3 affine matrix taking ``frame``'s pixels to the bank picture's pixels.

        Unit coordinates ``u`` become pixels ``scale (u - origin) - 0.5`` (pixel centres at
        integers, so the crop's outer edge is at -0.5).
        """
        c = self.scale * reg.c[frame]
        t = self.scale * (reg.t[frame] - self.origin) - 0.5 - 0.5j
        return np.array([[c.real, -c.imag, t.real], [c.imag, c.real, t.imag]])

    def points(self, reg: Registration, frame: int, points: np.ndarray) -> np.ndarray:
        """``frame``'s mesh points in the bank picture's pixels (``z`` scaled alike)."""
        m = self.matrix(reg, frame)
        p = np.asarray(points, np.float64)
        xy = p[..., :2] @ m[:, :2].T + m[:, 2]
        if p.shape[-1] > 2:
            xy = np.concatenate([xy, p[..., 2:] * float(np.hypot(m[0, 0], m[1, 0]))], axis=-1)
        return xy


def mirror_axis_unit(unit_points: Sequence[np.ndarray]) -> float:
    """The face's vertical mirror axis in unit coordinates, the median over meshes
    (:func:`lipsync.face.lines.midline_axis`, measured at a scale where its half-pixel
    rounding is negligible)."""
    from ..face.lines import midline_axis

    fine = 1e4  # midline_axis rounds to half a unit: in units of 1e-4 eye distances
    return midline_axis([np.asarray(p, np.float64)[:, :2] * fine for p in unit_points]) / fine


def framing(regs: Sequence[Tuple[Registration, int, Tuple[int, int]]], unit_points: Sequence[np.ndarray], *,
            source_scale: float, size: Optional[Tuple[int, int]] = None, max_side: int = 512) -> Framing:
    """The crop and scale of the bank's pictures.

    Parameters
    ----------
    regs : sequence of (Registration, frame, (W, H))
        The frames that may become bank pictures, with their video's size: the crop stays
        inside every one's picture.
    unit_points : sequence of numpy.ndarray
        Their meshes in unit coordinates (for the mirror axis).
    source_scale : float
        The videos' eye distance in pixels: the default scale (no detail invented or lost).
    size : (int, int), optional
        ``(W, H)`` asked for: the crop is trimmed to its aspect and scaled to it.
    max_side : int
        Without ``size``: the longer side is scaled down to this.

    Returns
    -------
    Framing
        With ``cut`` naming the sides where the videos' pictures end before the margin the
        face needs (the caller warns).
    """
    axis = mirror_axis_unit(unit_points)
    # what the videos' pictures hold around the face, in unit coordinates: each picture's
    # corners moved by its frame's transform, the tightest over all the frames
    left, right, top, bottom = -np.inf, np.inf, -np.inf, np.inf
    for reg, i, (w, h) in regs:
        corners = reg.c[i] * np.array([-0.5 - 0.5j, w - 0.5 - 0.5j, w - 0.5 + (h - 0.5) * 1j,
                                       -0.5 + (h - 0.5) * 1j]) + reg.t[i]
        left = max(left, corners[0].real, corners[3].real)
        right = min(right, corners[1].real, corners[2].real)
        top = max(top, corners[0].imag, corners[1].imag)
        bottom = min(bottom, corners[2].imag, corners[3].imag)
    # room on each side of the axis, above and below the eye line
    room_half, room_top, room_bottom = min(axis - left, right - axis), -top, bottom
    half, top, bottom = min(HALF_WIDTH, room_half), min(TOP, room_top), min(BOTTOM, room_bottom)
    if size is not None:
        w, h = size
        want = w / h
        if 2 * half / (top + bottom) < want:
            # too tall for the asked aspect: more room at the sides where the pictures have it,
            # else less hair, then less neck
            half = min(room_half, want * (top + bottom) / 2)
            extra = max(0.0, (top + bottom) - 2 * half / want)
            from_top = min(extra, max(0.0, top - TOP_NEEDED))
            top, bottom = top - from_top, bottom - (extra - from_top)
        else:
            # too wide: more below (neck, shoulders), then above, where the pictures have it;
            # else narrower
            add = 2 * half / want - (top + bottom)
            more = min(add, room_bottom - bottom)
            bottom, add = bottom + more, add - more
            more = min(add, room_top - top)
            top, add = top + more, add - more
            if add > 1e-9:
                half = want * (top + bottom) / 2
        scale = w / (2 * half)
    else:
        scale = source_scale
        longer = max(2 * half, top + bottom) * scale
        if longer > max_side:
            scale *= max_side / longer
        # even sides (video encoders subsample chroma by two)
        w = max(2, 2 * int(round(half * scale)))
        h = max(2, 2 * int(round((top + bottom) * scale / 2)))
    cut = tuple(name for name, have, need in (("top", top, TOP_NEEDED), ("bottom", bottom, BOTTOM_NEEDED),
                                              ("sides", half, HALF_WIDTH_NEEDED)) if have < need - 1e-9)
    # the crop exactly W/scale wide, centred on the axis; H/scale tall from the top margin
    half = w / (2 * scale)
    return Framing(origin=complex(axis - half, -top), scale=float(scale), size=(int(w), int(h)), cut=cut)
