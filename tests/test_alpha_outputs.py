"""Outputs with alpha (WebM/VP9, MOV/ProRes 4444 and Animation, PNG, WebP, GIF), flattening
onto a background, and mouth sprites composited onto a body (issue 18)."""

import os
import shutil
import subprocess
import wave

import cv2
import numpy as np
import pytest

from lipsync.morphing import alpha as alpha_mod
from lipsync.banks.bank import Bank
from lipsync.cli import main
from lipsync.pipeline.clip import render_clip
from lipsync.composite import Composite, Compositor
from lipsync.encode import ENCODERS, EncodeError, format_for, has_alpha, open_writer, probe
from lipsync.encode.ffmpeg import ffmpeg_exe
from lipsync.errors import BankError, InputError
from lipsync.morphing.render import Renderer

H, W = 48, 64
BANDS = (0, 64, 160, 255)


def band_frames(n=10):
    """RGBA frames: a colour ramp, and alpha in four vertical bands (0, 64, 160, 255) that
    move one pixel a frame, so every frame's alpha differs."""
    out = []
    for i in range(n):
        f = np.zeros((H, W, 4), np.uint8)
        f[..., 0] = 200
        f[..., 1] = np.linspace(40, 220, W).astype(np.uint8)[None, :]
        f[..., 2] = 40 + 10 * (i % 20)
        for k, a in enumerate(BANDS):
            f[:, k * 16:(k + 1) * 16, 3] = a
        f[..., 3] = np.roll(f[..., 3], i, axis=1)
        out.append(f)
    return out


def decode_rgba(path, *, decoder=None, shape=(H, W)):
    """Every frame of ``path`` as RGBA, decoded by ffmpeg (``decoder``: e.g. libvpx-vp9)."""
    cmd = [ffmpeg_exe(), "-v", "error"] + (["-c:v", decoder] if decoder else []) + \
          ["-i", str(path), "-f", "rawvideo", "-pix_fmt", "rgba", "-"]
    raw = subprocess.run(cmd, capture_output=True, check=True).stdout
    return np.frombuffer(raw, np.uint8).reshape((-1,) + tuple(shape) + (4,))


def write_wav(path, seconds, rate=48000):
    t = np.arange(int(seconds * rate)) / rate
    samples = (0.3 * np.sin(2 * np.pi * 440 * t) * 32767).astype(np.int16)
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(samples.tobytes())
    return path


def write(out, images, fmt=None, **kw):
    with open_writer(out, fps=25, size=(images[0].shape[1], images[0].shape[0]), format=fmt,
                     channels=images[0].shape[2], quiet=True, **kw) as w:
        for f in images:
            w.write(f)
    return out


# -- formats ---------------------------------------------------------------------------------

def test_formats_from_the_registry():
    assert format_for("a.webm") == "webm" and format_for("a.MOV") == "mov"
    assert format_for("a.webp") == "webp" and format_for("a.gif") == "gif"
    assert [n for n in ENCODERS.names() if has_alpha(n)] == ["png", "webm", "mov", "qtrle", "webp", "gif"]
    assert not has_alpha("mp4")
    # the CLI's --format choices are the registry's names
    from lipsync.cli import build_parser

    parser = build_parser(["render"])
    sub = next(a for a in parser._actions if a.dest == "command").choices["render"]
    fmt = next(a for a in sub._actions if a.dest == "format")
    assert list(fmt.choices) == ENCODERS.names()


# tolerance of alpha after the round trip, per format: VP9 is lossy (its alpha plane too,
# at crf 30), ProRes 4444 keeps 16-bit alpha from 8-bit input (exact up to rounding),
# QuickTime Animation, PNG and WebP's alpha are lossless
ALPHA_TOL = {"webm": 8, "mov": 1, "qtrle": 0, "webp": 0}
COLOUR_TOL = {"webm": 12, "mov": 3, "qtrle": 0, "webp": 14}


@pytest.mark.parametrize("fmt,ext,decoder", [("webm", ".webm", "libvpx-vp9"), ("mov", ".mov", None),
                                             ("qtrle", ".mov", None), ("webp", ".webp", None)])
def test_alpha_decoded_back_with_ffmpeg(tmp_path, fmt, ext, decoder):
    frames = band_frames()
    out = write(tmp_path / f"a{ext}", frames, fmt)
    got = decode_rgba(out, decoder=decoder)
    ref = np.stack(frames)
    assert got.shape == ref.shape
    err = np.abs(got[..., 3].astype(int) - ref[..., 3])
    # away from the band edges (VP9 smears a sharp 0 -> 255 step by a few levels)
    inner = np.ones(ref.shape[:3], bool)
    for i in range(len(frames)):
        edges = np.flatnonzero(np.diff(ref[i, 0, :, 3].astype(int))) + 1
        for e in edges:
            inner[i, :, max(0, e - 2):e + 2] = False
    assert err[inner].max() <= ALPHA_TOL[fmt], err[inner].max()
    # every band's value comes back (not just "has alpha"): per band medians
    for i in (0, len(frames) - 1):
        for k, a in enumerate(BANDS):
            cols = np.arange(k * 16 + i + 3, (k + 1) * 16 + i - 3) % W
            assert abs(np.median(got[i][:, cols, 3]) - a) <= max(1, ALPHA_TOL[fmt])
    visible = inner & (ref[..., 3] >= 160)
    cerr = np.abs(got[..., :3].astype(int) - ref[..., :3]).max(axis=-1)
    assert cerr[visible].max() <= COLOUR_TOL[fmt], cerr[visible].max()


def test_vp9_alpha_needs_the_libvpx_decoder(tmp_path):
    # ffmpeg's native vp9 decoder drops the alpha side data: everything reads as opaque.
    # (Why the test above decodes with -c:v libvpx-vp9.)
    out = write(tmp_path / "a.webm", band_frames(3))
    assert (decode_rgba(out)[..., 3] == 255).all()
    assert (decode_rgba(out, decoder="libvpx-vp9")[..., 3] < 10).any()


def test_prores_4444_with_an_alpha_plane(tmp_path):
    out = write(tmp_path / "a.mov", band_frames(2))
    text = subprocess.run([ffmpeg_exe(), "-hide_banner", "-i", str(out)], capture_output=True, text=True).stderr
    assert "prores" in text and "4444" in text and "yuva444p" in text


def test_png_sequence_is_rgba(tmp_path):
    frames = band_frames(3)
    out = write(tmp_path / "seq", frames, "png")
    for i, f in enumerate(frames):
        back = cv2.imread(str(out / f"frame_{i:06d}.png"), cv2.IMREAD_UNCHANGED)
        np.testing.assert_array_equal(cv2.cvtColor(back, cv2.COLOR_BGRA2RGBA), f)


def test_gif_transparency_is_one_bit(tmp_path):
    frames = band_frames(4)
    got = decode_rgba(write(tmp_path / "a.gif", frames))
    ref = np.stack(frames)[..., 3]
    assert got.shape[0] == 4
    want = np.where(ref >= 128, 255, 0)
    assert (got[..., 3] == want).mean() > 0.99
    solid = ref == 255
    assert np.abs(got[..., :3].astype(int) - np.stack(frames)[..., :3])[solid].mean() < 12


@pytest.mark.parametrize("fmt,ext,codec", [("webm", ".webm", "opus"), ("mov", ".mov", "pcm_s16le")])
@pytest.mark.parametrize("announced", [False, True])
def test_speech_in_containers_with_audio(tmp_path, fmt, ext, codec, announced):
    wav = write_wav(tmp_path / "a.wav", 0.9)
    frames = band_frames(20)  # 0.8 s: the audio is cut to the video
    out = write(tmp_path / f"a{ext}", frames, fmt, audio=wav, frames=20 if announced else None)
    info = probe(out)
    assert info["audio_codec"] == codec and info["n_frames"] == 20
    assert abs(info["audio_duration"] - 0.8) <= 0.03
    assert sorted(os.listdir(tmp_path)) == sorted(["a.wav", f"a{ext}"])  # no temporaries left


def test_no_audio_track_formats_warn(tmp_path):
    wav = write_wav(tmp_path / "a.wav", 0.5)
    for name in ("a.gif", "a.webp"):
        with pytest.warns(UserWarning, match="no audio track"):
            write(tmp_path / name, band_frames(2), audio=wav)
        assert probe(tmp_path / name)["audio_codec"] is None


def test_opaque_formats_refuse_rgba_and_writers_check_shapes(tmp_path):
    with pytest.raises(ValueError, match="stores no alpha.*flatten"):
        open_writer(tmp_path / "a.mp4", fps=25, size=(W, H), channels=4)
    assert os.listdir(tmp_path) == []
    with pytest.raises(ValueError, match=r"expected uint8 of shape \(48, 64, 4\)"):
        with open_writer(tmp_path / "a.webm", fps=25, size=(W, H), channels=4, quiet=True) as w:
            w.write(np.zeros((H, W, 3), np.uint8))
    assert os.listdir(tmp_path) == []


def test_odd_sizes_and_opaque_frames(tmp_path):
    f = np.zeros((21, 33, 3), np.uint8)
    f[..., 1] = 150
    for name, decoder in (("a.webm", "libvpx-vp9"), ("a.mov", None)):
        out = write(tmp_path / name, [f, f])
        got = decode_rgba(out, decoder=decoder, shape=(21, 33))
        assert (got[..., 3] == 255).all() and abs(int(np.median(got[..., 1])) - 150) <= 3


def test_a_failing_encoder_leaves_nothing(tmp_path, monkeypatch):
    from lipsync import encode

    exe = tmp_path / "fake-ffmpeg"
    exe.write_text('#!/bin/sh\nhead -c 1000 >/dev/null; echo "simulated VP9 crash" >&2; exit 1\n')
    exe.chmod(0o755)
    monkeypatch.setattr(encode.ffmpeg, "ffmpeg_exe", lambda: str(exe))
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    with pytest.raises(EncodeError, match="simulated VP9 crash"):
        write(out_dir / "a.webm", band_frames(30))
    assert os.listdir(out_dir) == []


# -- clips: flattening and backgrounds ---------------------------------------------------------

def rgba_toon(tmp_path):
    from lipsync._data import default_bank_dir
    from lipsync.bench.alpha import rgba_twin

    return Bank.load(rgba_twin(default_bank_dir(), tmp_path / "rgba-toon"))


@pytest.fixture(scope="module")
def toon_rgba(tmp_path_factory):
    return rgba_toon(tmp_path_factory.mktemp("toon"))


TIMELINE = "0.00\tX\n0.12\tD\n0.28\tB\n0.40\tX\n"


@pytest.fixture
def cues(tmp_path):
    p = tmp_path / "cues.tsv"
    p.write_text(TIMELINE)
    return p


@pytest.fixture
def sprite_cues(tmp_path):
    p = tmp_path / "sprite.tsv"
    p.write_text("0.00\tX\n0.10\tA\n0.30\tX\n")
    return p


def test_rgba_bank_to_webm_keeps_its_alpha(toon_rgba, cues, tmp_path):
    out = tmp_path / "talk.webm"
    render_clip(cues, out, bank=toon_rgba, quiet=True)
    got = decode_rgba(out, decoder="libvpx-vp9", shape=toon_rgba.shape)
    rest = toon_rgba.images["X"]
    assert np.abs(got[0, ..., 3].astype(int) - rest[..., 3]).max() <= 24  # VP9 is lossy at edges
    assert np.median(np.abs(got[0, ..., 3].astype(int) - rest[..., 3])) == 0
    # frames in between: alpha as the renderer made it
    r = Renderer(toon_rgba)
    specs = __import__("lipsync").Animator(toon_rgba, cues).specs
    k = next(i for i, s in enumerate(specs) if 0.2 < s.alpha < 0.8 and s.from_viseme != s.to_viseme)
    want = r.render(specs[k].from_viseme, specs[k].to_viseme, specs[k].alpha)
    assert np.mean(np.abs(got[k, ..., 3].astype(int) - want[..., 3])) < 1.0


def test_rgba_bank_to_mp4_is_flattened_onto_white_with_a_warning(toon_rgba, cues, tmp_path):
    out = tmp_path / "talk.mp4"
    with pytest.warns(UserWarning, match="flattened onto white"):
        render_clip(cues, out, bank=toon_rgba, quiet=True)
    got = decode_rgba(out, shape=toon_rgba.shape)[0, ..., :3].astype(int)
    want = alpha_mod.flatten(toon_rgba.images["X"], (255, 255, 255)).astype(int)
    assert np.abs(got - want).mean() < 1.5  # H.264 at crf 18
    assert (got[:4, :4] >= 250).all()  # a transparent corner is white


def test_background_colour_and_image(toon_rgba, cues, tmp_path):
    out = tmp_path / "green"
    render_clip(cues, out, bank=toon_rgba, quiet=True, background="#00ff00", format="png")
    first = cv2.cvtColor(cv2.imread(str(out / "frame_000000.png"), cv2.IMREAD_UNCHANGED), cv2.COLOR_BGR2RGB)
    assert first.shape == toon_rgba.shape + (3,)  # opaque: flattened though png could keep alpha
    np.testing.assert_array_equal(first, alpha_mod.flatten(toon_rgba.images["X"], (0, 255, 0)))
    bg = np.zeros((128, 128, 3), np.uint8)
    bg[:, :64] = (0, 0, 255)
    cv2.imwrite(str(tmp_path / "bg.png"), cv2.cvtColor(bg, cv2.COLOR_RGB2BGR))
    assert main(["render", str(cues), "--bank", str(toon_rgba.path), "-o", str(tmp_path / "bg-frames") + "/",
                 "--background", str(tmp_path / "bg.png"), "-q"]) == 0
    first = cv2.imread(str(tmp_path / "bg-frames" / "frame_000000.png"))[..., ::-1]
    # the 128-px image was scaled to 512: the left half blue, the right half black where clear
    assert first[2, 2].tolist() == [0, 0, 255] and first[2, 509].tolist() == [0, 0, 0]
    assert main(["render", str(cues), "--bank", str(toon_rgba.path), "-o", str(tmp_path / "x.mp4"),
                 "--background", "no-such-colour", "-q"]) == 2


# -- composite -------------------------------------------------------------------------------

BODY_H, BODY_W = 180, 220


def body_image():
    """A grey character (opaque body) on a transparent surround."""
    img = np.zeros((BODY_H, BODY_W, 4), np.uint8)
    cv2.ellipse(img, (110, 95), (80, 70), 0, 0, 360, (150, 120, 100, 255), -1, cv2.LINE_AA)
    return img


def sprite_bank(folder, composite_yaml=""):
    """The disc bank of test_alpha (mouth sprites) with an optional composite block."""
    import test_alpha as ta

    folder.mkdir(parents=True, exist_ok=True)
    ta.write_rgba(folder / "X.png", ta.disc_image(**ta.DISC_X))
    ta.write_rgba(folder / "A.png", ta.disc_image(**ta.DISC_A))
    ta.write_rgba(folder / "body.png", body_image())
    # every viseme of the default map: X the red disc, the others the blue one
    visemes = "".join(
        f"  {v}: {{image: {'X' if v == 'X' else 'A'}.png, lines: {{axis: [[{d['cx']}, 20], [{d['cx']}, 60]]}}}}\n"
        for v, d in [("X", ta.DISC_X)] + [(v, ta.DISC_A) for v in "ABCDEFGH"])
    (folder / "bank.yaml").write_text("name: disc\nrest: X\nsymmetry: false\n" + composite_yaml + "visemes:\n"
                                      + visemes)
    return folder


def expected_composite(mouth, body, at, scale, *, flatten_on=None):
    """The body with the mouth over it, worked out pixel by pixel in float (independent of
    lipsync.composite)."""
    mh, mw = mouth.shape[:2]
    sh, sw = round(mh * scale), round(mw * scale)
    m = mouth if (sh, sw) == (mh, mw) else alpha_mod.resize_rgba(
        mouth, (sw, sh), interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
    x0, y0 = int(np.floor(at[0] - (sw - 1) / 2 + 0.5)), int(np.floor(at[1] - (sh - 1) / 2 + 0.5))
    base = body.astype(float)
    if flatten_on is not None:
        a = base[..., 3:4] / 255
        base = base[..., :3] * a + np.array(flatten_on, float) * (1 - a)
    out = base.copy()
    for y in range(sh):
        for x in range(sw):
            by, bx = y0 + y, x0 + x
            if 0 <= by < body.shape[0] and 0 <= bx < body.shape[1]:
                ma = m[y, x, 3] / 255
                if out.shape[2] == 3:
                    out[by, bx] = m[y, x, :3] * ma + base[by, bx] * (1 - ma)
                else:
                    ba = base[by, bx, 3] / 255
                    oa = ma + ba * (1 - ma)
                    col = (m[y, x, :3] * ma + base[by, bx, :3] * ba * (1 - ma)) / max(oa, 1e-9)
                    out[by, bx, :3] = col if oa > 0 else 0
                    out[by, bx, 3] = oa * 255
    return out, (y0, x0, sh, sw)


def test_bank_composite_block_renders_the_whole_character(tmp_path, sprite_cues):
    cues = sprite_cues
    bank = Bank.load(sprite_bank(tmp_path / "b", "composite: {image: body.png, at: [110, 120], scale: 0.5}\n"))
    assert bank.composite.at == (110.0, 120.0) and bank.composite.scale == 0.5
    out = tmp_path / "frames"
    render_clip(cues, out, bank=bank, quiet=True, format="png")
    files = sorted(out.iterdir())
    specs = __import__("lipsync").Animator(bank, cues).specs
    r = Renderer(bank)
    for i in (0, 3, 5):
        got = cv2.cvtColor(cv2.imread(str(files[i]), cv2.IMREAD_UNCHANGED), cv2.COLOR_BGRA2RGBA)
        assert got.shape == (BODY_H, BODY_W, 4)  # the body's size; its surround stays transparent
        mouth = r.render(specs[i].from_viseme, specs[i].to_viseme, specs[i].alpha)
        want, (y0, x0, sh, sw) = expected_composite(mouth, bank.composite.image, (110, 120), 0.5)
        assert np.abs(got.astype(float) - want).max() <= 1.0
        outside = np.ones((BODY_H, BODY_W), bool)
        outside[y0:y0 + sh, x0:x0 + sw] = False
        np.testing.assert_array_equal(got[outside], bank.composite.image[outside])
    # in an mp4 the transparent surround becomes white, the mouth still over the body
    with pytest.warns(UserWarning, match="flattened onto the body"):
        render_clip(cues, tmp_path / "c.mp4", bank=bank, quiet=True)
    got = decode_rgba(tmp_path / "c.mp4", shape=(BODY_H, BODY_W))[0, ..., :3].astype(float)
    want, _ = expected_composite(r.render("X", "X", 0.0), bank.composite.image, (110, 120), 0.5,
                                 flatten_on=(255, 255, 255))
    assert np.abs(got - want).mean() < 1.5


def test_over_at_scale_on_the_command_line(tmp_path, sprite_cues):
    cues = sprite_cues
    folder = sprite_bank(tmp_path / "b")
    body = np.full((120, 160, 3), (90, 160, 90), np.uint8)  # an opaque body: opaque output
    cv2.imwrite(str(tmp_path / "green-body.png"), cv2.cvtColor(body, cv2.COLOR_RGB2BGR))
    out = tmp_path / "f"
    assert main(["render", str(cues), "--bank", str(folder), "-o", str(out) + "/",
                 "--over", str(tmp_path / "green-body.png"), "--at", "40,30", "--scale", "1.5", "-q"]) == 0
    first = cv2.imread(str(out / "frame_000000.png"), cv2.IMREAD_UNCHANGED)
    assert first.shape == (120, 160, 3)  # an opaque body gives RGB frames
    bank = Bank.load(folder)
    want, _ = expected_composite(bank.images["X"], body, (40, 30), 1.5)
    assert np.abs(first[..., ::-1].astype(float) - want).max() <= 1.0
    # bad placements and option mixes are exit 2 with a message
    for extra in (["--at", "40,30"], ["--over", str(tmp_path / "green-body.png")],
                  ["--over", str(tmp_path / "green-body.png"), "--at", "500,30"],
                  ["--over", str(tmp_path / "green-body.png"), "--at", "4,3", "--scale", "0"],
                  ["--over", str(tmp_path / "green-body.png"), "--at", "x"],
                  ["--mouth-only", "--at", "1,2"]):
        assert main(["render", str(cues), "--bank", str(folder), "-o", str(tmp_path / "bad.mp4"), "-q"] + extra) == 2
    assert not (tmp_path / "bad.mp4").exists()


def test_mouth_only_ignores_the_composite(tmp_path, sprite_cues):
    cues = sprite_cues
    folder = sprite_bank(tmp_path / "b", "composite: {image: body.png, at: [110, 120]}\n")
    out = tmp_path / "m"
    assert main(["render", str(cues), "--bank", str(folder), "-o", str(out) + "/", "--mouth-only", "-q"]) == 0
    first = cv2.imread(str(out / "frame_000000.png"), cv2.IMREAD_UNCHANGED)
    assert first.shape[:2] == Bank.load(folder).shape


@pytest.mark.parametrize("block,message,line", [
    ("composite: {image: nobody.png, at: [1, 2]}\n", "does not exist", 4),
    ("composite: {image: ../body.png, at: [1, 2]}\n", "outside the bank folder", 4),
    ("composite: {image: body.png, at: [1000, 2]}\n", "outside the 220x180 body", 4),
    ("composite: {image: body.png, at: [1, .nan]}\n", "finite", 4),
    ("composite: {image: body.png, at: [1, 2], scale: -1}\n", "scale must be", 4),
    ("composite: {image: body.png, at: [1, 2], scale: 100}\n", "scale must be", 4),
    ("composite:\n  image: body.png\n  at: [1, 2, 3]\n", "at", 6),
    ("composite: {image: body.png, at: [1, 2], offset: 3}\n", "offset", 4),
])
def test_composite_block_is_validated(tmp_path, block, message, line):
    folder = sprite_bank(tmp_path / "b", block)
    shutil.copy(folder / "body.png", tmp_path / "body.png")
    with pytest.raises(BankError) as err:
        Bank.load(folder)
    assert message in str(err.value) and err.value.path == str(folder / "bank.yaml")
    assert err.value.line is not None and abs(err.value.line - line) <= 1


def test_compositor_touches_only_the_mouth_rectangle():
    body = np.random.default_rng(1).integers(0, 256, (60, 80, 3), dtype=np.uint8)
    c = Compositor((20, 30), 4, composite=Composite(body, (10.0, 50.0), 1.0), alpha_out=False)
    buf = c.initial.copy()
    mouth = np.zeros((20, 30, 4), np.uint8)
    mouth[..., 0] = 255
    mouth[..., 3] = 255
    c.apply(mouth, buf)
    # centre (10, 50) of 30x20 px: columns -4..25 (clipped to 0..25), rows 41..60 (to 59)
    assert (buf[41:60, 0:26] == (255, 0, 0)).all()
    mask = np.ones((60, 80), bool)
    mask[41:60, 0:26] = False
    np.testing.assert_array_equal(buf[mask], body[mask])
    with pytest.raises(InputError, match="outside"):
        Compositor((20, 30), 4, composite=Composite(body, (100.0, 50.0), 1.0))


def test_init_over_writes_the_composite_block(tmp_path, capsys):
    import test_alpha as ta

    folder = tmp_path / "sprites"
    folder.mkdir()
    for v in "ABCDEFGHX":
        ta.write_rgba(folder / f"mouth_{v}.png", ta.disc_image(**(ta.DISC_X if v == "X" else ta.DISC_A)))
    ta.write_rgba(tmp_path / "hero.png", body_image())
    # without --over: the mouth layout, and a hint how to put the sprites on a character
    assert main(["init", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "mouth layout" in out and "composite: {image: body.png" in out and "--over" in out
    assert Bank.load(folder).composite is None
    # a placement outside the body: exit 2, and the body copied for it is gone again
    assert main(["init", str(folder), "--over", str(tmp_path / "hero.png"), "--at", "500,20", "--force"]) == 2
    assert not (folder / "hero.png").exists()
    assert main(["init", str(folder), "--over", str(tmp_path / "hero.png"), "--at", "110,120", "--scale", "0.5",
                 "--force"]) == 0
    bank = Bank.load(folder)
    assert (folder / "hero.png").is_file() and sorted(bank.names) == list("ABCDEFGHX")  # the body is no viseme
    assert bank.composite.at == (110.0, 120.0) and bank.composite.scale == 0.5
    np.testing.assert_array_equal(bank.composite.image, body_image())
    assert "composite: {image: hero.png, at: [110.0, 120.0], scale: 0.5}" in (folder / "bank.yaml").read_text()
    # and render gives the whole character
    cues = tmp_path / "c.tsv"
    cues.write_text("0.00\tX\n0.10\tA\n0.30\tX\n")
    assert main(["render", str(cues), "--bank", str(folder), "-o", str(tmp_path / "c.webm"), "-q"]) == 0
    info = probe(tmp_path / "c.webm")
    assert (info["width"], info["height"]) == (BODY_W, BODY_H)
    assert main(["init", str(folder), "--at", "1,2", "--force"]) == 2
