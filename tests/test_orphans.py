"""Worker processes end with their parent (issue 19, item 6).

Each command runs in a subprocess whose environment carries a unique tag (inherited by
every process it starts); once it has started its workers, only the command's own process
is killed with SIGKILL (what an OOM killer or ``kill -9`` does: no handler runs). Within a
few seconds no process with the tag may be left: no worker decoding on, none waiting on a
queue nobody fills, no resource tracker.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import uuid
import wave
from pathlib import Path

import psutil
import pytest

import synthetic

ROOT = Path(__file__).resolve().parents[1]
#: How long the orphans may take to notice (the batch host gives its nannies 5 s to stop
#: their workers before it exits anyway).
GONE_WITHIN_S = 20


def tagged(tag: str):
    out = []
    for q in psutil.process_iter():
        try:
            if q.environ().get("LIPSYNC_TEST_TAG") == tag:
                out.append(q)
        except (psutil.AccessDenied, psutil.NoSuchProcess, psutil.ZombieProcess):
            pass
    return out


def start(args, tag, cwd, **kw):
    return subprocess.Popen([sys.executable, "-m", "lipsync", *args], env=dict(os.environ, LIPSYNC_TEST_TAG=tag), cwd=cwd,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, **kw)


def kill_main_then_expect_no_orphans(p: subprocess.Popen, tag: str) -> None:
    p.kill()  # SIGKILL to the command's process only, not its group
    p.wait(30)
    deadline = time.monotonic() + GONE_WITHIN_S
    left = tagged(tag)
    while left and time.monotonic() < deadline:
        time.sleep(0.2)
        left = tagged(tag)
    for q in left:  # do not leave them to the rest of the suite either
        q.kill()
    assert not left, f"left running after their parent was killed: {[(q.pid, q.cmdline()) for q in left]}"


def wait_for(cond, p, timeout=180):
    deadline = time.monotonic() + timeout
    while not cond():
        assert p.poll() is None, p.stderr.read()[-2000:]
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def test_align_workers_end_with_their_parent(tmp_path):
    # 36 s of speech without a transcript: recognised in 15 s chunks by forked workers.
    with wave.open(str(ROOT / "samples" / "hello.wav")) as w:
        params, frames = w.getparams(), w.readframes(w.getnframes())
    with wave.open(str(tmp_path / "long.wav"), "wb") as w:
        w.setparams(params)
        w.writeframes(frames * 12)
    tag = uuid.uuid4().hex
    p = start(["align", str(tmp_path / "long.wav"), "-o", str(tmp_path / "out.TextGrid"), "--quiet"], tag, tmp_path)
    try:
        main = psutil.Process(p.pid)

        def decoding_workers():  # forked children (not ffmpeg reading the audio), well into a chunk
            try:
                return [c for c in main.children() if c.cmdline() == main.cmdline() and c.cpu_times().user > 0.3]
            except psutil.NoSuchProcess:
                return []

        wait_for(lambda: len(decoding_workers()) >= 2, p)
    finally:
        kill_main_then_expect_no_orphans(p, tag)


def test_preprocess_leaves_nothing_running_when_killed(tmp_path):
    bank = synthetic.write_bank(tmp_path / "bank", synthetic.RHUBARB_SHAPES)
    store = tmp_path / "store"
    tag = uuid.uuid4().hex
    p = start(["preprocess", str(bank), "--jobs", "2", "--quiet", "--store", str(store)], tag, tmp_path)
    try:
        wait_for(lambda: len(list(store.glob("flows/*.flow"))) >= 2, p)
    finally:
        kill_main_then_expect_no_orphans(p, tag)


@pytest.mark.slow
def test_batch_workers_end_with_their_parent(tmp_path):
    bank = synthetic.write_bank(tmp_path / "bank", synthetic.RHUBARB_SHAPES)
    rows = []
    for i in range(8):
        (tmp_path / f"c{i}.tsv").write_text("0.00\tX\n0.30\tD\n0.62\tB\n1.00\tA\n" + f"{1.6 + 0.1 * i:.2f}\tX\n")
        rows.append(json.dumps({"input": f"c{i}.tsv", "output": f"c{i}.mp4", "bank": str(bank)}))
    (tmp_path / "m.jsonl").write_text("\n".join(rows) + "\n")
    out = tmp_path / "out"
    tag = uuid.uuid4().hex
    p = start(["batch", str(tmp_path / "m.jsonl"), "-o", str(out), "--workers", "2", "--cache",
               str(tmp_path / "cache"), "--quiet"], tag, tmp_path)
    try:
        wait_for(lambda: list(out.glob("*.lipsync.json")), p)
        assert len(tagged(tag)) >= 4  # this command, the nannies' host and two workers
    finally:
        kill_main_then_expect_no_orphans(p, tag)
