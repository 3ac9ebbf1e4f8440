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
``lipsync init --video`` (words recognised: no transcript comes with the clip), renders
``samples/hello.wav`` with it and with ``visemes/grid-s1``, runs the face mesh on the
decoded frames and prints: the bank's timing and warnings, each picture's lip opening, the
rendered mouth's opening inside and outside the words and on P/B/M frames, and how still
the rendered head is (eye-centre drift and per-frame steps, in eye distances) next to the
GRID bank's render of the same speech. Then (issue 28) ``lipsync dub`` re-voices the clip
itself with the same speech and the same figures are printed for the dub.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# MediaPipe mesh points of the outer eye corners (the stabiliser's still points include them).
EYE_CORNERS = (33, 263)


def _run(args) -> None:
    subprocess.run(args, check=True)


def _render_stats(video: Path, bank_dir: Path) -> dict:
    from lipsync import Animator, Bank
    from lipsync.face import measure as M
    from lipsync.face.track import track_frames
    from lipsync.face.video import read_video
    from lipsync.phonetics.phonemes import DEFAULT_MAP, load_map

    from lipsync.face.video import probe_video

    fps = probe_video(video).fps  # a dub keeps the clip's own rate
    frames = list(read_video(video))
    points = track_frames(frames, fps=fps, smooth=False).points
    opening = M.lip_opening(points)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        anim = Animator.from_audio(Bank.load(bank_dir), ROOT / "samples" / "hello.wav",
                                   (ROOT / "samples" / "hello.lab").read_text(), fps=fps)
    speech = np.zeros(len(frames), bool)
    for w in anim.alignment.words:
        speech[int(w.start * anim.fps):int(np.ceil(w.end * anim.fps))] = True
    closures = set(load_map(DEFAULT_MAP).closures)     # both banks are made with the default map
    closed = [i for i, f in enumerate(anim.specs[:len(frames)]) if f.shown in closures]
    eyes = points[:, list(EYE_CORNERS)].mean(axis=1)
    iod = float(np.nanmedian(np.linalg.norm(points[:, EYE_CORNERS[0]] - points[:, EYE_CORNERS[1]], axis=1)))
    drift = np.linalg.norm(eyes - np.nanmedian(eyes, axis=0), axis=1) / iod
    step = np.linalg.norm(np.diff(eyes, axis=0), axis=1) / iod
    return {"face found": float(np.isfinite(opening).mean()),
            "opening in words (median)": round(float(np.nanmedian(opening[speech])), 3),
            "opening outside (median)": round(float(np.nanmedian(opening[~speech])), 3),
            "P/B/M frames": len(closed),
            "opening on P/B/M (max)": round(float(np.nanmax(opening[closed])), 3) if closed else None,
            "eye-centre drift p95 (eye distances)": round(float(np.nanpercentile(drift, 95)), 3),
            "per-frame step p95 (eye distances)": round(float(np.nanpercentile(step, 95)), 3),
            "eye distance px": round(iod, 1)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("video", type=Path)
    ap.add_argument("--crop", help="W:H:X:Y of the face's part of the picture (ffmpeg crop)")
    args = ap.parse_args(argv)
    import imageio_ffmpeg

    from lipsync import Bank
    from lipsync.bench.coarticulation import bank_values

    ffmpeg = imageio_ffmpeg.get_ffmpeg_exe()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        clip = tmp / "face.mp4"
        crop = ["-vf", f"crop={args.crop}"] if args.crop else []
        _run([ffmpeg, "-loglevel", "error", "-y", "-i", str(args.video), *crop, "-c:v", "libx264", "-crf", "16",
              "-c:a", "aac", str(clip)])
        bank = tmp / "bank"
        lipsync = [sys.executable, "-m", "lipsync"]
        _run([*lipsync, "init", str(bank), "--video", str(clip), "-q"])
        rep = json.loads((bank / "init-report.json").read_text())
        print("bank:", {"seconds": round(sum(rep["seconds"].values()), 1), "size": rep["size"],
               "words recognised": " ".join(rep["videos"][0]["words"]), "missing": rep["missing"],
               "symmetry": rep["symmetry"]})
        print("pictures' lip opening:", {k: round(v, 3) for k, v in bank_values(Bank.load(bank)).items()})
        for name, b in (("this face", bank), ("visemes/grid-s1", ROOT / "visemes" / "grid-s1")):
            out = tmp / f"{name.replace('/', '-')}.mp4"
            _run([*lipsync, "render", str(ROOT / "samples" / "hello.wav"), "--text", str(ROOT / "samples" / "hello.lab"),
                  "--bank", str(b), "-o", str(out), "-q"])
            print(f"hello.wav rendered with {name}:", _render_stats(out, b))
        # issue 28: the clip itself re-voiced with hello.wav (its own frames, its bank made by dub)
        out = tmp / "dub.mp4"
        proc = subprocess.run([*lipsync, "dub", str(clip), "--audio", str(ROOT / "samples" / "hello.wav"), "--text",
                               str(ROOT / "samples" / "hello.lab"), "-o", str(out), "--cache", str(tmp / "cache")],
                              capture_output=True, text=True)
        said = [line for line in proc.stderr.splitlines() if "warning" in line or "error" in line or "wrote" in line]
        print("lipsync dub (exit", proc.returncode, "):", " | ".join(said)[:600])
        if proc.returncode == 0:
            print("hello.wav dubbed onto the clip:", _render_stats(out, bank))
    return 0


if __name__ == "__main__":
    sys.exit(main())
