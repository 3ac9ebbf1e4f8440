"""Frames between two visemes (paper 3.4, with DESIGN.md's erratum 1 fixed).

At ``alpha`` the first image moves by ``alpha * forward_flow`` and the second by
``(1 - alpha) * backward_flow``; the frame is ``(1 - alpha) * A' + alpha * B'``. So
alpha = 0 shows A and alpha = 1 shows B exactly.

Methods (registry :data:`METHODS`):

``flow`` (default)
    Gather. Output pixel Y takes A at the X that moves onto it, ``X + alpha F(X) = Y``,
    and likewise B with ``(1 - alpha)`` and the backward flow. Those inversions are
    per-pair work, so preprocessing solves them (Newton's method,
    :func:`lipsync.morphing.flows.inverse_tables`) at t = k / TABLE_STEPS on a coarse grid and the
    store keeps them (:mod:`lipsync.morphing.store`). A frame interpolates the four nearest tables
    in t with a cubic on the coarse grid, then one fused pass reads both displacements
    bilinearly, samples both images and blends: about two image lookups and a blend per
    pixel, whatever the subject. Only the box where the (dead-zoned) flows are non-zero or
    the images differ is rendered; the rest of the frame is the common background. The
    pass is compiled C with AVX-512 or AVX2 gathers (:mod:`lipsync.morphing._flowkernel`, chosen
    at run time by CPU); without it (no compiler at install, or a CPU without AVX2) a numba
    kernel does the same in fixed point (:data:`KERNELS`).
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

Transparency: a bank with transparency (:attr:`lipsync.Bank.channels` 4) renders RGBA
``(H, W, 4)`` frames with straight alpha; every method resamples and blends premultiplied
values (:mod:`lipsync.morphing.alpha`), so a morphing edge neither darkens nor takes the hidden
colour of transparent pixels. The compiled kernel reads the premultiplied alpha in its
fourth byte; the numba kernel reads it from a plane beside the packed colours. An opaque
bank takes exactly the RGB path it always did (same frames, same speed).
"""

from __future__ import annotations

import os
import threading
import warnings
from collections import OrderedDict
from dataclasses import dataclass
from typing import Dict, Optional, Tuple

import cv2
import numpy as np

from .alpha import blend_premultiplied, premultiply, unpremultiply
from ..banks.bank import Bank
from ..errors import InputError
from .preprocess import bank_pair_flows
from .normalise import NormalisedBank, normalise
from ..registry import Registry
from .store import Crop, FlowStore, InverseTables, StoredField, StoreWarning, pack_pair, union_box, unpack_pair
from .warp import beier_neely_map, identity_grid

#: Splat holes are filled by Telea inpainting with this radius (px): holes from
#: expansion are one or two pixels wide, so a small radius keeps edges sharp.
INPAINT_RADIUS = 2
#: A splatted pixel whose summed bilinear weight is below this is a hole: its colour
#: would rest on a sliver of one source pixel.
MIN_SPLAT_WEIGHT = 0.05
#: Fewest ROI rows per thread worth splitting a frame for (below, thread hand-off, some
#: 20-50 us, is a large part of the rows: 64 rows of 512 px are ~0.1 ms of the compiled
#: kernel, ~0.5 ms of numba's).
MIN_ROWS_PER_THREAD = 64
#: Cached per-pair states (views of the mapped store entries); 9 visemes need at most 72.
MAX_PAIR_STATES = 96

try:  # built by setup.py when a C compiler was there; optional
    from . import _flowkernel
except ImportError:  # pragma: no cover - depends on the install
    _flowkernel = None

#: Frame kernels of the flow method, fastest first, with the compiled kernel's level.
#: "avx512" and "avx2": compiled C, 16 or 8 pixels at a time with gathers, identical
#: frames (on whole-frame motion at 512x512, 4.3x and 3.2x less CPU per frame than numba,
#: measured side by side by the bench figure "whole_frame"); "numba": portable fixed
#: point, one pixel at a time.
KERNELS: Registry[int] = Registry("frame kernel")
KERNELS.register("avx512", 2)   # x86-64 with AVX-512 F/BW/DQ/VL (Intel servers since 2017, AMD Zen 4)
KERNELS.register("avx2", 1)     # x86-64 with AVX2 + FMA (Intel since 2013, AMD since 2015)
KERNELS.register("numba", 0)    # any CPU numba runs on


def available_kernels() -> list:
    """The frame kernels this install and CPU can run, fastest first.

    Examples
    --------
    >>> "numba" in available_kernels()
    True
    """
    level = _flowkernel.simd_available() if _flowkernel is not None else 0
    return [name for name in KERNELS.names() if KERNELS.get(name) <= level]


def default_kernel() -> str:
    """The kernel renderers use: ``$LIPSYNC_KERNEL`` if set (and runnable), else the fastest."""
    name = os.environ.get("LIPSYNC_KERNEL")
    if name:
        name = name.lower()
        KERNELS.get(name)  # unknown names list the valid ones
        if name not in available_kernels():
            raise InputError(f"LIPSYNC_KERNEL={name}: not available here (available: "
                             f"{', '.join(available_kernels())})")
        return name
    return available_kernels()[0]

METHODS: Registry[str] = Registry("morph method")
for _name, _why in [("flow", "interpolate the cached flows (fast, default)"),
                    ("splat", "paper's forward splat with hole filling"),
                    ("beier-neely", "full Beier-Neely warp every frame (reference, slow)"),
                    ("dissolve", "cross-fade only (baseline)")]:
    METHODS.register(_name, _why, aliases=[_name.replace("-", "_")] if "-" in _name else [])

# --------------------------------------------------------------------------- kernels
#
# One fused pass per frame: for every output pixel, the two inverse displacements are read
# bilinearly off the coarse tables, both images are sampled bilinearly (edge pixels
# repeated) and blended. No full-resolution map is ever materialised: cv2.remap would need
# one per side (resize + convertMaps + remap: three passes over 8-byte-per-pixel maps) and
# a fourth for the blend. The compiled kernel is lipsync/_flowkernel.c; the portable one,
# numba's, is in lipsync/_numba_kernels.py (imported only when used: numba's import and
# cache load are ~0.3 s of a `lipsync render`). Both release the GIL: frames, or row bands
# of one frame, render in parallel threads.

#: Packed pixels: R | G << 21 | B << 42 in one int64, so a bilinear tap is one load and one
#: multiply for all three channels. 21-bit lanes hold 255 * 4096 (a full set of 12-bit
#: bilinear weights) without carrying into the next lane.
_LANE = 21
_LANE_MASK = (1 << _LANE) - 1
#: Sample positions are fixed-point in 1/64 px (cv2.remap uses 1/32); bilinear weights are
#: products of two 6-bit fractions, summing to exactly 4096.
_SUBPIXEL = 64
#: The blend weight alpha in 1/4096 steps (cannot be seen: at most 1/16 of a grey level).
_BLEND_ONE = 4096


def pack_pixels(image: np.ndarray) -> np.ndarray:
    """RGB ``uint8`` ``(H, W, 3)`` -> int64 ``(H, W)``: R | G << 21 | B << 42 (the kernel's input).

    (RGBA: the colours premultiplied by alpha, which :func:`pack_alpha` gives as a plane.)

    Examples
    --------
    >>> int(pack_pixels(np.array([[[1, 2, 3]]], np.uint8))[0, 0]) == 1 + (2 << 21) + (3 << 42)
    True
    """
    if image.shape[2] == 4:
        image = premultiply(image, dtype=np.uint8)
    p = image[..., 0].astype(np.int64)
    p |= image[..., 1].astype(np.int64) << _LANE
    p |= image[..., 2].astype(np.int64) << (2 * _LANE)
    return p


def pack_alpha(image: np.ndarray) -> np.ndarray:
    """RGBA ``uint8`` ``(H, W, 4)`` -> its alpha as int64 ``(H, W)`` (the numba kernel's RGBA input).

    Examples
    --------
    >>> pack_alpha(np.array([[[9, 9, 9, 7]]], np.uint8)).tolist()
    [[7]]
    """
    return image[..., 3].astype(np.int64)


def pack_rgbx(image: np.ndarray) -> np.ndarray:
    """RGB ``uint8`` ``(H, W, 3)`` -> uint32 ``(H + 1, W + 1)`` R | G << 8 | B << 16, edges repeated.

    The compiled kernel's input: one 4-byte load per tap, and the extra row and column let
    the second taps of a pixel at the last row or column be read without a bounds test
    (their weight is zero there). RGBA ``(H, W, 4)``: premultiplied R | G << 8 | B << 16 |
    A << 24.

    Examples
    --------
    >>> p = pack_rgbx(np.array([[[1, 2, 3]]], np.uint8))
    >>> p.shape, int(p[0, 0]) == 1 + (2 << 8) + (3 << 16), int(p[1, 1]) == int(p[0, 0])
    ((2, 2), True, True)
    """
    if image.shape[2] == 4:
        padded = cv2.copyMakeBorder(premultiply(image, dtype=np.uint8), 0, 1, 0, 1, cv2.BORDER_REPLICATE)
        return padded.view(np.uint32)[..., 0]
    # two SIMD passes in OpenCV (edge padding, then RGB -> RGBX with X = 0): ~10x faster
    # than numpy's strided channel copies, and this is on a pair's first frame
    padded = cv2.copyMakeBorder(np.ascontiguousarray(image), 0, 1, 0, 1, cv2.BORDER_REPLICATE)
    packed = cv2.cvtColor(padded, cv2.COLOR_RGB2RGBA).view(np.uint32)[..., 0]
    np.bitwise_and(packed, np.uint32(0xFFFFFF), out=packed)  # X = 0 (the kernel does not mask it)
    return packed


def table_weights(t: float, steps: int) -> Tuple[np.ndarray, np.ndarray]:
    """Cubic (Lagrange) weights of the tables nearest ``t``: ``(indices, weights)``, 4 each.

    Nodes are ``t = n / steps`` for n = 0..steps; node 0 (the identity) is index -1, node n
    is table ``n - 1``. At a node the weights are exactly one-hot, so t = 0 gives the image.

    Examples
    --------
    >>> idx, w = table_weights(0.5, 4)
    >>> idx.tolist(), [abs(float(v)) for v in w]
    ([0, 1, 2, 3], [0.0, 1.0, 0.0, 0.0])
    """
    x = float(t) * steps
    n_nodes = min(4, steps + 1)
    j0 = min(max(int(np.floor(x)) - 1, 0), steps + 1 - n_nodes)
    nodes = list(range(j0, j0 + n_nodes))
    idx = np.full(4, -1, np.int64)
    wts = np.zeros(4, np.float32)
    for slot, n in enumerate(nodes):
        w = 1.0
        for m in nodes:
            if m != n:
                w *= (x - m) / (n - m)
        idx[slot] = n - 1
        wts[slot] = w
    return idx, wts


@dataclass
class _Pair:
    """Everything a frame of the ordered pair (a, b) needs: read-only, shared by threads."""

    a: str
    b: str
    roi: Crop                  # rendered region: the tables' box and where the images differ
    box: Crop                  # where the tables say anything moves
    inv_a: InverseTables       # X - Y for the first image (t = alpha)
    inv_b: InverseTables       # ... and the second (t = 1 - alpha)
    fwd_field: StoredField     # the flows themselves, only for splat
    bwd_field: StoredField
    splat_state: Optional[tuple] = None  # (fwd, bwd, grid) over the ROI, made on first splat


def _difference_box(a: np.ndarray, b: np.ndarray) -> Crop:
    """Box of the pixels where ``a`` and ``b`` differ (packed ``(H, W)`` or ``(H, W, C)`` images)."""
    diff = a != b if a.ndim == 2 else np.any(a != b, axis=2)
    rows = np.flatnonzero(diff.any(axis=1))
    if rows.size == 0:
        return Crop(0, 0, 0, 0)
    cols = np.flatnonzero(diff.any(axis=0))
    return Crop(int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1)


def _intersect(a: Crop, b: Crop) -> Crop:
    """The part of box ``a`` inside box ``b`` (empty when they do not meet)."""
    c = Crop(max(a.y0, b.y0), min(a.y1, b.y1), max(a.x0, b.x0), min(a.x1, b.x1))
    return c if not c.empty else Crop(0, 0, 0, 0)


def _copy_outside(dst: np.ndarray, src: np.ndarray, r: Crop) -> None:
    """dst = src outside the box r (the four strips around it)."""
    h, w = dst.shape[:2]
    if r.empty:
        np.copyto(dst, src)
        return
    if r.y0 > 0:
        dst[:r.y0] = src[:r.y0]
    if r.y1 < h:
        dst[r.y1:] = src[r.y1:]
    if r.x0 > 0:
        dst[r.y0:r.y1, :r.x0] = src[r.y0:r.y1, :r.x0]
    if r.x1 < w:
        dst[r.y0:r.y1, r.x1:] = src[r.y0:r.y1, r.x1:]


class Renderer:
    """Renders in-between frames of a bank, reusing buffers and flows across frames.

    ``render(..., out=buffer)`` may be called from several threads at once (the frame
    kernels release the GIL): pair states are read-only and scratch is per thread.

    Parameters
    ----------
    bank : Bank or NormalisedBank
        The subject. A plain bank is normalised first.
    method : str
        One of :data:`METHODS`: ``flow``, ``splat``, ``beier-neely``, ``dissolve``.
    store : FlowStore, optional
        Where flows are read from (and written to, when a pair is missing); default: the
        bank's store. Missing pairs are computed on first use.
    kernel : str, optional
        The flow method's frame kernel, one of :func:`available_kernels` (default:
        :func:`default_kernel`, the fastest). Their frames agree within two grey levels
        (the numba kernel rounds positions to 1/64 px, the compiled one does not).

    Examples
    --------
    >>> from lipsync._data import default_bank_dir
    >>> r = Renderer(Bank.load(default_bank_dir()))
    >>> frame = r.render("A", "D", 0.5)
    >>> frame.shape, frame.dtype
    ((512, 512, 3), dtype('uint8'))

    A bank with transparency gives RGBA frames ``(H, W, 4)`` (straight alpha).
    """

    def __init__(self, bank, *, method: str = "flow", store: Optional[FlowStore] = None,
                 kernel: Optional[str] = None):
        METHODS.get(method)  # raises, listing the valid names, if unknown
        self.method = _canonical(method)
        if kernel is None:
            kernel = default_kernel()
        elif kernel.lower() not in available_kernels():
            KERNELS.get(kernel)  # unknown names list the valid ones
            raise InputError(f"frame kernel {kernel!r} is not available here (available: "
                             f"{', '.join(available_kernels())})")
        self.kernel = kernel.lower()
        self.bank: Bank = bank.bank if isinstance(bank, NormalisedBank) else bank
        self.store = store if store is not None else FlowStore.for_bank(self.bank)
        self.nb: NormalisedBank = bank if isinstance(bank, NormalisedBank) else normalise(self.bank, cache=self.store)
        h, w = self.nb.shape
        self.shape = (h, w)
        #: 3 (RGB frames) or 4 (RGBA frames, for a bank with transparency).
        self.channels = self.nb.images[self.bank.names[0]].shape[2]
        self._frame = np.empty((h, w, self.channels), np.uint8)
        self._frame_pair: Optional[Tuple[str, str]] = None
        self._pairs: "OrderedDict[Tuple[str, str], _Pair]" = OrderedDict()
        self._lock = threading.Lock()
        self._local = threading.local()
        self._packed_images: Dict[str, np.ndarray] = {}
        self._alpha_planes: Dict[str, np.ndarray] = {}
        self._premul_images: Dict[str, np.ndarray] = {}
        self._rgbx_images: Dict[str, np.ndarray] = {}
        #: Threads one flow frame is split across. All cores by default (a single frame,
        #: e.g. live playback, comes back sooner); 1 when frames themselves are rendered in
        #: parallel (lipsync render) or when measuring one core.
        self.frame_threads = max(1, os.cpu_count() or 1)
        self._pool = None
        self._full_a = np.empty((h, w, self.channels), np.uint8)
        self._full_b = np.empty((h, w, self.channels), np.uint8)

    # ------------------------------------------------------------------ public
    def render(self, from_viseme: str, to_viseme: str, alpha: float, *, out: Optional[np.ndarray] = None,
               region: Optional[Crop] = None) -> np.ndarray:
        """The frame at ``alpha`` between two visemes, RGB ``uint8`` ``(H, W, 3)`` (RGBA
        ``(H, W, 4)`` for a bank with transparency).

        Without ``out`` the returned array is the renderer's own buffer, overwritten by the
        next call: copy it to keep it. With ``region`` (a :class:`~lipsync.morphing.store.Crop`, flow
        and splat methods, with ``out``) only the pixels inside it are made right (those
        outside are left as they were, or rendered where the region's rows cross the moving
        part): a caller that reads one box of the frame (the lower face composited onto a
        plate) pays for little more than that box.
        """
        self._check(from_viseme, to_viseme, alpha)
        if out is not None and not out.flags.c_contiguous:
            # the compiled kernel writes whole rows of a contiguous frame; a strided view
            # (a frame inside a larger canvas) gets a copy
            np.copyto(out, self.render(from_viseme, to_viseme, alpha, out=np.empty(out.shape, np.uint8)))
            return out
        frame = self._frame if out is None else out
        imgs = self.nb.images
        if from_viseme == to_viseme or alpha <= 0.0:
            np.copyto(frame, imgs[from_viseme])
            if out is None:
                self._frame_pair = None
            return frame
        if alpha >= 1.0:
            np.copyto(frame, imgs[to_viseme])
            if out is None:
                self._frame_pair = None
            return frame
        if self.method == "dissolve":
            if self.channels == 4:
                blend_premultiplied(self._premul(from_viseme), self._premul(to_viseme), alpha, frame)
            else:
                cv2.addWeighted(imgs[from_viseme], 1.0 - alpha, imgs[to_viseme], alpha, 0.0, dst=frame)
            if out is None:
                self._frame_pair = None
            return frame
        if self.method == "beier-neely":
            wa, wb = self._beier_neely_parts(from_viseme, to_viseme, alpha)
            self._blend(wa, wb, alpha, frame)  # (RGBA: the parts are premultiplied)
            if out is None:
                self._frame_pair = None
            return frame
        pair = self._pair(from_viseme, to_viseme)
        r = pair.roi
        if region is not None and out is not None:
            # the ROI's rows inside the region; its columns whole (the kernel renders rows
            # across the tables' whole box)
            r = _intersect(r, Crop(region.y0, region.y1, r.x0, r.x1))
            inside = _intersect(r, region)
            _copy_outside(frame[region.y0:region.y1, region.x0:region.x1],
                          imgs[from_viseme][region.y0:region.y1, region.x0:region.x1],
                          Crop(inside.y0 - region.y0, inside.y1 - region.y0, inside.x0 - region.x0,
                               inside.x1 - region.x0) if not inside.empty else inside)
        elif out is not None:
            _copy_outside(frame, imgs[from_viseme], r)  # outside the ROI both images are equal
        elif self._frame_pair != (from_viseme, to_viseme):
            _copy_outside(frame, imgs[from_viseme], r)
            self._frame_pair = (from_viseme, to_viseme)
        if r.empty:
            return frame
        if self.method == "flow":
            self._flow_frame(pair, alpha, frame, roi=r)
        else:
            buf_a, buf_b = self._splat_parts(pair, alpha)
            p = pair.roi
            self._blend(buf_a[r.y0 - p.y0:r.y1 - p.y0, r.x0 - p.x0:r.x1 - p.x0],
                        buf_b[r.y0 - p.y0:r.y1 - p.y0, r.x0 - p.x0:r.x1 - p.x0], alpha,
                        frame[r.y0:r.y1, r.x0:r.x1])
        return frame

    def parts(self, from_viseme: str, to_viseme: str, alpha: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(forward warp of A, backward warp of B, blended frame)`` at ``alpha``, as new arrays.

        The rows of the paper's figures 8 and 9 (used by ``lipsync morph --frames``).
        """
        self._check(from_viseme, to_viseme, alpha)
        imgs = self.nb.images
        a, b = imgs[from_viseme], imgs[to_viseme]
        # RGBA: wa, wb are made premultiplied where the method blends premultiplied, and
        # returned straight
        pm = self.channels == 4
        if self.method == "dissolve" or from_viseme == to_viseme:
            wa, wb = (self._premul(from_viseme).copy(), self._premul(to_viseme).copy()) if pm else (a.copy(), b.copy())
        elif self.method == "beier-neely":
            wa, wb = (x.copy() for x in self._beier_neely_parts(from_viseme, to_viseme, alpha))
        else:
            pair = self._pair(from_viseme, to_viseme)
            wa, wb = a.copy(), b.copy()
            r = pair.roi
            if self.method == "flow":
                pm = False  # the kernel gives straight RGBA
                if not r.empty:
                    self._flow_frame(pair, alpha, wa, wb)
            else:
                if pm:
                    wa, wb = self._premul(from_viseme).copy(), self._premul(to_viseme).copy()
                if not r.empty:
                    buf_a, buf_b = self._splat_parts(pair, alpha)
                    wa[r.y0:r.y1, r.x0:r.x1] = buf_a
                    wb[r.y0:r.y1, r.x0:r.x1] = buf_b
        if pm:
            blend = blend_premultiplied(wa, wb, alpha, np.empty_like(wa))
            wa, wb = (cv2.cvtColor(x, cv2.COLOR_mRGBA2RGBA) for x in (wa, wb))
            return wa, wb, blend
        blend = self._blend(wa, wb, alpha, np.empty_like(wa))
        return wa, wb, blend

    def inverse_map(self, from_viseme: str, to_viseme: str, t: float, side: str = "a") -> np.ndarray:
        """The coarse inverse displacement ``X - Y`` a frame uses, float32 ``(hc, wc, 2)``.

        ``side`` "a" is the first image at ``t = alpha``, "b" the second at
        ``t = 1 - alpha``; the grid is :func:`lipsync.morphing.flows.coarse_points` of the pair's box
        (``self._pair(a, b).box``). For tests and figures.
        """
        pair = self._pair(from_viseme, to_viseme)
        inv = pair.inv_a if side == "a" else pair.inv_b
        out = np.zeros((inv.data.shape[1], inv.coarse_width, 2), np.float32)
        _fill_coarse(inv, t, out)
        return out

    def _blend(self, a: np.ndarray, b: np.ndarray, alpha: float, out: np.ndarray) -> np.ndarray:
        """``(1 - alpha) a + alpha b`` into ``out``. RGBA: ``a`` and ``b`` premultiplied
        (splat and beier-neely make them so) except for the flow kernel's straight parts."""
        if self.channels == 4:
            if self.method == "flow":
                a, b = premultiply(a, dtype=np.uint8), premultiply(b, dtype=np.uint8)
            # the mix and the division in float: one rounding, as in the flow kernel (splat
            # and beier-neely cost far more than this pass anyway)
            return unpremultiply(cv2.addWeighted(a, 1.0 - alpha, b, alpha, 0.0, dtype=cv2.CV_32F), out)
        return cv2.addWeighted(a, 1.0 - alpha, b, alpha, 0.0, dst=out)

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
        nb = self.nb
        i, j = self.bank.names.index(a), self.bank.names.index(b)
        first, second = (a, b) if i <= j else (b, a)
        key = self.store.pair_key(self.bank, first, second, nb.axis)
        if got is not None and self.method == "splat":
            # splat reads the float fields themselves: non-finite values there (which a CRC
            # cannot tell from good ones) make the entry a miss, as a bad CRC does
            try:
                got[0].data, got[1].data
            except ValueError as exc:
                warnings.warn(f"{self.store.pair_path(key)}: unusable flow store entry ({exc}); recomputing it",
                              StoreWarning, stacklevel=3)
                got = None
        if got is not None:
            return got
        fwd, bwd, axis = bank_pair_flows(nb, first, second)
        try:
            self.store.put_pair(key, fwd, bwd, axis=axis, names=(first, second))
            got = self.store.load_pair(key, self.shape)
        except OSError:
            got = None  # unwritable store: the same entry, kept in memory
        if got is None:
            meta, arrays = pack_pair(fwd, bwd, axis=axis)
            got = unpack_pair(meta, arrays, self.shape)
        return got if (first, second) == (a, b) else (got[1], got[0])

    def _pair(self, a: str, b: str) -> _Pair:
        key = (a, b)
        with self._lock:
            pair = self._pairs.get(key)
            if pair is not None:
                self._pairs.move_to_end(key)
                return pair
            fwd, bwd = self._flows(a, b)
            box = fwd.inverse.box
            # the images in the form this renderer's kernel reads (one value per pixel)
            h, w = self.shape
            # (RGBA: compared premultiplied, alpha included: pixels differing only in the
            # hidden colour of transparency are the same)
            pa, pb = (self._packed(a), self._packed(b)) if self.kernel == "numba" and self.channels == 3 else \
                (self._rgbx(a)[:h, :w], self._rgbx(b)[:h, :w])
            roi = union_box([box, _difference_box(pa, pb)], self.shape, 0)
            pair = _Pair(a=a, b=b, roi=roi, box=box, inv_a=fwd.inverse, inv_b=bwd.inverse,
                         fwd_field=fwd, bwd_field=bwd)
            self._pairs[key] = pair
            if len(self._pairs) > MAX_PAIR_STATES:
                self._pairs.popitem(last=False)
            return pair

    def _scratch(self, hc: int, wc: int):
        """Per-thread planes (coarse displacement per side, row buffers), reused across frames."""
        cache = getattr(self._local, "coarse", None)
        if cache is None or cache[0].shape[:2] != (hc, wc):
            cache = (np.zeros((hc, wc, 2), np.float32), np.zeros((hc, wc, 2), np.float32),
                     np.zeros((max(wc, 1), 4), np.float32), np.zeros((self.shape[1], 4), np.float32))
            self._local.coarse = cache
        return cache

    # ------------------------------------------------------------------ methods
    def _flow_frame(self, p: _Pair, alpha: float, out: np.ndarray, out_b: Optional[np.ndarray] = None,
                    roi: Optional[Crop] = None) -> None:
        """Write the ROI of the frame (or, with ``out_b``, of both warped images) into ``out``
        (``roi``: a part of the pair's ROI instead)."""
        r = p.roi if roi is None else roi
        band = self._bands_numba(p, alpha, out, out_b, r) if self.kernel == "numba" else \
            self._bands_compiled(p, alpha, out, out_b, r)
        n = self.frame_threads if (r.y1 - r.y0) >= MIN_ROWS_PER_THREAD * 2 else 1
        if n <= 1:
            band(r.y0, r.y1)
            return
        # One frame on several threads (the kernels release the GIL): bands of rows.
        edges = np.linspace(r.y0, r.y1, n + 1).astype(int)
        for f in [self._band_pool().submit(band, edges[i], edges[i + 1]) for i in range(n)]:
            f.result()

    def _bands_compiled(self, p: _Pair, alpha: float, out: np.ndarray, out_b: Optional[np.ndarray], r: Crop):
        """``band(y0, y1)`` rendering rows of the frame with the compiled kernel.

        The kernel sums the stored tables itself, one coarse row at a time as a band
        reaches it, so nothing per frame runs outside the (parallel) bands.
        """
        ia, ib = p.inv_a, p.inv_b
        pa, pb = self._rgbx(p.a), self._rgbx(p.b)
        h, w = self.shape
        bx = p.box
        side_a = _table_args(ia, alpha)
        side_b = _table_args(ib, 1.0 - alpha)
        geometry = (w, h, pa.shape[1], ia.data.shape[1], ia.coarse_width, ia.data.shape[2], int(ia.half),
                    bx.y0, bx.x0, bx.y1 - bx.y0, bx.x1 - bx.x0, ia.step)
        jobs = [(1.0 - alpha, out)] if out_b is None else [(1.0, out), (0.0, out_b)]
        level = KERNELS.get(self.kernel)

        nch = self.channels

        def band(y0, y1):
            for wa, dst in jobs:
                _flowkernel.warp_blend(pa, pb, ia.data, ib.data, dst, dst.strides[0], *geometry,
                                       y0, y1, r.x0, r.x1, *side_a, *side_b, wa, level, nch)
        return band

    def _bands_numba(self, p: _Pair, alpha: float, out: np.ndarray, out_b: Optional[np.ndarray], r: Crop):
        """``band(y0, y1)`` rendering rows of the frame with the numba kernel."""
        ia, ib = p.inv_a, p.inv_b
        hc = ia.data.shape[1]
        da, db, _, _ = self._scratch(hc, ia.coarse_width)
        if hc:
            _fill_coarse(ia, alpha, da)
            _fill_coarse(ib, 1.0 - alpha, db)
        pa, pb = self._packed(p.a), self._packed(p.b)
        bx = p.box
        box = (bx.y0, bx.x0, bx.y1 - bx.y0, bx.x1 - bx.x0, ia.step)
        jobs = [(int(round((1.0 - alpha) * _BLEND_ONE)), out)] if out_b is None else \
            [(_BLEND_ONE, out), (0, out_b)]  # the two warped images alone: all weight on one side

        if self.channels == 4:
            aa, ab = self._alpha_plane(p.a), self._alpha_plane(p.b)

            def band(y0, y1):
                _, _, rb, rf = self._scratch(hc, ia.coarse_width)
                for ka, dst in jobs:
                    _numba_kernels().warp_blend_rgba(pa, pb, aa, ab, da, db, *box, y0, y1, r.x0, r.x1, ka, dst,
                                                     rb, rf)
            return band

        def band(y0, y1):
            # each thread its own row buffers; the coarse planes are shared, read-only
            _, _, rb, rf = self._scratch(hc, ia.coarse_width)
            for ka, dst in jobs:
                _numba_kernels().warp_blend(pa, pb, da, db, *box, y0, y1, r.x0, r.x1, ka, dst, rb, rf)
        return band

    def _band_pool(self):
        with self._lock:
            if self._pool is None:
                from concurrent.futures import ThreadPoolExecutor

                self._pool = ThreadPoolExecutor(self.frame_threads, thread_name_prefix="lipsync-band")
            return self._pool

    def _rgbx(self, v: str) -> np.ndarray:
        got = self._rgbx_images.get(v)
        if got is None:
            got = self._rgbx_images[v] = pack_rgbx(self.nb.images[v])
        return got

    def _packed(self, v: str) -> np.ndarray:
        got = self._packed_images.get(v)
        if got is None:
            got = self._packed_images[v] = pack_pixels(self.nb.images[v])
        return got

    def _premul(self, v: str) -> np.ndarray:
        """Viseme ``v``'s image premultiplied, uint8 (RGBA banks)."""
        got = self._premul_images.get(v)
        if got is None:
            got = self._premul_images[v] = premultiply(self.nb.images[v], dtype=np.uint8)
        return got

    def _alpha_plane(self, v: str) -> np.ndarray:
        got = self._alpha_planes.get(v)
        if got is None:
            got = self._alpha_planes[v] = pack_alpha(self.nb.images[v])
        return got

    def _splat_parts(self, p: _Pair, alpha: float) -> Tuple[np.ndarray, np.ndarray]:
        r = p.roi
        if p.splat_state is None:
            sl = (slice(r.y0, r.y1), slice(r.x0, r.x1))
            p.splat_state = (np.ascontiguousarray(p.fwd_field.full()[sl]),
                             np.ascontiguousarray(p.bwd_field.full()[sl]),
                             identity_grid((r.y1 - r.y0, r.x1 - r.x0)))
        fwd, bwd, grid = p.splat_state
        # RGBA: splatted premultiplied, and returned so (render blends them premultiplied)
        imgs = self.nb.images if self.channels == 3 else {v: self._premul(v) for v in (p.a, p.b)}
        buf_a = np.empty(grid.shape[:2] + (self.channels,), np.uint8)
        buf_b = np.empty_like(buf_a)
        _splat(imgs[p.a][r.y0:r.y1, r.x0:r.x1], fwd, alpha, grid, buf_a, premultiplied=self.channels == 4)
        _splat(imgs[p.b][r.y0:r.y1, r.x0:r.x1], bwd, 1.0 - alpha, grid, buf_b, premultiplied=self.channels == 4)
        return buf_a, buf_b

    def _beier_neely_parts(self, a: str, b: str, alpha: float) -> Tuple[np.ndarray, np.ndarray]:
        nb, w = self.nb, self.bank.warp
        lines = (1.0 - alpha) * nb.lines[a] + alpha * nb.lines[b]
        for src, out in ((a, self._full_a), (b, self._full_b)):
            m = beier_neely_map(self.shape, dst_lines=lines, src_lines=nb.lines[src], a=w.a, b=w.b, p=w.p)
            # (RGBA: resampled premultiplied, and left so for the blend)
            img = self._premul(src) if self.channels == 4 else nb.images[src]
            cv2.remap(img, m, None, cv2.INTER_LINEAR, dst=out, borderMode=cv2.BORDER_REPLICATE)
        return self._full_a, self._full_b


def _table_args(inv: InverseTables, t: float) -> Tuple[Tuple[int, ...], Tuple[float, ...]]:
    """The compiled kernel's view of :func:`table_weights`: indices, weights over the scale."""
    idx, wts = table_weights(t, inv.steps)
    return tuple(int(i) for i in idx), tuple(float(v) / inv.scale for v in wts)


def _fill_coarse(inv: InverseTables, t: float, out: np.ndarray) -> None:
    idx, wts = table_weights(t, inv.steps)
    _numba_kernels().combine_tables(inv.data, idx, wts, inv.half, inv.coarse_width, float(inv.scale), out)


def _numba_kernels():
    from . import _numba_kernels as nk  # numba loads only for the portable kernel  # numba loads only for the portable kernel

    return nk


def _canonical(method: str) -> str:
    return method.lower().replace("_", "-")


def _splat(image: np.ndarray, flow: np.ndarray, t: float, grid: np.ndarray, out: np.ndarray, *,
           premultiplied: bool = False) -> None:
    """Paper 3.4 forward mapping: carry each pixel to ``X + t*flow(X)``, then fill holes.

    Each source pixel adds its colour, with bilinear weights, to the four output pixels
    around its target; ``np.bincount`` does the scattered sums in one pass per channel.
    RGBA: ``image`` premultiplied (``premultiplied=True``), the sums and the hole filling are
    of premultiplied colour, and so is ``out``.
    """
    if image.shape[2] == 4 and not premultiplied:
        raise ValueError("an RGBA image is splatted premultiplied")
    h, w = out.shape[:2]
    tx = (grid[..., 0] + t * flow[..., 0]).ravel()
    ty = (grid[..., 1] + t * flow[..., 1]).ravel()
    x0 = np.floor(tx)
    y0 = np.floor(ty)
    fx = (tx - x0).astype(np.float32)
    fy = (ty - y0).astype(np.float32)
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    nch = image.shape[2]
    colours = image.reshape(-1, nch).astype(np.float32)
    acc = np.zeros((h * w, nch), np.float64)
    weight = np.zeros(h * w, np.float64)
    for dx, dy, wgt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)),
                        (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        xs, ys = x0 + dx, y0 + dy
        ok = (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
        idx = (ys * w + xs)[ok]
        wk = wgt[ok]
        weight += np.bincount(idx, weights=wk, minlength=h * w)
        for c in range(nch):
            acc[:, c] += np.bincount(idx, weights=wk * colours[ok, c], minlength=h * w)
    holes = weight < MIN_SPLAT_WEIGHT
    np.divide(acc, np.maximum(weight, MIN_SPLAT_WEIGHT)[:, None], out=acc)
    np.copyto(out, np.clip(np.rint(acc), 0, 255).astype(np.uint8).reshape(h, w, nch))
    if holes.any():
        mask = holes.reshape(h, w).view(np.uint8)
        if nch == 3:
            cv2.inpaint(out, mask, INPAINT_RADIUS, cv2.INPAINT_TELEA, dst=out)
        else:  # cv2.inpaint takes 1 or 3 channels: colour and alpha apart
            out[..., :3] = cv2.inpaint(np.ascontiguousarray(out[..., :3]), mask, INPAINT_RADIUS, cv2.INPAINT_TELEA)
            out[..., 3] = cv2.inpaint(np.ascontiguousarray(out[..., 3]), mask, INPAINT_RADIUS, cv2.INPAINT_TELEA)


_RENDERERS: Dict[Tuple[int, str], Renderer] = {}


def morph(bank, from_name: str, to_name: str, alpha: float, method: str = "flow") -> np.ndarray:
    """One in-between frame: RGB ``uint8`` ``(H, W, 3)``, a new array (RGBA ``(H, W, 4)``,
    straight alpha, for a bank with transparency).

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

