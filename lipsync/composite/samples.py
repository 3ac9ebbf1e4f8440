"""Real mouth samples onto a plate: one warp from the source frame's crop to the output pixel.

A frame that shows a sample as it is (:func:`lipsync.selection.frame_plan`: inside a run of
the source, or a join's last frame) is written with **one** resample at most::

    sample crop --(pose o affine: stabilisation, pose onto the plate, placement, as one 2x3)-->
    plate ROI --colour LUT--> --feathered mask blend--> plate frame (in place)

bicubic (:data:`INTERPOLATION`), at the footage's own scale (a bank made from video keeps
it: nothing is upscaled); where that map is a translation (a dub onto the bank's own
speaker: :data:`SNAP_PX`) the crop is copied at a whole-pixel offset, not resampled. Across a join the two samples are brought into the bank's box
(one resample each), morphed by the Beier–Neely flow between their lip lines (the paper's
method, computed once per pair and kept in the flow store) and composited as the viseme
morph is (:meth:`lipsync.composite.plate.PlateCompositor.apply`).

The samples are duck-typed (``crops``, ``affine``, ``lips`` arrays: :class:`lipsync.samples.Samples`),
so this room does not import the sample store above it.

Examples
--------
>>> import numpy as np
>>> from types import SimpleNamespace
>>> crops = np.zeros((1, 20, 20, 3), np.uint8); crops[0, 5:15, 5:15] = 200
>>> s = SimpleNamespace(crops=crops, affine=np.array([[[1.0, 0, 10], [0, 1.0, 10]]]), lips=np.zeros((1, 44, 2)))
>>> mask = np.zeros((40, 40), np.float32); mask[12:28, 12:28] = 1
>>> sc = SampleCompositor(s, mask)
>>> plate = np.zeros((40, 40, 3), np.uint8)
>>> out = sc.paste(0, plate, np.array([[1.0, 0, 0], [0, 1.0, 0]]))
>>> int(out[20, 20, 0]), int(out[5, 5, 0])          # the crop's square lands at 15-24, shifted by 10
(200, 0)
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Optional

import cv2
import numpy as np

from .plate import PlateCompositor, compose, pose_inverse

#: The one resample from the source crop to the output, where the map is not a whole-pixel
#: copy (:data:`SNAP_PX`): a sample whose head is turned or scaled from the plate's. Lanczos4
#: keeps 0.92 / 0.97 of real GRID mouths' Laplacian variance at a half / quarter pixel and
#: 0.97 through a 1 degree turn, where bicubic keeps 0.85 / 0.93 / 0.93 (bilinear 0.52 /
#: 0.62 / 0.66); its overshoot is no larger than bicubic's (0.04 % of pixels at half a pixel),
#: so the feathered seam shows no halo. On movie-hello, whose chosen samples are turned 3.2
#: degrees from the plate's head (82 % of pastes resampled), the render's lips went 0.74 ->
#: 0.80 of the clip's before encoding; on GRID, where most pastes are copies, nothing moved.
#: The plate is cut with the same kernel (:mod:`lipsync.videobank.cut`). The price: 8x8 taps
#: against 4x4, so a resampled paste costs about 5x bicubic's (the bench's dub frame, three-
#: clip banks, one run side by side: 0.29 -> 0.65 ms at 360x288, 0.63 -> 3.19 ms at 1280x720,
#: against 0.31 / 0.94 ms for the one-picture morph): at 720p still 300 frames a second, and
#: 2.4 s of a 30 s dub's CPU. Sharpness is what this round is for, so it is paid.
INTERPOLATION = cv2.INTER_LANCZOS4
#: A paste whose map from the crop to the output is a translation to within this many pixels
#: (the linear part's residual at the crop's corners) is a copy at the nearest whole-pixel
#: offset: no resample at all. Any resample at a fractional offset is a low-pass filter: on
#: GRID s1's stored crops bicubic keeps 0.85 of the Laplacian's variance at a quarter-pixel
#: shift and 0.71 at a half (Lanczos4 0.92 / 0.81; bilinear 0.55 / 0.41), and a dub onto the
#: bank's own speaker (crop -> video scale 1 to within a per cent) lands at arbitrary fractions:
#: its mouth was 0.82-0.86x the input's. The copy is off by at most half a pixel plus this
#: residual: below the face tracker's own jitter at GRID's scale (about half a pixel).
SNAP_PX = 1.0
#: Join flows kept in memory (each a box of ~100x90x2 floats at GRID's scale, 70 kB).
CACHE_FLOWS = 64
#: Beier–Neely weights for the lip lines (bank.yaml's warp defaults).
WARP = dict(a=1.0, b=2.0, p=0.5)


def lip_lines(lips: np.ndarray) -> np.ndarray:
    """``(L, 2, 2)`` control lines along a sample's 44 lip points (four contours of 11:
    consecutive points joined), for the Beier–Neely flow between two samples.

    Examples
    --------
    >>> lip_lines(np.zeros((44, 2))).shape
    (40, 2, 2)
    """
    p = np.asarray(lips, np.float64).reshape(4, 11, 2)
    return np.concatenate([np.stack([c[:-1], c[1:]], axis=1) for c in p])


def whole_shift(m: np.ndarray, shape) -> Optional[tuple]:
    """``(dx, dy)`` whole pixels if the 2x3 map ``m`` of an image of ``shape`` (H, W) moves
    every corner to within :data:`SNAP_PX` of where the pure translation of its centre puts
    it; else None (the map scales or turns: it needs a resample).

    Examples
    --------
    >>> whole_shift(np.array([[1.0, 0, 10.4], [0, 1.0, -3.6]]), (64, 82))
    (10, -4)
    >>> whole_shift(np.array([[1.002, 0, 10.4], [0, 1.002, -3.6]]), (64, 82))   # 0.1 px at the corners
    (10, -4)
    >>> whole_shift(np.array([[0.96, 0, 10.4], [0, 0.96, -3.6]]), (64, 82)) is None   # 4% smaller
    True
    """
    h, w = shape[:2]
    lin = np.asarray(m, np.float64)[:, :2] - np.eye(2)
    corners = np.array([[-w, -h], [w, -h], [w, h], [-w, h]], np.float64) / 2.0
    if float(np.abs(corners @ lin.T).max()) > SNAP_PX:
        return None
    centre = np.asarray(m, np.float64) @ np.array([(w - 1) / 2.0, (h - 1) / 2.0, 1.0])
    off = centre - np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    return int(np.floor(off[0] + 0.5)), int(np.floor(off[1] + 0.5))


class SampleCompositor:
    """Writes samples (or a morph across a join) onto plate frames.

    Parameters
    ----------
    samples : object
        With ``crops`` ``(N, h, w, 3)``, ``affine`` ``(N, 2, 3)`` (crop -> bank pixels),
        ``lips`` ``(N, 44, 2)`` (bank pixels) and optionally ``gain`` ``(N, 3)`` (each
        sample's colour onto the plate's).
    mask : numpy.ndarray
        The lower-face mask, float32 bank pixels (as :class:`PlateCompositor`'s).
    lut : numpy.ndarray, optional
        Colour table applied to the pasted pixels.
    store : lipsync.morphing.store.FlowStore, optional
        Where join flows are kept between runs (else only in memory).
    tag : bytes
        What identifies the samples in the store's keys (the table's digest).
    """

    def __init__(self, samples, mask: np.ndarray, *, lut: Optional[np.ndarray] = None, store=None,
                 tag: bytes = b""):
        self.samples, self.lut, self.store, self.tag = samples, lut, store, tag
        self.plate = PlateCompositor(mask, lut=lut)
        self.box = self.plate.box
        x0, y0, x1, y1 = self.box
        self._shift = np.array([[1.0, 0.0, -x0], [0.0, 1.0, -y0]])
        self._flows: "OrderedDict[tuple, np.ndarray]" = OrderedDict()
        self._lock = threading.Lock()
        self._local = threading.local()
        bw, bh = x1 - x0, y1 - y0
        # the box's edges stay where they are in both samples: the morph moves the mouth, not the box
        e = np.array([[0, 0], [bw - 1, 0], [bw - 1, bh - 1], [0, bh - 1]], np.float64)
        self._frame_lines = np.stack([e, np.roll(e, -1, axis=0)], axis=1)
        self._gains, self._pastes = self._tables(getattr(samples, "gain", None), lut)

    @staticmethod
    def _tables(gains, lut):
        """Per sample, its colour table (gain only: a morph's, before the plate's own ``lut``)
        and the table of a paste (gain, then ``lut``); None where there is nothing to apply."""
        from .plate import colour_lut

        if gains is None:
            return None, (None if lut is None else np.broadcast_to(lut, (1,) + lut.shape[1:]))
        own = np.stack([colour_lut(g)[0] for g in np.asarray(gains, np.float64)])  # (N, 256, 3)
        if lut is None:
            return own, own
        return own, np.stack([lut[0][t, np.arange(3)] for t in own])

    # ----------------------------------------------------------------- the one-warp paste
    def paste(self, k: int, plate: np.ndarray, pose: np.ndarray, prepared=None) -> np.ndarray:
        """Sample ``k`` onto ``plate`` (in place) under ``pose`` (bank -> plate pixels); ``prepared``
        is the plate compositor's :meth:`~PlateCompositor.prepare` of that pose (its ROI and
        mask), when made beforehand. Returns ``plate``."""
        if prepared is None:
            prepared = self.plate.prepare(pose, plate.shape)
            if prepared is None:
                return plate
        rx0, ry0, rx1, ry1 = prepared.roi
        h, w = ry1 - ry0, rx1 - rx0
        to_plate = compose(pose, self.samples.affine[k])
        shift = whole_shift(to_plate, self.samples.crops.shape[1:3])
        img = self._scratch(h, w)
        if shift is not None:  # a copy: crop pixel (x, y) to output (x + dx, y + dy)
            inv = np.array([[1.0, 0.0, rx0 - shift[0]], [0.0, 1.0, ry0 - shift[1]]])
            flags = cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP
        else:
            inv = compose(pose_inverse(to_plate), np.array([[1.0, 0.0, rx0], [0.0, 1.0, ry0]]))
            flags = INTERPOLATION | cv2.WARP_INVERSE_MAP
        cv2.warpAffine(self.samples.crops[k], inv, (w, h), dst=img, flags=flags, borderMode=cv2.BORDER_REPLICATE)
        if self._pastes is not None:
            cv2.LUT(img, self._pastes[min(k, len(self._pastes) - 1)][None], dst=img)
        dst = plate[ry0:ry1, rx0:rx1]
        cv2.blendLinear(img, dst, prepared.mask, prepared.rest, dst=dst)
        return plate

    def _scratch(self, h: int, w: int) -> np.ndarray:
        buf = getattr(self._local, "img", None)
        if buf is None or buf.shape[0] < h or buf.shape[1] < w:
            buf = self._local.img = np.empty((int(h * 1.25) + 8, int(w * 1.25) + 8, 3), np.uint8)
        return buf[:h, :w]

    # ----------------------------------------------------------------- joins
    def in_box(self, k: int) -> np.ndarray:
        """Sample ``k`` in the bank's box (one resample), float32 RGB."""
        x0, y0, x1, y1 = self.box
        img = cv2.warpAffine(self.samples.crops[k], compose(self._shift, self.samples.affine[k]), (x1 - x0, y1 - y0),
                             flags=INTERPOLATION, borderMode=cv2.BORDER_REPLICATE)
        if self._gains is not None:
            cv2.LUT(img, self._gains[k][None], dst=img)
        return img.astype(np.float32)

    def flow(self, a: int, b: int) -> np.ndarray:
        """The Beier–Neely flow from sample ``a`` to ``b`` over the box: for each pixel of
        ``a``'s geometry, the offset to where it is in ``b`` (the paper's forward flow, lines
        of ``a`` as destination and ``b``'s as source). Cached in memory and in the store."""
        key = (a, b)
        with self._lock:
            if key in self._flows:
                self._flows.move_to_end(key)
                return self._flows[key]
        skey = None
        got = None
        if self.store is not None:
            skey = self.store.join_key([self.tag, np.int64(a).tobytes(), np.int64(b).tobytes(),
                                        repr((self.box, WARP)).encode()])
            got = self.store.get_join(skey)
        if got is None or got.shape != (self.box[3] - self.box[1], self.box[2] - self.box[0], 2):
            got = self._compute_flow(a, b)
            if skey is not None:
                try:
                    self.store.put_join(skey, got)
                except OSError:
                    pass  # a read-only store: the flow is kept in memory only
        with self._lock:
            self._flows[key] = got
            while len(self._flows) > CACHE_FLOWS:
                self._flows.popitem(last=False)
        return got

    def _compute_flow(self, a: int, b: int) -> np.ndarray:
        from ..morphing.warp import beier_neely_map, identity_grid

        x0, y0, x1, y1 = self.box
        off = np.array([x0, y0], np.float64)
        la = np.concatenate([lip_lines(self.samples.lips[a]) - off, self._frame_lines])
        lb = np.concatenate([lip_lines(self.samples.lips[b]) - off, self._frame_lines])
        shape = (y1 - y0, x1 - x0)
        return (beier_neely_map(shape, dst_lines=la, src_lines=lb, **WARP) - identity_grid(shape)).astype(np.float32)

    def morph(self, a: int, b: int, alpha: float, out: np.ndarray) -> np.ndarray:
        """The morph from sample ``a`` to ``b`` at ``alpha`` written into ``out``'s box (a
        bank-sized RGB frame; only the box is written); returns ``out``.

        At alpha, a pixel at Y samples ``a`` at ``Y - alpha F(Y)`` and ``b`` at
        ``Y + (1 - alpha) F(Y)`` (F the forward flow) and blends ``(1 - alpha) a + alpha b``:
        alpha 0 is ``a`` and alpha 1 is ``b`` (DESIGN.md, erratum 1)."""
        from ..morphing.warp import identity_grid

        x0, y0, x1, y1 = self.box
        f = self.flow(a, b)
        grid = identity_grid(f.shape[:2])
        ia, ib = self.in_box(a), self.in_box(b)
        wa = cv2.remap(ia, grid - alpha * f, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        wb = cv2.remap(ib, grid + (1.0 - alpha) * f, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        out[y0:y1, x0:x1] = np.clip((1.0 - alpha) * wa + alpha * wb + 0.5, 0, 255).astype(np.uint8)
        return out

    def render(self, src: int, dst: int, alpha: float, plate: np.ndarray, pose: np.ndarray, prepared=None,
               geometry=None) -> np.ndarray:
        """Frame of the plan ``(src, dst, alpha)`` onto ``plate``: ``dst`` pasted (alpha 1 or
        ``src == dst``), else the morph composited. ``prepared``/``geometry``: the pose's work
        made beforehand (:meth:`PlateCompositor.prepare` / :meth:`PlateCompositor.geometry`)."""
        if alpha >= 1.0 or src == dst:
            if prepared is None and geometry is not None:
                prepared = self._prepared_from(geometry)
                if prepared is None:
                    return plate
            return self.paste(dst, plate, pose, prepared)
        buf = getattr(self._local, "frame", None)
        h, w = self.plate.mask.shape
        if buf is None:
            buf = self._local.frame = np.zeros((h, w, 3), np.uint8)
        self.morph(src, dst, alpha, buf)
        if prepared is not None:
            return self.plate.apply_prepared(buf, plate, prepared)
        return self.plate.apply(buf, plate, pose, geometry)

    def _prepared_from(self, geometry):
        """A :class:`~lipsync.composite.plate.Prepared`-like ROI and mask from a pose's :meth:`PlateCompositor.geometry`."""
        from types import SimpleNamespace

        (rx0, ry0, rx1, ry1), inv = geometry
        m = cv2.warpAffine(self.plate._mask_box, inv, (rx1 - rx0, ry1 - ry0),
                           flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_CONSTANT,
                           borderValue=0.0)
        return SimpleNamespace(roi=(rx0, ry0, rx1, ry1), mask=m, rest=np.subtract(1.0, m))
