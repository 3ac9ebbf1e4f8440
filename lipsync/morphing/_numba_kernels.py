"""The portable numba kernels: the fallback when lipsync.morphing._flowkernel is not built (the
Beier-Neely field, yuv420p conversion) or the CPU lacks AVX2 (frame kernel, table combine).

Imported only when used (numba's import and its on-disk cache load cost ~0.3 s, a fifth of
a short `lipsync render`); compiled once and cached on disk. The same contracts as the
compiled kernel's, see lipsync.morphing.render and lipsync.encode.yuv.
"""

import numba as _nb
import numpy as np



@_nb.njit(cache=True, nogil=True, fastmath=True, boundscheck=False)
def beier_neely_field(xs, ys, coef, a, b, block, out):  # pragma: no cover - compiled
    """out (h, w, 2) float32 = Beier-Neely displacement at the pixels ys x xs (lipsync.morphing.warp).

    The compiled ``beier_neely_field`` (lipsync/_flowkernel.c) in numba: ``coef`` (L, 14)
    float64 holds each line's affine coefficients in the order of
    :data:`lipsync.morphing.warp._COEF_ORDER`; each quantity is a column part (``c * x``) plus a row
    part (``c * y + c0``), each rounded to float32 before they are added; columns go in
    blocks of ``block`` whose column parts stay in cache. Without the GIL, like the C copy.
    """
    n_lines = coef.shape[0]
    w = xs.shape[0]
    h = ys.shape[0]
    col = np.empty((4, n_lines, block), np.float32)
    acc_w = np.empty(block, np.float32)
    acc_x = np.empty(block, np.float32)
    acc_y = np.empty(block, np.float32)
    af = np.float32(a)
    bf = np.float32(b)
    zero = np.float32(0.0)
    for c0 in range(0, w, block):
        n = min(block, w - c0)
        for i in range(n_lines):
            for c in range(n):
                x = xs[c0 + c]
                col[0, i, c] = np.float32(coef[i, 0] * x)
                col[1, i, c] = np.float32(coef[i, 3] * x)
                col[2, i, c] = np.float32(coef[i, 8] * x)
                col[3, i, c] = np.float32(coef[i, 11] * x)
        for r in range(h):
            y = ys[r]
            acc_w[:n] = zero
            acc_x[:n] = zero
            acc_y[:n] = zero
            for i in range(n_lines):
                rs = np.float32(coef[i, 1] * y + coef[i, 2])
                rv = np.float32(coef[i, 4] * y + coef[i, 5])
                rdx = np.float32(coef[i, 9] * y + coef[i, 10])
                rdy = np.float32(coef[i, 12] * y + coef[i, 13])
                half = np.float32(coef[i, 6])
                lenp = np.float32(coef[i, 7])
                for c in range(n):
                    # distance beyond the segment's ends, max(|s| - |e|/2, 0), then hypot with v
                    s = abs(col[0, i, c] + rs) - half
                    s = max(s, zero)
                    v = col[1, i, c] + rv
                    d = np.sqrt(s * s + v * v) + af
                    if bf == np.float32(2.0):      # the common exponents without pow()
                        q = lenp / d
                        wt = q * q
                    elif bf == np.float32(4.0):
                        q = lenp / d
                        q = q * q
                        wt = q * q
                    elif bf == np.float32(1.0):
                        wt = lenp / d
                    else:
                        wt = (lenp / d) ** bf
                    acc_w[c] += wt
                    acc_x[c] += (col[2, i, c] + rdx) * wt
                    acc_y[c] += (col[3, i, c] + rdy) * wt
            for c in range(n):
                out[r, c0 + c, 0] = acc_x[c] / acc_w[c]
                out[r, c0 + c, 1] = acc_y[c] / acc_w[c]


@_nb.njit(cache=True, nogil=True)
def combine_tables(tab, idx, wts, half, wc, scale, out):  # pragma: no cover - compiled
    """out (hc, wc, 2) float32 = sum_n wts[n] * tab[idx[n]] / scale (idx < 0: the zero table)."""
    hc = tab.shape[1]
    keep = tab.shape[2]
    inv = np.float32(1.0 / scale)
    for i in range(hc):
        for j in range(keep):
            dx = np.float32(0.0)
            dy = np.float32(0.0)
            for n in range(4):
                k = idx[n]
                if k >= 0:
                    dx += wts[n] * np.float32(tab[k, i, j, 0])
                    dy += wts[n] * np.float32(tab[k, i, j, 1])
            dx *= inv
            dy *= inv
            if half:
                jj = wc - 1 - j
                out[i, jj, 0] = -dx
                out[i, jj, 1] = dy
            out[i, j, 0] = dx
            out[i, j, 1] = dy


@_nb.njit(inline="always", fastmath=True, boundscheck=False)
def _tap(p, px, py, xmax, ymax):  # pragma: no cover - compiled
    """Bilinear sample of packed image ``p`` at (px, py): the three 21-bit lanes, in 1/4096."""
    H = p.shape[0]
    W = p.shape[1]
    sx = min(max(int(px * np.float32(64.0) + np.float32(0.5)), 0), xmax)
    sy = min(max(int(py * np.float32(64.0) + np.float32(0.5)), 0), ymax)
    x0 = sx >> 6
    y0 = sy >> 6
    ux = sx & 63
    uy = sy & 63
    x1 = np.uint64(min(x0 + 1, W - 1))  # unsigned indices: numba then skips its
    y1 = np.uint64(min(y0 + 1, H - 1))  # negative-index wraparound (~15% of the loop)
    x0 = np.uint64(x0)
    y0 = np.uint64(y0)
    return (p[y0, x0] * ((64 - ux) * (64 - uy)) + p[y0, x1] * (ux * (64 - uy))
            + p[y1, x0] * ((64 - ux) * uy) + p[y1, x1] * (ux * uy))


@_nb.njit(inline="always", fastmath=True, boundscheck=False)
def _row_displacements(da, db, y, by0, bx0, bh, bw, inv, rx0, rowbuf, rowfull):  # pragma: no cover - compiled
    """Row y's displacements (ax, ay, bx, by per pixel of the ROI) into ``rowfull``."""
    hc = da.shape[0]
    wc = da.shape[1]
    yl = y - by0
    if hc > 0 and yl >= 0 and yl < bh:
        cy = (np.float32(yl) + np.float32(0.5)) * inv - np.float32(0.5)
        cy = min(max(cy, np.float32(0.0)), np.float32(hc - 1))
        i0 = int(cy)
        fy = cy - np.float32(i0)
        i1 = np.uint64(min(i0 + 1, hc - 1))
        i0 = np.uint64(i0)
        for j in range(wc):
            for c in range(2):
                rowbuf[j, c] = da[i0, j, c] + fy * (da[i1, j, c] - da[i0, j, c])
                rowbuf[j, 2 + c] = db[i0, j, c] + fy * (db[i1, j, c] - db[i0, j, c])
        for xl in range(bw):
            cx = (np.float32(xl) + np.float32(0.5)) * inv - np.float32(0.5)
            cx = min(max(cx, np.float32(0.0)), np.float32(wc - 1))
            j0 = int(cx)
            fx = cx - np.float32(j0)
            j1 = np.uint64(min(j0 + 1, wc - 1))
            j0 = np.uint64(j0)
            o = np.uint64(xl + bx0 - rx0)
            for c in range(4):
                rowfull[o, c] = rowbuf[j0, c] + fx * (rowbuf[j1, c] - rowbuf[j0, c])
    else:
        rowfull[:, :] = 0.0


@_nb.njit(cache=True, nogil=True, fastmath=True, boundscheck=False)
def warp_blend(pa, pb, da, db, by0, bx0, bh, bw, step, ry0, ry1, rx0, rx1, ka, out,
                       rowbuf, rowfull):  # pragma: no cover - compiled
    """Frame pixels [ry0, ry1) x [rx0, rx1): (1-alpha) A(Y + da(Y)) + alpha B(Y + db(Y)).

    pa, pb: packed images (:func:`pack_pixels`); da, db: coarse displacements over the box
    (by0, bx0, bh, bw) with spacing ``step``, zero outside it; ka = (1 - alpha) in
    1/4096. Per output row the coarse rows are interpolated once into ``rowfull`` (4
    floats per pixel), so the pixel loop is only two fixed-point bilinear samples of packed
    pixels and the blend. Edge pixels are repeated (positions are clamped to the image).
    """
    H = pa.shape[0]
    W = pa.shape[1]
    kb = 4096 - ka
    xmax = (W - 1) * 64
    ymax = (H - 1) * 64
    inv = np.float32(1.0 / step)
    m = np.int64(2097151)
    rw = rx1 - rx0
    rowfull[:rw, :] = 0.0
    for y in range(ry0, ry1):
        _row_displacements(da, db, y, by0, bx0, bh, bw, inv, rx0, rowbuf, rowfull[:rw])
        fyy = np.float32(y)
        for o in range(rw):
            x = rx0 + o
            fxx = np.float32(x)
            acc_a = _tap(pa, fxx + rowfull[o, 0], fyy + rowfull[o, 1], xmax, ymax)
            acc_b = _tap(pb, fxx + rowfull[o, 2], fyy + rowfull[o, 3], xmax, ymax)
            # blend in 1/4096 and round: (wa * acc_a + wb * acc_b) / 4096^2 per lane
            out[y, x, 0] = ((acc_a & m) * ka + (acc_b & m) * kb + 8388608) >> 24
            out[y, x, 1] = (((acc_a >> 21) & m) * ka + ((acc_b >> 21) & m) * kb + 8388608) >> 24
            out[y, x, 2] = (((acc_a >> 42) & m) * ka + ((acc_b >> 42) & m) * kb + 8388608) >> 24


@_nb.njit(cache=True, nogil=True, fastmath=True, boundscheck=False)
def warp_blend_rgba(pa, pb, aa, ab, da, db, by0, bx0, bh, bw, step, ry0, ry1, rx0, rx1, ka, out,
                    rowbuf, rowfull):  # pragma: no cover - compiled
    """:func:`warp_blend` for RGBA: ``pa``, ``pb`` packed premultiplied colours, ``aa``, ``ab``
    alpha planes (int64); ``out`` gets straight RGBA, colour = premultiplied sum * 255 / alpha."""
    H = pa.shape[0]
    W = pa.shape[1]
    kb = 4096 - ka
    xmax = (W - 1) * 64
    ymax = (H - 1) * 64
    inv = np.float32(1.0 / step)
    m = np.int64(2097151)
    rw = rx1 - rx0
    rowfull[:rw, :] = 0.0
    for y in range(ry0, ry1):
        _row_displacements(da, db, y, by0, bx0, bh, bw, inv, rx0, rowbuf, rowfull[:rw])
        fyy = np.float32(y)
        for o in range(rw):
            x = rx0 + o
            fxx = np.float32(x)
            ax = fxx + rowfull[o, 0]
            ay = fyy + rowfull[o, 1]
            bx = fxx + rowfull[o, 2]
            by = fyy + rowfull[o, 3]
            acc_a = _tap(pa, ax, ay, xmax, ymax)
            acc_b = _tap(pb, bx, by, xmax, ymax)
            # alpha and the premultiplied colours in 1/4096^2; straight colour = c * 255 / alpha
            # (the alpha taps repeat the colour taps' position arithmetic: LLVM shares it)
            alpha = _tap(aa, ax, ay, xmax, ymax) * ka + _tap(ab, bx, by, xmax, ymax) * kb
            out[y, x, 3] = (alpha + 8388608) >> 24
            if alpha > 0:
                s = 255.0 / alpha  # one division a pixel (float64 holds the sums exactly)
                out[y, x, 0] = min(int(((acc_a & m) * ka + (acc_b & m) * kb) * s + 0.5), 255)
                out[y, x, 1] = min(int((((acc_a >> 21) & m) * ka + ((acc_b >> 21) & m) * kb) * s + 0.5), 255)
                out[y, x, 2] = min(int((((acc_a >> 42) & m) * ka + ((acc_b >> 42) & m) * kb) * s + 0.5), 255)
            else:
                out[y, x, 0] = 0
                out[y, x, 1] = 0
                out[y, x, 2] = 0


# int32 values keep the arithmetic in 32 bits (numba would widen to int64 around Python
# ints); with luma in its own row loop this measured 1.1 ms per 1280x720 frame against 1.5
# ms for one int64 loop over 2x2 blocks. The constants come from lipsync.encode.yuv, as arguments
# (the compiled kernel takes them the same way: one source, and no import of yuv here).
_I = np.int32


@_nb.njit(cache=True, nogil=True, boundscheck=False)
def rgb_to_yuv420p(rgb, out, coefficients, yhalf, chalf, shift):  # pragma: no cover - compiled
    # Flat rows (3 bytes a pixel): twice as fast as indexing [x, channel] (2.35 ms -> 1.1).
    # coefficients: 9 int32 (Y, U, V rows of R, G, B weights); yhalf, chalf, shift: int32.
    s1 = shift
    s2 = shift + _I(2)
    yr, yg, yb, ur, ug, ub, vr, vg, vb = coefficients
    h, w = rgb.shape[0], rgb.shape[1]
    flat = rgb.reshape(h, w * 3)
    cw = w // 2
    u0 = h * w
    v0 = u0 + (h // 2) * cw
    for r in range(h):
        row = flat[r]
        o = r * w
        for x in range(w):
            k = 3 * x
            out[o + x] = np.uint8((yr * _I(row[k]) + yg * _I(row[k + 1]) + yb * _I(row[k + 2]) + yhalf) >> s1)
    for j in range(h // 2):
        a = flat[2 * j]
        b = flat[2 * j + 1]
        for i in range(cw):
            k = 6 * i
            rs = _I(a[k]) + _I(a[k + 3]) + _I(b[k]) + _I(b[k + 3])
            gs = _I(a[k + 1]) + _I(a[k + 4]) + _I(b[k + 1]) + _I(b[k + 4])
            bs = _I(a[k + 2]) + _I(a[k + 5]) + _I(b[k + 2]) + _I(b[k + 5])
            out[u0 + j * cw + i] = np.uint8((ur * rs + ug * gs + ub * bs + chalf) >> s2)
            out[v0 + j * cw + i] = np.uint8((vr * rs + vg * gs + vb * bs + chalf) >> s2)
