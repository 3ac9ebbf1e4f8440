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


# ---------------------------------------------------------------- item 2: rotation

FFMPEG = None


def _ffmpeg(*args):
    import imageio_ffmpeg

    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-y", *map(str, args)], check=True)


@pytest.fixture(scope="module")
def turned(tmp_path_factory):
    """The GRID clip re-encoded, then tagged (stream copy) with display rotations, and a
    phone-style one: pixels stored sideways, the tag turning them upright."""
    d = tmp_path_factory.mktemp("turned")
    _ffmpeg("-i", CLIP, "-c:v", "libx264", "-preset", "ultrafast", "-qp", "0", "-c:a", "aac", d / "upright.mp4")
    for deg in (90, 180):
        _ffmpeg("-display_rotation", deg, "-i", d / "upright.mp4", "-c", "copy", d / f"rot{deg}.mp4")
    _ffmpeg("-i", d / "upright.mp4", "-vf", "transpose=2", "-c:v", "libx264", "-preset", "ultrafast", "-qp", "0",
            "-c:a", "copy", d / "sideways.mp4")
    _ffmpeg("-display_rotation", -90, "-i", d / "sideways.mp4", "-c", "copy", d / "phone.mp4")
    for name in ("rot90", "rot180", "phone", "upright"):
        (d / f"{name}.txt").write_text("bin blue with m five soon\n")
    return d


@pytest.mark.parametrize("name, turns", [("upright", 0), ("rot90", 3), ("rot180", 2), ("phone", 0)])
def test_the_face_is_found_upright_whatever_the_rotation_tag(turned, name, turns):
    import warnings

    import numpy as np

    from lipsync.face.video import probe_video, read_video
    from lipsync.videobank.sources import find_upright

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        info = find_upright(turned / f"{name}.mp4", probe_video(turned / f"{name}.mp4"))
    assert info.turns == turns and info.size == (360, 288)
    assert bool(turns) == any("turned upright" in str(w.message) for w in caught)
    # lossless streams: the turned frames are the upright clip's own pixels
    want = [f for i, f in zip(range(3), read_video(turned / "upright.mp4"))]
    got = [f for i, f in zip(range(3), read_video(turned / f"{name}.mp4", info=info))]
    tol = 0 if name != "phone" else 3   # phone: transposed and re-encoded in 4:2:0 (chroma resampled)
    assert all(np.abs(a.astype(int) - b).max() <= tol for a, b in zip(want, got))


def test_init_video_of_a_sideways_tagged_clip_makes_an_upright_bank(turned, tmp_path, capsys, caplog):
    from lipsync.banks.bank import Bank
    from lipsync.face.landmarks import FaceMesh

    out = tmp_path / "me"
    with pytest.warns(UserWarning, match="turned 90 degrees counterclockwise"):
        code, err = _exit(["init", out, "--video", turned / "rot90.mp4", "--quiet"], capsys)
    assert code == 0, err
    assert not any("frame size for reading" in r.getMessage() for r in caplog.records)  # imageio's note hidden
    bank = Bank.load(out)
    pts = FaceMesh().find(bank.images["X"])
    eyes_y, mouth_y = pts[[33, 263], 1].mean(), pts[[13, 14], 1].mean()
    assert eyes_y < mouth_y - 20   # upright: the eyes well above the mouth
    lip = bank.features["X"]["lip_inner_lower_l"].points
    assert abs(lip[-1][0] - pts[14, 0]) < 3 and abs(lip[-1][1] - pts[14, 1]) < 3   # the line is on the lip


def test_jpeg_exif_orientation_is_honoured(tmp_path):
    import struct

    import cv2
    import numpy as np

    from lipsync.banks.bank import read_image
    from lipsync.face.video import read_video

    frame = next(iter(read_video(CLIP)))
    # stored turned a quarter counterclockwise, EXIF orientation 6 ("turn 90 clockwise to show")
    ok, jpg = cv2.imencode(".jpg", cv2.cvtColor(np.ascontiguousarray(np.rot90(frame, 1)), cv2.COLOR_RGB2BGR),
                           [cv2.IMWRITE_JPEG_QUALITY, 98])
    tiff = b"MM\x00*\x00\x00\x00\x08" + struct.pack(">H", 1) + struct.pack(">HHIHH", 0x0112, 3, 1, 6, 0) + b"\0" * 4
    app1 = b"\xff\xe1" + struct.pack(">H", 2 + 6 + len(tiff)) + b"Exif\x00\x00" + tiff
    path = tmp_path / "X.jpg"
    path.write_bytes(jpg.tobytes()[:2] + app1 + jpg.tobytes()[2:])
    img = read_image(path)
    assert img.shape == frame.shape
    assert np.abs(img.astype(int) - frame).mean() < 2.0   # upright again (JPEG's error only)


# ---------------------------------------------------------------- item 6: a silent sound track

def test_a_silent_sound_track_is_exit_2_and_the_transcript_is_not_dropped_silently(tmp_path, capsys):
    silent = tmp_path / "silent.mp4"
    _ffmpeg("-i", CLIP, "-f", "lavfi", "-i", "anullsrc=r=16000:cl=mono", "-map", "0:v", "-map", "1:a", "-shortest",
            "-c:v", "libx264", "-preset", "ultrafast", "-c:a", "aac", silent)
    out = tmp_path / "me"
    code, err = _exit(["init", out, "--video", silent, "--text", "bin blue with m five soon", "--quiet"], capsys)
    assert code == 2 and f"{silent}: its sound track is silent (loudest" in err
    assert "the transcript (--text) could not be used" in err
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["silent.mp4"]
    # the aligner itself says so too (lipsync align --text on silence)
    with pytest.warns(UserWarning, match="the audio is silent; the transcript was not used"):
        _exit(["align", silent, "--text", "bin blue", "-o", tmp_path / "a.TextGrid"], capsys)


# ---------------------------------------------------------------- item 11: smaller holes

def test_underflowing_dominances_are_refused(tmp_path):
    from lipsync._data import default_bank_dir
    from lipsync.banks.bank import Bank
    from lipsync.motion.coarticulation import MIN_DOMINANCE, as_params

    with pytest.raises(InputError, match="closure.dominance"):
        as_params({"closure": {"dominance": 5e-324}})
    assert as_params({"closure": {"dominance": MIN_DOMINANCE}}).closure.dominance == MIN_DOMINANCE
    bank = tmp_path / "bank"
    shutil.copytree(default_bank_dir(), bank)
    with open(bank / "bank.yaml", "a") as f:
        f.write("coarticulation: {closure: {dominance: 5.0e-324}}\n")
    with pytest.raises(InputError, match="dominance"):
        Bank.load(bank)


def test_photo_only_options_are_refused_with_video(tmp_path, capsys):
    for extra in (["--over", tmp_path / "body.png"], ["--at", "10,20"]):
        code, err = _exit(["init", tmp_path / "me", "--video", CLIP, *extra, "--quiet"], capsys)
        assert code == 2 and f"{extra[0]} is for a folder of images" in err


def test_audio_only_mp4_has_no_video_stream(tmp_path, capsys):
    sound = tmp_path / "voice.mp4"
    _ffmpeg("-f", "lavfi", "-i", "sine=duration=1", sound)
    code, err = _exit(["init", tmp_path / "me", "--video", sound, "--quiet"], capsys)
    assert code == 2 and f"{sound}: has no video stream" in err and "Invalid argument" not in err


def test_a_face_too_small_or_cut_by_the_frame_is_refused(turned, tmp_path, capsys):
    tiny, edge = tmp_path / "tiny.mp4", tmp_path / "edge.mp4"
    _ffmpeg("-i", turned / "upright.mp4", "-vf", "scale=32:32", "-c:a", "copy", tiny)
    # the head at the frame's edge: a 42x238 bank (0.8 eye distances wide) before, lips cut
    _ffmpeg("-i", turned / "upright.mp4", "-vf", "crop=225:288:135:0", "-c:a", "copy", edge)
    for clip in (tiny, edge):
        clip.with_suffix(".txt").write_text("bin blue with m five soon\n")
    code, err = _exit(["init", tmp_path / "a", "--video", tiny, "--quiet"], capsys)
    assert code == 2 and "tiny.mp4: the face is too small: 4 px between the eyes in a 32x32 picture" in err
    code, err = _exit(["init", tmp_path / "b", "--video", edge, "--quiet"], capsys)
    assert code == 2 and "edge.mp4: the mouth is outside the picture in" in err
    # narrower than the face room finds a face in (1.5 eye distances), even with the lips inside
    from lipsync.videobank.make import _check_trackable

    with pytest.raises(InputError, match=r"the face is cut: the bank's pictures would be 42x238 px, 0.9 eye"):
        _check_trackable("edge.mp4", 42, 238, 49.0)
    _check_trackable("ok.mp4", 74, 238, 49.0)   # 1.51 eye distances: accepted
    # the frame's bottom through the lips (GRID's lower lip reaches row 216): exit 1 and a
    # cv2.error in select.sharpness before, or a bank whose lines lie off its pictures
    cut = tmp_path / "cut.mp4"
    _ffmpeg("-i", turned / "upright.mp4", "-vf", "crop=360:200:0:0", "-c:a", "copy", cut)
    cut.with_suffix(".txt").write_text("bin blue with m five soon\n")
    code, err = _exit(["init", tmp_path / "c", "--video", cut, "--quiet"], capsys)
    assert code == 2 and "cut.mp4: the mouth is outside the picture in" in err
    assert not any((tmp_path / n).exists() for n in "abc")


def test_a_face_tilted_halfway_between_turns_is_refused_not_guessed(turned, tmp_path):
    from lipsync.face.video import probe_video
    from lipsync.videobank.sources import find_upright

    tilted = tmp_path / "tilt45.mp4"
    _ffmpeg("-i", turned / "upright.mp4", "-t", "4", "-vf", "rotate=PI/4:ow=460:oh=460", "-c:a", "copy", tilted)
    with pytest.raises(InputError, match=r"tilt45.mp4: cannot tell which way up the face is \(tilted 4\d degrees\)"):
        find_upright(tilted, probe_video(tilted))


def test_a_failing_run_makes_no_folders(tmp_path, capsys):
    code, err = _exit(["init", tmp_path / "new" / "deep" / "me", "--video", tmp_path / "missing.mpg", "--quiet"],
                      capsys)
    assert code == 2 and "missing.mpg" in err
    assert list(tmp_path.iterdir()) == []
