"""Encoder tests: round trips decoded by ffmpeg, audio sync, and clean failures."""

from __future__ import annotations

import errno
import math
import os
import signal
import stat
import struct
import subprocess
import wave

import cv2
import imageio_ffmpeg
import numpy as np
import pytest

from lipsync import encode
from lipsync.encode import ENCODERS, EncodeError, format_for, open_writer, probe
from lipsync.errors import InputError, UnknownNameError

W, H = 64, 48
FPS = 25


def colour_frames(n, w=W, h=H):
    """Frame i is one flat colour, all different and away from the range limits."""
    rng = np.random.default_rng(7)
    colours = rng.integers(30, 226, size=(n, 3)).astype(np.uint8)
    return colours, [np.broadcast_to(c, (h, w, 3)).copy() for c in colours]


def square_frame(i, w=W, h=H, side=12):
    """A white square on grey moving 3 px right per frame; returns the frame and its centre."""
    frame = np.full((h, w, 3), 60, np.uint8)
    x0, y0 = 4 + 3 * i, 10
    frame[y0:y0 + side, x0:x0 + side] = 230
    return frame, (x0 + (side - 1) / 2, y0 + (side - 1) / 2)


def decode(path):
    """All frames of a video as RGB arrays, decoded by ffmpeg independently of the writer."""
    gen = imageio_ffmpeg.read_frames(str(path))
    meta = next(gen)
    w, h = meta["size"]
    return [np.frombuffer(buf, np.uint8).reshape(h, w, 3) for buf in gen]


def decode_audio(path, rate=48000):
    """The first audio stream as mono float samples in [-1, 1]."""
    out = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(path), "-map", "0:a:0",
                          "-ac", "1", "-ar", str(rate), "-f", "s16le", "-"], capture_output=True, check=True)
    return np.frombuffer(out.stdout, "<i2").astype(np.float64) / 32768.0


def write_wav(path, seconds, *, rate=44100, freq=440.0, silence_before=0.0):
    """A mono 16-bit sine of exactly round(seconds*rate) samples, after optional silence."""
    n = int(round(seconds * rate))
    lead = int(round(silence_before * rate))
    t = np.arange(n - lead) / rate
    samples = np.concatenate([np.zeros(lead), 0.5 * np.sin(2 * math.pi * freq * t)])
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes((samples * 32767).astype("<i2").tobytes())
    return path


def leftovers(folder, *expected):
    """Everything in ``folder`` (hidden temp files included) except the names given."""
    return sorted(set(os.listdir(folder)) - set(expected))


# -- format choice ---------------------------------------------------------------------------

def test_registry_names_and_format_choice(tmp_path):
    assert ENCODERS.names() == ["mp4", "png", "webm", "mov", "qtrle", "webp", "gif"]
    assert format_for(tmp_path / "a.mp4") == "mp4"
    assert format_for(tmp_path / "a.MKV") == "mp4"
    assert format_for(tmp_path / "a.mov") == "mov"  # ProRes 4444 since issue 18 (H.264: format="mp4")
    assert format_for(str(tmp_path / "seq") + os.sep) == "png"
    (tmp_path / "existing").mkdir()
    assert format_for(tmp_path / "existing") == "png"
    with pytest.raises(UnknownNameError) as err:
        format_for(tmp_path / "a.avi")
    assert "mp4" in str(err.value) and "png" in str(err.value) and "a.avi" in str(err.value)
    with pytest.raises(UnknownNameError) as err:
        open_writer(tmp_path / "a.mp4", fps=FPS, size=(W, H), format="tiff")
    assert "'tiff'" in str(err.value) and "mp4, png" in str(err.value)
    assert leftovers(tmp_path, "existing") == []


# -- mp4 round trips -------------------------------------------------------------------------

def test_mp4_round_trip_colours_count_and_size(tmp_path):
    out = tmp_path / "clip.mp4"
    colours, frames = colour_frames(12)
    with open_writer(out, fps=FPS, size=(W, H), quiet=True) as w:
        for f in frames:
            w.write(f)
    assert w.n_frames == 12
    decoded = decode(out)
    assert len(decoded) == 12
    assert decoded[0].shape == (H, W, 3)
    means = np.array([d.reshape(-1, 3).mean(0) for d in decoded])
    # Flat colours survive 4:2:0 + crf 18 within a few levels (matrix rounding + quantiser).
    assert np.abs(means - colours).max() < 4.0
    # Each decoded frame is closest to its own colour: no frame dropped, duplicated or reordered.
    dist = np.abs(means[:, None, :] - colours[None, :, :]).sum(-1)
    assert list(dist.argmin(1)) == list(range(12))
    info = probe(out)
    assert info["streams"] == [("video", "h264")]
    assert (info["n_frames"], info["width"], info["height"], info["fps"]) == (12, W, H, 25.0)
    assert info["video_duration"] == pytest.approx(12 / FPS)
    assert leftovers(tmp_path, "clip.mp4") == []


def test_mp4_moving_square_keeps_geometry(tmp_path):
    out = tmp_path / "square.mp4"
    expected = []
    with open_writer(out, fps=FPS, size=(W, H), quiet=True) as w:
        for i in range(8):
            frame, centre = square_frame(i)
            expected.append(centre)
            w.write(frame)
    decoded = decode(out)
    assert len(decoded) == 8
    for d, (cx, cy) in zip(decoded, expected):
        ys, xs = np.nonzero(d[:, :, 1] > 145)
        assert xs.mean() == pytest.approx(cx, abs=0.5)
        assert ys.mean() == pytest.approx(cy, abs=0.5)


def test_mp4_odd_size_is_padded_by_repeating_the_edge(tmp_path):
    out = tmp_path / "odd.mp4"
    w_odd, h_odd = 33, 21
    frame = np.zeros((h_odd, w_odd, 3), np.uint8)
    frame[:, :, 0] = np.linspace(40, 200, w_odd).astype(np.uint8)[None, :]  # red ramp left to right
    frame[:, :, 2] = np.linspace(40, 200, h_odd).astype(np.uint8)[:, None]  # blue ramp top to bottom
    with open_writer(out, fps=FPS, size=(w_odd, h_odd), quiet=True) as w:
        for _ in range(3):
            w.write(frame)
    info = probe(out)
    assert (info["width"], info["height"]) == (34, 22)
    d = decode(out)[1].astype(int)
    reference = np.pad(frame, ((0, 1), (0, 1), (0, 0)), mode="edge").astype(int)
    assert np.abs(d - reference).mean() < 3.0
    # The added column/row repeats the edge rather than being black.
    assert d[:, -1, 0].mean() == pytest.approx(200, abs=6)
    assert d[-1, :, 2].mean() == pytest.approx(200, abs=6)


def test_other_containers(tmp_path):
    for name in ("clip.mkv", "clip.mov"):
        _, frames = colour_frames(5)
        with open_writer(tmp_path / name, fps=FPS, size=(W, H), quiet=True, format="mp4") as w:
            for f in frames:
                w.write(f)
        assert probe(tmp_path / name)["n_frames"] == 5
        assert probe(tmp_path / name)["video_codec"] == "h264"
        assert len(decode(tmp_path / name)) == 5
    assert leftovers(tmp_path, "clip.mkv", "clip.mov") == []


# -- audio -----------------------------------------------------------------------------------

@pytest.mark.parametrize("announced", [False, True], ids=["two-pass", "one-process"])
@pytest.mark.parametrize("audio_seconds", [0.52, 1.73])
def test_audio_is_aac_and_matches_video_duration(tmp_path, audio_seconds, announced):
    n = 25  # exactly 1 s of video: shorter than one wav, longer than the other
    wav = write_wav(tmp_path / "speech.wav", audio_seconds)
    out = tmp_path / "talk.mp4"
    _, frames = colour_frames(n)
    with open_writer(out, fps=FPS, size=(W, H), audio=wav, quiet=True, frames=n if announced else None) as w:
        for f in frames:
            w.write(f)
    info = probe(out)
    assert info["streams"] == [("video", "h264"), ("audio", "aac")]
    assert info["n_frames"] == n
    assert info["video_duration"] == pytest.approx(1.0)
    assert abs(info["audio_duration"] - n / FPS) <= 1 / FPS
    samples = decode_audio(out)
    rms = lambda a: float(np.sqrt(np.mean(a ** 2)))  # noqa: E731
    # Where the wav had sound, the output has it (sine of amplitude 0.5: rms 0.354) ...
    end_of_sound = min(audio_seconds, 1.0)
    assert rms(samples[int(0.1 * 48000):int((end_of_sound - 0.05) * 48000)]) == pytest.approx(0.354, abs=0.03)
    if audio_seconds < 1.0:
        # ... and the padding after a short wav is silence.
        assert rms(samples[int((audio_seconds + 0.05) * 48000):int(0.95 * 48000)]) < 0.01
    assert leftovers(tmp_path, "speech.wav", "talk.mp4") == []


@pytest.mark.parametrize("announced", [False, True], ids=["two-pass", "one-process"])
def test_audio_starts_at_the_first_frame(tmp_path, announced):
    # 0.4 s of silence then a tone: the onset must land at 0.4 s in the output (no AAC
    # priming delay, no offset), i.e. the first video frame is t = 0 of the audio.
    wav = write_wav(tmp_path / "onset.wav", 1.2, silence_before=0.4, rate=48000)
    out = tmp_path / "onset.mp4"
    _, frames = colour_frames(30)
    with open_writer(out, fps=FPS, size=(W, H), audio=wav, quiet=True, frames=30 if announced else None) as w:
        for f in frames:
            w.write(f)
    samples = decode_audio(out)
    onset = np.argmax(np.abs(samples) > 0.1) / 48000
    assert onset == pytest.approx(0.4, abs=0.005)


def test_announced_frame_count_runs_one_ffmpeg_and_is_enforced(tmp_path, monkeypatch):
    started = []
    real_popen = encode.ffmpeg.popen
    monkeypatch.setattr(encode.ffmpeg, "popen", lambda cmd, **kw: started.append(cmd) or real_popen(cmd, **kw))
    wav = write_wav(tmp_path / "a.wav", 0.7)
    _, frames = colour_frames(20)
    with open_writer(tmp_path / "one.mp4", fps=FPS, size=(W, H), audio=wav, quiet=True, frames=20) as w:
        for f in frames:
            w.write(f)
    assert len(started) == 1 and f"file:{wav}" in started[0]  # opened as a plain file (lipsync._media)
    assert probe(tmp_path / "one.mp4")["streams"] == [("video", "h264"), ("audio", "aac")]
    # fewer frames than announced: an error, and nothing left behind
    with pytest.raises(EncodeError, match="19 frames were written, 20 were announced"):
        with open_writer(tmp_path / "short.mp4", fps=FPS, size=(W, H), audio=wav, quiet=True, frames=20) as w:
            for f in frames[:19]:
                w.write(f)
    assert leftovers(tmp_path, "a.wav", "one.mp4") == []


def test_missing_or_unreadable_audio_is_input_error_before_any_work(tmp_path):
    out = tmp_path / "x.mp4"
    with pytest.raises(InputError) as err:
        open_writer(out, fps=FPS, size=(W, H), audio=tmp_path / "nope.wav")
    assert "nope.wav" in str(err.value)
    junk = tmp_path / "junk.wav"
    junk.write_bytes(b"this is not audio at all\n" * 10)
    with pytest.raises(InputError) as err:
        open_writer(out, fps=FPS, size=(W, H), audio=junk)
    assert "junk.wav" in str(err.value)
    assert leftovers(tmp_path, "junk.wav") == []


# -- png sequences ---------------------------------------------------------------------------

def test_png_sequence_round_trip_is_exact(tmp_path):
    out = str(tmp_path / "seq") + os.sep
    rng = np.random.default_rng(3)
    frames = [rng.integers(0, 256, (H, W, 3), dtype=np.uint8) for _ in range(5)]
    with open_writer(out, fps=FPS, size=(W, H), quiet=True) as w:
        for f in frames:
            w.write(f)
    names = sorted(os.listdir(tmp_path / "seq"))
    assert names == [f"frame_{i:06d}.png" for i in range(5)]
    for name, f in zip(names, frames):
        back = cv2.imread(str(tmp_path / "seq" / name), cv2.IMREAD_UNCHANGED)[:, :, ::-1]
        assert np.array_equal(back, f)
    assert leftovers(tmp_path, "seq") == []


def test_png_replaces_an_older_longer_sequence_and_refuses_foreign_files(tmp_path):
    seq = tmp_path / "seq"
    for n in (6, 2):  # the second, shorter run must not leave frames 2..5 of the first
        with open_writer(str(seq) + os.sep, fps=FPS, size=(W, H), quiet=True) as w:
            for i in range(n):
                w.write(np.full((H, W, 3), 10 * n, np.uint8))
    assert sorted(os.listdir(seq)) == ["frame_000000.png", "frame_000001.png"]
    assert cv2.imread(str(seq / "frame_000000.png"))[0, 0, 0] == 20

    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep me")
    with pytest.raises(FileExistsError) as err:
        open_writer(mine, fps=FPS, size=(W, H), quiet=True)
    assert "notes.txt" in str(err.value)
    assert (mine / "notes.txt").read_text() == "keep me"
    assert leftovers(tmp_path, "seq", "mine") == []


def test_png_failure_keeps_the_previous_sequence(tmp_path):
    seq = tmp_path / "seq"
    with open_writer(seq, fps=FPS, size=(W, H), format="png", quiet=True) as w:
        w.write(np.full((H, W, 3), 99, np.uint8))
    with pytest.raises(RuntimeError):
        with open_writer(seq, fps=FPS, size=(W, H), quiet=True) as w:
            w.write(np.full((H, W, 3), 1, np.uint8))
            raise RuntimeError("renderer bug")
    assert os.listdir(seq) == ["frame_000000.png"]
    assert cv2.imread(str(seq / "frame_000000.png"))[0, 0, 0] == 99
    assert leftovers(tmp_path, "seq") == []


# -- clean failures --------------------------------------------------------------------------

def fake_ffmpeg(tmp_path, body):
    script = tmp_path / "fake-ffmpeg"
    script.write_text("#!/bin/sh\n" + body + "\n")
    script.chmod(0o755)
    return str(script)


@pytest.mark.parametrize("n_frames", [2, 60])
def test_ffmpeg_failing_mid_stream_is_encode_error_and_leaves_nothing(tmp_path, monkeypatch, n_frames):
    # Reads 20 kB (about two frames) then dies: with 60 frames the pipe breaks while
    # writing; with 2 the failure is only seen from the exit status at close.
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    exe = fake_ffmpeg(tmp_path, 'head -c 20000 >/dev/null; echo "simulated encoder crash" >&2; exit 1')
    monkeypatch.setattr(encode.ffmpeg, "ffmpeg_exe", lambda: exe)
    _, frames = colour_frames(n_frames)
    with pytest.raises(EncodeError) as err:
        with open_writer(out_dir / "clip.mp4", fps=FPS, size=(W, H), quiet=True) as w:
            for f in frames:
                w.write(f)
    assert "simulated encoder crash" in str(err.value)
    assert err.value.path == str(out_dir / "clip.mp4")
    assert err.value.returncode == 1
    assert leftovers(out_dir) == []


def test_ffmpeg_killed_mid_stream(tmp_path):
    out = tmp_path / "clip.mp4"
    _, frames = colour_frames(40)
    with pytest.raises(EncodeError) as err:
        with open_writer(out, fps=FPS, size=(W, H), quiet=True) as w:
            for i, f in enumerate(frames):
                if i == 3:
                    proc = w._proc
                    proc.kill()
                    proc.wait()
                w.write(f)
    assert str(out) in str(err.value)
    assert leftovers(tmp_path) == []


def test_unwritable_output_folder_fails_before_any_work(tmp_path, monkeypatch):
    started = []
    monkeypatch.setattr(encode.ffmpeg, "popen", lambda *a, **k: started.append(a))
    # a missing folder is made, as every command's -o does (issue 19, item 8) ...
    with open_writer(tmp_path / "no" / "such" / "clip.mp4", fps=FPS, size=(W, H), quiet=True) as w:
        assert (tmp_path / "no" / "such").is_dir()
        w._abort()
    started.clear()
    # ... one that cannot be made is an error naming OUT, before ffmpeg starts
    (tmp_path / "ro").mkdir()
    os.chmod(tmp_path / "ro", 0o500)
    if os.access(tmp_path / "ro", os.W_OK):  # root: permissions are not enforced
        os.chmod(tmp_path / "ro", 0o700)
    else:
        with pytest.raises(PermissionError) as err:
            open_writer(tmp_path / "ro" / "sub" / "clip.mp4", fps=FPS, size=(W, H))
        assert str(tmp_path / "ro" / "sub" / "clip.mp4") in str(err.value)
    (tmp_path / "afile").write_text("x")
    with pytest.raises(NotADirectoryError):
        open_writer(tmp_path / "afile" / "clip.mp4", fps=FPS, size=(W, H))
    with pytest.raises(NotADirectoryError):
        open_writer(str(tmp_path / "afile" / "seq") + os.sep, fps=FPS, size=(W, H))
    assert started == []
    assert leftovers(tmp_path, "afile", "no", "ro") == [] and os.listdir(tmp_path / "no" / "such") == []


def test_read_only_folder(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        try:
            (ro / "probe").write_text("")
        except PermissionError:
            pass
        else:
            pytest.skip("permissions are not enforced for this user (root)")
        for out in (ro / "clip.mp4", ro / "seq"):
            with pytest.raises(PermissionError) as err:
                open_writer(out, fps=FPS, size=(W, H), format="png" if out.name == "seq" else None)
            assert "not writable" in str(err.value)
        assert os.listdir(ro) == []
    finally:
        ro.chmod(0o755)


@pytest.mark.parametrize("fmt", ["mp4", "png"])
def test_disk_full_while_writing(tmp_path, monkeypatch, fmt):
    real = encode.base.write_all
    calls = []

    def filling_up(stream, data):
        calls.append(1)
        if len(calls) == 4:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real(stream, data)

    monkeypatch.setattr(encode.base, "write_all", filling_up)
    out = tmp_path / ("clip.mp4" if fmt == "mp4" else "seq")
    _, frames = colour_frames(10)
    with pytest.raises(OSError) as err:
        with open_writer(out, fps=FPS, size=(W, H), format=fmt, quiet=True) as w:
            for f in frames:
                w.write(f)
    assert err.value.errno == errno.ENOSPC
    assert "disk full" in str(err.value) and str(out) in str(err.value)
    assert leftovers(tmp_path) == []


def test_disk_full_reported_by_ffmpeg(tmp_path, monkeypatch):
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    exe = fake_ffmpeg(tmp_path, 'cat >/dev/null; echo "av_interleaved_write_frame(): No space left on device" >&2; exit 1')
    monkeypatch.setattr(encode.ffmpeg, "ffmpeg_exe", lambda: exe)
    with pytest.raises(OSError) as err:
        with open_writer(out_dir / "clip.mp4", fps=FPS, size=(W, H), quiet=True) as w:
            w.write(np.zeros((H, W, 3), np.uint8))
    assert err.value.errno == errno.ENOSPC and "disk full" in str(err.value)
    assert leftovers(out_dir) == []


@pytest.mark.parametrize("with_audio", [False, True])
def test_keyboard_interrupt_inside_with(tmp_path, with_audio):
    wav = write_wav(tmp_path / "a.wav", 0.5) if with_audio else None
    out = tmp_path / "clip.mp4"
    _, frames = colour_frames(6)
    with pytest.raises(KeyboardInterrupt):
        with open_writer(out, fps=FPS, size=(W, H), audio=wav, quiet=True) as w:
            proc = w._proc
            for f in frames:
                w.write(f)
            raise KeyboardInterrupt
    assert proc.poll() is not None  # ffmpeg was stopped, not left running
    assert leftovers(tmp_path, "a.wav") == []


def test_sigint_inside_with(tmp_path):
    out = tmp_path / "clip.mp4"
    _, frames = colour_frames(6)
    with pytest.raises(KeyboardInterrupt):
        with open_writer(out, fps=FPS, size=(W, H), quiet=True) as w:
            for i, f in enumerate(frames):
                w.write(f)
                if i == 2:
                    os.kill(os.getpid(), signal.SIGINT)
    assert leftovers(tmp_path) == []


def test_other_errors_zero_frames_and_bad_frames(tmp_path):
    out = tmp_path / "clip.mp4"
    with pytest.raises(ZeroDivisionError):
        with open_writer(out, fps=FPS, size=(W, H), quiet=True) as w:
            w.write(np.zeros((H, W, 3), np.uint8))
            1 / 0
    with pytest.raises(EncodeError) as err:
        with open_writer(out, fps=FPS, size=(W, H), quiet=True):
            pass
    assert "no frames" in str(err.value)
    with pytest.raises(ValueError) as err:
        with open_writer(out, fps=FPS, size=(W, H), quiet=True) as w:
            w.write(np.zeros((W, H, 3), np.uint8))  # transposed
    assert "(48, 64, 3)" in str(err.value)
    assert leftovers(tmp_path) == []


def test_existing_output_is_replaced_only_when_complete(tmp_path):
    out = tmp_path / "clip.mp4"
    out.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with open_writer(out, fps=FPS, size=(W, H), quiet=True) as w:
            w.write(np.zeros((H, W, 3), np.uint8))
            raise RuntimeError("stop")
    assert out.read_bytes() == b"old"
    with open_writer(out, fps=FPS, size=(W, H), quiet=True) as w:
        w.write(np.zeros((H, W, 3), np.uint8))
    assert probe(out)["n_frames"] == 1
    assert leftovers(tmp_path, "clip.mp4") == []


def test_probe_rejects_non_video(tmp_path):
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(struct.pack("<4I", 1, 2, 3, 4))
    with pytest.raises(InputError) as err:
        probe(bad)
    assert "bad.mp4" in str(err.value)


def test_docstring_examples_run():
    import doctest

    attempted = 0
    for module in (encode, encode.base, encode.ffmpeg, encode.mp4, encode.png):
        result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
        assert result.failed == 0, module.__name__
        attempted += result.attempted
    assert attempted >= 9


def test_high_frame_rate_with_audio_keeps_a_constant_rate(tmp_path):
    # 60 fps does not divide a millisecond clock: an intermediate container with 1 ms
    # timestamps would turn this into 60.08 fps variable-rate video.
    wav = write_wav(tmp_path / "a.wav", 0.3)
    out = tmp_path / "fast.mp4"
    _, frames = colour_frames(31)
    with open_writer(out, fps=60, size=(W, H), audio=wav, quiet=True) as w:
        for f in frames:
            w.write(f)
    info = probe(out)
    assert info["fps"] == 60.0 and info["n_frames"] == 31
    assert abs(info["audio_duration"] - 31 / 60) <= 1 / 60


CHILD = """
import sys, time, numpy as np
from lipsync.encode import open_writer
with open_writer(sys.argv[1], fps=25, size=(64, 48), audio=sys.argv[2], quiet=True) as w:
    w.write(np.zeros((48, 64, 3), np.uint8))
    print("started", flush=True)
    while True:
        w.write(np.zeros((48, 64, 3), np.uint8))
        time.sleep(0.01)
"""


@pytest.mark.skipif(os.name != "posix", reason="process groups and SIGINT are POSIX")
def test_ctrl_c_to_the_process_group(tmp_path):
    # A terminal's Ctrl-C signals the whole foreground group; ffmpeg must not finalise a
    # file of its own, and Python's cleanup must leave nothing behind.
    import sys

    script = tmp_path / "child.py"
    script.write_text(CHILD)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    wav = write_wav(tmp_path / "a.wav", 0.5)
    proc = subprocess.Popen([sys.executable, str(script), str(out_dir / "o.mp4"), str(wav)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        assert proc.stdout.readline().strip() == b"started"
        os.killpg(proc.pid, signal.SIGINT)
        assert proc.wait(timeout=30) != 0
    finally:
        if proc.poll() is None:
            proc.kill()
    assert b"KeyboardInterrupt" in proc.stderr.read()
    assert leftovers(out_dir) == []


def test_permission_denied_is_reported_even_when_running_as_root(tmp_path, monkeypatch):
    # root ignores folder permissions, so deny creation of anything under this folder the
    # way a read-only mount would, whoever runs the tests.
    ro = tmp_path / "ro"
    ro.mkdir()
    real_open, real_mkdir = os.open, os.mkdir

    def deny(real):
        def wrapped(path, *args, **kwargs):
            if os.fspath(path).startswith(str(ro)):
                raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), os.fspath(path))
            return real(path, *args, **kwargs)
        return wrapped

    monkeypatch.setattr(os, "open", deny(real_open))
    monkeypatch.setattr(os, "mkdir", deny(real_mkdir))
    for out, fmt in ((ro / "clip.mp4", None), (ro / "seq", "png")):
        with pytest.raises(PermissionError) as err:
            open_writer(out, fps=FPS, size=(W, H), format=fmt, quiet=True)
        assert "not writable" in str(err.value) and str(ro) in str(err.value)
    monkeypatch.undo()
    assert os.listdir(ro) == []


def x264_options(path):
    """The option string x264 writes into the stream (its SEI), as a dict."""
    data = open(path, "rb").read()
    start = data.index(b"options: ") + len(b"options: ")
    text = data[start:data.index(b"\x00", start)].decode("ascii", "replace")
    return dict(item.split("=", 1) for item in text.split() if "=" in item)


def test_named_preset_and_threads_reach_x264(tmp_path):
    from lipsync.pipeline.clip import DEFAULT_PRESET

    assert DEFAULT_PRESET in encode.X264_PRESETS
    out = tmp_path / "th.mp4"
    _, frames = colour_frames(8)
    with open_writer(out, fps=FPS, size=(W, H), quiet=True, preset="talking-head", threads=1) as w:
        for f in frames:
            w.write(f)
    opts = x264_options(out)
    # ultrafast's analysis (subme 0, diamond search) with the tools added on top
    assert (opts["cabac"], opts["bframes"], opts["b_adapt"], opts["mbtree"], opts["rc_lookahead"]) == \
        ("1", "3", "0", "1", "5")
    assert (opts["subme"], opts["me"], opts["8x8dct"], opts["threads"], opts["crf"]) == \
        ("0", "dia", "1", "1", "18.0")
    # Any other name goes to x264 unchanged.
    with open_writer(out, fps=FPS, size=(W, H), quiet=True, preset="veryfast") as w:
        for f in frames:
            w.write(f)
    opts = x264_options(out)
    assert (opts["subme"], opts["me"], opts["b_adapt"], opts["rc_lookahead"]) == ("2", "hex", "1", "10")
