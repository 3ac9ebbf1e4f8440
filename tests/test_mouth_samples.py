"""Mouth samples of a bank made from video (issue 35), on GRID speaker s1's clips in tests/data/grid-s1.

The bank is made from two clips; one of them is rendered from its own alignment, so the
selection can reproduce the footage, and the pixels are checked against the decoded
source video (an independent path: the source frame, cut and warped here).
"""

from __future__ import annotations

import shutil
import warnings
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from lipsync.banks.bank import Bank
from lipsync.cli import main as lipsync
from lipsync.composite.plate import compose
from lipsync.face.video import read_video
from lipsync.readers.grid import read_words

GRID = Path(__file__).parent / "data" / "grid-s1"
BANK = ("bbwm5s", "lwae8n")


def _transcript(clip: str) -> str:
    p = GRID / f"{clip}.align"
    return " ".join(s.label for s in read_words(str(p), p.read_bytes()))


@pytest.fixture(scope="module")
def bank(tmp_path_factory):
    from lipsync.videobank import make_bank

    out = tmp_path_factory.mktemp("samples") / "bank"
    videos = [GRID / f"{c}.mpg" for c in BANK]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return make_bank(out, videos, texts={v: _transcript(v.stem) for v in videos}, quiet=True).path


@pytest.fixture(scope="module")
def own(bank):
    """The bank's first clip rendered from its own alignment, samples on."""
    from lipsync.pipeline.animator import Animator
    from lipsync.speech.align import align

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        phones = align(str(GRID / f"{BANK[0]}.mpg"), _transcript(BANK[0])).phones
    return Animator(Bank.load(bank), phones, fps=25, samples="on")


def test_the_stored_crops_are_the_footage_cut_at_integer_offsets(bank):
    from lipsync.samples import load_samples

    s = load_samples(Bank.load(bank))
    assert [str(c) for c in s.clips] == [f"{c}.mpg" for c in BANK]
    src = [np.array(f) for f in read_video(GRID / f"{BANK[0]}.mpg")]
    h, w = s.crops.shape[1:3]
    def grey(img):
        return cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2GRAY).astype(np.int16)

    for k in np.nonzero(s.clip == 0)[0][::10]:
        x, y = (int(v) for v in s.origin[k])
        f = src[int(s.frame[k])]
        stored = grey(s.crops[k])
        here = np.abs(stored - grey(f[y:y + h, x:x + w])).mean()
        moved = np.abs(stored - grey(f[y + 1:y + 1 + h, x + 1:x + 1 + w])).mean()
        assert here < 2.0 and moved > 2 * here, (k, here, moved)   # near-lossless (crf 8), not resampled or moved
    # runs are consecutive frames of one clip; the opening is the source track's
    same = s.run[1:] == s.run[:-1]
    assert (s.frame[1:][same] == s.frame[:-1][same] + 1).all()
    assert s.opening.max() > 3 * np.median(s.opening[s.labels == "sil"])


def test_rendering_its_own_sentence_replays_the_footage_where_it_can(own, monkeypatch):
    from lipsync.motion.coarticulation import DominanceParams
    from lipsync.selection import select as S

    sp = own.sample_path
    sel, s = sp.selection, sp.samples
    n = len(sel.samples)
    same = (s.clip[sel.samples] == 0) & (s.frame[sel.samples] == np.arange(n))
    assert same.mean() > 0.4, same.mean()          # the sentence's own frames, in their own order
    assert sel.runs() >= 3
    # the frames it does not replay are its motion-blurred ones: blind to blur, it keeps
    # longer runs of real video (GRID s1: 5 frames a run), and what the blur term gave up
    # is softer than what it kept
    monkeypatch.setitem(S.WEIGHTS, "blur", 0.0)
    params = own.timing if isinstance(own.timing, DominanceParams) else None
    blind = sp.selector.select(own.specs, own.phones, own.fps, params, audio=sp.audio_prediction)
    assert blind.runs() >= 4
    assert ((s.clip[blind.samples] == 0) & (s.frame[blind.samples] == np.arange(n))).mean() > 0.6
    kept = blind.samples[blind.samples == sel.samples]
    dropped = blind.samples[blind.samples != sel.samples]
    soft = sp.selector.softness
    assert len(dropped) and np.median(soft[dropped]) > np.median(soft[kept]) + 0.05, (
        np.median(soft[dropped]), np.median(soft[kept]))


def test_a_replayed_frame_is_the_source_frame_warped_once(own, bank):
    """Where a frame shows a sample as it is, its mouth is the decoded source frame moved by
    the composed affine (stabilisation, plate pose) in one warp: checked by warping the
    source video's own frame here."""
    sp, plate = own.sample_path, own.plate
    s = sp.samples
    src = [np.array(f) for f in read_video(GRID / f"{BANK[0]}.mpg")]
    checked = 0
    for i in range(len(own)):
        k = int(sp.dst[i])
        if sp.alpha[i] < 1.0 or s.clip[k] != 0:
            continue
        frame = own.frame(i)
        j = plate.index(i, own.fps, own.plate_line)
        x, y = (int(v) for v in s.origin[k])
        # source pixels -> plate pixels, composed here: the affine's crop shift undone
        to_plate = compose(compose(plate.poses[j], s.affine[k]), np.array([[1.0, 0, -x], [0, 1.0, -y]]))
        h, w = frame.shape[:2]
        want = cv2.warpAffine(src[int(s.frame[k])], to_plate, (w, h), flags=cv2.INTER_CUBIC)
        inside = cv2.warpAffine(s.mask, plate.poses[j], (w, h)) > 250
        diff = np.abs(frame.astype(np.int16) - want.astype(np.int16))[inside]
        gain = float(np.abs(s.gain[k] - 1).max())
        assert diff.mean() < 3.0 + 255 * gain, (i, diff.mean())
        checked += 1
        if checked == 5:
            break
    assert checked == 5


def test_a_bank_without_samples_renders_exactly_as_before(bank, tmp_path):
    from lipsync.motion.timeline import Segment, Timeline
    from lipsync.pipeline.animator import Animator

    plain = tmp_path / "plain"
    shutil.copytree(bank, plain, ignore=shutil.ignore_patterns(".lipsync", "samples.*"))
    text = (plain / "bank.yaml").read_text()
    (plain / "bank.yaml").write_text("".join(l for l in text.splitlines(True) if not l.startswith("samples:")))
    tl = Timeline((Segment(0.0, 0.3, "sil"), Segment(0.3, 0.5, "AA"), Segment(0.5, 0.7, "M"),
                   Segment(0.7, 1.2, "sil")), kind="phoneme")
    before = Animator(Bank.load(plain), tl, fps=25)
    off = Animator(Bank.load(bank), tl, fps=25, samples="off")
    on = Animator(Bank.load(bank), tl, fps=25)
    assert before.sample_path is None and off.sample_path is None and on.sample_path is not None
    for i in range(len(before)):
        assert np.array_equal(before.frame(i), off.frame(i)), i
    assert any(not np.array_equal(on.frame(i), off.frame(i)) for i in range(len(on)))
    # bank.yaml's switch does what --samples off does
    (plain / "bank.yaml").write_text(text.replace("samples: {", "samples: {enabled: false, "))
    shutil.copy(Path(bank) / "samples.mp4", plain)
    shutil.copy(Path(bank) / "samples.npz", plain)
    switched = Animator(Bank.load(plain), tl, fps=25)
    assert switched.sample_path is None
    assert np.array_equal(switched.frame(9), before.frame(9))


def test_the_toon_has_no_samples():
    from lipsync import Animator
    from lipsync._data import default_bank_dir
    from lipsync.motion.timeline import Segment, Timeline

    a = Animator(default_bank_dir(), Timeline((Segment(0.0, 0.2, "AA"),), kind="phoneme"), samples="on")
    assert a.sample_path is None


def _broken(bank: Path, tmp_path: Path, name: str) -> Path:
    out = tmp_path / name
    shutil.copytree(bank, out, ignore=shutil.ignore_patterns(".lipsync"))
    return out


def test_check_validates_the_sample_files_and_names_the_broken_one(bank, tmp_path, capsys):
    assert lipsync(["check", str(bank)]) == 0
    assert "mouth samples" in capsys.readouterr().out
    # not a table
    b = _broken(bank, tmp_path, "garbage")
    (b / "samples.npz").write_bytes(b"PK\x03\x04 not really")
    assert lipsync(["check", str(b)]) == 2
    assert "samples.npz" in capsys.readouterr().err
    # a table missing an array, and one whose runs are not consecutive frames
    from lipsync.samples import read_table

    table = read_table(Path(bank) / "samples.npz")
    for what, change in (("'lips' is missing", lambda t: t.pop("lips")),
                         ("not consecutive", lambda t: t["frame"].__setitem__(1, t["frame"][1] + 5)),
                         ("'pictures' and 'picture_opening' come together", lambda t: t.pop("picture_opening")),
                         ("'picture_opening' must be one finite number",
                          lambda t: t["picture_opening"].__setitem__(0, np.nan))):
        b = _broken(bank, tmp_path, what.split("'")[1] if "'" in what else "runs")
        t = {k: v.copy() for k, v in table.items()}
        change(t)
        with open(b / "samples.npz", "wb") as fh:
            np.savez(fh, **t)
        assert lipsync(["check", str(b)]) == 2
        err = capsys.readouterr().err
        assert "samples.npz" in err and what in err and "Traceback" not in err
    # crops that do not match the table's rows
    b = _broken(bank, tmp_path, "short")
    t = {k: v.copy() for k, v in table.items()}
    (b / "samples.mp4").write_bytes((Path(bank) / "plate.mp4").read_bytes())
    assert lipsync(["check", str(b)]) == 2
    assert "samples.mp4" in capsys.readouterr().err
    # a missing file is named by bank.yaml's loader
    b = _broken(bank, tmp_path, "missing")
    (b / "samples.mp4").unlink()
    assert lipsync(["check", str(b)]) == 2
    assert "samples.mp4" in capsys.readouterr().err


def test_a_broken_join_flow_in_the_store_is_a_miss(tmp_path):
    from lipsync.morphing.store import FlowStore, StoreWarning

    store = FlowStore(tmp_path)
    key = store.join_key([b"a", b"b"])
    flow = np.arange(24, dtype=np.float32).reshape(2, 6, 2)
    store.put_join(key, flow)
    assert np.array_equal(store.get_join(key), flow)
    p = store.join_path(key)
    data = bytearray(p.read_bytes())
    data[len(data) // 2] ^= 0xFF
    p.write_bytes(bytes(data))
    with pytest.warns(StoreWarning):
        assert store.get_join(key) is None


def test_render_cli_samples_off_matches_the_old_path(bank, tmp_path):
    tl = tmp_path / "a.tsv"
    tl.write_text("0.00\tX\n0.20\tD\n0.60\tA\n0.80\tX\n")
    outs = {}
    for opt in ("on", "off"):
        out = tmp_path / f"f-{opt}"
        assert lipsync(["render", str(tl), "-o", str(out), "--bank", str(bank), "--format", "png", "--quiet",
                        "--samples", opt]) == 0
        outs[opt] = sorted(out.iterdir())
    ref = tmp_path / "f-ref"
    from lipsync.pipeline.clip import render_clip

    render_clip(str(tl), ref, bank=replace(Bank.load(bank), samples=None), format="png", quiet=True)
    for a, b in zip(outs["off"], sorted(ref.iterdir())):
        assert np.array_equal(cv2.imread(str(a)), cv2.imread(str(b)))
    assert any(not np.array_equal(cv2.imread(str(a)), cv2.imread(str(b))) for a, b in zip(outs["on"], outs["off"]))


def test_the_table_holds_each_pictures_opening(bank):
    """``picture_opening`` is each bank picture's lip opening: measured again here on the
    pictures as written (the face mesh on the PNGs, independently of the bank's making)."""
    import cv2

    from lipsync.face import measure as M
    from lipsync.face.track import track_frames
    from lipsync.samples import read_table

    t = read_table(Path(bank) / "samples.npz")
    names = t["pictures"].tolist()
    assert sorted(names) == sorted(Bank.load(bank).names)
    pictures = [cv2.cvtColor(cv2.imread(str(Path(bank) / f"{v}.png")), cv2.COLOR_BGR2RGB) for v in names]
    tr = track_frames(pictures, fps=25.0, smooth=False)
    assert tr.found.all()
    again = M.lip_opening(tr.points)
    assert np.abs(again - t["picture_opening"]).max() < 0.015, (again.round(3), t["picture_opening"].round(3))
    # the open shapes open wider than the closed one
    by = dict(zip(names, t["picture_opening"]))
    assert by["D"] > 2 * by["A"]
