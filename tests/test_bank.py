"""Bank loading: every validation rule, with errors naming file, line, viseme and control line."""

import os
import shutil

import numpy as np
import pytest
import yaml

from lipsync.banks.bank import Bank
from lipsync.cli import main
from lipsync.errors import BankError


@pytest.fixture()
def bank_dir(synthetic_bank_dir, tmp_path):
    d = tmp_path / "bank"
    shutil.copytree(synthetic_bank_dir, d)
    return d


def edit(bank_dir, fn):
    spec = yaml.safe_load((bank_dir / "bank.yaml").read_text())
    fn(spec)
    (bank_dir / "bank.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))


def test_loads_synthetic_bank(bank_dir):
    bank = Bank.load(bank_dir)
    assert bank.names == ("X", "A", "O", "E") and bank.rest == "X"
    assert bank.shape == (160, 192) and bank.images["A"].dtype == np.uint8
    assert bank.lines["O"].shape == (len(bank.line_names), 2, 2)
    assert (bank.warp.a, bank.warp.b, bank.warp.p) == (1.0, 2.0, 0.5)


@pytest.mark.parametrize("mutate, pattern", [
    (lambda s: s["visemes"]["A"]["lines"].pop("height"), r"viseme 'A': missing line 'height'"),
    (lambda s: s["visemes"]["O"]["lines"].update(extra=[[1, 1], [2, 2]]), r"viseme 'O': line 'extra' is not in"),
    (lambda s: s["visemes"]["E"]["lines"].update(nose=[[5, 5], [5, 5]]), r"viseme 'E', line 'nose': zero-length"),
    (lambda s: s.update(rest="Z"), r"rest viseme 'Z' is not among"),
    (lambda s: s["visemes"]["A"].update(image="missing.png"), r"viseme 'A': image 'missing.png' does not exist"),
    (lambda s: s["visemes"]["A"].update(image="../X.png"), r"viseme 'A': image path '../X.png' leads outside"),
    (lambda s: s["visemes"]["A"].update(image="/etc/passwd"), r"must be relative"),
    (lambda s: [v["lines"].pop("eye_r") for v in s["visemes"].values()], r"line 'eye_l': symmetry is on but its mirror partner 'eye_r'"),
    (lambda s: s["visemes"]["A"]["lines"].update(width=[[1, 2, 3], [4, 5]]), r"visemes\.A\.lines\.width"),
    (lambda s: s.update(warp={"a": -1}), r"warp\.a"),
    (lambda s: s.update(colour="red"), r"colour"),
])
def test_invalid_banks_name_file_line_and_place(bank_dir, mutate, pattern):
    edit(bank_dir, mutate)
    with pytest.raises(BankError, match=pattern) as exc:
        Bank.load(bank_dir)
    message = str(exc.value)
    assert message.startswith(str(bank_dir / "bank.yaml") + ":")
    assert exc.value.line is not None and exc.value.line >= 1


def test_error_line_points_at_the_bad_line(bank_dir):
    edit(bank_dir, lambda s: s["visemes"]["E"]["lines"].update(nose=[[5, 5], [5, 5]]))
    with pytest.raises(BankError) as exc:
        Bank.load(bank_dir)
    text = (bank_dir / "bank.yaml").read_text().splitlines()
    # the reported line is the line of the key "nose:" inside viseme E
    assert text[exc.value.line - 1].strip().startswith("nose:")
    e_line = next(i for i, t in enumerate(text) if t.strip() == "E:")
    assert exc.value.line - 1 > e_line


def test_images_of_different_sizes(bank_dir):
    import cv2

    cv2.imwrite(str(bank_dir / "O.png"), np.zeros((10, 12, 3), np.uint8))
    with pytest.raises(BankError, match=r"viseme 'O': image 'O.png' is 12x10 but 'X' is 192x160"):
        Bank.load(bank_dir)


def test_unreadable_image(bank_dir):
    (bank_dir / "E.png").write_bytes(b"not a png at all")
    with pytest.raises(BankError, match=r"viseme 'E': cannot decode image 'E.png'"):
        Bank.load(bank_dir)


def test_symlink_leaving_the_bank_is_refused(bank_dir, tmp_path):
    outside = tmp_path / "outside.png"
    shutil.copy(bank_dir / "A.png", outside)
    (bank_dir / "A.png").unlink()
    os.symlink(outside, bank_dir / "A.png")
    with pytest.raises(BankError, match="leads outside the bank folder"):
        Bank.load(bank_dir)


def test_yaml_custom_tags_are_refused(bank_dir):
    text = (bank_dir / "bank.yaml").read_text()
    (bank_dir / "bank.yaml").write_text(text.replace("name: synthetic", "name: !!python/object:os.system ls"))
    with pytest.raises(BankError, match=r"bank.yaml:1: invalid YAML"):
        Bank.load(bank_dir)


def test_huge_png_header_is_refused_before_decoding(bank_dir):
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", 100000, 100000, 8, 2, 0, 0, 0)
    (bank_dir / "E.png").write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b""))
    with pytest.raises(BankError, match="above the limit"):
        Bank.load(bank_dir)


def test_missing_bank_yaml(tmp_path):
    with pytest.raises(BankError, match="no bank.yaml"):
        Bank.load(tmp_path)


def test_cli_check_exit_codes(bank_dir, capsys):
    assert main(["check", str(bank_dir)]) == 0
    out = capsys.readouterr().out
    assert "4 visemes" in out and "axis x = 95.5" in out and "0 of 6 pairs present" in out
    edit(bank_dir, lambda s: s.update(rest="Z"))
    assert main(["check", str(bank_dir)]) == 2
    err = capsys.readouterr().err
    assert "bank.yaml:" in err and "rest viseme 'Z'" in err


@pytest.mark.parametrize("value", [".nan", ".inf", "-.inf"])
def test_non_finite_warp_parameters_are_named_as_such(bank_dir, value):
    # issue 19, item 8: `a: .nan` was reported as "less than or equal to 10000"
    text = (bank_dir / "bank.yaml").read_text()
    (bank_dir / "bank.yaml").write_text(text.replace("rest: X\n", f"rest: X\nwarp: {{a: {value}}}\n", 1))
    with pytest.raises(BankError, match=r"bank\.yaml:\d+: warp\.a: Input should be a finite number"):
        Bank.load(bank_dir)
