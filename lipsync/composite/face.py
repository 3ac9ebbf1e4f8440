"""One face: a lower face (mouth, lips, jaw, chin, lower cheeks) joined onto a plate picture.

A bank made from video shows every viseme on one **plate** (a frame with the eyes open and
the mouth relaxed): each viseme's picture is the plate's pixels everywhere except the
*lower-face mask*, where the chosen frame's lower face, moved onto the plate's pose, is
blended in. Outside the mask every picture is the plate, pixel for pixel, so a render
never swaps hair, eyes, collar or colour when the viseme changes.

The pieces, each usable alone (the render-time plate and ``lipsync dub`` use them too):

* :func:`lower_face_polygon` -- the region's outline from the jaw and the nose base (mesh
  points, :func:`polygon_from_mesh`, or a bank's lines, :func:`polygon_from_lines`): the jaw
  below the level of the nose's wings, the chin, and the nose's lower edge on top;
* :func:`lower_face_mask` -- float32 ``(H, W)`` in [0, 1]: the union of outlines (grown
  outwards below the nose: an open jaw's chin and a closed one's both covered), feathered
  *inside* the outline so that nothing above the nose base changes;
* :func:`pose_onto` -- the similarity taking one face's points onto another's by points
  around the mask's upper edge (nose base, upper cheeks, eye corners), so the pasted lower
  face meets the plate where the blend happens;
* :func:`colour_match` / :func:`apply_colour` -- per-channel gain and offset bringing the
  pasted picture's skin just outside the mask (:func:`skin_ring`) to the plate's;
* :func:`paste` -- the blend (feathered alpha, the default, or Poisson, ``cv2.seamlessClone``).

Examples
--------
>>> import numpy as np
>>> poly = np.array([[10, 10], [50, 10], [50, 40], [10, 40]], np.float64)
>>> m = lower_face_mask([poly], (60, 60), feather=4.0)
>>> float(m[25, 30]), float(m[5, 30]), float(m[10, 30])
(1.0, 0.0, 0.0)
>>> plate = np.zeros((60, 60, 3), np.uint8); face = np.full((60, 60, 3), 200, np.uint8)
>>> out = paste(plate, face, m)
>>> out[25, 30].tolist(), out[5, 30].tolist()
([200, 200, 200], [0, 0, 0])
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence, Tuple

import numpy as np

from ..face import topology as T

#: Feather width of the mask, in eye distances: the blend runs from 0 at the outline to 1
#: this far inside it. GRID's nose base sits 0.28 eye distances above the upper lip's top
#: edge: 0.12 leaves the lip itself fully the chosen frame's while the skin under the nose
#: changes smoothly.
FEATHER = 0.12
#: The outline is grown outwards (below the nose) by this many eye distances: a wide-open
#: jaw drops the chin ~0.2 eye distances below a closed one's (GRID s1: 1.86 to 2.07 from
#: the eye line), and the union of plate and frame outlines plus this margin keeps the
#: chin's shadow and the neck under it from two different moments.
GROW = 0.15
#: The outline's jaw: mesh points from the ear's level to the chin (each side).
JAW = (T.JAW_L, T.JAW_R)
#: The nose's lower edge, wing to the point under the tip (each side): the top of the region.
NOSE_BASE = (T.NOSE_BASE_L, T.NOSE_BASE_R)
#: Points that move little in speech around the mask's upper edge: the nose base, the upper
#: cheeks under the eyes and the eye corners. A similarity fitted on them puts the pasted
#: lower face where the plate's skin continues it (the bank's stabilisation fits the eye
#: corners and the nose bridge only; a nod leaves a residual at the nose base).
ANCHORS = T.NOSE_BASE_L + T.NOSE_BASE_R[:-1] + (50, 280, 123, 352, 36, 266) + T.EYE_CORNERS_L + T.EYE_CORNERS_R
#: Colour match gains beyond this range are a different light, not a drift: clipped.
GAIN_RANGE = (0.7, 1.4)
#: Width of the skin ring outside the mask the colour is matched on, in eye distances.
RING = 0.12
#: Paste methods (:func:`paste`).
METHODS = ("alpha", "poisson")


def _level_crossing(line: np.ndarray, down: np.ndarray, level: float) -> np.ndarray:
    """The part of polyline ``line`` (top → bottom) below ``level`` along ``down``, starting
    at the interpolated crossing."""
    d = line @ down - level
    below = np.nonzero(d >= 0)[0]
    if below.size == 0:
        return line[-1:]
    k = int(below[0])
    if k == 0:
        return line
    a, b = line[k - 1], line[k]
    t = -d[k - 1] / max(d[k] - d[k - 1], 1e-12)
    return np.vstack([a + t * (b - a), line[k:]])


def lower_face_polygon(jaw_l: np.ndarray, jaw_r: np.ndarray, nose_base_l: np.ndarray, nose_base_r: np.ndarray, *,
                       grow: float = 0.0) -> np.ndarray:
    """The lower face's outline, ``(K, 2)`` pixels, from the jaw and the nose's lower edge.

    Parameters
    ----------
    jaw_l, jaw_r : numpy.ndarray
        ``(N, 2)`` each side's jaw from the ear's level down to the chin (the mesh's
        :data:`~lipsync.face.topology.JAW_L`, a bank's ``jaw_l`` line).
    nose_base_l, nose_base_r : numpy.ndarray
        ``(M, 2)`` the nose's lower edge from each wing to the point under the tip.
    grow : float
        Pixels the chin is pushed outwards along the jaw's outward normal; the jaw's points
        less, in proportion to their depth below the wings' level (none at that level).

    Returns
    -------
    numpy.ndarray
        The jaw below the wings' level on the image left, the chin, the other jaw back up,
        then the nose's lower edge from the image-right wing to the image-left one.

    Examples
    --------
    >>> jl = np.array([[0., 0], [0, 10], [5, 20], [10, 22]]); jr = np.array([[20., 0], [20, 10], [15, 20], [10, 22]])
    >>> nl = np.array([[7., 5], [10, 6]]); nr = np.array([[13., 5], [10, 6]])
    >>> lower_face_polygon(jl, jr, nl, nr).round(1).tolist()[:2]
    [[0.0, 5.0], [0.0, 10.0]]
    """
    jl, jr = np.asarray(jaw_l, np.float64)[:, :2], np.asarray(jaw_r, np.float64)[:, :2]
    nl, nr = np.asarray(nose_base_l, np.float64)[:, :2], np.asarray(nose_base_r, np.float64)[:, :2]
    across = nr[0] - nl[0]
    across = across / max(float(np.linalg.norm(across)), 1e-12)
    down = np.array([-across[1], across[0]])  # image y grows downwards: (1, 0) -> (0, 1)
    level = float(np.mean([nl[0] @ down, nr[0] @ down]))
    left = _level_crossing(jl, down, level)
    right = _level_crossing(jr, down, level)
    jaw = np.vstack([left, right[::-1][1:] if np.allclose(right[-1], left[-1]) else right[::-1]])
    if grow > 0 and len(jaw) > 2:
        tangent = np.gradient(jaw, axis=0)
        normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        centre = np.vstack([nl, nr]).mean(axis=0)
        normal *= np.where(((jaw - centre) * normal).sum(axis=1, keepdims=True) < 0, -1.0, 1.0)
        # full growth at the chin, none at the wings' level: beside the cheeks the face's
        # edge meets the background, and a frame's edge a pixel or two off the plate's would
        # paste a sliver of skin onto it
        depth = jaw @ down - level
        taper = np.clip(depth / max(float(depth.max()), 1e-9), 0.0, 1.0)[:, None]
        jaw = jaw + grow * taper * normal
    return np.vstack([jaw, nr, nl[::-1][1:]])


def polygon_from_mesh(points: np.ndarray, *, grow: float = 0.0) -> np.ndarray:
    """:func:`lower_face_polygon` of a 468-point face mesh (picture pixels)."""
    p = np.asarray(points, np.float64)[:, :2]
    return lower_face_polygon(p[list(JAW[0])], p[list(JAW[1])], p[list(NOSE_BASE[0])], p[list(NOSE_BASE[1])],
                              grow=grow)


def polygon_from_lines(lines: Mapping[str, object], *, grow: float = 0.0) -> np.ndarray:
    """:func:`lower_face_polygon` of a bank viseme's face lines (``jaw_l``, ``jaw_r``,
    ``nose_base_l``, ``nose_base_r``: :class:`~lipsync.banks.bank.Feature` or ``(N, 2)`` arrays)."""
    def pts(name):
        f = lines[name]
        return np.asarray(getattr(f, "points", f), np.float64)

    return lower_face_polygon(pts("jaw_l"), pts("jaw_r"), pts("nose_base_l"), pts("nose_base_r"), grow=grow)


def eye_distance_of_lines(lines: Mapping[str, object]) -> float:
    """Distance between the eye centres of a bank viseme's face lines (``eye_upper_*``/``eye_lower_*``)."""
    def centre(side):
        return np.vstack([np.asarray(getattr(lines[f"eye_{k}_{side}"], "points", lines[f"eye_{k}_{side}"]),
                                     np.float64) for k in ("upper", "lower")]).mean(axis=0)

    return float(np.linalg.norm(centre("r") - centre("l")))


def lower_face_mask(polygons: Sequence[np.ndarray], shape: Tuple[int, int], *, feather: float) -> np.ndarray:
    """The feathered lower-face mask: float32 ``(H, W)``, 1 = the pasted face, 0 = the plate.

    Parameters
    ----------
    polygons : sequence of numpy.ndarray
        ``(K, 2)`` outlines in pixels (:func:`lower_face_polygon`, grown as wanted); the mask
        covers their union (the plate's and every pasted frame's): a mask of more outlines
        is 0 in fewer places.
    shape : (int, int)
        ``(H, W)``.
    feather : float
        Pixels from the outline inwards over which the mask rises from 0 to 1 (smoothstep of
        the distance to the outline): the mask is exactly 0 on and outside the outline.

    Returns
    -------
    numpy.ndarray
        float32 ``(H, W)`` in [0, 1].

    Examples
    --------
    A 40x30 rectangle feathered by 4 px: 1 deeper than 4 px, 0 outside, half at 2 px in.

    >>> poly = np.array([[10, 10], [49, 10], [49, 39], [10, 39]], np.float64)
    >>> m = lower_face_mask([poly], (50, 60), feather=4.0)
    >>> float(m[25, 30]), float(m[25, 9]), round(float(m[25, 12]), 2)
    (1.0, 0.0, 0.5)
    """
    import cv2

    h, w = shape
    area = np.zeros((h, w), np.uint8)
    for poly in polygons:
        p = np.asarray(poly, np.float64)[:, :2]
        # pixel centres inside the outline (fixed point: a quarter-pixel outline is not rounded away)
        cv2.fillPoly(area, [np.round(p * 16).astype(np.int32)], 1, lineType=cv2.LINE_8, shift=4)
    if feather <= 0:
        return area.astype(np.float32)
    dist = cv2.distanceTransform(area, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    # a pixel on the outline is 1 from the nearest pixel outside it: it gets 0, and the
    # ramp is feather pixels long from there
    t = np.clip((dist - 1.0) / feather, 0.0, 1.0)
    return (t * t * (3 - 2 * t)).astype(np.float32)


def mask_from_mesh(meshes: Sequence[np.ndarray], shape: Tuple[int, int], *, feather: float = FEATHER,
                   grow: float = GROW) -> np.ndarray:
    """:func:`lower_face_mask` of the union of faces with 468-point ``meshes`` (picture pixels),
    ``feather`` and ``grow`` in eye distances (of the first mesh).

    Examples
    --------
    >>> from lipsync.face.measure import eye_distance
    >>> p = np.zeros((468, 2))       # a toy mesh: jaw a U, nose base a bar, eyes 40 px apart
    >>> p[list(JAW[0])] = np.c_[np.linspace(20, 50, 11), np.linspace(40, 90, 11)]
    >>> p[list(JAW[1])] = np.c_[np.linspace(80, 50, 11), np.linspace(40, 90, 11)]
    >>> p[list(NOSE_BASE[0])] = [[40, 50], [45, 51], [50, 52]]; p[list(NOSE_BASE[1])] = [[60, 50], [55, 51], [50, 52]]
    >>> p[list(T.EYE_UPPER_L + T.EYE_LOWER_L)] = [30, 30]; p[list(T.EYE_UPPER_R + T.EYE_LOWER_R)] = [70, 30]
    >>> m = mask_from_mesh([p], (100, 100))
    >>> float(m[70, 50]), float(m[45, 50])       # the chin's middle, above the nose base
    (1.0, 0.0)
    """
    from ..face.measure import eye_distance

    d = float(eye_distance(np.asarray(meshes[0], np.float64)))
    return lower_face_mask([polygon_from_mesh(p, grow=grow * d) for p in meshes], shape, feather=feather * d)


def mask_from_lines(visemes: Sequence[Mapping[str, object]], shape: Tuple[int, int], *, feather: float = FEATHER,
                    grow: float = GROW) -> np.ndarray:
    """:func:`lower_face_mask` of the union of bank visemes' face lines (``bank.features[v]``),
    ``feather`` and ``grow`` in eye distances (of the first viseme's eye lines)."""
    d = eye_distance_of_lines(visemes[0])
    return lower_face_mask([polygon_from_lines(f, grow=grow * d) for f in visemes], shape, feather=feather * d)


def pose_onto(points: np.ndarray, target: np.ndarray, *, anchors: Sequence[int] = ANCHORS) -> np.ndarray:
    """The 2x3 similarity (rotation, scale, shift) taking mesh ``points`` onto ``target`` by
    the ``anchors`` (least squares, as :func:`lipsync.videobank.stabilise.fit_similarity`).

    Examples
    --------
    >>> rng = np.random.default_rng(0); p = rng.uniform(0, 100, (468, 2))
    >>> q = p @ np.array([[0.0, 1.0], [-1.0, 0.0]]) * 2 + [5, 7]    # turned 90 degrees, doubled
    >>> m = pose_onto(p, q)
    >>> np.allclose(p @ m[:, :2].T + m[:, 2], q)
    True
    """
    a = np.asarray(points, np.float64)[list(anchors), :2]
    b = np.asarray(target, np.float64)[list(anchors), :2]
    # Umeyama's closed form without reflections, as complex numbers (the stabilisation's
    # fit; not imported from lipsync.videobank, which sits above this room)
    za, zb = a[:, 0] + 1j * a[:, 1], b[:, 0] + 1j * b[:, 1]
    ca, cb = za - za.mean(), zb - zb.mean()
    c = complex((np.conj(ca) * cb).sum() / max(float((np.abs(ca) ** 2).sum()), 1e-300))
    t = complex(zb.mean() - c * za.mean())
    return np.array([[c.real, -c.imag, t.real], [c.imag, c.real, t.imag]])


def skin_ring(mask: np.ndarray, width: float) -> np.ndarray:
    """Boolean ``(H, W)``: pixels outside ``mask`` (0 there) within ``width`` pixels of it.

    Examples
    --------
    >>> m = np.zeros((9, 9), np.float32); m[4, 4] = 1.0
    >>> skin_ring(m, 1.0).sum(), bool(skin_ring(m, 1.0)[4, 4])      # the 4 neighbours, not the centre
    (np.int64(4), False)
    """
    import cv2

    outside = (mask <= 0).astype(np.uint8)
    dist = cv2.distanceTransform(outside, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return (outside > 0) & (dist <= max(width, 1.0))


def face_area(points: np.ndarray, shape: Tuple[int, int]) -> np.ndarray:
    """Boolean ``(H, W)``: inside the face's outline (the jaw and the upper outline of a
    468-point mesh): the skin ring is matched on skin, not on the background or a collar
    beside the jaw."""
    import cv2

    p = np.asarray(points, np.float64)[:, :2]
    outline = np.vstack([p[list(T.JAW_L)], p[list(T.JAW_R[::-1])], p[list(T.FACE_UPPER_R)], p[list(T.FACE_UPPER_L[::-1])]])
    area = np.zeros(shape, np.uint8)
    cv2.fillPoly(area, [np.round(outline * 16).astype(np.int32)], 1, shift=4)
    return area.astype(bool)


def colour_match(source: np.ndarray, target: np.ndarray, where: np.ndarray, *, offset: bool = False
                 ) -> Tuple[np.ndarray, np.ndarray]:
    """Per-channel ``gain, offset`` (each ``(3,)``) bringing ``source``'s pixels in ``where`` to
    ``target``'s; gains clipped to :data:`GAIN_RANGE`.

    Without ``offset`` (the default) the gain is the ratio of the means and the offset 0: a
    camera's exposure and white balance drift is a gain per channel (exact for its power-law
    tone curve, :mod:`lipsync.videobank.colour`), and a ratio of means is not pulled by the
    few pixels of the ring that differ for another reason (a collar, a strand of hair). With
    ``offset``, the least-squares line per channel (gain and black level).

    Examples
    --------
    >>> a = np.random.default_rng(0).integers(40, 200, (8, 8, 3)).astype(np.uint8)
    >>> g, o = colour_match(a, np.round(a * 0.9).astype(np.uint8), np.ones((8, 8), bool))
    >>> np.allclose(g, 0.9, atol=0.005), o.tolist()
    (True, [0.0, 0.0, 0.0])
    >>> b = np.clip(a * 1.1 + 5, 0, 255).round().astype(np.uint8)
    >>> g, o = colour_match(a, b, np.ones((8, 8), bool), offset=True)
    >>> np.allclose(g, 1.1, atol=0.01), np.allclose(o, 5, atol=1.0)
    (True, True)
    """
    s = source[where].reshape(-1, source.shape[-1])[:, :3].astype(np.float64)
    t = target[where].reshape(-1, target.shape[-1])[:, :3].astype(np.float64)
    if len(s) < 8:
        return np.ones(3), np.zeros(3)
    ms, mt = s.mean(axis=0), t.mean(axis=0)
    if not offset:
        return np.clip(mt / np.maximum(ms, 1.0), *GAIN_RANGE), np.zeros(3)
    var = ((s - ms) ** 2).mean(axis=0)
    gain = np.where(var > 1.0, ((s - ms) * (t - mt)).mean(axis=0) / np.maximum(var, 1e-9), 1.0)
    gain = np.clip(gain, *GAIN_RANGE)
    return gain, mt - gain * ms


def apply_colour(image: np.ndarray, gain: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """``image`` (uint8, RGB or RGBA) with ``gain * value + offset`` per colour channel (a lookup table).

    Examples
    --------
    >>> apply_colour(np.full((1, 1, 4), 100, np.uint8), np.array([1.1, 1.0, 0.5]), np.zeros(3))[0, 0].tolist()
    [110, 100, 50, 100]
    """
    lut = np.clip(np.round(np.arange(256)[:, None] * np.asarray(gain)[None, :] + np.asarray(offset)[None, :]),
                  0, 255).astype(np.uint8)
    out = image.copy()
    for c in range(3):
        out[..., c] = lut[image[..., c], c]
    return out


def paste(plate: np.ndarray, face: np.ndarray, mask: np.ndarray, *, method: str = "alpha") -> np.ndarray:
    """``face`` blended onto ``plate`` by ``mask`` (1 = face); exactly ``plate`` where the mask is 0.

    Parameters
    ----------
    plate, face : numpy.ndarray
        uint8 ``(H, W, C)`` of one size (``face`` already on the plate's pose and colour).
    mask : numpy.ndarray
        float ``(H, W)`` in [0, 1] (:func:`lower_face_mask`).
    method : {"alpha", "poisson"}
        ``alpha``: ``plate + mask (face - plate)``. ``poisson``: OpenCV's seamless cloning
        (the face's gradients inside the mask's support, the plate's values on its edge),
        then the feathered alpha on top of that.
    """
    if method not in METHODS:
        raise ValueError(f"unknown paste method {method!r}; valid: {', '.join(METHODS)}")
    m = np.asarray(mask, np.float32)
    src = face
    if method == "poisson" and (m > 0).any():
        import cv2

        support = ((m > 0) * 255).astype(np.uint8)
        ys, xs = np.nonzero(support)
        # seamlessClone places the mask's bounding box centred on ``centre``: its own centre
        centre = (int((xs.min() + xs.max() + 1) // 2), int((ys.min() + ys.max() + 1) // 2))
        src = cv2.seamlessClone(np.ascontiguousarray(face[..., :3]), np.ascontiguousarray(plate[..., :3]),
                                support, centre, cv2.NORMAL_CLONE)
        if face.shape[-1] == 4:
            src = np.concatenate([src, face[..., 3:]], axis=-1)
    out = plate.astype(np.float32) + m[..., None] * (src.astype(np.float32) - plate.astype(np.float32))
    out = np.clip(np.round(out), 0, 255).astype(np.uint8)
    out[m <= 0] = plate[m <= 0]
    return out


@dataclass(frozen=True)
class Pasted:
    """A picture made by :func:`onto_plate`.

    Attributes
    ----------
    image : numpy.ndarray
        The plate with the lower face pasted in.
    points : numpy.ndarray
        Its face mesh: the plate's where the mask is 0, the pasted face's where it is 1, in
        between by the mask (so lines placed from it match the picture).
    mask : numpy.ndarray
        The mask used (float32 ``(H, W)``).
    gain, offset : numpy.ndarray
        The colour match applied to the pasted face (:func:`colour_match`).
    """

    image: np.ndarray
    points: np.ndarray
    mask: np.ndarray
    gain: np.ndarray
    offset: np.ndarray


def onto_plate(plate: np.ndarray, plate_points: np.ndarray, image: np.ndarray, points: np.ndarray, *,
               method: str = "alpha") -> Pasted:
    """``image``'s lower face pasted onto ``plate`` (both already on one pose: the cut of a
    video bank, or :func:`pose_onto` with ``cv2.warpAffine``).

    The mask is the union of both faces' lower-face outlines (:func:`mask_from_mesh`); the
    colour is matched on the plate's skin just outside it (:data:`RING`); the blend is
    :func:`paste`.

    Examples
    --------
    >>> p = np.zeros((468, 2))
    >>> p[list(JAW[0])] = np.c_[np.linspace(20, 50, 11), np.linspace(40, 90, 11)]
    >>> p[list(JAW[1])] = np.c_[np.linspace(80, 50, 11), np.linspace(40, 90, 11)]
    >>> p[list(NOSE_BASE[0])] = [[40, 50], [45, 51], [50, 52]]; p[list(NOSE_BASE[1])] = [[60, 50], [55, 51], [50, 52]]
    >>> p[list(T.EYE_UPPER_L + T.EYE_LOWER_L)] = [30, 30]; p[list(T.EYE_UPPER_R + T.EYE_LOWER_R)] = [70, 30]
    >>> plate = np.full((100, 100, 3), 100, np.uint8); face = np.full((100, 100, 3), 100, np.uint8)
    >>> face[60:80, 40:60] = 20                                   # a dark mouth
    >>> r = onto_plate(plate, p, face, p)
    >>> r.image[70, 50].tolist(), r.image[20, 50].tolist(), bool((r.points == p).all())
    ([20, 20, 20], [100, 100, 100], True)
    """
    from ..face.measure import eye_distance

    h, w = plate.shape[:2]
    p, q = np.asarray(plate_points, np.float64), np.asarray(points, np.float64)

    def merged_by(mask: np.ndarray) -> np.ndarray:
        xy = np.round(q[:, :2]).astype(int)
        inside = (xy[:, 0] >= 0) & (xy[:, 0] < w) & (xy[:, 1] >= 0) & (xy[:, 1] < h)
        m = np.zeros(len(q))
        m[inside] = mask[xy[inside, 1], xy[inside, 0]]
        # rounded as bank.yaml writes them (1/1000 px): the mask made again from the
        # written lines is this one
        return np.round(p + m[:, None] * (q - p), 3)

    # the points follow the pasted face by the mask; the mask that is used is the one of the
    # merged points (and the plate's), so a bank's lines give back exactly this mask
    merged = merged_by(mask_from_mesh([p, q], (h, w)))
    mask = mask_from_mesh([p, merged], (h, w))
    d = float(eye_distance(p))
    gain, offset = colour_match(image, plate, skin_ring(mask, RING * d) & face_area(p, (h, w)))
    out = paste(plate, apply_colour(image, gain, offset), mask, method=method)
    return Pasted(image=out, points=merged, mask=mask, gain=gain, offset=offset)
