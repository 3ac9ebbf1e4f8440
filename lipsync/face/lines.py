"""Control lines for a talking head, placed from the face mesh.

:data:`FACE_TEMPLATE` is the rule table: each feature names the mesh points it follows, how
many segments it becomes (polylines resampled by arc length, so a feature has the same
segment count on every viseme however the mesh points are spaced on it), and why it is
there. Three kinds of feature:

* **moving**: the lip contours (outer and inner, each lip split at the midline into an
  image-left and an image-right half running from the corner to the middle, so mirror
  partners correspond segment by segment), the mouth corners, the jaw and the chin's
  midline. These carry the motion of speech.
* **still on the face**: eyes, brows, nose, upper cheeks and the upper face outline. They
  follow the real features (in photos of one person taken at different moments the head
  may have moved a little; the flow then registers it), and they keep the warp from
  dragging the face along with the mouth: Beier–Neely weights fall off only as
  1/distance^b, so without anchors a moving jaw pulls the eyes too.
* **anchors off the face** (:func:`_anchor_lines`): the neck, the shoulders and the picture's
  edges, which the mesh does not cover. They are placed from the eyes alone (position, size,
  tilt), never from the mouth or jaw, so an open mouth does not move them.

Names end in ``_l`` / ``_r`` for mirror partners (image left / image right); midline
features have no suffix. A bank of these lines can use ``symmetry: true``.

Examples
--------
>>> names = [f.name for f in FACE_TEMPLATE]
>>> "lip_outer_upper_l" in names and "jaw_r" in names
True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from ..banks.bank import Feature, WarpParams
from . import topology as T

#: Beier–Neely weights for banks of face lines: the method's standard b = 2. With the
#: template's anchors on the still face, b = 2 measured best of b = 1-4 on GRID frame pairs
#: (Beier–Neely in-betweens against the real frames between: 32.8, 33.1, 33.1, 33.0 dB mouth
#: PSNR); the toon's b = 4 is for a drawing with few anchors.
FACE_WARP = WarpParams(a=1.0, b=2.0, p=0.5)


@dataclass(frozen=True)
class FaceFeature:
    """One rule of the template: a feature following mesh points."""

    name: str
    points: Tuple[int, ...]
    segments: int
    moves: bool
    why: str


def _pair(name: str, left: Tuple[int, ...], right: Tuple[int, ...], segments: int, moves: bool, why: str):
    return (FaceFeature(name + "_l", left, segments, moves, why),
            FaceFeature(name + "_r", right, segments, moves, why))


def _half(contour: Tuple[int, ...]) -> Tuple[Tuple[int, ...], Tuple[int, ...]]:
    """A corner-to-corner contour split at its midline point: (left corner → mid, right corner → mid)."""
    mid = len(contour) // 2
    return contour[:mid + 1], contour[::-1][:mid + 1]


#: The template. Segment counts: 3 per lip half (six chords follow a lip's curve to within
#: about half a pixel at 100 px mouth width; more lines cost preprocessing time, ~5 ns per
#: pixel per line per flow), fewer on features that barely bend.
FACE_TEMPLATE: Tuple[FaceFeature, ...] = (
    *_pair("lip_outer_upper", *_half(T.LIP_OUTER_UPPER), 3, True, "outer edge of the upper lip"),
    *_pair("lip_outer_lower", *_half(T.LIP_OUTER_LOWER), 3, True, "outer edge of the lower lip"),
    *_pair("lip_inner_upper", *_half(T.LIP_INNER_UPPER), 3, True,
           "inner edge of the upper lip: where the mouth opening (teeth, dark inside) begins"),
    *_pair("lip_inner_lower", *_half(T.LIP_INNER_LOWER), 3, True, "inner edge of the lower lip"),
    *_pair("mouth_corner", T.MOUTH_CORNERS[0], T.MOUTH_CORNERS[1], 1, True,
           "outer to inner corner: the corners stretch and round with the lips"),
    *_pair("jaw", T.JAW_L, T.JAW_R, 4, True, "the jaw drops as the mouth opens"),
    FaceFeature("chin", T.CHIN_MIDLINE, 2, True, "the chin's midline follows the jaw"),
    FaceFeature("nose_bridge", T.NOSE_BRIDGE, 2, False, "keeps the nose still"),
    *_pair("nose_base", T.NOSE_BASE_L, T.NOSE_BASE_R, 1, False,
           "the nose's base, just above the upper lip: keeps the nose still while the lip moves"),
    *_pair("cheek", (123, 50, 36), (352, 280, 266), 2, False, "upper cheek: still in speech"),
    *_pair("eye_upper", T.EYE_UPPER_L, T.EYE_UPPER_R, 2, False, "keeps the eyes still"),
    *_pair("eye_lower", T.EYE_LOWER_L, T.EYE_LOWER_R, 2, False, "keeps the eyes still"),
    *_pair("brow", T.BROW_L, T.BROW_R, 2, False, "keeps the brows still"),
    *_pair("face_upper", T.FACE_UPPER_L, T.FACE_UPPER_R, 3, False,
           "the face's outline above the jaw: keeps forehead, temples and hair still"),
)

# Anchors off the face, in units of the distance between the eye centres (d), measured
# from the point between the eyes along the eyes' frame (u across, v down the face). Adult
# proportions, checked on GRID's speaker: the chin's lowest point lies about 1.85 d below the
# eye line and drops by up to ~0.3 d when the jaw opens wide; the neck's sides are about
# 0.6 d from the midline; the shoulder line slopes from ~2.2 d below the eyes beside the neck
# to ~2.5 d at 2.8 d out. Being off by a fraction of d matters little: an anchor only has to
# lie on ground that does not move.
#: (name, (u0, v0), (u1, v1), why)
_ANCHORS_FROM_EYES = (
    ("neck_l", (-0.6, 2.3), (-0.6, 2.9), "side of the neck, below the lowest the chin goes"),
    ("neck_r", (0.6, 2.3), (0.6, 2.9), "side of the neck, below the lowest the chin goes"),
    ("shoulders_l", (-2.8, 2.5), (-1.5, 2.2), "shoulder line"),
    ("shoulders_r", (2.8, 2.5), (1.5, 2.2), "shoulder line"),
)
#: Picture-edge anchors sit this far inside the border (pixels), so that their pixels exist.
EDGE_INSET = 2.0
#: An anchor is kept only when both ends lie at least this far inside the picture on every
#: viseme (pixels): a line past the border pins nothing visible.
ANCHOR_MARGIN = 4.0


def _eye_frame(points: np.ndarray) -> Tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    left = points[list(T.EYE_UPPER_L + T.EYE_LOWER_L), :2].mean(axis=0)
    right = points[list(T.EYE_UPPER_R + T.EYE_LOWER_R), :2].mean(axis=0)
    u = right - left
    d = float(np.hypot(*u))
    u = u / d
    v = np.array([-u[1], u[0]])
    return (left + right) / 2, d, u, v


def _anchor_lines(points: np.ndarray) -> Dict[str, np.ndarray]:
    centre, d, u, v = _eye_frame(points)
    out = {}
    for name, (u0, v0), (u1, v1), _why in _ANCHORS_FROM_EYES:
        out[name] = np.array([centre + d * (u0 * u + v0 * v), centre + d * (u1 * u + v1 * v)])
    return out


def _edge_lines(shape: Tuple[int, int], axis: Optional[float]) -> Dict[str, np.ndarray]:
    h, w = shape
    e = EDGE_INSET
    # Symmetric about the bank's mirror axis when it has one (the normaliser would otherwise
    # move them onto symmetric places, shifting the picture's border); the whole width if not.
    half = (w - 1) / 2 - e if axis is None else min(axis - e, w - 1 - e - axis)
    mid = (w - 1) / 2 if axis is None else axis
    if half <= 0:
        return {}
    x0, x1 = mid - half, mid + half
    y0, y1 = e + 0.1 * h, h - 1 - e - 0.1 * h
    return {
        # Top and bottom cross the axis symmetrically; the sides are mirror partners.
        "frame_top": np.array([[x0, e], [x1, e]]),
        "frame_bottom": np.array([[x0, h - 1 - e], [x1, h - 1 - e]]),
        "frame_side_l": np.array([[x0, y0], [x0, y1]]),
        "frame_side_r": np.array([[x1, y0], [x1, y1]]),
    }


def _clip(line: np.ndarray, shape: Tuple[int, int]) -> Optional[np.ndarray]:
    """The part of a line inside the picture (less :data:`ANCHOR_MARGIN`), or None (Liang–Barsky)."""
    h, w = shape
    m = ANCHOR_MARGIN
    p, d = line[0], line[1] - line[0]
    t0, t1 = 0.0, 1.0
    for q, dq, lo, hi in ((p[0], d[0], m, w - 1 - m), (p[1], d[1], m, h - 1 - m)):
        if abs(dq) < 1e-12:
            if q < lo or q > hi:
                return None
            continue
        a, b = (lo - q) / dq, (hi - q) / dq
        t0, t1 = max(t0, min(a, b)), min(t1, max(a, b))
    if t1 <= t0:
        return None
    return np.array([p + t0 * d, p + t1 * d])


#: An anchor cut by the picture's border is kept when at least this share of it (on every
#: viseme) is inside: a stub pins too little to be worth its cost.
MIN_ANCHOR_SHARE = 0.4


def face_features(points: Mapping[str, np.ndarray], shape: Tuple[int, int], *,
                  edges: bool = True, axis: Optional[float] = None) -> Dict[str, Dict[str, Feature]]:
    """Control features for every viseme of a bank from each viseme's face mesh.

    Parameters
    ----------
    points : mapping
        Viseme name → its mesh points, ``(468, 2)`` or ``(468, 3)`` in image pixels.
    shape : tuple of int
        ``(H, W)`` of the bank's images.
    edges : bool
        Add lines pinning the picture's border (a whole picture that must not move at its
        edges; off for sprites that are composited).

    Returns
    -------
    dict
        Viseme → {feature name → :class:`~lipsync.banks.bank.Feature`}: the same names, kinds and
        segment counts for every viseme (anchors are cut at the picture's border; one
        mostly outside any viseme's picture is left out of all of them, with its mirror
        partner), ready for bank.yaml.

    Examples
    --------
    >>> from lipsync.face.topology import MESH_POINTS
    >>> rng = np.random.default_rng(0)
    >>> pts = rng.uniform(100, 300, (468, 2))
    >>> feats = face_features({"X": pts, "A": pts + 1.0}, (400, 400))
    >>> list(feats["X"]) == list(feats["A"])
    True
    >>> feats["X"]["jaw_l"].segment_count
    4
    """
    anchors = {name: _anchor_lines(np.asarray(p, np.float64)) for name, p in points.items()}
    clipped = {v: {n: _clip(line, shape) for n, line in a.items()} for v, a in anchors.items()}

    def enough(full: np.ndarray, part: Optional[np.ndarray]) -> bool:
        return part is not None and np.hypot(*np.diff(part, axis=0)[0]) >= MIN_ANCHOR_SHARE * np.hypot(
            *np.diff(full, axis=0)[0])

    keep = [n for n in anchors[next(iter(anchors))]
            if all(enough(anchors[v][n], clipped[v][n]) for v in anchors)]
    # A mirror pair is kept or dropped together, so symmetry still finds every partner.
    keep = [n for n in keep if _partner(n) is None or _partner(n) in keep]
    edge = _edge_lines(shape, axis) if edges else {}
    out: Dict[str, Dict[str, Feature]] = {}
    for viseme, p in points.items():
        p = np.asarray(p, np.float64)[:, :2]
        feats: Dict[str, Feature] = {}
        for f in FACE_TEMPLATE:
            pts = p[list(f.points)]
            feats[f.name] = (Feature("line", pts) if len(pts) == 2 and f.segments == 1
                             else Feature("polyline", pts, segments=f.segments))
        for n in keep:
            feats[n] = Feature("line", clipped[viseme][n])
        for n, line in edge.items():
            feats[n] = Feature("line", line)
        out[viseme] = feats
    return out


def _partner(name: str):
    if name.endswith("_l"):
        return name[:-2] + "_r"
    if name.endswith("_r"):
        return name[:-2] + "_l"
    return None


def moving_features() -> List[str]:
    """Names of the template's features that move in speech (lips, corners, jaw, chin)."""
    return [f.name for f in FACE_TEMPLATE if f.moves]


def describe_template() -> str:
    """The rule table as text (for documentation and ``--help``)."""
    rows: List[str] = []
    for f in FACE_TEMPLATE:
        rows.append(f"{f.name:18s} {'moves' if f.moves else 'still':5s} {f.segments} seg  {f.why}")
    for name, _a, _b, why in _ANCHORS_FROM_EYES:
        rows.append(f"{name:18s} still 1 seg  {why}")
    return "\n".join(rows)


def template_points(features: Sequence[FaceFeature] = FACE_TEMPLATE) -> List[int]:
    """Every mesh point the template uses (sorted, once each)."""
    return sorted({i for f in features for i in f.points})


def midline_axis(points: Sequence[np.ndarray]) -> float:
    """The face's vertical mirror axis (x) over several meshes, rounded to half a pixel.

    The median of each mesh's estimate (the mean x of its midline points and of its mirror
    pairs' midpoints), as the bank normaliser estimates a bank's axis from its lines.

    Examples
    --------
    >>> p = np.zeros((468, 2)); p[:, 0] = 50.0
    >>> midline_axis([p, p + 1.0])
    50.5
    """
    est = []
    for p in points:
        p = np.asarray(p, np.float64)
        pairs = np.array(T.MIRROR_PAIRS)
        mids = np.concatenate([(p[pairs[:, 0], 0] + p[pairs[:, 1], 0]) / 2, p[list(T.MIDLINE_POINTS), 0]])
        est.append(mids.mean())
    return float(np.round(2.0 * np.median(est)) / 2.0)


#: A face counts as symmetric (a bank of it may use ``symmetry: true``) when its points lie
#: within this many eye distances (RMS) of their mirror partners' reflections about its
#: midline. Normalisation moves each point by about that much to make the lines exactly
#: symmetric; 0.03 is ~1.5 px on a face with eyes 50 px apart, below what shows in a morph,
#: while GRID's speaker, whose head is turned and tilted a little, measures 0.05-0.11 and
#: would visibly change.
SYMMETRIC_BELOW = 0.03


#: Above this asymmetry (eye distances) the face is turned well away from the camera (a
#: three-quarter or profile view: measured 0.73 on a man filmed in profile, 0.05 on a frontal
#: portrait, 0.05-0.11 on GRID's speaker): the mesh then squeezes a frontal face onto it and
#: the lines on the far side are poor, which deserves a warning.
TURNED_ABOVE = 0.25


def face_asymmetry(points: Sequence[np.ndarray], axis: Optional[float] = None) -> float:
    """How far a face is from mirror symmetry about a vertical axis, in eye distances (RMS).

    Parameters
    ----------
    points : sequence of numpy.ndarray
        Meshes ``(468, 2|3)`` of the face (e.g. one per viseme).
    axis : float, optional
        The mirror axis; default :func:`midline_axis` of ``points``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> p = rng.uniform(0, 100, (468, 2))
    >>> q = p.copy()
    >>> for a, b in T.MIRROR_PAIRS: q[b] = [100.0 - p[a, 0], p[a, 1]]
    >>> q[list(T.MIDLINE_POINTS), 0] = 50.0
    >>> face_asymmetry([q], axis=50.0) < 1e-12
    True
    """
    from .measure import eye_distance

    pts = [np.asarray(p, np.float64)[:, :2] for p in points]
    ax = midline_axis(pts) if axis is None else axis
    pairs = np.array(T.MIRROR_PAIRS)
    mid = list(T.MIDLINE_POINTS)
    sq = []
    for p in pts:
        d = float(eye_distance(p))
        a, b = p[pairs[:, 0]], p[pairs[:, 1]].copy()
        b[:, 0] = 2 * ax - b[:, 0]
        # a pair's gap is twice each point's distance from the symmetric position
        sq.append(np.concatenate([(np.linalg.norm(a - b, axis=1) / (2 * d)) ** 2, ((p[mid, 0] - ax) / d) ** 2]))
    return float(np.sqrt(np.mean(np.concatenate(sq))))
