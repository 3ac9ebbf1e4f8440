"""Symmetric normalisation and mirrored half-fields (paper section 3, 3.2, 3.3)."""

import numpy as np

from lipsync.banks.bank import WarpParams
from lipsync.morphing.flows import flow_field, pair_flows
from lipsync.morphing.normalise import estimate_axis, is_symmetric, normalise_image, symmetric_lines
from lipsync.morphing.warp import beier_neely_displacement

NAMES = ["lip_l", "lip_r", "mid", "chin", "eye_l", "eye_r"]


def symmetric_set(axis, rng, jitter=0.0):
    left = np.array([[[axis - 30, 60], [axis - 8, 52]], [[axis - 40, 20], [axis - 25, 22]]], float)
    right = left.copy()
    right[..., 0] = 2 * axis - right[..., 0]
    mid = np.array([[[axis, 30], [axis, 48]]], float)
    chin = np.array([[[axis - 20, 80], [axis + 20, 80]]], float)
    lines = np.concatenate([left[:1], right[:1], mid, chin, left[1:], right[1:]])
    return lines + rng.normal(0, jitter, lines.shape) if jitter else lines


def test_symmetric_lines_are_exactly_mirror_symmetric():
    rng = np.random.default_rng(0)
    lines = symmetric_set(50.5, rng, jitter=1.5)
    axis = round(2 * estimate_axis(lines, NAMES)) / 2
    sym = symmetric_lines(lines, NAMES, axis)
    assert is_symmetric(sym, NAMES, axis, tol=1e-9)
    assert not is_symmetric(lines, NAMES, axis, tol=1e-3)
    # the nearest symmetric set moves lines by about the jitter, no more
    assert np.abs(sym - lines).max() < 6


def test_mirrored_half_field_equals_full_field():
    rng = np.random.default_rng(1)
    for axis in (50.5, 50.0, 40.0):  # half-pixel axis, integer axis, off-centre axis
        a = symmetric_set(axis, rng)
        b = symmetric_set(axis, rng)
        b[0, 1] += [-3, 6]           # move the left lip line, and its mirror partner to match
        b[1, 1] += [3, 6]
        b[3, :, 1] += 4              # chin down (a line crossing the axis)
        w = WarpParams()
        full = beier_neely_displacement((90, 101), dst_lines=a, src_lines=b)
        half = flow_field((90, 101), a, b, w, axis=axis)
        np.testing.assert_allclose(half, full, atol=1e-3)
        fwd, bwd = pair_flows((90, 101), a, b, w, line_names=NAMES, axis=axis)
        np.testing.assert_allclose(fwd, full, atol=1e-3)


def _half_plane_coverage(shape, to_source, angle_deg=30.0, offset=20.0):
    """Anti-aliased half-plane ``x cos t + y sin t > offset`` sampled at ``to_source(pixel)``.

    Each value is the fraction of a one-pixel box centred on the source position that
    lies inside the half-plane (8x8 supersampling). With ``to_source`` the identity this
    is the source image; through the analytic warp it is the ideal warped image: the same
    box-filtered edge, sampled exactly where the warp says.
    """
    h, w = shape
    s = 8
    off = (np.arange(s) + 0.5) / s - 0.5
    ys, xs = np.mgrid[0:h, 0:w].astype(float)
    S = to_source(np.stack([xs, ys], -1))
    px = S[..., 0][..., None, None] + off[None, :]
    py = S[..., 1][..., None, None] + off[:, None]
    t = np.deg2rad(angle_deg)
    inside = px * np.cos(t) + py * np.sin(t) > offset
    return np.rint(inside.mean(axis=(-2, -1)) * 255)


def test_bilinear_normalisation_beats_nearest_on_a_diagonal_edge():
    # One line pair is an exact affine map (u scales with the line, v stays in pixels), so
    # the true warped image is the half-plane seen through that affine map. Stretching the
    # line 2.5x expands the image along it, which is where nearest-neighbour staircases.
    shape = (64, 64)
    src_lines = np.array([[[0.0, 0.0], [10.0, 4.0]]])
    dst_lines = src_lines * 2.5
    (P, Q), (Ps, Qs) = dst_lines[0], src_lines[0]
    e, es = Q - P, Qs - Ps
    n, ns = np.array([-e[1], e[0]]) / np.linalg.norm(e), np.array([-es[1], es[0]]) / np.linalg.norm(es)
    M = np.outer(es, e) / (e @ e) + np.outer(ns, n)
    src_img = _half_plane_coverage(shape, lambda X: X).astype(np.uint8)
    truth = _half_plane_coverage(shape, lambda X: (X - P) @ M.T + Ps)
    lin = normalise_image(src_img, src_lines, dst_lines, interpolation="linear").astype(float)
    near = normalise_image(src_img, src_lines, dst_lines, interpolation="nearest").astype(float)
    # Compare where the source position is inside the source image (outside, the warp
    # repeats the border while the analytic half-plane goes on).
    ys, xs = np.mgrid[0:64, 0:64]
    S = (np.stack([xs, ys], -1) - P) @ M.T + Ps
    valid = np.all((S >= 1) & (S <= 62), axis=-1)
    assert valid.mean() > 0.4
    err_lin = np.abs(lin - truth)[valid].mean()
    err_near = np.abs(near - truth)[valid].mean()
    assert err_lin < 0.75 * err_near, (err_lin, err_near)  # measured 1.80 vs 2.62
