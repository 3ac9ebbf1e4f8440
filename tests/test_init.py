"""lipsync init: a starting bank.yaml from a folder of images."""

import shutil

import cv2
import numpy as np
import pytest
import yaml

from lipsync._data import default_bank_dir
from lipsync.banks.bank import Bank
from lipsync.videobank.photos import FRAME_PREFIX, MOUTH_FILL, _is_mouth, init_bank
from lipsync.banks.names import SYSTEMS
from lipsync.cli import main
from lipsync.errors import InputError

TOON = default_bank_dir()


@pytest.fixture(scope="module")
def toon():
    return Bank.load(TOON)


def blank(path, w, h, value=128):
    img = np.full((h, w, 3), value, np.uint8)
    img[h // 3: h // 2, w // 4: 3 * w // 4] = 40  # something to look at
    cv2.imwrite(str(path), img)


def test_toon_images_reproduce_the_toon(tmp_path, toon):
    for v in toon.names:
        shutil.copy(TOON / f"{v}.png", tmp_path / f"lisa_{v}.png")
    r = init_bank(tmp_path, lines="template")
    assert (r.system, r.rest, r.layout, r.size) == ("rhubarb", "X", "face", (512, 512))
    bank = Bank.load(tmp_path)
    assert bank.names == tuple("ABCDEFGHX") and bank.line_names == toon.line_names
    for v in toon.names:
        np.testing.assert_allclose(bank.lines[v], toon.lines[v], atol=1e-3)
    assert bank.symmetry and bank.warp == toon.warp
    text = (tmp_path / "bank.yaml").read_text()
    assert text.startswith("# Written by lipsync init")
    assert main(["check", str(tmp_path)]) == 0


def test_half_size_images_get_half_size_lines(tmp_path, toon):
    for v in "AXD":
        img = cv2.imread(str(TOON / f"{v}.png"))
        cv2.imwrite(str(tmp_path / f"{v}.png"), cv2.resize(img, (256, 256), interpolation=cv2.INTER_AREA))
    init_bank(tmp_path, layout="face", lines="template")
    bank = Bank.load(tmp_path)
    for v in "AXD":
        # pixel centres: x' = (x + 0.5) / 2 - 0.5
        np.testing.assert_allclose(bank.lines[v], (toon.lines[v] + 0.5) / 2 - 0.5, atol=1e-3)


def test_face_box_maps_the_template_face_onto_it(tmp_path, toon):
    for v in "AX":
        blank(tmp_path / f"{v}.png", 640, 480)
    init_bank(tmp_path, face_box=(200, 100, 240, 300))
    bank = Bank.load(tmp_path)
    face = [i for i, n in enumerate(bank.line_names) if not n.startswith(FRAME_PREFIX)]
    pts = np.concatenate([bank.lines[v][face].reshape(-1, 2) for v in bank.names])
    np.testing.assert_allclose(pts.min(axis=0), [200, 100], atol=1e-3)
    np.testing.assert_allclose(pts.max(axis=0), [440, 400], atol=1e-3)
    # frame lines follow the image border: the toon's frame_top at y = 4 of 512
    top = bank.lines["X"][bank.line_names.index("frame_top")]
    np.testing.assert_allclose(top[:, 1], (4 + 0.5) * 480 / 512 - 0.5, atol=1e-3)
    assert bank_axis_of(bank) == pytest.approx(320.0)


def bank_axis_of(bank):
    from lipsync.morphing.normalise import bank_axis
    return bank_axis(bank)


def test_mouth_sprites_keep_mouth_lines_centred(tmp_path, toon):
    for v in "ABCDEFGHX":
        blank(tmp_path / f"{v}.png", 160, 120)
    r = init_bank(tmp_path)
    assert r.layout == "mouth"
    bank = Bank.load(tmp_path)
    assert all(_is_mouth(n) or n.startswith(FRAME_PREFIX) for n in bank.line_names)
    assert {n for n in toon.line_names if _is_mouth(n)} <= set(bank.line_names)
    mouth = [i for i, n in enumerate(bank.line_names) if _is_mouth(n)]
    pts = np.concatenate([bank.lines[v][mouth].reshape(-1, 2) for v in bank.names])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    np.testing.assert_allclose((lo + hi) / 2, [79.5, 59.5], atol=1e-3)  # centred
    # the widest template mouth fills MOUTH_FILL of the sprite in its limiting direction
    fill = max((hi - lo)[0] / 160, (hi - lo)[1] / 120)
    assert fill == pytest.approx(MOUTH_FILL, abs=1e-4)
    assert main(["check", str(tmp_path)]) == 0


@pytest.mark.parametrize("system", ["preston-blair", "oculus"])
def test_other_naming_systems(tmp_path, system):
    names = list(SYSTEMS[system])
    for n in names:
        blank(tmp_path / f"char-{n.lower()}.png", 64, 64)
    r = init_bank(tmp_path)
    bank = Bank.load(tmp_path)
    assert r.system == system and bank.names == tuple(names)
    assert bank.rest == {"preston-blair": "rest", "oculus": "sil"}[system]


def test_names_option_and_unknown_names(tmp_path, capsys):
    for stem in ("closed", "open", "X"):
        blank(tmp_path / f"{stem}.png", 64, 64)
    with pytest.raises(InputError, match=r"cannot tell which viseme 2 image\(s\) show: closed.png, open.png"):
        init_bank(tmp_path)
    assert not (tmp_path / "bank.yaml").exists()
    assert main(["init", str(tmp_path), "--names", "closed=A,open.png=D"]) == 0
    bank = Bank.load(tmp_path)
    assert bank.names == ("A", "D", "X") and bank.rest == "X"
    spec = yaml.safe_load((tmp_path / "bank.yaml").read_text())
    assert spec["visemes"]["A"]["image"] == "closed.png"


def test_sizes_checked(tmp_path):
    blank(tmp_path / "A.png", 64, 64)
    blank(tmp_path / "X.png", 64, 48)
    with pytest.raises(InputError, match=r"X.png.*64x48 but A.png is 64x64"):
        init_bank(tmp_path)
    assert not (tmp_path / "bank.yaml").exists()


def test_refuses_to_overwrite_without_force(tmp_path, capsys):
    for v in "AX":
        blank(tmp_path / f"{v}.png", 64, 64)
    (tmp_path / "bank.yaml").write_text("# mine\n")
    assert main(["init", str(tmp_path)]) == 2
    assert "bank.yaml exists already; use --force" in capsys.readouterr().err
    assert (tmp_path / "bank.yaml").read_text() == "# mine\n"
    assert main(["init", str(tmp_path), "--force"]) == 0
    assert Bank.load(tmp_path).names == ("A", "X")


def test_bad_input_exit_2(tmp_path, capsys):
    assert main(["init", str(tmp_path)]) == 2  # empty folder
    assert "no PNG or JPEG images" in capsys.readouterr().err
    for v in "AX":
        blank(tmp_path / f"{v}.png", 64, 64)
    assert main(["init", str(tmp_path), "--face-box", "0,0,100,10"]) == 2
    assert "reaches outside" in capsys.readouterr().err
    assert main(["init", str(tmp_path), "--template", "nope"]) == 2
    assert "toon" in capsys.readouterr().err


def test_mouth_sprites_lines_go_where_the_mouth_moves(tmp_path, toon):
    # Sprites cut from the toon around its mouth: the true lines are the toon's, shifted by
    # the cut's corner. The template is fitted to where the sprites differ, not to the middle.
    x0, y0 = 176, 300
    for v in toon.names:
        img = cv2.imread(str(TOON / f"{v}.png"))
        cv2.imwrite(str(tmp_path / f"{v}.png"), img[y0:y0 + 120, x0:x0 + 160])
    assert init_bank(tmp_path).layout == "mouth"
    bank = Bank.load(tmp_path)
    idx = [i for i, n in enumerate(toon.line_names) if _is_mouth(n)]
    mine = [bank.line_names.index(toon.line_names[i]) for i in idx]
    for v in toon.names:
        err = np.abs(toon.lines[v][idx] - [x0, y0] - bank.lines[v][mine])
        assert err.mean() < 3.0 and err.max() < 7.0, (v, err.mean(), err.max())


def test_nine_images_to_a_video(tmp_path):
    """The README's path: a folder of nine mouth images, no bank.yaml -> init -> render."""
    import sys
    import subprocess

    import synthetic
    from lipsync.encode import probe

    folder = tmp_path / "mine"
    folder.mkdir()
    for v, (rx, ry) in synthetic.RHUBARB_SHAPES.items():
        cv2.imwrite(str(folder / f"face-{v}.png"), cv2.cvtColor(synthetic.draw(rx, ry), cv2.COLOR_RGB2BGR))
    from pathlib import Path

    samples = Path(__file__).resolve().parents[1] / "samples"
    out = tmp_path / "hello.mp4"
    for args in (["init", str(folder)],
                 ["render", str(samples / "hello.phn"), "--bank", str(folder), "--audio", str(samples / "hello.wav"),
                  "-o", str(out), "--quiet"]):
        r = subprocess.run([sys.executable, "-m", "lipsync", *args], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
    info = probe(out)
    assert info["streams"] == [("video", "h264"), ("audio", "aac")]
    assert info["n_frames"] > 10 and abs(info["audio_duration"] - info["video_duration"]) < 0.1


# --- face lines on photos (real GRID frames: tests/data/grid-s1, CC BY 4.0, see SOURCE.md there) ---

GRID = __import__("pathlib").Path(__file__).parent / "data" / "grid-s1"


@pytest.fixture(scope="module")
def grid_frames():
    from lipsync.face.video import read_video

    frames = list(read_video(GRID / "lwae8n.mpg"))
    # closed at rest after the sentence, rounded for "white", wide open in "eight", half open
    return {"X": frames[50], "F": frames[16], "D": frames[29], "B": frames[19]}


def _save(folder, images):
    folder.mkdir(exist_ok=True)
    for v, img in images.items():
        cv2.imwrite(str(folder / f"{v}.png"), cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2BGR))


def test_photos_of_a_face_get_lines_from_the_face(tmp_path, grid_frames, capsys):
    from lipsync.face.landmarks import FaceMesh
    from lipsync.face.lines import FACE_TEMPLATE, FACE_WARP

    _save(tmp_path, grid_frames)
    assert main(["init", str(tmp_path), "--keep-photos"]) == 0
    out = capsys.readouterr().out
    for v in grid_frames:
        assert f"{v}.png: lines from face" in out
    assert "one face" not in out and not (tmp_path / "one-face").exists()
    bank = Bank.load(tmp_path)
    assert set(bank.feature_names) >= {f.name for f in FACE_TEMPLATE}
    assert bank.warp == FACE_WARP
    # a real, slightly turned head is not normalised to symmetry (it would visibly change)
    assert bank.symmetry is False
    mesh = FaceMesh()
    for v, img in grid_frames.items():
        pts = mesh.find(img)
        lip = bank.features[v]["lip_inner_lower_l"].points
        # the inner lower lip's line runs from the mouth corner to the middle, on the mesh's points
        np.testing.assert_allclose(lip[0], pts[78, :2], atol=0.01)
        np.testing.assert_allclose(lip[-1], pts[14, :2], atol=0.01)
    # the open mouth's inner lips are apart, the closed ones together
    gap = lambda v: np.linalg.norm(bank.features[v]["lip_inner_upper_l"].points[-1]  # noqa: E731
                                   - bank.features[v]["lip_inner_lower_l"].points[-1])
    assert gap("D") > 3 * gap("X")
    assert main(["check", str(tmp_path)]) == 0


def test_photos_of_one_face_become_one_face_by_default(tmp_path, grid_frames, capsys):
    from lipsync.composite.face import mask_from_lines
    from lipsync.face.landmarks import FaceMesh

    _save(tmp_path, grid_frames)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert main(["init", str(tmp_path)]) == 0
    assert "one face: the pictures are X.png outside the lower face" in capsys.readouterr().out
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file() and p.name != "bank.yaml"} == before
    bank = Bank.load(tmp_path)
    assert "one-face/D.png" in (tmp_path / "bank.yaml").read_text()
    png = {v: cv2.cvtColor(cv2.imread(str(tmp_path / "one-face" / f"{v}.png")), cv2.COLOR_BGR2RGB) for v in grid_frames}
    # the rest photo is the plate as it was; every other picture is it outside the lower-face mask
    assert np.array_equal(png["X"], grid_frames["X"])
    outside = mask_from_lines([bank.features[v] for v in bank.names], bank.shape) == 0
    assert 0.6 < outside.mean() < 0.98
    for v in "FDB":
        assert np.array_equal(png[v][outside], grid_frames["X"][outside]), v
        # ... where the photo itself differed (another moment: the head and light moved)
        assert np.abs(grid_frames[v].astype(int) - grid_frames["X"])[outside].mean() > 0.5, v
    # inside, each photo's own mouth: the mesh finds D's open lips and X's closed ones on the
    # pictures, where bank.yaml's lines put them
    mesh = FaceMesh()
    for v in "XD":
        pts = mesh.find(png[v])
        lip = bank.features[v]["lip_inner_lower_l"].points
        assert np.linalg.norm(lip[-1] - pts[14, :2]) < 1.5, v
    gap = lambda v: np.linalg.norm(bank.features[v]["lip_inner_upper_l"].points[-1]  # noqa: E731
                                   - bank.features[v]["lip_inner_lower_l"].points[-1])
    assert gap("D") > 3 * gap("X")
    assert main(["check", str(tmp_path)]) == 0
    # run again with --keep-photos --force: the photos, no one-face folder left behind
    assert main(["init", str(tmp_path), "--keep-photos", "--force"]) == 0
    assert Bank.load(tmp_path).images["D"].shape[:2] == grid_frames["D"].shape[:2]
    assert "one-face/" not in (tmp_path / "bank.yaml").read_text()


def test_a_symmetric_face_gets_a_symmetric_bank(tmp_path, grid_frames):
    from lipsync.face.landmarks import FaceMesh
    from lipsync.face.lines import midline_axis
    from lipsync.morphing.normalise import bank_axis

    # each frame's left half mirrored onto its right: an exactly symmetric face
    mesh = FaceMesh()
    axis = int(round(midline_axis([mesh.find(grid_frames["X"])])))
    sym = {}
    for v, img in grid_frames.items():
        s = img.copy()
        s[:, axis + 1:2 * axis + 1] = img[:, axis - 1::-1][:, :img.shape[1] - axis - 1]
        sym[v] = s
    _save(tmp_path, sym)
    r = init_bank(tmp_path)
    assert set(r.lines.values()) == {"face"}
    bank = Bank.load(tmp_path)
    assert bank.symmetry is True
    assert abs(bank_axis(bank) - axis) <= 1.0
    assert main(["check", str(tmp_path)]) == 0


def test_an_image_without_a_face_borrows_the_rest_visemes_face(tmp_path, grid_frames, capsys):
    imgs = dict(grid_frames)
    imgs["B"] = np.full_like(imgs["B"], 100)  # no face here
    _save(tmp_path, imgs)
    r = init_bank(tmp_path)
    assert r.lines["B"] == "face of X.png (no face found in B.png)"
    assert all(r.lines[v] == "face" for v in "XFD")
    bank = Bank.load(tmp_path)
    np.testing.assert_allclose(bank.lines["B"], bank.lines["X"])


def test_lines_option_forces_a_source(tmp_path, grid_frames, capsys):
    _save(tmp_path / "faces", grid_frames)
    r = init_bank(tmp_path / "faces", lines="template")
    assert set(r.lines.values()) == {"template toon"}
    assert "upper_outer_l" in Bank.load(tmp_path / "faces").line_names
    # no face anywhere: template by default, an error naming the images when forced
    for v in "AX":
        blank(tmp_path / "blank" / f"{v}.png" if (tmp_path / "blank").mkdir(exist_ok=True) is None else None, 400, 300)
    assert set(init_bank(tmp_path / "blank").lines.values()) == {"template toon"}
    assert main(["init", str(tmp_path / "blank"), "--lines", "face", "--force"]) == 2
    err = capsys.readouterr().err
    assert "no face found in any image (A.png, X.png)" in err and "--lines template" in err


def test_drawn_faces_the_mesh_recognises_get_face_lines(tmp_path, toon):
    # The toon is a drawing, but the face mesh finds its face: auto takes the face's lines
    for v in "XAD":
        shutil.copy(TOON / f"{v}.png", tmp_path / f"{v}.png")
    r = init_bank(tmp_path)
    assert set(r.lines.values()) == {"face"}
    bank = Bank.load(tmp_path)
    # the lips are where the toon's own lines put them (within a few pixels)
    for v in "XAD":
        ours = bank.features[v]["lip_outer_upper_l"].points
        mid = toon.lines[v][toon.line_names.index("upper_bow_l")][1]
        assert np.linalg.norm(ours[-1] - mid) < 12, v  # 0.1 of its eye distance
