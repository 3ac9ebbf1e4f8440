"""docs/strip-real.png: frames of ``lipsync render samples/hello.wav --text samples/hello.lab
--bank visemes/grid-s1 -o hello-real.mp4`` (``make docs-images``).

The clip is rendered by the command itself, decoded again, and every few frames of the
speech are laid out with their time and what the sequencer shows there (one viseme, or a
morph between two).
"""

from __future__ import annotations

import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from lipsync.pipeline.animator import Animator
from lipsync.cli import main as lipsync
from lipsync.face.video import read_video
from lipsync.encode.preview import save_png, strip

ROOT = Path(__file__).resolve().parents[1]
#: Frames shown, and every how many frames of the speech.
COUNT, EVERY = 12, 3
#: Shown: the picture below this share of its height, without this share at each side.
CROP = (0.45, 0.2)
#: Width of each shown frame.
TILE = 200


def main(out: str) -> int:
    wav, lab, bank = ROOT / "samples" / "hello.wav", ROOT / "samples" / "hello.lab", ROOT / "visemes" / "grid-s1"
    with tempfile.TemporaryDirectory() as tmp:
        video = Path(tmp) / "hello-real.mp4"
        code = lipsync(["render", str(wav), "--text", str(lab), "--bank", str(bank), "-o", str(video), "-q"])
        if code:
            return code
        frames = list(read_video(video))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        anim = Animator.from_audio(bank, wav, lab.read_text())
    start = int(anim.alignment.words[0].start * anim.fps)
    picks = [start + EVERY * k for k in range(COUNT) if start + EVERY * k < len(frames)]
    h, w = frames[0].shape[:2]

    def lower_face(img):
        # the mouth is what moves: the face from below the eyes to the chin, cut from the middle
        return img[int(CROP[0] * h):, int(CROP[1] * w):int((1 - CROP[1]) * w)]

    def label(i):
        s = anim.specs[i]
        return f"{i / anim.fps:.2f} s  " + (s.shown or f"{s.from_viseme}-{s.to_viseme}")

    half = (len(picks) + 1) // 2
    image = np.concatenate([strip([[lower_face(frames[i]) for i in row]], column_labels=[label(i) for i in row],
                                  tile=TILE)
                            for row in (picks[:half], picks[half:])], axis=0)
    save_png(out, image)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else str(ROOT / "docs" / "strip-real.png")))
