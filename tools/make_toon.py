#!/usr/bin/env python3
"""Draw lipsync's default subject "toon": one cartoon face, nine Rhubarb mouth shapes.

The bank (``visemes/toon``) is generated, not hand-drawn, so that it is reproducible and free of
licence questions.  Run from the repository root::

    python tools/make_toon.py               # rewrites visemes/toon/
    python tools/make_toon.py /tmp/toon     # or anywhere else

Output: ``A.png`` … ``H.png`` and ``X.png`` (512×512 RGB) and ``bank.yaml`` with the control
lines.  Only numpy and OpenCV are used and nothing is random, so the output is identical on every
run with the same library versions (``tests/test_toon.py`` checks this).

How it is drawn:

* Everything is painted at ``SUPERSAMPLE``× resolution and averaged down with ``cv2.INTER_AREA``,
  which anti-aliases every edge.
* Only the image-left half (x < 256) is painted; the right half is its mirror image, so the face
  is exactly mirror-symmetric about the vertical axis x = 255.5 (column ``i`` mirrors column
  ``511 - i``).  The control lines are mirror-symmetric about the same axis.
* The mouth is described by a few numbers per viseme (``VISEMES``): the lip contours are
  functions of a parameter ``t`` in [-1, 1] across the mouth, and the control lines are placed on
  those same functions, so every lip line's end points lie on the drawn contour.
* Only the mouth, the lower lip's shadow and the jaw/chin outline change between visemes; all
  other pixels are identical in all nine images (static anchors hold them still in the morph).
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

SIZE = 512
HALF = SIZE // 2
# Column i mirrors column SIZE - 1 - i, so the axis lies between columns 255 and 256.
AXIS = (SIZE - 1) / 2.0
# 4× supersampling: edges get 16 coverage levels after INTER_AREA, smooth enough for
# 8-bit output, and a 1024×2048 half canvas keeps a full run to a few seconds.
SUPERSAMPLE = 4
# Fixed-point bits for cv2.fillPoly/polylines: 1/16 supersampled pixel vertex precision.
SHIFT = 4

# Face layout (output pixels).  Proportions of a friendly cartoon: big eyes at mid-height,
# small nose, a mouth wide enough for the shapes to read at thumbnail size.
EYE_DX, EYE_Y = 62.0, 238.0
MOUTH_Y = 364.0           # mouth line at rest (lips meeting at the centre)
JAW_TOP = 322.0           # head outline above this never moves; below, the jaw drops
CHIN_Y = 448.0
# The only pixels that differ between visemes: rows 322…511, columns 96…415 (mirror-symmetric),
# holding the mouth, the lower lip's shadow, the jaw and chin outline and the chin's shadow on
# the neck.  Everything else is the rest viseme's pixels.
MOUTH_REGION = (slice(int(JAW_TOP), SIZE), slice(96, SIZE - 96))

# Colours (RGB).
BACKGROUND_TOP = (206, 228, 238)
BACKGROUND_BOTTOM = (150, 192, 214)
SKIN = (252, 214, 182)
SKIN_SHADOW = (214, 150, 124)
OUTLINE = (112, 60, 46)
HAIR = (104, 62, 40)
HAIR_LIGHT = (160, 104, 66)
HAIR_DARK = (58, 32, 22)
SHIRT = (62, 132, 150)
SHIRT_DARK = (40, 92, 108)
LIP_UPPER = (194, 86, 94)
LIP_LOWER = (224, 114, 118)
LIP_LINE = (102, 36, 44)
LIP_EDGE = (170, 72, 80)
MOUTH_BACK = (58, 14, 24)
MOUTH_FRONT = (112, 36, 48)
TEETH = (252, 250, 244)
TONGUE = (226, 104, 116)
TONGUE_DARK = (170, 62, 78)
EYE_WHITE = (255, 255, 255)
IRIS = (98, 140, 70)
IRIS_DARK = (48, 78, 36)
PUPIL = (24, 20, 20)
LID = (56, 32, 28)
BLUSH = (244, 140, 140)

# The nine Rhubarb Lip Sync mouth shapes.  Offsets are in output pixels relative to the rest
# mouth line MOUTH_Y; "up"/"lo" are how far the inner upper/lower lip move away from it at the
# centre, "k" the roundness of the opening (1 = lens, 0.5 = ellipse), "thu"/"thl" the upper/lower
# lip thickness at the centre, "tu"/"tl" the y offset of the upper/lower teeth edge at the
# centre (drawn only when "show_tu"/"show_tl"; hidden teeth still get a line, behind the lips),
# "drop" how far the chin moves down.
VISEMES = {
    # Rest, lips closed and relaxed, a faint smile so the idle face looks friendly.
    "X": dict(w=45, cy=-2.5, up=0, lo=0, k=1.0, thu=9, thl=12, tu=-1.5, tl=1.5, drop=0),
    # P B M: lips pressed together, thinner, corners level.
    "A": dict(w=43, cy=0.0, up=0, lo=0, k=1.0, thu=6.5, thl=8.5, tu=-1.5, tl=1.5, drop=0,
              pressed=True),
    # Most consonants and EE: slightly open, teeth clenched and showing.
    "B": dict(w=49, cy=-2.0, up=6.5, lo=7.5, k=0.75, thu=8, thl=10.5, tu=0.0, tl=1.0, drop=2,
              show_tu=True, show_tl=True),
    # EH AE: open, upper teeth and a low tongue.
    "C": dict(w=50, cy=0.0, up=12, lo=20, k=0.6, thu=8, thl=11, tu=-3.0, tl=22, drop=7,
              show_tu=True, tongue="low"),
    # AA: wide open.
    "D": dict(w=52, cy=2.0, up=16, lo=38, k=0.55, thu=7.5, thl=10.5, tu=-6.0, tl=33, drop=15,
              show_tu=True, show_tl=True, tongue="low"),
    # AO ER: slightly rounded.
    "E": dict(w=35, cy=1.0, up=10, lo=15, k=0.5, thu=10.5, thl=13, tu=-4.0, tl=13, drop=5,
              show_tu=True, tongue="low"),
    # UW OW W: puckered.
    "F": dict(w=25, cy=0.0, up=4.5, lo=5.5, k=0.5, thu=13, thl=14.5, tu=-1.0, tl=2.0, drop=3),
    # F V: upper teeth resting on the tucked-in lower lip.
    "G": dict(w=46, cy=-1.0, up=6.5, lo=3.5, k=0.85, thu=8.5, thl=8.5, tu=2.5, tl=6.5, drop=2,
              show_tu=True, teeth_on_lip=True),
    # L: open, tongue tip raised behind the upper teeth.
    "H": dict(w=49, cy=0.0, up=11, lo=18, k=0.6, thu=8, thl=11, tu=-3.5, tl=20, drop=6,
              show_tu=True, tongue="up"),
}
NAMES = tuple(sorted(VISEMES))
REST = "X"

# Parameter values along the lip contours where the lip lines end: the corner (t = ±1), the
# cupid's-bow peak (upper outer contour), a split point 45 % of the way in from the corner
# (where a single chord from corner to centre would cut far inside a round opening), the
# centre (t = 0).
T_BOW = 0.34
T_SPLIT = 0.55
# The dental arch does not change with the lips, so the teeth lines keep one width.
TEETH_HALF = 20.0
# Upper teeth edges curve up toward the sides (smile line); lower edges down.
TEETH_CURVE = 0.0035


# --------------------------------------------------------------------------- drawing helpers


class Canvas:
    """A supersampled RGB float canvas covering output pixels [0, width) × [0, height)."""

    def __init__(self, width: int, height: int, s: int = SUPERSAMPLE):
        self.s = s
        self.img = np.zeros((height * s, width * s, 3), np.float32)

    def _ss(self, pts) -> np.ndarray:
        # Output pixel centres are integers; supersampled pixel centres are integers too.
        return (np.asarray(pts, np.float64) + 0.5) * self.s - 0.5

    def _box(self, polys, pad: float):
        allpts = np.concatenate([self._ss(p) for p in polys])
        h, w = self.img.shape[:2]
        x0 = max(int(math.floor(allpts[:, 0].min() - pad)), 0)
        x1 = min(int(math.ceil(allpts[:, 0].max() + pad)) + 1, w)
        y0 = max(int(math.floor(allpts[:, 1].min() - pad)), 0)
        y1 = min(int(math.ceil(allpts[:, 1].max() + pad)) + 1, h)
        if x0 >= x1 or y0 >= y1:
            return None
        return y0, y1, x0, x1

    def _raster(self, polys, box, *, stroke=0.0, closed=True) -> np.ndarray:
        y0, y1, x0, x1 = box
        m = np.zeros((y1 - y0, x1 - x0), np.uint8)
        fixed = [np.round((self._ss(p) - (x0, y0)) * (1 << SHIFT)).astype(np.int32) for p in polys]
        if stroke:
            cv2.polylines(m, fixed, closed, 255, max(1, round(stroke * self.s)), cv2.LINE_8, SHIFT)
        else:
            # One call per polygon: a single fillPoly of overlapping polygons leaves their
            # overlap empty (even-odd rule); we want the union.
            for f in fixed:
                cv2.fillPoly(m, [f], 255, cv2.LINE_8, SHIFT)
        return m.astype(np.float32) / 255.0

    def grid(self, box):
        """Output-pixel coordinates (X row, Y column) of the supersampled pixels in ``box``."""
        y0, y1, x0, x1 = box
        xs = (np.arange(x0, x1, dtype=np.float32) + 0.5) / self.s - 0.5
        ys = (np.arange(y0, y1, dtype=np.float32) + 0.5) / self.s - 0.5
        return xs[None, :], ys[:, None]

    def coverage(self, polys, *, blur=0.0, clip=None, stroke=0.0, closed=True, pad=0.0):
        if isinstance(polys, np.ndarray):
            polys = [polys]
        box = self._box(polys, pad * self.s + 3 * blur * self.s + stroke * self.s + 2)
        if box is None:
            return None, None
        m = self._raster(polys, box, stroke=stroke, closed=closed)
        if blur:
            # Soft shapes need no supersampled precision: blur at output resolution (a
            # supersampled blur of a 40 px halo costs seconds).
            h, w = m.shape
            small = cv2.resize(m, (max(1, w // self.s), max(1, h // self.s)),
                               interpolation=cv2.INTER_AREA)
            small = cv2.GaussianBlur(small, (0, 0), blur)
            m = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
        if clip is not None:
            clips = [clip] if isinstance(clip, np.ndarray) else clip
            m *= self._raster(clips, box)
        return m, box

    def paint(self, polys, color, *, alpha=1.0, **kw):
        """Composite ``color`` (RGB or a function of the X, Y grids) over the polygons."""
        m, box = self.coverage(polys, **kw)
        if box is None:
            return
        y0, y1, x0, x1 = box
        col = color(*self.grid(box)) if callable(color) else np.asarray(color, np.float32)
        region = self.img[y0:y1, x0:x1]
        region += (col - region) * (m * alpha)[..., None]

    def multiply(self, polys, factor, **kw):
        """Scale the pixels under the polygons by ``factor`` (a number or function of X, Y)."""
        m, box = self.coverage(polys, **kw)
        if box is None:
            return
        y0, y1, x0, x1 = box
        f = factor(*self.grid(box)) if callable(factor) else np.float32(factor)
        self.img[y0:y1, x0:x1] *= (1.0 + m * (f - 1.0))[..., None]

    def result(self) -> np.ndarray:
        h, w = self.img.shape[:2]
        small = cv2.resize(self.img, (w // self.s, h // self.s), interpolation=cv2.INTER_AREA)
        return np.clip(np.round(small), 0, 255).astype(np.uint8)


def ellipse(cx, cy, rx, ry, a0=0.0, a1=2 * math.pi, n=120) -> np.ndarray:
    a = np.linspace(a0, a1, n, endpoint=not math.isclose(a1 - a0, 2 * math.pi))
    return np.stack([cx + rx * np.cos(a), cy + ry * np.sin(a)], 1)


def spline(points, closed=True, n=14) -> np.ndarray:
    """A Catmull–Rom curve through ``points`` (n samples per segment)."""
    p = np.asarray(points, np.float64)
    if closed:
        ext = np.concatenate([p[-1:], p, p[:2]])
        segs = len(p)
    else:
        ext = np.concatenate([2 * p[:1] - p[1:2], p, 2 * p[-1:] - p[-2:-1]])
        segs = len(p) - 1
    u = np.linspace(0.0, 1.0, n, endpoint=False)[:, None]
    out = []
    for i in range(segs):
        p0, p1, p2, p3 = ext[i], ext[i + 1], ext[i + 2], ext[i + 3]
        out.append(0.5 * ((2 * p1) + (-p0 + p2) * u + (2 * p0 - 5 * p1 + 4 * p2 - p3) * u**2
                          + (-p0 + 3 * p1 - 3 * p2 + p3) * u**3))
    if not closed:
        out.append(p[-1:])
    return np.concatenate(out)


def mirror_points(pts) -> np.ndarray:
    q = np.array(pts, np.float64)
    q[..., 0] = 2 * AXIS - q[..., 0]
    return q


def symmetric_closed(left) -> np.ndarray:
    """Close a left-half outline (top on the axis … bottom on the axis) with its mirror."""
    left = np.asarray(left, np.float64)
    return np.concatenate([left, mirror_points(left[-2:0:-1])])


def rotated_ellipse(cx, cy, rx, ry, degrees, n=90) -> np.ndarray:
    a = math.radians(degrees)
    e = ellipse(0.0, 0.0, rx, ry, n=n)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    return e @ rot.T + (cx, cy)


def smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def vertical(top, bottom, y0, y1):
    """A colour function: linear gradient from ``top`` at y0 to ``bottom`` at y1."""
    top, bottom = np.asarray(top, np.float32), np.asarray(bottom, np.float32)

    def f(X, Y):
        a = np.clip((Y - y0) / (y1 - y0), 0, 1)[..., None]
        return top + (bottom - top) * a + 0 * X[..., None]
    return f


# --------------------------------------------------------------------------- the face

# Head outline, image-left side, top of the head to the chin (both on the axis).
HEAD_LEFT = [(AXIS, 72), (204, 77), (156, 98), (122, 138), (106, 192), (103, 250), (107, 300),
             (117, 340), (136, 382), (166, 416), (208, 440), (AXIS, CHIN_Y)]
# A closed spline through the mirrored points is smooth (horizontal) where it crosses the axis.
HEAD = spline(symmetric_closed(HEAD_LEFT), closed=True, n=24)

# The hair cap: crown, sides down to short sideburns, and a straight edge under the fringe
# (the fringe locks below hide it).
HAIR_CAP_LEFT = [(AXIS, 46), (194, 50), (142, 72), (104, 112), (88, 166), (91, 226), (106, 230),
                 (112, 184), (124, 160), (160, 146), (200, 140), (AXIS, 138)]
# Fringe locks: (centre x offset from the axis, centre y, rx, ry, tilt in degrees).  Round
# bottoms give a soft, friendly bob rather than spikes.
FRINGE_LOCKS = [(0.0, 140.0, 20.0, 17.0, 0.0), (-36.0, 141.0, 20.0, 18.0, 12.0),
                (-71.0, 144.0, 19.0, 19.0, 22.0), (-104.0, 156.0, 17.0, 24.0, 28.0),
                (-128.0, 178.0, 12.0, 30.0, 14.0)]


def jaw(pts, drop):
    """Move outline points below JAW_TOP down, smoothly, by up to ``drop`` at the chin."""
    q = np.array(pts, np.float64)
    q[:, 1] += drop * smoothstep((q[:, 1] - JAW_TOP) / (CHIN_Y - JAW_TOP))
    return q


def head_outline(drop):
    return jaw(HEAD, drop)


def brow_polygon():
    centre = spline([(AXIS - 100, 198), (AXIS - 74, 180), (AXIS - 46, 181), (AXIS - 30, 190)],
                    closed=False, n=16)
    d = np.gradient(centre, axis=0)
    nrm = np.stack([-d[:, 1], d[:, 0]], 1) / np.linalg.norm(d, axis=1)[:, None]
    s = np.linspace(0, 1, len(centre))[:, None]
    half = 2.2 + 3.6 * s          # thin at the outer end, thick near the nose
    return np.concatenate([centre + nrm * half, (centre - nrm * half)[::-1]]), centre


def draw_static(c: Canvas, drop: float):
    """Background, body, head, hair and face; ``drop`` only moves the chin."""
    c.paint(np.array([(-2, -2), (SIZE + 2, -2), (SIZE + 2, SIZE + 2), (-2, SIZE + 2)]),
            vertical(BACKGROUND_TOP, BACKGROUND_BOTTOM, 0, SIZE))
    # A soft pale halo behind the head lifts it off the background.
    c.paint(ellipse(AXIS, 250, 215, 235), (230, 242, 246), alpha=0.55, blur=40)

    # Shirt and neck.
    shirt = symmetric_closed([(AXIS, 505), (214, 470), (150, 474), (70, 488), (20, 506),
                              (-10, 530), (AXIS, 530)])
    neck = np.array([(AXIS - 50, 360), (AXIS + 50, 360), (AXIS + 54, 500), (AXIS - 54, 500)])
    c.paint(neck, vertical(SKIN_SHADOW, SKIN, 400, 500))
    # The chin's shadow on the neck moves with the chin.
    c.paint(jaw(HEAD, drop) + (0, 14), SKIN_SHADOW, alpha=0.9, blur=4, clip=neck)
    c.paint(shirt, vertical(SHIRT, SHIRT_DARK, 470, 520))
    c.paint(spline([(170, 473), (214, 471), (AXIS, 506)], closed=False), (104, 178, 190),
            stroke=5, closed=False)
    c.paint(shirt, OUTLINE, stroke=2.5, alpha=0.8)

    # Ears, behind the head.
    for_ear = ellipse(104, 262, 19, 32)
    c.paint(for_ear, SKIN)
    c.paint(ellipse(104, 264, 10, 20), SKIN_SHADOW, alpha=0.55, blur=2.5)
    c.paint(for_ear, OUTLINE, stroke=2.6)

    # Head: skin darkening toward the outline gives a rounded, lit-from-the-front look.
    head = head_outline(drop)
    m, box = c.coverage(head, pad=2)
    y0, y1, x0, x1 = box
    inside = (m > 0.5).astype(np.uint8)
    dist = cv2.distanceTransform(inside, cv2.DIST_L2, 5) / c.s
    X, Y = c.grid(box)
    edge = np.exp(-dist / 17.0)
    base = np.asarray(SKIN, np.float32) * (1.0 - 0.03 * (Y - 250) / 200)[..., None]
    col = base + (np.asarray(SKIN_SHADOW, np.float32) - base) * (0.55 * edge)[..., None]
    region = c.img[y0:y1, x0:x1]
    region += (col - region) * m[..., None]
    # Forehead sheen.
    c.paint(ellipse(AXIS - 30, 150, 40, 24), (255, 236, 214), alpha=0.45, blur=14, clip=head)
    # Blush.
    c.paint(ellipse(AXIS - 94, 318, 28, 16), BLUSH, alpha=0.38, blur=7)

    c.paint(head, OUTLINE, stroke=3.0)

    # Hair: shadow on the forehead, then the hair mass with a highlight band.
    cap = spline(symmetric_closed(HAIR_CAP_LEFT), closed=True, n=12)
    locks = [rotated_ellipse(AXIS + dx, y, rx, ry, tilt) for dx, y, rx, ry, tilt in FRINGE_LOCKS]
    locks += [mirror_points(lk) for lk in locks[1:]]
    hair = [cap] + locks
    c.paint([p + (0, 7) for p in hair], SKIN_SHADOW, alpha=0.6, blur=4, clip=head)
    # Outline first, thick, then the fill over it: only the hair's outer edge stays dark, not
    # the seams between the cap and the locks.
    c.paint(hair, HAIR_DARK, stroke=5.0)
    c.paint(hair, vertical(HAIR_LIGHT, HAIR, 40, 160))
    c.paint(spline([(112, 138), (150, 92), (205, 70), (250, 66)], closed=False), HAIR_LIGHT,
            stroke=10, alpha=0.75, blur=3, closed=False, clip=hair)
    # Strands: a few darker arcs that give the locks direction.
    for dx, y, rx, ry, tilt in FRINGE_LOCKS[1:4]:
        strand = spline([(AXIS + dx + 16, y - 62), (AXIS + dx + 5, y - 26),
                         (AXIS + dx - 3, y + 4)], closed=False)
        c.paint(strand, HAIR_DARK, stroke=1.5, alpha=0.3, blur=0.3, closed=False)

    draw_eye(c)
    brow, _ = brow_polygon()
    c.paint(brow, HAIR)
    c.paint(brow, HAIR_DARK, stroke=1.4)

    # Nose: a soft rounded tip, nostrils, and a shadow under it.
    c.paint(ellipse(AXIS, 314, 20, 6), SKIN_SHADOW, alpha=0.45, blur=3)
    c.paint(ellipse(AXIS, 301, 17, 12), (242, 184, 156), alpha=0.7, blur=2.5)
    c.paint(ellipse(AXIS - 2, 294, 7, 4.5), (255, 240, 228), alpha=0.7, blur=2)
    c.paint(ellipse(AXIS - 8.5, 308, 4.2, 2.6), (150, 82, 72), alpha=0.9)
    c.paint(spline([(AXIS - 19, 298), (AXIS - 16, 309), (AXIS - 9, 312)], closed=False),
            OUTLINE, stroke=1.8, alpha=0.6, closed=False)


def draw_eye(c: Canvas):
    cx, cy = AXIS - EYE_DX, EYE_Y
    sclera = ellipse(cx, cy, 24, 29)
    c.paint(sclera, EYE_WHITE)
    c.paint(ellipse(cx, cy - 26, 30, 14), (200, 196, 206), alpha=0.6, blur=4, clip=sclera)
    iris = ellipse(cx + 3, cy + 4, 15.5, 17)
    c.paint(iris, vertical(IRIS_DARK, IRIS, cy - 12, cy + 18), clip=sclera)
    c.paint(iris, IRIS_DARK, stroke=1.6, clip=sclera)
    c.paint(ellipse(cx + 3, cy + 5, 7.5, 8.5), PUPIL, clip=sclera)
    c.paint(ellipse(cx - 3, cy - 3, 5, 5.5), (255, 255, 255), alpha=0.95)
    c.paint(ellipse(cx + 8, cy + 11, 2.3, 2.3), (255, 255, 255), alpha=0.85)
    # Upper lid: a heavy arc with a flick of lashes at the outer corner; a light lower lid.
    lid = ellipse(cx, cy, 24, 29, math.pi * 1.02, math.pi * 1.98, n=60)
    c.paint(lid, LID, stroke=4.2, closed=False)
    c.paint(np.array([(cx - 22, cy - 9), (cx - 31, cy - 16), (cx - 23, cy - 13)]), LID,
            stroke=2.2, closed=False)
    c.paint(ellipse(cx, cy, 24, 29, math.pi * 0.18, math.pi * 0.82, n=40), LID, stroke=1.4,
            alpha=0.6, closed=False)


# --------------------------------------------------------------------------- the mouth


class Mouth:
    """The lip contours of one viseme as functions of t in [-1, 1] (left corner → right)."""

    def __init__(self, v: dict):
        self.v = v
        self.w = v["w"]

    def x(self, t):
        return AXIS + np.asarray(t, np.float64) * self.w

    def base(self, t):
        return MOUTH_Y + self.v["cy"] * np.asarray(t, np.float64) ** 2

    def open_profile(self, t):
        return np.clip(1.0 - np.asarray(t, np.float64) ** 2, 0, 1) ** self.v["k"]

    def inner_upper(self, t):
        return self.base(t) - self.v["up"] * self.open_profile(t)

    def inner_lower(self, t):
        return self.base(t) + self.v["lo"] * self.open_profile(t)

    def outer_upper(self, t):
        t = np.asarray(t, np.float64)
        # The dip at the centre makes the cupid's bow.
        bow = 1.0 - 0.28 * np.exp(-(t / 0.17) ** 2)
        return self.inner_upper(t) - self.v["thu"] * np.clip(1 - t**2, 0, 1) ** 0.5 * bow

    def outer_lower(self, t):
        t = np.asarray(t, np.float64)
        return self.inner_lower(t) + self.v["thl"] * np.clip(1 - t**2, 0, 1) ** 0.55

    def teeth_upper_y(self, x):
        return MOUTH_Y + self.v["tu"] - TEETH_CURVE * (np.asarray(x) - AXIS) ** 2

    def teeth_lower_y(self, x):
        return MOUTH_Y + self.v["tl"] + TEETH_CURVE * (np.asarray(x) - AXIS) ** 2

    def curve(self, fn, t0=-1.0, t1=1.0, n=97):
        t = np.linspace(t0, t1, n)
        return np.stack([self.x(t), fn(t)], 1)

    def point(self, fn, t):
        return (float(self.x(t)), float(fn(t)))

    @property
    def opening(self):
        return np.concatenate([self.curve(self.inner_upper),
                               self.curve(self.inner_lower)[::-1][1:-1]])

    @property
    def upper_lip(self):
        return np.concatenate([self.curve(self.outer_upper), self.curve(self.inner_upper)[::-1]])

    @property
    def lower_lip(self):
        return np.concatenate([self.curve(self.inner_lower), self.curve(self.outer_lower)[::-1]])


def draw_mouth(c: Canvas, v: dict):
    m = Mouth(v)
    w = m.w
    is_open = v["up"] + v["lo"] > 0
    ol_c = float(m.outer_lower(0.0))

    # Soft shadow under the lower lip (the chin crease) and around a puckered mouth.
    c.paint(ellipse(AXIS, ol_c + 5, 0.55 * w + 4, 5), SKIN_SHADOW, alpha=0.45, blur=3.5)
    if w < 30:
        c.paint(ellipse(AXIS, MOUTH_Y, w + 12, 24), SKIN_SHADOW, alpha=0.25, blur=5)

    if is_open:
        opening = m.opening
        c.paint(opening, vertical(MOUTH_BACK, MOUTH_FRONT, m.inner_upper(0.0),
                                  m.inner_lower(0.0) + 2))
        if v.get("tongue") == "low":
            ry = max(6.0, 0.5 * v["lo"])
            cy = float(m.inner_lower(0.0)) + 0.25 * ry
            tongue = ellipse(AXIS, cy, 0.62 * w, ry)
            draw_tongue(c, tongue, AXIS, cy - ry, ry, opening)
        elif v.get("tongue") == "up":
            bottom = float(m.inner_lower(0.0)) + 6
            tip = float(m.teeth_upper_y(AXIS)) - 2.5
            body = ellipse(AXIS, bottom, 0.62 * w, 0.45 * (bottom - tip))
            raised = ellipse(AXIS, 0.5 * (tip + bottom), 0.3 * w, 0.5 * (bottom - tip))
            c.paint(body, TONGUE_DARK, clip=opening)
            draw_tongue(c, raised, AXIS, tip, 0.5 * (bottom - tip), opening)
        if v.get("show_tl"):
            far = m.inner_lower(0.0) + 10
            band = np.array([(AXIS - 2 * w, far)] + [(x, m.teeth_lower_y(x)) for x in
                            np.linspace(AXIS - 2 * w, AXIS + 2 * w, 41)] + [(AXIS + 2 * w, far)])
            draw_teeth(c, band, opening, w, m.teeth_lower_y, lower=True)
        if v.get("show_tu") and not v.get("teeth_on_lip"):
            draw_teeth(c, teeth_band_upper(m, w), opening, w, m.teeth_upper_y, lower=False)
        # Depth: the opening darkens toward the corners.
        c.multiply(opening, lambda X, Y: 1.0 - 0.45 * np.clip(np.abs(X - AXIS) / w, 0, 1) ** 3)

    # Lips.
    upper, lower = m.upper_lip, m.lower_lip
    lower_col = LIP_UPPER if v.get("teeth_on_lip") else LIP_LOWER
    c.paint(lower, lower_col)
    c.paint(upper, LIP_UPPER)
    # Shade the upper lip toward the inner edge, the lower lip toward its bottom edge.
    c.paint(m.curve(m.inner_upper, -0.9, 0.9), LIP_LINE, stroke=3.5, alpha=0.35, blur=1.2,
            closed=False, clip=upper)
    c.paint(m.curve(m.outer_lower, -0.9, 0.9), LIP_LINE, stroke=3.5, alpha=0.3, blur=1.5,
            closed=False, clip=lower)
    hl_y = 0.5 * (m.inner_lower(0.0) + ol_c) - 0.5
    c.paint(ellipse(AXIS - 0.0, hl_y, 0.3 * w, 0.2 * v["thl"]), (255, 236, 232), alpha=0.55,
            blur=1.8, clip=lower)
    c.paint(ellipse(AXIS - 0.42 * w, float(m.outer_upper(-0.42)) + 0.35 * v["thu"],
                    0.12 * w, 0.14 * v["thu"]), (246, 170, 170), alpha=0.45, blur=1.2,
            clip=upper)
    if v.get("teeth_on_lip"):
        draw_teeth(c, teeth_band_upper(m, w, extra=2.0), None, w, m.teeth_upper_y,
                   lower=False, clip_poly=teeth_clip_on_lip(m))

    c.paint(m.curve(m.outer_upper), LIP_EDGE, stroke=1.3, alpha=0.7, closed=False)
    c.paint(m.curve(m.outer_lower), LIP_EDGE, stroke=1.3, alpha=0.55, closed=False)
    if not is_open:
        width = 2.6 if v.get("pressed") else 2.1
        c.paint(m.curve(m.inner_upper), LIP_LINE, stroke=width, closed=False)
    else:
        c.paint(m.opening, LIP_LINE, stroke=1.5, alpha=0.85)
    # Little creases beyond the corners.
    for side in (-1,):
        cx, cy = float(m.x(side)), float(m.base(side))
        crease = spline([(cx - 1.5, cy - 4.5), (cx - 4.0, cy - 0.5), (cx - 3.0, cy + 3)],
                        closed=False)
        c.paint(crease, SKIN_SHADOW, stroke=1.4, alpha=0.6, blur=0.4, closed=False)


def teeth_band_upper(m: Mouth, w, extra=0.0):
    far = m.inner_upper(0.0) - 10
    xs = np.linspace(AXIS - 2 * w, AXIS + 2 * w, 41)
    return np.array([(AXIS + 2 * w, far), (AXIS - 2 * w, far)]
                    + [(x, m.teeth_upper_y(x) + extra) for x in xs])


def teeth_clip_on_lip(m: Mouth):
    # For F/V the upper teeth sit over the tucked lower lip: clip them to the opening plus the
    # top of the lower lip.
    return np.concatenate([m.curve(m.inner_upper),
                           m.curve(lambda t: m.inner_lower(t) + 3 * m.open_profile(t))[::-1]])


def draw_tongue(c: Canvas, shape, cx, top, ry, clip):
    c.paint(shape, vertical(TONGUE, TONGUE_DARK, top, top + 2.2 * ry), clip=clip)
    c.paint(np.array([(cx, top + 0.25 * ry), (cx, top + 1.2 * ry)]), TONGUE_DARK, stroke=1.6,
            alpha=0.7, blur=0.8, closed=False, clip=clip)
    c.paint(ellipse(cx - 0.35 * ry, top + 0.45 * ry, 0.5 * ry, 0.22 * ry), (250, 170, 176),
            alpha=0.5, blur=1.2, clip=clip)


def draw_teeth(c: Canvas, band, opening, w, edge_y, *, lower, clip_poly=None):
    clip = opening if clip_poly is None else clip_poly
    # Teeth further back (toward the corners) are in shadow.
    def col(X, Y):
        d = np.clip(np.abs(X - AXIS) / w, 0, 1)
        return (np.asarray(TEETH, np.float32) * (1.0 - 0.42 * d ** 2)[..., None]
                + 0 * Y[..., None])
    c.paint(band, col, clip=clip)
    # Gaps between the teeth: incisors wide, then narrower.
    for x in (AXIS, AXIS - 13.0, AXIS - 24.5, AXIS - 34.5, AXIS + 13.0, AXIS + 24.5,
              AXIS + 34.5):
        y = float(edge_y(x))
        seg = np.array([(x, y - (-1 if lower else 1) * 0.5), (x, y - (-1 if lower else 1) * 14)])
        c.paint(seg, (196, 186, 184), stroke=1.1, alpha=0.85, closed=False, clip=clip)
    xs = np.linspace(AXIS - w, AXIS + w, 41)
    c.paint(np.stack([xs, edge_y(xs)], 1), (200, 190, 188), stroke=1.0, alpha=0.8, closed=False,
            clip=clip)


# --------------------------------------------------------------------------- control lines

HEAD_DENSE = HEAD[HEAD[:, 0] <= AXIS]


def _outline_vertex(y):
    """The drawn head-outline vertex (left side) nearest to height ``y`` at rest."""
    i = int(np.argmin(np.abs(HEAD_DENSE[:, 1] - y)))
    return HEAD_DENSE[i]


def control_lines(v: dict) -> dict:
    """name → ((Px, Py), (Qx, Qy)) for one viseme; *_r are mirrors of *_l."""
    m = Mouth(v)
    left = {
        # Lips: corner → cupid's-bow peak → centre; corner → split point → centre.
        "upper_outer_l": (m.point(m.outer_upper, -1.0), m.point(m.outer_upper, -T_BOW)),
        "upper_bow_l": (m.point(m.outer_upper, -T_BOW), m.point(m.outer_upper, 0.0)),
        "lower_outer_l": (m.point(m.outer_lower, -1.0), m.point(m.outer_lower, -T_SPLIT)),
        "lower_outer_mid_l": (m.point(m.outer_lower, -T_SPLIT), m.point(m.outer_lower, 0.0)),
        "upper_inner_l": (m.point(m.inner_upper, -1.0), m.point(m.inner_upper, -T_SPLIT)),
        "upper_inner_mid_l": (m.point(m.inner_upper, -T_SPLIT), m.point(m.inner_upper, 0.0)),
        "lower_inner_l": (m.point(m.inner_lower, -1.0), m.point(m.inner_lower, -T_SPLIT)),
        "lower_inner_mid_l": (m.point(m.inner_lower, -T_SPLIT), m.point(m.inner_lower, 0.0)),
        # The corner, pointing into it from the cheek.
        "corner_l": ((float(m.x(-1.0)) - 10.0, float(m.base(-1.0))), m.point(m.base, -1.0)),
    }
    # The jaw outline in two pieces, cheek → jaw angle → chin centre (on the drawn outline,
    # which the chin drop moves).
    jaw_top, jaw_low, chin = jaw(np.array([_outline_vertex(340), _outline_vertex(416),
                                           HEAD_DENSE[np.argmax(HEAD_DENSE[:, 1])]]), v["drop"])
    left["jaw_l"] = (tuple(jaw_top), tuple(jaw_low))
    left["chin_l"] = (tuple(jaw_low), tuple(chin))
    # Static anchors: identical in every viseme.
    left["cheek_l"] = (tuple(_outline_vertex(190)), tuple(_outline_vertex(300)))
    left["eye_l"] = ((AXIS - EYE_DX - 24, EYE_Y), (AXIS - EYE_DX + 24, EYE_Y))
    _, brow = brow_polygon()
    left["brow_l"] = (tuple(brow[0]), tuple(brow[-1]))
    # The hair's side and the shoulders: without anchors up there, the chin drop of the
    # open shapes would drag the top of the head along (Beier-Neely weights fall off only
    # as 1/dist^2), which showed as a double outline on the hair mid-morph.
    left["hair_l"] = ((142.0, 72.0), (104.0, 112.0))
    left["shoulder_l"] = ((30.0, 500.0), (130.0, 478.0))

    lines = {}
    for name, (p, q) in left.items():
        lines[name] = (p, q)
        lines[name[:-2] + "_r"] = tuple(map(tuple, mirror_points([p, q])))
    lines["teeth_upper"] = ((AXIS - TEETH_HALF, float(m.teeth_upper_y(AXIS - TEETH_HALF))),
                            (AXIS + TEETH_HALF, float(m.teeth_upper_y(AXIS + TEETH_HALF))))
    lines["teeth_lower"] = ((AXIS - TEETH_HALF, float(m.teeth_lower_y(AXIS - TEETH_HALF))),
                            (AXIS + TEETH_HALF, float(m.teeth_lower_y(AXIS + TEETH_HALF))))
    lines["nose"] = ((AXIS, 262.0), (AXIS, 302.0))
    lines["nostrils"] = ((AXIS - 12.5, 308.0), (AXIS + 12.5, 308.0))
    # The shirt's neckline: holds the neck and shirt still under a moving chin.
    lines["collar"] = ((AXIS - 106.0, 473.0), (AXIS + 106.0, 473.0))
    lines["crown"] = ((AXIS - 60.0, 48.0), (AXIS + 60.0, 48.0))
    # The picture's frame: pins the image corners, where lines far away would otherwise
    # extrapolate the mouth's motion (a line's influence grows with distance along it).
    lines["frame_top"] = ((AXIS - 240.0, 4.0), (AXIS + 240.0, 4.0))
    lines["frame_side_l"] = ((4.0, 24.0), (4.0, 488.0))
    lines["frame_side_r"] = ((SIZE - 5.0, 24.0), (SIZE - 5.0, 488.0))
    return lines


# --------------------------------------------------------------------------- output


def _render_full(name: str) -> np.ndarray:
    v = VISEMES[name]
    c = Canvas(HALF, SIZE)
    draw_static(c, v["drop"])
    draw_mouth(c, v)
    left = c.result()
    return np.concatenate([left, left[:, ::-1]], axis=1)


def render(name: str, rest: np.ndarray | None = None) -> np.ndarray:
    """The 512×512 RGB uint8 image of one viseme.

    Outside MOUTH_REGION the pixels are copied from the rest viseme, so that they are identical
    in every image by construction (soft shadows' faint tails would otherwise differ by one
    level here and there).
    """
    img = _render_full(name)
    if rest is None or name == REST:
        return img
    out = rest.copy()
    out[MOUTH_REGION] = img[MOUTH_REGION]
    return out


def _fmt(x: float) -> str:
    r = round(float(x), 3)
    return repr(r + 0.0)


def bank_yaml(all_lines: dict) -> str:
    out = ["# Generated by tools/make_toon.py -- edit the generator, not this file.",
           "name: toon",
           f"rest: {REST}",
           # b = 4 rather than the default 2: with ~20 moving lip lines, b = 2 lets the
           # mouth drag the hair and the image corners by several pixels (weights fall
           # off only as 1/dist^2); with b = 4 motion above a quarter pixel stays in the
           # lower face (30% of the frame, against all of it with b = 2).
           "warp: {a: 1.0, b: 4.0, p: 0.5}",
           "symmetry: true    # mirror axis x = 255.5 (column i mirrors column 511 - i)",
           "visemes:"]
    for name in NAMES:
        out.append(f"  {name}:")
        out.append(f"    image: {name}.png")
        out.append("    lines:")
        for ln, (p, q) in all_lines[name].items():
            out.append(f"      {ln}: [[{_fmt(p[0])}, {_fmt(p[1])}], [{_fmt(q[0])}, {_fmt(q[1])}]]")
    return "\n".join(out) + "\n"


def _write_atomic(path: Path, data: bytes):
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        # mkstemp makes the file private (0600); an image is meant to be shared.  (Reading the
        # umask would mean setting it, which is not thread-safe.)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _round_mirror(lines: dict) -> dict:
    """Round to 1/1000 px on the image-left side and mirror, so symmetry stays exact."""
    out = {}
    for name, (p, q) in lines.items():
        if name.endswith("_r"):
            continue
        rp = (round(p[0], 3), round(p[1], 3))
        rq = (round(q[0], 3), round(q[1], 3))
        out[name] = (rp, rq)
        if name.endswith("_l"):
            out[name[:-2] + "_r"] = ((round(2 * AXIS - rp[0], 3), rp[1]),
                                     (round(2 * AXIS - rq[0], 3), rq[1]))
        elif rp[0] != rq[0]:       # a horizontal self line: make Q the exact mirror of P
            out[name] = (rp, (round(2 * AXIS - rp[0], 3), rp[1]))
    # Keep the declared order: pairs first, then self lines.
    return {k: out[k] for k in lines}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    root = Path(__file__).resolve().parent.parent
    out_dir = Path(argv[0]) if argv else root / "visemes" / "toon"
    out_dir.mkdir(parents=True, exist_ok=True)
    all_lines = {}
    rest = render(REST)
    for name in NAMES:
        rgb = render(name, rest)
        ok, png = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR),
                               [cv2.IMWRITE_PNG_COMPRESSION, 9])
        if not ok:
            raise RuntimeError(f"PNG encoding failed for {name}")
        _write_atomic(out_dir / f"{name}.png", png.tobytes())
        all_lines[name] = _round_mirror(control_lines(VISEMES[name]))
    _write_atomic(out_dir / "bank.yaml", bank_yaml(all_lines).encode())
    print(f"wrote {len(NAMES)} visemes and bank.yaml to {out_dir}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
