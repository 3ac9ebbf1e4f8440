"""Clean failures of ``lipsync render``, each through the command line.

Environment failures -- ffmpeg dying mid-stream or at the end, an output folder that cannot
take the file, a full disk, Ctrl-C -- end with exit 1 (130 for Ctrl-C), a message on
stderr saying what happened, nothing at OUT and no temporary file beside it. Bad input is
refused with exit 2 and a message naming the file: bank image paths that leave the bank
folder (``../``, absolute, a symlink out), YAML custom tags, images above the pixel limit
(by PNG and by JPEG header), more control lines or visemes than allowed, a timeline naming
a viseme the bank lacks, an unknown ``--method`` or ``--format``.

Failures that need a real process (ffmpeg, signals) run ``python -m lipsync`` as a
subprocess; the rest call :func:`lipsync.cli.main` in-process, which is much faster.
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import stat
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import List

import cv2
import numpy as np
import pytest
import yaml

import synthetic
from lipsync import cli, encode
from lipsync.banks.bank import MAX_IMAGE_PIXELS, MAX_LINES, MAX_VISEMES

ROOT = Path(__file__).resolve().parent.parent
HELLO = ROOT / "samples" / "hello.phn"
#: Upper bound on any one command here; only a hang reaches it.
CMD_TIMEOUT_S = 300


# --------------------------------------------------------------------------- helpers

@pytest.fixture(scope="module")
def bank(tmp_path_factory) -> Path:
    """A small bank the default (Rhubarb-shape) map renders, with its flows precomputed."""
    folder = synthetic.write_bank(tmp_path_factory.mktemp("clibank") / "bank", synthetic.RHUBARB_SHAPES)
    result = run_cli("preprocess", str(folder), "--jobs", "2", "--quiet")
    assert result.returncode == 0, result.stderr
    return folder


def run_cli(*args: str, env_extra=None, **kwargs) -> subprocess.CompletedProcess:
    env = dict(os.environ, **(env_extra or {}))
    return subprocess.run([sys.executable, "-m", "lipsync", *args], capture_output=True, text=True,
                          timeout=CMD_TIMEOUT_S, env=env, **kwargs)


def render_args(bank: Path, out: Path, timeline: Path = HELLO, *extra: str) -> List[str]:
    return ["render", str(timeline), "-o", str(out), "--bank", str(bank), "--quiet", *extra]


def assert_nothing_left(folder: Path, before=()) -> None:
    """No output and no temporary file (hidden or not) in the output folder."""
    left = sorted(set(os.listdir(folder)) - set(before))
    assert left == [], f"left behind in {folder}: {left}"


def fake_ffmpeg(tmp_path: Path, body: str) -> Path:
    """A shell script standing in for ffmpeg (lipsync finds ffmpeg through imageio-ffmpeg,
    which honours IMAGEIO_FFMPEG_EXE)."""
    script = tmp_path / "fake-ffmpeg"
    script.write_text("#!/bin/sh\n" + body)
    script.chmod(script.stat().st_mode | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH)
    return script


def main_in_process(argv: List[str], capsys):
    code = cli.main(argv)
    captured = capsys.readouterr()
    return code, captured.err


# --------------------------------------------------------------------------- ffmpeg failing

#: One 192x160 RGB frame is 92,160 bytes: the fake reads ~3 frames, then fails.
FRAME_BYTES_READ = 300_000


@pytest.mark.parametrize("when", ["mid-stream", "at-the-end"])
def test_ffmpeg_failing(bank, tmp_path, when):
    body = {"mid-stream": f"head -c {FRAME_BYTES_READ} > /dev/null\n",
            "at-the-end": "cat > /dev/null\n"}[when]
    script = fake_ffmpeg(tmp_path, body + 'echo "fake-ffmpeg: encoder exploded" >&2\nexit 1\n')
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    result = run_cli(*render_args(bank, out_dir / "talk.mp4"), env_extra={"IMAGEIO_FFMPEG_EXE": str(script)})
    assert result.returncode == 1, result.stderr
    assert "lipsync: error:" in result.stderr and "ffmpeg" in result.stderr
    assert "encoder exploded" in result.stderr  # ffmpeg's own words are quoted
    assert str(out_dir / "talk.mp4") in result.stderr
    assert_nothing_left(out_dir)


# --------------------------------------------------------------------------- output path

def test_output_folder_missing_is_made_as_every_command_makes_it(bank, tmp_path):
    # render, cues, align, preview and morph all make OUT's missing folder (issue 19, item 8;
    # render alone used to refuse), and all name OUT when it cannot be written
    out = tmp_path / "no" / "such" / "folder" / "talk.mp4"
    result = run_cli(*render_args(bank, out))
    assert result.returncode == 0, result.stderr
    assert out.stat().st_size > 0 and sorted(os.listdir(out.parent)) == ["talk.mp4"]
    timeline = tmp_path / "t.phn"
    timeline.write_text("0 1600 h#\n1600 4800 aa\n4800 8000 h#\n")
    made = {"cues": tmp_path / "c" / "d" / "cues.tsv", "preview": tmp_path / "p" / "q" / "sheet.png",
            "morph": tmp_path / "m" / "n" / "half.png"}
    assert run_cli("cues", str(timeline), "-o", str(made["cues"])).returncode == 0
    assert run_cli("preview", str(bank), "-o", str(made["preview"])).returncode == 0
    assert run_cli("morph", str(bank), "X", "A", "--alpha", "0.5", "-o", str(made["morph"])).returncode == 0
    for path in made.values():
        assert path.stat().st_size > 0 and sorted(os.listdir(path.parent)) == [path.name]
    for cmd in (["cues", str(timeline)], ["render", str(timeline), "--bank", str(bank), "--quiet"],
                ["preview", str(bank)], ["morph", str(bank), "X", "A", "--alpha", "0.5"]):
        out = "/proc/no-such/x.png" if cmd[0] in ("preview", "morph") else \
            ("/proc/no-such/x.tsv" if cmd[0] == "cues" else "/proc/no-such/x.mp4")
        result = run_cli(*cmd, "-o", out)
        assert result.returncode == 1 and f"cannot write {out}" in result.stderr, (cmd, result.stderr)
        assert ".partial-" not in result.stderr and ".tmp" not in result.stderr


def test_output_folder_is_a_file(bank, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    result = run_cli(*render_args(bank, blocker / "talk.mp4"))
    assert result.returncode == 1
    assert "not a folder" in result.stderr
    assert sorted(os.listdir(tmp_path)) == ["file"] and blocker.read_text() == "not a folder"


def test_output_folder_not_writable(bank, tmp_path, monkeypatch, capsys):
    # In-process so that it also holds when the tests run as root (who may write anywhere):
    # the writer's first write into the folder fails as a read-only folder would make it.
    out_dir = tmp_path / "ro"
    out_dir.mkdir()
    real_open = os.open

    def refusing_open(path, flags, *args, **kwargs):
        if os.path.dirname(os.fspath(path)) == str(out_dir) and flags & os.O_CREAT:
            raise PermissionError(errno.EACCES, "Permission denied", os.fspath(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(encode.os, "open", refusing_open)
    code, err = main_in_process(render_args(bank, out_dir / "talk.mp4", HELLO, "--store", str(bank / ".lipsync")),
                                capsys)
    assert code == 2   # bad input, named before any work (issue 38 item 13; was exit 1 after the work)
    assert "not writable" in err and str(out_dir / "talk.mp4") in err
    assert_nothing_left(out_dir)


def test_output_is_an_existing_folder(bank, tmp_path):
    out = tmp_path / "talk.mp4"
    out.mkdir()
    result = run_cli(*render_args(bank, out, HELLO, "--format", "mp4"))
    assert result.returncode == 1
    assert "folder of that name exists" in result.stderr
    assert os.listdir(out) == [] and sorted(os.listdir(tmp_path)) == ["talk.mp4"]


# --------------------------------------------------------------------------- full disk

@pytest.mark.parametrize("fmt", ["mp4", "png"])
def test_disk_full_mid_render(bank, tmp_path, monkeypatch, capsys, fmt):
    calls = {"n": 0}
    real_write_all = encode.base.write_all

    def filling_disk(stream, data):
        calls["n"] += 1
        if calls["n"] > 5:  # a few frames fit, then the disk is full
            raise OSError(errno.ENOSPC, "No space left on device")
        real_write_all(stream, data)

    monkeypatch.setattr(encode.base, "write_all", filling_disk)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / ("talk.mp4" if fmt == "mp4" else "frames")
    code, err = main_in_process(render_args(bank, out, HELLO, "--format", fmt), capsys)
    assert code == 1
    assert calls["n"] == 6  # it failed at the write that hit the full disk, and stopped
    assert "lipsync: error:" in err and ("disk full" in err or "No space left" in err)
    assert_nothing_left(out_dir)


# --------------------------------------------------------------------------- Ctrl-C

def long_timeline(path: Path, seconds: float = 120.0) -> Path:
    """A TIMIT-style phone file alternating open and closed mouths for ``seconds``."""
    rate, phone = 16000, 0.12
    rows = [f"{int(i * phone * rate)} {int((i + 1) * phone * rate)} {('aa', 'm', 'iy', 'uw')[i % 4]}"
            for i in range(int(seconds / phone))]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_ctrl_c_during_render(bank, tmp_path):
    timeline = long_timeline(tmp_path / "long.phn")
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / "talk.mp4"
    proc = subprocess.Popen([sys.executable, "-m", "lipsync", *render_args(bank, out, timeline, "--method",
                                                                           "beier-neely")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # Wait until the encoder's temporary output exists and has received data: frames are
        # flowing. beier-neely renders ~3000 frames here, far longer than this wait.
        deadline = time.monotonic() + CMD_TIMEOUT_S
        while proc.poll() is None and time.monotonic() < deadline:
            partial = [p for p in out_dir.iterdir() if p.name.startswith(".talk.mp4.partial")]
            if partial and partial[0].stat().st_size > 0:
                break
            time.sleep(0.02)
        assert proc.poll() is None, "render ended before it could be interrupted"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert "interrupted" in err and "no partial output" in err
    assert "Traceback" not in err
    assert_nothing_left(out_dir)


# --------------------------------------------------------------------------- refusals (exit 2)

@pytest.fixture()
def bank_copy(bank, tmp_path) -> Path:
    folder = tmp_path / "bank"
    shutil.copytree(bank, folder, ignore=shutil.ignore_patterns(".lipsync"))
    return folder


def edit_bank(folder: Path, change) -> Path:
    spec = yaml.safe_load((folder / "bank.yaml").read_text())
    change(spec)
    (folder / "bank.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    return folder / "bank.yaml"


def refused(argv: List[str], capsys, *needles: str, out: Path = None) -> str:
    code, err = main_in_process(argv, capsys)
    assert code == 2, err
    assert err.startswith("lipsync: error:")
    for needle in needles:
        assert needle in err, f"{needle!r} not in: {err}"
    if out is not None:
        assert not out.exists()
    return err


@pytest.mark.parametrize("how", ["dotdot", "absolute", "symlink-out", "symlinked-folder-out"])
def test_image_paths_leaving_the_bank_are_refused(bank_copy, tmp_path, capsys, how):
    outside = tmp_path / "outside"
    outside.mkdir()
    shutil.copy(bank_copy / "A.png", outside / "A.png")  # a perfectly good image, just elsewhere
    if how == "dotdot":
        rel = "../outside/A.png"
    elif how == "absolute":
        rel = str(outside / "A.png")
    elif how == "symlink-out":
        (bank_copy / "link.png").symlink_to(outside / "A.png")
        rel = "link.png"
    else:
        (bank_copy / "sub").symlink_to(outside)
        rel = "sub/A.png"
    yaml_path = edit_bank(bank_copy, lambda s: s["visemes"]["A"].__setitem__("image", rel))
    out = tmp_path / "talk.mp4"
    refused(render_args(bank_copy, out), capsys, str(yaml_path), "'A'", out=out)
    err = refused(["check", str(bank_copy)], capsys, str(yaml_path))
    assert ("outside the bank folder" in err) or ("relative to the bank folder" in err)


def test_image_path_inside_the_bank_through_a_subfolder_is_fine(bank_copy, capsys):
    (bank_copy / "img").mkdir()
    shutil.move(str(bank_copy / "A.png"), bank_copy / "img" / "A.png")
    edit_bank(bank_copy, lambda s: s["visemes"]["A"].__setitem__("image", "img/../img/A.png"))
    code, err = main_in_process(["check", str(bank_copy)], capsys)
    assert code == 0, err


@pytest.mark.parametrize("tag", ["!!python/object/apply:os.system ['touch PWNED']", "!custom toon",
                                 "!!python/name:os.system"])
def test_yaml_custom_tags_are_refused(bank_copy, tmp_path, capsys, tag, monkeypatch):
    yaml_path = bank_copy / "bank.yaml"
    text = yaml_path.read_text().replace("name: synthetic", f"name: {tag}", 1)
    assert text != yaml_path.read_text()
    yaml_path.write_text(text)
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "talk.mp4"
    refused(render_args(bank_copy, out), capsys, str(yaml_path), "invalid YAML", out=out)
    assert not (tmp_path / "PWNED").exists()


def _png_claiming(width: int, height: int) -> bytes:
    ok, buf = cv2.imencode(".png", np.zeros((2, 2, 3), np.uint8))
    data = bytearray(buf.tobytes())
    data[16:24] = struct.pack(">II", width, height)  # IHDR width and height
    return bytes(data)


def _jpeg_claiming(width: int, height: int) -> bytes:
    ok, buf = cv2.imencode(".jpg", np.full((16, 16, 3), 128, np.uint8))
    data = bytearray(buf.tobytes())
    i = data.find(b"\xff\xc0")  # baseline frame header: length, precision, height, width
    data[i + 5:i + 9] = struct.pack(">HH", height, width)
    return bytes(data)


@pytest.mark.parametrize("kind", ["png", "jpeg"])
def test_images_above_the_pixel_limit_are_refused(bank_copy, tmp_path, capsys, kind):
    # 8000 x 4400 is just over 7680 x 4320; the files are a few hundred bytes, so only the
    # header says how big they are (a decompression bomb).
    width, height = 8000, 4400
    assert width * height > MAX_IMAGE_PIXELS
    name = "big.png" if kind == "png" else "big.jpg"
    (bank_copy / name).write_bytes(_png_claiming(width, height) if kind == "png" else _jpeg_claiming(width, height))
    yaml_path = edit_bank(bank_copy, lambda s: s["visemes"]["B"].__setitem__("image", name))
    out = tmp_path / "talk.mp4"
    refused(render_args(bank_copy, out), capsys, str(yaml_path), "'B'", "8000x4400", "above the limit", out=out)


def test_a_real_jpeg_bank_still_loads(bank_copy, capsys):
    # The JPEG header check must read true sizes: a bank of JPEG images renders as before.
    def to_jpeg(spec):
        for v, entry in spec["visemes"].items():
            img = cv2.imread(str(bank_copy / entry["image"]))
            cv2.imwrite(str(bank_copy / f"{v}.jpg"), img)
            entry["image"] = f"{v}.jpg"

    edit_bank(bank_copy, to_jpeg)
    code, err = main_in_process(["check", str(bank_copy)], capsys)
    assert code == 0, err


def test_more_lines_than_allowed_are_refused(bank_copy, tmp_path, capsys):
    def add_lines(spec):
        for entry in spec["visemes"].values():
            for i in range(MAX_LINES + 1 - len(entry["lines"])):
                entry["lines"][f"extra{i}"] = [[10.0 + i % 50, 10.0], [10.0 + i % 50, 20.0]]

    yaml_path = edit_bank(bank_copy, add_lines)
    out = tmp_path / "talk.mp4"
    refused(render_args(bank_copy, out), capsys, str(yaml_path), f"{MAX_LINES + 1} lines", f"at most {MAX_LINES}",
            out=out)


def test_more_visemes_than_allowed_are_refused(bank_copy, tmp_path, capsys):
    def add_visemes(spec):
        first = next(iter(spec["visemes"].values()))
        for i in range(MAX_VISEMES + 1 - len(spec["visemes"])):
            spec["visemes"][f"V{i}"] = dict(first)

    yaml_path = edit_bank(bank_copy, add_visemes)
    out = tmp_path / "talk.mp4"
    refused(render_args(bank_copy, out), capsys, str(yaml_path), f"{MAX_VISEMES + 1} visemes",
            f"at most {MAX_VISEMES}", out=out)


def test_timeline_naming_a_viseme_the_bank_lacks(bank, tmp_path, capsys):
    cues = tmp_path / "cues.tsv"
    cues.write_text("0.00\tX\n0.20\tB\n0.45\tZ\n0.70\tX\n")  # Rhubarb TSV; the bank has no Z
    out = tmp_path / "talk.mp4"
    refused(render_args(bank, out, cues), capsys, str(cues), "Z", out=out)


@pytest.mark.parametrize("option, value", [("--method", "morph-o-matic"), ("--format", "tiff")])
def test_unknown_method_or_format(bank, tmp_path, capsys, option, value):
    out = tmp_path / "talk.mp4"
    with pytest.raises(SystemExit) as exc:
        cli.main(render_args(bank, out, HELLO, option, value))
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert option in err and "invalid choice" in err and repr(value) in err
    assert "flow" in err if option == "--method" else "mp4" in err  # the valid choices are listed
    assert not out.exists()


#: Address-space cap for the child in the test below: a regression (per-frame arrays for 10^9
#: frames need ~8 GB) then fails fast with MemoryError instead of swamping the machine.
CHILD_MEMORY_LIMIT = 3 << 30


@pytest.mark.parametrize("name, text, expect", [
    # past 24 hours (MAX_TIMELINE_S): the reader refuses the line holding the number
    ("huge.dat", "MohoSwitch1\n1 X\n1000000000 A\n", ":3: "),          # frame 10^9 at 24 fps
    ("huge.phn", "0 1600 h#\n1600 100000000000000 aa\n", ":2: "),       # 10^14 samples at 16 kHz
    ("huge.tsv", "0.00\tX\n0.50\tB\n1e12\tX\n", ":3: "),                # a cue at 10^12 s
    # under 24 hours but over the sequencer's MAX_FRAMES at 25 fps (2 million frames)
    ("long.tsv", "0.00\tX\n0.50\tB\n80000\tX\n", "frames"),
])
def test_absurdly_long_timelines_are_refused_without_allocating(bank, tmp_path, name, text, expect):
    import resource

    timeline = tmp_path / name
    timeline.write_text(text)
    out = tmp_path / "talk.mp4"

    def cap_memory():
        resource.setrlimit(resource.RLIMIT_AS, (CHILD_MEMORY_LIMIT, CHILD_MEMORY_LIMIT))

    result = subprocess.run([sys.executable, "-m", "lipsync", *render_args(bank, out, timeline)],
                            capture_output=True, text=True, timeout=CMD_TIMEOUT_S, preexec_fn=cap_memory)
    assert result.returncode == 2, result.stderr[-800:]
    assert str(timeline) in result.stderr and expect in result.stderr and "limit" in result.stderr
    assert sorted(os.listdir(tmp_path)) == [name]


def test_render_imports_only_what_it_runs_on(tmp_path):
    # `lipsync render` registers only its own command: the other commands' modules and
    # what they run on (starlette, dask, the writers, recognisers) stay unloaded.
    tsv = tmp_path / "cues.tsv"
    tsv.write_text("0.00\tX\n0.20\tD\n0.60\tX\n")
    code = ("import sys; from lipsync.cli import main; "
            f"rc = main(['render', {str(tsv)!r}, '-o', {str(tmp_path / 'f')!r}, '--format', 'png', '--quiet']); "
            "print(rc); print(' '.join(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[0] == "0"
    loaded = set(out[1].split())
    assert "lipsync.cli.render" in loaded
    for name in ("lipsync.cli.serve", "lipsync.cli.batch", "lipsync.cli.cues", "lipsync.server", "lipsync.batch",
                 "lipsync.writers", "starlette", "dask", "pocketsphinx"):
        assert name not in loaded, name
    # --help and a mistyped command still see every command.
    parser = cli.build_parser([])
    names = set(parser._subparsers._group_actions[0].choices)
    assert {"render", "serve", "batch", "cues", "align"} <= names
    assert set(cli.build_parser(["rendr"])._subparsers._group_actions[0].choices) == names


# --------------------------------------------------------------------------- issue 19, item 5

def test_unknown_preset_is_refused_before_any_work(tmp_path):
    bank = tmp_path / "toon"
    shutil.copytree(ROOT / "visemes" / "toon", bank, ignore=shutil.ignore_patterns(".lipsync"))
    out = tmp_path / "talk.mp4"
    result = run_cli("render", str(HELLO), "-o", str(out), "--bank", str(bank), "--preset", "bogus", "--quiet")
    assert result.returncode == 2, result.stderr
    assert "--preset 'bogus'" in result.stderr and "talking-head" in result.stderr and "veryslow" in result.stderr
    assert "ffmpeg" not in result.stderr.lower() and "Traceback" not in result.stderr
    assert not (bank / ".lipsync").exists()  # nothing was computed
    assert sorted(os.listdir(tmp_path)) == ["toon"]


def test_a_timeline_of_no_length_is_bad_input_naming_it(tmp_path):
    import wave

    phn = tmp_path / "z.phn"
    phn.write_text("0 0 h#\n")
    wav = tmp_path / "empty.wav"
    with wave.open(str(wav), "wb") as w:  # a WAV that is only its header
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(16000)
    for src in (phn, wav):
        out = tmp_path / f"{src.stem}.mp4"
        result = run_cli("render", str(src), "-o", str(out), "--quiet")
        assert result.returncode == 2, result.stderr
        assert f"{src}: the timeline lasts 0 s" in result.stderr and not out.exists()
    assert sorted(os.listdir(tmp_path)) == ["empty.wav", "z.phn"]
