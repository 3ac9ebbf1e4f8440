"""docs/strip-samples.png and docs/mouth-samples.png: real frames, the old morph and the mouth samples.

A GRID s1 sentence that ``visemes/grid-s1`` was not made from (``prap6p``, "place red at p
six please") is rendered from its own sound and transcript with the bank twice, as
``lipsync render prap6p.mpg --text ... --bank visemes/grid-s1 --samples off|on`` does, and
decoded again; the strip shows, every few frames of the speech, the speaker's real frame
(top), the old one-picture-per-viseme morph (middle) and the selected samples (bottom),
each cut around its own mouth (found by the face mesh) at the same size. The close-up is
one frame of each at full size (1 video pixel = 1 picture pixel), side by side.

Usage (``make docs-images``)::

    .venv/bin/python tools/samples_strip.py docs/strip-samples.png docs/mouth-samples.png
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from lipsync.bench import grid
from lipsync.cli import main as lipsync
from lipsync.encode.preview import save_png, strip
from lipsync.face.landmarks import FaceMesh
from lipsync.face.video import read_video

ROOT = Path(__file__).resolve().parents[1]
CLIP = "prap6p"
#: Frames shown, from this one, every how many.
COUNT, FIRST, EVERY = 8, 20, 4
#: The window around the mouth's centre (W, H), video pixels: the lower face at GRID's scale.
WINDOW = (120, 84)
#: The close-up's frame.
CLOSE_UP = 44


def around_mouth(frame: np.ndarray, mesh: FaceMesh) -> np.ndarray:
    """The :data:`WINDOW` of ``frame`` centred on its mouth (the outer lip corners' middle)."""
    p = mesh.find(np.ascontiguousarray(frame))
    h, w = frame.shape[:2]
    cx, cy = (p[[61, 291], :2].mean(axis=0) if p is not None else (w / 2, h / 2))
    x0 = int(np.clip(round(cx - WINDOW[0] / 2), 0, w - WINDOW[0]))
    y0 = int(np.clip(round(cy - WINDOW[1] / 2), 0, h - WINDOW[1]))
    return frame[y0:y0 + WINDOW[1], x0:x0 + WINDOW[0]]


def main(out: str, close_up: str) -> int:
    bank = ROOT / "visemes" / "grid-s1"
    rows = {"real": [np.array(f) for f in read_video(grid.video(CLIP))]}
    with tempfile.TemporaryDirectory() as tmp:
        for name, opt in (("old morph", "off"), ("samples", "on")):
            video = Path(tmp) / f"{opt}.mp4"
            code = lipsync(["render", str(grid.video(CLIP)), "--text", grid.transcript(CLIP), "--bank", str(bank),
                            "-o", str(video), "-q", "--samples", opt])
            if code:
                return code
            rows[name] = [np.array(f) for f in read_video(video)]
    mesh = FaceMesh()
    picks = [FIRST + EVERY * k for k in range(COUNT)]
    image = np.concatenate([strip([[around_mouth(frames[i], mesh) for i in picks]],
                                  column_labels=[f"{name}  {i / 25:.2f} s" for i in picks], tile=WINDOW[0])
                            for name, frames in rows.items()], axis=0)
    save_png(out, image)
    save_png(close_up, np.concatenate([around_mouth(frames[CLOSE_UP], mesh) for frames in rows.values()], axis=1))
    return 0


if __name__ == "__main__":
    args = sys.argv[1:] or [str(ROOT / "docs" / "strip-samples.png"), str(ROOT / "docs" / "mouth-samples.png")]
    sys.exit(main(*args))
