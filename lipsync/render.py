"""Frames between two visemes (paper 3.4, with DESIGN.md's erratum 1 fixed).

At ``alpha`` the first image moves by ``alpha * forward_flow`` and the second by
``(1 - alpha) * backward_flow``; the frame is ``(1 - alpha) * A' + alpha * B'``. So
alpha = 0 shows A and alpha = 1 shows B exactly.

Methods (registry :data:`METHODS`):

``flow`` (default)
    Gather with ``cv2.remap``. Output pixel Y takes A at the X that moves onto it,
    ``X + alpha F(X) = Y``, and likewise B with ``(1 - alpha)`` and the backward flow.
    X is found by Newton's method from ``X0 = Y - alpha F(Y)`` with the flow's Jacobian
    (precomputed once per pair). The plain fixed-point iteration ``X <- Y - alpha F(X)``
    is cheaper per step but diverges where ``alpha |dF/dX| > 1``, which is exactly where a
    closed mouth opens (the lips' gap expands five-fold or more). The inverse map is
    smooth, so it is solved on a grid of every :data:`SOLVE_STEP`-th pixel and its
    displacement upsampled bilinearly; only the image lookup runs at full resolution.
    Only the box where the (dead-zoned, see :mod:`lipsync.store`) flows are non-zero or
    the images differ is rendered; the rest of the frame is the common background.
``splat``
    The paper's forward mapping: every pixel of A is carried to ``X + alpha F(X)``. The
    paper rounds that to the nearest pixel; here each pixel is shared bilinearly among the
    four pixels around its target and the sums are normalised (the same forward mapping,
    without the half-pixel jitter that rounding puts on every edge). Pixels that receive
    nothing are holes where the image expands; they are inpainted from their surroundings.
``beier-neely``
    The classic morph: interpolate the lines, warp both images to them with a full
    Beier–Neely warp every frame. The quality reference and the speed baseline.
``dissolve``
    A cross-fade: the baseline any morph must beat.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple

import cv2
import numpy as np

from .bank import Bank
from .errors import InputError
from .flows import pair_flows
from .normalise import NormalisedBank, normalise
from .registry import Registry
from .store import Crop, FlowStore, StoredField
from .warp import beier_neely_map, identity_grid

#: Newton steps inverting ``Y = X + alpha F(X)`` after the first-order guess. Three steps
#: leave a residual under 0.05 px at 99.9% of pixels even where a closed mouth opens
#: five-fold; more steps gain nothing, bilinear sampling of F limits it (measured in
#: tests/test_render.py against 30 steps).
FLOW_ITERATIONS = 3
#: Anchors of the warm start: the inverse map is solved from scratch (FLOW_ITERATIONS steps)
#: only at alpha = k / WARM_ANCHORS, once per pair and side; a frame at any other alpha
#: starts from the nearest anchor's solution, at most 1/8 away, and needs WARM_ITERATIONS
#: steps for the same accuracy. Anchors (not the previous frame) keep every frame a pure
#: function of (pair, alpha), whatever order frames are asked for in.
WARM_ANCHORS = 4
WARM_ITERATIONS = 2
#: Smallest Jacobian determinant a Newton step divides by. Where the warp folds over
#: (det <= 0) there is no unique inverse; clamping keeps those rare pixels finite.
MIN_DET = 0.05
#: Largest Newton correction (px) per step, for the same reason.
MAX_STEP = 4.0
#: Extra pixels around the moving region: bilinear taps reach one pixel out.
ROI_MARGIN = 2
#: The inverse map is solved on every SOLVE_STEP-th pixel and upsampled: 4x less work
#: for the Newton steps; the map is smooth, so bilinear upsampling of its displacement
#: costs under 0.05 px on average (tests/test_render.py measures it).
SOLVE_STEP = 2
#: Splat holes are filled by Telea inpainting with this radius (px): holes from
#: expansion are one or two pixels wide, so a small radius keeps edges sharp.
INPAINT_RADIUS = 2
#: A splatted pixel whose summed bilinear weight is below this is a hole: its colour
#: would rest on a sliver of one source pixel.
MIN_SPLAT_WEIGHT = 0.05
#: Cached per-pair states (ROI-sized arrays); 9 visemes need at most 72.
MAX_PAIR_STATES = 96

METHODS: Registry[str] = Registry("morph method")
for _name, _why in [("flow", "interpolate the cached flows (fast, default)"),
                    ("splat", "paper's forward splat with hole filling"),
                    ("beier-neely", "full Beier-Neely warp every frame (reference, slow)"),
                    ("dissolve", "cross-fade only (baseline)")]:
    METHODS.register(_name, _why, aliases=[_name.replace("-", "_")] if "-" in _name else [])


@dataclass
class _Pair:
    """Everything a frame of the ordered pair (a, b) needs, allocated once."""

    a: str
    b: str
    roi: Crop
    img_a: np.ndarray          # ROI views of the normalised images
    img_b: np.ndarray
    fwd: np.ndarray            # float32 (h, w, 2) flows inside the ROI
    bwd: np.ndarray
    jac_f: np.ndarray          # float32 (h, w, 4) Jacobians d(flow)/d(x, y): xx, xy, yx, yy
    jac_b: np.ndarray
    grid: np.ndarray           # ROI-relative identity grid (full resolution)
    coarse: np.ndarray         # the coarse solve grid, in full-resolution coordinates
    map_a: np.ndarray          # full-resolution maps handed to cv2.remap
    map_b: np.ndarray
    work: "_NewtonBuffers"
    buf_a: np.ndarray
    buf_b: np.ndarray
    anchors: Dict[Tuple[str, int], np.ndarray] = field(default_factory=dict)  # (side, k) -> coarse X


@dataclass
class _NewtonBuffers:
    """Per-pair scratch planes for the Newton inversion (allocated once)."""

    m: np.ndarray     # (h, w, 2) current estimate of X on the coarse grid
    fixed_xy: np.ndarray   # (H, W, 2) int16 and (H, W) uint16: cv2.convertMaps' fixed-point map
    fixed_frac: np.ndarray
    sampled: np.ndarray  # (h, w, 2) flow sampled at X
    disp: np.ndarray  # (H, W, 2) upsampled displacement X - Y at full resolution
    jac: np.ndarray   # (h, w, 4) Jacobian sampled at X
    rx: np.ndarray
    ry: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    det: np.ndarray
    t1: np.ndarray

    @classmethod
    def allocate(cls, h: int, w: int, full: Tuple[int, int]) -> "_NewtonBuffers":
        planes = [np.empty((h, w), np.float32) for _ in range(8)]
        return cls(np.empty((h, w, 2), np.float32), np.empty(full + (2,), np.int16), np.empty(full, np.uint16),
                   np.empty((h, w, 2), np.float32), np.empty(full + (2,), np.float32),
                   np.empty((h, w, 4), np.float32), *planes)


def _jacobian(flow: np.ndarray) -> np.ndarray:
    """d(flow)/d(x, y) by central differences, as (h, w, 4): dFx/dx, dFx/dy, dFy/dx, dFy/dy."""
    jac = np.empty(flow.shape[:2] + (4,), np.float32)
    for c in range(2):
        if flow.shape[0] > 1 and flow.shape[1] > 1:
            gy, gx = np.gradient(flow[..., c])
        else:
            gy = gx = np.zeros(flow.shape[:2], np.float32)
        jac[..., 2 * c] = gx
        jac[..., 2 * c + 1] = gy
    return jac


def _union(boxes, shape, margin) -> Crop:
    boxes = [b for b in boxes if not b.empty]
    if not boxes:
        return Crop(0, 0, 0, 0)
    h, w = shape
    return Crop(max(0, min(b.y0 for b in boxes) - margin), min(h, max(b.y1 for b in boxes) + margin),
                max(0, min(b.x0 for b in boxes) - margin), min(w, max(b.x1 for b in boxes) + margin))


def _difference_box(a: np.ndarray, b: np.ndarray) -> Crop:
    diff = np.any(a != b, axis=2)
    rows = np.flatnonzero(diff.any(axis=1))
    if rows.size == 0:
        return Crop(0, 0, 0, 0)
    cols = np.flatnonzero(diff.any(axis=0))
    return Crop(int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1)


class Renderer:
    """Renders in-between frames of a bank, reusing buffers and flows across frames.

    Parameters
    ----------
    bank : Bank or NormalisedBank
        The subject. A plain bank is normalised first.
    method : str
        One of :data:`METHODS`: ``flow``, ``splat``, ``beier-neely``, ``dissolve``.
    store : FlowStore, optional
        Where flows are read from (and written to, when a pair is missing); default: the
        bank's store. Missing pairs are computed on first use.

    Examples
    --------
    >>> from lipsync._data import default_bank_dir
    >>> r = Renderer(Bank.load(default_bank_dir()))
    >>> frame = r.render("A", "D", 0.5)
    >>> frame.shape, frame.dtype
    ((512, 512, 3), dtype('uint8'))
    """

    def __init__(self, bank, *, method: str = "flow", store: Optional[FlowStore] = None):
        METHODS.get(method)  # raises, listing the valid names, if unknown
        self.method = _canonical(method)
        self.bank: Bank = bank.bank if isinstance(bank, NormalisedBank) else bank
        self.store = store if store is not None else FlowStore.for_bank(self.bank)
        self.nb: NormalisedBank = bank if isinstance(bank, NormalisedBank) else normalise(self.bank, cache=self.store)
        h, w = self.nb.shape
        self.shape = (h, w)
        self._frame = np.empty((h, w, 3), np.uint8)
        self._frame_pair: Optional[Tuple[str, str]] = None
        self._pairs: "OrderedDict[Tuple[str, str], _Pair]" = OrderedDict()
        self._full_a = np.empty((h, w, 3), np.uint8)
        self._full_b = np.empty((h, w, 3), np.uint8)

    # ------------------------------------------------------------------ public
    def render(self, from_viseme: str, to_viseme: str, alpha: float, *, out: Optional[np.ndarray] = None
               ) -> np.ndarray:
        """The frame at ``alpha`` between two visemes, RGB ``uint8`` ``(H, W, 3)``.

        Without ``out`` the returned array is the renderer's own buffer, overwritten by the
        next call: copy it to keep it.
        """
        self._check(from_viseme, to_viseme, alpha)
        frame = self._frame if out is None else out
        imgs = self.nb.images
        if from_viseme == to_viseme or alpha <= 0.0:
            np.copyto(frame, imgs[from_viseme])
            self._frame_pair = None
            return frame
        if alpha >= 1.0:
            np.copyto(frame, imgs[to_viseme])
            self._frame_pair = None
            return frame
        if self.method == "dissolve":
            cv2.addWeighted(imgs[from_viseme], 1.0 - alpha, imgs[to_viseme], alpha, 0.0, dst=frame)
            self._frame_pair = None
            return frame
        if self.method == "beier-neely":
            wa, wb = self._beier_neely_parts(from_viseme, to_viseme, alpha)
            cv2.addWeighted(wa, 1.0 - alpha, wb, alpha, 0.0, dst=frame)
            self._frame_pair = None
            return frame
        pair = self._pair(from_viseme, to_viseme)
        if out is not None or self._frame_pair != (from_viseme, to_viseme):
            # Outside the ROI both images are equal and nothing moves.
            np.copyto(frame, imgs[from_viseme])
            if out is None:
                self._frame_pair = (from_viseme, to_viseme)
        if pair.roi.empty:
            return frame
        if self.method == "flow":
            self._flow_parts(pair, alpha)
        else:
            self._splat_parts(pair, alpha)
        r = pair.roi
        cv2.addWeighted(pair.buf_a, 1.0 - alpha, pair.buf_b, alpha, 0.0, dst=frame[r.y0:r.y1, r.x0:r.x1])
        return frame

    def parts(self, from_viseme: str, to_viseme: str, alpha: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(forward warp of A, backward warp of B, blended frame)`` at ``alpha``, as new arrays.

        The rows of the paper's figures 8 and 9 (used by ``lipsync morph --frames``).
        """
        self._check(from_viseme, to_viseme, alpha)
        imgs = self.nb.images
        a, b = imgs[from_viseme], imgs[to_viseme]
        if self.method == "dissolve" or from_viseme == to_viseme:
            wa, wb = a.copy(), b.copy()
        elif self.method == "beier-neely":
            wa, wb = (x.copy() for x in self._beier_neely_parts(from_viseme, to_viseme, alpha))
        else:
            pair = self._pair(from_viseme, to_viseme)
            wa, wb = a.copy(), b.copy()
            if not pair.roi.empty:
                (self._flow_parts if self.method == "flow" else self._splat_parts)(pair, alpha)
                r = pair.roi
                wa[r.y0:r.y1, r.x0:r.x1] = pair.buf_a
                wb[r.y0:r.y1, r.x0:r.x1] = pair.buf_b
        blend = cv2.addWeighted(wa, 1.0 - alpha, wb, alpha, 0.0)
        return wa, wb, blend

    # ------------------------------------------------------------------ checks
    def _check(self, a: str, b: str, alpha: float) -> None:
        for v in (a, b):
            if v not in self.nb.images:
                raise InputError(f"unknown viseme {v!r}; the bank {self.bank.name!r} has "
                                 f"{', '.join(self.bank.names)}", path=self.bank.yaml_path)
        if not (0.0 <= alpha <= 1.0) or alpha != alpha:
            raise InputError(f"alpha must be between 0 and 1, got {alpha}")

    # ------------------------------------------------------------------ pair state
    def _flows(self, a: str, b: str) -> Tuple[StoredField, StoredField]:
        got = self.store.get_pair(self.bank, a, b)
        if got is not None:
            return got
        nb = self.nb
        i, j = self.bank.names.index(a), self.bank.names.index(b)
        first, second = (a, b) if i <= j else (b, a)
        fwd, bwd = pair_flows(self.shape, nb.lines[first], nb.lines[second], self.bank.warp,
                              line_names=self.bank.line_names, axis=nb.axis)
        key = self.store.pair_key(self.bank, first, second, nb.axis)
        try:
            self.store.put_pair(key, fwd, bwd, axis=nb.axis, names=(first, second))
            got = self.store.load_pair(key, self.shape)
        except OSError:
            got = None  # unwritable store: use the fields directly
        if got is None:
            full = Crop(0, self.shape[0], 0, self.shape[1])
            got = (StoredField(self.shape, full, fwd), StoredField(self.shape, full, bwd))
        return got if (first, second) == (a, b) else (got[1], got[0])

    def _pair(self, a: str, b: str) -> _Pair:
        key = (a, b)
        pair = self._pairs.get(key)
        if pair is not None:
            self._pairs.move_to_end(key)
            return pair
        fwd, bwd = self._flows(a, b)
        ia, ib = self.nb.images[a], self.nb.images[b]
        roi = _union([fwd.crop, bwd.crop, _difference_box(ia, ib)], self.shape, ROI_MARGIN)
        h, w = roi.y1 - roi.y0, roi.x1 - roi.x0
        sl = (slice(roi.y0, roi.y1), slice(roi.x0, roi.x1))
        fwd_full = np.ascontiguousarray(fwd.full()[sl])
        bwd_full = np.ascontiguousarray(bwd.full()[sl])
        hc, wc = -(-h // SOLVE_STEP), -(-w // SOLVE_STEP)
        # Coarse point (i, j) sits at the centre of the fine block it covers, which is where
        # cv2.resize puts it when upsampling by SOLVE_STEP.
        coarse = identity_grid((hc, wc)) * SOLVE_STEP + (SOLVE_STEP - 1) / 2.0
        pair = _Pair(a=a, b=b, roi=roi, img_a=ia[sl], img_b=ib[sl], fwd=fwd_full, bwd=bwd_full,
                     jac_f=_jacobian(fwd_full), jac_b=_jacobian(bwd_full),
                     grid=identity_grid((h, w)), coarse=coarse.astype(np.float32),
                     map_a=np.empty((h, w, 2), np.float32), map_b=np.empty((h, w, 2), np.float32),
                     work=_NewtonBuffers.allocate(hc, wc, (h, w)),
                     buf_a=np.empty((h, w, 3), np.uint8), buf_b=np.empty((h, w, 3), np.uint8))
        self._pairs[key] = pair
        if len(self._pairs) > MAX_PAIR_STATES:
            self._pairs.popitem(last=False)
        return pair

    # ------------------------------------------------------------------ methods
    @staticmethod
    def _invert(flow: np.ndarray, jac: np.ndarray, t: float, grid: np.ndarray, m: np.ndarray,
                sampled: np.ndarray, wk: _NewtonBuffers) -> None:
        """Write into ``m`` the X with ``X + t*flow(X) = grid`` (Newton's method).

        ``grid`` holds the target points Y (any positions, in the flow's pixel coordinates);
        ``m`` and ``sampled`` have its shape.
        """
        cv2.remap(flow, grid, None, cv2.INTER_LINEAR, dst=sampled, borderMode=cv2.BORDER_REPLICATE)
        cv2.addWeighted(sampled, -t, grid, 1.0, 0.0, dst=m)  # first-order guess Y - t F(Y)
        Renderer._newton(flow, jac, t, grid, m, sampled, wk, FLOW_ITERATIONS)

    @staticmethod
    def _newton(flow: np.ndarray, jac: np.ndarray, t: float, grid: np.ndarray, m: np.ndarray,
                sampled: np.ndarray, wk: _NewtonBuffers, iterations: int) -> None:
        """Refine ``m`` toward ``X + t*flow(X) = grid`` by ``iterations`` Newton steps."""
        mx, my = m[..., 0], m[..., 1]
        for _ in range(iterations):
            cv2.remap(flow, m, None, cv2.INTER_LINEAR, dst=sampled, borderMode=cv2.BORDER_REPLICATE)
            cv2.remap(jac, m, None, cv2.INTER_LINEAR, dst=wk.jac, borderMode=cv2.BORDER_REPLICATE)
            # residual r = X + t F(X) - Y
            cv2.addWeighted(sampled, t, m, 1.0, 0.0, dst=sampled)
            np.subtract(sampled[..., 0], grid[..., 0], out=wk.rx)
            np.subtract(sampled[..., 1], grid[..., 1], out=wk.ry)
            # M = I + t J(X) = [[a, b], [c, d]]; step = M^-1 r
            np.multiply(wk.jac[..., 0], t, out=wk.a)
            wk.a += 1.0
            np.multiply(wk.jac[..., 1], t, out=wk.b)
            np.multiply(wk.jac[..., 2], t, out=wk.c)
            np.multiply(wk.jac[..., 3], t, out=wk.d)
            wk.d += 1.0
            np.multiply(wk.a, wk.d, out=wk.det)
            np.multiply(wk.b, wk.c, out=wk.t1)
            wk.det -= wk.t1
            np.maximum(wk.det, MIN_DET, out=wk.det)
            # dx = (d rx - b ry) / det ; dy = (a ry - c rx) / det
            np.multiply(wk.d, wk.rx, out=wk.t1)
            wk.b *= wk.ry
            wk.t1 -= wk.b
            wk.t1 /= wk.det
            np.clip(wk.t1, -MAX_STEP, MAX_STEP, out=wk.t1)
            wk.a *= wk.ry
            wk.c *= wk.rx
            wk.a -= wk.c
            wk.a /= wk.det
            np.clip(wk.a, -MAX_STEP, MAX_STEP, out=wk.a)
            mx -= wk.t1
            my -= wk.a

    def _solve_coarse(self, p: _Pair, side: str, flow: np.ndarray, jac: np.ndarray, t: float) -> None:
        """Leave in ``p.work.m`` the coarse-grid X with ``X + t*flow(X) = Y`` (warm-started)."""
        wk = p.work
        k = int(round(t * WARM_ANCHORS))
        if k == 0:  # near alpha 0 the first-order guess is as good as an anchor
            self._invert(flow, jac, t, p.coarse, wk.m, wk.sampled, wk)
            return
        anchor = p.anchors.get((side, k))
        if anchor is None:
            self._invert(flow, jac, k / WARM_ANCHORS, p.coarse, wk.m, wk.sampled, wk)
            anchor = p.anchors[(side, k)] = wk.m.copy()
        np.copyto(wk.m, anchor)
        if t != k / WARM_ANCHORS:
            self._newton(flow, jac, t, p.coarse, wk.m, wk.sampled, wk, WARM_ITERATIONS)

    def _gather(self, p: _Pair, side: str, image: np.ndarray, flow: np.ndarray, jac: np.ndarray, t: float,
                m: np.ndarray, out: np.ndarray) -> None:
        """``out[Y] = image[X]`` with ``X + t*flow(X) = Y``, X solved on the coarse grid."""
        wk = p.work
        self._solve_coarse(p, side, flow, jac, t)
        # Upsample the displacement X - Y (not X itself): it vanishes at the ROI's edge, so
        # the edge clamping of cv2.resize costs nothing there.
        wk.m -= p.coarse
        h, w = m.shape[:2]
        cv2.resize(wk.m, (w, h), dst=wk.disp, interpolation=cv2.INTER_LINEAR)
        np.add(p.grid, wk.disp, out=m)
        # Fixed-point maps remap ~1.7x faster than float maps; 1/32 px resolution is plenty.
        m1, m2 = cv2.convertMaps(m, None, cv2.CV_16SC2, dstmap1=wk.fixed_xy, dstmap2=wk.fixed_frac)
        cv2.remap(image, m1, m2, cv2.INTER_LINEAR, dst=out, borderMode=cv2.BORDER_REPLICATE)

    def _flow_parts(self, p: _Pair, alpha: float) -> None:
        self._gather(p, "a", p.img_a, p.fwd, p.jac_f, alpha, p.map_a, p.buf_a)
        self._gather(p, "b", p.img_b, p.bwd, p.jac_b, 1.0 - alpha, p.map_b, p.buf_b)

    def _splat_parts(self, p: _Pair, alpha: float) -> None:
        _splat(p.img_a, p.fwd, alpha, p.grid, p.buf_a)
        _splat(p.img_b, p.bwd, 1.0 - alpha, p.grid, p.buf_b)

    def _beier_neely_parts(self, a: str, b: str, alpha: float) -> Tuple[np.ndarray, np.ndarray]:
        nb, w = self.nb, self.bank.warp
        lines = (1.0 - alpha) * nb.lines[a] + alpha * nb.lines[b]
        for src, out in ((a, self._full_a), (b, self._full_b)):
            m = beier_neely_map(self.shape, dst_lines=lines, src_lines=nb.lines[src], a=w.a, b=w.b, p=w.p)
            cv2.remap(nb.images[src], m, None, cv2.INTER_LINEAR, dst=out, borderMode=cv2.BORDER_REPLICATE)
        return self._full_a, self._full_b


def _canonical(method: str) -> str:
    return method.lower().replace("_", "-")


def _splat(image: np.ndarray, flow: np.ndarray, t: float, grid: np.ndarray, out: np.ndarray) -> None:
    """Paper 3.4 forward mapping: carry each pixel to ``X + t*flow(X)``, then fill holes.

    Each source pixel adds its colour, with bilinear weights, to the four output pixels
    around its target; ``np.bincount`` does the scattered sums in one pass per channel.
    """
    h, w = out.shape[:2]
    tx = (grid[..., 0] + t * flow[..., 0]).ravel()
    ty = (grid[..., 1] + t * flow[..., 1]).ravel()
    x0 = np.floor(tx)
    y0 = np.floor(ty)
    fx = (tx - x0).astype(np.float32)
    fy = (ty - y0).astype(np.float32)
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    colours = image.reshape(-1, 3).astype(np.float32)
    acc = np.zeros((h * w, 3), np.float64)
    weight = np.zeros(h * w, np.float64)
    for dx, dy, wgt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)),
                        (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        xs, ys = x0 + dx, y0 + dy
        ok = (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
        idx = (ys * w + xs)[ok]
        wk = wgt[ok]
        weight += np.bincount(idx, weights=wk, minlength=h * w)
        for c in range(3):
            acc[:, c] += np.bincount(idx, weights=wk * colours[ok, c], minlength=h * w)
    holes = weight < MIN_SPLAT_WEIGHT
    np.divide(acc, np.maximum(weight, MIN_SPLAT_WEIGHT)[:, None], out=acc)
    np.copyto(out, np.clip(np.rint(acc), 0, 255).astype(np.uint8).reshape(h, w, 3))
    if holes.any():
        cv2.inpaint(out, holes.reshape(h, w).view(np.uint8), INPAINT_RADIUS, cv2.INPAINT_TELEA, dst=out)


_RENDERERS: Dict[Tuple[int, str], Renderer] = {}


def morph(bank, from_name: str, to_name: str, alpha: float, method: str = "flow") -> np.ndarray:
    """One in-between frame: RGB ``uint8`` ``(H, W, 3)``, a new array.

    Parameters
    ----------
    bank : Bank
        A loaded bank (flows are read from, or computed into, its store).
    from_name, to_name : str
        Visemes; alpha = 0 gives ``from_name``'s image, alpha = 1 ``to_name``'s.
    alpha : float
        Position in [0, 1].
    method : str
        ``flow`` (default), ``splat``, ``beier-neely`` or ``dissolve``.

    Examples
    --------
    >>> from lipsync import Bank
    >>> from lipsync._data import default_bank_dir
    >>> bank = Bank.load(default_bank_dir())
    >>> bool((morph(bank, "A", "D", 0.0) == bank.images["A"]).all())
    True
    """
    key = (id(bank), _canonical(method))
    r = _RENDERERS.get(key)
    if r is None or r.bank is not bank:
        r = Renderer(bank, method=method)
        _RENDERERS.clear()  # one bank at a time: renderers hold image-sized buffers
        _RENDERERS[key] = r
    return r.render(from_name, to_name, alpha).copy()

