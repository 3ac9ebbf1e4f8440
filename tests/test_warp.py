"""Beier–Neely map: analytic cases and a plain float64 per-line reference (DESIGN.md)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lipsync.morphing.warp import beier_neely_displacement, beier_neely_map, identity_grid, warp


def perp(v):
    return np.array([-v[1], v[0]])


def reference_map(shape, dst, src, a=1.0, b=2.0, p=0.5):
    """DESIGN.md's formulas, one pixel and one line at a time in float64 (vectorised over pixels only)."""
    h, w = shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    X = np.stack([xs, ys], -1)
    num = np.zeros_like(X)
    den = np.zeros((h, w))
    for (P, Q), (Ps, Qs) in zip(np.asarray(dst, float), np.asarray(src, float)):
        e, es = Q - P, Qs - Ps
        length = np.linalg.norm(e)
        u = ((X - P) @ e) / length ** 2
        v = ((X - P) @ perp(e)) / length
        Xi = Ps + u[..., None] * es + v[..., None] * perp(es) / np.linalg.norm(es)
        dist = np.where(u < 0, np.linalg.norm(X - P, axis=-1),
                        np.where(u > 1, np.linalg.norm(X - Q, axis=-1), np.abs(v)))
        weight = (length ** p / (a + dist)) ** b
        num += weight[..., None] * (Xi - X)
        den += weight
    return X + num / den[..., None]


def test_identical_lines_give_identity():
    rng = np.random.default_rng(1)
    lines = rng.uniform(0, 50, (7, 2, 2))
    m = beier_neely_map((40, 50), dst_lines=lines, src_lines=lines)
    assert m.dtype == np.float32 and m.shape == (40, 50, 2)
    np.testing.assert_array_equal(m, identity_grid((40, 50)))


def single_line_affine(dst, src):
    """The analytic map of one line pair: X' = P' + M (X - P).

    u (along the line) scales with the line's length, v (across it) stays in pixels
    (DESIGN.md eq. 3), so M = e' e^T / |e|^2 + n' n^T with unit normals n, n'.
    """
    (P, Q), (Ps, Qs) = np.asarray(dst, float)[0], np.asarray(src, float)[0]
    e, es = Q - P, Qs - Ps
    n, ns = perp(e) / np.linalg.norm(e), perp(es) / np.linalg.norm(es)
    M = np.outer(es, e) / (e @ e) + np.outer(ns, n)
    return lambda X: (X - P) @ M.T + Ps


def test_single_line_is_the_analytic_affine_map():
    dst = np.array([[[10.0, 20.0], [40.0, 25.0]]])
    src = np.array([[[5.0, 8.0], [20.0, 44.0]]])
    m = beier_neely_map((60, 70), dst_lines=dst, src_lines=src)
    ys, xs = np.mgrid[0:60, 0:70]
    X = np.stack([xs, ys], -1).astype(float)
    np.testing.assert_allclose(m, single_line_affine(dst, src)(X), atol=2e-3)


def test_single_line_of_equal_length_is_a_rigid_motion():
    # Equal lengths: the similarity has scale 1, a rotation by the lines' angle plus a shift.
    dst = np.array([[[10.0, 20.0], [40.0, 20.0]]])
    ang = np.deg2rad(25)
    src = np.array([[[30.0, 5.0], [30.0 + 30 * np.cos(ang), 5.0 + 30 * np.sin(ang)]]])
    m = beier_neely_map((50, 60), dst_lines=dst, src_lines=src)
    R = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    ys, xs = np.mgrid[0:50, 0:60]
    X = np.stack([xs, ys], -1).astype(float)
    np.testing.assert_allclose(m, (X - dst[0, 0]) @ R.T + src[0, 0], atol=2e-3)


def test_translating_all_lines_translates_every_pixel():
    rng = np.random.default_rng(2)
    dst = rng.uniform(0, 60, (9, 2, 2))
    shift = np.array([3.25, -1.5])
    m = beier_neely_map((50, 60), dst_lines=dst, src_lines=dst + shift)
    np.testing.assert_allclose(m - identity_grid((50, 60)), np.broadcast_to(shift, (50, 60, 2)), atol=1e-4)


KERNELS = [None, "plain", "numba"]  # compiled (AVX2 where the CPU has it), its portable path, numba's copy


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 12), a=st.floats(0.1, 5),
       b=st.one_of(st.sampled_from([1.0, 2.0, 4.0]), st.floats(0.5, 4.5)), p=st.floats(0, 1),
       kernel=st.sampled_from(KERNELS))
def test_matches_plain_reference(seed, n, a, b, p, kernel):
    rng = np.random.default_rng(seed)
    dst = rng.uniform(-5, 45, (n, 2, 2))
    src = dst + rng.normal(0, 5, (n, 2, 2))
    # keep lines from degenerating to (near) zero length
    for L in (dst, src):
        short = np.linalg.norm(L[:, 1] - L[:, 0], axis=1) < 1
        L[short, 1] += 3
    m = beier_neely_displacement((33, 41), dst_lines=dst, src_lines=src, a=a, b=b, p=p, kernel=kernel)
    m += identity_grid((33, 41))
    np.testing.assert_allclose(m, reference_map((33, 41), dst, src, a, b, p), atol=1e-3)


def test_kernels_agree_and_threads_do_not_change_the_field():
    # The compiled field's AVX2 and portable paths do the same float operations: identical;
    # numba's copy (fastmath) within rounding. Fields computed in threads at once (as
    # preprocessing does) equal those computed one at a time.
    from concurrent.futures import ThreadPoolExecutor

    rng = np.random.default_rng(5)
    cases = []
    for _ in range(6):
        dst = rng.uniform(0, 90, (15, 2, 2))
        cases.append((dst, dst + rng.normal(0, 4, (15, 2, 2))))
    run = lambda case, kernel=None: beier_neely_displacement((70, 97), dst_lines=case[0], src_lines=case[1],
                                                              b=4.0, kernel=kernel)
    serial = [run(c) for c in cases]
    with ThreadPoolExecutor(3) as ex:
        threaded = list(ex.map(run, cases))
    for one, par, case in zip(serial, threaded, cases):
        np.testing.assert_array_equal(one, par)
        np.testing.assert_array_equal(one, run(case, "plain"))
        np.testing.assert_allclose(one, run(case, "numba"), atol=1e-4)


def test_blocks_cover_every_column(monkeypatch):
    import lipsync.morphing.warp as w

    rng = np.random.default_rng(3)
    dst = rng.uniform(0, 30, (4, 2, 2))
    src = dst + rng.normal(0, 3, (4, 2, 2))
    whole = beier_neely_map((29, 31), dst_lines=dst, src_lines=src)
    monkeypatch.setattr(w, "BLOCK_COLUMNS", 7)  # 5 blocks, the last one partial
    np.testing.assert_array_equal(beier_neely_map((29, 31), dst_lines=dst, src_lines=src), whole)


def test_column_window_equals_slice_of_full_field():
    rng = np.random.default_rng(4)
    dst = rng.uniform(0, 30, (5, 2, 2))
    src = dst + rng.normal(0, 3, (5, 2, 2))
    full = beier_neely_displacement((20, 30), dst_lines=dst, src_lines=src)
    part = beier_neely_displacement((20, 30), dst_lines=dst, src_lines=src, columns=(7, 19))
    np.testing.assert_allclose(part, full[:, 7:19], atol=1e-5)


def test_zero_length_line_is_rejected():
    with pytest.raises(ValueError, match="zero-length"):
        beier_neely_map((5, 5), dst_lines=[[[1, 1], [1, 1]]], src_lines=[[[1, 1], [2, 2]]])


def test_warp_moves_content_by_the_map():
    img = np.zeros((20, 20), np.uint8)
    img[5, 7] = 200
    # A pure translation by (+2, +3): destination pixel (9, 8) samples source (7, 5).
    lines = np.array([[[2.0, 2.0], [12.0, 4.0]], [[3.0, 15.0], [15.0, 11.0]]])
    m = beier_neely_map(img.shape, dst_lines=lines + [2, 3], src_lines=lines)
    out = warp(img, m)
    assert out[8, 9] == 200 and out.sum() == 200
