"""What a terminated or killed lipsync leaves behind (issue 19, item 6).

* SIGTERM (what ``kill``, systemd and ``docker stop`` send) is handled as Ctrl-C is: ``lipsync
  serve`` removes its job folder (uploads and outputs) and exits cleanly, ``lipsync render``
  removes its partial output and exits 143;
* a SIGKILL, which no handler sees, leaves ``.OUT.partial-PID.*`` beside OUT: the next write
  of that OUT removes the partials of processes that no longer exist (and never those of a
  running one).

(Worker processes ending with their parent: tests/test_orphans.py.)
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from lipsync._files import atomic_write_bytes, remove_stale_partials

ROOT = Path(__file__).resolve().parents[1]
HELLO = ROOT / "samples" / "hello.phn"


def _wait(cond, timeout=120):
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def test_sigterm_to_serve_removes_its_job_folder(tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    p = subprocess.Popen([sys.executable, "-m", "lipsync", "serve", "--port", "0", "--method", "dissolve"],
                         env=dict(os.environ, TMPDIR=str(tmp)), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, cwd=tmp_path)
    try:
        line = p.stdout.readline()
        assert "open http://127.0.0.1:" in line, line + p.stderr.read()
        url = line.split()[-1]
        base, query = url.split("?")
        r = httpx.post(base.rstrip("/") + "/api/render?" + query + "&name=hello.phn", content=HELLO.read_bytes())
        assert r.status_code == 202
        job = r.json()["job"]
        _wait(lambda: httpx.get(base.rstrip("/") + f"/api/jobs/{job}?" + query).json()["state"] == "done")
        folders = list(tmp.glob("lipsync-serve-*"))
        assert len(folders) == 1 and (folders[0] / job / "out.mp4").is_file()
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err  # a clean stop, as after Ctrl-C
    assert "Traceback" not in err
    assert list(tmp.iterdir()) == [], list(tmp.rglob("*"))


def test_sigterm_to_render_leaves_no_partial_output(tmp_path):
    # A long clip (slow x264 settings) so that the signal lands mid-encode.
    long = tmp_path / "long.phn"
    long.write_text("".join(f"{i * 8000} {(i + 1) * 8000} {'aa' if i % 2 else 'm'}\n" for i in range(400)))
    out = tmp_path / "out" / "talk.mp4"
    p = subprocess.Popen([sys.executable, "-m", "lipsync", "render", str(long), "-o", str(out), "--quiet",
                          "--method", "dissolve", "--preset", "veryslow"], stderr=subprocess.PIPE, text=True)
    try:
        _wait(lambda: any(n.startswith(".talk.mp4.partial-") for n in os.listdir(out.parent))
              if out.parent.is_dir() else False)
        time.sleep(0.5)
        p.send_signal(signal.SIGTERM)
        err = p.communicate(timeout=60)[1]
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 143, err
    assert "terminated" in err and "Traceback" not in err
    assert os.listdir(out.parent) == []


def test_partials_of_killed_renders_are_removed_by_the_next_one(tmp_path):
    out = tmp_path / "talk.mp4"
    dead = 2**22 + 7  # no Linux process has this id (pids stop at 2**22)
    left = [tmp_path / f".talk.mp4.partial-{dead}.mp4", tmp_path / f".talk.mp4.video-{dead}.mp4"]
    for f in left:
        f.write_bytes(b"half a video")
    frames = tmp_path / f".talk.mp4.partial-{dead}-x"
    frames.mkdir()
    (frames / "frame_000000.png").write_bytes(b"x")
    alive = tmp_path / f".talk.mp4.partial-{os.getppid()}.mp4"   # a running process's: kept
    alive.write_bytes(b"being written")
    other = tmp_path / f".other.mp4.partial-{dead}.mp4"          # another OUT's: not ours to judge now
    other.write_bytes(b"x")
    result = subprocess.run([sys.executable, "-m", "lipsync", "render", str(HELLO), "-o", str(out), "--quiet",
                             "--method", "dissolve"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert sorted(os.listdir(tmp_path)) == sorted([alive.name, other.name, "talk.mp4"])
    # PNG sequences, cue files and every other atomic write do the same
    seq = tmp_path / "frames"
    (tmp_path / f".frames.partial-{dead}").mkdir()
    result = subprocess.run([sys.executable, "-m", "lipsync", "render", str(HELLO), "-o", str(seq) + os.sep,
                             "--quiet", "--method", "dissolve"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert not (tmp_path / f".frames.partial-{dead}").exists()
    cues = tmp_path / "cues.tsv"
    (tmp_path / f".cues.tsv.partial-{dead}-abcd").write_text("x")
    atomic_write_bytes(cues, lambda fh: fh.write(b"0.000\tX\n"))
    assert not (tmp_path / f".cues.tsv.partial-{dead}-abcd").exists() and cues.read_bytes() == b"0.000\tX\n"


def test_remove_stale_partials_touches_nothing_else(tmp_path):
    out = tmp_path / "a.mp4"
    dead = 2**22 + 7
    names = ["a.mp4", ".a.mp4.partial-x.mp4", f".a.mp4.partialx-{dead}.mp4", f"a.mp4.partial-{dead}",
             f".b.a.mp4.partial-{dead}", f".a.mp4.partial-{os.getpid()}.mp4", f".a.mp4.other-{dead}.mp4",
             f".a.mp4.partial-{dead}x", f".aa.mp4.partial-{dead}"]
    for n in names:
        (tmp_path / n).write_text("x")
    assert remove_stale_partials(out, tags=("partial", "video")) == []
    assert sorted(os.listdir(tmp_path)) == sorted(names)
