"""A subject from a video of someone other than GRID's speaker, and what happens to it.

Issue 17 asks what ``lipsync init --video`` does with faces unlike the dev speaker, on
openly licensed footage only. Two such clips were found in
Debian packages (nothing of them is shipped here):

* ``forensics-samples-files``' ``movie-hello.mp4`` (CC BY-SA 4.0, Joao Eriberto Mota Filho):
  a screencast with the speaker's webcam in a corner (glasses, a headset, backlit, looking
  down at the keyboard at times, about 44 px between the eyes);
* ``kphotoalbum``'s ``demo/movie.avi`` (GPL-2+, the KPhotoAlbum authors): a man with glasses
  introducing himself to a webcam, 160x120 at 15 fps, 4.5 s.

Fetch and run them with::

    apt-get download forensics-samples-files kphotoalbum
    dpkg -x forensics-samples-files_*.deb pkg && dpkg -x kphotoalbum_*.deb pkg
    python tools/other_face.py pkg/usr/share/forensics-samples/original-files/movie2/movie-hello.mp4 \\
        --crop 252:190:113:84
    python tools/other_face.py pkg/usr/share/kphotoalbum/demo/movie.avi

The script crops the webcam (``--crop W:H:X:Y``, ffmpeg's order), makes a bank with
``lipsync init --video`` (words recognised: no transcript comes with the clip; its mouth
samples included), prints the bank's timing, warnings and each picture's lip opening, then
(issue 35) renders ``samples/hello.wav`` on the bank's plate and dubs it onto the clip itself
(:func:`lipsync.dub`) each way of :data:`lipsync.bench.samples.METHODS` -- samples with
joins morphed, samples with joins cut, ``--samples off`` (the one-picture morph), hard cuts
(render only) -- encodes as the product does and, with the face mesh on the decoded frames,
prints against the clip's own frames (re-encoded the same way; a dub: frame for frame):

* **sharpness**: median variance of the Laplacian of the mouth box
  (:func:`lipsync.bench.videobank.mouth_sharpness`), and of the lips' box without the
  samples' mask edge (:func:`lipsync.bench.samples.lip_sharpness`), before and after encoding;
* **range** (the opening's standard deviation over the clip's), **pops** (p99 grey change
  above the nose over the clip's), **P/B/M** (share of closure frames whose opening is at
  most :data:`lipsync.selection.select.CLOSED`, and the largest opening on them);
* **join step**: the mouth box's p99 change into a new run of samples over the clip's own
  p99 frame-to-frame change (:func:`lipsync.bench.samples.join_steps`).

``--sheets DIR`` writes full-size mouth crops of the frames around the largest joins
(``join-*.png``: before, the join, after; samples with joins morphed above, cut below).
``--bank DIR`` keeps the bank there (and reuses it when it is already made: a before/after
comparison on the same bank); ``--default-only`` runs the default way alone (the first of :data:`METHODS`; the tool passes no sound, so its target is the phones').
Each samples row ends with the share of its frames whose mouth was a sample pasted
as a whole-pixel copy, a sample resampled, or a morph across a join (``pastes``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _run(args) -> None:
    subprocess.run(args, check=True)


from lipsync.bench.samples import METHODS  # noqa: E402  (the tool runs from the repository)

#: The dub's ways (hard cuts is a render-only baseline).
DUB_METHODS = METHODS[:3]


class _Pastes:
    """Counts what each frame's mouth was while it is entered: a sample copied at a whole-pixel
    offset, a sample resampled (its map onto the frame turns or scales it), or a morph across a
    join (:meth:`lipsync.composite.samples.SampleCompositor.render`'s three cases)."""

    def __enter__(self):
        from lipsync.composite.plate import compose
        from lipsync.composite.samples import SampleCompositor, whole_shift
        from lipsync.selection import Selector

        self.kinds = {"whole-pixel": 0, "resampled": 0, "morphed": 0}
        self._orig = orig = SampleCompositor.render
        self._select = select = Selector.select
        kinds = self.kinds
        #: The selection made inside (a dub's: its joins).
        self.selection = None

        def selecting(sel, *args, **kwargs):
            self.selection = select(sel, *args, **kwargs)
            return self.selection

        def render(sc, src, dst, alpha, plate, pose, prepared=None, geometry=None):
            if alpha < 1.0 and src != dst:
                kinds["morphed"] += 1
            else:
                s = sc.samples
                copy = whole_shift(compose(pose, s.affine[dst]), s.crops.shape[1:3]) is not None
                kinds["whole-pixel" if copy else "resampled"] += 1
            return orig(sc, src, dst, alpha, plate, pose, prepared=prepared, geometry=geometry)

        SampleCompositor.render, Selector.select = render, selecting
        return self

    def __exit__(self, *exc):
        from lipsync.composite.samples import SampleCompositor
        from lipsync.selection import Selector

        SampleCompositor.render, Selector.select = self._orig, self._select

    def row(self) -> dict:
        n = max(sum(self.kinds.values()), 1)
        return {"pastes whole-pixel / resampled / morphed": " / ".join(
            f"{v / n:.2f}" for v in self.kinds.values())} if sum(self.kinds.values()) else {}


def _decoded(path: Path) -> List[np.ndarray]:
    from lipsync.face.video import read_video

    return [np.array(f) for f in read_video(path)]


def _measures(frames, fps: float, mesh, specs=None, closures=(), joins=None) -> dict:
    """The face mesh through ``frames`` and what the figures read off it."""
    from lipsync.bench import grid
    from lipsync.bench.samples import box_steps, join_steps, lip_sharpness
    from lipsync.bench.videobank import _closure_frames, mouth_sharpness
    from lipsync.face import measure as M
    from lipsync.face.track import track_frames

    tr = track_frames(frames, fps=fps, mesh=mesh)
    opening = M.lip_opening(tr.points)
    steps = box_steps(frames, tr.points)
    n = len(frames) if specs is None else min(len(frames), len(specs))
    shut = (_closure_frames(specs[:n], set(closures)) & np.isfinite(opening[:n])) if specs is not None else None
    return {"found": float(tr.found.mean()), "opening": opening, "sharp": mouth_sharpness(frames, tr.points),
            "lips": lip_sharpness(frames, tr.points), "steps": steps,
            "pops": grid.above_nose_pops(frames, tr.points) if tr.found.any() else float("nan"),
            "shut": None if shut is None else opening[:n][shut],
            "joins": None if joins is None else join_steps(steps, np.asarray(joins, bool)[:len(steps)])}


def _row(got: dict, ref: dict, raw: Optional[dict] = None) -> dict:
    """``got``'s figures over the reference's (``raw``: the same frames before encoding)."""
    from lipsync.selection.select import CLOSED

    def med(x):
        return float(np.nanmedian(x))

    row = {"face found": round(got["found"], 3),
           "sharpness": round(med(got["sharp"]) / med(ref["sharp"]), 3),
           "lips' sharpness": round(med(got["lips"]) / med(ref["lips"]), 3)}
    if raw is not None:
        row["lips' sharpness before encoding"] = round(med(raw["lips"]) / med(ref["lips"]), 3)
    row["range"] = round(float(np.nanstd(got["opening"]) / np.nanstd(ref["opening"])), 3)
    row["pops"] = round(got["pops"] / ref["pops"], 2)
    if got["shut"] is not None and len(got["shut"]):
        row["P/B/M closed"] = round(float((got["shut"] <= CLOSED).mean()), 3)
        row["P/B/M max opening"] = round(float(np.nanmax(got["shut"])), 3)
    if got["joins"] is not None and np.isfinite(got["joins"]).any():
        row["join step p99"] = round(float(np.nanpercentile(got["joins"], 99)) / float(
            np.nanpercentile(ref["steps"], 99)), 2)
        row["joins"] = int(np.isfinite(got["joins"]).sum())
    return row


def _timeline(bank, fps: float):
    """hello.wav's phones (aligned once) and the sequencer's frames on ``bank``."""
    from lipsync import Animator

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        anim = Animator.from_audio(bank, ROOT / "samples" / "hello.wav", (ROOT / "samples" / "hello.lab").read_text(),
                                   fps=fps, samples="off")
    return anim.alignment.phones, anim


def _renders(bank, clip: Path, tmp: Path, mesh, closures, sheets: Optional[Path], methods=METHODS) -> tuple:
    """hello.wav rendered on the bank's plate each way: the rows (against the clip's own
    frames) and the clip's own measures."""
    from lipsync.bench.samples import _encoded, render_method
    from lipsync.face.video import probe_video

    fps = probe_video(clip).fps
    source = _decoded(clip)
    ref = _measures(_encoded(source, tmp, fps), fps, mesh)
    phones, base = _timeline(bank, fps)
    rows, shown = {}, {}
    for m in methods:
        with warnings.catch_warnings(), _Pastes() as pastes:
            warnings.simplefilter("ignore")
            frames, anim = render_method(bank, phones, fps, m)
        sp = anim.sample_path
        joins = None if sp is None else sp.selection.joins
        got = _measures(_encoded(frames, tmp, fps), fps, mesh, anim.specs, closures, joins)
        rows[f"render: {m}"] = {**_row(got, ref, _measures(frames, fps, mesh)), **pastes.row()}
        shown[m] = (frames, joins)
        if m == METHODS[0]:
            rows[f"stages: {m}"] = _stages(anim, source, mesh, ref)
    if sheets is not None and "samples, joins morphed" in shown:
        _join_sheets(shown, mesh, fps, sheets)
    return rows, ref


def _stages(anim, source, mesh, ref: dict) -> dict:
    """What happens to the render's mouth between the source frame and the output, stage by
    stage (issue 35: count every resample): the samples' crops as stored (samples.mp4)
    against the same crops cut from the decoded clip (Laplacian variance, median ratio);
    the plate under the render (its lips' sharpness over the clip's, re-encoded as the
    product does: the same reference as the rows), and whether it was cut whole-pixel; the
    clip's own frames the render shows. What each frame's paste was (whole-pixel, resampled,
    morphed) is the render row's ``pastes`` (:class:`_Pastes`)."""
    from lipsync.samples.build import _cut
    from lipsync.samples.quality import sharpness

    sp, plate = anim.sample_path, anim.plate
    s = sp.samples
    h, w = s.crops.shape[1:3]
    ratios = [sharpness(s.crops[k], (0, 0, w, h)) / max(sharpness(np.ascontiguousarray(
        _cut(source[int(s.frame[k])], tuple(int(x) for x in s.origin[k]), (w, h))), (0, 0, w, h)), 1e-9)
        for k in range(len(s.crops)) if int(s.clip[k]) == 0 and int(s.frame[k]) < len(source)]
    pm = _measures(list(plate.frames), plate.fps, mesh)
    # the frames the render's samples were cut from, as the reference measured them: a
    # render saying other words shows other mouths (closed ones have no teeth's edges), so
    # its lips are judged against the clip's own frames it shows, frame for frame
    lips = np.asarray(ref["lips"], np.float64)
    shown = [lips[int(s.frame[int(sp.dst[i])])] for i in range(len(sp))
             if int(s.clip[int(sp.dst[i])]) == 0 and int(s.frame[int(sp.dst[i])]) < len(lips)]
    import json

    cut = json.loads(anim.bank.plate.poses.read_text())["source"].get("cut")
    return {"crops as stored": round(float(np.median(ratios)), 3) if ratios else None,
            "plate lips' sharpness": round(float(np.nanmedian(pm["lips"]) / np.nanmedian(ref["lips"])), 3),
            "shown samples' own frames' lips": round(float(np.nanmedian(shown) / np.nanmedian(lips)), 3)
            if shown else None,
            "plate cut": "none" if cut is None else ("whole-pixel" if cut[:2] == [1.0, 0.0] and cut[3:5] == [0.0, 1.0]
                                                      and float(cut[2]).is_integer() else "resampled")}


def _dubs(bank_dir: Path, clip: Path, tmp: Path, mesh, closures, ref: dict, methods=DUB_METHODS) -> Dict[str, dict]:
    """The clip re-voiced with hello.wav each way (its own bank), frame for frame against its own frames."""
    from lipsync import Animator, Bank
    from lipsync.face.video import probe_video
    from lipsync.pipeline.dubbing import dub
    from lipsync.selection import plan
    from lipsync.bench.samples import JOINS

    bank = Bank.load(bank_dir)
    fps = probe_video(clip).fps
    phones, _ = _timeline(bank, fps)
    anim = Animator(bank, phones, fps=fps, samples="off", still=True)
    rows = {}
    for m in methods:
        out = tmp / "dub.mp4"
        keep, plan.JOIN_FRAMES = plan.JOIN_FRAMES, JOINS.get(m, plan.JOIN_FRAMES)
        try:
            with warnings.catch_warnings(), _Pastes() as pastes:
                warnings.simplefilter("ignore")
                dub(clip, ROOT / "samples" / "hello.wav", out, text=(ROOT / "samples" / "hello.lab").read_text(),
                    bank=bank, quiet=True, cache=tmp / "cache", samples="on" if m.startswith("samples") else "off")
        finally:
            plan.JOIN_FRAMES = keep
        frames = _decoded(out)
        n = len(frames)
        own = {k: (v[:n] if isinstance(v, np.ndarray) and k in ("sharp", "lips", "opening") else v)
               for k, v in ref.items()}  # the same frames of the input
        joins = pastes.selection.joins if m.startswith("samples") and pastes.selection is not None else None
        got = _measures(frames, fps, mesh, anim.specs, closures, joins)
        rows[f"dub: {m}"] = {**_row(got, own), **pastes.row()}
    return rows


def _join_sheets(shown: dict, mesh, fps: float, out: Path) -> None:
    """Full-size mouth crops around the three joins whose step is largest when cut."""
    import cv2

    from lipsync.bench.samples import box_steps
    from lipsync.face.compare import mouth_box
    from lipsync.face.track import track_frames

    out.mkdir(parents=True, exist_ok=True)
    cut, joins = shown["samples, joins cut"]
    morphed = shown["samples, joins morphed"][0]
    pts = track_frames(cut, fps=fps, mesh=mesh).points
    steps = box_steps(cut, pts)
    at = [t for t in np.nonzero(joins[:len(steps)])[0] if 1 <= t < len(cut) - 1 and np.isfinite(steps[t])]
    for t in sorted(at, key=lambda t: -steps[t])[:3]:
        x0, y0, x1, y1 = mouth_box(pts[t], cut[t].shape[:2])
        rows = [np.concatenate([f[k][y0:y1, x0:x1] for k in (t - 1, t, t + 1)], axis=1) for f in (morphed, cut)]
        sheet = np.concatenate(rows, axis=0)
        sheet = cv2.resize(sheet, None, fx=3, fy=3, interpolation=cv2.INTER_NEAREST)  # pixels shown as they are
        cv2.imwrite(str(out / f"join-{t:04d}.png"), np.ascontiguousarray(sheet[..., ::-1]))


def _print(rows: Dict[str, dict]) -> None:
    for name, row in rows.items():
        print(f"  {name:32s}", "  ".join(f"{k} {v}" for k, v in row.items()))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("video", type=Path)
    ap.add_argument("--crop", help="W:H:X:Y of the face's part of the picture (ffmpeg crop)")
    ap.add_argument("--sheets", type=Path, help="write mouth crops around the largest joins here")
    ap.add_argument("--bank", type=Path, help="make the bank here and keep it (reused when already made)")
    ap.add_argument("--default-only", action="store_true", help="only the default way (samples, joins cut)")
    args = ap.parse_args(argv)
    import imageio_ffmpeg

    from lipsync import Bank
    from lipsync.bench.coarticulation import bank_values
    from lipsync.face.landmarks import FaceMesh
    from lipsync.phonetics.phonemes import DEFAULT_MAP, load_map

    ffmpeg = imageio_ffmpeg.get_ffmpeg_exe()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        clip = tmp / "face.mp4"
        crop = ["-vf", f"crop={args.crop}"] if args.crop else []
        _run([ffmpeg, "-loglevel", "error", "-y", "-i", str(args.video), *crop, "-c:v", "libx264", "-crf", "16",
              "-c:a", "aac", str(clip)])
        bank_dir = args.bank or tmp / "bank"
        if not (bank_dir / "bank.yaml").exists():
            _run([sys.executable, "-m", "lipsync", "init", str(bank_dir), "--video", str(clip), "-q"])
        rep = json.loads((bank_dir / "init-report.json").read_text())
        bank = Bank.load(bank_dir)
        print("bank:", {"seconds": round(sum(rep["seconds"].values()), 1), "size": rep["size"],
               "words recognised": " ".join(rep["videos"][0]["words"]), "missing": rep["missing"],
               "symmetry": rep["symmetry"], "samples": None if bank.samples is None else
               int(np.load(bank.samples.table)["clip"].shape[0])})
        print("pictures' lip opening:", {k: round(v, 3) for k, v in bank_values(bank).items()})
        mesh = FaceMesh()
        closures = load_map(DEFAULT_MAP).closures  # the bank is made with the default map
        only = METHODS[:1] if args.default_only else None  # the default: joins as the product plans them
        rows, ref = _renders(bank, clip, tmp, mesh, closures, args.sheets, only or METHODS)
        rows.update(_dubs(bank_dir, clip, tmp, mesh, closures, ref, only or DUB_METHODS))
        print("against the clip's own frames (re-encoded as the product encodes):")
        _print(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
