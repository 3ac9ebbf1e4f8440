"""``lipsync init OUT --video`` against careless and hostile use (issue 32, items 2, 3, 5, 6, 10, 11).

Each test runs the real command (in-process ``main`` or a subprocess for kills) on the GRID
clips in tests/data/grid-s1 and checks what is on disk afterwards: inputs never deleted,
nothing hidden left beside OUT, errors naming OUT (not a hidden staging folder), exit 2.
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lipsync.cli import main
from lipsync.errors import InputError
from lipsync.videobank.write import Staging

ROOT = Path(__file__).resolve().parents[1]
GRID = ROOT / "tests" / "data" / "grid-s1"
CLIP = GRID / "bbwm5s.mpg"


def _exit(argv, capsys):
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


# ---------------------------------------------------------------- item 3: --force and the inputs

def test_force_never_deletes_an_input_inside_out(tmp_path, capsys):
    out = tmp_path / "me"
    out.mkdir()
    clip = out / "clip.mpg"
    shutil.copy(CLIP, clip)
    (out / "clip.txt").write_text("bin blue with m five soon\n")
    (out / "notes.md").write_text("mine")
    code, err = _exit(["init", out, "--video", clip, "--force", "--quiet"], capsys)
    assert code == 2 and f"holds {clip}" in err and "Traceback" not in err
    assert sorted(p.name for p in out.iterdir()) == ["clip.mpg", "clip.txt", "notes.md"]
    assert clip.read_bytes() == CLIP.read_bytes()
    # the transcript named with --text counts as an input too
    out2 = tmp_path / "texts"
    out2.mkdir()
    (out2 / "t.txt").write_text("bin blue with m five soon\n")
    code, err = _exit(["init", out2, "--video", CLIP, "--text", out2 / "t.txt", "--force", "--quiet"], capsys)
    assert code == 2 and "t.txt" in err and (out2 / "t.txt").is_file()


def test_force_replaces_only_a_bank(tmp_path, capsys):
    out = tmp_path / "photos"
    out.mkdir()
    (out / "holiday.jpg").write_bytes(b"not mine to delete")
    code, err = _exit(["init", out, "--video", CLIP, "--force", "--quiet"], capsys)
    assert code == 2 and "not a bank (no bank.yaml)" in err
    assert [p.name for p in out.iterdir()] == ["holiday.jpg"]


def test_init_dot_force_is_refused_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    bank = tmp_path / "bank"
    bank.mkdir()
    (bank / "bank.yaml").write_text("name: x\n")
    monkeypatch.chdir(bank)
    code, err = _exit(["init", ".", "--video", CLIP, "--force", "--quiet"], capsys)
    assert code == 2 and "current folder" in err and "Errno" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bank"]
    assert [p.name for p in bank.iterdir()] == ["bank.yaml"]


# ---------------------------------------------------------------- item 5: a killed run's staging folder

_STAGE_AND_HANG = """
import sys, time
from pathlib import Path
from lipsync.videobank.write import Staging
with Staging(Path(sys.argv[1])) as tmp:
    (tmp / "X.png").write_bytes(b"half a bank")
    print(tmp.name, flush=True)
    time.sleep(120)
"""


def test_a_killed_init_video_staging_folder_is_removed_by_the_next_run(tmp_path, capsys):
    out = tmp_path / "me"
    p = subprocess.Popen([sys.executable, "-c", _STAGE_AND_HANG, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        staged = p.stdout.readline().strip()
        assert staged and (tmp_path / staged / "X.png").is_file()
        # while the writer lives, another run leaves its staging folder alone
        code, _ = _exit(["init", out, "--video", tmp_path / "missing.mpg", "--quiet"], capsys)
        assert code == 2 and (tmp_path / staged).is_dir()
    finally:
        p.send_signal(signal.SIGKILL)
        p.wait(10)
    assert (tmp_path / staged).is_dir()        # SIGKILL: no handler ran
    code, err = _exit(["init", out, "--video", tmp_path / "missing.mpg", "--quiet"], capsys)
    assert code == 2 and "missing.mpg" in err
    assert list(tmp_path.iterdir()) == []      # the next run removed it


# ---------------------------------------------------------------- item 10: write errors name OUT

def test_out_under_a_file_and_a_name_too_long_are_exit_2_naming_out(tmp_path, capsys):
    afile = tmp_path / "a-file"
    afile.write_text("x")
    code, err = _exit(["init", afile / "me", "--video", CLIP, "--quiet"], capsys)
    assert code == 2 and f"{afile / 'me'}: cannot write the bank: a file stands where a folder" in err
    long_out = tmp_path / ("b" * 300)
    code, err = _exit(["init", long_out, "--video", CLIP, "--quiet"], capsys)
    assert code == 2 and "name is too long" in err and "partial" not in err and "Errno" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]


@pytest.mark.parametrize("code_, words", [(errno.ENOSPC, "the disk is full"),
                                          (errno.EROFS, "the file system is read-only")])
def test_disk_errors_while_staging_name_out_not_the_hidden_folder(tmp_path, code_, words):
    out = tmp_path / "me"
    with pytest.raises(InputError) as caught:
        with Staging(out) as tmp:
            (tmp / "X.png").write_bytes(b"x")
            # what the OS says when the disk fills up writing the third picture
            raise OSError(code_, os.strerror(code_), str(tmp / "C.png"))
    assert str(caught.value) == f"{out}: cannot write the bank: {words} (nothing was written)"
    assert list(tmp_path.iterdir()) == []
