"""lipsync init: a starting bank.yaml from a folder of images."""

import shutil

import cv2
import numpy as np
import pytest
import yaml

from lipsync._data import default_bank_dir
from lipsync.bank import Bank
from lipsync.banks.init import FRAME_PREFIX, MOUTH_FILL, _is_mouth, init_bank
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
    r = init_bank(tmp_path)
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
    init_bank(tmp_path, layout="face")
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
    from lipsync.normalise import bank_axis
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
