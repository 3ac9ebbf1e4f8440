"""docs/face-lines.jpg: the face template's lines on two real GRID frames (``make docs-images``)."""

from __future__ import annotations

import sys

import cv2
import numpy as np

from lipsync.bench.grid import video
from lipsync.face.landmarks import FaceMesh
from lipsync.face.lines import face_features, midline_axis
from lipsync.face.video import read_video

SCALE = 2
MOVING = ("lip", "mouth", "jaw", "chin")


def main(out: str) -> None:
    frames = list(read_video(video("prap6p")))
    imgs = [frames[5], frames[37]]  # silence, and the open vowel of "six"... "please"
    mesh = FaceMesh()
    pts = {str(i): mesh.find(im) for i, im in enumerate(imgs)}
    feats = face_features(pts, imgs[0].shape[:2], axis=midline_axis(list(pts.values())))
    tiles = []
    for k, im in zip(pts, imgs):
        big = cv2.cvtColor(cv2.resize(im, None, fx=SCALE, fy=SCALE, interpolation=cv2.INTER_CUBIC),
                           cv2.COLOR_RGB2BGR)
        for name, f in feats[k].items():
            colour = (40, 40, 230) if name.startswith(MOVING) else (40, 200, 40)
            for p, q in f.expand():
                a = tuple(int(round(v)) for v in (p + 0.5) * SCALE)
                b = tuple(int(round(v)) for v in (q + 0.5) * SCALE)
                cv2.line(big, a, b, colour, 2, cv2.LINE_AA)
        tiles.append(big[150 * SCALE // 3 * 2:, 60 * SCALE:300 * SCALE])
    ok = cv2.imwrite(out, np.hstack(tiles), [cv2.IMWRITE_JPEG_QUALITY, 90])
    if not ok:
        sys.exit(f"could not write {out}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "docs/face-lines.jpg")
