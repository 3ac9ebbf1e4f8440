"""``lipsync dub`` and the idle plate (issue 28), on GRID speaker s1's clips in tests/data/grid-s1
(CC BY 4.0, see SOURCE.md there), checked on decoded videos with independent measures: the
input's own frames (the eye region frame by frame), the new speech's length as ffmpeg
decodes it, the face mesh run on the decoded frames at the new speech's P, B, M.
"""

from __future__ import annotations

import subprocess
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from lipsync.pipeline.dubbing import DubWarning, dub, lost_frames_text
from lipsync.composite.plate import PlateCompositor, compose, pingpong, pose_inverse
from lipsync.face import measure as M
from lipsync.face import topology as T
from lipsync.face.landmarks import FaceMesh
from lipsync.face.video import probe_video, read_video
from lipsync.readers.grid import read_words
from test_videobank import _write_video  # the clips re-encoded as a camera would (H.264, crf 12)

GRID = Path(__file__).parent / "data" / "grid-s1"
#: The bank; the video dubbed (its first 2 s: the 3 s speech plays it forwards and back);
#: the new speech ("place red at p six please": P, P, P and an M-less B-less set of vowels).
BANK, VIDEO, SPEECH = ("bbwm5s", "lwae8n"), "lwae8n", "prap6p"
CUT_FRAMES = 50
#: Frames of the cut video whose face is covered (no face: passed through unchanged).
COVERED = range(30, 34)


def _transcript(clip: str) -> str:
    p = GRID / f"{clip}.align"
    return " ".join(s.label for s in read_words(str(p), p.read_bytes()))


def _grey(f):
    return cv2.cvtColor(np.ascontiguousarray(f), cv2.COLOR_RGB2GRAY).astype(np.float64)


def _eye_box(points):
    p = np.asarray(points, np.float64)
    idx = list(T.EYE_UPPER_L + T.EYE_LOWER_L + T.BROW_L + T.EYE_UPPER_R + T.EYE_LOWER_R + T.BROW_R)
    (x0, y0), (x1, y1) = p[idx, :2].min(axis=0) - 4, p[idx, :2].max(axis=0) + 4
    return int(y0), int(y1), int(x0), int(x1)


@pytest.fixture(scope="module")
def mesh():
    return FaceMesh()


@pytest.fixture(scope="module")
def bank(tmp_path_factory):
    from lipsync.videobank import make_bank

    out = tmp_path_factory.mktemp("dub") / "bank"
    videos = [GRID / f"{c}.mpg" for c in BANK]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return make_bank(out, videos, texts={v: _transcript(v.stem) for v in videos}, quiet=True).path


@pytest.fixture(scope="module")
def cut(tmp_path_factory):
    """The first 2 s of VIDEO, once as they are and once with the face covered in COVERED."""
    tmp = tmp_path_factory.mktemp("cut")
    frames = list(read_video(GRID / f"{VIDEO}.mpg"))[:CUT_FRAMES]
    covered = [f.copy() for f in frames]
    for i in COVERED:
        covered[i][40:260, 90:270] = 128  # the whole head under a grey card
    return _write_video(tmp / "cut.mp4", frames), _write_video(tmp / "covered.mp4", covered)


@pytest.fixture(scope="module")
def dubbed(bank, cut, tmp_path_factory):
    out = tmp_path_factory.mktemp("out") / "dub.mp4"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        report = dub(cut[0], GRID / f"{SPEECH}.mpg", out, text=_transcript(SPEECH), bank=bank, quiet=True,
                     cache=out.parent / "cache")
    return out, report, [w for w in caught if issubclass(w.category, DubWarning)]


def test_pingpong_plays_forwards_then_backwards_without_repeating_the_turns():
    assert [pingpong(i, 4) for i in range(13)] == [0, 1, 2, 3, 2, 1, 0, 1, 2, 3, 2, 1, 0]
    assert [pingpong(i, 2) for i in range(5)] == [0, 1, 0, 1, 0]
    assert [pingpong(i, 1) for i in range(3)] == [0, 0, 0]
    n = 50  # every frame shown once per pass; the turns (0 and n-1) once per period
    shown = [pingpong(i, n) for i in range(2 * (n - 1))]
    assert sorted(shown) == sorted(list(range(n)) + list(range(1, n - 1)))


def test_compositor_moves_the_masked_face_by_the_pose_and_leaves_the_rest():
    # a bank picture with a bright square in the mask; the pose turns it 90 degrees and shifts it
    mouth = np.zeros((40, 40, 3), np.uint8)
    mouth[10:30, 10:30] = 200
    mask = np.zeros((40, 40), np.float32)
    mask[10:30, 10:30] = 1.0
    pose = np.array([[0.0, -1.0, 70.0], [1.0, 0.0, 5.0]])    # (x, y) -> (70 - y, 5 + x)
    plate = np.full((80, 100, 3), 50, np.uint8)
    before = plate.copy()
    PlateCompositor(mask).apply(mouth, plate, pose)
    # bank (20, 20) lands on (50, 25); bank (12, 28) on (42, 17)
    assert plate[25, 50].tolist() == [200, 200, 200] and plate[17, 42].tolist() == [200, 200, 200]
    changed = np.any(plate != before, axis=2)
    ys, xs = np.nonzero(changed)
    assert xs.min() >= 39 and xs.max() <= 61 and ys.min() >= 14 and ys.max() <= 36
    assert np.allclose(compose(pose, pose_inverse(pose)), [[1, 0, 0], [0, 1, 0]])


def _plan(video, n):
    """The video frame a dub of ``n`` frames shows at each (lipsync.composite.plate_time via
    the dub's own face track of ``video``)."""
    from lipsync.pipeline.dubbing import video_frames_for, video_track

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        track = video_track(Path(video), probe_video(video), entry=None, quiet=True)
    return video_frames_for(track, n)


def test_dub_has_the_new_speech_length_and_joins_the_video_where_it_matches(dubbed, cut):
    from lipsync.speech.audio import load_audio

    out, report, _ = dubbed
    speech_s = len(load_audio(GRID / f"{SPEECH}.mpg")) / 16000
    frames = list(read_video(out))
    info = probe_video(out)
    assert info.has_audio and info.size == (360, 288) and info.fps == 25
    assert len(frames) == report.frames == int(np.ceil(speech_s * 25 - 1e-6))
    assert len(frames) > CUT_FRAMES  # longer than the video: it goes on along the plate timeline
    assert not list(out.parent.glob(".dub.mp4.partial*"))  # the frames kept for the way back are gone
    sound_s = len(load_audio(out)) / 16000
    assert abs(sound_s - len(frames) / 25) < 0.05 and abs(sound_s - speech_s) < 0.05
    # frame by frame, the eye region is the input's own frame plan[i]: that frame fits best of
    # all the input's frames, within a few grey levels; straight on first, then joined
    from lipsync.composite.plate_time import MIN_RUN_S

    plan = _plan(cut[0], len(frames))
    through = CUT_FRAMES - int(round(MIN_RUN_S * 25))  # the video played through before any join
    assert list(plan[:through]) == list(range(through)) and len(set(plan.tolist())) > through
    src = [_grey(f) for f in read_video(cut[0])]
    mesh = FaceMesh()
    y0, y1, x0, x1 = _eye_box(mesh.find(list(read_video(cut[0]))[0]))
    diffs = []
    for i, f in enumerate(frames):
        g = _grey(f)[y0:y1, x0:x1]
        d = [np.abs(g - s[y0:y1, x0:x1]).mean() for s in src]
        j = int(plan[i])
        diffs.append(d[j])
        assert int(np.argmin(d)) == j or d[j] - min(d) < 0.3, (i, j, int(np.argmin(d)))
    # what the H.264 encoding alone costs there: the input's frames through the same writer
    from lipsync.encode import open_writer

    plain = out.parent / "plain.mp4"
    with open_writer(plain, fps=25, size=(360, 288), format="mp4", quiet=True, preset="talking-head") as w:
        for f in read_video(cut[0]):
            w.write(f)
    codec = [np.abs(_grey(a)[y0:y1, x0:x1] - s[y0:y1, x0:x1]).mean() for a, s in zip(read_video(plain), src)]
    assert np.mean(diffs[:CUT_FRAMES]) < np.mean(codec) + 0.3, (np.mean(diffs), np.mean(codec))
    assert np.max(diffs) < 4.0, np.max(diffs)


def test_dub_closes_the_lips_on_p_b_m_of_the_new_speech(dubbed, mesh):
    from lipsync.face.track import track_frames
    from lipsync.speech.align import align

    out, _, _ = dubbed
    frames = list(read_video(out))
    tr = track_frames(frames, fps=25.0, mesh=mesh)
    assert tr.found.all()
    opening = M.lip_opening(tr.points)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        phones = align(GRID / f"{SPEECH}.mpg", _transcript(SPEECH)).phones
    mid = lambda s: min(len(frames) - 1, int(round((s.start + s.end) / 2 * 25)))  # noqa: E731
    bilabial = [mid(s) for s in phones if s.label.rstrip("012") in ("P", "B", "M")]
    vowels = [mid(s) for s in phones if s.label.rstrip("012") in ("AE", "EH", "AY", "IY", "EY")]
    assert len(bilabial) >= 3 and len(vowels) >= 4
    closed, open_ = opening[bilabial], opening[vowels]
    # (the mesh measures real closed lips at 0.02-0.03 eye distances on GRID)
    assert closed.max() < 0.035, closed
    assert closed.mean() < 0.5 * open_.mean() and closed.max() < 0.45 * open_.max(), (closed, open_)


def test_frames_without_a_face_pass_through_unchanged_with_a_warning(bank, cut, tmp_path):
    out = tmp_path / "covered-dub.mp4"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        report = dub(cut[1], GRID / f"{SPEECH}.mpg", out, text=_transcript(SPEECH), bank=bank, quiet=True,
                     cache=tmp_path / "cache")
    # output frames showing covered input frames: on the way forwards and on the way back
    plan = _plan(cut[1], report.frames)
    lost = [i for i in range(report.frames) if plan[i] in COVERED]
    assert list(report.lost) == lost and lost[:4] == [30, 31, 32, 33]
    said = [str(w.message) for w in caught if issubclass(w.category, DubWarning)]
    assert len(said) == 1 and lost_frames_text(lost, 25.0) in said[0] and "30-33 (1.20-1.32 s)" in said[0]
    src = list(read_video(cut[1]))
    frames = list(read_video(out))
    for i in lost:
        diff = np.abs(frames[i].astype(np.int16) - src[plan[i]]).mean()
        assert diff < 1.5, (i, diff)
    # a frame with a face has its lower face replaced: it differs from the input below the nose
    assert np.abs(frames[10].astype(np.int16) - src[10])[200:240, 150:210].mean() > 2.0


def test_cli_exits_2_naming_a_video_without_a_face_and_speech_without_sound(cut, tmp_path, capsys):
    import imageio_ffmpeg

    from lipsync.cli import main

    blank = tmp_path / "blank.mp4"
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-f", "lavfi", "-i",
                    "testsrc=size=160x120:rate=25:duration=1", "-f", "lavfi", "-i",
                    "sine=frequency=300:duration=1", "-shortest", "-pix_fmt", "yuv420p", str(blank)], check=True)
    silent = cut[0]  # no audio stream
    out = tmp_path / "o.mp4"
    assert main(["dub", str(GRID / f"{VIDEO}.mpg"), "--audio", str(silent), "-o", str(out), "-q",
                 "--cache", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert str(silent) in err and "no audio stream" in err and "Traceback" not in err
    assert main(["dub", str(blank), "--audio", str(GRID / f"{SPEECH}.mpg"), "-o", str(out), "-q",
                 "--cache", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert str(blank) in err and "no face" in err and "Traceback" not in err
    assert not out.exists() and not list(tmp_path.glob(".o.mp4*"))


def test_render_lives_on_the_plate_and_still_turns_it_off(bank):
    from lipsync.pipeline.animator import Animator
    from lipsync.banks.bank import Bank
    from lipsync.motion.timeline import Segment, Timeline

    b = Bank.load(bank)
    assert b.plate is not None and b.plate.enabled
    tl = Timeline((Segment(0.0, 0.3, "sil"), Segment(0.3, 0.5, "AA"), Segment(0.5, 0.7, "M"),
                   Segment(0.7, 4.5, "sil")), kind="phoneme")
    live, still = Animator(b, tl, fps=25), Animator(b, tl, fps=25, still=True)
    plate = live.plate
    n = len(plate)
    assert n >= 50 and len(live) > n  # long enough to turn round
    # above the lower-face mask (where any frame's pose puts it): the plate frame itself
    top = min(plate.compositor.roi(p, plate.frames.shape[1:])[1] for p in plate.poses)
    assert top > 0.4 * plate.frames.shape[1]
    for i in (0, 5, n - 1, n + 3, len(live) - 1):
        assert np.array_equal(live.frame(i)[:top], plate.frames[plate.index(i, 25.0, live.plate_line)][:top]), i
    # the plate moves (blinks, the head) through the long silence; the still pictures hold
    tops = [live.frame(i)[:top].astype(np.int16) for i in range(40, len(live), 5)]
    assert max(np.abs(a - tops[0]).mean() for a in tops) > 0.5
    assert still.plate is None
    assert all(np.array_equal(still.frame(i), still.frame(40)) for i in range(45, len(still), 5))
    assert not live.same_as_previous(len(live) - 1) and still.same_as_previous(len(still) - 1)
    # the mouth is the morph's: the closure (M) differs from the rest shape below the nose
    y0 = top
    m = int(0.6 * 25)
    assert np.abs(live.frame(m)[y0:].astype(np.int16) - plate.frames[plate.index(m, 25.0, live.plate_line)][y0:]
                  ).mean() > 1.0


def test_a_broken_cache_entry_is_a_miss(cut, tmp_path):
    from lipsync.banks.bank import Bank
    from lipsync.pipeline.dubbing import bank_from_video, video_track

    video = GRID / f"{VIDEO}.mpg"
    info = probe_video(video)
    entry = tmp_path / "entry"
    entry.mkdir()
    (entry / "track.npz").write_bytes(b"not a track")  # e.g. a disk that filled up
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        track = video_track(video, info, entry=entry, quiet=True)
    assert len(track) == 75 and track.found.all()
    again = video_track(video, info, entry=entry, quiet=True)  # now from the cache, the same points
    assert np.allclose(again.points, track.points, equal_nan=True)
    # a bank folder whose bank.yaml does not load is made again from the video
    text = _transcript(VIDEO)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        first = bank_from_video(video, entry=entry, text=text)
        (first.path / "bank.yaml").write_text("name: [broken\n")
        second = bank_from_video(video, entry=entry, text=text)
    assert second.path == first.path and isinstance(second, Bank) and second.plate is not None


@pytest.mark.parametrize("method", ["flow", "splat"])
def test_rendering_a_region_gives_the_full_frames_pixels_there(bank, method):
    from lipsync.banks.bank import Bank
    from lipsync.morphing.render import Renderer, available_kernels
    from lipsync.morphing.store import Crop

    b = Bank.load(bank)
    h, w = b.shape
    for kernel in available_kernels() if method == "flow" else [None]:
        r = Renderer(b, method=method, kernel=kernel)
        for reg in (Crop(h // 2, h - 10, w // 4, 3 * w // 4), Crop(0, h, 0, w),
                    Crop(h // 2, h // 2 + 6, w // 2, w // 2 + 6), Crop(0, 4, 0, 4)):
            for a, z, alpha in (("X", "D", 0.3), ("A", "C", 0.7)):
                full = r.render(a, z, alpha, out=np.empty((h, w, 3), np.uint8))
                part = np.zeros((h, w, 3), np.uint8)
                r.render(a, z, alpha, out=part, region=reg)
                box = (slice(reg.y0, reg.y1), slice(reg.x0, reg.x1))
                assert np.array_equal(part[box], full[box]), (kernel, reg, a, z)
                assert not part[:reg.y0].any() and not part[reg.y1:].any()  # rows outside: untouched


def test_bank_yaml_switches_the_plate_off_and_a_missing_plate_file_is_named(bank, tmp_path):
    import shutil

    from lipsync.pipeline.animator import Animator
    from lipsync.banks.bank import Bank
    from lipsync.errors import BankError
    from lipsync.motion.timeline import Segment, Timeline

    copy = tmp_path / "bank"
    shutil.copytree(bank, copy, ignore=shutil.ignore_patterns(".lipsync"))
    text = (copy / "bank.yaml").read_text()
    assert "plate: {video: plate.mp4, poses: plate.json, mask: plate-mask.png}" in text
    (copy / "bank.yaml").write_text(text.replace("mask: plate-mask.png}", "mask: plate-mask.png, enabled: false}"))
    tl = Timeline((Segment(0.0, 0.5, "sil"),), kind="phoneme")
    assert Animator(Bank.load(copy), tl).plate is None
    (copy / "bank.yaml").write_text(text)
    (copy / "plate.json").unlink()
    with pytest.raises(BankError, match="plate poses: file 'plate.json' not found"):
        Bank.load(copy)


def test_dub_takes_lang_and_refuses_an_unknown_one(tmp_path, monkeypatch):
    # --lang reaches the aligner of the new speech (and the cache key of a bank made from the
    # video); an unknown code stops before any work, naming the codes
    from lipsync.cli import main
    from lipsync.pipeline import animator

    seen = {}

    def fake_align(audio, text=None, *, lang=None, **kw):
        seen["lang"] = lang
        raise SystemExit(0)

    monkeypatch.setattr("lipsync.speech.align.align", fake_align)
    with pytest.raises(SystemExit):
        animator.Animator.from_audio("toon", str(Path(__file__).parents[1] / "samples" / "hello.wav"), "hello", lang="fr")
    assert seen == {"lang": "fr"}
    with pytest.raises(SystemExit) as stop:  # argparse refuses it: exit 2 with the list of codes
        main(["dub", str(GRID / "bbwm5s.mpg"), "--audio", str(Path(__file__).parents[1] / "samples" / "hello.wav"),
              "--lang", "xx-nowhere", "-o", str(tmp_path / "out.mp4"), "--quiet"])
    assert stop.value.code == 2
    assert not (tmp_path / "out.mp4").exists()
