"""``lipsync dub`` under hostile conditions (issue 38 items 3, 7, 8, 9, 11): a full disk, a
dub killed while it builds its bank, an unwritable or poisoned cache, a variable-frame-rate
video.

Real runs of the command (a subprocess where a kill or a signal is part of the case) on GRID
speaker s1's ``bbwm5s`` (tests/data/grid-s1, CC BY 4.0, see SOURCE.md there) with the
project's own speech samples (samples/hello.wav, 3.0 s, shorter than the 3.0 s video, and
samples/balloons.wav, 5.0 s, which outlasts it so the video plays on backwards from frames
kept on disk). Checked against what is on disk afterwards (every name in the folders), the
exit status and message, and for the frame timing the decoded output's own pixels (each
source frame carries its number as a barcode the dub does not touch).
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from lipsync.cli import main

ROOT = Path(__file__).parents[1]
VIDEO = ROOT / "tests" / "data" / "grid-s1" / "bbwm5s.mpg"
SHORT, SHORT_TEXT = ROOT / "samples" / "hello.wav", ROOT / "samples" / "hello.lab"
LONG, LONG_TEXT = ROOT / "samples" / "balloons.wav", ROOT / "samples" / "balloons.lab"
#: A pid Linux never hands out (pids stop at 2**22): the owner of a killed run's leftovers.
DEAD = 2 ** 22 + 4321


def _dub(*args, env=None, timeout=300) -> subprocess.CompletedProcess:
    e = dict(os.environ, **(env or {}))
    return subprocess.run([sys.executable, "-m", "lipsync", "dub", *map(str, args), "--quiet"], env=e,
                          capture_output=True, text=True, timeout=timeout)


def _partials(folder: Path):
    return sorted(p.name for p in folder.iterdir() if ".partial-" in p.name)


def _entry(cache: Path) -> Path:
    (entry,) = [p for p in cache.iterdir() if not p.name.startswith(".")]
    return entry


def _bank_of(entry: Path) -> Path:
    (bank,) = [p for p in entry.iterdir() if p.name.startswith("bank-")]
    return bank


def _tree(folder: Path):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """A cache made by a dub that was SIGKILLed while building its bank, then by a dub run to
    the end (which finds the leftovers of the killed one, and others planted beside them)."""
    tmp = tmp_path_factory.mktemp("cache")
    root = tmp / "cache"
    cmd = [sys.executable, "-m", "lipsync", "dub", str(VIDEO), "--audio", str(SHORT), "--text", str(SHORT_TEXT),
           "--cache", str(root), "-o", str(tmp / "first.mp4"), "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    seen = []
    deadline = time.monotonic() + 240
    try:
        while not seen and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
            for entry in root.glob("*") if root.is_dir() else []:
                seen = [p for p in entry.glob(".*partial-*") if p.is_dir() and any(p.iterdir())]
        if seen:
            proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    assert seen, "the dub finished before its bank's folder was seen being written"
    entry = _entry(root)
    left = _partials(entry)
    # planted: a killed run's leftovers under today's names and under round 4's doubled name,
    # and a running dub's (this process's: alive), which must stay
    legacy = entry / f"..bank-0123456789ab.partial-{DEAD}.partial-{DEAD}-abcd"
    legacy.mkdir()
    (legacy / "A.png").write_bytes(b"x" * 1000)
    (entry / f".track.npz.partial-{DEAD}-77aa").write_bytes(b"half a track")
    live = entry / f".bank-0123456789ab.partial-{os.getpid()}-beef"
    live.mkdir()
    run = _dub(VIDEO, "--audio", SHORT, "--text", SHORT_TEXT, "--cache", root, "-o", tmp / "second.mp4")
    assert run.returncode == 0, run.stderr
    after = _partials(entry)
    shutil.rmtree(live)
    return {"root": root, "entry": entry, "killed_left": left, "after": after, "live": live.name, "tmp": tmp}


# --------------------------------------------------------------------------- item 7: killed builds

def test_a_killed_bank_build_leaves_one_hidden_name_that_the_next_run_removes(cache):
    left = cache["killed_left"]
    assert left, "the kill left nothing to test with"
    for name in left:  # the bank's own staging name, not one nested inside another partial's
        assert name.count(".partial-") == 1 and not name.startswith(".."), left
    assert cache["after"] == [cache["live"]]  # dead runs' leftovers gone, the live one kept
    assert (_bank_of(cache["entry"]) / "bank.yaml").is_file()


# --------------------------------------------------------------------------- item 8: unwritable caches

def test_a_cache_that_is_a_file_is_exit_2_naming_it(cache, tmp_path):
    not_a_folder = tmp_path / "cache-file"
    not_a_folder.write_text("x")
    run = _dub(VIDEO, "--audio", SHORT, "--text", SHORT_TEXT, "--cache", not_a_folder, "-o", tmp_path / "o.mp4")
    assert run.returncode == 2, run.stderr
    assert str(not_a_folder) in run.stderr and "cache" in run.stderr and "Traceback" not in run.stderr
    assert sorted(os.listdir(tmp_path)) == ["cache-file"]


def test_a_read_only_cache_named_by_cache_is_exit_2_naming_it(cache, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(ro)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a read-only tmpfs here (root's permissions ignore chmod)")
    try:
        run = _dub(VIDEO, "--audio", SHORT, "--text", SHORT_TEXT, "--cache", ro, "-o", tmp_path / "o.mp4")
    finally:
        subprocess.run(["umount", str(ro)])
    assert run.returncode == 2, run.stderr
    assert f"{ro}: cannot write the cache" in run.stderr and "read-only" in run.stderr
    assert not (tmp_path / "o.mp4").exists()


def test_an_unwritable_default_cache_warns_and_dubs_without_caching(cache, tmp_path):
    home_cache = tmp_path / "xdg"
    home_cache.write_text("a file where the cache folder's parent should be")
    tmpdir = tmp_path / "tmp"
    tmpdir.mkdir()
    out = tmp_path / "o.mp4"
    bank = tmp_path / "bank"  # given, so that only the track goes to the run's own folder
    shutil.copytree(_bank_of(cache["entry"]), bank)
    run = _dub(VIDEO, "--audio", SHORT, "--text", SHORT_TEXT, "--bank", bank, "-o", out,
               env={"XDG_CACHE_HOME": str(home_cache), "TMPDIR": str(tmpdir)})
    assert run.returncode == 0, run.stderr
    assert "cannot write the cache" in run.stderr and "without a cache" in run.stderr
    assert str(home_cache) in run.stderr
    assert out.stat().st_size > 10_000
    assert os.listdir(tmpdir) == []  # the bank made for this run only is gone with it


def test_an_entry_that_is_a_file_is_a_miss(cache, tmp_path):
    root = tmp_path / "c"
    root.mkdir()
    entry = cache["entry"]
    (root / entry.name).write_text("not an entry")
    bank = tmp_path / "bank"
    shutil.copytree(_bank_of(entry), bank)
    run = _dub(VIDEO, "--audio", SHORT, "--text", SHORT_TEXT, "--bank", bank, "--cache", root, "-o", tmp_path / "o.mp4")
    assert run.returncode == 0, run.stderr
    assert (root / entry.name / "track.npz").is_file()


def test_an_entry_that_is_a_link_is_replaced_not_followed(cache, tmp_path):
    from lipsync.pipeline.cache import open_entry

    root, outside = tmp_path / "c", tmp_path / "outside"
    root.mkdir()
    outside.mkdir()
    (outside / "track.npz").write_bytes((cache["entry"] / "track.npz").read_bytes())
    (root / "0123abcd").symlink_to(outside, target_is_directory=True)
    e = open_entry("0123abcd", root)
    assert e.path == root / "0123abcd" and not e.path.is_symlink() and e.path.is_dir()
    assert os.listdir(e.path) == [] and os.listdir(outside) == ["track.npz"]


# --------------------------------------------------------------------------- item 9: damaged entries

def _copy_cache(cache, tmp_path) -> Path:
    root = tmp_path / "c"
    shutil.copytree(cache["root"], root, symlinks=True)
    return root


def test_a_track_with_nan_points_is_a_miss_and_is_made_again(cache, tmp_path):
    root = _copy_cache(cache, tmp_path)
    track = _entry(root) / "track.npz"
    with np.load(track) as z:
        parts = {k: z[k] for k in z.files}
    good = parts["points"].copy()
    parts["points"][5, 13] = np.nan
    np.savez(track, **parts)
    out = tmp_path / "o.mp4"
    assert main(["dub", str(VIDEO), "--audio", str(SHORT), "--text", str(SHORT_TEXT), "--cache", str(root),
                 "-o", str(out), "--quiet"]) == 0
    with np.load(track) as z:
        assert np.isfinite(z["points"][z["found"]]).all()
        assert np.allclose(z["points"], good, atol=1e-3, equal_nan=True)
    assert out.stat().st_size > 10_000


def test_a_track_that_is_a_link_is_not_followed(cache, tmp_path):
    root = _copy_cache(cache, tmp_path)
    entry = _entry(root)
    outside = tmp_path / "elsewhere.npz"
    shutil.move(entry / "track.npz", outside)
    before = outside.read_bytes()
    (entry / "track.npz").symlink_to(outside)
    assert main(["dub", str(VIDEO), "--audio", str(SHORT), "--text", str(SHORT_TEXT), "--cache", str(root),
                 "-o", str(tmp_path / "o.mp4"), "--quiet"]) == 0
    assert not (entry / "track.npz").is_symlink() and (entry / "track.npz").is_file()
    assert outside.read_bytes() == before


def test_a_bank_entry_linked_outside_is_remade_inside_and_its_target_untouched(cache, tmp_path):
    from lipsync.face.video import probe_video
    from lipsync.phonetics.phonemes import DEFAULT_MAP
    from lipsync.morphing.store import FlowStore
    from lipsync.pipeline.cache import load_bank
    from lipsync.pipeline.dubbing import bank_from_video, video_track

    root = _copy_cache(cache, tmp_path)
    entry = _entry(root)
    bank = _bank_of(entry)
    # one link to a broken bank (fails every run today, never remade), one to a valid bank
    # (today: loaded, and the flows of a new map written into it, outside the cache)
    broken, valid = tmp_path / "broken", tmp_path / "valid"
    shutil.copytree(bank, broken, symlinks=True)
    shutil.move(bank, valid)
    (broken / "bank.yaml").write_text("name: [broken\n")
    before = {p: _tree(p) for p in (broken, valid)}
    bank.symlink_to(broken, target_is_directory=True)
    assert load_bank(bank) is None and not bank.is_symlink() and not bank.exists()  # a miss: remade
    assert (broken / "bank.yaml").read_text() == "name: [broken\n"
    info = probe_video(VIDEO)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        track = video_track(VIDEO, info, entry=entry, quiet=True)
    # the valid one: the bank remade here is the one returned, and its flows go into it
    made = _relinked(bank, valid, lambda: bank_from_video(VIDEO, entry=entry, map=DEFAULT_MAP, track=track))
    assert made.path.resolve() == bank.resolve() and not bank.is_symlink() and (bank / "bank.yaml").is_file()
    assert FlowStore.for_bank(made).root.resolve().is_relative_to(entry.resolve())
    assert {p: _tree(p) for p in (broken, valid)} == before  # nothing written outside the cache


def _relinked(bank: Path, target: Path, make):
    if bank.is_dir() and not bank.is_symlink():
        shutil.rmtree(bank)
    bank.symlink_to(target, target_is_directory=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return make()


# --------------------------------------------------------------------------- item 3: full disks

@pytest.fixture
def small_disk(tmp_path):
    """A 6 MB file system (a tmpfs; the test is skipped where one cannot be mounted)."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=6m", "tmpfs", str(mnt)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    yield mnt
    for _ in range(50):  # ffmpeg may still be closing a file on it
        if subprocess.run(["umount", str(mnt)], capture_output=True).returncode == 0:
            break
        time.sleep(0.1)


def test_a_full_disk_is_exit_2_and_leaves_nothing(cache, small_disk):
    # the speech outlasts the video: its 75 frames (23 MB) are kept to play it backwards,
    # more than the 6 MB disk the output and the temporary folder are on
    out = small_disk / "o.mp4"
    run = _dub(VIDEO, "--audio", LONG, "--text", LONG_TEXT, "--cache", cache["root"], "-o", out,
               env={"TMPDIR": str(small_disk)})
    assert run.returncode == 2, (run.returncode, run.stderr)
    assert "Traceback" not in run.stderr and "disk" in run.stderr and str(small_disk) in run.stderr
    assert os.listdir(small_disk) == []


def test_an_output_on_a_full_disk_is_exit_2_naming_it_and_leaves_nothing(cache, small_disk, tmp_path):
    ballast = small_disk / "ballast"  # the disk as good as full: room for less than the output
    ballast.write_bytes(b"\0" * (6 * 2 ** 20 - 64 * 1024))
    out = small_disk / "o.mp4"
    tmpdir = tmp_path / "tmp"
    tmpdir.mkdir()
    run = _dub(VIDEO, "--audio", LONG, "--text", LONG_TEXT, "--cache", cache["root"], "-o", out,
               env={"TMPDIR": str(tmpdir)})
    assert run.returncode == 2, (run.returncode, run.stderr)
    assert f"{out}: cannot write: disk full" in run.stderr and "Traceback" not in run.stderr
    assert os.listdir(small_disk) == ["ballast"] and os.listdir(tmpdir) == []


def test_a_disk_too_small_for_the_kept_frames_is_refused_before_writing(cache, tmp_path, monkeypatch, capsys):
    # the same without a mount: the free-space probe says 10 MB; 75 frames of 360x288 are 23 MB
    from lipsync.pipeline import cache as dub_cache

    tmpdir = tmp_path / "tmp"
    tmpdir.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmpdir))
    monkeypatch.setattr("tempfile.tempdir", None)
    monkeypatch.setattr(dub_cache, "free_bytes", lambda folder: 10 << 20)
    out = tmp_path / "out" / "o.mp4"
    code = main(["dub", str(VIDEO), "--audio", str(LONG), "--text", str(LONG_TEXT), "--cache", str(cache["root"]),
                 "-o", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert f"{tmpdir}: not enough free space" in err and "22 MB needed" in err  # 75 x 360x288x3 bytes
    assert os.listdir(tmpdir) == [] and (not out.parent.exists() or os.listdir(out.parent) == [])


def test_a_write_failing_with_enospc_is_exit_2_and_leaves_nothing(cache, tmp_path, monkeypatch, capsys):
    from lipsync.encode import base

    real = base.write_all
    calls = []

    def fills_up(stream, data):
        calls.append(1)
        if len(calls) > 20:
            raise OSError(errno.ENOSPC, "No space left on device")
        real(stream, data)

    tmpdir = tmp_path / "tmp"
    tmpdir.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmpdir))
    monkeypatch.setattr("tempfile.tempdir", None)
    monkeypatch.setattr(base, "write_all", fills_up)
    out = tmp_path / "out" / "o.mp4"
    code = main(["dub", str(VIDEO), "--audio", str(LONG), "--text", str(LONG_TEXT), "--cache", str(cache["root"]),
                 "-o", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert f"{out}: cannot write: disk full" in err
    assert os.listdir(out.parent) == [] and os.listdir(tmpdir) == []


# --------------------------------------------------------------------------- item 11: variable frame rate

BITS, CELL = 7, 16


def _stamp(frame, i):
    f = frame.copy()
    for b in range(BITS):
        f[0:CELL, b * CELL:(b + 1) * CELL] = 255 if (i >> b) & 1 else 0
    return f


def _read_stamp(f):
    return sum(1 << b for b in range(BITS) if f[3:CELL - 3, b * CELL + 3:(b + 1) * CELL - 3].mean() > 128)


def test_a_variable_frame_rate_video_keeps_its_timing(cache, tmp_path):
    """The source: bbwm5s's 75 frames at 25 fps, each stamped with its number, of which the
    second second keeps only every third (8.3 fps), each kept frame at its own time. At every
    output time t the dub must show the frame the source shows at t."""
    from lipsync.encode.ffmpeg import ffmpeg_exe
    from lipsync.face.video import probe_video, read_video

    frames = list(read_video(VIDEO))
    h, w = frames[0].shape[:2]
    kept = [i for i in range(len(frames)) if i < 25 or i >= 50 or i % 3 == 0]
    vfr = tmp_path / "vfr.mp4"
    subprocess.run([ffmpeg_exe(), "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}",
                    "-framerate", "25", "-i", "pipe:0", "-vf", r"select='lt(n\,25)+gte(n\,50)+not(mod(n\,3))'",
                    "-fps_mode", "passthrough", "-c:v", "libx264", "-crf", "12", "-pix_fmt", "yuv420p", str(vfr)],
                   input=b"".join(_stamp(f, i).tobytes() for i, f in enumerate(frames)), check=True)
    bank = tmp_path / "bank"
    shutil.copytree(_bank_of(cache["entry"]), bank)
    out = tmp_path / "o.mp4"
    run = _dub(vfr, "--audio", SHORT, "--text", SHORT_TEXT, "--bank", bank, "--cache", tmp_path / "c", "-o", out)
    assert run.returncode == 0, run.stderr
    assert "variable frame rate" in run.stderr and "25 fps" in run.stderr
    rate = probe_video(out).fps
    shown = [_read_stamp(f) for f in read_video(out)]
    assert rate == pytest.approx(25.0, abs=0.01) and len(shown) == pytest.approx(2.97 * rate, abs=1.5)
    expected = [max(i for i in kept if i / 25.0 <= k / rate + 1e-6) for k in range(len(shown))]
    assert shown == expected
