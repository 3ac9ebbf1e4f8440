"""docs/atlas.jpg: a sprite atlas of the toon for samples/hello.phn, each cell labelled (``make docs-images``).

The texture itself (``lipsync atlas visemes/toon -o mouth.png samples/hello.phn``) is the same
grid at full size; here it is made at half scale, drawn over a checkerboard where it is clear,
and each cell carries its pair and alpha, so the picture shows what the JSON says.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

from lipsync.atlas import load_atlas
from lipsync.cli import main as lipsync

ROOT = Path(__file__).resolve().parent.parent


def main(out: str) -> None:
    d = Path(tempfile.mkdtemp(prefix="lipsync-atlas-picture-"))
    code = lipsync(["atlas", str(ROOT / "visemes" / "toon"), "-o", str(d / "mouth.png"), "--scale", "0.5",
                    "-n", "3", "-q", str(ROOT / "samples" / "hello.phn")])
    if code:
        sys.exit(code)
    atlas = load_atlas(d / "mouth.json")
    tex = cv2.imread(str(d / "mouth.png"), cv2.IMREAD_UNCHANGED).astype(np.float32)
    h, w = tex.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    checker = np.where(((yy // 8) + (xx // 8)) % 2 == 0, 235.0, 205.0)[..., None]
    a = tex[..., 3:4] / 255.0
    img = (tex[..., :3] * a + checker * (1 - a)).astype(np.uint8)
    for c in atlas.cells:
        x, y, cw, ch = c.rect
        label = c.from_viseme if c.viseme else f"{c.from_viseme}>{c.to_viseme} {c.alpha:.2f}"
        cv2.rectangle(img, (x, y), (x + cw - 1, y + ch - 1), (90, 90, 90), 1)
        cv2.putText(img, label, (x + 4, y + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 3, cv2.LINE_AA)
        cv2.putText(img, label, (x + 4, y + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (30, 30, 30), 1, cv2.LINE_AA)
    if not cv2.imwrite(out, img, [cv2.IMWRITE_JPEG_QUALITY, 88]):
        sys.exit(f"could not write {out}")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python tools/atlas_picture.py OUT.jpg")
    main(sys.argv[1])
