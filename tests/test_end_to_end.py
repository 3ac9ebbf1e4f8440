"""``lipsync render`` end to end: decode the mp4 and check what it shows, and when."""

import subprocess
import sys
import wave

import numpy as np
import pytest

import synthetic
from lipsync import Animator, Bank, Segment, Timeline
from lipsync.encode import probe

FPS = 25
# A literal viseme timeline (Rhubarb TSV: start<TAB>shape): holds of >= 200 ms and quick ones.
CUES = [(0.00, "X"), (0.30, "D"), (0.62, "B"), (0.70, "F"), (1.00, "A"), (1.08, "C"), (1.40, "E"),
        (1.70, "X")]
END = 2.0


@pytest.fixture(scope="module")
def rhubarb_bank(tmp_path_factory):
    return synthetic.write_bank(tmp_path_factory.mktemp("e2e") / "bank", synthetic.RHUBARB_SHAPES)


def write_wav(path, seconds, rate=16000):
    t = np.arange(int(seconds * rate)) / rate
    samples = (0.3 * np.sin(2 * np.pi * 220 * t) * 32767).astype("<i2")
    with wave.open(str(path), "wb") as wf:
        wf.setnchannels(1)
        wf.setsampwidth(2)
        wf.setframerate(rate)
        wf.writeframes(samples.tobytes())


def decode(path):
    import imageio_ffmpeg

    gen = imageio_ffmpeg.read_frames(str(path))
    meta = next(gen)
    w, h = meta["size"]
    return np.stack([np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in gen])


def test_render_mp4_shows_each_long_viseme_at_its_midpoint(rhubarb_bank, tmp_path):
    tsv = tmp_path / "cues.tsv"
    tsv.write_text("".join(f"{t:.2f}\t{v}\n" for t, v in CUES) + f"{END:.2f}\tX\n")
    wav = tmp_path / "speech.wav"
    write_wav(wav, END + 0.37)  # longer than the timeline: cut to the video's length
    out = tmp_path / "out.mp4"
    r = subprocess.run([sys.executable, "-m", "lipsync", "render", str(tsv), "--bank", str(rhubarb_bank),
                        "--audio", str(wav), "--fps", str(FPS), "-o", str(out), "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    info = probe(out)
    n = int(np.ceil(END * FPS))
    assert info["n_frames"] == n
    assert info["streams"] == [("video", "h264"), ("audio", "aac")]
    assert abs(info["audio_duration"] - info["video_duration"]) <= 1 / FPS
    frames = decode(out)
    assert len(frames) == n
    bank = Bank.load(rhubarb_bank)
    refs = {v: bank.images[v].astype(np.float32) for v in bank.names}
    ends = [t for t, _ in CUES[1:]] + [END]
    checked = 0
    for (start, viseme), end in zip(CUES, ends):
        if end - start < 0.2:
            continue
        frame = frames[int(round((start + end) / 2 * FPS))].astype(np.float32)
        dist = {v: float(np.mean((frame - ref) ** 2)) for v, ref in refs.items()}
        assert min(dist, key=dist.get) == viseme, (start, viseme, sorted(dist.items(), key=lambda kv: kv[1])[:3])
        checked += 1
    assert checked == 6


def test_png_sequence_output(rhubarb_bank, tmp_path):
    tsv = tmp_path / "cues.tsv"
    tsv.write_text("0.00\tX\n0.30\tD\n0.60\tX\n")
    out = tmp_path / "frames"
    r = subprocess.run([sys.executable, "-m", "lipsync", "render", str(tsv), "--bank", str(rhubarb_bank),
                        "--fps", "10", "--format", "png", "-o", str(out), "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    pngs = sorted(out.glob("*.png"))
    assert len(pngs) == 6
    import cv2

    mid = cv2.cvtColor(cv2.imread(str(pngs[4])), cv2.COLOR_BGR2RGB)  # t = 0.4 s, inside the D hold
    np.testing.assert_array_equal(mid, Bank.load(rhubarb_bank).images["D"])


def test_animator_random_access_matches_the_stream(rhubarb_bank):
    bank = Bank.load(rhubarb_bank)
    tl = Timeline((Segment(0.0, 0.25, "M"), Segment(0.25, 0.6, "AA"), Segment(0.6, 0.9, "UW")), kind="phoneme")
    anim = Animator(bank, tl, fps=FPS)
    stream = list(anim.frames())
    assert len(stream) == len(anim) == int(np.ceil(0.9 * FPS))
    for i in (0, 5, 9, 13, len(anim) - 1):
        np.testing.assert_array_equal(anim.frame_at(i / FPS + 0.001), stream[i])
    # the AA segment is long: its midpoint shows D (AA -> D in the default map) exactly
    np.testing.assert_array_equal(anim.frame_at(0.425), bank.images["D"])


def test_parallel_png_render_equals_the_serial_frames_in_order(rhubarb_bank, tmp_path):
    # render_clip renders on worker threads; the written sequence must be the animator's
    # frames in order, bit for bit (PNG is lossless).
    import cv2

    from lipsync.pipeline.clip import render_clip

    tsv = tmp_path / "cues.tsv"
    tsv.write_text("".join(f"{t:.2f}\t{v}\n" for t, v in CUES))
    report = render_clip(tsv, tmp_path / "frames", bank=rhubarb_bank, fps=FPS, format="png", quiet=True)
    serial = list(Animator(Bank.load(rhubarb_bank), tsv, fps=FPS).frames())
    pngs = sorted((tmp_path / "frames").glob("*.png"))
    assert report.frames == len(pngs) == len(serial) > 40
    for i, p in enumerate(pngs):
        np.testing.assert_array_equal(cv2.cvtColor(cv2.imread(str(p)), cv2.COLOR_BGR2RGB), serial[i])


def test_render_parallel_keeps_order_and_stops_on_errors():
    import random
    import time

    from lipsync.pipeline.clip import render_parallel

    def render_into(i, buf):
        time.sleep(random.random() * 0.005)  # finish out of order
        buf[:] = i

    got = []
    render_parallel(render_into, 50, (2, 2, 3), lambda b: got.append(int(b[0, 0, 0])), threads=4)
    assert got == list(range(50))

    def failing(i, buf):
        if i == 7:
            raise RuntimeError("frame 7 broke")
        buf[:] = i

    written = []
    with pytest.raises(RuntimeError, match="frame 7 broke"):
        render_parallel(failing, 50, (2, 2, 3), lambda b: written.append(int(b[0, 0, 0])), threads=3)
    assert written == list(range(7))


def test_render_parallel_renders_a_held_frame_once_and_prepares_on_the_workers():
    import random
    import threading
    import time

    from lipsync.pipeline.clip import render_parallel

    # frames 0..59 show value i // 4 (each held for 4 frames), except a run of 9 equal ones
    values = [i // 4 for i in range(60)]
    values[20:29] = [99] * 9
    rendered, prepared_on = [], set()

    def render_into(i, buf):
        time.sleep(random.random() * 0.003)
        rendered.append(i)
        buf[:] = values[i]

    def prepare(buf, previous):
        prepared_on.add(threading.current_thread().name)
        out = previous if previous is not None else np.empty(1, np.int64)
        out[0] = int(buf[0, 0, 0]) + 1000   # the writer gets the prepared value, not the frame
        return out

    for threads in (1, 3):
        rendered.clear()
        got = []
        render_parallel(render_into, 60, (2, 2, 3), lambda p: got.append(int(p[0])), threads=threads,
                        prepare=prepare, same_as_previous=lambda i: values[i] == values[i - 1])
        assert got == [v + 1000 for v in values]
        fresh = [i for i in range(60) if i == 0 or values[i] != values[i - 1]]
        assert sorted(rendered) == fresh          # each distinct frame rendered once
    assert all(name.startswith("lipsync-render") for name in prepared_on)


def test_a_damaged_flow_entry_is_recomputed_during_render(rhubarb_bank, tmp_path):
    import shutil

    from lipsync.pipeline.clip import render_clip
    from lipsync.morphing.store import StoreWarning

    bank_dir = tmp_path / "bank"
    shutil.copytree(rhubarb_bank, bank_dir, ignore=shutil.ignore_patterns(".lipsync"))
    tsv = tmp_path / "cues.tsv"
    tsv.write_text("".join(f"{t:.2f}\t{v}\n" for t, v in CUES))
    first = render_clip(tsv, tmp_path / "a", bank=bank_dir, fps=FPS, format="png", quiet=True, jobs=1)
    entries = sorted((bank_dir / ".lipsync" / "flows").glob("*.flow"))
    for p in entries:  # cut every entry: all present, all broken
        p.write_bytes(p.read_bytes()[:100])
    with pytest.warns(StoreWarning, match="unusable flow store entry"):
        second = render_clip(tsv, tmp_path / "b", bank=bank_dir, fps=FPS, format="png", quiet=True)
    assert first.frames == second.frames
    for a, b in zip(sorted((tmp_path / "a").glob("*.png")), sorted((tmp_path / "b").glob("*.png"))):
        assert a.read_bytes() == b.read_bytes()


@pytest.mark.parametrize("cores, threads", [(2, "1"), (8, None)])
def test_render_clip_encodes_on_one_x264_thread_on_two_cores(rhubarb_bank, tmp_path, monkeypatch, cores, threads):
    # On <= 2 cores the render threads fill the machine; x264 gets one thread (lipsync.pipeline.clip).
    from lipsync.pipeline import clip
    from test_encode import x264_options

    monkeypatch.setattr(clip.os, "cpu_count", lambda: cores)
    tsv = tmp_path / "cues.tsv"
    tsv.write_text("".join(f"{t:.2f}\t{v}\n" for t, v in CUES))
    out = tmp_path / "a.mp4"
    clip.render_clip(tsv, out, bank=rhubarb_bank, fps=FPS, quiet=True)
    opts = x264_options(out)
    assert opts["bframes"] == "3" and opts["mbtree"] == "1"  # the default preset, talking-head
    if threads is None:
        assert opts["threads"] != "1"
    else:
        assert opts["threads"] == threads
