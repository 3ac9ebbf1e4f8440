"""docs/strip-dub.png: a held-out GRID sentence, real / rendered / dubbed (``make docs-images``).

A bank is made from GRID's bank sentences (``lipsync init --video``, as
:data:`lipsync.bench.grid.BANK_CLIPS`), then, by the commands themselves:

* **real** — sentence B's own frames;
* **render** — ``lipsync render B.mpg --text "..." --bank BANK``: B's sound and transcript on
  the bank's idle plate (the speaker's own blinks and head motion);
* **dub** — ``lipsync dub A.mpg --audio B.mpg --text "..." --bank BANK``: another sentence's
  video (A) re-voiced with B's sound.

Every few frames of B's speech are shown, each video cut to its face (the face mesh's box,
median over the clip) so the three rows line up.
"""

from __future__ import annotations

import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from lipsync.bench import grid
from lipsync.cli import main as lipsync
from lipsync.face.track import track_frames
from lipsync.face.video import read_video
from lipsync.encode.preview import save_png, strip

ROOT = Path(__file__).resolve().parents[1]
#: The dubbed video (A) and the sentence whose sound drives render and dub (B).
A, B = "bbbs6p", "bgbb3a"
#: Frames shown, every how many frames of the speech, and the width of each.
COUNT, EVERY, TILE = 10, 4, 150


def _face(frames):
    """The frames cut to the face: the mesh's box (median over the clip) grown by a tenth."""
    pts = track_frames(frames, fps=25.0).points
    p = np.nanmedian(pts[..., :2], axis=0)
    (x0, y0), (x1, y1) = p.min(axis=0), p.max(axis=0)
    gx, gy = 0.1 * (x1 - x0), 0.1 * (y1 - y0)
    h, w = frames[0].shape[:2]
    ys, xs = slice(max(0, int(y0 - gy)), min(h, int(y1 + gy))), slice(max(0, int(x0 - gx)), min(w, int(x1 + gx)))
    return [f[ys, xs] for f in frames]


def main(out: str) -> int:
    names = [c for c in grid.BANK_CLIPS if grid.video(c).is_file()]
    if not names or not grid.video(A).is_file() or not grid.video(B).is_file():
        print(f"GRID clips {A}, {B} and the bank sentences are needed in {grid.grid_dir()}", file=sys.stderr)
        return 2
    text = grid.transcript(B)
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tmp = Path(tmp)
        bank = tmp / "bank"
        for c in names:
            (tmp / f"{c}.txt").write_text(grid.transcript(c) + "\n")
            (tmp / f"{c}.mpg").symlink_to(grid.video(c))
        steps = [["init", str(bank), "--video", *[str(tmp / f"{c}.mpg") for c in names], "-q"],
                 ["render", str(grid.video(B)), "--text", text, "--bank", str(bank), "-o", str(tmp / "render.mp4"),
                  "-q"],
                 ["dub", str(grid.video(A)), "--audio", str(grid.video(B)), "--text", text, "--bank", str(bank),
                  "-o", str(tmp / "dub.mp4"), "-q", "--cache", str(tmp / "cache")]]
        for args in steps:
            code = lipsync(args)
            if code:
                return code
        rows = [list(read_video(v)) for v in (grid.video(B), tmp / "render.mp4", tmp / "dub.mp4")]
    words = grid.alignment_of(B).words
    start = int(words[0].start * 25)
    picks = [start + EVERY * k for k in range(COUNT) if start + EVERY * k < min(len(r) for r in rows)]
    cut = [_face(r) for r in rows]
    image = strip([[c[i] for i in picks] for c in cut], row_labels=["real", "render", "dub"],
                  column_labels=[f"{i / 25:.2f} s" for i in picks], tile=TILE)
    save_png(out, image)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else str(ROOT / "docs" / "strip-dub.png")))
