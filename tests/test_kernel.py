"""The flow method's frame kernels against a plain numpy reference written here.

A flow frame is defined by the coarse inverse maps the renderer reports
(``Renderer.inverse_map``): upsample them linearly to pixels (coarse point (i, j) at the
centre of its step x step block, edges repeated), sample both images bilinearly at
``Y + d(Y)`` (positions clamped to the image), blend with (1 - alpha, alpha). Every kernel
must give that frame; the compiled one to within rounding.
"""

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

import synthetic
from lipsync.morphing import render as render_mod
from lipsync.banks.bank import Bank
from lipsync.errors import InputError, UnknownNameError
from lipsync.morphing.render import Renderer, available_kernels, pack_rgbx

needs_avx2 = pytest.mark.skipif("avx2" not in available_kernels(),
                                reason="compiled kernel not built or CPU without AVX2")


def _upsample(coarse: np.ndarray, shape, step: int) -> np.ndarray:
    """Separable linear interpolation of a coarse grid to ``shape`` pixels (np.interp clamps)."""
    hc, wc = coarse.shape[:2]
    h, w = shape
    cy = np.arange(hc) * step + (step - 1) / 2.0
    cx = np.arange(wc) * step + (step - 1) / 2.0
    out = np.empty((h, w, 2))
    for c in range(2):
        cols = np.stack([np.interp(np.arange(h), cy, coarse[:, j, c]) for j in range(wc)], axis=1)
        out[..., c] = np.stack([np.interp(np.arange(w), cx, cols[i]) for i in range(h)])
    return out


def _bilinear(img: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    h, w = img.shape[:2]
    px = np.clip(px, 0, w - 1)
    py = np.clip(py, 0, h - 1)
    x0 = np.floor(px).astype(int)
    y0 = np.floor(py).astype(int)
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    fx = (px - x0)[..., None]
    fy = (py - y0)[..., None]
    f = img.astype(np.float64)
    return ((1 - fx) * (1 - fy) * f[y0, x0] + fx * (1 - fy) * f[y0, x1]
            + (1 - fx) * fy * f[y1, x0] + fx * fy * f[y1, x1])


def reference_frame(r: Renderer, a: str, b: str, alpha: float) -> np.ndarray:
    """The flow frame from the renderer's own coarse maps, in float64 numpy."""
    pair = r._pair(a, b)
    h, w = r.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    parts = []
    for side, t, img in (("a", alpha, r.nb.images[a]), ("b", 1.0 - alpha, r.nb.images[b])):
        d = np.zeros((h, w, 2))
        bx = pair.box
        if not bx.empty:
            coarse = r.inverse_map(a, b, t, side)
            d[bx.y0:bx.y1, bx.x0:bx.x1] = _upsample(coarse, (bx.y1 - bx.y0, bx.x1 - bx.x0), pair.inv_a.step)
        parts.append(_bilinear(img, xs + d[..., 0], ys + d[..., 1]))
    return np.floor((1 - alpha) * parts[0] + alpha * parts[1] + 0.5).clip(0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def banks(tmp_path_factory):
    root = tmp_path_factory.mktemp("kernel")
    # the synthetic subject; an odd-sized crop of it (scalar tails, an axis on a column);
    # and one without symmetry (full-width tables)
    full = synthetic.write_bank(root / "full", {k: synthetic.SHAPES[k] for k in ("X", "O", "E")})
    odd = root / "odd"
    shutil.copytree(full, odd)
    import cv2
    import yaml

    spec = yaml.safe_load((odd / "bank.yaml").read_text())
    for v in spec["visemes"].values():
        img = cv2.imread(str(odd / v["image"]))
        cv2.imwrite(str(odd / v["image"]), img[:157, 4:187])   # 157 x 183: x -> x - 4
        v["lines"] = {n: [[x - 4, y] for x, y in line] for n, line in v["lines"].items()}
    (odd / "bank.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    asym = synthetic.write_bank(root / "asym", {k: synthetic.SHAPES[k] for k in ("X", "O", "E")}, symmetry=False)
    return {"full": Bank.load(full), "odd": Bank.load(odd), "asym": Bank.load(asym)}


@pytest.mark.parametrize("kernel", ["avx512", "avx2", "numba"])
@pytest.mark.parametrize("which", ["full", "odd", "asym"])
def test_kernel_matches_the_numpy_reference(banks, kernel, which):
    if kernel not in available_kernels():
        pytest.skip(f"{kernel} kernel not available here")
    bank = banks[which]
    r = Renderer(bank, kernel=kernel)
    # numba rounds positions to 1/64 px: within 2 levels; the compiled kernel is float32
    # all the way: within 1 (rounding at the .5 boundary)
    tol = 2 if kernel == "numba" else 1
    for a, b in (("X", "O"), ("O", "E"), ("E", "X")):
        for alpha in (0.2, 0.5, 0.85):
            got = r.render(a, b, alpha).astype(int)
            want = reference_frame(r, a, b, alpha).astype(int)
            diff = np.abs(got - want)
            assert diff.max() <= tol, (which, a, b, alpha, diff.max())
            assert (diff > 0).mean() < 0.02, (which, a, b, alpha, (diff > 0).mean())


@needs_avx2
@pytest.mark.parametrize("which", ["full", "odd"])
def test_kernels_agree_and_threads_do_not_change_frames(banks, which):
    bank = banks[which]
    fast, slow = Renderer(bank, kernel="avx2"), Renderer(bank, kernel="numba")
    # the AVX-512 path does the same float operations in the same order: identical frames
    wide = Renderer(bank, kernel="avx512") if "avx512" in available_kernels() else None
    banded = Renderer(bank, kernel="avx2")
    banded.frame_threads = 3
    for a, b in (("X", "O"), ("E", "O")):
        for alpha in np.linspace(0.05, 0.95, 7):
            f = fast.render(a, b, float(alpha)).copy()
            assert np.abs(f.astype(int) - slow.render(a, b, float(alpha))).max() <= 2
            np.testing.assert_array_equal(banded.render(a, b, float(alpha)), f)
            if wide is not None:
                np.testing.assert_array_equal(wide.render(a, b, float(alpha)), f)
            wa, wb, _ = fast.parts(a, b, float(alpha))
            na, nb, _ = slow.parts(a, b, float(alpha))
            assert np.abs(wa.astype(int) - na).max() <= 2 and np.abs(wb.astype(int) - nb).max() <= 2


@needs_avx2
def test_a_strided_output_gets_the_same_frame(banks):
    bank = banks["odd"]
    r = Renderer(bank, kernel="avx2")
    h, w = bank.shape
    canvas = np.full((h + 4, w + 6, 3), 7, np.uint8)
    view = canvas[2:2 + h, 3:3 + w]
    r.render("X", "O", 0.4, out=view)
    np.testing.assert_array_equal(view, r.render("X", "O", 0.4))
    assert (canvas[:2] == 7).all() and (canvas[:, :3] == 7).all()  # nothing outside the view


@needs_avx2
def test_the_compiled_kernel_refuses_geometry_that_would_leave_its_buffers():
    from lipsync.morphing import _flowkernel

    img = pack_rgbx(np.zeros((8, 8, 3), np.uint8))
    tab = np.zeros((4, 4, 4, 2), np.int16)
    out = np.zeros((8, 8, 3), np.uint8)
    ok = dict(w=8, h=8, wp=9, hc=4, wc=4, keep=4, half=0, by0=0, bx0=0, bh=8, bw=8, step=2,
              ry0=0, ry1=8, rx0=0, rx1=8)

    def call(**kw):
        g = dict(ok, **kw)
        _flowkernel.warp_blend(img, img, tab, tab, out, out.strides[0], *g.values(),
                               (0, -1, -1, -1), (1 / 64, 0, 0, 0), (3, -1, -1, -1), (1 / 64, 0, 0, 0), 0.5)

    call()  # sound
    for bad in (dict(ry1=9), dict(rx1=9), dict(h=9), dict(wp=8), dict(bw=9), dict(keep=5), dict(hc=5)):
        with pytest.raises(ValueError):
            call(**bad)
    with pytest.raises(ValueError):  # a table index past the tables given
        _flowkernel.warp_blend(img, img, tab, tab, out, out.strides[0], *ok.values(),
                               (4, -1, -1, -1), (1.0, 0, 0, 0), (0, -1, -1, -1), (1.0, 0, 0, 0), 0.5)


def test_unknown_or_unavailable_kernels_are_refused(banks, monkeypatch):
    with pytest.raises(UnknownNameError, match="avx2"):
        Renderer(banks["full"], kernel="gpu")
    assert available_kernels()[-1] == "numba"
    monkeypatch.setenv("LIPSYNC_KERNEL", "nope")
    with pytest.raises(UnknownNameError, match="numba"):
        render_mod.default_kernel()
    monkeypatch.setenv("LIPSYNC_KERNEL", "numba")
    assert Renderer(banks["full"]).kernel == "numba"
    monkeypatch.setattr(render_mod, "_flowkernel", None)
    assert available_kernels() == ["numba"]
    monkeypatch.setenv("LIPSYNC_KERNEL", "avx2")
    with pytest.raises(InputError, match="not available"):
        render_mod.default_kernel()


def test_the_default_kernel_keeps_the_synthetic_quality(tmp_path):
    """Mouth PSNR against the true in-between (test_render's measure) within 0.1 dB of the
    numba kernel, which made the figures before the compiled kernel existed."""
    from test_render import mouth_psnr

    default = available_kernels()[0]
    if default == "numba":
        pytest.skip("only the numba kernel here")
    bank = Bank.load(synthetic.write_bank(tmp_path / "bank"))
    renderers = {k: Renderer(bank, kernel=k) for k in (default, "numba")}
    for a, b in (("X", "O"), ("O", "E"), ("A", "E")):
        (rx0, ry0), (rx1, ry1) = synthetic.SHAPES[a], synthetic.SHAPES[b]
        mean = {}
        for k, r in renderers.items():
            scores = []
            for alpha in (0.25, 0.5, 0.75):
                truth = synthetic.draw(rx0 + (rx1 - rx0) * alpha, ry0 + (ry1 - ry0) * alpha)
                scores.append(mouth_psnr(r.render(a, b, alpha), truth))
            mean[k] = float(np.mean(scores))
        assert abs(mean[default] - mean["numba"]) < 0.1, (a, b, mean)


def _reference_from_tables(img_a, img_b, tabs, sides, box, step, half, wc, wa):
    """warp_blend's contract in numpy: tables summed with their weights, mirrored, upsampled,
    both images sampled bilinearly and blended (rows and columns outside the box: no motion)."""
    h, w = img_a.shape[:2]
    y0, x0, bh, bw = box
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    parts = []
    for img, tab, (idx, wts) in zip((img_a, img_b), tabs, sides):
        coarse = np.zeros(tab.shape[1:3] + (2,))
        for k, wt in zip(idx, wts):
            if k >= 0:
                coarse += wt * tab[k].astype(np.float64)
        if half:
            full = np.zeros((coarse.shape[0], wc, 2))
            keep = coarse.shape[1]
            full[:, wc - keep:] = coarse[:, ::-1] * [-1, 1]   # mirrored columns, x negated
            full[:, :keep] = coarse                            # the middle column keeps its own
            coarse = full
        d = np.zeros((h, w, 2))
        d[y0:y0 + bh, x0:x0 + bw] = _upsample(coarse, (bh, bw), step)
        parts.append(_bilinear(img, xs + d[..., 0], ys + d[..., 1]))
    return np.floor(wa * parts[0] + (1 - wa) * parts[1] + 0.5).clip(0, 255).astype(np.uint8)


@needs_avx2
@pytest.mark.parametrize("step,half,width", [(2, True, 61), (2, False, 61), (3, False, 58), (2, True, 40)])
def test_every_path_of_the_compiled_kernel_on_random_tables(step, half, width):
    from lipsync.morphing import _flowkernel

    rng = np.random.default_rng(step * 100 + width + half)
    h, w = 37, width
    img_a = rng.integers(0, 256, (h, w, 3), np.uint8)
    img_b = rng.integers(0, 256, (h, w, 3), np.uint8)
    y0, x0, bh, bw = 3, 5, 29, w - 10           # a box inside the image; the ROI is all of it
    hc, wc = -(-bh // step), -(-bw // step)
    keep = -(-wc // 2) if half else wc
    # displacements up to +-12 px (1/64 px units), some pushing samples past the image edges
    tabs = [rng.integers(-768, 768, (4, hc, keep, 2)).astype(np.int16) for _ in range(2)]
    sides = [((0, 1, 2, 3), (0.1 / 64, 0.5 / 64, 0.5 / 64, -0.1 / 64)), ((-1, 0, 1, 2), (0.0, 0.3 / 64, 0.9 / 64, -0.2 / 64))]
    wa = 0.35
    want = _reference_from_tables(img_a, img_b, tabs, sides, (y0, x0, bh, bw), step, half, wc, wa).astype(int)
    levels = range(0, _flowkernel.simd_available() + 1)
    frames = []
    for level in levels:
        out = np.zeros((h, w, 3), np.uint8)
        _flowkernel.warp_blend(pack_rgbx(img_a), pack_rgbx(img_b), tabs[0], tabs[1], out, out.strides[0],
                               w, h, w + 1, hc, wc, keep, int(half), y0, x0, bh, bw, step, 0, h, 0, w,
                               *sides[0], *sides[1], wa, level)
        diff = np.abs(out.astype(int) - want)
        assert diff.max() <= 1 and (diff > 0).mean() < 0.01, (level, diff.max(), (diff > 0).mean())
        frames.append(out)
    for f in frames[1:]:  # the vector paths do the scalar path's arithmetic
        assert np.abs(f.astype(int) - frames[0]).max() <= 1


def test_without_the_compiled_extension_everything_falls_back_to_numba(banks):
    """An install whose C build failed (no compiler): the same frames within 2 levels, the
    same yuv bytes and the same Beier-Neely fields (within rounding), from numba, with
    nothing else changed."""
    bank_dir = banks["full"].path
    script = f"""
import sys, numpy as np
class NoExtension:
    def find_spec(self, name, path=None, target=None):
        if name == "lipsync.morphing._flowkernel":
            raise ImportError("no compiled extension in this test")
sys.meta_path.insert(0, NoExtension())
from lipsync import render
from lipsync.banks.bank import Bank
from lipsync.encode.yuv import rgb_to_yuv420p
from lipsync import warp
assert render._flowkernel is None and render.available_kernels() == ["numba"] and warp._compiled is None
bank = Bank.load({str(bank_dir)!r})
r = render.Renderer(bank)  # its flows are computed here too, by numba's field kernel
frame = r.render("X", "O", 0.4)
np.save(sys.argv[1], frame)
np.save(sys.argv[2], rgb_to_yuv420p(frame))
np.save(sys.argv[3], warp.beier_neely_displacement(bank.shape, dst_lines=bank.lines["X"], src_lines=bank.lines["O"]))
print(r.kernel)
"""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        f, y, b = os.path.join(d, "f.npy"), os.path.join(d, "y.npy"), os.path.join(d, "b.npy")
        run = subprocess.run([sys.executable, "-c", script, f, y, b], capture_output=True, text=True)
        assert run.returncode == 0, run.stderr
        assert run.stdout.strip() == "numba"
        frame = np.load(f)
        here = Renderer(banks["full"]).render("X", "O", 0.4)
        assert np.abs(frame.astype(int) - here).max() <= 2
        from lipsync.encode.yuv import rgb_to_yuv420p

        np.testing.assert_array_equal(np.load(y), rgb_to_yuv420p(frame))
        from lipsync.morphing.warp import beier_neely_displacement

        bank = banks["full"]
        field = beier_neely_displacement(bank.shape, dst_lines=bank.lines["X"], src_lines=bank.lines["O"])
        np.testing.assert_allclose(np.load(b), field, atol=1e-4)
