"""The face room: detection, mesh, tracking, measures and lines from a face, on real frames.

Expectations are independent of the code under test: analytic transforms of a real frame
(a rotated, scaled, shifted or mirrored face must give correspondingly moved points),
another landmark model's output on the same frames (dlib's 68-point predictor, stored in
tests/data/grid-s1/dlib68.json by tools/dlib_reference.py), and GRID's own alignments.
"""

from __future__ import annotations

import doctest
import importlib
import json
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from lipsync.banks.bank import Bank
from lipsync.banks.yamlio import dump_bank
from lipsync.errors import InputError
from lipsync.face import measure as M
from lipsync.face import topology as T
from lipsync.face.landmarks import FaceMesh, FaceWarning, NoFaceError, Roi, ssd_anchors
from lipsync.face.lines import FACE_TEMPLATE, face_features, midline_axis
from lipsync.face.track import one_euro, smooth, track_frames, track_video
from lipsync.face.video import probe_video, read_video

GRID = Path(__file__).parent / "data" / "grid-s1"
CLIPS = ("bbwm5s", "lwae8n", "prap6p")

# dlib's 68-point lip points and the mesh points at the same places on the lip contours.
DLIB_TO_MESH = {48: 61, 49: 40, 50: 37, 51: 0, 52: 267, 53: 270, 54: 291, 55: 321, 56: 314, 57: 17,
                58: 84, 59: 91, 60: 78, 61: 81, 62: 13, 63: 311, 64: 308, 65: 402, 66: 14, 67: 178}


@pytest.fixture(scope="module")
def mesh():
    return FaceMesh()


@pytest.fixture(scope="module")
def frames():
    return {c: list(read_video(GRID / f"{c}.mpg")) for c in CLIPS}


@pytest.fixture(scope="module")
def tracks():
    return {c: track_video(GRID / f"{c}.mpg") for c in CLIPS}


def _eye_dist(points):
    return float(M.eye_distance(points))


@pytest.mark.parametrize("module", ["topology", "landmarks", "measure", "video", "track", "lines", "compare"])
def test_docstring_examples(module):
    mod = importlib.import_module(f"lipsync.face.{module}")
    result = doctest.testmod(mod, optionflags=doctest.ELLIPSIS | doctest.IGNORE_EXCEPTION_DETAIL)
    assert result.failed == 0


def test_anchor_grid_matches_the_model_outputs(mesh):
    a = ssd_anchors()
    assert a.shape == (896, 2)
    # 16x16 cells of 8 px with 2 anchors, then 8x8 cells of 16 px with 6 anchors
    assert np.allclose(a[:2], [[0.5 / 16, 0.5 / 16]] * 2)
    assert np.allclose(a[512:518], [[0.5 / 8, 0.5 / 8]] * 6)
    assert np.allclose(a[511], [15.5 / 16, 15.5 / 16])


def test_detection_finds_the_face_and_its_eyes(mesh, frames):
    img = frames["lwae8n"][0]
    dets = mesh.detect(img)
    assert len(dets) == 1 and dets[0].score > 0.9
    pts = mesh.find(img)
    # the detector's eye keypoints lie on the mesh's eye centres (within a tenth of their distance)
    a, b = M.eye_centres(pts)
    d = np.linalg.norm(b - a)
    assert np.linalg.norm(dets[0].keypoints[0] - a) < 0.15 * d
    assert np.linalg.norm(dets[0].keypoints[1] - b) < 0.15 * d
    x0, y0, x1, y1 = dets[0].box
    assert x0 < a[0] < b[0] < x1 and y0 < a[1] < y1


def _similarity(angle_deg, scale, shift, centre):
    m = cv2.getRotationMatrix2D(centre, angle_deg, scale)
    m[:, 2] += shift
    return m


@pytest.mark.parametrize("angle,scale,shift", [(0.0, 1.0, (37.0, 21.0)), (15.0, 1.0, (0.0, 0.0)),
                                               (-25.0, 1.3, (40.0, -10.0)), (8.0, 0.7, (-20.0, 30.0))])
def test_points_follow_a_known_similarity(mesh, frames, angle, scale, shift):
    # Pre- and post-processing (letterbox, rotated crop, mapping back) checked analytically:
    # the face moved by a known transform must give its points moved by that transform.
    img = frames["lwae8n"][40]
    ref = mesh.find(img)
    big = np.zeros((420, 480, 3), np.uint8)
    big[60:60 + img.shape[0], 60:60 + img.shape[1]] = img
    ref_big = ref[:, :2] + 60
    m = _similarity(angle, scale, shift, (240.0, 210.0))
    moved = cv2.warpAffine(big, m, (480, 420), flags=cv2.INTER_LINEAR)
    got = mesh.find(moved)[:, :2]
    want = ref_big @ m[:, :2].T + m[:, 2]
    err = np.linalg.norm(got - want, axis=1) / _eye_dist(got)
    assert err.mean() < 0.03, err.mean()
    lips = list(T.LIP_OUTER_UPPER + T.LIP_OUTER_LOWER)
    assert err[lips].mean() < 0.03


def test_mirrored_face_gives_mirrored_points(mesh, frames):
    img = frames["bbwm5s"][30]
    pts = mesh.find(img)
    flipped = mesh.find(np.ascontiguousarray(img[:, ::-1]))
    w = img.shape[1]
    back = flipped.copy()
    back[:, 0] = (w - 1) - flipped[:, 0]
    perm = np.arange(468)
    for a, b in T.MIRROR_PAIRS:
        perm[a], perm[b] = b, a
    err = np.linalg.norm(back[perm, :2] - pts[:, :2], axis=1) / _eye_dist(pts)
    used = sorted({i for pair in T.MIRROR_PAIRS for i in pair} | set(T.MIDLINE_POINTS))
    assert err[used].mean() < 0.03, err[used].mean()


def test_lips_agree_with_an_independent_landmark_model(tracks):
    # dlib's 68-point predictor on every third frame of the three clips
    ref = json.loads((GRID / "dlib68.json").read_text())["videos"]
    errs, ours, theirs = [], [], []
    for name, r in ref.items():
        tr = tracks[Path(name).stem]
        for f, p in zip(r["frames"], r["points"]):
            p = np.asarray(p, float)
            m = tr.points[f, :, :2]
            iod = np.linalg.norm(p[36] - p[45])  # outer eye corners: the usual normaliser
            errs += [np.linalg.norm(p[d] - m[i]) / iod for d, i in DLIB_TO_MESH.items()]
            ours.append(np.linalg.norm(m[13] - m[14]) / iod)
            theirs.append(np.linalg.norm(p[62] - p[66]) / iod)
    assert len(ours) > 60
    assert np.mean(errs) < 0.04, np.mean(errs)          # measured 0.029
    assert np.percentile(errs, 95) < 0.09
    # the lip opening both models see moves together
    assert np.corrcoef(ours, theirs)[0, 1] > 0.9         # measured 0.95


def test_track_follows_every_frame_and_smoothing_does_not_lag(tracks):
    for c, tr in tracks.items():
        assert len(tr) == 75 and tr.found.all() and tr.fps == 25.0 and tr.size == (360, 288)
        raw, smoothed = M.lip_opening(tr.raw), M.lip_opening(tr.points)
        # the smoothed opening is the raw one without its jitter: close, and not shifted in time
        assert np.abs(raw - smoothed).mean() < 0.005
        lags = range(-3, 4)
        r = [np.corrcoef(raw[3:-3], np.roll(smoothed, k)[3:-3])[0, 1] for k in lags]
        assert int(np.argmax(r)) == 3, r
        # still points jitter less after smoothing
        still = list(T.STILL_POINTS)
        jitter = lambda p: np.abs(np.diff(p[:, still, :2], n=2, axis=0)).mean()  # noqa: E731
        assert jitter(tr.points) < 0.8 * jitter(tr.raw)


def test_lip_opening_follows_the_speech(tracks):
    # GRID's alignment says when words are spoken: the mouth is open more during them than in
    # the leading and trailing silence, and it closes on the bilabials of "bin blue ... m".
    from lipsync.readers.grid import read_words

    for c, tr in tracks.items():
        words = read_words(str(GRID / f"{c}.align"), (GRID / f"{c}.align").read_bytes())
        t = tr.times()
        opening = M.lip_opening(tr.points)
        speech = np.zeros(len(t), bool)
        for s in words:
            speech |= (t >= s.start) & (t < s.end)
        assert opening[speech].mean() > 1.5 * opening[~speech].mean(), c
    # "place red at p six please": the lips close at each P (the word's first 80 ms) almost to
    # where they rest in the silence, and open several times wider on the vowels between
    tr = tracks["prap6p"]
    words = read_words(str(GRID / "prap6p.align"), (GRID / "prap6p.align").read_bytes())
    t = tr.times()
    op = M.lip_opening(tr.points)
    rest = np.median(op[t > words[-1].end])
    for w in words:
        if w.label in ("place", "p", "please"):
            at_p = op[(t >= w.start - 0.04) & (t <= w.start + 0.08)].min()
            assert at_p < rest + 0.015, (w.label, at_p, rest)
    assert op.max() > rest + 0.07


def test_smoothing_passes_speech_rates_and_removes_jitter():
    fps = 25.0
    t = np.arange(250) / fps
    clean = 0.05 * np.sin(2 * np.pi * 4.0 * t)
    noise = np.random.default_rng(1).normal(0, 0.005, t.size)
    y = smooth((clean + noise)[:, None], fps)[:, 0]
    # a 4 Hz lip motion keeps its amplitude (no flattening) and its timing (no lag) ...
    assert 0.9 < y[25:-25].std() / clean[25:-25].std() < 1.1
    rms = lambda e: float(np.sqrt(np.mean(e[25:-25] ** 2)))  # noqa: E731
    assert rms(y - clean) < 1.25 * rms(noise)  # fast motion: hardly smoothed, not distorted
    # ... while the causal filter alone is late: its best match with the clean motion is a later frame
    causal = one_euro((clean + noise)[:, None], fps)[:, 0]
    lags = [np.corrcoef(np.roll(clean, k)[25:-25], causal[25:-25])[0, 1] for k in range(0, 4)]
    zero = [np.corrcoef(np.roll(clean, k)[25:-25], y[25:-25])[0, 1] for k in range(0, 4)]
    assert int(np.argmax(zero)) == 0 and zero[0] >= lags[0]
    # a still point's jitter is reduced
    still = smooth(noise[:, None], fps)[:, 0]
    assert still.std() < 0.75 * noise.std()


def _write_video(path: Path, frames, fps=25):
    import imageio_ffmpeg

    h, w = frames[0].shape[:2]
    gen = imageio_ffmpeg.write_frames(str(path), (w, h), fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                      output_params=["-crf", "12"], macro_block_size=1)
    gen.send(None)
    for f in frames:
        gen.send(np.ascontiguousarray(f))
    gen.close()


def test_video_without_a_face_is_an_error_naming_it(tmp_path):
    p = tmp_path / "wall.mp4"
    _write_video(p, [np.full((96, 128, 3), 120, np.uint8)] * 5)
    with pytest.raises(NoFaceError, match=r"wall\.mp4: no face found in any of its 5 frames"):
        track_video(p)
    with pytest.raises(NoFaceError, match="black.png: no face found"):
        FaceMesh().find(np.zeros((64, 64, 3), np.uint8), source="black.png")


def test_not_a_video_is_an_error_naming_it(tmp_path):
    p = tmp_path / "notes.mp4"
    p.write_text("not a video")
    with pytest.raises(InputError, match="notes.mp4: not a video"):
        probe_video(p)
    with pytest.raises(InputError, match="no such file"):
        list(read_video(tmp_path / "missing.mkv"))


def test_lost_frames_are_named_and_the_face_is_found_again(frames):
    clip = [f.copy() for f in frames["lwae8n"][:20]]
    for i in (5, 6, 7, 12):
        clip[i][:] = 90
    with pytest.warns(FaceWarning, match=r"no face in 4 of 20 frames \(5-7, 12\)"):
        tr = track_frames(clip, fps=25.0, source="clip.mp4")
    assert tr.found.tolist() == [i not in (5, 6, 7, 12) for i in range(20)]
    assert np.isnan(tr.points[6]).all()
    # re-acquired frames are placed as precisely as tracked ones: same points as a fresh find
    fresh = FaceMesh().find(clip[8])
    assert np.abs(tr.raw[8, :, :2] - fresh[:, :2]).mean() < 0.5


def test_several_faces_take_the_largest_with_a_warning(mesh, frames):
    img = frames["lwae8n"][10]
    small = cv2.resize(img, None, fx=0.6, fy=0.6, interpolation=cv2.INTER_AREA)
    canvas = np.zeros((288, 360 + small.shape[1], 3), np.uint8)
    canvas[:, :360] = img
    canvas[:small.shape[0], 360:] = small
    with pytest.warns(FaceWarning, match="2 faces found; using the largest"):
        pts = mesh.find(canvas, source="two.png")
    assert pts[:, 0].max() < 360  # the big face, on the left
    ref = mesh.find(img)
    assert np.abs(pts[:, :2] - ref[:, :2]).mean() < 1.0


def test_roi_maps_crop_centres_and_edges():
    r = Roi((50.0, 40.0), 96.0, np.pi / 2)  # x axis of the crop points down the image
    m = r.crop_matrix(192)
    # crop pixel centre (95.5, 95.5) is the ROI's centre; +1 crop px along u moves 0.5 px down
    assert np.allclose(m @ [95.5, 95.5, 1.0], [50.0, 40.0])
    assert np.allclose((m @ [96.5, 95.5, 1.0]) - (m @ [95.5, 95.5, 1.0]), [0.0, 0.5])
    # model coordinates (edges at 0 and 192) map consistently with the crop's pixel centres
    assert np.allclose(r.to_image(np.array([[96.0, 96.0, 4.0]]))[0], [50.0, 40.0, 2.0])


def test_measures_of_a_drawn_mouth():
    p = np.zeros((468, 3))
    p[list(T.EYE_UPPER_L + T.EYE_LOWER_L), :2] = [100.0, 100.0]
    p[list(T.EYE_UPPER_R + T.EYE_LOWER_R), :2] = [150.0, 100.0]
    p[61, :2], p[291, :2] = [105.0, 180.0], [145.0, 180.0]
    for a, b in T.INNER_LIP_PAIRS:
        p[a, :2], p[b, :2] = [125.0, 175.0], [125.0, 185.0]
    p[[61, 291], 2], p[[0, 17], 2] = 10.0, 5.0
    assert M.lip_opening(p) == pytest.approx(10 / 50)
    assert M.mouth_width(p) == pytest.approx(40 / 50)
    assert M.lip_protrusion(p) == pytest.approx(5 / 50)
    # a track of faces at once
    assert M.lip_opening(np.stack([p, p])).shape == (2,)


def test_face_lines_make_a_valid_bank_of_real_frames(tmp_path, mesh, frames):
    imgs = {"X": frames["bbwm5s"][5], "D": frames["lwae8n"][37]}
    pts = {v: mesh.find(im) for v, im in imgs.items()}
    axis = midline_axis(list(pts.values()))
    feats = face_features(pts, (288, 360), axis=axis)
    assert list(feats["X"]) == list(feats["D"])
    assert [f.segment_count for f in feats["X"].values()] == [f.segment_count for f in feats["D"].values()]
    names = set(feats["X"])
    for n in names:  # every mirror partner is there
        if n.endswith("_l"):
            assert n[:-2] + "_r" in names
    assert {f.name for f in FACE_TEMPLATE} <= names
    for v, im in imgs.items():
        cv2.imwrite(str(tmp_path / f"{v}.png"), cv2.cvtColor(im, cv2.COLOR_RGB2BGR))
    for symmetry in (False, True):
        doc = {"name": "grid", "rest": "X", "symmetry": symmetry,
               "visemes": {v: {"image": f"{v}.png", "lines": {n: f.to_yaml_value() for n, f in feats[v].items()}}
                           for v in imgs}}
        (tmp_path / "bank.yaml").write_text(dump_bank(doc))
        bank = Bank.load(tmp_path)
        assert bank.names == ("X", "D") and len(bank.line_names) == sum(f.segment_count for f in feats["X"].values())
    # the lip lines lie on the lips: the outer upper lip's middle is the mesh's point 0
    up = feats["D"]["lip_outer_upper_l"].expand()
    assert np.allclose(up[-1, 1], pts["D"][0, :2])
    # moving features differ between a closed and an open mouth, still ones hardly
    jaw = np.abs(feats["D"]["jaw_l"].expand() - feats["X"]["jaw_l"].expand()).max()
    inner = np.abs(feats["D"]["lip_inner_lower_l"].expand() - feats["X"]["lip_inner_lower_l"].expand()).max()
    assert inner > 3.0 and jaw > 1.0
    assert np.allclose(feats["D"]["frame_top"].points, feats["X"]["frame_top"].points)


def test_anchors_cut_at_the_border_or_left_out(mesh, frames):
    img = frames["lwae8n"][0]
    pts = mesh.find(img)
    full = face_features({"X": pts}, (288, 360))["X"]
    # the shoulders are in GRID's picture; crop the picture just under the chin: they go
    chin = pts[152, 1]
    tight = face_features({"X": pts}, (int(chin) + 8, 360))["X"]
    assert "shoulders_l" in full and "shoulders_r" in full
    assert "shoulders_l" not in tight and "shoulders_r" not in tight and "neck_l" not in tight
    h = int(chin) + 8
    for f in tight.values():
        assert (f.points[:, 1] <= h - 1).all() or f.kind != "line"


def test_grid_alignment_reader():
    from lipsync.readers import read_timeline

    tl = read_timeline(GRID / "prap6p.align")
    words = [ln.split() for ln in (GRID / "prap6p.align").read_text().splitlines()]
    assert tl.duration == pytest.approx(int(words[-1][1]) / 25000)
    first = next(w for w in words if w[2] not in ("sil", "sp"))
    assert tl[0].start == pytest.approx(int(first[0]) / 25000)
    assert tl[0].label == "P"  # "place"
    assert "sp" not in {s.label.lower() for s in tl}


def test_similarity_fit_recovers_a_known_transform():
    from lipsync.face.compare import similarity_from_points

    rng = np.random.default_rng(3)
    src = rng.uniform(0, 100, (12, 2))
    m = _similarity(21.0, 1.4, (7.0, -3.0), (50.0, 50.0))
    got = similarity_from_points(src, src @ m[:, :2].T + m[:, 2])
    assert np.allclose(got, m, atol=1e-9)


def test_registration_undoes_a_head_movement(mesh, frames):
    from lipsync.face.compare import mouth_box, psnr, register

    img = frames["lwae8n"][20]
    m = _similarity(6.0, 1.05, (5.0, -4.0), (180.0, 144.0))
    moved = cv2.warpAffine(img, m, (360, 288), borderMode=cv2.BORDER_REPLICATE)
    p, q = mesh.find(img), mesh.find(moved)
    back, mat, residual = register(moved, q, p)
    inverse = cv2.invertAffineTransform(m)
    # the fitted transform is the inverse of the known one (within the mesh's precision)
    corners = np.array([[120.0, 100.0], [240.0, 100.0], [180.0, 230.0]])
    assert np.abs((corners @ mat[:, :2].T + mat[:, 2]) - (corners @ inverse[:, :2].T + inverse[:, 2])).max() < 1.5
    assert residual < 0.02
    box = mouth_box(p, img.shape[:2])
    assert psnr(img, back, box) > psnr(img, moved, box) + 6


def _plain_ssim(x, y):
    # Wang et al.'s SSIM written out pixel by pixel with the 11-tap Gaussian window
    g = np.exp(-((np.arange(11) - 5) ** 2) / (2 * 1.5 ** 2))
    g = np.outer(g, g) / np.outer(g, g).sum()
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    vals = []
    for i in range(5, x.shape[0] - 5):
        for j in range(5, x.shape[1] - 5):
            a, b = x[i - 5:i + 6, j - 5:j + 6], y[i - 5:i + 6, j - 5:j + 6]
            ma, mb = (g * a).sum(), (g * b).sum()
            va, vb = (g * (a - ma) ** 2).sum(), (g * (b - mb) ** 2).sum()
            cov = (g * (a - ma) * (b - mb)).sum()
            vals.append((2 * ma * mb + c1) * (2 * cov + c2) / ((ma ** 2 + mb ** 2 + c1) * (va + vb + c2)))
    return float(np.mean(vals))


def test_ssim_and_psnr_against_plain_references():
    from lipsync.face.compare import psnr, ssim

    rng = np.random.default_rng(5)
    x = rng.integers(0, 256, (30, 34)).astype(np.uint8)
    y = np.clip(x.astype(int) + rng.integers(-30, 31, x.shape), 0, 255).astype(np.uint8)
    assert ssim(x, y) == pytest.approx(_plain_ssim(x.astype(float), y.astype(float)), abs=1e-9)
    assert ssim(x, x) == pytest.approx(1.0)
    mse = ((x.astype(float) - y) ** 2).mean()
    assert psnr(x, y) == pytest.approx(10 * np.log10(255 ** 2 / mse))
    assert psnr(x, y, (2, 3, 12, 20)) == pytest.approx(
        10 * np.log10(255 ** 2 / ((x[3:20, 2:12].astype(float) - y[3:20, 2:12]) ** 2).mean()))


FACES = Path(__file__).parent / "data" / "faces"


def _photo(name):
    return cv2.cvtColor(cv2.imread(str(FACES / name)), cv2.COLOR_BGR2RGB)


def test_a_face_unlike_the_dev_speaker(mesh):
    # Eileen Collins' NASA portrait (public domain): a woman, smiling with her teeth showing.
    # Mouth corners marked by hand on the picture (8x zoom): (128.8, 110.0) and (168.8, 111.9).
    pts = mesh.find(_photo("astronaut.jpg"))
    d = _eye_dist(pts)
    assert np.linalg.norm(pts[61, :2] - [128.8, 110.0]) < 0.1 * d
    assert np.linalg.norm(pts[291, :2] - [168.8, 111.9]) < 0.1 * d
    assert M.lip_opening(pts) > 0.1  # the lips are apart
    from lipsync.face.lines import SYMMETRIC_BELOW, TURNED_ABOVE, face_asymmetry

    assert SYMMETRIC_BELOW < face_asymmetry([pts]) < TURNED_ABOVE


def test_a_face_in_profile_is_found_but_warned_about(tmp_path):
    # A man filming in profile (CC0): the mesh is frontal, so lines on a profile are poor
    from lipsync.videobank.photos import init_bank

    for v in "XA":
        cv2.imwrite(str(tmp_path / f"{v}.png"), cv2.imread(str(FACES / "camera.jpg")))
    with pytest.warns(FaceWarning, match="turned away from the camera"):
        r = init_bank(tmp_path)
    assert set(r.lines.values()) == {"face"}
